//! Noise models (Poisson-Gaussian, ELD, the PGRF per-pixel composite), camera
//! profiles, the virtual sensor and training-pair synthesis.
//!
//! Empty until the noise-model stage lands; the crate exists so the workspace
//! has its final shape and the data flow raw -> noise/calib -> nn -> eval is
//! fixed from the start.

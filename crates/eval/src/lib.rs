//! Metrics (PSNR/SSIM as scikit-image computes them), dataset protocols
//! (ELD, SID, paired lists) and comparison tables.
//!
//! Empty until the evaluation stage lands.

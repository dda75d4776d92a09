//! Networks (SID U-Net, SR3 velocity field), rectified-flow training and
//! sampling, checkpoints. The only crate that depends on the deep-learning
//! framework.
//!
//! Empty until the network stage lands.

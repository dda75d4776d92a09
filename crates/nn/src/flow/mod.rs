//! The rectified flow of PGRF, in one place: the straight path, the
//! training loss and draws and the samplers (the sampling search that
//! chooses t2 is the application's, `pgrf_app::search`).
//!
//! Symbols as in the paper: X1 the clean image, X0 ~ N(0, I) the start,
//! T the condition (the synthetic or real noisy capture, amplified by its
//! exposure ratio), t in [0, 1] the time along the path, v(Xt, T, t) the
//! velocity field (an SR3-style U-Net, [`crate::arch::sr3`]), t2 the searched
//! second time of the two-stage sampler.
//!
//! | paper | here |
//! |---|---|
//! | eq. 4.1, 4.5 path Xt = t X1 + (1 - t) X0 | [`interpolate`] |
//! | loss \|X1 - X0 - v(Xt, T, t)\|_1 | [`flow_loss`] |
//! | X0 ~ N(0, I), t ~ U(0, 1) (Algorithm 1) | `draw::fill_start`, `draw::draw_time` (crate-internal) |
//! | eq. 4.10 XZ = v(X0, T, 0) + X0 | [`sample::first_stage`] |
//! | eq. 4.11-4.12 XM = v(t2 XZ + (1 - t2) X0, T, t2) + X0 | [`sample::second_stage`] |
//! | two-stage sampler (Algorithm 3's core) | [`sample::two_stage`] |
//! | sampling search (Algorithm 2) | `pgrf_app::search` (`pgrf search`'s recipe), over [`sample::first_stage`] and [`sample::second_stage`] |
//!
//! The training step that applies the loss with an optimiser is
//! [`crate::step::flow_step`]; the training loop is [`crate::train`];
//! inference over whole images (tiles, seeded per-row start fields) is
//! [`crate::infer`], which runs [`sample::Sampler`].

pub(crate) mod draw;
mod loss;
mod path;
pub mod sample;

pub use loss::flow_loss;
pub use path::interpolate;
pub use sample::SamplerKind;

//! One module per subcommand: argument struct plus `run`.

pub mod calibrate;
pub mod chart;
pub mod convert;
pub mod demo;
pub mod enhance;
pub mod eval;
pub mod info;
pub mod make_dataset;
pub mod metrics;
pub mod preview;
pub mod profiles;
pub mod reduce;
pub mod search;
pub mod simulate;
pub mod synth;
pub mod train;
pub mod weights;

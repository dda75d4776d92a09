//! One module per subcommand: argument struct plus `run`.

pub mod bench;
pub mod bench_synth;
pub mod bench_train;
pub mod calibrate;
pub mod chart;
pub mod convert;
pub mod info;
pub mod preview;
pub mod simulate;
pub mod synth;
pub mod train;

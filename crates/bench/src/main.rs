//! `pgrf-bench`: timings of pgrf's hot paths, for BENCHMARKS.md. A binary of
//! its own so that the product, `pgrf`, carries no benchmark code; the
//! scripts in bench/ run it beside the peers (LibRaw through rawpy, numpy,
//! scikit-image, PyTorch) in the same session.
//!
//! Timings are medians over repeated runs after warm-up, as
//! `pgrf_core::stats::median` takes them: for an even number of runs the
//! upper of the two middle samples, not their mean.

mod decode;
mod enhance;
mod loader;
mod ssim;
mod stack;
mod synth;
mod train;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// The command line: one subcommand per benchmark.
#[derive(Parser, Debug)]
#[command(name = "pgrf-bench", version, about = "Time pgrf's hot paths (results go to BENCHMARKS.md)", long_about = None)]
struct Cli {
    #[command(subcommand)]
    what: Bench,
}

/// The benchmarks.
#[derive(Subcommand, Debug)]
enum Bench {
    /// Full PGRF noise model (all components, per-pixel maps) on an A7S2-sized
    /// frame (4 x 1424 x 2128 packed), plus this machine's memory bandwidth.
    Synth(synth::SynthArgs),
    /// Per-pixel statistics of a bias stack (decode + Welford accumulation),
    /// with the decode-only time and this process's peak memory.
    Stack(stack::StackArgs),
    /// Decode + pack + normalise RAW files.
    Decode(decode::DecodeArgs),
    /// Crops per second of `pgrf train`'s data loader alone (photos,
    /// RAW folders or procedural scenes), to compare with the trainer's.
    Loader(loader::LoaderArgs),
    /// Forward and training-step time of the SID U-Net and the SR3 velocity
    /// field on the CPU (bench/train.sh runs PyTorch beside it).
    Train(train::TrainArgs),
    /// Inference on a whole frame (`pgrf enhance`'s network part: tiles,
    /// sampler, blend) with either network; bench/enhance.sh runs PyTorch beside it.
    Enhance(Box<enhance::EnhanceArgs>),
    /// PSNR + SSIM under the ELD protocol on a deterministic A7S2-sized pair
    /// (4 x 1424 x 2128 packed); bench/ssim.sh times scikit-image beside it.
    Ssim(ssim::SsimArgs),
}

fn main() -> ExitCode {
    pgrf_core::exit::one_line_panics("pgrf-bench");
    let cli = Cli::parse();
    // As `pgrf` does; `pgrf-bench train --default-malloc` measures without.
    if !matches!(&cli.what, Bench::Train(a) if a.default_malloc) {
        pgrf_core::mem::keep_freed_buffers();
    }
    let result = match &cli.what {
        Bench::Synth(a) => synth::run(a),
        Bench::Stack(a) => stack::run(a),
        Bench::Decode(a) => decode::run(a),
        Bench::Train(a) => train::run(a),
        Bench::Loader(a) => loader::run(a),
        Bench::Enhance(a) => enhance::run(a),
        Bench::Ssim(a) => ssim::run(a),
    };
    pgrf_core::exit::finish("pgrf-bench", result)
}

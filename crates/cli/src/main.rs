//! `pgrf`: low-light RAW photography toolkit. This binary only parses
//! arguments, shows progress and reports errors; the science lives in the
//! library crates.

mod cmd;
mod input;
mod io;
mod progress;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(name = "pgrf", version, about = "Measure sensor noise, synthesise training pairs, denoise dark RAW photos", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Whose CPU operations the networks run: pgrf's own kernels (convolution gradients, transposed convolution, activations, Adam) or burn 0.21's, for comparison. Same numbers to rounding; CUDA always runs burn's.
    #[arg(long, global = true, default_value = "pgrf", value_name = "pgrf|burn")]
    kernels: pgrf_nn::ops::Kernels,
    /// darktable's noiseprofiles.json, for `--profile darktable:"MAKER MODEL"` and `pgrf profiles` [default: darktable's install, e.g. /usr/share/darktable/noiseprofiles.json].
    #[arg(long, global = true, value_name = "PATH")]
    darktable_profiles: Option<std::path::PathBuf>,
}

/// The global flags, handed to the commands that use them: configuration
/// of their calls, not process state.
pub struct Globals<'a> {
    /// `--kernels`.
    pub kernels: pgrf_nn::ops::Kernels,
    /// `--darktable-profiles`.
    pub darktable: Option<&'a std::path::Path>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Show the whole product on built-in data: a Canon EOS 550D photo of a colour chart captured x100 and x200 too dark, restored by the built-in SPC and PGRF models, scored and pictured.
    Demo(cmd::demo::DemoArgs),
    /// Print what pgrf reads from a RAW file: size, CFA, levels, white balance, colour matrix, exposure.
    Info(cmd::info::InfoArgs),
    /// Render a RAW file to an sRGB PNG (demosaic, white balance, colour matrix, gamma).
    Preview(cmd::preview::PreviewArgs),
    /// Convert a RAW file (or headerless dump) to a lossless DNG, keeping pixels and metadata.
    Convert(cmd::convert::ConvertArgs),
    /// Simulate a low-light capture of a clean RAW with a physics noise model (P-G, ELD or PGRF).
    Synth(cmd::synth::SynthArgs),
    /// Write bias, dark and flat stacks of a virtual sensor with known per-pixel truth.
    SimulateSensor(cmd::simulate::SimulateArgs),
    /// Per-pixel calibration from bias, dark and flat-field stacks, with a report.
    Calibrate(cmd::calibrate::CalibrateArgs),
    /// Calibrate light frames with the masters and calibration of `pgrf calibrate --masters`: (light - bias - scaled dark) / normalised flat, defects replaced.
    Reduce(cmd::reduce::ReduceArgs),
    /// Render pgrf's built-in colour test chart as a DNG.
    Chart(cmd::chart::ChartArgs),
    /// Train the SPC denoiser or the PGRF flow model on synthetic pairs (procedural scenes or clean RAWs).
    Train(Box<cmd::train::TrainArgs>),
    /// Denoise dark RAW photos with a trained model: clean linear DNGs and sRGB previews.
    Enhance(Box<cmd::enhance::EnhanceArgs>),
    /// Sampling search: find the flow model's best second time t2 and store it in its weight file.
    Search(cmd::search::SearchArgs),
    /// Raw-domain PSNR and SSIM of a result against its reference (ELD protocol).
    Metrics(cmd::metrics::MetricsArgs),
    /// Evaluate models on ELD / SID / a pair list, or on clean RAWs given synthetic dark captures (`--protocol synthetic`): PSNR/SSIM (and colour cast) per ratio or condition, per-image CSV, worst images.
    Eval(Box<cmd::eval::EvalArgs>),
    /// Write a miniature benchmark folder in the ELD or SID layout (procedural scenes, A7S2 noise).
    MakeDataset(cmd::make_dataset::MakeDatasetArgs),
    /// Import a published PyTorch SID U-Net checkpoint (SID, ELD, PMN, PNNP, LED) as a pgrf weight file.
    ImportWeights(cmd::weights::ImportArgs),
    /// Export a pgrf weight file for PyTorch (.pth or .safetensors in UNetSeeInDark's names).
    ExportWeights(cmd::weights::ExportArgs),
    /// List the camera profiles --profile accepts (built in, darktable's cameras) and show what one holds.
    Profiles(cmd::profiles::ProfilesArgs),
}

/// The noise model kind's old names (`--model` is a weight file, `--noise` noise values).
const RENAMED: [pgrf_core::exit::Renamed; 3] = [
    ("synth", "--model", "--noise-model"),
    ("train", "--noise", "--noise-model"),
    ("eval", "--noise", "--noise-model"),
];

fn main() -> ExitCode {
    pgrf_core::exit::one_line_panics("pgrf");
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    let command = match &cli.command {
        Command::Synth(_) => "synth",
        Command::Train(_) => "train",
        Command::Eval(_) => "eval",
        _ => "",
    };
    pgrf_core::exit::note_renamed("pgrf", &RENAMED, command);
    pgrf_core::mem::keep_freed_buffers();
    if let Err(e) = io::check(&cli.command, cli.darktable_profiles.as_deref()) {
        return pgrf_core::exit::finish("pgrf", Err(e));
    }
    let g = Globals {
        kernels: cli.kernels,
        darktable: cli.darktable_profiles.as_deref(),
    };
    let result = match &cli.command {
        Command::Demo(a) => cmd::demo::run(a, &g),
        Command::Info(a) => cmd::info::run(a, &g),
        Command::Preview(a) => cmd::preview::run(a),
        Command::Convert(a) => cmd::convert::run(a),
        Command::Chart(a) => cmd::chart::run(a),
        Command::Synth(a) => cmd::synth::run(a, &g),
        Command::SimulateSensor(a) => cmd::simulate::run(a),
        Command::Calibrate(a) => cmd::calibrate::run(a),
        Command::Reduce(a) => cmd::reduce::run(a),
        Command::Train(a) => cmd::train::run(a, &g),
        Command::Enhance(a) => cmd::enhance::run(a, &g),
        Command::Search(a) => cmd::search::run(a, &g),
        Command::Metrics(a) => cmd::metrics::run(a),
        Command::Eval(a) => cmd::eval::run(a, &g),
        Command::MakeDataset(a) => cmd::make_dataset::run(a),
        Command::ImportWeights(a) => cmd::weights::run_import(a),
        Command::ExportWeights(a) => cmd::weights::run_export(a),
        Command::Profiles(a) => cmd::profiles::run(a, &g),
    };
    pgrf_core::exit::finish("pgrf", result)
}

/// Help and version go to stdout with exit 0, as clap prints them; a usage
/// error keeps clap's text (the usage line and the `--help` hint), but its
/// first line names the program like every other pgrf error, and the exit
/// code is clap's 2.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let text = e.render().to_string();
    let text = text.strip_prefix("error: ").unwrap_or(&text);
    eprint!("pgrf: error: {text}");
    ExitCode::from(2)
}

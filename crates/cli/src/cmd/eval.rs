//! `pgrf eval`: one or more models on a benchmark (ELD Sony A7S2, SID Sony,
//! a CSV of pairs, or dark captures synthesised from clean files), measured
//! under the ELD protocol, printed as the paper's tables print them (one row
//! per ratio, or per ISO and ratio, PSNR/SSIM per method, plus the colour
//! cast for synthetic captures), with per-image CSV, a Markdown table and a
//! PNG of the worst images.

use crate::progress::Bar;
use anyhow::{Context, Result};
use clap::Args;
use pgrf_app::enhance::describe_method;
use pgrf_app::method::NetworkMethod;
use pgrf_eval::dataset::run::NOISY;
use pgrf_eval::evaluation::BoxError;
use pgrf_eval::flags::{EvalFlags, PROTOCOLS_HELP};
use pgrf_eval::MethodUnderTest;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::infer::{SamplerChoice, Tiling};
use std::path::PathBuf;

#[derive(Args, Debug)]
#[command(after_help = PROTOCOLS_HELP)]
pub struct EvalArgs {
    #[command(flatten)]
    pub eval: EvalFlags,
    /// Weight file from `pgrf train`; repeat for a comparison table.
    #[arg(long, short = 'm')]
    pub model: Vec<PathBuf>,
    /// Tile side in packed pixels (default: as pgrf enhance chooses).
    #[arg(long)]
    pub tile: Option<usize>,
    /// cpu, or cuda (needs a build with `--features cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: DeviceKind,
}

/// Every --model, named by its file stem (primed when taken), announced on
/// stderr.
fn load_models(
    a: &EvalArgs,
    kernels: pgrf_nn::ops::Kernels,
) -> Result<Vec<Box<dyn MethodUnderTest>>> {
    a.device.check_available().map_err(anyhow::Error::msg)?;
    let tiling = Tiling {
        tile: a.tile,
        overlap: None,
        seed: a.eval.seed,
        device: a.device,
        kernels,
    };
    let mut names: Vec<String> = Vec::new();
    let mut models: Vec<Box<dyn MethodUnderTest>> = Vec::new();
    for m in &a.model {
        let r = pgrf_app::builtin::load_model(m, SamplerChoice::default(), a.device)
            .with_context(|| format!("--model {}", m.display()))?;
        let mut name = m
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| m.display().to_string());
        while names.contains(&name) || name == NOISY {
            name.push('\'');
        }
        if !a.eval.quiet {
            eprintln!("model {name}: {}", describe_method(r.as_ref()));
        }
        names.push(name.clone());
        models.push(Box::new(NetworkMethod::new(name, r, tiling)));
    }
    Ok(models)
}

pub fn run(a: &EvalArgs, g: &crate::Globals) -> Result<()> {
    let kernels = g.kernels;
    pgrf_nn::infer::check_tiling_args(a.tile, None)?;
    let mut cfg = a.eval.config(!a.model.is_empty())?;
    cfg.synthetic.darktable = g.darktable.map(Into::into);
    let load = || load_models(a, kernels).map_err(BoxError::from);
    let bar = || Bar::new("eval", 0, "images", a.eval.quiet);
    let evaluation = pgrf_eval::run_protocol(&cfg, load, bar)?;
    println!("{}", evaluation.header);
    print!("{}", evaluation.summary.text());
    evaluation.write(&cfg, &mut |line| eprintln!("{line}"))?;
    Ok(())
}

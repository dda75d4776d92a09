//! `pgrf demo`: the whole product on data built into the binary. A real
//! photograph (the Canon 550D colour-chart DNG, `crates/cli/assets`) or a
//! procedural scene (dead leaves, a ColorChecker, a ramp) is captured x100
//! and x200 too dark at ISO 1600 through the Sony A7S2 noise model, both
//! captures are restored by the built-in SPC and PGRF models, and the result
//! is a PSNR/SSIM table under the ELD protocol, the DNGs, and one picture
//! with everything side by side.

use crate::progress::Bar;
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use pgrf_app::builtin;
use pgrf_app::demo::{
    self, BoxError, Demo, DemoConfig, Models, PhotoSource, Scene as DemoScene, ISO, RATIOS,
};
use pgrf_core::paths::require_parent_dir;
use pgrf_eval::dataset::table::summarise;
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::infer::{Restore, SamplerChoice};
use std::path::{Path, PathBuf};

/// The real photograph built into the binary (MIT, syoyo/tinydng; see
/// `crates/cli/assets/README.md`).
const PHOTO: &[u8] = include_bytes!("../../assets/canon550d_colorchart.dng");
/// How the built-in photograph is named in messages and reports.
const PHOTO_NAME: &str = "canon550d_colorchart.dng";
/// Where it comes from, in the report.
const PHOTO_CREDIT: &str = "built in; Canon EOS 550D, tinydng, MIT";
/// The procedural scene's size when `--size` is not given.
const PROCEDURAL_SIZE: &str = "1536x1024";

/// What the demo starts from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Scene {
    /// A real RAW photograph: the built-in Canon 550D colour chart, or --photo FILE.
    Photo,
    /// pgrf's procedural scene: dead leaves, a ColorChecker and a ramp.
    Procedural,
}

#[derive(Args, Debug)]
#[command(
    after_help = "Writes DIR/demo.png (per ratio: clean, noisy, SPC, PGRF, whole frame \
and a 2x crop), DIR/clean.dng, and DIR/noisy_x100.dng, spc_x100.dng, pgrf_x100.dng (and x200). \
The models are built in; --spc and --pgrf take weight files from `pgrf train` instead. \
The built-in photograph is a Canon EOS 550D capture of a colour chart from the tinydng project \
(MIT licence, Syoyo Fujita and contributors)."
)]
pub struct DemoArgs {
    /// Output folder (created if its parent exists; demo files in it are replaced).
    #[arg(short, long, default_value = "pgrf-demo")]
    pub output: PathBuf,
    /// What to start from: a real photograph or the procedural scene.
    #[arg(long, value_enum, default_value = "photo")]
    pub scene: Scene,
    /// The photograph for --scene photo: any Bayer RAW pgrf reads, taken as the clean reference [default: the built-in Canon 550D chart].
    #[arg(long)]
    pub photo: Option<PathBuf>,
    /// Size in mosaic pixels, WxH (even, at least 64x64): the procedural scene's [default: 1536x1024], or the centre window of the photograph [default: all of it].
    #[arg(long)]
    pub size: Option<String>,
    /// Seed of the scene and of the noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// SPC weight file (default: built in).
    #[arg(long)]
    pub spc: Option<PathBuf>,
    /// PGRF flow weight file (default: built in).
    #[arg(long)]
    pub pgrf: Option<PathBuf>,
    /// Tile side in packed pixels (default: as `pgrf enhance` chooses).
    #[arg(long)]
    pub tile: Option<usize>,
    /// End with one JSON line of the scores on stdout.
    #[arg(long)]
    pub json: bool,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// A model given as a file, or the built-in one, checked to be of the
/// expected method.
fn model(file: Option<&Path>, builtin: &str, method: &str, flag: &str) -> Result<Box<dyn Restore>> {
    let path = file.unwrap_or(Path::new(builtin));
    let r = builtin::load_model(path, SamplerChoice::default(), DeviceKind::Cpu)
        .with_context(|| format!("{flag} {}", path.display()))?;
    if r.meta().arch.method().name() != method {
        bail!(
            "{flag} {}: holds a {}, not the {} model",
            path.display(),
            r.meta().arch.describe(),
            method.to_uppercase()
        );
    }
    Ok(r)
}

fn models(a: &DemoArgs) -> Result<Models> {
    Ok(Models {
        spc: model(a.spc.as_deref(), "builtin:spc", "spc", "--spc")?,
        pgrf: model(a.pgrf.as_deref(), "builtin:pgrf", "pgrf", "--pgrf")?,
    })
}

/// What the demo starts from, as the flags say.
fn scene(a: &DemoArgs) -> Result<DemoScene<'static>> {
    if a.photo.is_some() && a.scene != Scene::Photo {
        bail!("--photo goes with --scene photo");
    }
    Ok(match a.scene {
        Scene::Procedural => {
            let size = a.size.as_deref().unwrap_or(PROCEDURAL_SIZE);
            let (width, height) = super::make_dataset::parse_size(size, 64)?;
            DemoScene::Procedural { width, height }
        }
        Scene::Photo => DemoScene::Photo {
            source: match &a.photo {
                Some(p) => PhotoSource::File(p.clone()),
                None => PhotoSource::Bytes {
                    name: PHOTO_NAME,
                    credit: PHOTO_CREDIT,
                    bytes: PHOTO,
                },
            },
            size: match a.size.as_deref() {
                Some(s) => Some(super::make_dataset::parse_size(s, 64)?),
                None => None,
            },
        },
    })
}

pub fn run(a: &DemoArgs, g: &crate::Globals) -> Result<()> {
    let kernels = g.kernels;
    pgrf_nn::infer::check_tiling_args(a.tile, None)?;
    if !a.output.is_dir() {
        require_parent_dir(&a.output)?;
    }
    let cfg = DemoConfig {
        output: a.output.clone(),
        scene: scene(a)?,
        seed: a.seed,
        tile: a.tile,
        kernels,
    };
    let load = || models(a).map_err(BoxError::from);
    let start = || {
        // Steps: the reference, then per ratio capture + 2 models, then pictures.
        let steps = Bar::new("demo", 0, "steps", a.quiet);
        steps
            .bar()
            .enable_steady_tick(std::time::Duration::from_millis(200));
        steps
    };
    let d = demo::run(&cfg, load, start)?;
    print_report(a, &d);
    if a.json {
        println!("{}", d.json());
    }
    Ok(())
}

fn print_report(a: &DemoArgs, d: &Demo) {
    // The table goes to stderr with the rest of the report when stdout
    // carries the JSON line, so scripts read exactly one line.
    let out = |s: &str| {
        if a.json {
            eprintln!("{s}");
        } else {
            println!("{s}");
        }
    };
    out(&format!(
        "pgrf demo: {}; dark captures x{} and x{} simulated with the Sony A7S2's noise \
(pgrf model, built-in profile) at ISO {ISO}, seed {}; the camera counts as calibrated: its black-level \
error at the ISO is subtracted before the denoisers and the noisy score, as `pgrf enhance --calib` does",
        d.what, RATIOS[0], RATIOS[1], a.seed
    ));
    let source = |file: &Option<PathBuf>| {
        file.as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "built in".into())
    };
    out(&format!("SPC : {}, {}", d.models[0], source(&a.spc)));
    out(&format!("PGRF: {}, {}", d.models[1], source(&a.pgrf)));
    out(&format!(
        "protocol: whole frame, packed 4-channel (RGGB), each file's black/white levels; {}",
        d.protocol.describe()
    ));
    out(&summarise(&d.rows()).text());
    out(&format!(
        "wrote {} (rows: x{} and x{}, whole frame and 2x crop; columns: clean, noisy, SPC, PGRF) and 7 DNGs in {} ({:.1} s)",
        d.picture.display(),
        RATIOS[0],
        RATIOS[1],
        a.output.display(),
        d.seconds
    ));
}

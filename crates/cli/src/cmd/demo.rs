//! `pgrf demo`: the whole product on data built into the binary. A real
//! photograph (the Canon 550D colour-chart DNG, `crates/cli/assets`) or a
//! procedural scene (dead leaves, a ColorChecker, a ramp) is captured x100
//! and x200 too dark at ISO 1600 through the Sony A7S2 noise model, both
//! captures are restored by the built-in SPC and PGRF models, and the result
//! is a PSNR/SSIM table under the ELD protocol, the DNGs, and one picture
//! with everything side by side.

use crate::output::require_parent_dir;
use crate::progress::Bar;
use crate::shipped;
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use pgrf_core::NoProgress;
use pgrf_eval::dataset::table::{summarise, Row};
use pgrf_eval::{evaluate, Protocol, Scores};
use pgrf_nn::backend::DeviceKind;
use pgrf_nn::infer::prepare::network_input;
use pgrf_nn::infer::restorer::describe_sampler;
use pgrf_nn::infer::{restore_frame, Restore, SamplerChoice, Tiling};
use pgrf_noise::capture::DarkCapture;
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::unpack_normalized;
use pgrf_raw::{
    decode_bytes, decode_file, pack_normalized, render_preview, write_dng, Cfa, DngOptions,
    LevelOverrides, Preview, PreviewOptions, RawFrame,
};
use pgrf_report::{write_montage, Panel};
use pgrf_scenes::demo::render_demo;
use pgrf_scenes::SceneLevels;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The two captures, as in ELD's test set.
pub const RATIOS: [u32; 2] = [100, 200];
/// Their ISO.
pub const ISO: u32 = 1600;
/// Exposure of the clean frame; the dark ones get this / ratio.
const CLEAN_EXPOSURE_S: f64 = 1.0;
/// The real photograph built into the binary (MIT, syoyo/tinydng; see
/// `crates/cli/assets/README.md`).
const PHOTO: &[u8] = include_bytes!("../../assets/canon550d_colorchart.dng");
/// How the built-in photograph is named in messages and reports.
const PHOTO_NAME: &str = "canon550d_colorchart.dng";
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
    let r = shipped::load_model(path, SamplerChoice::default(), DeviceKind::Cpu)
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

/// One capture's results, in table order: noisy input, SPC, PGRF.
struct Capture {
    ratio: u32,
    /// The simulated capture, as the camera wrote it.
    dark: RawFrame,
    /// What the denoisers and the noisy score saw: the capture minus its
    /// calibrated dark level (before the ratio), for the noisy panel.
    calibrated: RawFrame,
    scores: [Scores; 3],
    restored: [RawFrame; 2],
}

/// The clean frame the demo starts from, and its description for the report.
struct Clean {
    frame: RawFrame,
    what: String,
}

/// The even centre window of `frame` of `size` ("WxH"), or all of it.
fn centre(frame: RawFrame, size: Option<&str>, name: &str) -> Result<RawFrame> {
    let Some(size) = size else {
        return Ok(frame);
    };
    let (w, h) = super::make_dataset::parse_size(size, 64)?;
    if w > frame.width || h > frame.height {
        bail!(
            "--size {w}x{h} is larger than {name} ({}x{})",
            frame.width,
            frame.height
        );
    }
    let (row, col) = ((frame.height - h) / 4 * 2, (frame.width - w) / 4 * 2);
    Ok(frame.crop(row, col, h, w)?)
}

/// Load or render the clean frame (before any model is loaded or file written).
fn clean_frame(a: &DemoArgs) -> Result<Clean> {
    if a.photo.is_some() && a.scene != Scene::Photo {
        bail!("--photo goes with --scene photo");
    }
    let (mut frame, what) = match a.scene {
        Scene::Procedural => {
            let size = a.size.as_deref().unwrap_or(PROCEDURAL_SIZE);
            let (w, h) = super::make_dataset::parse_size(size, 64)?;
            let f = render_demo(w, h, a.seed, Cfa::Rggb, &SceneLevels::default())?;
            let what = format!(
                "procedural scene {w}x{h} (dead leaves, ColorChecker, ramp; seed {})",
                a.seed
            );
            (f, what)
        }
        Scene::Photo => {
            let (frame, name) = match &a.photo {
                Some(p) => (
                    decode_file(p, &LevelOverrides::default())
                        .with_context(|| format!("--photo {}", p.display()))?,
                    p.display().to_string(),
                ),
                None => (
                    decode_bytes(Path::new(PHOTO_NAME), PHOTO, &LevelOverrides::default())?,
                    format!("{PHOTO_NAME} (built in; Canon EOS 550D, tinydng, MIT)"),
                ),
            };
            let f = centre(frame, a.size.as_deref(), &name)?;
            let what = format!("real photograph {name}, {}x{}", f.width, f.height);
            (f, what)
        }
    };
    frame.iso = Some(ISO);
    frame.exposure_s = Some(CLEAN_EXPOSURE_S);
    Ok(Clean { frame, what })
}

pub fn run(a: &DemoArgs) -> Result<()> {
    let t0 = Instant::now();
    pgrf_nn::infer::check_tiling_args(a.tile, None)?;
    if !a.output.is_dir() {
        require_parent_dir(&a.output)?;
    }
    let Clean { frame: clean, what } = clean_frame(a)?;
    let spc = model(a.spc.as_deref(), "builtin:spc", "spc", "--spc")?;
    let pgrf = model(a.pgrf.as_deref(), "builtin:pgrf", "pgrf", "--pgrf")?;
    let profile = CameraProfile::built_in("sony-a7s2").context("no sony-a7s2 profile")?;
    if !a.output.is_dir() {
        std::fs::create_dir(&a.output)
            .with_context(|| format!("creating output folder {}", a.output.display()))?;
    }

    // Steps: the reference, then per ratio capture + 2 models, then pictures.
    let steps = Bar::new("demo", 2 + 3 * RATIOS.len() as u64, "steps", a.quiet);
    let bar = steps.bar();
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let reference = pack_normalized(&clean, true)?;
    bar.inc(1);

    let protocol = Protocol::eld(false);
    // Tiles as `pgrf enhance` chooses them (memory, and the flow model's
    // cap at twice its training crop).
    let tiling = Tiling {
        tile: a.tile,
        overlap: None,
        seed: a.seed,
        device: DeviceKind::Cpu,
    };
    let mut captures = Vec::new();
    for (k, &ratio) in RATIOS.iter().enumerate() {
        bar.set_message(format!("x{ratio}: simulating the capture"));
        let dark_model = DarkCapture {
            profile: profile.clone(),
            model: ModelKind::Pgrf,
            iso: ISO,
            exposure_s: CLEAN_EXPOSURE_S / ratio as f64,
            ratio: ratio as f32,
            seed: a.seed.wrapping_mul(1_000_003).wrapping_add(k as u64 + 1),
        };
        let dark = dark_model.take(&clean)?;
        // The simulated camera is calibrated: its black-level error at the
        // ISO is known (bias frames), subtracted as `enhance --calib` does.
        let dark_dn = dark_model.dark_level_dn(&clean)?;
        let input = network_input(&dark, ratio as f32, Some(&dark_dn))?;
        let noisy = evaluate(input.view(), reference.view(), &protocol)?;
        bar.inc(1);
        let run = |r: &dyn Restore, name: &str| -> Result<(Scores, RawFrame)> {
            bar.set_message(format!("x{ratio}: {name}"));
            let out = restore_frame(r, &dark, ratio as f32, Some(&dark_dn), &tiling, &NoProgress)?;
            let s = evaluate(out.packed.output.view(), reference.view(), &protocol)?;
            bar.inc(1);
            Ok((s, out.frame))
        };
        let (spc_s, spc_f) = run(spc.as_ref(), "SPC")?;
        let (pgrf_s, pgrf_f) = run(pgrf.as_ref(), "PGRF")?;
        let calibrated = unpack_normalized(input.mapv(|v| v / ratio as f32).view(), &dark)?;
        captures.push(Capture {
            ratio,
            dark,
            calibrated,
            scores: [noisy, spc_s, pgrf_s],
            restored: [spc_f, pgrf_f],
        });
    }

    bar.set_message("writing DNGs and the picture");
    let dng = |f: &RawFrame, name: &str| -> Result<PathBuf> {
        let p = a.output.join(name);
        write_dng(f, &p, &DngOptions::default()).with_context(|| format!("{}", p.display()))?;
        Ok(p)
    };
    dng(&clean, "clean.dng")?;
    for c in &captures {
        dng(&c.dark, &format!("noisy_x{}.dng", c.ratio))?;
        dng(&c.restored[0], &format!("spc_x{}.dng", c.ratio))?;
        dng(&c.restored[1], &format!("pgrf_x{}.dng", c.ratio))?;
    }
    let picture = a.output.join("demo.png");
    write_picture(&picture, &clean, &captures, a.scene)?;
    bar.inc(1);
    bar.finish_and_clear();
    let seconds = t0.elapsed().as_secs_f64();

    print_report(
        a, &what, &*spc, &*pgrf, &captures, &protocol, &picture, seconds,
    );
    if a.json {
        let mut obj = serde_json::Map::new();
        for c in &captures {
            let s = |x: &Scores| json!({"psnr": x.psnr, "ssim": x.ssim});
            obj.insert(
                format!("x{}", c.ratio),
                json!({"noisy": s(&c.scores[0]), "spc": s(&c.scores[1]), "pgrf": s(&c.scores[2])}),
            );
        }
        obj.insert("seconds".into(), json!(seconds));
        println!("{}", serde_json::Value::Object(obj));
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn print_report(
    a: &DemoArgs,
    what: &str,
    spc: &dyn Restore,
    pgrf: &dyn Restore,
    captures: &[Capture],
    protocol: &Protocol,
    picture: &Path,
    seconds: f64,
) {
    const METHODS: [&str; 3] = ["noisy input", "SPC", "PGRF"];
    let mut rows = Vec::new();
    for c in captures {
        for (m, s) in METHODS.iter().zip(&c.scores) {
            rows.push(Row {
                protocol: s.protocol.clone(),
                id: "demo".into(),
                group: c.ratio,
                ratio: c.ratio as f32,
                noisy: format!("noisy_x{}.dng", c.ratio),
                reference: "clean.dng".into(),
                method: (*m).into(),
                psnr: s.psnr,
                ssim: s.ssim,
                gain: s.gain,
                iso: None,
                seed: None,
                cast: None,
            });
        }
    }
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
        "pgrf demo: {what}; dark captures x{} and x{} simulated with the Sony A7S2's noise \
(pgrf model, built-in profile) at ISO {ISO}, seed {}; the camera counts as calibrated: its black-level \
error at the ISO is subtracted before the denoisers and the noisy score, as `pgrf enhance --calib` does",
        RATIOS[0], RATIOS[1], a.seed
    ));
    let model_line = |name: &str, r: &dyn Restore, file: &Option<PathBuf>| {
        let src = file
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "built in".into());
        format!(
            "{name}: {} ({}), {src}",
            r.meta().arch.describe(),
            describe_sampler(r)
        )
    };
    out(&model_line("SPC ", spc, &a.spc));
    out(&model_line("PGRF", pgrf, &a.pgrf));
    out(&format!(
        "protocol: whole frame, packed 4-channel (RGGB), each file's black/white levels; {}",
        protocol.describe()
    ));
    out(&summarise(&rows).text());
    out(&format!(
        "wrote {} (rows: x{} and x{}, whole frame and 2x crop; columns: clean, noisy, SPC, PGRF) and 7 DNGs in {} ({seconds:.1} s)",
        picture.display(),
        RATIOS[0],
        RATIOS[1],
        a.output.display()
    ));
}

/// The crop shown at 2x, a quarter of the frame each way: on the photograph
/// the chart's middle patches and its printed lettering, on the procedural
/// scene the lower left corner of the chart and the leaves around it.
/// Returns `(row, col, h, w)` in preview pixels.
fn crop_box(width: usize, height: usize, scene: Scene) -> (usize, usize, usize, usize) {
    let (ch, cw) = (height / 4, width / 4);
    match scene {
        Scene::Photo => (height / 2, width * 11 / 20, ch, cw),
        Scene::Procedural => (height * 2 / 5, width / 2, ch, cw),
    }
}

fn crop_zoom(p: &Preview, (r0, c0, ch, cw): (usize, usize, usize, usize)) -> Preview {
    let mut rgb = Vec::with_capacity(4 * ch * cw * 3);
    for y in 0..2 * ch {
        for x in 0..2 * cw {
            let o = ((r0 + y / 2) * p.width + c0 + x / 2) * 3;
            rgb.extend_from_slice(&p.rgb[o..o + 3]);
        }
    }
    Preview {
        width: 2 * cw,
        height: 2 * ch,
        rgb,
        warnings: Vec::new(),
    }
}

/// Per ratio two rows, the whole frame at half size and a crop at twice
/// full size: clean, noisy (brightened by the ratio), SPC, PGRF.
fn write_picture(path: &Path, clean: &RawFrame, captures: &[Capture], scene: Scene) -> Result<()> {
    let half = PreviewOptions {
        half: true,
        ..PreviewOptions::default()
    };
    let full = PreviewOptions::default();
    let views = |f: &RawFrame, gain: f32| -> Result<(Preview, Preview)> {
        let whole = render_preview(
            f,
            &PreviewOptions {
                gain,
                ..half.clone()
            },
        )?;
        let detail = render_preview(
            f,
            &PreviewOptions {
                gain,
                ..full.clone()
            },
        )?;
        let b = crop_box(detail.width, detail.height, scene);
        Ok((whole, crop_zoom(&detail, b)))
    };
    let (clean_whole, clean_crop) = views(clean, 1.0)?;
    let mut rows = Vec::new();
    for c in captures {
        let caption = |name: &str, s: Option<&Scores>| match s {
            Some(s) => format!("x{} {name}: {:.2} dB, SSIM {:.3}", c.ratio, s.psnr, s.ssim),
            None => name.to_string(),
        };
        let (nw, nc) = views(&c.calibrated, c.ratio as f32)?;
        let (sw, sc) = views(&c.restored[0], 1.0)?;
        let (pw, pc) = views(&c.restored[1], 1.0)?;
        let panel = |caption: String, image: Preview| Panel { caption, image };
        rows.push(vec![
            panel(caption("clean reference", None), clean_whole.clone()),
            panel(caption("noisy", Some(&c.scores[0])), nw),
            panel(caption("SPC", Some(&c.scores[1])), sw),
            panel(caption("PGRF", Some(&c.scores[2])), pw),
        ]);
        rows.push(vec![
            panel("clean, 2x crop".into(), clean_crop.clone()),
            panel(format!("x{} noisy, 2x crop", c.ratio), nc),
            panel(format!("x{} SPC, 2x crop", c.ratio), sc),
            panel(format!("x{} PGRF, 2x crop", c.ratio), pc),
        ]);
    }
    write_montage(path, &rows).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

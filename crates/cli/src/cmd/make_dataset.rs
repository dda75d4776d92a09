//! `pgrf make-dataset`: a miniature benchmark folder in the exact ELD or SID
//! layout, made from procedural clean scenes and the A7S2 noise profile, so
//! that `pgrf eval` can be checked end to end without the real datasets.
//!
//! Files are DNGs (pgrf writes no ARW), named as the benchmark names them
//! with a `.dng` extension; the walkers of `pgrf eval` accept `.ARW` and
//! `.dng` alike. ISO and exposure time are written to each file's EXIF so
//! that the ELD walker's ratio (ISO x exposure of reference / noisy) and the
//! SID names' exposure times give the benchmark's ratios.

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use pgrf_eval::dataset::{eld, sid};
use pgrf_noise::capture::DarkCapture;
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::scene::{render_frame, SceneKind, SceneLevels, SceneSpec};
use pgrf_raw::{write_dng, Cfa, DngOptions, RawFrame};
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Layout {
    /// DIR/SonyA7S2/scene-K/IMG_0001.dng .. IMG_0016.dng (ELD's frame table).
    Eld,
    /// DIR/Sony/short, DIR/Sony/long and DIR/Sony_test_list.txt (SID's naming).
    Sid,
}

#[derive(Args, Debug)]
#[command(
    after_help = "ELD: every scene gets all 16 frames with the ISO and exposure of ELD's \
frame table (references 1, 6, 11, 16: the clean scene at ISO 100, 4 s; the others synthesised \
with the sony-a7s2 profile at their ISO, exposure and ratio). SID: scenes 10001.. get one long \
exposure (10 s, clean) and short exposures of 0.1 s, 0.04 s and 0.033 s (x100, x250, x300) at \
ISO 800, listed in Sony_test_list.txt.\n\nThen: pgrf eval --protocol eld --root DIR --scenes 1-N --model M"
)]
pub struct MakeDatasetArgs {
    /// Which benchmark's folder layout to write.
    #[arg(long)]
    pub layout: Layout,
    /// Output folder (created; must not hold files already).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Number of scenes (ELD's benchmark has 10).
    #[arg(long, default_value_t = 10)]
    pub scenes: u32,
    /// Frame size in pixels, WxH (even).
    #[arg(long, default_value = "256x256")]
    pub size: String,
    /// Seed of the scenes and the noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// `--size WxH` of a rendered frame: even sides of at least `min` pixels.
pub fn parse_size(s: &str, min: usize) -> Result<(usize, usize)> {
    let parsed = s.split_once(['x', 'X']).and_then(|(w, h)| {
        Some((
            w.trim().parse::<usize>().ok()?,
            h.trim().parse::<usize>().ok()?,
        ))
    });
    match parsed {
        Some((w, h)) if w >= min && h >= min && w.is_multiple_of(2) && h.is_multiple_of(2) => {
            Ok((w, h))
        }
        _ => bail!("--size {s}: expected WxH, even and at least {min}x{min}, e.g. 256x256"),
    }
}

/// The clean long exposure of scene `k`: a dead-leaves scene, dimmed so a
/// dark capture stays in range, with A7S2 metadata.
fn clean_scene(w: usize, h: usize, seed: u64, iso: u32, t: f64) -> Result<RawFrame> {
    let mut f = render_frame(
        &SceneSpec::new(SceneKind::DeadLeaves, w, h, seed),
        Cfa::Rggb,
        &SceneLevels::default(),
    )?;
    f.make = "Sony".into();
    f.model = "ILCE-7SM2".into();
    f.wb = Some([2.4, 1.0, 1.7]);
    f.iso = Some(iso);
    f.exposure_s = Some(t);
    Ok(f)
}

/// A capture of `clean` `ratio` times darker at `iso`, `t` seconds, written
/// un-amplified (as a camera would record it).
fn dark_capture(
    clean: &RawFrame,
    iso: u32,
    t: f64,
    ratio: f32,
    seed: u64,
    path: &Path,
) -> Result<()> {
    let out = DarkCapture {
        profile: CameraProfile::built_in("sony-a7s2").context("no sony-a7s2 profile")?,
        model: ModelKind::Pgrf,
        iso,
        exposure_s: t,
        ratio,
        seed,
    }
    .take(clean)?;
    write_dng(&out, path, &DngOptions::default())?;
    Ok(())
}

fn write_ref(clean: &RawFrame, path: &Path) -> Result<()> {
    write_dng(clean, path, &DngOptions::default())?;
    Ok(())
}

pub fn run(a: &MakeDatasetArgs) -> Result<()> {
    let (w, h) = parse_size(&a.size, 32)?;
    if a.scenes == 0 {
        bail!("--scenes must be at least 1");
    }
    if a.output.is_dir()
        && std::fs::read_dir(&a.output)
            .map(|mut d| d.next().is_some())
            .unwrap_or(false)
    {
        bail!(
            "-o {}: folder is not empty; give a new folder",
            a.output.display()
        );
    }
    std::fs::create_dir_all(&a.output).with_context(|| format!("-o {}", a.output.display()))?;
    let mut files = 0usize;
    match a.layout {
        Layout::Eld => {
            for k in 1..=a.scenes {
                let dir = a.output.join(eld::CAMERA).join(format!("scene-{k}"));
                std::fs::create_dir_all(&dir)?;
                let (ri, rt) = eld::FRAME_TABLE[0];
                let clean = clean_scene(w, h, a.seed.wrapping_mul(1000) + k as u64, ri, rt)?;
                for f in 1..=16u32 {
                    let path = dir.join(format!("IMG_{f:04}.dng"));
                    let (iso, t) = eld::FRAME_TABLE[f as usize - 1];
                    if eld::REFERENCES.contains(&f) {
                        write_ref(&clean, &path)?;
                    } else {
                        let (gi, gt) = eld::FRAME_TABLE[eld::reference_for(f) as usize - 1];
                        let ratio = (gi as f64 * gt / (iso as f64 * t)) as f32;
                        let seed = a.seed.wrapping_mul(1_000_003) + (k * 100 + f) as u64;
                        dark_capture(&clean, iso, t, ratio, seed, &path)
                            .with_context(|| format!("{}", path.display()))?;
                    }
                    files += 1;
                }
            }
            eprintln!(
                "wrote {files} DNGs in the ELD layout under {} (scenes 1-{})",
                a.output.join(eld::CAMERA).display(),
                a.scenes
            );
            eprintln!(
                "evaluate: pgrf eval --protocol eld --root {} --scenes 1-{} --model MODEL",
                a.output.display(),
                a.scenes
            );
        }
        Layout::Sid => {
            let short_dir = a.output.join("Sony").join("short");
            let long_dir = a.output.join("Sony").join("long");
            std::fs::create_dir_all(&short_dir)?;
            std::fs::create_dir_all(&long_dir)?;
            let iso = 800;
            let mut list = String::new();
            let mut id = 10000u32;
            for k in 1..=a.scenes {
                id += 1;
                while sid::MISALIGNED.contains(&id.to_string().as_str()) {
                    id += 1;
                }
                let long_name = format!("{id}_00_10s.dng");
                let clean = clean_scene(w, h, a.seed.wrapping_mul(1000) + k as u64, iso, 10.0)?;
                write_ref(&clean, &long_dir.join(&long_name))?;
                files += 1;
                for (n, (label, t)) in [("0.1", 0.1), ("0.04", 0.04), ("0.033", 0.033)]
                    .into_iter()
                    .enumerate()
                {
                    let short_name = format!("{id}_00_{label}s.dng");
                    let path = short_dir.join(&short_name);
                    let ratio = (10.0 / t) as f32;
                    let seed = a.seed.wrapping_mul(1_000_003) + (k as u64) * 10 + n as u64;
                    dark_capture(&clean, iso, t, ratio, seed, &path)
                        .with_context(|| format!("{}", path.display()))?;
                    files += 1;
                    list.push_str(&format!(
                        "./Sony/short/{short_name} ./Sony/long/{long_name} ISO{iso} F8\n"
                    ));
                }
            }
            let list_path = a.output.join(sid::DEFAULT_LIST);
            pgrf_core::write_atomic(&list_path, list.as_bytes())
                .with_context(|| format!("{}", list_path.display()))?;
            eprintln!(
                "wrote {files} DNGs in the SID layout under {} and {}",
                a.output.join("Sony").display(),
                list_path.display()
            );
            eprintln!(
                "evaluate: pgrf eval --protocol sid --root {} --model MODEL",
                a.output.display()
            );
        }
    }
    Ok(())
}

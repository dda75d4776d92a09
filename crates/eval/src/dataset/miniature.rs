//! Miniature benchmark folders in the exact ELD or SID layout, made from
//! procedural clean scenes and the A7S2 noise profile, so that an
//! evaluation can be checked end to end without the real datasets.
//!
//! Files are DNGs (pgrf writes no ARW), named as the benchmark names them
//! with a `.dng` extension; the walkers accept `.ARW` and `.dng` alike. ISO
//! and exposure time are written to each file's EXIF so that the ELD
//! walker's ratio (ISO x exposure of reference / noisy) and the SID names'
//! exposure times give the benchmark's ratios.

use super::{eld, sid, DatasetError, Result};
use pgrf_core::parse::ParseError;
use pgrf_noise::capture::DarkCapture;
use pgrf_noise::{CameraProfile, ModelKind};
use pgrf_raw::{write_dng, Cfa, DngOptions, RawFrame};
use pgrf_scenes::scene::{render_frame, SceneKind, SceneLevels, SceneSpec};
use std::path::{Path, PathBuf};

/// Which benchmark's layout to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// ELD's Sony A7S2 scenes: 16 frames each, references 1, 6, 11, 16.
    Eld,
    /// SID's Sony set: one long exposure and three short ones per scene.
    Sid,
}

impl std::str::FromStr for Layout {
    type Err = ParseError;
    fn from_str(s: &str) -> std::result::Result<Layout, ParseError> {
        match s.to_ascii_lowercase().as_str() {
            "eld" => Ok(Layout::Eld),
            "sid" => Ok(Layout::Sid),
            o => Err(ParseError::unknown_name(
                s,
                format!("unknown layout '{o}' (eld or sid)"),
            )),
        }
    }
}

/// What to write.
#[derive(Clone, Debug)]
pub struct Miniature {
    /// The layout.
    pub layout: Layout,
    /// Number of scenes (at least 1).
    pub scenes: u32,
    /// Mosaic width and height of every frame (even).
    pub width: usize,
    /// See `width`.
    pub height: usize,
    /// Seed of the scenes and the noise.
    pub seed: u64,
}

/// What was written: the number of DNGs, the folder of the frames and, for
/// SID, the list file.
pub struct Written {
    /// DNG files written.
    pub files: usize,
    /// The folder holding the frames (ELD: ROOT/SonyA7S2, SID: ROOT/Sony).
    pub frames: PathBuf,
    /// SID's `Sony_test_list.txt` (None for ELD).
    pub list: Option<PathBuf>,
}

fn err(e: impl std::fmt::Display) -> DatasetError {
    DatasetError(e.to_string())
}

fn clean_scene(w: usize, h: usize, seed: u64, iso: u32, t: f64) -> Result<RawFrame> {
    let mut f = render_frame(
        &SceneSpec::new(SceneKind::DeadLeaves, w, h, seed),
        Cfa::Rggb,
        &SceneLevels::default(),
    )
    .map_err(err)?;
    f.make = "Sony".into();
    f.model = "ILCE-7SM2".into();
    f.wb = Some([2.4, 1.0, 1.7]);
    f.iso = Some(iso);
    f.exposure_s = Some(t);
    Ok(f)
}

fn dark_capture(
    clean: &RawFrame,
    iso: u32,
    t: f64,
    ratio: f32,
    seed: u64,
    path: &Path,
) -> Result<()> {
    let profile =
        CameraProfile::built_in("sony-a7s2").ok_or_else(|| err("no sony-a7s2 profile"))?;
    let out = DarkCapture {
        profile,
        model: ModelKind::Pgrf,
        iso,
        exposure_s: t,
        ratio,
        seed,
    }
    .take(clean)
    .map_err(|e| err(format!("{}: {e}", path.display())))?;
    write_dng(&out, path, &DngOptions::default()).map_err(err)
}

fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| err(format!("{}: {e}", dir.display())))
}

/// Bytes per mosaic pixel of the DNGs written, rounded up from a measurement
/// (512 x 512 frames: ELD 1.14, SID 0.91 bytes per pixel, LJPEG-92 of
/// noisy 14-bit data), and bytes of metadata per file.
const BYTES_PER_PIXEL: f64 = 1.2;
const BYTES_PER_FILE: f64 = 4096.0;

/// Refuse a benchmark the disk under `root` cannot hold (files and bytes),
/// before any work: `--scenes 1000000000` would otherwise run until the
/// disk is full. Each scene is written and dropped before the next, so
/// memory holds one scene whatever the count.
fn check_room(root: &Path, m: &Miniature) -> Result<()> {
    let per_scene: u64 = match m.layout {
        Layout::Eld => 16,
        Layout::Sid => 4,
    };
    let frames = u64::from(m.scenes) * per_scene;
    let bytes =
        frames as f64 * (m.width as f64 * m.height as f64 * BYTES_PER_PIXEL + BYTES_PER_FILE);
    // Scene folders (ELD) count as files too.
    let files = frames + u64::from(m.scenes);
    pgrf_core::disk::check_room(
        &format!(
            "--scenes {} of {}x{} frames ({} per scene)",
            m.scenes, m.width, m.height, per_scene
        ),
        bytes,
        files,
        root,
    )
    .map_err(|e| err(format!("{e}; give fewer --scenes or a smaller --size")))
}

/// Write the miniature benchmark under `root` (which must be empty or new).
pub fn write(root: &Path, m: &Miniature) -> Result<Written> {
    if m.scenes == 0 {
        return Err(err("--scenes must be at least 1"));
    }
    if root.is_dir()
        && std::fs::read_dir(root)
            .map(|mut d| d.next().is_some())
            .unwrap_or(false)
    {
        return Err(err(format!(
            "-o {}: folder is not empty; give a new folder",
            root.display()
        )));
    }
    check_room(root, m)?;
    create_dir(root)?;
    match m.layout {
        Layout::Eld => write_eld(root, m),
        Layout::Sid => write_sid(root, m),
    }
}

/// The ELD layout: per scene, 16 frames of the ELD table (the references
/// clean, the others dark captures of them).
fn write_eld(root: &Path, m: &Miniature) -> Result<Written> {
    let (w, h) = (m.width, m.height);
    let mut files = 0usize;
    for k in 1..=m.scenes {
        let dir = root.join(eld::CAMERA).join(format!("scene-{k}"));
        create_dir(&dir)?;
        let (ri, rt) = eld::FRAME_TABLE[0];
        let clean = clean_scene(w, h, m.seed.wrapping_mul(1000) + k as u64, ri, rt)?;
        for f in 1..=16u32 {
            let path = dir.join(format!("IMG_{f:04}.dng"));
            let (iso, t) = eld::FRAME_TABLE[f as usize - 1];
            if eld::REFERENCES.contains(&f) {
                write_dng(&clean, &path, &DngOptions::default()).map_err(err)?;
            } else {
                let (gi, gt) = eld::FRAME_TABLE[eld::reference_for(f) as usize - 1];
                let ratio = (gi as f64 * gt / (iso as f64 * t)) as f32;
                let seed = m.seed.wrapping_mul(1_000_003) + (k * 100 + f) as u64;
                dark_capture(&clean, iso, t, ratio, seed, &path)?;
            }
            files += 1;
        }
    }
    Ok(Written {
        files,
        frames: root.join(eld::CAMERA),
        list: None,
    })
}

/// The SID layout: per scene, a 10 s long exposure and three short ones,
/// and the list file that pairs them.
fn write_sid(root: &Path, m: &Miniature) -> Result<Written> {
    let (w, h) = (m.width, m.height);
    let mut files = 0usize;
    let short_dir = root.join("Sony").join("short");
    let long_dir = root.join("Sony").join("long");
    create_dir(&short_dir)?;
    create_dir(&long_dir)?;
    let iso = 800;
    let mut list = String::new();
    let mut id = 10000u32;
    for k in 1..=m.scenes {
        id += 1;
        while sid::MISALIGNED.contains(&id.to_string().as_str()) {
            id += 1;
        }
        let long_name = format!("{id}_00_10s.dng");
        let clean = clean_scene(w, h, m.seed.wrapping_mul(1000) + k as u64, iso, 10.0)?;
        write_dng(&clean, &long_dir.join(&long_name), &DngOptions::default()).map_err(err)?;
        files += 1;
        for (n, (label, t)) in [("0.1", 0.1), ("0.04", 0.04), ("0.033", 0.033)]
            .into_iter()
            .enumerate()
        {
            let short_name = format!("{id}_00_{label}s.dng");
            let path = short_dir.join(&short_name);
            let ratio = (10.0 / t) as f32;
            let seed = m.seed.wrapping_mul(1_000_003) + (k as u64) * 10 + n as u64;
            dark_capture(&clean, iso, t, ratio, seed, &path)?;
            files += 1;
            list.push_str(&format!(
                "./Sony/short/{short_name} ./Sony/long/{long_name} ISO{iso} F8\n"
            ));
        }
    }
    let list_path = root.join(sid::DEFAULT_LIST);
    pgrf_core::write_atomic(&list_path, list.as_bytes()).map_err(err)?;
    Ok(Written {
        files,
        frames: root.join("Sony"),
        list: Some(list_path),
    })
}

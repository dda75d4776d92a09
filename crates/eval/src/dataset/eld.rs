//! The ELD Sony A7S2 benchmark (Wei et al., "A Physics-based Noise Formation
//! Model for Extreme Low-light Raw Denoising"), walked as ELD's own
//! `ELDEvalDataset` and `test_ELD.py` do:
//!
//! - folders `ROOT/SonyA7S2/scene-1 .. scene-10` (or `ROOT/scene-K` when ROOT
//!   is the camera folder), frames `IMG_0001.ARW .. IMG_0016.ARW`;
//! - x100 = frames 4, 9, 14; x200 = frames 5, 10, 15 (ISO 800, 1600, 3200);
//! - references are frames 1, 6, 11, 16 (ISO 100, long exposure); each noisy
//!   frame is paired with the *nearest* reference by frame number
//!   (`argmin |id - [1, 6, 11, 16]|`): 4, 5 -> 6; 9, 10 -> 11; 14, 15 -> 16;
//! - ratio = (ISO x exposure time of the reference) / (ISO x exposure time of
//!   the noisy frame), from the files' EXIF (e.g. 100 x 4 s / (800 x 0.005 s)
//!   = 100);
//! - input x ratio clamped to [0, 1] (pgrf: clipped at 1, values below black
//!   kept for the networks that read them, clamped by the others), reference
//!   clamped (both normalised
//!   with white 16383 as ELD's `pack_raw_bayer`);
//! - measured on full images (`crop=False`) with ELD's illuminance correction
//!   (`correct=True`), as `test_ELD.py` calls `engine.eval`.
//!
//! `ELD_SonyA7S2_frames.json` in the project's shared data lists every
//! frame's ISO and exposure. A frame may be stored as `.ARW` (as published)
//! or `.dng` (what `pgrf make-dataset --layout eld` writes).

use super::{err, existing, with_alternatives, DatasetKind, RatioRule, Result, Sample};
use pgrf_core::parse::ParseError;
use std::path::{Path, PathBuf};

/// Camera folder name in the ELD release.
pub const CAMERA: &str = "SonyA7S2";
/// Frames evaluated at x100.
pub const X100: [u32; 3] = [4, 9, 14];
/// Frames evaluated at x200.
pub const X200: [u32; 3] = [5, 10, 15];
/// Long-exposure reference frames.
pub const REFERENCES: [u32; 4] = [1, 6, 11, 16];

/// The ISO and exposure time of each frame 1..=16 in the ELD table (scene 1;
/// other scenes scale all exposures alike, so ratios are the same). Used by
/// `pgrf make-dataset` to write EXIF that gives the walker ELD's ratios.
pub const FRAME_TABLE: [(u32, f64); 16] = [
    (100, 4.0),
    (800, 0.5),
    (800, 0.05),
    (800, 0.005),
    (800, 0.0025),
    (100, 4.0),
    (1600, 0.25),
    (1600, 0.025),
    (1600, 0.0025),
    (1600, 0.00125),
    (100, 4.0),
    (3200, 0.125),
    (3200, 0.0125),
    (3200, 0.00125),
    (3200, 0.000625),
    (100, 4.0),
];

/// ELD's reference for a noisy frame: the nearest of [`REFERENCES`] (the
/// first on a tie, as numpy's argmin).
pub fn reference_for(frame: u32) -> u32 {
    let mut best = REFERENCES[0];
    for r in REFERENCES {
        if r.abs_diff(frame) < best.abs_diff(frame) {
            best = r;
        }
    }
    best
}

/// The frame file name ELD builds (`IMG_{:04d}.ARW`).
pub(crate) fn frame_name(frame: u32) -> String {
    format!("IMG_{frame:04}.ARW")
}

/// The folder holding `scene-K`: ROOT/SonyA7S2 when it exists, else ROOT.
pub(crate) fn camera_dir(root: &Path) -> Result<PathBuf> {
    if !root.is_dir() {
        return err(format!("--root {}: no such folder", root.display()));
    }
    let cam = root.join(CAMERA);
    Ok(if cam.is_dir() {
        cam
    } else {
        root.to_path_buf()
    })
}

/// Every pair of the benchmark for `scenes` (x100 frames of all scenes,
/// then x200), checking that each file exists.
pub fn walk(root: &Path, scenes: &[u32]) -> Result<Vec<Sample>> {
    let dir = camera_dir(root)?;
    if scenes.is_empty() {
        return err("no ELD scenes selected");
    }
    let mut out = Vec::new();
    for (group, frames) in [(100, X100), (200, X200)] {
        for &scene in scenes {
            let sdir = dir.join(format!("scene-{scene}"));
            if !sdir.is_dir() {
                return err(format!(
                    "missing ELD scene folder {} (expected scene-1..scene-10 under {})",
                    sdir.display(),
                    dir.display()
                ));
            }
            for f in frames {
                let r = reference_for(f);
                let noisy = existing(
                    &with_alternatives(&sdir.join(frame_name(f))),
                    &format!("ELD frame (x{group} input)"),
                )?;
                let reference = existing(
                    &with_alternatives(&sdir.join(frame_name(r))),
                    "ELD reference frame",
                )?;
                out.push(Sample {
                    kind: DatasetKind::Eld,
                    id: format!("scene-{scene}/IMG_{f:04}"),
                    group,
                    ratio: RatioRule::IsoExposure,
                    noisy,
                    reference,
                });
            }
        }
    }
    Ok(out)
}

/// Parse a scene list: "1-10", "1,3,5", "2".
pub fn parse_scenes(s: &str) -> std::result::Result<Vec<u32>, ParseError> {
    let mut v = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let bad = || {
            ParseError::malformed(
                s,
                format!("bad scene list {s:?}: expected e.g. 1-10 or 1,2,5"),
            )
        };
        if let Some((a, b)) = part.split_once('-') {
            let a: u32 = a.trim().parse().map_err(|_| bad())?;
            let b: u32 = b.trim().parse().map_err(|_| bad())?;
            if a == 0 || b < a {
                return Err(bad());
            }
            v.extend(a..=b);
        } else {
            let a: u32 = part.parse().map_err(|_| bad())?;
            if a == 0 {
                return Err(bad());
            }
            v.push(a);
        }
    }
    if v.is_empty() {
        return Err(ParseError::malformed(s, format!("empty scene list {s:?}")));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str, scenes: u32, ext: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pgrf-eld-walk-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        for s in 1..=scenes {
            let sd = d.join(CAMERA).join(format!("scene-{s}"));
            std::fs::create_dir_all(&sd).unwrap();
            for f in 1..=16 {
                std::fs::write(sd.join(format!("IMG_{f:04}.{ext}")), b"x").unwrap();
            }
        }
        d
    }

    #[test]
    fn nearest_reference_as_eld() {
        let pairs: Vec<(u32, u32)> = X100
            .iter()
            .chain(&X200)
            .map(|&f| (f, reference_for(f)))
            .collect();
        assert_eq!(
            pairs,
            vec![(4, 6), (9, 11), (14, 16), (5, 6), (10, 11), (15, 16)]
        );
    }

    #[test]
    fn ratios_of_the_table_are_100_and_200() {
        for f in X100.iter().chain(&X200) {
            let (i, t) = FRAME_TABLE[*f as usize - 1];
            let (ri, rt) = FRAME_TABLE[reference_for(*f) as usize - 1];
            let r = (ri as f64 * rt / (i as f64 * t)).round();
            assert_eq!(r, if X100.contains(f) { 100.0 } else { 200.0 }, "frame {f}");
        }
    }

    #[test]
    fn walker_picks_exactly_the_listed_frames() {
        for ext in ["ARW", "dng"] {
            let d = folder(ext, 2, ext);
            let v = walk(&d, &[1, 2]).unwrap();
            let got: Vec<(u32, String, String)> = v
                .iter()
                .map(|s| {
                    let n = |p: &PathBuf| {
                        let sc = p
                            .parent()
                            .unwrap()
                            .file_name()
                            .unwrap()
                            .to_string_lossy()
                            .into_owned();
                        format!("{sc}/{}", p.file_stem().unwrap().to_string_lossy())
                    };
                    (s.group, n(&s.noisy), n(&s.reference))
                })
                .collect();
            let mut want = Vec::new();
            for (g, frames) in [(100, X100), (200, X200)] {
                for sc in 1..=2 {
                    for f in frames {
                        want.push((
                            g,
                            format!("scene-{sc}/IMG_{f:04}"),
                            format!("scene-{sc}/IMG_{:04}", reference_for(f)),
                        ));
                    }
                }
            }
            assert_eq!(got, want);
            assert!(v.iter().all(|s| s.ratio == RatioRule::IsoExposure));
            assert!(v.iter().all(|s| s.noisy.extension().unwrap() == ext));
            // The camera folder itself works as the root too.
            assert_eq!(walk(&d.join(CAMERA), &[1, 2]).unwrap(), v);
            std::fs::remove_dir_all(&d).unwrap();
        }
    }

    #[test]
    fn a_missing_frame_is_named() {
        let d = folder("missing", 2, "ARW");
        let gone = d.join(CAMERA).join("scene-2").join("IMG_0010.ARW");
        std::fs::remove_file(&gone).unwrap();
        let e = walk(&d, &[1, 2]).unwrap_err().to_string();
        assert!(e.contains(&gone.display().to_string()), "{e}");
        assert!(!e.contains('\n'));
        let gone = d.join(CAMERA).join("scene-1").join("IMG_0011.ARW");
        std::fs::remove_file(&gone).unwrap();
        let e = walk(&d, &[1]).unwrap_err().to_string();
        assert!(
            e.contains("reference") && e.contains(&gone.display().to_string()),
            "{e}"
        );
        let e = walk(&d, &[3]).unwrap_err().to_string();
        assert!(e.contains("scene-3"), "{e}");
        let e = walk(&d.join("nope"), &[1]).unwrap_err().to_string();
        assert!(e.contains("no such folder"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn scene_lists() {
        assert_eq!(parse_scenes("1-3").unwrap(), vec![1, 2, 3]);
        assert_eq!(parse_scenes("2,5").unwrap(), vec![2, 5]);
        assert!(parse_scenes("0").is_err());
        assert!(parse_scenes("3-1").is_err());
    }
}

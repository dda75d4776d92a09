//! The SID Sony test set ("Learning to See in the Dark"), walked as ELD
//! evaluates it (`test_SID.py` with `SIDDataset`):
//!
//! - pairs come from a list file: SID's own format
//!   (`./Sony/short/10003_00_0.1s.ARW ./Sony/long/10003_00_10s.ARW ISO200 F9`,
//!   paths relative to ROOT) or ELD/PMN's paired format
//!   (`10003_00_0.1s.ARW 10003_00_10s.ARW 100`, names under ROOT/Sony/short
//!   and ROOT/Sony/long, third column the table row); ELD's own `test_SID.py`
//!   evaluates `SID_Sony_15_paired.txt` (15 indoor scenes) in this format;
//! - the amplification is `min(long / short, 300)` with both exposure times
//!   read from the file names (ELD's `compute_expo_ratio`);
//! - the table row of SID's list format is `min(int(long / short), 300)`
//!   (`test_SID.py`): 100 (0.1 s), 250 (0.04 s), 300 (0.033 s and 30 s/0.1 s);
//! - scenes 10034, 10045 and 10172 are left out by default: SID's authors
//!   found their references misaligned (SID README, Aug 2018);
//! - input and reference cropped to the centre 512x512 of the packed planes
//!   *before* the network runs (ELD's `eval(crop=True)`: "fixed pattern noise
//!   appeared at the bottom corner of some pictures")
//!   with the illuminance correction (`correct=True`).

use super::{err, existing, with_alternatives, DatasetKind, RatioRule, Result, Sample};
use std::path::{Path, PathBuf};

/// SID test scenes whose long exposure is misaligned with the short ones.
pub const MISALIGNED: [&str; 3] = ["10034", "10045", "10172"];
/// List file looked for in ROOT when none is given.
pub const DEFAULT_LIST: &str = "Sony_test_list.txt";
/// Cap on the ratio (ELD's `min(..., 300)`).
pub(crate) const MAX_RATIO: f64 = 300.0;

/// Exposure time in seconds from a SID file name (`10003_00_0.1s.ARW`).
pub(crate) fn exposure_from_name(name: &str) -> Option<f64> {
    let stem = Path::new(name).file_stem()?.to_str()?;
    let last = stem.rsplit('_').next()?;
    let t: f64 = last.strip_suffix('s')?.parse().ok()?;
    (t > 0.0).then_some(t)
}

/// The folder that holds `Sony/`: ROOT, or ROOT's parent when ROOT is the
/// `Sony` folder itself.
fn base_dir(root: &Path) -> Result<PathBuf> {
    if !root.is_dir() {
        return err(format!("--root {}: no such folder", root.display()));
    }
    if !root.join("Sony").is_dir() && root.join("short").is_dir() {
        if let Some(p) = root.parent() {
            return Ok(p.to_path_buf());
        }
    }
    Ok(root.to_path_buf())
}

/// The list to read: `list`, else `base`/Sony_test_list.txt, which must
/// exist.
fn list_file(base: &Path, list: Option<&Path>) -> Result<PathBuf> {
    match list {
        Some(l) => Ok(l.to_path_buf()),
        None => {
            let p = base.join(DEFAULT_LIST);
            if !p.is_file() {
                return err(format!(
                    "no SID list: {} not found (give --list Sony_test_list.txt or a paired list)",
                    p.display()
                ));
            }
            Ok(p)
        }
    }
}

/// A list line's short and long files: relative to `base` when the line
/// names paths (ELD's paired lists), else in SID's Sony/short and
/// Sony/long.
fn pair_paths(base: &Path, short: &str, long: &str) -> (PathBuf, PathBuf) {
    if short.contains('/') {
        (
            base.join(short.trim_start_matches("./")),
            base.join(long.trim_start_matches("./")),
        )
    } else {
        (
            base.join("Sony").join("short").join(short),
            base.join("Sony").join("long").join(long),
        )
    }
}

/// The path's last component, lossily as text.
fn file_name(p: &Path) -> String {
    p.file_name()
        .unwrap_or_default()
        .to_string_lossy()
        .into_owned()
}

/// The pairs of `list` (default ROOT/Sony_test_list.txt), misaligned scenes
/// dropped unless `keep_misaligned`, each file checked to exist.
pub fn walk(root: &Path, list: Option<&Path>, keep_misaligned: bool) -> Result<Vec<Sample>> {
    let base = base_dir(root)?;
    let list_path = list_file(&base, list)?;
    let text = std::fs::read_to_string(&list_path)
        .map_err(|e| super::DatasetError(format!("{}: {e}", list_path.display())))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let bad = |why: &str| {
            err::<()>(format!(
                "{} line {}: {why}: {line:?}",
                list_path.display(),
                n + 1
            ))
        };
        if f.len() < 2 {
            bad("expected a short and a long file")?;
        }
        let (short, long) = pair_paths(&base, f[0], f[1]);
        let (sn, ln) = (file_name(&short), file_name(&long));
        let (Some(ts), Some(tl)) = (exposure_from_name(&sn), exposure_from_name(&ln)) else {
            bad("no exposure time in the file names (expected e.g. 10003_00_0.1s.ARW)")?;
            unreachable!()
        };
        let scene: String = sn.chars().take(5).collect();
        if !keep_misaligned && MISALIGNED.contains(&scene.as_str()) {
            continue;
        }
        let ratio = (tl / ts).min(MAX_RATIO);
        // ELD groups a paired list by its third column, SID's list by
        // `min(int(long / short), 300)`.
        let group = match f.get(2).and_then(|g| g.parse::<u32>().ok()) {
            Some(g) if !f[0].contains('/') => g,
            _ => ((tl / ts) + 1e-9).floor().min(MAX_RATIO) as u32,
        };
        let noisy = existing(&with_alternatives(&short), "SID short exposure")?;
        let reference = existing(&with_alternatives(&long), "SID long exposure")?;
        out.push(Sample {
            kind: DatasetKind::Sid,
            id: Path::new(&sn)
                .file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned(),
            group,
            ratio: RatioRule::Fixed(ratio as f32),
            noisy,
            reference,
        });
    }
    if out.is_empty() {
        return err(format!("{}: no pairs to evaluate", list_path.display()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pgrf-sid-walk-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("Sony/short")).unwrap();
        std::fs::create_dir_all(d.join("Sony/long")).unwrap();
        for n in [
            "short/10003_00_0.1s.ARW",
            "short/10003_00_0.04s.ARW",
            "short/10003_00_0.033s.ARW",
            "long/10003_00_10s.ARW",
            "short/10034_00_0.1s.ARW",
            "long/10034_00_10s.ARW",
            "short/10040_00_0.1s.dng",
            "long/10040_00_30s.dng",
        ] {
            std::fs::write(d.join("Sony").join(n), b"x").unwrap();
        }
        std::fs::write(
            d.join(DEFAULT_LIST),
            "./Sony/short/10003_00_0.04s.ARW ./Sony/long/10003_00_10s.ARW ISO200 F9\n\
             ./Sony/short/10003_00_0.1s.ARW ./Sony/long/10003_00_10s.ARW ISO200 F9\n\
             ./Sony/short/10003_00_0.033s.ARW ./Sony/long/10003_00_10s.ARW ISO200 F9\n\
             ./Sony/short/10034_00_0.1s.ARW ./Sony/long/10034_00_10s.ARW ISO200 F9\n\
             ./Sony/short/10040_00_0.1s.ARW ./Sony/long/10040_00_30s.ARW ISO200 F9\n",
        )
        .unwrap();
        d
    }

    #[test]
    fn ratios_groups_and_exclusions() {
        let d = folder("list");
        let v = walk(&d, None, false).unwrap();
        let got: Vec<(String, u32)> = v.iter().map(|s| (s.id.clone(), s.group)).collect();
        assert_eq!(
            got,
            vec![
                ("10003_00_0.04s".into(), 250),
                ("10003_00_0.1s".into(), 100),
                ("10003_00_0.033s".into(), 300),
                ("10040_00_0.1s".into(), 300),
            ]
        );
        assert_eq!(v[2].ratio, RatioRule::Fixed(300.0));
        assert_eq!(v[1].ratio, RatioRule::Fixed(100.0));
        // Listed as .ARW, found as .dng.
        assert_eq!(v[3].noisy.extension().unwrap(), "dng");
        let all = walk(&d.join("Sony"), None, true).unwrap();
        assert_eq!(all.len(), 5);
        assert!(all.iter().any(|s| s.id.starts_with("10034")));
        // The paired format.
        let p = d.join("paired.txt");
        std::fs::write(&p, "10003_00_0.1s.ARW 10003_00_10s.ARW 100\n").unwrap();
        let v = walk(&d, Some(&p), false).unwrap();
        assert_eq!((v.len(), v[0].group), (1, 100));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn missing_files_and_empty_lists_are_named() {
        let d = folder("missing");
        let gone = d.join("Sony/long/10003_00_10s.ARW");
        std::fs::remove_file(&gone).unwrap();
        let e = walk(&d, None, false).unwrap_err().to_string();
        assert!(e.contains(&gone.display().to_string()), "{e}");
        let p = d.join("empty.txt");
        std::fs::write(&p, "\n").unwrap();
        let e = walk(&d, Some(&p), false).unwrap_err().to_string();
        assert!(e.contains("no pairs"), "{e}");
        std::fs::remove_file(d.join(DEFAULT_LIST)).unwrap();
        let e = walk(&d, None, false).unwrap_err().to_string();
        assert!(e.contains(DEFAULT_LIST), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    #[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
    fn the_shared_test_list_has_three_ratios() {
        let list = pgrf_core::shared_data_dir()
            .expect("../shared/data")
            .join("protocols/Sony_test_list.txt");
        let text = std::fs::read_to_string(&list).unwrap();
        let mut groups = std::collections::BTreeMap::new();
        for l in text.lines().filter(|l| !l.trim().is_empty()) {
            let f: Vec<&str> = l.split_whitespace().collect();
            let (s, lo) = (
                exposure_from_name(f[0]).unwrap(),
                exposure_from_name(f[1]).unwrap(),
            );
            *groups
                .entry(((lo / s) + 1e-9).floor().min(MAX_RATIO) as u32)
                .or_insert(0) += 1;
        }
        assert_eq!(
            groups.keys().copied().collect::<Vec<_>>(),
            vec![100, 250, 300]
        );
    }
}

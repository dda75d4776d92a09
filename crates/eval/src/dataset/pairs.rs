//! A user's own paired data (e.g. the PGRF paper's LLID): a CSV of
//! `noisy,reference,ratio`, one pair per line, an optional header line
//! starting with `noisy`, paths relative to the CSV's folder. An empty ratio
//! or `auto` takes (ISO x exposure) of the reference over that of the noisy
//! file, as ELD does. Rows are grouped by the ratio rounded to an integer.
//! No crop and no illuminance correction unless asked.

use super::{err, existing, DatasetKind, RatioRule, Result, Sample};
use std::path::{Path, PathBuf};

/// CSV looked for when `--root` is a folder.
pub(crate) const DEFAULT_CSV: &str = "pairs.csv";

/// The samples of the CSV `root` (or `root/pairs.csv` when `root` is a
/// folder), in file order; every file it names must exist.
pub fn walk(root: &Path) -> Result<Vec<Sample>> {
    let csv = if root.is_dir() {
        root.join(DEFAULT_CSV)
    } else {
        root.to_path_buf()
    };
    if !csv.is_file() {
        return err(format!("pair list {} not found", csv.display()));
    }
    let base = csv
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let text = std::fs::read_to_string(&csv)
        .map_err(|e| super::DatasetError(format!("{}: {e}", csv.display())))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if n == 0 && f[0].eq_ignore_ascii_case("noisy") {
            continue;
        }
        let at = || format!("{} line {}", csv.display(), n + 1);
        if f.len() < 2 || f[0].is_empty() || f[1].is_empty() {
            return err(format!(
                "{}: expected noisy,reference[,ratio], got {line:?}",
                at()
            ));
        }
        let ratio = match f.get(2).copied().unwrap_or("") {
            "" | "auto" => RatioRule::IsoExposure,
            r => match r.parse::<f32>() {
                Ok(v) if v.is_finite() && v > 0.0 => RatioRule::Fixed(v),
                _ => return err(format!("{}: ratio {r:?} is not a positive number", at())),
            },
        };
        let group = match ratio {
            RatioRule::Fixed(v) => v.round() as u32,
            RatioRule::IsoExposure => 0,
        };
        let noisy = existing(&[base.join(f[0])], "noisy file")?;
        let reference = existing(&[base.join(f[1])], "reference file")?;
        out.push(Sample {
            kind: DatasetKind::Pairs,
            id: f[0].to_string(),
            group,
            ratio,
            noisy,
            reference,
        });
    }
    if out.is_empty() {
        return err(format!("{}: no pairs to evaluate", csv.display()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_rows_header_and_errors() {
        let d = std::env::temp_dir().join(format!("pgrf-pairs-walk-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        for n in ["a.dng", "b.dng", "ref.dng"] {
            std::fs::write(d.join(n), b"x").unwrap();
        }
        std::fs::write(
            d.join(DEFAULT_CSV),
            "noisy,reference,ratio\na.dng,ref.dng,100\nb.dng,ref.dng,\n",
        )
        .unwrap();
        let v = walk(&d).unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!((v[0].group, v[0].ratio), (100, RatioRule::Fixed(100.0)));
        assert_eq!(v[1].ratio, RatioRule::IsoExposure);
        std::fs::write(d.join(DEFAULT_CSV), "noisy,reference,ratio\n").unwrap();
        assert!(walk(&d).unwrap_err().to_string().contains("no pairs"));
        std::fs::write(d.join(DEFAULT_CSV), "c.dng,ref.dng,100\n").unwrap();
        let e = walk(&d).unwrap_err().to_string();
        assert!(e.contains(&d.join("c.dng").display().to_string()), "{e}");
        std::fs::write(d.join(DEFAULT_CSV), "a.dng,ref.dng,-3\n").unwrap();
        assert!(walk(&d).unwrap_err().to_string().contains("-3"));
        std::fs::remove_dir_all(&d).unwrap();
    }
}

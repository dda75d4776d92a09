//! Per-image results and the comparison table in the shape of the paper's
//! Tables 2 and 4: one row per ratio (per ISO and ratio for the synthetic
//! protocol), PSNR/SSIM columns per method, means over the images of that
//! row; with the colour-cast figure when the rows carry one.

use crate::Cast;
use std::collections::BTreeMap;
use std::fmt::Write;

/// One image measured for one method.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The dataset protocol the pair came from ("eld", "sid", "pairs" or
    /// "synthetic").
    pub protocol: String,
    /// The pair's identifier ("scene-3/IMG_0009", "10003_00_0.1s"; the
    /// clean file's name for the synthetic protocol).
    pub id: String,
    /// Table row (x100, x200, ...).
    pub group: u32,
    /// The exact amplification used.
    pub ratio: f32,
    /// Path of the noisy file (synthetic: empty, the capture is made in memory).
    pub noisy: String,
    /// Path of the reference file.
    pub reference: String,
    /// The method's name (a model, or [`NOISY`](super::run::NOISY) for the
    /// amplified input).
    pub method: String,
    /// PSNR in dB under the protocol.
    pub psnr: f64,
    /// SSIM (channel mean) under the protocol.
    pub ssim: f64,
    /// ELD's illuminance gain applied to the output, when the run corrects.
    pub gain: Option<f64>,
    /// The synthetic capture's ISO (None for the file-pair protocols); rows
    /// with an ISO are tabled per (ISO, ratio).
    pub iso: Option<u32>,
    /// The synthetic capture's noise seed.
    pub seed: Option<u64>,
    /// The colour-cast figure, when the run measures it and a block qualified.
    pub cast: Option<Cast>,
    /// The black-level figures (mean and median output minus reference where
    /// the reference is below 1 % of white, fractions of white), measured
    /// with the cast, when such pixels exist.
    pub black: Option<crate::metrics::BlackLevel>,
    /// Synthetic: the noise a noise-aware method was told, and the truth.
    pub noise: Option<NoiseRecord>,
}

/// The noise parameters a noise-aware method was told of a synthetic
/// capture (`--blind-noise`: the blind estimate), beside the true ones; K in
/// DN per electron, read noise in DN, on the profile's scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseRecord {
    /// K told.
    pub told_k: f64,
    /// Read noise told.
    pub told_read: f64,
    /// K of the capture.
    pub true_k: f64,
    /// Read noise of the capture.
    pub true_read: f64,
}

/// Means of one method in one table row.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Cell {
    pub(crate) psnr: f64,
    pub(crate) ssim: f64,
    pub(crate) images: usize,
    /// Mean chroma cast (ΔE*ab) and signed Δa*, Δb* over the images that
    /// have one, with their count.
    pub(crate) cast: Option<([f64; 3], usize)>,
}

/// A table row: (ISO for synthetic rows, ratio group).
pub(crate) type Key = (Option<u32>, u32);

/// Mean PSNR/SSIM (and colour cast) per (row, method), methods in first-seen order.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Method names, one PSNR/SSIM column pair each, in first-seen order.
    pub methods: Vec<String>,
    /// row -> per method means; None when the method has no image there.
    pub(crate) rows: BTreeMap<Key, Vec<Option<Cell>>>,
    /// Whether any row carries a colour cast (then the table shows it).
    pub(crate) cast: bool,
}

#[derive(Clone, Copy, Default)]
struct Acc {
    psnr: f64,
    ssim: f64,
    n: usize,
    cast: [f64; 3],
    cast_n: usize,
}

/// Average `rows` per (row, method): the paper's table, one row per ratio
/// (per ISO and ratio when the rows have an ISO).
pub fn summarise(rows: &[Row]) -> Summary {
    let mut methods: Vec<String> = Vec::new();
    for r in rows {
        if !methods.contains(&r.method) {
            methods.push(r.method.clone());
        }
    }
    let mut acc: BTreeMap<Key, Vec<Acc>> = BTreeMap::new();
    for r in rows {
        let m = methods.iter().position(|x| *x == r.method).unwrap_or(0);
        let e = &mut acc
            .entry((r.iso, r.group))
            .or_insert_with(|| vec![Acc::default(); methods.len()])[m];
        e.psnr += r.psnr;
        e.ssim += r.ssim;
        e.n += 1;
        if let Some(c) = &r.cast {
            e.cast[0] += c.dab;
            e.cast[1] += c.da;
            e.cast[2] += c.db;
            e.cast_n += 1;
        }
    }
    let table = acc
        .into_iter()
        .map(|(g, v)| {
            let v = v
                .into_iter()
                .map(|a| {
                    (a.n > 0).then(|| Cell {
                        psnr: a.psnr / a.n as f64,
                        ssim: a.ssim / a.n as f64,
                        images: a.n,
                        cast: (a.cast_n > 0)
                            .then(|| (a.cast.map(|c| c / a.cast_n as f64), a.cast_n)),
                    })
                })
                .collect();
            (g, v)
        })
        .collect();
    Summary {
        methods,
        rows: table,
        cast: rows.iter().any(|r| r.cast.is_some()),
    }
}

fn cell(v: &Option<Cell>) -> (String, String) {
    match v {
        Some(c) => (format!("{:.2}", c.psnr), format!("{:.4}", c.ssim)),
        None => ("-".into(), "-".into()),
    }
}

/// The mean chroma cast, and the signed (Δa*, Δb*), of a cell.
fn cast_cell(v: &Option<Cell>) -> (String, String) {
    match v.and_then(|c| c.cast) {
        Some((c, _)) => (
            format!("{:.2}", c[0]),
            format!("{:+.2}, {:+.2}", c[1], c[2]),
        ),
        None => ("-".into(), "-".into()),
    }
}

fn images(v: &[Option<Cell>]) -> usize {
    v.iter().flatten().map(|x| x.images).max().unwrap_or(0)
}

/// A table row's label: "x100", or "ISO 1600 x100".
fn label(k: &Key) -> String {
    match k.0 {
        Some(iso) => format!("ISO {iso} x{}", k.1),
        None => format!("x{}", k.1),
    }
}

impl Summary {
    /// Name of the first column: "ratio", or "condition" for (ISO, ratio) rows.
    fn first_column(&self) -> &'static str {
        if self.rows.keys().any(|k| k.0.is_some()) {
            "condition"
        } else {
            "ratio"
        }
    }

    /// Plain-text table for the terminal.
    pub fn text(&self) -> String {
        let w = self
            .methods
            .iter()
            .map(|m| m.len())
            .max()
            .unwrap_or(0)
            .max(if self.cast { 22 } else { 16 });
        let lw = self
            .rows
            .keys()
            .map(|k| label(k).len())
            .max()
            .unwrap_or(0)
            .max(7);
        let mut s = String::new();
        let _ = write!(s, "{:<lw$} {:>6}", self.first_column(), "images");
        for m in &self.methods {
            let _ = write!(s, "  {m:>w$}");
        }
        s.push('\n');
        let _ = write!(s, "{:<lw$} {:>6}", "", "");
        let unit = if self.cast {
            "PSNR / SSIM / dEab"
        } else {
            "PSNR / SSIM"
        };
        for _ in &self.methods {
            let _ = write!(s, "  {unit:>w$}");
        }
        s.push('\n');
        for (g, v) in &self.rows {
            let _ = write!(s, "{:<lw$} {:>6}", label(g), images(v));
            for c in v {
                let (p, q) = cell(c);
                let text = if self.cast {
                    format!("{p} / {q} / {}", cast_cell(c).0)
                } else {
                    format!("{p} / {q}")
                };
                let _ = write!(s, "  {text:>w$}");
            }
            s.push('\n');
        }
        s
    }

    /// The same table in Markdown.
    pub fn markdown(&self) -> String {
        let first = match self.first_column() {
            "ratio" => "Ratio",
            _ => "Condition",
        };
        let mut s = format!("| {first} | Images |");
        for m in &self.methods {
            let _ = write!(s, " {m} PSNR | {m} SSIM |");
            if self.cast {
                let _ = write!(s, " {m} cast ΔE*ab | {m} Δa*, Δb* |");
            }
        }
        s.push_str("\n|---|---:|");
        for _ in &self.methods {
            s.push_str(if self.cast {
                "---:|---:|---:|---:|"
            } else {
                "---:|---:|"
            });
        }
        s.push('\n');
        for (g, v) in &self.rows {
            let _ = write!(s, "| {} | {} |", label(g), images(v));
            for c in v {
                let (p, q) = cell(c);
                let _ = write!(s, " {p} | {q} |");
                if self.cast {
                    let (d, ab) = cast_cell(c);
                    let _ = write!(s, " {d} | {ab} |");
                }
            }
            s.push('\n');
        }
        s
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// Per-image CSV: protocol, id, ratio group, ratio, files, method, scores.
/// Rows of the synthetic protocol (rows with an ISO) have their own
/// columns: protocol, id, reference, iso, ratio, seed, method, psnr, ssim,
/// cast_dab, cast_da, cast_db, cast_blocks, gain, black_lift, black_median, told_k, told_read, true_k,
/// true_read.
pub fn csv(rows: &[Row]) -> String {
    if rows.iter().any(|r| r.iso.is_some()) {
        return synthetic_csv(rows);
    }
    let mut s =
        String::from("protocol,id,ratio_group,ratio,noisy,reference,method,psnr,ssim,gain\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{}",
            csv_field(&r.protocol),
            csv_field(&r.id),
            r.group,
            r.ratio,
            csv_field(&r.noisy),
            csv_field(&r.reference),
            csv_field(&r.method),
            r.psnr,
            r.ssim,
            opt(r.gain)
        );
    }
    s
}

fn synthetic_csv(rows: &[Row]) -> String {
    let mut s = String::from(
        "protocol,id,reference,iso,ratio,seed,method,psnr,ssim,cast_dab,cast_da,cast_db,cast_blocks,gain,black_lift,black_median,told_k,told_read,true_k,true_read\n",
    );
    for r in rows {
        let c = r.cast.as_ref();
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            csv_field(&r.protocol),
            csv_field(&r.id),
            csv_field(&r.reference),
            opt(r.iso),
            r.ratio,
            opt(r.seed),
            csv_field(&r.method),
            r.psnr,
            r.ssim,
            opt(c.map(|c| c.dab)),
            opt(c.map(|c| c.da)),
            opt(c.map(|c| c.db)),
            opt(c.map(|c| c.blocks)),
            opt(r.gain),
            opt(r.black.map(|b| b.mean)),
            opt(r.black.map(|b| b.median)),
            opt(r.noise.map(|n| n.told_k)),
            opt(r.noise.map(|n| n.told_read)),
            opt(r.noise.map(|n| n.true_k)),
            opt(r.noise.map(|n| n.true_read))
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(id: &str, group: u32, method: &str, psnr: f64) -> Row {
        Row {
            protocol: "eld".into(),
            id: id.into(),
            group,
            ratio: group as f32,
            noisy: format!("{id}.ARW"),
            reference: "ref, 1.ARW".into(),
            method: method.into(),
            psnr,
            ssim: psnr / 100.0,
            gain: None,
            iso: None,
            seed: None,
            cast: None,
            black: None,
            noise: None,
        }
    }

    #[test]
    fn means_per_ratio_and_method() {
        let rows = vec![
            row("a", 100, "noisy input", 20.0),
            row("a", 100, "m", 40.0),
            row("b", 100, "noisy input", 22.0),
            row("b", 100, "m", 42.0),
            row("c", 200, "m", 30.0),
        ];
        let s = summarise(&rows);
        assert_eq!(s.methods, vec!["noisy input", "m"]);
        let r: Vec<(f64, usize)> = s.rows[&(None, 100)]
            .iter()
            .map(|c| (c.unwrap().psnr, c.unwrap().images))
            .collect();
        assert_eq!(r, vec![(21.0, 2), (41.0, 2)]);
        assert!((s.rows[&(None, 100)][1].unwrap().ssim - 0.41).abs() < 1e-12);
        assert_eq!(s.rows[&(None, 200)][0], None);
        let t = s.text();
        assert!(t.lines().nth(2).unwrap().starts_with("x100"), "{t}");
        assert!(t.contains("41.00 / 0.4100"), "{t}");
        let m = s.markdown();
        assert!(m.contains("| x200 | 1 | - | - | 30.00 | 0.3000 |"), "{m}");
        let c = csv(&rows);
        assert_eq!(c.lines().count(), 6);
        assert!(c.contains("\"ref, 1.ARW\""));
    }

    #[test]
    fn synthetic_rows_are_tabled_per_iso_and_ratio_with_the_cast() {
        let cast = |dab: f64| Cast {
            dab,
            da: -dab,
            db: 0.5,
            blocks: 10,
            eligible: 20,
            white_balance: true,
            matrix: true,
        };
        let mut rows = Vec::new();
        for (iso, group, dab) in [(3200, 100, 1.0), (800, 200, 2.0), (800, 100, 3.0)] {
            for (m, p) in [("noisy input", 20.0), ("m", 30.0)] {
                let mut r = row("chart.dng", group, m, p);
                r.protocol = "synthetic".into();
                r.iso = Some(iso);
                r.seed = Some(42);
                r.cast = Some(cast(dab + p / 10.0));
                rows.push(r);
            }
        }
        rows[5].cast = None;
        let s = summarise(&rows);
        let keys: Vec<Key> = s.rows.keys().copied().collect();
        assert_eq!(
            keys,
            vec![(Some(800), 100), (Some(800), 200), (Some(3200), 100)]
        );
        let t = s.text();
        let lines: Vec<&str> = t.lines().collect();
        assert!(lines[0].starts_with("condition"), "{t}");
        assert!(lines[1].contains("PSNR / SSIM / dEab"), "{t}");
        assert!(lines[2].starts_with("ISO 800 x100"), "{t}");
        assert!(lines[2].contains("20.00 / 0.2000 / 5.00"), "{t}");
        assert!(lines[2].ends_with("30.00 / 0.3000 / -"), "{t}");
        assert!(lines[4].starts_with("ISO 3200 x100"), "{t}");
        let m = s.markdown();
        assert!(m.starts_with("| Condition | Images |"), "{m}");
        assert!(
            m.contains("| ISO 3200 x100 | 1 | 20.00 | 0.2000 | 3.00 | -3.00, +0.50 | 30.00 | 0.3000 | 4.00 | -4.00, +0.50 |"),
            "{m}"
        );
        let c = csv(&rows);
        let lines: Vec<&str> = c.lines().collect();
        assert_eq!(
            lines[0],
            "protocol,id,reference,iso,ratio,seed,method,psnr,ssim,cast_dab,cast_da,cast_db,cast_blocks,gain,black_lift,black_median,told_k,told_read,true_k,true_read"
        );
        assert_eq!(lines.len(), 7);
        assert_eq!(
            lines[1],
            "synthetic,chart.dng,\"ref, 1.ARW\",3200,100,42,noisy input,20,0.2,3,-3,0.5,10,,,,,,,"
        );
        assert!(lines[6].ends_with(",m,30,0.3,,,,,,,,,,,"), "{c}");
    }
}

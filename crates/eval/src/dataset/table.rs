//! Per-image results and the comparison table in the shape of the paper's
//! Tables 2 and 4: one row per ratio, PSNR/SSIM columns per method, means
//! over the images of that ratio.

use std::collections::BTreeMap;
use std::fmt::Write;

/// One image measured for one method.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The dataset protocol the pair came from ("eld", "sid" or "pairs").
    pub protocol: String,
    /// The pair's identifier ("scene-3/IMG_0009", "10003_00_0.1s").
    pub id: String,
    /// Table row (x100, x200, ...).
    pub group: u32,
    /// The exact amplification used.
    pub ratio: f32,
    /// Path of the noisy file.
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
}

/// (mean PSNR, mean SSIM, images) of one method at one ratio; None when the
/// method has no image there.
pub(crate) type Cell = Option<(f64, f64, usize)>;

/// Mean PSNR/SSIM per (group, method), methods in first-seen order.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Method names, one PSNR/SSIM column pair each, in first-seen order.
    pub methods: Vec<String>,
    /// group -> per method (mean PSNR, mean SSIM, images).
    pub(crate) rows: BTreeMap<u32, Vec<Cell>>,
}

/// Average `rows` per (group, method): the paper's table, one row per ratio.
pub fn summarise(rows: &[Row]) -> Summary {
    let mut methods: Vec<String> = Vec::new();
    for r in rows {
        if !methods.contains(&r.method) {
            methods.push(r.method.clone());
        }
    }
    let mut acc: BTreeMap<u32, Vec<(f64, f64, usize)>> = BTreeMap::new();
    for r in rows {
        let m = methods.iter().position(|x| *x == r.method).unwrap_or(0);
        let e = acc
            .entry(r.group)
            .or_insert_with(|| vec![(0.0, 0.0, 0); methods.len()]);
        e[m].0 += r.psnr;
        e[m].1 += r.ssim;
        e[m].2 += 1;
    }
    let rows = acc
        .into_iter()
        .map(|(g, v)| {
            let v = v
                .into_iter()
                .map(|(p, s, n)| (n > 0).then(|| (p / n as f64, s / n as f64, n)))
                .collect();
            (g, v)
        })
        .collect();
    Summary { methods, rows }
}

fn cell(v: &Cell) -> (String, String) {
    match v {
        Some((p, s, _)) => (format!("{p:.2}"), format!("{s:.4}")),
        None => ("-".into(), "-".into()),
    }
}

fn images(v: &[Cell]) -> usize {
    v.iter().flatten().map(|x| x.2).max().unwrap_or(0)
}

impl Summary {
    /// Plain-text table for the terminal.
    pub fn text(&self) -> String {
        let w = self
            .methods
            .iter()
            .map(|m| m.len())
            .max()
            .unwrap_or(0)
            .max(16);
        let mut s = String::new();
        let _ = write!(s, "{:<7} {:>6}", "ratio", "images");
        for m in &self.methods {
            let _ = write!(s, "  {m:>w$}");
        }
        s.push('\n');
        let _ = write!(s, "{:<7} {:>6}", "", "");
        for _ in &self.methods {
            let _ = write!(s, "  {:>w$}", "PSNR / SSIM");
        }
        s.push('\n');
        for (g, v) in &self.rows {
            let _ = write!(s, "{:<7} {:>6}", format!("x{g}"), images(v));
            for c in v {
                let (p, q) = cell(c);
                let _ = write!(s, "  {:>w$}", format!("{p} / {q}"));
            }
            s.push('\n');
        }
        s
    }

    /// The same table in Markdown.
    pub fn markdown(&self) -> String {
        let mut s = String::from("| Ratio | Images |");
        for m in &self.methods {
            let _ = write!(s, " {m} PSNR | {m} SSIM |");
        }
        s.push_str("\n|---|---:|");
        for _ in &self.methods {
            s.push_str("---:|---:|");
        }
        s.push('\n');
        for (g, v) in &self.rows {
            let _ = write!(s, "| x{g} | {} |", images(v));
            for c in v {
                let (p, q) = cell(c);
                let _ = write!(s, " {p} | {q} |");
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

/// Per-image CSV: protocol, id, ratio group, ratio, files, method, scores.
pub fn csv(rows: &[Row]) -> String {
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
            r.gain.map(|g| g.to_string()).unwrap_or_default()
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
        let r: Vec<(f64, usize)> = s.rows[&100]
            .iter()
            .map(|c| (c.unwrap().0, c.unwrap().2))
            .collect();
        assert_eq!(r, vec![(21.0, 2), (41.0, 2)]);
        assert!((s.rows[&100][1].unwrap().1 - 0.41).abs() < 1e-12);
        assert_eq!(s.rows[&200][0], None);
        let t = s.text();
        assert!(t.lines().nth(2).unwrap().starts_with("x100"), "{t}");
        assert!(t.contains("41.00 / 0.4100"), "{t}");
        let m = s.markdown();
        assert!(m.contains("| x200 | 1 | - | - | 30.00 | 0.3000 |"), "{m}");
        let c = csv(&rows);
        assert_eq!(c.lines().count(), 6);
        assert!(c.contains("\"ref, 1.ARW\""));
    }
}

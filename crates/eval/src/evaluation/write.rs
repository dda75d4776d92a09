//! The files an evaluation leaves: per-image CSV, the table in Markdown
//! under the header quoted, and a PNG of the worst images side by side
//! (pgrf-report's montage of sRGB previews).

use super::{EvalConfig, EvalError, Evaluation};
use crate::dataset::run::Worst;
use crate::dataset::table::csv;
use pgrf_raw::{render_preview, unpack_normalized, PreviewOptions};
use pgrf_report::{write_montage, Panel};
use std::path::{Path, PathBuf};

fn write_file(path: &Path, text: &str) -> Result<(), EvalError> {
    pgrf_core::write_atomic(path, text.as_bytes()).map_err(|source| EvalError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Where the worst-images picture goes: `worst` as given, else next to the
/// CSV as NAME_worst.png, else nowhere.
pub fn worst_path(worst: Option<&Path>, csv: Option<&Path>) -> Option<PathBuf> {
    worst.map(Path::to_path_buf).or_else(|| {
        csv.map(|c| {
            let stem = c.file_stem().unwrap_or_default().to_string_lossy();
            c.with_file_name(format!("{stem}_worst.png"))
        })
    })
}

impl Evaluation {
    /// Write the files `cfg` asks for (CSV, Markdown, worst-images picture),
    /// telling `wrote` one line as each is written.
    pub fn write(&self, cfg: &EvalConfig, wrote: &mut dyn FnMut(&str)) -> Result<(), EvalError> {
        if let Some(p) = &cfg.csv {
            write_file(p, &csv(&self.rows))?;
            wrote(&format!("wrote {}", p.display()));
        }
        if let Some(p) = &cfg.markdown {
            let text = format!(
                "{}\n\n{}",
                self.header
                    .lines()
                    .map(|l| format!("> {l}"))
                    .collect::<Vec<_>>()
                    .join("  \n"),
                self.summary.markdown()
            );
            write_file(p, &text)?;
            wrote(&format!("wrote {}", p.display()));
        }
        if let Some(p) = worst_path(cfg.worst.as_deref(), cfg.csv.as_deref()) {
            if !self.worst.is_empty() {
                let cols = &self.worst_columns;
                write_worst(&self.worst, cols, &p)?;
                wrote(&format!(
                    "wrote {}: {} (columns: {})",
                    p.display(),
                    self.worst
                        .iter()
                        .map(|w| w.id.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                    cols.join(", ")
                ));
            }
        }
        Ok(())
    }
}

/// Rows of previews (one per worst image), each captioned with its image
/// id and column name.
fn write_worst(worst: &[Worst], cols: &[String], path: &Path) -> Result<(), EvalError> {
    let mut rows: Vec<Vec<Panel>> = Vec::new();
    for w in worst {
        let mut row = Vec::new();
        for (t, col) in w.tiles.iter().zip(cols) {
            let f = unpack_normalized(t.view(), &w.template)?;
            row.push(Panel {
                caption: format!("{}: {col}", w.id),
                image: render_preview(&f, &PreviewOptions::default())?,
            });
        }
        rows.push(row);
    }
    write_montage(path, &rows).map_err(|reason| EvalError::Montage {
        path: path.to_path_buf(),
        reason,
    })
}

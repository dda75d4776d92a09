//! Pictures side by side: rows of sRGB previews with a caption over each,
//! written as one PNG. Comparisons (noisy input, each method, reference) are
//! judged by eye as much as by PSNR, and only side by side at the same scale.

use crate::png::{ensure_font, render_png, FONT_FAMILY};
use crate::ReportError;
use pgrf_raw::Preview;
use plotters::prelude::*;
use std::path::Path;

/// One picture and the words above it.
pub struct Panel {
    /// Text drawn over the picture (empty: no caption).
    pub caption: String,
    /// The sRGB picture.
    pub image: Preview,
}

/// White space between panels, in pixels.
const GAP: usize = 8;
/// Height of the caption band over each panel when any panel has one.
const CAPTION: usize = 30;

/// Font size of a caption: 20 px, smaller (down to 9 px) for a caption that
/// would otherwise run into the next panel (a glyph is taken as ~0.55 of
/// the size wide, generous for DejaVu Sans).
fn caption_size(text: &str, cell_width: usize) -> f64 {
    let fit = (cell_width.saturating_sub(8)) as f64 / (0.55 * text.chars().count().max(1) as f64);
    fit.clamp(9.0, 20.0)
}

/// Write `rows` of panels as a grid (cells as large as the largest panel,
/// white between them), atomically.
pub fn write_montage(path: &Path, rows: &[Vec<Panel>]) -> Result<(), ReportError> {
    let panels = || rows.iter().flatten();
    let cw = panels().map(|p| p.image.width).max().unwrap_or(0);
    let ch = panels().map(|p| p.image.height).max().unwrap_or(0);
    let ncols = rows.iter().map(|r| r.len()).max().unwrap_or(0);
    if cw == 0 || ch == 0 || ncols == 0 {
        return Err(ReportError::Empty("nothing to put side by side"));
    }
    let band = if panels().any(|p| !p.caption.is_empty()) {
        ensure_font()?;
        CAPTION
    } else {
        0
    };
    let width = ncols * cw + (ncols - 1) * GAP;
    let height = rows.len() * (ch + band) + (rows.len() - 1) * GAP;
    render_png(path, (width as u32, height as u32), |root| {
        for (ri, row) in rows.iter().enumerate() {
            for (ci, p) in row.iter().enumerate() {
                let (x0, y0) = (ci * (cw + GAP), ri * (ch + band + GAP));
                if !p.caption.is_empty() {
                    root.draw_text(
                        &p.caption,
                        &(FONT_FAMILY, caption_size(&p.caption, cw))
                            .into_font()
                            .color(&BLACK),
                        (x0 as i32 + 4, y0 as i32 + 5),
                    )?;
                }
                let img = &p.image;
                for y in 0..img.height {
                    for x in 0..img.width {
                        let o = (y * img.width + x) * 3;
                        let c = |k: usize| (img.rgb[o + k].clamp(0.0, 1.0) * 255.0).round() as u8;
                        root.draw_pixel(
                            ((x0 + x) as i32, (y0 + band + y) as i32),
                            &RGBColor(c(0), c(1), c(2)),
                        )?;
                    }
                }
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::caption_size;

    #[test]
    fn long_captions_shrink_to_their_panel() {
        assert_eq!(caption_size("noisy input", 256), 20.0);
        let long = "kodak_dc50.kdc ISO 6400 x300: noisy input";
        let size = caption_size(long, 256);
        assert!((9.0..12.0).contains(&size), "{size}");
        assert!(0.55 * size * long.chars().count() as f64 <= 248.0 + 1e-9);
    }
}

//! The demo's picture: per ratio two rows, the whole frame at half size and
//! a detail at twice full size, each of clean, noisy (brightened by the
//! ratio), SPC and PGRF, captioned with the scores (pgrf-report's montage).

use super::{Capture, DemoError};
use pgrf_eval::Scores;
use pgrf_raw::{render_preview, Preview, PreviewOptions, RawFrame};
use pgrf_report::{write_montage, Panel};
use std::path::Path;

/// The crop shown at 2x, a quarter of the frame each way: on the photograph
/// the chart's middle patches and its printed lettering, on the procedural
/// scene the lower left corner of the chart and the leaves around it.
/// Returns `(row, col, h, w)` in preview pixels.
fn crop_box(width: usize, height: usize, photo: bool) -> (usize, usize, usize, usize) {
    let (ch, cw) = (height / 4, width / 4);
    if photo {
        (height / 2, width * 11 / 20, ch, cw)
    } else {
        (height * 2 / 5, width / 2, ch, cw)
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
pub(super) fn write_picture(
    path: &Path,
    clean: &RawFrame,
    captures: &[Capture],
    photo: bool,
) -> Result<(), DemoError> {
    let half = PreviewOptions {
        half: true,
        ..PreviewOptions::default()
    };
    let full = PreviewOptions::default();
    let views = |f: &RawFrame, gain: f32| -> Result<(Preview, Preview), DemoError> {
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
        let b = crop_box(detail.width, detail.height, photo);
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
    write_montage(path, &rows).map_err(|reason| DemoError::Picture {
        path: path.to_path_buf(),
        reason,
    })
}

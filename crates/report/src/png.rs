//! Pictures to PNG: the embedded font, rendering a plotters drawing into
//! memory, encoding and writing atomically.

use crate::error::ReportError;
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

/// plotters' default family; registering the embedded font under it means
/// every text element (captions, tick labels, legends) finds a font without
/// each call site naming one.
pub(crate) const FONT_FAMILY: &str = "sans-serif";

/// Register the embedded font once per process: the `ab_glyph` backend has
/// no system-font fallback, and without a registered family every text draw
/// fails.
pub(crate) fn ensure_font() -> Result<(), ReportError> {
    // The face that failed to load, once for the process.
    static FONT: OnceLock<Result<(), &'static str>> = OnceLock::new();
    FONT.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, dejavu::sans::regular())
            .map_err(|_| "regular")?;
        plotters::style::register_font(FONT_FAMILY, FontStyle::Bold, dejavu::sans::bold())
            .map_err(|_| "bold")
    })
    .map_err(|face| ReportError::Font { face })
}

/// What a drawing closure returns: plotters' errors are boxed.
pub(crate) type PlotResult = Result<(), Box<dyn std::error::Error>>;

/// Render with plotters into an in-memory RGB buffer, encode and write
/// atomically: the crate has no `bitmap_encoder` feature (it would pull in a
/// second image stack), and writing through a temp file keeps a crashed run
/// from leaving half a PNG behind.
pub(crate) fn render_png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend, plotters::coord::Shift>) -> PlotResult,
) -> Result<(), ReportError> {
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let result = root
            .fill(&WHITE)
            .map_err(|e| Box::new(e) as Box<dyn std::error::Error>)
            .and_then(|_| draw(&root))
            .and_then(|_| root.present().map_err(|e| e.into()));
        result.map_err(|e| ReportError::Plot {
            file: path.display().to_string(),
            reason: one_line(&e.to_string()),
        })?;
    }
    let png = encode_png(path, &rgb, (w, h), image::ExtendedColorType::Rgb8)?;
    pgrf_core::write_atomic(path, &png)?;
    Ok(())
}

/// Encode 8-bit pixels (`color` says the channels) as the PNG bytes of
/// `path` (which names it in the error).
pub(crate) fn encode_png(
    path: &Path,
    pixels: &[u8],
    (w, h): (u32, u32),
    color: image::ExtendedColorType,
) -> Result<Vec<u8>, ReportError> {
    use image::ImageEncoder as _;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(pixels, w, h, color)
        .map_err(|e| ReportError::Encode {
            file: path.display().to_string(),
            reason: one_line(&e.to_string()),
        })?;
    Ok(out)
}

/// Backend and font errors can carry newlines; the error type promises one.
pub(crate) fn one_line(s: &str) -> String {
    let line = s
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("; ");
    if line.is_empty() {
        "unknown error".to_string()
    } else {
        line
    }
}

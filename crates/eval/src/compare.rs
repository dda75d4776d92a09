//! One result file against its reference file (`pgrf metrics`): both
//! decoded, normalised by their own black and white levels, packed and
//! measured under the ELD protocol, with the line that says how.

use crate::{evaluate, seams, speckles, MetricError, Protocol, Scores, Seams, Speckles};
use pgrf_raw::{decode_file, pack_normalized, Cfa, LevelOverrides, RawError, RawFrame};
use std::path::{Path, PathBuf};

/// Why two files could not be compared.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// A file could not be decoded or packed.
    #[error(transparent)]
    Raw(#[from] RawError),
    /// The files differ in size or CFA phase.
    #[error(
        "cannot compare {} ({}) with {} ({}): sizes or CFA phases differ",
        output.display(), describe(output_layout), reference.display(), describe(reference_layout)
    )]
    Mismatch {
        /// The file judged.
        output: PathBuf,
        /// Its width, height and CFA phase.
        output_layout: (usize, usize, Cfa),
        /// The reference file.
        reference: PathBuf,
        /// Its width, height and CFA phase.
        reference_layout: (usize, usize, Cfa),
    },
    /// The measurement refused the pair.
    #[error(transparent)]
    Metric(#[from] MetricError),
}

fn describe(&(w, h, cfa): &(usize, usize, Cfa)) -> String {
    format!("{w}x{h} {cfa}")
}

fn layout(f: &RawFrame) -> (usize, usize, Cfa) {
    (f.width, f.height, f.cfa)
}

/// Two files' scores and how they were measured.
#[derive(Clone, Debug, PartialEq)]
pub struct FileScores {
    /// PSNR, SSIM and the illuminance gain applied.
    pub scores: Scores,
    /// One line: packing, normalisation and the protocol's steps.
    pub protocol: String,
    /// Speckles in the reference's flat regions ([`crate::artefacts`]).
    pub speckles: Speckles,
    /// The worst seam at the borders of the seam grid, when one was given.
    pub seams: Option<Seams>,
}

/// Measure file `output` against file `reference` (same size and CFA
/// phase), each normalised by its own levels, under ELD's protocol with or
/// without its illuminance correction; speckles always, and seams at the
/// borders of `seam_grid` when given: (period, offset), the borders every
/// period packed pixels from `offset` before the frame ([`seams`]).
pub fn compare_files(
    output: &Path,
    reference: &Path,
    illuminance_correct: bool,
    seam_grid: Option<(usize, usize)>,
) -> Result<FileScores, CompareError> {
    let o = LevelOverrides::default();
    let (out, refr) = rayon::join(|| decode_file(output, &o), || decode_file(reference, &o));
    let (out, refr) = (out?, refr?);
    if layout(&out) != layout(&refr) {
        return Err(CompareError::Mismatch {
            output: output.to_path_buf(),
            output_layout: layout(&out),
            reference: reference.to_path_buf(),
            reference_layout: layout(&refr),
        });
    }
    let po = pack_normalized(&out, true)?;
    let pr = pack_normalized(&refr, true)?;
    let protocol = Protocol::eld(illuminance_correct);
    let scores = evaluate(po.view(), pr.view(), &protocol)?;
    let speckles = speckles(po.view(), pr.view())?;
    let seams = seam_grid
        .map(|(period, offset)| seams(po.view(), pr.view(), period, offset))
        .transpose()?;
    Ok(FileScores {
        scores,
        speckles,
        seams,
        protocol: format!(
            "packed R,G1,B,G2, each file normalised by its own black/white levels, {}",
            protocol.describe()
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pgrf_scenes::chart::{render_chart, ChartSpec};

    #[test]
    fn files_are_compared_only_when_they_match() {
        let d = std::env::temp_dir().join(format!("pgrf-compare-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let chart = |width, height| {
            render_chart(&ChartSpec {
                width,
                height,
                ..Default::default()
            })
            .unwrap()
        };
        let (a, b) = (d.join("a.dng"), d.join("b.dng"));
        pgrf_raw::write_dng(&chart(128, 96), &a, &Default::default()).unwrap();
        pgrf_raw::write_dng(&chart(64, 64), &b, &Default::default()).unwrap();
        let same = compare_files(&a, &a, false, Some((32, 0))).unwrap();
        assert!(same.scores.psnr.is_infinite() && same.scores.ssim == 1.0);
        assert_eq!(same.speckles.count, 0);
        assert_eq!(same.seams.unwrap().worst, 0.0);
        assert!(same.protocol.starts_with("packed R,G1,B,G2, each file"));
        let e = compare_files(&a, &b, true, None).unwrap_err();
        assert!(matches!(e, CompareError::Mismatch { .. }));
        assert!(e.to_string().ends_with(
            "(128x96 RGGB) with {} (64x64 RGGB): sizes or CFA phases differ"
                .replace("{}", &b.display().to_string())
                .as_str()
        ));
        std::fs::remove_dir_all(&d).unwrap();
    }
}

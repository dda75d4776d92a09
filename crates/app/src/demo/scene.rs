//! The demo's clean frame: a real RAW photograph (a file, or bytes built
//! into the caller, its centre window if asked) or pgrf's procedural scene
//! (dead leaves, a ColorChecker, a ramp), stamped with the demo's ISO and
//! clean exposure.

use super::{DemoError, CLEAN_EXPOSURE_S, ISO};
use pgrf_raw::{decode_bytes, decode_file, Cfa, LevelOverrides, RawFrame};
use pgrf_scenes::demo::render_demo;
use pgrf_scenes::SceneLevels;
use std::path::{Path, PathBuf};

/// Where a photograph comes from.
pub enum PhotoSource<'a> {
    /// Any Bayer RAW file pgrf reads.
    File(PathBuf),
    /// A RAW file's bytes (a photograph built into the program).
    Bytes {
        /// Its file name, in messages.
        name: &'a str,
        /// Where it comes from and its licence, in the report.
        credit: &'a str,
        /// The file's bytes.
        bytes: &'a [u8],
    },
}

/// What the demo starts from.
pub enum Scene<'a> {
    /// A real RAW photograph taken as the clean reference.
    Photo {
        /// The photograph.
        source: PhotoSource<'a>,
        /// Its centre window (width, height in mosaic pixels, even), or all of it.
        size: Option<(usize, usize)>,
    },
    /// pgrf's procedural scene of this size (width, height in mosaic
    /// pixels, even, at least 64 x 64).
    Procedural {
        /// Width in mosaic pixels.
        width: usize,
        /// Height in mosaic pixels.
        height: usize,
    },
}

impl Scene<'_> {
    /// Whether it is a photograph (where the picture's detail crop goes).
    pub fn is_photo(&self) -> bool {
        matches!(self, Scene::Photo { .. })
    }
}

/// The clean frame the demo starts from, and its description for the report.
pub struct Clean {
    /// The frame, with the demo's ISO and exposure.
    pub frame: RawFrame,
    /// It in words.
    pub what: String,
}

/// The even centre window of `frame` of `size` (width, height), or all of it.
fn centre(
    frame: RawFrame,
    size: Option<(usize, usize)>,
    name: &str,
) -> Result<RawFrame, DemoError> {
    let Some((w, h)) = size else {
        return Ok(frame);
    };
    if w > frame.width || h > frame.height {
        return Err(DemoError::Size {
            size: (w, h),
            name: name.to_string(),
            frame: (frame.width, frame.height),
        });
    }
    let (row, col) = ((frame.height - h) / 4 * 2, (frame.width - w) / 4 * 2);
    Ok(frame.crop(row, col, h, w)?)
}

/// Decode a photograph, and name it for messages and the report.
fn photo(source: &PhotoSource<'_>) -> Result<(RawFrame, String), DemoError> {
    Ok(match source {
        PhotoSource::File(p) => (
            decode_file(p, &LevelOverrides::default()).map_err(|source| DemoError::Photo {
                path: p.clone(),
                source,
            })?,
            p.display().to_string(),
        ),
        PhotoSource::Bytes {
            name,
            credit,
            bytes,
        } => (
            decode_bytes(Path::new(name), bytes, &LevelOverrides::default())?,
            format!("{name} ({credit})"),
        ),
    })
}

/// Load or render the clean frame of `scene` (the procedural one from `seed`).
pub fn clean_frame(scene: &Scene<'_>, seed: u64) -> Result<Clean, DemoError> {
    let (mut frame, what) = match scene {
        Scene::Procedural { width, height } => {
            let (w, h) = (*width, *height);
            let f = render_demo(w, h, seed, Cfa::Rggb, &SceneLevels::default())?;
            let what =
                format!("procedural scene {w}x{h} (dead leaves, ColorChecker, ramp; seed {seed})");
            (f, what)
        }
        Scene::Photo { source, size } => {
            let (frame, name) = photo(source)?;
            let f = centre(frame, *size, &name)?;
            let what = format!("real photograph {name}, {}x{}", f.width, f.height);
            (f, what)
        }
    };
    frame.iso = Some(ISO);
    frame.exposure_s = Some(CLEAN_EXPOSURE_S);
    Ok(Clean { frame, what })
}

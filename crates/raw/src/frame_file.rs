//! One writer for "a frame to the file the user named": the format follows
//! the file name, so every command that writes frames (`pgrf convert`,
//! `pgrf simulate-sensor`) decides DNG or FITS the same way and refuses the
//! same names.

use crate::dng::{write_dng, DngOptions};
use crate::error::{RawError, Result};
use crate::fits_frame::write_fits_frame;
use crate::frame::RawFrame;
use std::path::Path;

/// The file formats a [`RawFrame`] can be written as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameFormat {
    /// DNG: pixels, levels, colour matrices and EXIF, for raw converters.
    Dng,
    /// FITS, 16-bit unsigned samples, for astronomy tools; it has no
    /// black-level keyword, so a frame's black level is not kept.
    Fits,
}

impl FrameFormat {
    /// The format `path`'s extension names (`.dng`; `.fits`, `.fit` or
    /// `.fts`; any case), refused with [`RawError::UnknownExtension`]
    /// naming the path otherwise.
    pub fn of_path(path: &Path) -> Result<FrameFormat> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("dng") => Ok(FrameFormat::Dng),
            Some("fits" | "fit" | "fts") => Ok(FrameFormat::Fits),
            _ => Err(RawError::UnknownExtension {
                path: path.to_path_buf(),
            }),
        }
    }

    /// The extension pgrf gives files of this format ("dng", "fits").
    pub fn extension(self) -> &'static str {
        match self {
            FrameFormat::Dng => "dng",
            FrameFormat::Fits => "fits",
        }
    }
}

/// Write `frame` atomically to `path` as DNG or FITS, chosen by the
/// extension ([`FrameFormat::of_path`]); `dng` applies to DNG output only.
/// Returns the format written, so a caller can warn about what it does not
/// keep (FITS has no black level).
pub fn write_frame(frame: &RawFrame, path: &Path, dng: &DngOptions) -> Result<FrameFormat> {
    let format = FrameFormat::of_path(path)?;
    match format {
        FrameFormat::Dng => write_dng(frame, path, dng)?,
        FrameFormat::Fits => write_fits_frame(frame, path)?,
    }
    Ok(format)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cfa::Cfa;

    #[test]
    fn the_extension_picks_the_format_and_others_are_refused() {
        for (name, want) in [
            ("a.dng", FrameFormat::Dng),
            ("dir.x/A.DNG", FrameFormat::Dng),
            ("a.fits", FrameFormat::Fits),
            ("a.FIT", FrameFormat::Fits),
            ("a.Fts", FrameFormat::Fits),
        ] {
            assert_eq!(
                FrameFormat::of_path(Path::new(name)).unwrap(),
                want,
                "{name}"
            );
        }
        for name in ["a.tif", "a", "a.dng.bak", ".dng"] {
            let p = Path::new(name);
            let e = FrameFormat::of_path(p).unwrap_err();
            assert!(
                matches!(&e, RawError::UnknownExtension { path } if path == p),
                "{name}: {e:?}"
            );
            assert!(e.to_string().starts_with(&format!("{name}: ")), "{e}");
        }
    }

    #[test]
    fn write_frame_writes_what_the_name_says_and_nothing_for_other_names() {
        let dir = std::env::temp_dir().join(format!("pgrf-raw-frame-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = RawFrame::from_mosaic(4, 2, (0..8).collect(), Cfa::Rggb, [0.0; 4], 1023).unwrap();
        let opts = DngOptions::default();
        let dng = dir.join("f.DNG");
        assert_eq!(write_frame(&f, &dng, &opts).unwrap(), FrameFormat::Dng);
        assert_eq!(
            std::fs::read(&dng).unwrap(),
            crate::dng::encode_dng(&f, &opts).unwrap()
        );
        let fits = dir.join("f.fit");
        assert_eq!(write_frame(&f, &fits, &opts).unwrap(), FrameFormat::Fits);
        assert_eq!(
            std::fs::read(&fits).unwrap(),
            crate::fits_frame::encode_fits_frame(&f).unwrap()
        );
        let other = dir.join("f.png");
        assert!(write_frame(&f, &other, &opts).is_err());
        assert!(!other.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

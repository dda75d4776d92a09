//! `RawFrame`: one Bayer mosaic with everything needed to interpret its numbers.
//!
//! The mosaic is the sensor's visible (active) area only, so that pixel (0, 0)
//! is the first pixel that saw light and the CFA phase refers to it. Levels are
//! kept per packed plane (R, G1, B, G2) because several cameras have a different
//! black level on each channel, and the whole pipeline normalises per channel.

use crate::cfa::Cfa;
use crate::error::{RawError, Result};
use crate::fits::FitsHeader;
use serde::Serialize;

/// XYZ -> camera RGB matrix (DNG `ColorMatrix`) and the illuminant it was measured under.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ColorMatrix {
    /// Row-major 3x3, rows are camera R, G, B.
    pub xyz_to_cam: [[f32; 3]; 3],
    /// Illuminant name as DNG calls it (e.g. "D65", "A").
    pub illuminant: String,
}

/// A decoded Bayer raw frame, visible area only.
#[derive(Clone, Debug)]
pub struct RawFrame {
    /// Visible width in pixels.
    pub width: usize,
    /// Visible height in pixels.
    pub height: usize,
    /// Row-major u16 samples in DN (black not subtracted), `width * height` of them.
    pub mosaic: Vec<u16>,
    /// Bayer phase of pixel (0, 0) of the visible area. For a monochrome
    /// frame ([`RawFrame::mono`]) there is no colour filter and this is only
    /// the order in which the packed planes hold the 2x2 sub-lattices
    /// (always RGGB's: (0,0), (0,1), (1,1), (1,0)).
    pub cfa: Cfa,
    /// A monochrome sensor (no colour filter: astronomy CCDs, Leica
    /// Monochrom). Per-pixel work (packing, calibration, synthesis,
    /// restoration, training and scoring by the packed four-plane networks)
    /// treats its 2x2 sub-lattices as four planes of one colour; nothing
    /// colour applies (no white balance, matrix, demosaic or colour cast),
    /// and what needs a camera's colour (unprocessing photos into it)
    /// refuses it ([`RawFrame::require_cfa`]).
    pub mono: bool,
    /// Black level in DN of the planes R, G1, B, G2.
    pub black: [f32; 4],
    /// Saturation level in DN.
    pub white: u32,
    /// Bits per sample the file declares (14 for most modern sensors).
    pub bits: u32,
    /// As-shot white-balance multipliers for R, G, B, normalised to G = 1.
    pub wb: Option<[f32; 3]>,
    /// Every XYZ->camera matrix the file carries (DNG ColorMatrix1/2), the
    /// D65-like one last. Raw converters interpolate between them by white
    /// balance, so a DNG written from this frame keeps all of them.
    pub color_matrices: Vec<ColorMatrix>,
    /// ISO speed from EXIF, when the file records one.
    pub iso: Option<u32>,
    /// Exposure time in seconds.
    pub exposure_s: Option<f64>,
    /// Camera maker as the file names it ("Sony"); "pgrf" for synthetic frames.
    pub make: String,
    /// Camera model as the file names it ("ILCE-7SM2").
    pub model: String,
    /// EXIF orientation (1 = as stored, 6 = rotate 90 degrees clockwise to
    /// display, ...). Pixels are never rotated; previews apply it, DNGs keep it.
    pub orientation: u16,
    /// Where the visible area starts on the full sensor readout (row, col),
    /// and the readout's size (height, width): for `pgrf info` and for
    /// checking a decode against another decoder.
    pub sensor_origin: (usize, usize),
    /// Size (height, width) of the full sensor readout; see `sensor_origin`.
    pub sensor_size: (usize, usize),
    /// Temperature at capture, degrees Celsius, when the file records one
    /// (EXIF AmbientTemperature, which DNGs pgrf writes carry): dark current
    /// doubles every few degrees, so calibration frames are checked against
    /// each other with it.
    pub temperature_c: Option<f32>,
    /// The DNG NoiseProfile of the file, when it has a usable one: (S, O)
    /// pairs, one for all planes or one per colour plane (R, G, B), with the
    /// noise variance S x + O at signal x normalised to [0, 1]. Written
    /// back into DNGs of this frame ([`crate::container::noise_profile`]).
    pub noise_profile: Option<Vec<[f64; 2]>>,
    /// The black level measured on the readout's masked (optical-black)
    /// pixels, when the file declares them ([`crate::masked`]); `black`
    /// stays the metadata's, and `pgrf enhance` chooses.
    pub masked: Option<crate::masked::Masked>,
    /// What a FITS file's header said beyond the fields above (None for
    /// camera RAW files): the one place for FITS-only data, so the fields
    /// above are those every RAW has.
    pub fits: Option<FitsHeader>,
    /// The decoder's EXIF record, carried into DNGs written from this frame so
    /// lens, date and exposure tags survive a round trip.
    pub(crate) exif: Option<rawler::decoders::RawMetadata>,
}

/// User overrides for the levels read from a file's metadata. Files lie
/// (Sony's compressed ARW reports 15360 white, its sensor clips at 16383),
/// so every level must be overridable.
#[derive(Clone, Debug, Default)]
pub struct LevelOverrides {
    /// One black level for all planes, or four for R, G1, B, G2.
    pub black: Option<Vec<f32>>,
    /// Saturation level in DN, replacing the file's.
    pub white: Option<u32>,
}

impl RawFrame {
    /// A frame built from raw samples; levels and CFA as given, no metadata.
    pub fn from_mosaic(
        width: usize,
        height: usize,
        mosaic: Vec<u16>,
        cfa: Cfa,
        black: [f32; 4],
        white: u32,
    ) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(RawError::EmptyFrame { width, height });
        }
        if mosaic.len() != width * height {
            return Err(RawError::MosaicSize {
                samples: mosaic.len(),
                width,
                height,
                needed: width * height,
            });
        }
        let frame = RawFrame {
            width,
            height,
            mosaic,
            cfa,
            mono: false,
            black,
            white,
            bits: bits_for(white),
            wb: None,
            color_matrices: Vec::new(),
            iso: None,
            exposure_s: None,
            make: String::new(),
            model: String::new(),
            orientation: 1,
            sensor_origin: (0, 0),
            sensor_size: (height, width),
            temperature_c: None,
            noise_profile: None,
            masked: None,
            fits: None,
            exif: None,
        };
        frame.check_levels()?;
        Ok(frame)
    }

    /// A monochrome frame from raw samples: one black level, no colour.
    pub fn from_mono(
        width: usize,
        height: usize,
        mosaic: Vec<u16>,
        black: f32,
        white: u32,
    ) -> Result<Self> {
        let mut frame = Self::from_mosaic(width, height, mosaic, Cfa::Rggb, [black; 4], white)?;
        frame.mono = true;
        Ok(frame)
    }

    /// The filter layout in words: the CFA's name ("RGGB") or "mono".
    pub fn layout(&self) -> &'static str {
        if self.mono {
            "mono"
        } else {
            self.cfa.name()
        }
    }

    /// Names of the packed planes for reports: R, G1, B, G2, or a
    /// monochrome frame's sub-lattices.
    pub fn plane_names(&self) -> [&'static str; 4] {
        if self.mono {
            crate::cfa::MONO_PLANE_NAMES
        } else {
            crate::cfa::PLANE_NAMES
        }
    }

    /// Per-plane levels named by plane ("R 512 G1 512 B 512 G2 512").
    pub fn plane_levels(&self, v: [f32; 4]) -> String {
        let named: Vec<String> = (self.plane_names().iter().zip(v))
            .map(|(n, b)| format!("{n} {b}"))
            .collect();
        named.join(" ")
    }

    /// Refuse a monochrome frame where colour is required; `what` says what
    /// needs it ("the SPC denoiser"). One check so every command words the
    /// refusal the same way.
    pub fn require_cfa(&self, what: &str) -> Result<()> {
        if self.mono {
            return Err(RawError::NeedsCfa {
                what: what.to_string(),
            });
        }
        Ok(())
    }

    /// Apply user overrides, then re-check that the levels make sense.
    pub(crate) fn apply_overrides(&mut self, o: &LevelOverrides) -> Result<()> {
        if let Some(b) = &o.black {
            self.black = black_per_plane(b)?;
        }
        if let Some(w) = o.white {
            self.white = w;
            // Samples up to a raised white need its bits (a FITS of 14
            // significant bits read with --white 65535).
            self.bits = self.bits.max(bits_for(w));
        }
        self.check_levels()
    }

    /// Levels that would make normalisation divide by zero, go negative or
    /// produce NaN are rejected here rather than discovered as garbage later.
    pub(crate) fn check_levels(&self) -> Result<()> {
        for (c, &b) in self.black.iter().enumerate() {
            if !b.is_finite() || b < 0.0 {
                return Err(RawError::BadBlack {
                    plane: crate::cfa::PLANE_NAMES[c],
                    black: b,
                });
            }
            if b >= self.white as f32 {
                return Err(RawError::BlackNotBelowWhite {
                    plane: crate::cfa::PLANE_NAMES[c],
                    black: b,
                    white: self.white,
                });
            }
        }
        if self.white > u16::MAX as u32 {
            return Err(RawError::WhiteTooHigh { white: self.white });
        }
        Ok(())
    }

    /// The matrix for rendering under daylight: D65, else D50/D55/daylight,
    /// else whatever the file has.
    pub fn color_matrix(&self) -> Option<&ColorMatrix> {
        ["D65", "D50", "D55", "Daylight"]
            .iter()
            .find_map(|name| self.color_matrices.iter().find(|m| m.illuminant == *name))
            .or_else(|| self.color_matrices.first())
    }

    /// Sample at (row, col).
    #[inline]
    pub fn at(&self, row: usize, col: usize) -> u16 {
        self.mosaic[row * self.width + col]
    }

    /// Width and height of the packed planes (odd trailing rows/columns are
    /// not part of any complete 2x2 cell and are left out of packing).
    pub fn packed_dims(&self) -> (usize, usize) {
        (self.height / 2, self.width / 2)
    }

    /// Black level of the pixel at (row, col).
    #[inline]
    pub fn black_at(&self, row: usize, col: usize) -> f32 {
        self.black[self.cfa.plane_at(row, col)]
    }

    /// The `height` x `width` window at (`row`, `col`), levels and metadata
    /// kept. Offsets and sizes must be even, so the window keeps the CFA's
    /// phase and every 2x2 cell whole, and the window must lie inside.
    pub fn crop(&self, row: usize, col: usize, height: usize, width: usize) -> Result<Self> {
        if ![row, col, height, width]
            .iter()
            .all(|v| v.is_multiple_of(2))
        {
            return Err(RawError::CropOdd {
                row,
                col,
                height,
                width,
            });
        }
        if height == 0
            || width == 0
            || row.checked_add(height).is_none_or(|e| e > self.height)
            || col.checked_add(width).is_none_or(|e| e > self.width)
        {
            return Err(RawError::CropOutside {
                row,
                col,
                height,
                width,
                frame_width: self.width,
                frame_height: self.height,
            });
        }
        let mut mosaic = Vec::with_capacity(height * width);
        for r in row..row + height {
            mosaic.extend_from_slice(
                &self.mosaic[r * self.width + col..r * self.width + col + width],
            );
        }
        let mut f = self.clone();
        f.mosaic = mosaic;
        f.width = width;
        f.height = height;
        f.sensor_origin = (self.sensor_origin.0 + row, self.sensor_origin.1 + col);
        // The masked pixels' level holds for any part of the sensor; their
        // strip is no longer beside the cropped pixels.
        if let Some(m) = &mut f.masked {
            m.strip = None;
        }
        Ok(f)
    }

    /// The same frame with new pixel data (levels and metadata kept): what a
    /// denoiser or a noise synthesiser produces.
    pub(crate) fn with_mosaic(&self, mosaic: Vec<u16>) -> Result<Self> {
        if mosaic.len() != self.mosaic.len() {
            return Err(RawError::MosaicReplaced {
                samples: mosaic.len(),
                expected: self.mosaic.len(),
            });
        }
        let mut f = self.clone();
        f.mosaic = mosaic;
        // New pixels (a restoration, a synthesised capture) are not what the
        // masked pixels were measured beside.
        f.masked = None;
        Ok(f)
    }
}

/// Black levels as users give them: one value for all planes, or four for
/// R, G1, B, G2.
pub(crate) fn black_per_plane(values: &[f32]) -> Result<[f32; 4]> {
    match values {
        [v] => Ok([*v; 4]),
        [r, g1, b, g2] => Ok([*r, *g1, *b, *g2]),
        other => Err(RawError::BlackCount { count: other.len() }),
    }
}

/// Smallest bit depth that holds `white`: what a frame declares when only
/// its levels are known (synthetic frames, headerless dumps).
pub fn bits_for(white: u32) -> u32 {
    (32 - white.leading_zeros()).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> RawFrame {
        RawFrame::from_mosaic(4, 2, vec![0; 8], Cfa::Rggb, [512.0; 4], 16383).unwrap()
    }

    #[test]
    fn overrides_apply_and_validate() {
        let mut f = frame();
        f.apply_overrides(&LevelOverrides {
            black: Some(vec![1.0, 2.0, 3.0, 4.0]),
            white: Some(4095),
        })
        .unwrap();
        assert_eq!(f.black, [1.0, 2.0, 3.0, 4.0]);
        assert_eq!(f.white, 4095);
        let bad = LevelOverrides {
            black: Some(vec![5000.0]),
            white: None,
        };
        let err = f.apply_overrides(&bad).unwrap_err().to_string();
        assert!(err.contains("not below the white level"), "{err}");
        let nan = LevelOverrides {
            black: Some(vec![f32::NAN]),
            white: None,
        };
        assert!(frame().apply_overrides(&nan).is_err());
        let three = LevelOverrides {
            black: Some(vec![1.0, 2.0, 3.0]),
            white: None,
        };
        assert!(frame().apply_overrides(&three).is_err());
    }

    #[test]
    fn crops_keep_the_cfa_phase_and_refuse_odd_or_outside_windows() {
        let mosaic: Vec<u16> = (0..6 * 8).map(|v| v as u16).collect();
        let f = RawFrame::from_mosaic(8, 6, mosaic, Cfa::Grbg, [1.0, 2.0, 3.0, 4.0], 4095).unwrap();
        let c = f.crop(2, 4, 4, 4).unwrap();
        assert_eq!(
            (c.width, c.height, c.cfa, c.black),
            (4, 4, Cfa::Grbg, f.black)
        );
        // Rows 2..6, columns 4..8 of a row-major 8-wide ramp.
        assert_eq!(&c.mosaic[..4], &[20, 21, 22, 23]);
        assert_eq!(c.at(3, 3), 5 * 8 + 7);
        assert_eq!(
            c.sensor_origin,
            (f.sensor_origin.0 + 2, f.sensor_origin.1 + 4)
        );
        assert_eq!(f.crop(0, 0, 6, 8).unwrap().mosaic, f.mosaic);
        for (r, c, h, w) in [
            (1, 0, 2, 2),
            (0, 2, 3, 2),
            (4, 0, 4, 2),
            (0, 6, 2, 4),
            (0, 0, 0, 2),
        ] {
            assert!(f.crop(r, c, h, w).is_err(), "({r}, {c}, {h}, {w}) accepted");
        }
        assert!(f.crop(usize::MAX - 1, 0, 2, 2).is_err());
    }

    #[test]
    fn bits_for_levels() {
        assert_eq!(bits_for(16383), 14);
        assert_eq!(bits_for(15000), 14);
        assert_eq!(bits_for(4095), 12);
        assert_eq!(bits_for(65535), 16);
    }

    #[test]
    fn size_mismatch_is_an_error() {
        assert!(RawFrame::from_mosaic(4, 4, vec![0; 8], Cfa::Rggb, [0.0; 4], 255).is_err());
        assert!(RawFrame::from_mosaic(0, 4, vec![], Cfa::Rggb, [0.0; 4], 255).is_err());
    }
}

//! Ordinary photographs (JPEG, PNG or TIFF, 8 or 16 bits per channel) as
//! training material: decoded to sRGB-encoded RGB in [0, 1] and downscaled
//! with an area filter, which averages away JPEG blocks and the camera's own
//! demosaicing before [`crate::unprocess`] turns them into a RAW mosaic.

use crate::error::{Result, SceneError};
use pgrf_raw::color::{srgb_decode, srgb_encode};
use std::path::Path;

/// A decoded photo: `height` rows of `width` pixels, R, G, B interleaved,
/// sRGB-encoded in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Photo {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `3 * width * height` values.
    pub rgb: Vec<f32>,
}

/// Decode a photo file. Refused with the reason: unreadable or truncated
/// files, CMYK images (no sRGB to invert), and grey-scale images (no colour
/// to unprocess: a camera's three channels cannot be told apart).
pub fn read_photo(path: &Path) -> Result<Photo> {
    use image::ImageDecoder as _;
    let fail = |reason: String| SceneError::Photo {
        path: path.to_path_buf(),
        reason,
    };
    let reader = image::ImageReader::open(path)
        .map_err(|e| fail(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| fail(e.to_string()))?;
    let decoder = reader
        .into_decoder()
        .map_err(|e| fail(format!("not a photo pgrf reads ({e})")))?;
    let original = decoder.original_color_type();
    if matches!(
        original,
        image::ExtendedColorType::Cmyk8 | image::ExtendedColorType::Cmyk16
    ) {
        return Err(fail(
            "CMYK image: only RGB photos can be unprocessed".into(),
        ));
    }
    let img = image::DynamicImage::from_decoder(decoder).map_err(|e| fail(e.to_string()))?;
    if !img.color().has_color() {
        return Err(fail(
            "grey-scale image: no colour to unprocess into a camera's three channels".into(),
        ));
    }
    let rgb = img.to_rgb32f();
    let (width, height) = (rgb.width() as usize, rgb.height() as usize);
    Ok(Photo {
        width,
        height,
        rgb: rgb
            .into_raw()
            .into_iter()
            .map(|v| v.clamp(0.0, 1.0))
            .collect(),
    })
}

impl Photo {
    /// The photo reduced `factor` times per side by averaging each
    /// `factor x factor` block in linear light (an area filter; a trailing
    /// partial block is dropped). `factor` 1 returns a copy.
    pub fn downscale(&self, factor: usize) -> Result<Photo> {
        if factor == 0 || self.width / factor == 0 || self.height / factor == 0 {
            return Err(SceneError::Downscale {
                width: self.width,
                height: self.height,
                factor,
            });
        }
        if factor == 1 {
            return Ok(self.clone());
        }
        let (w, h) = (self.width / factor, self.height / factor);
        let n = (factor * factor) as f32;
        let mut rgb = vec![0.0f32; w * h * 3];
        for (i, out) in rgb.chunks_mut(3).enumerate() {
            let (r, c) = (i / w, i % w);
            for (k, o) in out.iter_mut().enumerate() {
                let mut sum = 0.0f32;
                for dy in 0..factor {
                    for dx in 0..factor {
                        let (y, x) = (r * factor + dy, c * factor + dx);
                        sum += srgb_decode(self.rgb[(y * self.width + x) * 3 + k]);
                    }
                }
                *o = srgb_encode(sum / n);
            }
        }
        Ok(Photo {
            width: w,
            height: h,
            rgb,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("pgrf-photo-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Seeded test pixels (an LCG, so the test needs no RNG crate).
    fn pixels(n: usize, seed: u32) -> Vec<u16> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (s >> 16) as u16
            })
            .collect()
    }

    #[test]
    fn png_tiff_8_and_16_bit_read_back_exactly() {
        let d = scratch("formats");
        let (w, h) = (7u32, 5u32);
        let v16 = pixels((w * h * 3) as usize, 3);
        let v8: Vec<u8> = v16.iter().map(|v| (v >> 8) as u8).collect();
        let img16 = image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, v16.clone()).unwrap();
        let img8 = image::ImageBuffer::<image::Rgb<u8>, _>::from_raw(w, h, v8.clone()).unwrap();
        for (name, bits) in [
            ("a16.png", 16),
            ("a8.png", 8),
            ("a16.tif", 16),
            ("a8.tif", 8),
        ] {
            let p = d.join(name);
            if bits == 16 {
                img16.save(&p).unwrap();
            } else {
                img8.save(&p).unwrap();
            }
            let photo = read_photo(&p).unwrap();
            assert_eq!((photo.width, photo.height), (7, 5), "{name}");
            for (i, &x) in photo.rgb.iter().enumerate() {
                let want = if bits == 16 {
                    v16[i] as f32 / 65535.0
                } else {
                    v8[i] as f32 / 255.0
                };
                assert!((x - want).abs() < 1e-6, "{name} value {i}: {x} vs {want}");
            }
        }
        // A JPEG is lossy: only close (mean error under 2 of 255 on a
        // smooth image).
        let smooth = image::ImageBuffer::from_fn(32, 32, |x, y| {
            image::Rgb([(x * 6) as u8, (y * 6) as u8, 128u8])
        });
        let p = d.join("s.jpg");
        smooth.save(&p).unwrap();
        let photo = read_photo(&p).unwrap();
        let err: f32 = photo
            .rgb
            .iter()
            .zip(smooth.as_raw())
            .map(|(a, &b)| (a * 255.0 - b as f32).abs())
            .sum::<f32>()
            / photo.rgb.len() as f32;
        assert!(err < 2.0, "mean JPEG error {err} of 255");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn grey_truncated_and_junk_files_are_refused_with_the_reason() {
        let d = scratch("refuse");
        let grey = image::GrayImage::from_pixel(8, 8, image::Luma([100u8]));
        grey.save(d.join("g.png")).unwrap();
        let e = read_photo(&d.join("g.png")).unwrap_err().to_string();
        assert!(e.contains("grey-scale"), "{e}");
        let rgb = image::RgbImage::from_pixel(64, 64, image::Rgb([10, 200, 30]));
        rgb.save(d.join("c.png")).unwrap();
        let bytes = std::fs::read(d.join("c.png")).unwrap();
        std::fs::write(d.join("cut.png"), &bytes[..bytes.len() / 2]).unwrap();
        assert!(read_photo(&d.join("cut.png")).is_err());
        std::fs::write(d.join("junk.jpg"), b"not an image at all").unwrap();
        let e = read_photo(&d.join("junk.jpg")).unwrap_err().to_string();
        assert!(e.contains("junk.jpg"), "{e}");
        assert!(read_photo(&d.join("missing.png")).is_err());
        let _ = std::fs::remove_dir_all(&d);
    }

    /// The area filter averages linear light: a block of black and white
    /// pixels becomes linear 0.5 (sRGB 0.7354), not sRGB 0.5.
    #[test]
    fn downscale_averages_each_block_in_linear_light() {
        let mut rgb = Vec::new();
        for r in 0..4 {
            for c in 0..6 {
                let v = if (r + c) % 2 == 0 { 1.0 } else { 0.0 };
                rgb.extend([v, v, 0.5]);
            }
        }
        let p = Photo {
            width: 6,
            height: 4,
            rgb,
        };
        let half = p.downscale(2).unwrap();
        assert_eq!((half.width, half.height), (3, 2));
        for px in half.rgb.chunks(3) {
            assert!((px[0] - 0.735_357).abs() < 1e-4, "{px:?}");
            assert!((px[2] - 0.5).abs() < 1e-4, "{px:?}");
        }
        assert_eq!(p.downscale(1).unwrap(), p);
        assert!(p.downscale(0).is_err());
        assert!(p.downscale(5).is_err());
    }
}

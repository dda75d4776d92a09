//! Ordinary photographs as clean training images (Brooks et al., CVPR 2019,
//! "Unprocessing Images for Learned Raw Denoising"): each crop is
//! unprocessed into the target camera's RAW space by
//! [`pgrf_scenes::unprocess::unprocess_packed`], with the camera's colour
//! varied per crop so that a network learns noise, not one camera's
//! colours or one set of scenes' white balance.
//!
//! Per crop, drawn from the crop's own seed (so a run is repeatable and
//! independent of the worker count):
//! - exposure: log-uniform in [`EXPOSURE`] (linear light; values pushed
//!   past white clip there, as a sensor does);
//! - white balance: the camera's daylight multipliers, red and blue each
//!   scaled by a log-uniform factor in [1 / s, s], s = `wb_spread`
//!   ([`WB_SPREAD`] by default: about the spread of daylight, shade and
//!   flash on one camera);
//! - colour matrix: each entry of the camera's camera-from-sRGB matrix
//!   scaled by 1 + U(-[`MATRIX_SPREAD`], [`MATRIX_SPREAD`]), rows then
//!   renormalised to sum to 1 (white stays white before the white balance).
//!
//! Photos are decoded once, downscaled (area filter in linear light,
//! default 2x, which averages away JPEG blocks and the photographer's
//! camera's demosaicing), and kept as 16-bit codes within the memory budget;
//! beyond it they are decoded again when drawn.

use crate::data::cache::BudgetCache;
use crate::data::crop::Crop;
use crate::error::{NnError, Result};
use pgrf_scenes::photo::read_photo;
use pgrf_scenes::unprocess::{unprocess_packed, CameraSpace, EncodedPhoto, Unprocessing};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub use pgrf_scenes::unprocess::{EXPOSURE, MATRIX_SPREAD, WB_SPREAD};

/// File extensions read as photos (case-insensitive).
pub const PHOTO_EXTENSIONS: [&str; 5] = ["jpg", "jpeg", "png", "tif", "tiff"];

/// Whether `path` names a photo (by its extension) rather than a RAW.
pub fn is_photo(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| PHOTO_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// How photos become camera data.
#[derive(Clone, Debug)]
pub struct PhotoOptions {
    /// The camera crops are unprocessed into.
    pub camera: CameraSpace,
    /// Downscale factor per side before cropping (1: none).
    pub downscale: usize,
    /// Invert a global S-shaped tone curve before the sRGB transfer.
    pub inverse_tone: bool,
    /// Largest factor on the red and blue white-balance multipliers
    /// ([`WB_SPREAD`] by default).
    pub wb_spread: f32,
    /// Vary exposure, white balance and matrix per crop (validation and
    /// tests may want the camera's own colours).
    pub jitter: bool,
}

/// A folder's usable photos, decoded on demand and cached.
pub struct PhotoFolder {
    files: Vec<PathBuf>,
    opts: PhotoOptions,
    /// The camera's own unprocessing (checked once), which each crop's
    /// draw starts from.
    plain: Unprocessing,
    cache: BudgetCache<EncodedPhoto>,
}

fn load(path: &Path, downscale: usize) -> Result<EncodedPhoto> {
    let photo = read_photo(path)?;
    let small = photo.downscale(downscale).map_err(|e| NnError::BadData {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(EncodedPhoto::from_photo(&small))
}

impl PhotoFolder {
    /// Decode every photo of `files` (in parallel), keeping those that read
    /// and are at least `2 * patch` pixels on each side after the
    /// downscale; each one left out gives one warning line naming it and
    /// why. Refused when none is left. Decoded photos are kept up to
    /// `budget_mib` MiB.
    pub fn open(
        files: Vec<PathBuf>,
        opts: PhotoOptions,
        patch: usize,
        budget_mib: usize,
    ) -> Result<(PhotoFolder, Vec<String>)> {
        let mut plain = Unprocessing::plain(&opts.camera, 1.0)?;
        plain.inverse_tone = opts.inverse_tone;
        if opts.downscale == 0 {
            return Err(NnError::BadSetting {
                flag: "--photo-downscale",
                message: "the photo downscale must be at least 1".into(),
            });
        }
        let loaded: Vec<Result<EncodedPhoto>> = files
            .par_iter()
            .map(|p| {
                let img = load(p, opts.downscale)?;
                if img.width < 2 * patch || img.height < 2 * patch {
                    return Err(NnError::BadData {
                        path: p.clone(),
                        reason: format!(
                            "{}x{} after the {}x downscale, smaller than the {}x{} pixels a {patch}x{patch} packed crop needs",
                            img.width,
                            img.height,
                            opts.downscale,
                            2 * patch,
                            2 * patch
                        ),
                    });
                }
                Ok(img)
            })
            .collect();
        let mut warnings = Vec::new();
        let mut kept = Vec::new();
        let cache = BudgetCache::new(budget_mib);
        for (path, r) in files.into_iter().zip(loaded) {
            match r {
                Ok(img) => {
                    let bytes = img.bytes();
                    cache.offer(kept.len(), &Arc::new(img), bytes);
                    kept.push(path);
                }
                Err(e) => warnings.push(format!("skipped {e}")),
            }
        }
        if kept.is_empty() {
            return Err(NnError::BadSetting {
                flag: "--data",
                message: format!("no usable photo to train on ({} skipped)", warnings.len()),
            });
        }
        Ok((
            PhotoFolder {
                files: kept,
                opts,
                plain,
                cache,
            },
            warnings,
        ))
    }

    /// The usable photos, in the order given.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// How the photos become camera data.
    pub fn options(&self) -> &PhotoOptions {
        &self.opts
    }

    fn get(&self, i: usize) -> Result<Arc<EncodedPhoto>> {
        let load = || load(&self.files[i], self.opts.downscale);
        self.cache.get_or_load(i, load, EncodedPhoto::bytes)
    }

    /// The unprocessing of the crop with seed `seed`: the camera's own, or
    /// jittered as the module documentation says.
    pub fn unprocessing(&self, seed: u64) -> Unprocessing {
        if !self.opts.jitter {
            return self.plain.clone();
        }
        self.plain.jittered(seed, self.opts.wb_spread)
    }

    /// A packed `patch` crop of photo `pick` (modulo the count) at `(fy,
    /// fx)` in [0, 1) of the free range, unprocessed with the draw of
    /// `seed`.
    pub(crate) fn crop(
        &self,
        patch: usize,
        seed: u64,
        pick: u64,
        fy: f64,
        fx: f64,
    ) -> Result<Crop> {
        let i = (pick % self.files.len() as u64) as usize;
        let img = self.get(i)?;
        let side = 2 * patch;
        if img.width < side || img.height < side {
            return Err(NnError::BadData {
                path: self.files[i].clone(),
                reason: format!(
                    "{}x{} pixels, smaller than the {side}x{side} a {patch}x{patch} crop needs",
                    img.width, img.height
                ),
            });
        }
        let y = (((img.height - side + 1) as f64 * fy) as usize).min(img.height - side);
        let x = (((img.width - side + 1) as f64 * fx) as usize).min(img.width - side);
        let u = self.unprocessing(seed);
        let clean = unprocess_packed(&img, (y, x), patch, &self.opts.camera, &u).map_err(|e| {
            NnError::BadData {
                path: self.files[i].clone(),
                reason: e.to_string(),
            }
        })?;
        Ok(Crop {
            clean,
            plane_rows: self.opts.camera.cfa.offsets().map(|(r, _)| r),
            origin: (y / 2, x / 2),
            image: (img.height / 2, img.width / 2),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(dir: &Path, name: &str, w: u32, h: u32, seed: u32) -> PathBuf {
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let v = |k: u32| ((x * (3 + k) + y * (5 + seed + k) + k * 40) % 256) as u8;
            image::Rgb([v(0), v(1), v(2)])
        });
        let p = dir.join(name);
        img.save(&p).unwrap();
        p
    }

    fn options(jitter: bool) -> PhotoOptions {
        PhotoOptions {
            camera: CameraSpace::sony_a7s2(),
            downscale: 2,
            inverse_tone: false,
            wb_spread: WB_SPREAD,
            jitter,
        }
    }

    #[test]
    fn bad_photos_are_skipped_with_a_warning_and_none_left_is_refused() {
        let dir = std::env::temp_dir().join(format!("pgrf-photos-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let good = write_png(&dir, "good.png", 96, 80, 1);
        let small = write_png(&dir, "small.png", 40, 40, 2);
        let broken = dir.join("broken.jpg");
        std::fs::write(&broken, b"\xff\xd8\xff\xe0 not really a jpeg").unwrap();
        let files = vec![broken.clone(), good.clone(), small.clone()];
        let (f, warnings) = PhotoFolder::open(files, options(true), 16, 64).unwrap();
        assert_eq!(f.files(), &[good]);
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(warnings[0].contains("broken.jpg"), "{}", warnings[0]);
        assert!(warnings[1].contains("small.png") && warnings[1].contains("smaller"));
        let e = PhotoFolder::open(vec![broken, small], options(true), 16, 64)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("no usable photo"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The colour draws stay in their documented ranges, differ between
    /// seeds, repeat for a seed, and keep the matrix rows summing to 1.
    #[test]
    fn colour_draws_are_seeded_and_in_range() {
        let dir = std::env::temp_dir().join(format!("pgrf-photos-draw-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let p = write_png(&dir, "a.png", 64, 64, 3);
        let (f, _) = PhotoFolder::open(vec![p], options(true), 8, 16).unwrap();
        let base = CameraSpace::sony_a7s2().wb;
        let mut exposures = Vec::new();
        for seed in 0..200u64 {
            let u = f.unprocessing(seed);
            assert_eq!(u, f.unprocessing(seed));
            assert!(u.exposure >= EXPOSURE.0 && u.exposure <= EXPOSURE.1);
            for k in [0, 2] {
                let r = u.wb[k] / base[k];
                assert!(
                    (1.0 / WB_SPREAD - 1e-6..=WB_SPREAD + 1e-6).contains(&r),
                    "{r}"
                );
            }
            assert_eq!(u.wb[1], base[1]);
            for row in u.cam_from_srgb {
                assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            }
            exposures.push(u.exposure);
        }
        // Log-uniform: the geometric mean sits near sqrt(0.5 * 1.5) = 0.866
        // (200 draws: standard error of the mean log ~ 0.32/sqrt(200)).
        let gm = (exposures.iter().map(|e| e.ln()).sum::<f32>() / 200.0).exp();
        assert!((gm - 0.866).abs() < 0.06, "{gm}");
        let (plain, _) = PhotoFolder::open(f.files().to_vec(), options(false), 8, 16).unwrap();
        let u = plain.unprocessing(7);
        assert_eq!(u.exposure, 1.0);
        assert_eq!(u.wb, base);
        let c1 = f.crop(8, 5, 0, 0.5, 0.5).unwrap();
        assert_eq!(c1.clean.shape(), &[4, 8, 8]);
        assert_eq!(c1.image, (16, 16));
        assert!(c1.origin.0 <= 8 && c1.origin.1 <= 8);
        let c2 = f.crop(8, 6, 0, 0.5, 0.5).unwrap();
        assert_ne!(c1.clean, c2.clean);
        assert!(c1.clean.iter().all(|v| (0.0..=1.0).contains(v)));
        // A wider white-balance spread reaches balanced channels (the A7S2's
        // blue multiplier 1.6 divided by 2.5 is below 1); 1 keeps the
        // camera's own.
        let wide = PhotoOptions {
            wb_spread: 2.5,
            ..options(true)
        };
        let (w, _) = PhotoFolder::open(f.files().to_vec(), wide, 8, 16).unwrap();
        let ratios: Vec<f32> = (0..200u64)
            .map(|s| w.unprocessing(s).wb[2] / base[2])
            .collect();
        assert!(ratios.iter().all(|r| (0.4 - 1e-6..=2.5 + 1e-6).contains(r)));
        assert!(ratios.iter().any(|&r| r < 0.6) && ratios.iter().any(|&r| r > 1.8));
        let fixed = PhotoOptions {
            wb_spread: 1.0,
            ..options(true)
        };
        let (n, _) = PhotoFolder::open(f.files().to_vec(), fixed, 8, 16).unwrap();
        assert!((0..20u64).all(|s| n.unprocessing(s).wb == base));
        let _ = std::fs::remove_dir_all(&dir);
    }
}

//! Where clean training images come from: a folder of clean RAWs (any format
//! pgrf-raw reads) or procedural dead-leaves scenes. Either way a source hands
//! out packed, normalised `(4, P, P)` crops plus where on the sensor the crop
//! lies (for per-pixel calibration maps and row-noise parity).
//!
//! Decoding a 12-megapixel RAW costs ~100 ms, far more than one training
//! step's share of the data budget, so decoded files are kept (as packed u16,
//! half the bytes of f32) up to a memory budget; beyond it they are decoded
//! again when drawn.

use crate::data::cache::BudgetCache;
use crate::data::crop::Crop;
use crate::data::photos::PhotoFolder;
use crate::error::{NnError, Result};
use pgrf_core::seed::mix64;
use pgrf_raw::ndarray::{s, Array3};
use pgrf_raw::{decode_file, pack_u16, LevelOverrides, RawFrame};
use pgrf_scenes::{SceneKind, SceneSpec};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// One decoded clean file, packed.
struct Packed {
    planes: Array3<u16>,
    black: [f32; 4],
    white: f32,
    plane_rows: [usize; 4],
}

impl Packed {
    fn from_frame(f: &RawFrame) -> Result<Packed> {
        Ok(Packed {
            planes: pack_u16(f)?,
            black: f.black,
            white: f.white as f32,
            plane_rows: f.cfa.offsets().map(|(r, _)| r),
        })
    }

    fn shape(&self) -> (usize, usize) {
        (self.planes.shape()[1], self.planes.shape()[2])
    }

    fn crop(&self, y: usize, x: usize, h: usize, w: usize) -> Array3<f32> {
        let mut out = Array3::<f32>::zeros((4, h, w));
        for p in 0..4 {
            let scale = 1.0 / (self.white - self.black[p]);
            let src = self.planes.slice(s![p, y..y + h, x..x + w]);
            let black = self.black[p];
            out.slice_mut(s![p, .., ..])
                .zip_mut_with(&src, |o, &v| *o = (v as f32 - black) * scale);
        }
        out
    }
}

/// A folder of clean RAWs (any format pgrf-raw reads), each file decoded
/// with its own black and white levels (or the overrides given) and kept
/// packed in memory up to a budget.
pub struct Folder {
    files: Vec<PathBuf>,
    levels: LevelOverrides,
    /// Decoded files and the bytes they hold, under one lock.
    cache: BudgetCache<Packed>,
}

impl Folder {
    /// The clean RAWs `files`, decoded with `levels`; `budget_mib`: memory
    /// for decoded files in MiB (0 decodes on every draw). Refuses an empty
    /// list; files are only read when first drawn (see [`Folder::check`]).
    pub fn new(files: Vec<PathBuf>, levels: LevelOverrides, budget_mib: usize) -> Result<Folder> {
        if files.is_empty() {
            return Err(NnError::BadSetting {
                flag: "--data",
                message: "no clean RAW files to train on".into(),
            });
        }
        Ok(Folder {
            files,
            levels,
            cache: BudgetCache::new(budget_mib),
        })
    }

    /// The RAW files in `dir`, sorted by name.
    pub fn list(dir: &Path) -> Result<Vec<PathBuf>> {
        Ok(pgrf_raw::files::list_files(dir)?)
    }

    /// The files, in the order given.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    fn get(&self, i: usize) -> Result<Arc<Packed>> {
        let path = &self.files[i];
        let load = || {
            // A monochrome frame packs into its four sub-lattices as
            // enhance packs it: four half-resolution images of one scene.
            let frame = decode_file(path, &self.levels).map_err(|e| NnError::BadData {
                path: path.clone(),
                reason: e.to_string(),
            })?;
            Packed::from_frame(&frame)
        };
        self.cache.get_or_load(i, load, |p| p.planes.len() * 2)
    }

    /// Packed size of file `i` (decodes it).
    pub(crate) fn shape(&self, i: usize) -> Result<(usize, usize)> {
        Ok(self.get(i)?.shape())
    }

    /// Check every file decodes and is large enough, naming the first that is
    /// not, so a bad folder fails before training starts rather than hours in.
    /// `patch` is the crop side in packed pixels. Decodes every file (and
    /// keeps what fits in the budget).
    pub fn check(&self, patch: usize) -> Result<()> {
        for (i, path) in self.files.iter().enumerate() {
            let (h, w) = self.shape(i)?;
            if h < patch || w < patch {
                return Err(NnError::BadData {
                    path: path.clone(),
                    reason: format!(
                        "packs to {h}x{w}, smaller than the {patch}x{patch} training patch"
                    ),
                });
            }
        }
        Ok(())
    }
}

/// Clean images to train or validate on.
pub enum Source {
    /// Dead-leaves scenes from pgrf-raw's renderer, packed from an RGGB
    /// mosaic, a fresh scene (seeded per sample) for every crop: endless
    /// data with no files.
    Procedural,
    /// Crops of the clean RAWs in a folder.
    Folder(Folder),
    /// Crops of ordinary photos unprocessed into a camera's RAW space.
    Photos(PhotoFolder),
    /// Several sources, each crop drawn from one of them with probability
    /// proportional to its weight.
    Mixture(Vec<(f64, Source)>),
}

const MIX_DOMAIN: u64 = 0x6d69_7874; // "mixt"

impl Source {
    /// What the source is, in words ("procedural dead-leaves scenes",
    /// "12 clean RAW files").
    pub fn describe(&self) -> String {
        match self {
            Source::Procedural => "procedural dead-leaves scenes".into(),
            Source::Folder(f) => format!("{} clean RAW files", f.files.len()),
            Source::Photos(p) => format!(
                "{} photos unprocessed into the camera's RAW space ({}x downscale{})",
                p.files().len(),
                p.options().downscale,
                if p.options().inverse_tone {
                    ", inverse tone curve"
                } else {
                    ""
                }
            ),
            Source::Mixture(parts) => {
                let total: f64 = parts.iter().map(|(w, _)| w).sum();
                parts
                    .iter()
                    .map(|(w, s)| format!("{} ({:.0}%)", s.describe(), 100.0 * w / total))
                    .collect::<Vec<_>>()
                    .join(" + ")
            }
        }
    }

    /// A `patch` x `patch` crop: procedural scenes are rendered at exactly the
    /// patch size from `scene_seed`; files are cropped at `(fy, fx)` in [0, 1)
    /// of the free range, from file `pick` modulo the file count.
    pub(crate) fn crop(
        &self,
        patch: usize,
        scene_seed: u64,
        pick: u64,
        fy: f64,
        fx: f64,
    ) -> Result<Crop> {
        match self {
            Source::Procedural => {
                let spec = SceneSpec::new(SceneKind::DeadLeaves, 2 * patch, 2 * patch, scene_seed);
                Ok(Crop {
                    clean: pgrf_scenes::render_packed(&spec),
                    plane_rows: pgrf_raw::Cfa::Rggb.offsets().map(|(r, _)| r),
                    origin: (0, 0),
                    image: (patch, patch),
                })
            }
            Source::Folder(f) => {
                let i = (pick % f.files.len() as u64) as usize;
                let img = f.get(i)?;
                let (h, w) = img.shape();
                if h < patch || w < patch {
                    return Err(NnError::BadData {
                        path: f.files[i].clone(),
                        reason: format!("packs to {h}x{w}, smaller than the {patch}x{patch} patch"),
                    });
                }
                let y = ((h - patch + 1) as f64 * fy) as usize;
                let x = ((w - patch + 1) as f64 * fx) as usize;
                let (y, x) = (y.min(h - patch), x.min(w - patch));
                Ok(Crop {
                    clean: img.crop(y, x, patch, patch),
                    plane_rows: img.plane_rows,
                    origin: (y, x),
                    image: (h, w),
                })
            }
            Source::Photos(p) => p.crop(patch, scene_seed, pick, fy, fx),
            Source::Mixture(parts) => {
                let total: f64 = parts.iter().map(|(w, _)| w).sum();
                let u = (mix64(pick ^ MIX_DOMAIN) >> 11) as f64 / (1u64 << 53) as f64 * total;
                let mut acc = 0.0;
                let part = parts
                    .iter()
                    .find(|(w, _)| {
                        acc += w;
                        u < acc
                    })
                    .or(parts.last())
                    .ok_or_else(|| NnError::Invalid("an empty mixture of sources".into()))?;
                part.1.crop(patch, scene_seed, mix64(pick), fy, fx)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn procedural_crops_are_patch_sized_and_seeded() {
        let a = Source::Procedural.crop(32, 5, 0, 0.0, 0.0).unwrap();
        let b = Source::Procedural.crop(32, 5, 9, 0.7, 0.2).unwrap();
        let c = Source::Procedural.crop(32, 6, 0, 0.0, 0.0).unwrap();
        assert_eq!(a.clean.shape(), &[4, 32, 32]);
        assert_eq!(a.clean, b.clean);
        assert_ne!(a.clean, c.clean);
    }

    #[test]
    #[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
    fn folder_crops_normalise_with_each_files_levels() {
        let file = pgrf_core::shared_data_dir()
            .expect("../shared/data")
            .join("raw/canon550d_colorchart.dng");
        let frame = decode_file(&file, &LevelOverrides::default()).unwrap();
        let reference = pgrf_raw::pack_normalized(&frame, false).unwrap();
        let src = Source::Folder(Folder::new(vec![file], LevelOverrides::default(), 64).unwrap());
        let c = src.crop(64, 0, 0, 0.5, 1.0).unwrap();
        let (y, x) = c.origin;
        assert_eq!(x, reference.shape()[2] - 64);
        let want = reference.slice(s![.., y..y + 64, x..x + 64]);
        let err = c
            .clean
            .iter()
            .zip(want.iter())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(err < 1e-6, "{err}");
        let too_big = src.crop(100_000, 0, 0, 0.0, 0.0);
        assert!(too_big.unwrap_err().to_string().contains("smaller than"));
    }
}

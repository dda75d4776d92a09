//! From the `data` and `val_data` settings to the training and validation
//! sources.
//!
//! `data` is a comma-separated list of entries `SOURCE[@WEIGHT]`:
//! `procedural` (dead-leaves scenes), a folder or file of clean RAWs, or a
//! folder or file of photos (JPEG, PNG, TIFF by extension; see
//! [`crate::data::photos`]). A folder holding both photos and RAWs is
//! refused: give them as two entries, each with its own weight. Crops come
//! from the entries in proportion to their weights (default 1).
//!
//! Without `val_data`, a tenth of each folder's files (at least one, when
//! it has two or more) is held out for validation, and procedural entries
//! validate on procedural scenes; validation photos keep the camera's own
//! colours (no per-crop jitter) so the printed PSNR tracks one fixed set.

use crate::config::TrainConfig;
use crate::data::photos::{is_photo, PhotoFolder, PhotoOptions};
use crate::data::source::{Folder, Source};
use crate::error::{NnError, Result};
use pgrf_core::weighted::{parse_weighted, WeightedError};
use pgrf_raw::{decode_file, LevelOverrides};
use pgrf_scenes::unprocess::CameraSpace;
use std::path::{Path, PathBuf};

/// One entry of the `data` setting.
#[derive(Clone, Debug, PartialEq)]
pub struct DataEntry {
    /// `None` for procedural scenes, else the folder or file.
    pub path: Option<PathBuf>,
    /// Relative weight of the entry's crops.
    pub weight: f64,
}

/// Parse `data` (see the module documentation); refuses empty entries and
/// weights that are not positive numbers.
pub fn parse_data(text: &str) -> Result<Vec<DataEntry>> {
    let entries = parse_weighted(text).map_err(|e| {
        NnError::Config(match e {
            WeightedError::Empty => format!(
                "--data {text:?}: an empty entry (entries are SOURCE[@WEIGHT], comma-separated)"
            ),
            WeightedError::BadWeight(item) => {
                format!("--data {item:?}: the weight after @ must be a positive number")
            }
        })
    })?;
    Ok(entries
        .into_iter()
        .map(|(source, weight)| DataEntry {
            path: (source != "procedural").then(|| PathBuf::from(source)),
            weight,
        })
        .collect())
}

impl TrainConfig {
    /// The files a run reads: the `data` and `val_data` entries' files and
    /// folders (none when they do not parse), the calibration, the camera
    /// for photos and the starting weights; what no output may overwrite.
    pub fn input_files(&self) -> Vec<PathBuf> {
        let entries = |text: &str| -> Vec<PathBuf> {
            parse_data(text)
                .map(|entries| entries.into_iter().filter_map(|e| e.path).collect())
                .unwrap_or_default()
        };
        let mut inputs = entries(&self.data);
        inputs.extend(self.val_data.as_deref().map(entries).unwrap_or_default());
        inputs.extend(self.calib.clone());
        inputs.extend(self.camera_like.clone());
        inputs.extend(self.init.clone());
        inputs
    }
}

/// The training and validation sources of a configuration, and one line for
/// each file left out.
pub struct Sources {
    /// Where training crops come from.
    pub train: Source,
    /// Where the validation pairs come from.
    pub val: Source,
    /// Files skipped (unreadable, too small), one line each, to print.
    pub warnings: Vec<String>,
}

/// The camera photos are unprocessed into (see
/// [`TrainConfig::camera_like`]); with a mix of profiles, the first one's.
pub fn photo_camera(c: &TrainConfig) -> Result<CameraSpace> {
    match &c.camera_like {
        Some(path) => {
            let frame = decode_file(path, &LevelOverrides::default())
                .and_then(|f| f.require_cfa("--camera-like").map(|()| f))
                .map_err(|e| NnError::Config(format!("--camera-like {}: {e}", path.display())))?;
            CameraSpace::of(&frame)
                .map_err(|e| NnError::Config(format!("--camera-like {}: {e}", path.display())))
        }
        None => {
            // A mix unprocesses into its first camera.
            let first = pgrf_noise::mix::parse_profiles(&c.profile)
                .map_err(|e| NnError::Config(e.to_string()))?
                .swap_remove(0)
                .name;
            if first == "sony-a7s2" {
                Ok(CameraSpace::sony_a7s2())
            } else {
                Err(NnError::Config(format!(
                    "the {first} profile carries no colour matrix to unprocess photos with: give --camera-like FILE (any RAW of that camera)"
                )))
            }
        }
    }
}

/// The files of an entry given with `flag` (named in the messages): the
/// file itself, or the folder's files sorted by name; whether they are
/// photos, and the files (at least one, all of one kind).
fn entry_files(flag: &str, path: &Path) -> Result<(bool, Vec<PathBuf>)> {
    let files = if path.is_file() {
        vec![path.to_path_buf()]
    } else {
        pgrf_raw::files::list_files(path)
            .map_err(|e| NnError::Config(format!("{flag} {}: {e}", path.display())))?
    };
    let (photos, raws): (Vec<PathBuf>, Vec<PathBuf>) = files.into_iter().partition(|f| is_photo(f));
    match (photos.is_empty(), raws.is_empty()) {
        (false, false) => Err(NnError::Config(format!(
            "{flag} {}: holds both photos ({}) and RAW files ({}); give them as two entries",
            path.display(),
            photos.len(),
            raws.len()
        ))),
        (true, true) => Err(NnError::Config(format!(
            "{flag} {}: no files",
            path.display()
        ))),
        (false, true) => Ok((true, photos)),
        (true, false) => Ok((false, raws)),
    }
}

/// The last tenth of `files` (at least one) when `hold` and there are two or
/// more, else none.
fn hold_out(files: &mut Vec<PathBuf>, hold: bool) -> Option<Vec<PathBuf>> {
    (hold && files.len() >= 2).then(|| {
        let k = (files.len() / 10).max(1);
        files.split_off(files.len() - k)
    })
}

/// One source from a list of files of one kind.
fn open_files(
    c: &TrainConfig,
    photos: bool,
    files: Vec<PathBuf>,
    patch: usize,
    jitter: bool,
    budget_mib: usize,
    warnings: &mut Vec<String>,
) -> Result<Source> {
    if photos {
        let opts = PhotoOptions {
            camera: photo_camera(c)?,
            downscale: c.photo_downscale,
            inverse_tone: c.photo_inverse_tone,
            wb_spread: c.photo_wb_spread,
            jitter,
        };
        let (f, w) = PhotoFolder::open(files, opts, patch, budget_mib)?;
        warnings.extend(w);
        Ok(Source::Photos(f))
    } else {
        let f = Folder::new(files, LevelOverrides::default(), budget_mib)?;
        f.check(patch)?;
        Ok(Source::Folder(f))
    }
}

/// The validation source of one file or folder, all of it: clean RAW
/// files as they are, or photos unprocessed as `c` says (camera, downscale,
/// tone, white-balance range) with no per-crop jitter; crops of `patch`.
/// Also the files skipped, one line each. `pgrf search --val` uses it too,
/// with the model's own recorded configuration, so a flow model's second
/// time is searched on data like its validation set. Errors name `flag`
/// and `path`.
pub fn validation_source(
    c: &TrainConfig,
    flag: &str,
    path: &Path,
    patch: usize,
) -> Result<(Source, Vec<String>)> {
    let (is_photos, files) = entry_files(flag, path)?;
    let mut warnings = Vec::new();
    let v = open_files(c, is_photos, files, patch, false, 256, &mut warnings)
        .map_err(|e| NnError::Config(format!("{flag} {}: {e}", path.display())))?;
    Ok((v, warnings))
}

fn combine(mut parts: Vec<(f64, Source)>) -> Source {
    if parts.len() == 1 {
        parts.pop().expect("one part").1
    } else {
        Source::Mixture(parts)
    }
}

/// Build the sources of `c` (decodes every file once, to check it).
pub fn sources(c: &TrainConfig) -> Result<Sources> {
    let entries = parse_data(&c.data)?;
    let val_entries = c.val_data.as_deref().map(parse_data).transpose()?;
    let (patch, val_patch) = (c.patch, c.val_patch());
    let file_entries = entries.iter().filter(|e| e.path.is_some()).count().max(1);
    let budget = c.cache_mib / file_entries;
    let mut warnings = Vec::new();
    let mut train = Vec::new();
    let mut val = Vec::new();
    for e in &entries {
        let Some(path) = &e.path else {
            train.push((e.weight, Source::Procedural));
            val.push((e.weight, Source::Procedural));
            continue;
        };
        let (is_photos, mut files) = entry_files("--data", path)?;
        let held = hold_out(&mut files, val_entries.is_none());
        let val_files = held.unwrap_or_else(|| files.clone());
        train.push((
            e.weight,
            open_files(c, is_photos, files, patch, true, budget, &mut warnings)?,
        ));
        if val_entries.is_none() {
            let mut quiet = Vec::new();
            let v = open_files(c, is_photos, val_files, val_patch, false, 256, &mut quiet)?;
            warnings.extend(quiet.into_iter().map(|w| format!("validation: {w}")));
            val.push((e.weight, v));
        }
    }
    if let Some(ves) = val_entries {
        for e in ves {
            let Some(path) = &e.path else {
                val.push((e.weight, Source::Procedural));
                continue;
            };
            let (v, w) = validation_source(c, "--val-data", path, val_patch)?;
            warnings.extend(w.into_iter().map(|w| format!("validation: {w}")));
            val.push((e.weight, v));
        }
    }
    Ok(Sources {
        train: combine(train),
        val: combine(val),
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_entries_parse_with_weights() {
        let e = parse_data("procedural@0.25, /photos").unwrap();
        assert_eq!(e.len(), 2);
        assert_eq!((e[0].path.clone(), e[0].weight), (None, 0.25));
        assert_eq!(e[1].path.as_deref(), Some(Path::new("/photos")));
        assert_eq!(e[1].weight, 1.0);
        for bad in [
            "",
            "a,,b",
            "procedural@0",
            "procedural@-1",
            "x@nan",
            "x@two",
        ] {
            assert!(parse_data(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn photos_need_a_camera_with_a_matrix() {
        let c = TrainConfig {
            profile: "nikon-d850".into(),
            ..TrainConfig::default()
        };
        let e = photo_camera(&c).unwrap_err().to_string();
        assert!(e.contains("--camera-like"), "{e}");
        assert!(photo_camera(&TrainConfig::default()).is_ok());
    }

    #[test]
    fn a_folder_of_photos_and_raws_is_refused() {
        let dir = std::env::temp_dir().join(format!("pgrf-build-mixed-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("a.jpg"), b"x").unwrap();
        std::fs::write(dir.join("b.dng"), b"x").unwrap();
        let e = entry_files("--data", &dir).unwrap_err().to_string();
        assert!(e.contains("both photos (1) and RAW files (1)"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

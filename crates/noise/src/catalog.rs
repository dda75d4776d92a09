//! Where a `--profile` name leads: a built-in profile, a DNG's NoiseProfile
//! tag (`dng:FILE.dng`), a camera of darktable's noiseprofiles.json
//! (`darktable:MAKER MODEL`) or a profile JSON file; and the built-in
//! profiles as `pgrf profiles list` shows them.
//!
//! Kept apart from [`crate::profile`] (what a profile is and holds) because
//! the readers of other tools' formats ([`crate::pg_profile`],
//! [`crate::darktable`]) build profiles: the profile module imports neither.

use crate::darktable;
use crate::error::{NoiseError, Result};
use crate::pg_profile::{self, ProfileView};
use crate::profile::{built_in_names, CameraProfile};
use std::path::Path;

impl CameraProfile {
    /// A built-in name, `dng:FILE.dng` (the file's NoiseProfile tag at its
    /// ISO, [`crate::pg_profile`]), `darktable:MAKER MODEL` (a camera of
    /// darktable's noiseprofiles.json, [`crate::darktable`]) or a path to a
    /// JSON file, validated. `darktable` names darktable's file (else its
    /// install is searched: [`darktable::locate`]).
    pub fn load(name_or_path: &str, darktable: Option<&Path>) -> Result<CameraProfile> {
        if let Some(p) = Self::built_in(name_or_path) {
            return Ok(p);
        }
        if let Some(file) = name_or_path.strip_prefix("dng:") {
            return pg_profile::from_dng(file);
        }
        if let Some(camera) = name_or_path.strip_prefix("darktable:") {
            return darktable::load(camera, darktable);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(NoiseError::Profile {
                name: name_or_path.to_string(),
                reason: format!(
                    "no such file, and not a built-in profile ({})",
                    built_in_names().join(", ")
                ),
            });
        }
        let text = std::fs::read_to_string(path).map_err(|e| NoiseError::Profile {
            name: name_or_path.to_string(),
            reason: e.to_string(),
        })?;
        Self::from_json(name_or_path, &text)
    }
}

/// Every built-in profile (`--profile NAME`) with what it holds, in
/// [`built_in_names`] order.
pub fn built_in_views() -> Vec<(&'static str, ProfileView)> {
    built_in_names()
        .into_iter()
        .map(|n| {
            (
                n,
                pg_profile::view(&CameraProfile::built_in(n).expect("built-in")),
            )
        })
        .collect()
}

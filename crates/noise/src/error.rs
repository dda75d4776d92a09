//! Errors of the noise crate, one line each.
//!
//! Each variant names the setting, map or file that was refused and what was
//! wrong with it, so a caller can act on the case; the message is the one
//! line the CLI prints.

use pgrf_core::number::shown;
use std::path::PathBuf;

/// Why a profile, a noise setting or an output was refused.
#[derive(Debug, thiserror::Error)]
pub enum NoiseError {
    /// A camera profile that is unknown, unreadable or fails validation
    /// (missing keys, negative standard deviations, unsorted ISO table).
    #[error("profile {name}: {reason}")]
    Profile {
        /// The profile's name or file.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A number outside the range it must lie in (an exposure ratio, an
    /// exposure time, a gain, a noise scale, a map's constant value).
    #[error("invalid noise setting: {name} must be {must}, got {value}")]
    Setting {
        /// The setting.
        name: &'static str,
        /// What it must be ("> 0", "finite and >= 0").
        must: &'static str,
        /// What it was.
        value: f32,
    },
    /// A per-plane map value outside the range it must lie in.
    #[error("invalid noise setting: {name} must be {must}, got {value:?}")]
    PlaneSetting {
        /// The map.
        name: &'static str,
        /// What its values must be.
        must: &'static str,
        /// Its four values (R, G1, B, G2).
        value: [f32; 4],
    },
    /// An ISO range that is not positive and ordered.
    #[error("invalid noise setting: ISO range {lo}..{hi} must be positive and ordered")]
    IsoRange {
        /// Lowest ISO.
        lo: u32,
        /// Highest ISO.
        hi: u32,
    },
    /// A range to draw from (ratio, exposure) that is not positive and ordered.
    #[error("invalid noise setting: {name} range {lo}..{hi} is not positive and ordered")]
    DrawRange {
        /// "ratio" or "exposure".
        name: &'static str,
        /// Its low end.
        lo: f32,
        /// Its high end.
        hi: f32,
    },
    /// A per-pixel map whose shape is not the image's packed shape.
    #[error("invalid noise setting: {map} map has shape {shape:?}, the image packs to [4, {}, {}]", .packed.0, .packed.1)]
    MapShape {
        /// The map.
        map: &'static str,
        /// Its shape.
        shape: Vec<usize>,
        /// The image's packed (height, width).
        packed: (usize, usize),
    },
    /// A per-pixel map not in standard (row-major, contiguous) layout.
    #[error("invalid noise setting: {map} map is not in standard layout")]
    MapLayout {
        /// The map.
        map: &'static str,
    },
    /// A crop window that leaves its map.
    #[error("invalid noise setting: crop {}x{} at ({}, {}) leaves the {}x{} map", .size.0, .size.1, .at.0, .at.1, .map.0, .map.1)]
    CropOutside {
        /// The window's (y, x), packed.
        at: (usize, usize),
        /// The window's (height, width), packed.
        size: (usize, usize),
        /// The map's (height, width), packed.
        map: (usize, usize),
    },
    /// A fixed-pattern map with 1 + N_FP below zero somewhere.
    #[error("invalid noise setting: n_fp must be >= -1 (1 + N_FP >= 0), min is {min}")]
    FixedPatternBelow {
        /// Its smallest value.
        min: f32,
    },
    /// A per-pixel map value outside what a sensor can have.
    #[error("invalid noise setting: {map} map has an invalid value {} at flat index {index} (must be in {lo}..={hi})", shown(*.value as f64))]
    MapValue {
        /// The map.
        map: &'static str,
        /// The value.
        value: f32,
        /// Its flat index in the map.
        index: usize,
        /// The smallest value allowed.
        lo: f32,
        /// The largest value allowed.
        hi: f32,
    },
    /// A clean image that is not packed `(4, H, W)`.
    #[error("invalid noise setting: clean image must be packed (4, H, W), got {shape:?}")]
    ImageShape {
        /// Its shape.
        shape: Vec<usize>,
    },
    /// Plane row parities other than 0 or 1.
    #[error("invalid noise setting: plane_rows holds row parities (0 or 1)")]
    PlaneRows {
        /// The parities given.
        rows: [usize; 4],
    },
    /// A non-finite value in the clean image or a per-pixel map, found while
    /// synthesising.
    #[error("invalid noise setting: non-finite value in the clean image or in a per-pixel map")]
    NonFinite,
    /// A virtual-sensor preset pgrf does not know.
    #[error("invalid noise setting: unknown sensor preset '{name}' (use a7s2-iso<ISO>, e.g. a7s2-iso1600)")]
    UnknownPreset {
        /// The name given.
        name: String,
    },
    /// A virtual-sensor size that is odd or below 4 x 4.
    #[error(
        "invalid noise setting: virtual sensor size {width}x{height} must be even and at least 4x4"
    )]
    SensorSize {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
    /// A frame the RAW layer refused to pack or build.
    #[error("invalid noise setting: {error}")]
    Frame {
        /// What the RAW layer refused.
        error: pgrf_raw::RawError,
    },
    /// A noise-component list with a letter pgrf does not know.
    #[error("invalid noise setting: unknown noise component '{component}' in '{list}' (use P, G, H, Q, F, A)")]
    UnknownComponent {
        /// The letter.
        component: char,
        /// The list given.
        list: String,
    },
    /// A maps file that cannot be read, written or decoded.
    #[error("invalid noise setting: {}: {reason}", path.display())]
    MapsFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// An ISO at which a profile's gain leaves every sensor's range.
    #[error("invalid noise setting: ISO {iso} gives a gain of {} DN/e- with the {profile} profile, beyond any sensor (at most {max})", shown(*.k))]
    GainBeyond {
        /// The ISO.
        iso: u32,
        /// The gain it gives, DN/e-.
        k: f64,
        /// The profile.
        profile: String,
        /// The largest gain pgrf accepts (`profile::MAX_GAIN`).
        max: f64,
    },
    /// An ISO at which a profile's noise scales leave every sensor's range.
    #[error("invalid noise setting: ISO {iso} gives noise scales {scales:?} DN with the {profile} profile, beyond {max}")]
    ScalesBeyond {
        /// The ISO.
        iso: u32,
        /// Tukey scale, Gaussian read sigma and row sigma, DN.
        scales: [f64; 3],
        /// The profile.
        profile: String,
        /// The largest scale pgrf accepts, DN (`profile::MAX_SIGMA_DN`).
        max: f64,
    },
    /// ISO 0.
    #[error("invalid noise setting: ISO must be positive")]
    ZeroIso,
    /// An ISO outside a profile's per-ISO table.
    #[error("invalid noise setting: ISO {iso} is outside the range the {profile} profile was calibrated for ({lo}..={hi})")]
    IsoOutside {
        /// The ISO.
        iso: u32,
        /// The profile.
        profile: String,
        /// Its lowest ISO.
        lo: u32,
        /// Its highest ISO.
        hi: u32,
    },
    /// An ISO asked of a profile that has no way to use one.
    #[error("invalid noise setting: the {profile} profile has neither a per-ISO table nor a K-per-ISO relation; omit the ISO to sample K from its range")]
    NoIsoRelation {
        /// The profile.
        profile: String,
    },
    /// A malformed profile list (`NAME[@WEIGHT],...`).
    #[error("invalid noise setting: profile list {list:?}: {reason}")]
    ProfileList {
        /// The list given.
        list: String,
        /// The entry and what is wrong with it.
        reason: String,
    },
    /// A setting refused with a message and nothing more to act on.
    #[error("invalid noise setting: {0}")]
    Invalid(String),
    /// The frame's noise could not be estimated from its pixels (too few
    /// unclipped flat blocks); the message says what was found.
    #[error("blind noise estimate: {0}")]
    Estimate(String),
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
}

/// Result of every fallible function of the noise crate.
pub type Result<T> = std::result::Result<T, NoiseError>;

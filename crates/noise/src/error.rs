//! Errors of the noise crate, one line each.
//!
//! Each variant names the setting, map or file that was refused and what was
//! wrong with it, so a caller can act on the case; the message is the one
//! line the CLI prints.

use crate::profile::{MAX_GAIN, MAX_SIGMA_DN};
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
    /// A camera profile whose values fail validation; the
    /// [`ProfileFault`] names the field, for callers that point at it.
    #[error("profile {name}: {fault}")]
    ProfileValues {
        /// The profile's name or file.
        name: String,
        /// The field and what is wrong with it.
        fault: ProfileFault,
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
    /// A noise bank that cannot be drawn from.
    #[error("invalid noise setting: {0}")]
    Bank(String),
    /// A frame whose noise an estimate would misstate: a calibration frame,
    /// or one whose black level is unknown.
    #[error("{why}")]
    NotAPhoto {
        /// Why, in a sentence.
        why: String,
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

/// Why a camera profile's values were refused
/// ([`crate::CameraProfile::from_json`]): each names the field at fault, in
/// the profile's own key names.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ProfileFault {
    /// A schema other than 1.
    #[error("schema {0} is not supported (expected 1)")]
    Schema(u32),
    /// A field that must be a positive number (`dn_range`, `k_min`, a gain).
    #[error("{field} must be a positive number, got {}", shown(*.value))]
    NotPositive {
        /// The field.
        field: String,
        /// Its value.
        value: f64,
    },
    /// A `dn_range` beyond a 16-bit scale.
    #[error("dn_range must be at most 65535 (a 16-bit scale), got {}", shown(*.0))]
    DnRange(f64),
    /// A gain range whose top is below its bottom.
    #[error("k_max {k_max} is below k_min {k_min}")]
    GainRangeReversed {
        /// Its bottom, DN/e-.
        k_min: f64,
        /// Its top, DN/e-.
        k_max: f64,
    },
    /// A gain above any sensor's ([`crate::profile::MAX_GAIN`]).
    #[error("{field} {} DN/e- is beyond any sensor (at most {})", shown(*.value), MAX_GAIN)]
    GainBeyond {
        /// The field.
        field: String,
        /// Its value, DN/e-.
        value: f64,
    },
    /// A black level that is negative or not a number.
    #[error("black must be >= 0, got {0}")]
    Black(f64),
    /// ELD's fits without a Tukey shape.
    #[error("eld.tukey_shapes is empty")]
    NoTukeyShapes,
    /// One of ELD's scale fits with a non-finite value or a negative sigma.
    #[error("eld.{fit} has a non-finite value or a negative sigma")]
    FitNotFinite {
        /// The fit (`tukey_scale`, `gauss_scale`, `row_scale`).
        fit: &'static str,
    },
    /// One of ELD's scale fits that leaves every sensor's noise over the
    /// gain range.
    #[error("eld.{fit} gives noise scales above {} DN (or a fit sigma above 10) over the gain range {k_min}..{k_max}", MAX_SIGMA_DN)]
    FitUnbounded {
        /// The fit.
        fit: &'static str,
        /// The profile's lowest gain, DN/e-.
        k_min: f64,
        /// Its highest, DN/e-.
        k_max: f64,
    },
    /// A Tukey shape that is not finite.
    #[error("eld.tukey_shapes has a non-finite value")]
    TukeyShapeNotFinite,
    /// A colour-bias table with another number of rows than Tukey shapes.
    #[error("eld.color_bias has {rows} rows, tukey_shapes {shapes} (one per calibration setting)")]
    ColorBiasRows {
        /// Rows of `eld.color_bias`.
        rows: usize,
        /// Entries of `eld.tukey_shapes`.
        shapes: usize,
    },
    /// A per-ISO table out of order.
    #[error("per_iso must be sorted by increasing ISO (ISO {iso} after {previous})")]
    IsoOrder {
        /// The ISO out of place.
        iso: u32,
        /// The ISO before it.
        previous: u32,
    },
    /// A per-ISO standard deviation outside what a sensor can have.
    #[error("per_iso[{iso}].{what} must be a standard deviation in 0..={} DN, got {}", MAX_SIGMA_DN, shown(*.value))]
    Sigma {
        /// The row's ISO.
        iso: u32,
        /// The field (`sigma_tukey`, `sigma_gauss`, `sigma_row`).
        what: &'static str,
        /// Its value, DN.
        value: f64,
    },
    /// A per-ISO row with a non-finite Tukey shape or black-level error.
    #[error("per_iso[{iso}] has a non-finite value")]
    IsoNotFinite {
        /// The row's ISO.
        iso: u32,
    },
    /// A dark-current rate that is negative or not a number.
    #[error("dark_current.rate must be >= 0, got {0}")]
    DarkRate(f64),
}

/// Result of every fallible function of the noise crate.
pub type Result<T> = std::result::Result<T, NoiseError>;

//! Calibration errors: one line each, naming the file when there is one.
//!
//! Each variant names the input that was refused and what was wrong with it,
//! so a caller can act on the case (another camera, too few frames, a
//! damaged file) without reading the message; the message is the one line
//! the CLI prints.

use pgrf_core::number::shown;
use std::path::PathBuf;

/// Why a calibration could not be made, read, written or applied.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// An output that may not be written (missing folder, an input, named
    /// twice).
    #[error(transparent)]
    Path(#[from] pgrf_core::paths::PathError),
    /// An option's value that no input can make right (named by `flag`).
    #[error("{message}")]
    BadOption {
        /// The option, e.g. "--masters".
        flag: &'static str,
        /// What was wrong, on one line.
        message: String,
    },
    /// A frame could not be decoded or packed.
    #[error(transparent)]
    Raw(#[from] pgrf_raw::RawError),
    /// The maps file could not be read or written, or the maps are invalid
    /// for the noise model.
    #[error(transparent)]
    Noise(#[from] pgrf_noise::NoiseError),
    /// A stack with fewer frames than its per-pixel variance needs.
    #[error("{stack} stack has {count} frame{}; per-pixel variance needs at least {needed}", plural(.count))]
    TooFewFrames {
        /// "bias", "dark" or "flat".
        stack: String,
        /// Frames given.
        count: usize,
        /// Frames needed.
        needed: usize,
    },
    /// A frame that differs from the other frames of its stack (size, CFA,
    /// ISO or camera).
    #[error("{}: {} ({stack} stack)", file.display(), mismatch(*.what, .expected, .found))]
    MismatchedFrame {
        /// The frame.
        file: PathBuf,
        /// "bias", "dark" or "flat".
        stack: String,
        /// What differs.
        what: FrameField,
        /// The other frames' value ("4000x3000", "RGGB", "ISO 100", "Sony ILCE-7SM2").
        expected: String,
        /// The frame's value.
        found: String,
    },
    /// A dark or flat frame without an exposure time in its metadata.
    #[error("{}: no exposure time in the file's metadata ({stack} frames are grouped by exposure)", file.display())]
    NoExposure {
        /// The frame.
        file: PathBuf,
        /// "dark" or "flat".
        stack: String,
    },
    /// A frame of a single-exposure stack (bias) at another exposure time.
    #[error("{}: exposure {found} s differs from the other {stack} frames' {expected} s", file.display())]
    MixedExposure {
        /// The frame.
        file: PathBuf,
        /// "bias".
        stack: String,
        /// The other frames' exposure, s.
        expected: f64,
        /// The frame's exposure, s.
        found: f64,
    },
    /// An exposure of a stack with fewer frames than its variance needs.
    #[error("{stack} stack: only one frame at exposure {exposure_s} s ({}); each exposure needs at least {needed} (its per-pixel variance is measured)", file.display())]
    TooFewAtExposure {
        /// "bias" or "flat".
        stack: String,
        /// The exposure, s.
        exposure_s: f64,
        /// Its one frame.
        file: PathBuf,
        /// Frames each exposure needs.
        needed: usize,
    },
    /// A stack without frames.
    #[error("{stack} stack is empty")]
    EmptyStack {
        /// "bias", "dark" or "flat".
        stack: String,
    },
    /// A stack with too few exposure times for its fit.
    #[error("{stack} stack has one exposure time ({exposure_s} s); fitting a dark-current law needs at least {needed}")]
    TooFewExposures {
        /// "dark".
        stack: String,
        /// Its one exposure, s.
        exposure_s: f64,
        /// Exposure times needed.
        needed: usize,
    },
    /// A flat level without a pair of frames for the gain.
    #[error(
        "flat frames at {exposure_s} s: no pair of frames (the gain needs two frames per level)"
    )]
    NoFlatPair {
        /// The level's exposure, s.
        exposure_s: f64,
    },
    /// A flat level no brighter than the bias frames.
    #[error("flat frames at {exposure_s} s are not brighter than the bias frames (mean {mean_dn:.2} DN above bias)")]
    FlatNotBrighter {
        /// The level's exposure, s.
        exposure_s: f64,
        /// Its mean signal above the bias, DN.
        mean_dn: f64,
    },
    /// Every flat level clipped at the white level.
    #[error("flat frames at {exposure_s} s are saturated: {:.1} % of pixels reach the white level {white} within 3 sigma (a clipped flat has too little variance, and the gain comes out wrong or negative); every flat level is, so lower the light or the exposure", 100.0 * .clipped)]
    SaturatedFlats {
        /// The last clipped level's exposure, s.
        exposure_s: f64,
        /// Its share of pixels within 3 sigma of white (a fraction).
        clipped: f64,
        /// The white level, DN.
        white: u32,
    },
    /// A gain estimate that is not a positive number.
    #[error("system gain estimate {k} is not positive: are the flat frames lit and unsaturated?")]
    BadGain {
        /// The estimate, DN/e-.
        k: f64,
    },
    /// Frames taken further apart in temperature than the run allows.
    #[error("{}: taken at {temperature_c:.1} °C, the frames' median is {median_c:.1} °C; frames more than {tolerance} °C apart are not one calibration (dark current doubles every 5-7 °C): shoot at one temperature, or allow more with --temperature-tolerance", file.display())]
    TemperatureSpread {
        /// The frame furthest from the median.
        file: PathBuf,
        /// Its temperature, degrees C.
        temperature_c: f32,
        /// The frames' median, degrees C.
        median_c: f32,
        /// The allowed distance, degrees C.
        tolerance: f32,
    },
    /// Bias frames of another ISO than the one asked for.
    #[error("bias frames are ISO {found} ({}), --iso asked for {asked}", file.display())]
    StackIso {
        /// The first bias frame.
        file: PathBuf,
        /// The frames' ISO.
        found: u32,
        /// The ISO asked for.
        asked: u32,
    },
    /// A calibration applied to a frame of another camera.
    #[error("calibration is of '{calibration}', the frame is from '{frame}' (use --force to apply it anyway)")]
    WrongCamera {
        /// The calibration's camera, "MAKE MODEL".
        calibration: String,
        /// The frame's camera, "MAKE MODEL".
        frame: String,
    },
    /// A calibration applied to a frame of another ISO.
    #[error("calibration is for ISO {calibration}, the frame is ISO {frame} (use --force to apply it anyway)")]
    WrongIso {
        /// The calibration's ISO.
        calibration: u32,
        /// The frame's ISO.
        frame: u32,
    },
    /// A calibration applied to a frame of another filter layout.
    #[error("calibration is of a {calibration} sensor, the frame's layout is {frame}")]
    WrongLayout {
        /// The calibration's layout (a CFA phase or "mono").
        calibration: String,
        /// The frame's layout.
        frame: String,
    },
    /// A calibration applied to a frame whose rows are stored the other way
    /// up: every map would sit on the mirrored row.
    #[error("calibration's frames stored their rows {calibration}, the frame's are {frame} (FITS ROWORDER; none is BOTTOM-UP): its maps would lie upside down on the frame")]
    WrongRowOrder {
        /// The calibration frames' row order.
        calibration: &'static str,
        /// The frame's.
        frame: &'static str,
    },
    /// A calibration applied to a noise model without per-pixel maps.
    #[error("a calibration applies to the pgrf noise model (per-pixel maps), not {kind:?}")]
    WrongModel {
        /// The model asked for.
        kind: pgrf_noise::ModelKind,
    },
    /// An exposure time that is not a non-negative number of seconds.
    #[error("exposure time must be a non-negative number of seconds, got {exposure_s}")]
    BadExposure {
        /// The exposure asked for, s.
        exposure_s: f64,
    },
    /// A master frame that could not be made into a RAW frame of the camera.
    #[error("{error}")]
    Master {
        /// The master's name (`master_bias`, ...).
        master: String,
        /// What the RAW layer refused.
        error: pgrf_raw::RawError,
    },
    /// The calibration record could not be encoded.
    #[error("{0}")]
    EncodeRecord(serde_json::Error),
    /// A calibration file that could not be read.
    #[error("{}: {error}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// A maps file that is not a pgrf calibration.
    #[error("{}: not a pgrf calibration file", path.display())]
    NotCalibration {
        /// The file.
        path: PathBuf,
    },
    /// A calibration record that cannot be read or fails its checks.
    #[error("{}: bad calibration record: {fault}", path.display())]
    BadRecord {
        /// The file.
        path: PathBuf,
        /// The field and what is wrong with it.
        fault: RecordFault,
    },
    /// A map whose shape disagrees with the record's frame size.
    #[error("{}: map '{map}' has shape {shape:?}, the record says {expected:?}", path.display())]
    MapShape {
        /// The file.
        path: PathBuf,
        /// The map's name.
        map: String,
        /// Its shape.
        shape: Vec<usize>,
        /// The shape the record's frame size asks: packed, or for a
        /// monochrome sensor one plane of its pixels.
        expected: [usize; 3],
    },
    /// A calibration file without one of the required maps.
    #[error("{}: calibration has no '{map}' map", path.display())]
    MissingMap {
        /// The file.
        path: PathBuf,
        /// The missing map.
        map: String,
    },
    /// A calibration file with a map pgrf does not know.
    #[error("{}: unknown map '{map}' in a calibration file", path.display())]
    UnknownMap {
        /// The file.
        path: PathBuf,
        /// The unknown map.
        map: String,
    },
    /// Maps with values the noise model cannot use.
    #[error("{}: {error}", path.display())]
    MapValues {
        /// The file.
        path: PathBuf,
        /// What the noise model refused.
        error: pgrf_noise::NoiseError,
    },
    /// The darktable file to merge into could not be read.
    #[error("--darktable-into {}", path.display())]
    DarktableRead {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The darktable file to merge into is not darktable's format.
    #[error("--darktable-into")]
    DarktableParse {
        /// What the parser refused.
        #[source]
        source: pgrf_noise::NoiseError,
    },
    /// A darktable entry asked for frames that lack what darktable finds an
    /// entry by (ISO, maker, model).
    #[error("--darktable-into {}: the frames {what}, and darktable finds a profile by maker, model and ISO", path.display())]
    DarktableUnnamed {
        /// The darktable file.
        path: PathBuf,
        /// What the frames lack, and the option that gives it.
        what: &'static str,
    },
    /// The darktable entry could not be merged into its file.
    #[error("{flag} {}", path.display())]
    DarktableMerge {
        /// The option that named the file.
        flag: &'static str,
        /// The darktable file.
        path: PathBuf,
        /// Why.
        #[source]
        source: pgrf_noise::NoiseError,
    },
    /// The darktable file could not be written.
    #[error("{}", path.display())]
    DarktableWrite {
        /// The darktable file.
        path: PathBuf,
        /// Why.
        #[source]
        source: pgrf_core::WriteError,
    },
    /// An output folder could not be created.
    #[error("{}: cannot create {what}", path.display())]
    CreateFolder {
        /// The folder.
        path: PathBuf,
        /// Which ("the masters folder", "report folder").
        what: &'static str,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A master frame could not be encoded or written.
    #[error("--masters {}", path.display())]
    WriteMaster {
        /// The master's file.
        path: PathBuf,
        /// Why.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The defect picture could not be written.
    #[error(transparent)]
    DefectPicture(pgrf_raw::RawError),
    /// Inputs refused with a message and nothing more to act on.
    #[error("{0}")]
    Invalid(String),
}

/// What differs between a frame and the other frames of its stack.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameField {
    /// Width x height.
    Size,
    /// The filter layout.
    Cfa,
    /// The ISO ("ISO 100", or "no ISO").
    Iso,
    /// Maker and model.
    Camera,
    /// The stored row order (a FITS file's ROWORDER): frames stored the
    /// other way up would be averaged upside down against the rest.
    RowOrder,
    /// XBINNING x YBINNING: binned and unbinned frames do not average.
    Binning,
}

/// Result of every fallible function of the calibration crate.
pub type Result<T> = std::result::Result<T, CalibError>;

fn plural(n: &usize) -> &'static str {
    if *n == 1 {
        ""
    } else {
        "s"
    }
}

fn mismatch(what: FrameField, expected: &str, found: &str) -> String {
    match what {
        FrameField::Size => format!("size {found} differs from the other frames' {expected}"),
        FrameField::Cfa => format!("CFA {found} differs from the other frames' {expected}"),
        FrameField::Iso => format!("{found} differs from the other frames' {expected}"),
        FrameField::Camera => {
            format!("camera '{found}' differs from the other frames' '{expected}'")
        }
        FrameField::Binning => format!(
            "binning {found} (XBINNING x YBINNING) differs from the other frames' {expected}"
        ),
        FrameField::RowOrder => format!(
            "row order {found} (ROWORDER; a FITS file without one is BOTTOM-UP) differs from the other frames' {expected}"
        ),
    }
}

/// What is wrong with a calibration record
/// ([`crate::Calibration::from_bytes`]): it is not the record's JSON, or a
/// value that synthesis and restoration rely on is out of its range; each
/// names the field.
#[derive(Debug, thiserror::Error)]
pub enum RecordFault {
    /// The record's JSON has missing, unknown or mistyped keys.
    #[error("{0}")]
    Json(serde_json::Error),
    /// A frame size that is odd, below 2 or beyond the largest side.
    #[error("frame size {width}x{height} (must be even, 2..{max} on each side)")]
    FrameSize {
        /// Width, pixels.
        width: usize,
        /// Height, pixels.
        height: usize,
        /// The largest side accepted.
        max: usize,
    },
    /// A CFA name that is none of the four Bayer phases nor "mono".
    #[error("unknown CFA '{0}'")]
    Cfa(String),
    /// A white level outside 1..65535.
    #[error("white level {0} (must be 1..65535)")]
    White(u32),
    /// A black level that is negative, not a number, or not below white.
    #[error("black level {} (must be at least 0 and below the white level {white})", shown(*.black as f64))]
    Black {
        /// The black level, DN.
        black: f32,
        /// The white level, DN.
        white: u32,
    },
    /// A gain that is not positive or beyond any sensor's.
    #[error("gain K {} DN/e- (must be positive and at most {max}, more than any sensor)", shown(*.k))]
    Gain {
        /// The gain, DN/e-.
        k: f64,
        /// The largest gain accepted.
        max: f64,
    },
    /// A noise figure or exposure outside 0..=65535.
    #[error("{field} {} (must be a number in 0..=65535)", shown(*.value))]
    Figure {
        /// The field (`row_sigma`, `dsnu`, ...).
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// ISO 0.
    #[error("ISO 0")]
    ZeroIso,
    /// A dark or flat exposure that is not a time.
    #[error("exposure {} s (must be a number in 0..=1e6)", shown(*.0))]
    Exposure(f64),
    /// A mean dark rate that is not a finite rate.
    #[error("dark_rate_mean {} (must be a finite rate)", shown(*.0))]
    DarkRate(f64),
    /// A mean dark offset that is not finite or beyond the white level.
    #[error("dark_offset_mean {} DN (must be finite and within the white level)", shown(*.0))]
    DarkOffset(f64),
}

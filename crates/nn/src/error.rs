//! One error type for the network crate: every failure reaches the user as
//! one line, so a message carries its own context (file, step, reason), and
//! the variants a caller may act on are told apart.

use std::path::PathBuf;

/// Why a network, weight file, configuration or run was refused.
#[derive(Debug, thiserror::Error)]
pub enum NnError {
    /// A weight or checkpoint file that cannot be used: unreadable, not a
    /// pgrf weight file, damaged, or from a newer pgrf.
    #[error("{}: {reason}", path.display())]
    BadFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A weight file that holds the other method than the one asked for.
    #[error("{}: holds {found}, not {wanted}", path.display())]
    WrongMethod {
        /// The file.
        path: PathBuf,
        /// The method asked for.
        wanted: crate::Method,
        /// A description of what the file holds.
        found: String,
    },
    /// Tensors or arrays whose shapes do not fit each other (weights and
    /// architecture, a map and a frame, an input and a network).
    #[error("{0}")]
    SizeMismatch(String),
    /// A network or training configuration that cannot be built.
    #[error("{0}")]
    Config(String),
    /// A network configuration (a weight file's record, or what a run's
    /// settings make) that pgrf cannot build, by cause.
    #[error(transparent)]
    Architecture(#[from] ArchFault),
    /// A training configuration file (`--config`) that cannot be read or
    /// parsed.
    #[error("{}: {reason}", path.display())]
    BadConfigFile {
        /// The file.
        path: PathBuf,
        /// Why not (the TOML parser's message names the key).
        reason: String,
    },
    /// A setting (a flag, or its key in a configuration file) whose value
    /// cannot be used; the message names the flag and the value.
    #[error("{message}")]
    BadSetting {
        /// The flag, e.g. `--time-max`.
        flag: &'static str,
        /// What is wrong, in words (the whole message).
        message: String,
    },
    /// A file given with a flag that could not be used: the flag and the
    /// file name the underlying error.
    #[error("{flag} {}: {cause}", path.display())]
    Input {
        /// The flag, e.g. `--model`.
        flag: &'static str,
        /// The file.
        path: PathBuf,
        /// What went wrong with it.
        cause: Box<NnError>,
    },
    /// A weight file holding another network than the one the operation
    /// needs (a denoiser given to the flow's search, `--init` of another
    /// configuration, a checkpoint of another network).
    #[error("{message}")]
    WrongArchitecture {
        /// The file.
        path: PathBuf,
        /// What it holds and what was needed, in words (the whole message).
        message: String,
    },
    /// A device this build or machine cannot use ([`crate::backend::DeviceError`]).
    #[error(transparent)]
    Device(#[from] crate::backend::DeviceError),
    /// Work that would not fit in the machine's memory, with the settings
    /// that make it smaller.
    #[error("{0}")]
    TooLarge(String),
    /// An error of the caller's, passed through unchanged: the pairs'
    /// noise it builds for a run (a calibration file), the scores it takes.
    #[error("{0}")]
    Caller(Box<dyn std::error::Error + Send + Sync>),
    /// A clean training or validation file that cannot be used (unreadable,
    /// too small for the crops); a caller may leave it out.
    #[error("{}: {reason}", path.display())]
    BadData {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A file a run writes (its log) that could not be written.
    #[error("{}: {reason}", path.display())]
    Output {
        /// The file.
        path: PathBuf,
        /// Why not.
        reason: String,
    },
    /// A noise-conditioned model run without its input's noise level.
    #[error("the model is {conditioning} conditioned: it needs the input's noise level (give --noise, --calib, or let pgrf find it)")]
    NoNoiseLevel {
        /// The conditioning's name.
        conditioning: &'static str,
    },
    /// A noise level a network cannot be conditioned on.
    #[error("noise level gain {gain}, floor {floor}: needs a positive gain and a floor >= 0, both finite")]
    BadNoiseLevel {
        /// Variance per unit of signal.
        gain: f32,
        /// Signal-independent variance.
        floor: f32,
    },
    /// An input named on the command line that is neither a file nor a
    /// folder.
    #[error("{}: no such file or folder", .0.display())]
    NoSuchInput(PathBuf),
    /// An output that may not be written (missing folder, an input, named
    /// twice).
    #[error(transparent)]
    Path(#[from] pgrf_core::paths::PathError),
    /// Training diverged: the loss is no longer a finite number.
    #[error("loss became {loss} at step {step}; lower the learning rate or set clip_grad")]
    Diverged {
        /// The step whose loss it was.
        step: u64,
        /// The loss (NaN or infinite).
        loss: f32,
    },
    /// A weight file without a tensor the operation needs.
    #[error("the weight file has no {name} ({hint})")]
    MissingTensor {
        /// The tensor's name.
        name: String,
        /// What its absence suggests.
        hint: &'static str,
    },
    /// A network input holding a NaN or an infinity.
    #[error("network input holds a non-finite value (flat index {index})")]
    NonFiniteInput {
        /// The first such value's flat index.
        index: usize,
    },
    /// A network output holding a NaN (damaged weights).
    #[error("the network produced NaN (flat index {index}); the weight file may be damaged")]
    NanOutput {
        /// The first NaN's flat index.
        index: usize,
    },
    /// Any other refused input, on one line: internal failures (encoding a
    /// record, a worker thread gone) whose message is all there is.
    #[error("{0}")]
    Invalid(String),
    /// From reading or writing a RAW file.
    #[error(transparent)]
    Raw(#[from] pgrf_raw::RawError),
    /// From decoding or unprocessing a photo (pgrf-scenes).
    #[error(transparent)]
    Scene(#[from] pgrf_scenes::SceneError),
    /// From the noise model or a profile.
    #[error(transparent)]
    Noise(#[from] pgrf_noise::NoiseError),
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] pgrf_core::WriteError),
}

/// The crate's result type.
pub type Result<T> = std::result::Result<T, NnError>;

/// Why a network's configuration cannot be built (read from a weight
/// file's record or made from a run's settings): each names the setting at
/// fault, so a caller may say which to change.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ArchFault {
    /// An SR3 field with no level, residual block or channel.
    #[error("SR3 needs at least one level, one residual block and some channels")]
    Empty,
    /// The flow's input or output planes are not what pgrf feeds it.
    #[error("pgrf's flow network takes {planes} planes ({what}, packed; {}) and gives 4, not {found_in} and {found_out}", .conditioning.describe())]
    FlowPlanes {
        /// The planes pgrf feeds it.
        planes: usize,
        /// What they are, in words.
        what: &'static str,
        /// Its conditioning.
        conditioning: crate::condition::Conditioning,
        /// The record's input planes.
        found_in: usize,
        /// The record's output planes.
        found_out: usize,
    },
    /// The SID U-Net's width or planes are not what pgrf feeds it.
    #[error("the SID U-Net needs a width of at least 1, {planes} planes in ({}) and 4 out (got width {width}, {found_in} in, {found_out} out)", .conditioning.describe())]
    SidPlanes {
        /// The planes pgrf feeds it.
        planes: usize,
        /// Its conditioning.
        conditioning: crate::condition::Conditioning,
        /// The record's width.
        width: usize,
        /// The record's input planes.
        found_in: usize,
        /// The record's output planes.
        found_out: usize,
    },
    /// An odd number of inner channels (the time embedding is sin/cos pairs).
    #[error("inner channels must be even (the time embedding is sin/cos pairs), got {0}")]
    OddInner(usize),
    /// A channel multiplier of 0.
    #[error("every channel multiplier must be at least 1, got {0:?}")]
    ZeroMultiplier(Vec<usize>),
    /// Attention at a level the network does not have.
    #[error("attention level {level} does not exist: the network has {levels} levels")]
    NoSuchLevel {
        /// The level asked for.
        level: usize,
        /// The levels there are.
        levels: usize,
    },
    /// No GroupNorm groups.
    #[error("norm_groups must be at least 1")]
    NoGroups,
    /// A group count that does not divide a level's channels.
    #[error("norm_groups {groups} does not divide {channels} channels")]
    Groups {
        /// The groups.
        groups: usize,
        /// The level's channels.
        channels: usize,
    },
    /// A dropout probability outside [0, 1).
    #[error("dropout must be in [0, 1), got {0}")]
    Dropout(f64),
    /// A statistics window that is not a multiple of the network's sides.
    #[error("window {side} is not a multiple of the network's {multiple}")]
    Window {
        /// The window asked for.
        side: usize,
        /// The multiple the sides must be.
        multiple: usize,
    },
    /// A flow's prior that cannot be built.
    #[error("the prior: {0}")]
    Prior(Box<ArchFault>),
    /// A prior told the noise level, in a field that is not.
    #[error("the prior is {} but the field is not told the noise level", .0.describe())]
    PriorLevel(crate::condition::Conditioning),
}

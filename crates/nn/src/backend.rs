//! The backends pgrf runs on, named once so that commands and tests agree.
//!
//! CPU is burn's Flex backend (the fastest CPU backend burn 0.21 offers that
//! builds offline; its `cpu` backend downloads an LLVM bundle at build time).
//! CUDA is behind the `cuda` cargo feature: burn 0.21's CUDA runtime loads the
//! driver libraries at run time, so building needs no CUDA toolkit.

use crate::ops::PgrfOps;
use burn::backend::Autodiff;

/// Inference on the CPU.
pub type Cpu = burn::backend::Flex;
/// Training on the CPU.
pub type CpuTrain = Autodiff<Cpu>;

/// Inference on an NVIDIA GPU (with kernel fusion and autotuning).
#[cfg(feature = "cuda")]
pub type Gpu = burn::backend::Cuda;
/// Training on an NVIDIA GPU.
#[cfg(feature = "cuda")]
pub type GpuTrain = Autodiff<Gpu>;

/// Where a command runs its network: parsed from `--device cpu|cuda`
/// (`gpu` also names CUDA), written as `cpu` / `cuda` in TOML and JSON.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    /// The CPU, through burn's Flex backend ([`Cpu`], [`CpuTrain`]); uses
    /// rayon's thread pool.
    Cpu,
    /// NVIDIA GPU 0 through burn's CUDA backend; only in builds with the
    /// `cuda` feature ([`DeviceKind::check_available`] refuses it otherwise).
    Cuda,
}

impl std::str::FromStr for DeviceKind {
    type Err = pgrf_core::parse::ParseError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "cpu" => Ok(Self::Cpu),
            "cuda" | "gpu" => Ok(Self::Cuda),
            _ => Err(pgrf_core::parse::ParseError::unknown_name(
                s,
                format!("unknown device '{s}' (expected cpu or cuda)"),
            )),
        }
    }
}

impl std::fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Cpu => "cpu",
            Self::Cuda => "cuda",
        })
    }
}

/// Why the GPU cannot be used, each with its fix in the message: what a
/// caller may act on (fall back to the CPU, or tell the user what to
/// install).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DeviceError {
    /// This build has no CUDA backend.
    #[error(
        "this pgrf was built without CUDA; rebuild with `cargo build --release --features cuda`"
    )]
    NotBuilt,
    /// The NVIDIA driver (libcuda) cannot be loaded.
    #[error("no NVIDIA driver found (libcuda.so.1 could not be loaded): install the driver, or add the folder that holds libcuda.so.1 to LD_LIBRARY_PATH")]
    NoDriver,
    /// CUDA's runtime compiler (libnvrtc) cannot be loaded.
    #[error("CUDA's runtime compiler was not found (libnvrtc.so could not be loaded): install the CUDA toolkit, or add its lib64 folder to LD_LIBRARY_PATH")]
    NoCompiler,
    /// The driver loaded but did not start or count its devices (its
    /// error, in words).
    #[error("the NVIDIA driver {0}")]
    DriverFailed(String),
    /// The driver reports no device.
    #[error("the NVIDIA driver reports no CUDA device")]
    NoDevice,
}

impl DeviceKind {
    /// Refuses `cuda` in a build without the feature, or where the driver,
    /// NVRTC or a device is missing, with the fix in the message.
    pub fn check_available(self) -> Result<(), DeviceError> {
        if self == Self::Cuda && !cfg!(feature = "cuda") {
            return Err(DeviceError::NotBuilt);
        }
        #[cfg(feature = "cuda")]
        if self == Self::Cuda {
            // Asked once per process: commands check before their work and
            // again where they pick the backend.
            static READY: std::sync::OnceLock<Result<(), DeviceError>> = std::sync::OnceLock::new();
            READY.get_or_init(cuda_ready).clone()?;
        }
        Ok(())
    }
}

/// Whether burn's CUDA runtime can start here: it loads the driver
/// (libcuda) and the runtime compiler (libnvrtc) by name and panics when
/// either is missing or no device answers, so pgrf asks first.
#[cfg(feature = "cuda")]
#[allow(unsafe_code)]
fn cuda_ready() -> Result<(), DeviceError> {
    // SAFETY: these only try to open the libraries by name (dlopen).
    let (driver, nvrtc) = unsafe {
        (
            cudarc::driver::sys::is_culib_present(),
            cudarc::nvrtc::sys::is_culib_present(),
        )
    };
    if !driver {
        return Err(DeviceError::NoDriver);
    }
    if !nvrtc {
        return Err(DeviceError::NoCompiler);
    }
    cudarc::driver::result::init()
        .map_err(|e| DeviceError::DriverFailed(format!("did not start: {e:?}")))?;
    match cudarc::driver::result::device::get_count() {
        Ok(n) if n > 0 => Ok(()),
        Ok(_) => Err(DeviceError::NoDevice),
        Err(e) => Err(DeviceError::DriverFailed(format!(
            "could not count its devices: {e:?}"
        ))),
    }
}

/// Work generic over an inference backend: [`on_device`] runs it on the
/// backend of the device a user chose. The one place that maps a
/// [`DeviceKind`] to a backend type, with the CUDA arm compiled only in
/// `cuda` builds.
pub trait OnBackend {
    /// What the work returns.
    type Output;
    /// Run on backend `B` and its default device.
    fn run<B: PgrfOps>(self, device: B::Device) -> crate::Result<Self::Output>;
}

/// Work generic over a training (autodiff) backend, run by [`on_train_device`].
pub trait OnTrainBackend {
    /// What the work returns.
    type Output;
    /// Run on backend `B` and its default device.
    fn run<B: crate::ops::PgrfAutodiff>(self, device: B::Device) -> crate::Result<Self::Output>;
}

/// Run `job` on the inference backend of `kind` (refused without CUDA).
pub fn on_device<J: OnBackend>(kind: DeviceKind, job: J) -> crate::Result<J::Output> {
    kind.check_available().map_err(crate::NnError::Device)?;
    match kind {
        DeviceKind::Cpu => job.run::<Cpu>(Default::default()),
        #[cfg(feature = "cuda")]
        DeviceKind::Cuda => job.run::<Gpu>(Default::default()),
        #[cfg(not(feature = "cuda"))]
        DeviceKind::Cuda => unreachable!("checked above"),
    }
}

/// Run `job` on the training backend of `kind` (refused without CUDA).
pub fn on_train_device<J: OnTrainBackend>(kind: DeviceKind, job: J) -> crate::Result<J::Output> {
    kind.check_available().map_err(crate::NnError::Device)?;
    match kind {
        DeviceKind::Cpu => job.run::<CpuTrain>(Default::default()),
        #[cfg(feature = "cuda")]
        DeviceKind::Cuda => job.run::<GpuTrain>(Default::default()),
        #[cfg(not(feature = "cuda"))]
        DeviceKind::Cuda => unreachable!("checked above"),
    }
}

/// One line about the compute device and, on the CPU, whose operations
/// run there, for headers and summaries.
pub fn describe(kind: DeviceKind, kernels: crate::ops::Kernels) -> String {
    match kind {
        DeviceKind::Cpu => format!(
            "Flex, {} threads, {kernels} operations",
            rayon::current_num_threads(),
        ),
        DeviceKind::Cuda => "CUDA device 0".into(),
    }
}

//! The backends pgrf runs on, named once so that commands and tests agree.
//!
//! CPU is burn's Flex backend (the fastest CPU backend burn 0.21 offers that
//! builds offline; its `cpu` backend downloads an LLVM bundle at build time).
//! CUDA is behind the `cuda` cargo feature: burn 0.21's CUDA runtime loads the
//! driver libraries at run time, so building needs no CUDA toolkit.

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

/// Where a command runs its network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    Cpu,
    Cuda,
}

impl std::str::FromStr for DeviceKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "cpu" => Ok(Self::Cpu),
            "cuda" | "gpu" => Ok(Self::Cuda),
            _ => Err(format!("unknown device '{s}' (expected cpu or cuda)")),
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

impl DeviceKind {
    /// Refuses `cuda` in a build without the feature, with the fix in the message.
    pub fn check_available(self) -> Result<(), String> {
        if self == Self::Cuda && !cfg!(feature = "cuda") {
            return Err("this pgrf was built without CUDA; rebuild with `cargo build --release --features cuda`".into());
        }
        Ok(())
    }
}

/// One line about the compute device, for headers and summaries.
pub fn describe(kind: DeviceKind) -> String {
    match kind {
        DeviceKind::Cpu => format!("Flex, {} threads", rayon::current_num_threads()),
        DeviceKind::Cuda => "CUDA device 0".into(),
    }
}

/// Run the training loop on the chosen device.
pub fn train(
    kind: DeviceKind,
    settings: &crate::train::TrainSettings,
    source: std::sync::Arc<crate::data::Source>,
    spec: std::sync::Arc<pgrf_noise::pair::PairSpec>,
    val: Option<&crate::data::validation::ValSet>,
    progress: &dyn pgrf_core::Progress,
    stop: &std::sync::atomic::AtomicBool,
) -> crate::Result<crate::train::Outcome> {
    kind.check_available().map_err(crate::NnError::Invalid)?;
    match kind {
        DeviceKind::Cpu => crate::train::train::<CpuTrain>(
            settings,
            source,
            spec,
            val,
            &Default::default(),
            progress,
            stop,
        ),
        #[cfg(feature = "cuda")]
        DeviceKind::Cuda => crate::train::train::<GpuTrain>(
            settings,
            source,
            spec,
            val,
            &Default::default(),
            progress,
            stop,
        ),
        #[cfg(not(feature = "cuda"))]
        DeviceKind::Cuda => unreachable!("checked above"),
    }
}

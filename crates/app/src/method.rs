//! A network as a method under test of pgrf-eval (which sits below this
//! crate and cannot name the models): the packed, amplified input restored
//! tile by tile as `pgrf enhance` restores a frame.

use ndarray::{Array3, ArrayView3};
use pgrf_core::NoProgress;
use pgrf_eval::{CaseInfo, MethodUnderTest, RestoreError};
use pgrf_nn::condition::NoiseLevel;
use pgrf_nn::infer::{restore_packed, Restore, Tiling};

/// A loaded restorer under a column name, tiled as `tiling` says.
pub struct NetworkMethod {
    name: String,
    restorer: Box<dyn Restore>,
    tiling: Tiling,
}

impl NetworkMethod {
    /// `restorer` as column `name`.
    pub fn new(name: impl Into<String>, restorer: Box<dyn Restore>, tiling: Tiling) -> Self {
        NetworkMethod {
            name: name.into(),
            restorer,
            tiling,
        }
    }
}

impl MethodUnderTest for NetworkMethod {
    fn name(&self) -> &str {
        &self.name
    }

    fn restore(
        &self,
        input: ArrayView3<f32>,
        case: &CaseInfo<'_>,
    ) -> Result<Array3<f32>, RestoreError> {
        let level = (case.noise)
            .map(|n| NoiseLevel::from_dn(n.k, n.read, n.row, n.range, case.ratio as f64));
        restore_packed(
            self.restorer.as_ref(),
            input,
            level,
            &self.tiling,
            &NoProgress,
        )
        .map(|o| o.output)
        .map_err(RestoreError::method)
    }
}

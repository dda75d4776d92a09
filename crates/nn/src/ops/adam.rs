//! Adam as one pass per parameter tensor ([`PgrfAdam`]), a drop-in for
//! burn's `Adam` in burn's `OptimizerAdaptor`.
//!
//! Its state is burn's `AdamState`, so optimiser records (and therefore
//! pgrf's training checkpoints) are the same bytes whichever of the two
//! wrote them, and a run continues across the switch. Where the backend has
//! no kernels of its own, or [`super::Kernels::Burn`] is chosen, the step is
//! burn's `Adam` itself.

use super::{AdamStep, PgrfOps};
use burn::optim::{
    Adam, AdamConfig, AdamState, AdaptiveMomentumState, LearningRate, SimpleOptimizer,
};
use burn::tensor::{Tensor, TensorPrimitive};

/// Adam without weight decay or AMSGrad (what pgrf trains with).
#[derive(Clone)]
pub struct PgrfAdam {
    burn: Adam,
    beta_1: f32,
    beta_2: f32,
    epsilon: f32,
}

impl PgrfAdam {
    /// Adam with decays `beta_1`, `beta_2` and `epsilon` added to the root
    /// of the second moment (burn's placement: scaled by the bias
    /// correction).
    pub fn new(beta_1: f32, beta_2: f32, epsilon: f32) -> Self {
        PgrfAdam {
            burn: AdamConfig::new()
                .with_beta_1(beta_1)
                .with_beta_2(beta_2)
                .with_epsilon(epsilon)
                .build(),
            beta_1,
            beta_2,
            epsilon,
        }
    }
}

impl<B: PgrfOps> SimpleOptimizer<B> for PgrfAdam {
    type State<const D: usize> = AdamState<B, D>;

    fn step<const D: usize>(
        &self,
        lr: LearningRate,
        tensor: Tensor<B, D>,
        grad: Tensor<B, D>,
        state: Option<Self::State<D>>,
    ) -> (Tensor<B, D>, Option<Self::State<D>>) {
        if !B::pgrf_kernels() {
            return SimpleOptimizer::<B>::step(&self.burn, lr, tensor, grad, state);
        }
        let (time, m, v) = match state {
            Some(s) => (
                s.momentum.time + 1,
                Some(s.momentum.moment_1.into_primitive().tensor()),
                Some(s.momentum.moment_2.into_primitive().tensor()),
            ),
            None => (1, None, None),
        };
        let step = AdamStep {
            lr: lr as f32,
            beta_1: self.beta_1,
            beta_2: self.beta_2,
            epsilon: self.epsilon,
            time: i32::try_from(time).unwrap_or(i32::MAX),
        };
        let [p, m, v] = B::pgrf_adam(
            tensor.into_primitive().tensor(),
            grad.into_primitive().tensor(),
            m,
            v,
            step,
        );
        let wrap = |t| Tensor::<B, D>::from_primitive(TensorPrimitive::Float(t));
        let momentum = AdaptiveMomentumState::new(time, wrap(m), wrap(v));
        (wrap(p), Some(AdamState::new(momentum)))
    }

    fn to_device<const D: usize>(state: Self::State<D>, device: &B::Device) -> Self::State<D> {
        <Adam as SimpleOptimizer<B>>::to_device(state, device)
    }
}

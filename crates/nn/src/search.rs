//! The paper's sampling search (Algorithm 2): on validation pairs, the
//! two-stage sampler's result for every candidate second time t, so that the
//! caller can score them and keep the best as the file's t2.
//!
//! The first stage XZ = v(X0, T, 0) + X0 does not depend on t, so it is
//! computed once per pair: a grid of n times costs n + 1 network
//! evaluations per pair, not 2n.

use crate::backend::{Cpu, DeviceKind};
use crate::data::validation::ValPair;
use crate::error::{NnError, Result};
use crate::sr3::Sr3Unet;
use crate::weights;
use burn::tensor::backend::Backend;
use burn::tensor::{Tensor, TensorData};
use ndarray::Array3;
use std::path::Path;

/// The candidate times {s, 2s, .., ns} with ns <= 1 (1 included when s divides it).
pub fn grid(step: f64) -> Result<Vec<f64>> {
    if !(step.is_finite() && step > 0.0 && step <= 1.0) {
        return Err(NnError::Invalid(format!(
            "--step must be in (0, 1], got {step}"
        )));
    }
    let n = (1.0 / step + 1e-9).floor() as usize;
    if n > 1000 {
        return Err(NnError::Invalid(format!(
            "--step {step} gives {n} candidates; use at least 0.001"
        )));
    }
    Ok((1..=n).map(|i| i as f64 * step).collect())
}

/// Receives each search result: (pair index, candidate).
pub type ScoreFn<'s> = dyn FnMut(usize, Candidate) -> Result<()> + 's;
/// Receives each averaged result: (pair index, samples K, mean of K samples).
pub type AverageFn<'s> = dyn FnMut(usize, usize, &Array3<f32>) -> Result<()> + 's;

/// What the search hands back for one pair.
pub enum Candidate<'a> {
    /// The first stage alone (one-step sampler).
    OneStep(&'a Array3<f32>),
    /// The two-stage result at `times[index]`.
    TwoStage { index: usize, out: &'a Array3<f32> },
}

/// Run the flow model in `path` on `pairs` (each `(4, p, p)`) for every time
/// in `times`, calling `score(pair_index, candidate)` with each result.
pub fn search(
    path: &Path,
    device: DeviceKind,
    pairs: &[ValPair],
    patch: usize,
    times: &[f64],
    score: &mut ScoreFn,
    progress: &mut dyn FnMut(),
) -> Result<()> {
    device.check_available().map_err(NnError::Invalid)?;
    match device {
        DeviceKind::Cpu => run::<Cpu>(
            path,
            &Default::default(),
            pairs,
            patch,
            times,
            score,
            progress,
        ),
        #[cfg(feature = "cuda")]
        DeviceKind::Cuda => run::<crate::backend::Gpu>(
            path,
            &Default::default(),
            pairs,
            patch,
            times,
            score,
            progress,
        ),
        #[cfg(not(feature = "cuda"))]
        DeviceKind::Cuda => unreachable!("checked above"),
    }
}

fn run<B: Backend>(
    path: &Path,
    device: &B::Device,
    pairs: &[ValPair],
    patch: usize,
    times: &[f64],
    score: &mut ScoreFn,
    progress: &mut dyn FnMut(),
) -> Result<()> {
    let (net, _) = weights::load_flow::<B>(path, device)?;
    let tensor = |v: &[f32]| -> Result<Tensor<B, 4>> {
        if v.len() != 4 * patch * patch {
            return Err(NnError::Invalid("validation pair of the wrong size".into()));
        }
        Ok(Tensor::from_data(
            TensorData::new(v.to_vec(), [1, 4, patch, patch]),
            device,
        ))
    };
    for (i, pair) in pairs.iter().enumerate() {
        let cond = tensor(&pair.noisy)?;
        let x0 = tensor(&pair.x0)?;
        let xz = stage(&net, x0.clone(), cond.clone(), &x0, 0.0);
        score(i, Candidate::OneStep(&to_array(xz.clone(), patch)?))?;
        progress();
        for (k, &t) in times.iter().enumerate() {
            let t = t as f32;
            let xt = xz.clone() * t + x0.clone() * (1.0 - t);
            let xm = stage(&net, xt, cond.clone(), &x0, t);
            score(
                i,
                Candidate::TwoStage {
                    index: k,
                    out: &to_array(xm, patch)?,
                },
            )?;
            progress();
        }
    }
    Ok(())
}

/// What averaging K two-stage samples (different X0) buys: for each pair,
/// the running mean of samples 1..=`k_max` at `t2`, handed to
/// `score(pair_index, k, mean)` for k = 1, 2, 4, .. and `k_max`. Sample 1
/// uses the pair's own X0; the others draw fresh start noise from `seed`.
pub fn averaging(
    path: &Path,
    device: DeviceKind,
    pairs: &[ValPair],
    patch: usize,
    avg: Averaging,
    score: &mut AverageFn,
    progress: &mut dyn FnMut(),
) -> Result<()> {
    device.check_available().map_err(NnError::Invalid)?;
    match device {
        DeviceKind::Cpu => average_on::<Cpu>(
            path,
            &Default::default(),
            (pairs, patch),
            avg,
            score,
            progress,
        ),
        #[cfg(feature = "cuda")]
        DeviceKind::Cuda => average_on::<crate::backend::Gpu>(
            path,
            &Default::default(),
            (pairs, patch),
            avg,
            score,
            progress,
        ),
        #[cfg(not(feature = "cuda"))]
        DeviceKind::Cuda => unreachable!("checked above"),
    }
}

/// The two-stage time, the most samples averaged, and the seed of the
/// extra start fields.
#[derive(Clone, Copy, Debug)]
pub struct Averaging {
    pub t2: f64,
    pub k_max: usize,
    pub seed: u64,
}

/// Sample counts reported by [`averaging`]: powers of two and `k_max`.
pub fn reported_counts(k_max: usize) -> Vec<usize> {
    let mut v: Vec<usize> = std::iter::successors(Some(1usize), |k| Some(k * 2))
        .take_while(|k| *k < k_max)
        .collect();
    v.push(k_max.max(1));
    v
}

fn average_on<B: Backend>(
    path: &Path,
    device: &B::Device,
    (pairs, patch): (&[ValPair], usize),
    Averaging { t2, k_max, seed }: Averaging,
    score: &mut AverageFn,
    progress: &mut dyn FnMut(),
) -> Result<()> {
    let (net, _) = weights::load_flow::<B>(path, device)?;
    let report = reported_counts(k_max);
    let tensor =
        |v: Vec<f32>| Tensor::<B, 4>::from_data(TensorData::new(v, [1, 4, patch, patch]), device);
    for (i, pair) in pairs.iter().enumerate() {
        let cond = tensor(pair.noisy.clone());
        let mut sum: Option<Tensor<B, 4>> = None;
        for k in 1..=k_max.max(1) {
            let x0 = if k == 1 {
                tensor(pair.x0.clone())
            } else {
                let field = crate::infer::start::start_noise(
                    seed ^ ((i as u64) << 20),
                    k as u64,
                    4,
                    patch,
                    patch,
                );
                tensor(field.into_raw_vec_and_offset().0)
            };
            let y = crate::sample::two_stage(&net, cond.clone(), x0, t2 as f32);
            sum = Some(match sum {
                None => y,
                Some(s) => s + y,
            });
            progress();
            if report.contains(&k) {
                let mean = sum.clone().expect("k >= 1") / k as f32;
                score(i, k, &to_array(mean, patch)?)?;
            }
        }
    }
    Ok(())
}

/// v(x, T, t) + X0.
fn stage<B: Backend>(
    net: &Sr3Unet<B>,
    x: Tensor<B, 4>,
    cond: Tensor<B, 4>,
    x0: &Tensor<B, 4>,
    t: f32,
) -> Tensor<B, 4> {
    let device = x.device();
    net.forward(x, cond, Tensor::full([1], t, &device)) + x0.clone()
}

fn to_array<B: Backend>(t: Tensor<B, 4>, patch: usize) -> Result<Array3<f32>> {
    let v: Vec<f32> = t
        .into_data()
        .to_vec()
        .map_err(|e| NnError::Invalid(format!("reading the network output: {e:?}")))?;
    Array3::from_shape_vec((4, patch, patch), v)
        .map_err(|e| NnError::Invalid(format!("network output shape: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averaging_reports_powers_of_two_and_the_maximum() {
        assert_eq!(reported_counts(1), vec![1]);
        assert_eq!(reported_counts(4), vec![1, 2, 4]);
        assert_eq!(reported_counts(6), vec![1, 2, 4, 6]);
    }

    #[test]
    fn the_grid_is_s_to_ns() {
        let g = grid(0.1).unwrap();
        assert_eq!(g.len(), 10);
        assert!((g[0] - 0.1).abs() < 1e-12 && (g[9] - 1.0).abs() < 1e-12);
        assert_eq!(grid(0.3).unwrap().len(), 3);
        assert_eq!(grid(1.0).unwrap(), vec![1.0]);
        assert!(grid(0.0).is_err());
        assert!(grid(1.5).is_err());
        assert!(grid(f64::NAN).is_err());
    }
}

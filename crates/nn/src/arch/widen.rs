//! A wider SID U-Net started from a trained narrower one (`pgrf train spc
//! --width 32 --init narrow.safetensors`), so that a run buying capacity
//! does not start from scratch.
//!
//! The file's weights fill the old channels of every layer; the new
//! channels keep the run's seeded initialisation; every weight through which
//! an old channel would read a new one is zero. Convolutions, LeakyReLU,
//! max pooling and concatenation all act channel by channel, so the old
//! channels then compute exactly what the narrow network did and the wider
//! one starts at its quality. The new channels are not dead: the zero
//! weights that read them get gradients at the first step (their inputs are
//! not zero), after which the new channels' own weights do too. This is the
//! zero-padded form of Net2Net's function-preserving widening (Chen,
//! Goodfellow and Shlens, "Net2Net", 2016) rather than its copy-and-halve
//! form, which starts the copies identical and needs noise to tell them
//! apart.

use crate::named::{NamedTensor, TensorFault};
use std::collections::BTreeMap;

/// One convolution's channels: the output and input dimensions as
/// segments (a merge convolution reads the concatenation [upsampled, skip]:
/// two segments, each of which widens at its own end).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Layout {
    /// The convolution's field path, without `.weight` / `.bias`.
    pub name: String,
    /// A transposed convolution: its weight is (in, out, kh, kw), not
    /// (out, in, kh, kw).
    pub transposed: bool,
    /// Output channels, by segment.
    pub out: Vec<usize>,
    /// Input channels, by segment.
    pub input: Vec<usize>,
}

/// Where channel `i` of a dimension laid out as `wide` sits in the same
/// dimension laid out as `narrow` (segment by segment), if it was there.
fn old_index(narrow: &[usize], wide: &[usize], i: usize) -> Option<usize> {
    let (mut w_start, mut n_start) = (0, 0);
    for (&n, &w) in narrow.iter().zip(wide) {
        if i < w_start + w {
            let offset = i - w_start;
            return (offset < n).then_some(n_start + offset);
        }
        w_start += w;
        n_start += n;
    }
    None
}

/// The weight's shape under a layout, given its kernel.
fn weight_shape(l: &Layout, kernel: [usize; 2]) -> Vec<usize> {
    let (o, i) = (l.out.iter().sum(), l.input.iter().sum());
    let (a, b) = if l.transposed { (i, o) } else { (o, i) };
    vec![a, b, kernel[0], kernel[1]]
}

/// `into` (the wide network's freshly initialised tensors) with the narrow
/// network's tensors `from` written into its old channels and the weights
/// from new channels into old ones zeroed (see the module's documentation).
/// `narrow` and `wide` are the two networks' layouts, convolution by
/// convolution in the same order; every tensor of both must be in them at
/// the shape they give, else the error says which is not.
pub(super) fn widen(
    narrow: &[Layout],
    wide: &[Layout],
    from: &BTreeMap<String, NamedTensor>,
    into: &mut BTreeMap<String, NamedTensor>,
) -> Result<(), TensorFault> {
    if narrow.len() != wide.len() || from.len() != 2 * narrow.len() || into.len() != 2 * wide.len()
    {
        return Err(TensorFault::Count {
            from: from.len(),
            into: into.len(),
            convolutions: wide.len(),
        });
    }
    for (n, w) in narrow.iter().zip(wide) {
        let get = |map: &BTreeMap<String, NamedTensor>, part: &str| {
            map.get(&format!("{}.{part}", w.name))
                .cloned()
                .ok_or_else(|| TensorFault::Missing(format!("{}.{part}", w.name)))
        };
        let (mut weight, mut bias) = (get(into, "weight")?, get(into, "bias")?);
        let (old_weight, old_bias) = (get(from, "weight")?, get(from, "bias")?);
        let kernel = match weight.shape[..] {
            [_, _, kh, kw] => [kh, kw],
            _ => return Err(TensorFault::NotConvolution(format!("{}.weight", w.name))),
        };
        for (t, shape) in [
            (&weight, weight_shape(w, kernel)),
            (&old_weight, weight_shape(n, kernel)),
            (&bias, vec![w.out.iter().sum()]),
            (&old_bias, vec![n.out.iter().sum()]),
        ] {
            if t.shape != shape || t.values.len() != shape.iter().product::<usize>() {
                return Err(TensorFault::Shape {
                    name: w.name.to_string(),
                    found: t.shape.clone(),
                    wanted: shape,
                });
            }
        }
        fill_weight(n, w, kernel, &old_weight, &mut weight);
        for (o, v) in bias.values.iter_mut().enumerate() {
            if let Some(oo) = old_index(&n.out, &w.out, o) {
                *v = old_bias.values[oo];
            }
        }
        into.insert(format!("{}.weight", w.name), weight);
        into.insert(format!("{}.bias", w.name), bias);
    }
    Ok(())
}

/// One weight's values: old output from old input copied, old output from
/// new input zero, new outputs left as initialised.
fn fill_weight(
    n: &Layout,
    w: &Layout,
    kernel: [usize; 2],
    old: &NamedTensor,
    new: &mut NamedTensor,
) {
    let k = kernel[0] * kernel[1];
    let (a, b) = (new.shape[0], new.shape[1]);
    let old_b = old.shape[1];
    for ia in 0..a {
        for ib in 0..b {
            let (o, i) = if w.transposed { (ib, ia) } else { (ia, ib) };
            let Some(oo) = old_index(&n.out, &w.out, o) else {
                continue;
            };
            let dst = &mut new.values[(ia * b + ib) * k..][..k];
            match old_index(&n.input, &w.input, i) {
                Some(oi) => {
                    let (oa, ob) = if w.transposed { (oi, oo) } else { (oo, oi) };
                    dst.copy_from_slice(&old.values[(oa * old_b + ob) * k..][..k]);
                }
                None => dst.fill(0.0),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::{Architecture, StartAdapted};
    use crate::backend::Cpu;
    use crate::condition::{Conditioning, NoiseLevel};
    use crate::config::{Method, TrainConfig};
    use burn::tensor::{Tensor, TensorData};

    fn sid(width: usize, residual: bool) -> Architecture {
        TrainConfig {
            width: Some(width),
            residual,
            conditioning: Conditioning::LogSigmaMap,
            ..TrainConfig::default()
        }
        .architecture(Method::Spc)
        .unwrap()
    }

    /// A width-3 SID U-Net started from a width-2 one restores what the
    /// narrow one did, to float rounding, on a seeded input that the narrow
    /// one changes (its zero-initialised head is drawn too, so the check is
    /// not of an identity); its new channels are drawn, and read by the old
    /// ones through zeros. Narrower targets and other networks are refused.
    #[test]
    fn a_wider_unet_starts_where_the_narrow_one_was() {
        let device = Default::default();
        let (narrow, wide) = (sid(2, true), sid(3, true));
        assert!(wide.can_start_from(&narrow) && !narrow.can_start_from(&wide));
        assert!(!wide.can_start_from(&sid(2, false)));
        let mut tensors = narrow.init_seeded::<Cpu>(&device, 51).unwrap().parameters();
        let head = tensors.get_mut("head.weight").unwrap();
        for (i, v) in head.values.iter_mut().enumerate() {
            *v = 0.3 * (1.7 * i as f32).sin();
        }
        let narrow_net = narrow
            .init::<Cpu>(&device)
            .unwrap()
            .assign(&tensors, &device)
            .unwrap();
        let fresh = wide.init_seeded::<Cpu>(&device, 7).unwrap();
        let adapted = wide.adapt_start(&narrow, &mut tensors, &fresh).unwrap();
        assert_eq!(adapted, StartAdapted::Widened { from: 2, to: 3 });
        let first = &tensors["down.0.first.weight"]; // (3, 8, 3, 3)
        assert!(
            first.values[2 * 72..3 * 72].iter().any(|&v| v != 0.0),
            "new channel not drawn"
        );
        let second = &tensors["down.1.first.weight"]; // (6, 3, 3, 3): old out 0, new in 2
        assert!(second.values[2 * 9..3 * 9].iter().all(|&v| v == 0.0));
        let wide_net = fresh.assign(&tensors, &device).unwrap();

        let n = 2 * 4 * 32 * 32;
        let v: Vec<f32> = (0..n)
            .map(|i| 0.4 + 0.3 * (0.37 * i as f32).sin())
            .collect();
        let x = Tensor::<Cpu, 4>::from_data(TensorData::new(v, [2, 4, 32, 32]), &device);
        let levels = [
            NoiseLevel::from_dn(1.53, 3.2, 0.4, 15871.0, 100.0),
            NoiseLevel::from_dn(0.2, 1.5, 0.2, 16383.0, 5.0),
        ];
        let x0 = x.zeros_like();
        let a = narrow_net.restore(x.clone(), &levels, x0.clone(), 0.5);
        let b = wide_net.restore(x.clone(), &levels, x0, 0.5);
        let change: f32 = (a.clone() - x).abs().max().into_scalar();
        let d: f32 = (a - b).abs().max().into_scalar();
        assert!(
            change > 1e-2,
            "the narrow network changes its input by {change}"
        );
        assert!(d <= 1e-5, "the widened network differs by {d}");
    }

    #[test]
    fn tensors_off_the_layout_are_refused() {
        let (n, w) = match (sid(2, true), sid(3, true)) {
            (Architecture::SidUnet(n), Architecture::SidUnet(w)) => {
                (n.channel_layout(), w.channel_layout())
            }
            _ => unreachable!(),
        };
        let device = Default::default();
        let from = sid(2, true)
            .init_seeded::<Cpu>(&device, 1)
            .unwrap()
            .parameters();
        let mut into = sid(3, true)
            .init_seeded::<Cpu>(&device, 2)
            .unwrap()
            .parameters();
        let mut short = from.clone();
        short.remove("head.bias");
        assert!(matches!(
            widen(&n, &w, &short, &mut into.clone()),
            Err(TensorFault::Count { .. })
        ));
        // The narrow file read as if it were already wide.
        let e = widen(&w, &w, &from, &mut into).unwrap_err();
        assert!(
            matches!(&e, TensorFault::Shape { name, found, .. } if name == "down.0.first" && found == &vec![2, 8, 3, 3]),
            "{e:?}"
        );
    }

    #[test]
    fn old_index_follows_each_segment() {
        // [upsampled 2 -> 3, skip 2 -> 3]: wide 0,1 | 2 new | 3,4 | 5 new.
        let got: Vec<_> = (0..7).map(|i| old_index(&[2, 2], &[3, 3], i)).collect();
        assert_eq!(got, [Some(0), Some(1), None, Some(2), Some(3), None, None]);
    }

    #[test]
    fn transposed_weight_is_read_in_its_own_order() {
        // A transposed convolution 2 in -> 1 out widened to 3 in -> 2 out,
        // 1x1 kernel: old[(in, out)] = 10 * in + out.
        let l = |i: usize, o: usize| Layout {
            name: "up".into(),
            transposed: true,
            out: vec![o],
            input: vec![i],
        };
        let (n, w) = (l(2, 1), l(3, 2));
        let old = NamedTensor {
            shape: vec![2, 1, 1, 1],
            values: vec![0.0, 10.0],
        };
        let mut new = NamedTensor {
            shape: vec![3, 2, 1, 1],
            values: vec![-1.0; 6],
        };
        fill_weight(&n, &w, [1, 1], &old, &mut new);
        // (in 0, out 0) = 0, (in 0, out 1) new, (in 1, out 0) = 10,
        // (in 1, out 1) new, (in 2, out 0): old output from new input = 0.
        assert_eq!(new.values, [0.0, -1.0, 10.0, -1.0, 0.0, -1.0]);
    }
}

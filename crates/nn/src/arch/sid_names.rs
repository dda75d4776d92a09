//! The names of the SID U-Net's tensors in the field's PyTorch code
//! (`UNetSeeInDark` of ELD, PMN, PNNP and LED) and in pgrf's weight files.
//!
//! Both run the same layers in the same order: two 3x3 convolutions per
//! level (`conv{L}_1`, `conv{L}_2` for levels 1..5, pgrf `down.{L-1}.first`,
//! `.second`), transposed convolutions up (`upv6`..`upv9`, pgrf `up.0`..3),
//! two convolutions after each concatenation of [upsampled, skip]
//! (`conv6_1`..`conv9_2`, pgrf `merge.0`..3) and the 1x1 head (`conv10_1`,
//! pgrf `head`). Weight layouts are PyTorch's in both: convolutions (out,
//! in, kh, kw), transposed convolutions (in, out, kh, kw).

/// (PyTorch name, pgrf name) of every tensor, weights and biases, in the
/// order PyTorch's `state_dict` lists them.
pub fn pairs() -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut conv = |torch: String, pgrf: String| {
        for p in ["weight", "bias"] {
            out.push((format!("{torch}.{p}"), format!("{pgrf}.{p}")));
        }
    };
    for level in 1..=5 {
        conv(
            format!("conv{level}_1"),
            format!("down.{}.first", level - 1),
        );
        conv(
            format!("conv{level}_2"),
            format!("down.{}.second", level - 1),
        );
    }
    for level in 6..=9 {
        let k = level - 6;
        conv(format!("upv{level}"), format!("up.{k}"));
        conv(format!("conv{level}_1"), format!("merge.{k}.first"));
        conv(format!("conv{level}_2"), format!("merge.{k}.second"));
    }
    conv("conv10_1".into(), "head".into());
    out
}

/// The PyTorch shape of every tensor of `UNetSeeInDark` at first-level
/// width `w` with `cin` inputs and `cout` outputs, in `state_dict` order.
pub fn torch_shapes(w: usize, cin: usize, cout: usize) -> Vec<(String, Vec<usize>)> {
    let widths = [w, 2 * w, 4 * w, 8 * w, 16 * w];
    let mut out = Vec::new();
    // (name, weight shape); the bias has the output channels: dimension 0
    // of a convolution's weight, 1 of a transposed convolution's.
    let mut add = |name: String, weight: Vec<usize>, bias: usize| {
        out.push((format!("{name}.weight"), weight));
        out.push((format!("{name}.bias"), vec![bias]));
    };
    let mut c = cin;
    for (l, &wl) in widths.iter().enumerate() {
        add(format!("conv{}_1", l + 1), vec![wl, c, 3, 3], wl);
        add(format!("conv{}_2", l + 1), vec![wl, wl, 3, 3], wl);
        c = wl;
    }
    for level in 6..=9usize {
        let (hi, lo) = (widths[10 - level], widths[9 - level]);
        add(format!("upv{level}"), vec![hi, lo, 2, 2], lo);
        add(format!("conv{level}_1"), vec![lo, 2 * lo, 3, 3], lo);
        add(format!("conv{level}_2"), vec![lo, lo, 3, 3], lo);
    }
    add("conv10_1".into(), vec![cout, w, 1, 1], cout);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SID's published network, width 32: 7,760,484 parameters.
    #[test]
    fn the_full_width_network_has_sids_parameter_count() {
        let n: usize = torch_shapes(32, 4, 4)
            .iter()
            .map(|(_, s)| s.iter().product::<usize>())
            .sum();
        assert_eq!(n, 7_760_484);
        assert_eq!(pairs().len(), torch_shapes(32, 4, 4).len());
        for ((a, _), (b, _)) in pairs().iter().zip(torch_shapes(32, 4, 4)) {
            assert_eq!(*a, b);
        }
    }
}

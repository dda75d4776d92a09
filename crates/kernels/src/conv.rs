//! Data movement around the matrix products of a 2-D convolution, NCHW f32.
//!
//! A convolution of `n` images is one product per batch when its input is
//! laid out as im2col rows `[ci * kh * kw, n * oh * ow]` (row `(c, ky, kx)`
//! holds plane `c` shifted by `(ky, kx)` for every output pixel of every
//! image): the weight gradient is `dY · colᵀ`, the input gradient's columns
//! are `Wᵀ · dY`, scattered back by [`col2im`]. Rows of that layout are
//! contiguous copies of input rows (for stride 1), so building it costs one
//! pass, in parallel over rows, with no NHWC transposition.

use rayon::prelude::*;
use std::ops::Range;

/// Shape of a convolution's input and kernel: `n` images of `ci` planes of
/// `h` x `w`, a `kh` x `kw` kernel moved by `stride` (rows, columns) over the
/// input padded by `pad` zeros on both sides of each axis. Dilation 1, one
/// group.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvGeom {
    /// Images in the batch.
    pub n: usize,
    /// Input channels.
    pub ci: usize,
    /// Input height.
    pub h: usize,
    /// Input width.
    pub w: usize,
    /// Kernel height.
    pub kh: usize,
    /// Kernel width.
    pub kw: usize,
    /// Stride along rows and columns (non-zero).
    pub stride: [usize; 2],
    /// Zeros added before and after each axis (rows, columns).
    pub pad: [usize; 2],
}

impl ConvGeom {
    /// Output height and width, `None` when the kernel does not fit in the
    /// padded input or a stride is zero.
    pub fn out_hw(&self) -> Option<(usize, usize)> {
        let side = |len: usize, k: usize, s: usize, p: usize| {
            let padded = len + 2 * p;
            (s > 0 && k > 0 && padded >= k).then(|| (padded - k) / s + 1)
        };
        Some((
            side(self.h, self.kh, self.stride[0], self.pad[0])?,
            side(self.w, self.kw, self.stride[1], self.pad[1])?,
        ))
    }

    /// Rows of the im2col layout: `ci * kh * kw`.
    pub fn rows(&self) -> usize {
        self.ci * self.kh * self.kw
    }

    /// Output pixels per image.
    fn out_pixels(&self) -> usize {
        let (oh, ow) = self.out_hw().expect("a valid geometry");
        oh * ow
    }

    /// Images per chunk so that one chunk's im2col buffer stays within
    /// `budget` bytes (at least one image).
    pub fn images_per_chunk(&self, budget: usize) -> usize {
        let per_image = self.rows() * self.out_pixels() * std::mem::size_of::<f32>();
        (budget / per_image.max(1)).clamp(1, self.n.max(1))
    }
}

/// Output columns `lo..hi` of one row whose input column `ox * s + k - p`
/// lies inside `0..w`.
fn valid_columns(ow: usize, w: usize, k: usize, s: usize, p: usize) -> (usize, usize) {
    let lo = if p > k { (p - k).div_ceil(s) } else { 0 }.min(ow);
    let hi = (w + p).saturating_sub(k).div_ceil(s).min(ow).max(lo);
    (lo, hi)
}

/// im2col of `images` of `x` (`(n, ci, h, w)` contiguous) into `col`,
/// `[g.rows(), images.len() * oh * ow]`: `col[(c, ky, kx), (j, oy, ox)] =
/// x[images.start + j, c, oy * sy + ky - py, ox * sx + kx - px]`, zero
/// outside the image. Parallel over rows.
pub fn im2col(x: &[f32], g: &ConvGeom, images: Range<usize>, col: &mut [f32]) {
    let (oh, ow) = g.out_hw().expect("a valid geometry");
    let (plane, per) = (g.h * g.w, oh * ow);
    let len = images.len() * per;
    assert_eq!(x.len(), g.n * g.ci * plane, "input size");
    assert_eq!(col.len(), g.rows() * len, "im2col buffer size");
    col.par_chunks_mut(len.max(1))
        .enumerate()
        .for_each(|(r, row)| {
            let c = r / (g.kh * g.kw);
            for (j, img) in images.clone().enumerate() {
                let src = &x[(img * g.ci + c) * plane..][..plane];
                fill_im2col_row(src, g, r, 0..oh, &mut row[j * per..][..per]);
            }
        });
}

/// Row `r` = `(c, ky, kx)` of the im2col layout for output rows `oys` of
/// one image, from `src`, that image's plane `c` (`h * w`): `out[(oy -
/// oys.start) * ow + ox] = src[oy * sy + ky - py, ox * sx + kx - px]`, zero
/// outside the plane. Shared by [`im2col`] and [`im2col_tile`].
fn fill_im2col_row(src: &[f32], g: &ConvGeom, r: usize, oys: Range<usize>, out: &mut [f32]) {
    let (_, ow) = g.out_hw().expect("a valid geometry");
    let ([sy, sx], [py, px]) = (g.stride, g.pad);
    let (ky, kx) = ((r / g.kw) % g.kh, r % g.kw);
    let (lo, hi) = valid_columns(ow, g.w, kx, sx, px);
    for (i, oy) in oys.enumerate() {
        let out = &mut out[i * ow..][..ow];
        let iy = oy * sy + ky;
        if iy < py || iy - py >= g.h {
            out.fill(0.0);
            continue;
        }
        let line = &src[(iy - py) * g.w..][..g.w];
        out[..lo].fill(0.0);
        out[hi..].fill(0.0);
        if sx == 1 {
            let start = lo + kx - px;
            out[lo..hi].copy_from_slice(&line[start..start + hi - lo]);
        } else {
            for (ox, o) in out.iter_mut().enumerate().take(hi).skip(lo) {
                *o = line[ox * sx + kx - px];
            }
        }
    }
}

/// The im2col block of output rows `oys` of image `img` of `x` (`(n, ci,
/// h, w)` contiguous) into `col`, resized to `[g.rows(), oys.len() * ow]`:
/// one tile of the forward convolution and of the weight gradient.
pub(crate) fn im2col_tile(
    x: &[f32],
    g: &ConvGeom,
    img: usize,
    oys: Range<usize>,
    col: &mut Vec<f32>,
) {
    let (_, ow) = g.out_hw().expect("a valid geometry");
    let len = oys.len() * ow;
    // Every value is written below, so only a grown buffer's new part is
    // cleared (clearing whole tiles was 3 % of a U-Net training step).
    col.resize(g.rows() * len, 0.0);
    let plane = g.h * g.w;
    for (r, row) in col.chunks_mut(len.max(1)).enumerate() {
        let c = r / (g.kh * g.kw);
        let src = &x[(img * g.ci + c) * plane..][..plane];
        fill_im2col_row(src, g, r, oys.clone(), row);
    }
}

/// The im2col block of output rows `oys` of image `img` as a matrix
/// `[g.rows(), oys.len() * ow]`: the slice from its first element and its
/// row stride. A pointwise convolution (1x1 kernel, stride 1, no padding)
/// reads its input in place (rows `oys` of each plane, row stride `h * w`),
/// since its im2col block would be a copy of it (30 of the SR3's 94
/// convolutions); any other is built into `col` by [`im2col_tile`].
pub(crate) fn tile_matrix<'a>(
    x: &'a [f32],
    g: &ConvGeom,
    img: usize,
    oys: Range<usize>,
    col: &'a mut Vec<f32>,
) -> (&'a [f32], usize) {
    let pointwise = g.kh == 1 && g.kw == 1 && g.stride == [1, 1] && g.pad == [0, 0];
    if !pointwise {
        let len = oys.len() * g.out_hw().expect("a valid geometry").1;
        im2col_tile(x, g, img, oys, col);
        return (col, len);
    }
    let plane = g.h * g.w;
    let start = img * g.ci * plane + oys.start * g.w;
    let end = (img * g.ci + g.ci - 1) * plane + oys.end * g.w;
    (&x[start..end], plane)
}

/// The adjoint of [`im2col`]: `dx` (`(images, ci, h, w)`, the chunk's
/// images) receives the sum of every `dcol` entry at the input pixel it was
/// copied from; entries that came from padding are dropped. Overwrites `dx`.
/// Parallel over (image, channel) planes, each written by one task.
pub fn col2im(dcol: &[f32], g: &ConvGeom, images: usize, dx: &mut [f32]) {
    let (oh, ow) = g.out_hw().expect("a valid geometry");
    let (plane, per) = (g.h * g.w, oh * ow);
    let len = images * per;
    assert_eq!(dcol.len(), g.rows() * len, "im2col buffer size");
    assert_eq!(dx.len(), images * g.ci * plane, "input gradient size");
    let ([sy, sx], [py, px]) = (g.stride, g.pad);
    dx.par_chunks_mut(plane.max(1))
        .enumerate()
        .for_each(|(p, out)| {
            let (j, c) = (p / g.ci, p % g.ci);
            out.fill(0.0);
            for ky in 0..g.kh {
                for kx in 0..g.kw {
                    let r = (c * g.kh + ky) * g.kw + kx;
                    let (lo, hi) = valid_columns(ow, g.w, kx, sx, px);
                    let row = &dcol[r * len + j * per..][..per];
                    for oy in 0..oh {
                        let iy = oy * sy + ky;
                        if iy < py || iy - py >= g.h {
                            continue;
                        }
                        let line = &mut out[(iy - py) * g.w..][..g.w];
                        let src = &row[oy * ow..][..ow];
                        if sx == 1 {
                            let start = lo + kx - px;
                            for (d, s) in line[start..start + hi - lo].iter_mut().zip(&src[lo..hi])
                            {
                                *d += s;
                            }
                        } else {
                            for (ox, s) in src.iter().enumerate().take(hi).skip(lo) {
                                line[ox * sx + kx - px] += s;
                            }
                        }
                    }
                }
            }
        });
}

/// `(n, c, per)` batch-major to `[c, n * per]` channel-major: `dst[ch, j *
/// per + i] = src[j, ch, i]`. Parallel over channels.
pub fn to_channel_major(src: &[f32], n: usize, c: usize, per: usize, dst: &mut [f32]) {
    assert_eq!(src.len(), n * c * per, "source size");
    assert_eq!(dst.len(), n * c * per, "destination size");
    dst.par_chunks_mut((n * per).max(1))
        .enumerate()
        .for_each(|(ch, row)| {
            for j in 0..n {
                row[j * per..][..per].copy_from_slice(&src[(j * c + ch) * per..][..per]);
            }
        });
}

/// Per-channel sums of `(n, c, per)` (a bias gradient), accumulated in f64.
pub fn channel_sums(src: &[f32], n: usize, c: usize, per: usize) -> Vec<f32> {
    assert_eq!(src.len(), n * c * per, "source size");
    (0..c)
        .into_par_iter()
        .map(|ch| {
            (0..n)
                .map(|j| {
                    src[(j * c + ch) * per..][..per]
                        .iter()
                        .map(|&v| f64::from(v))
                        .sum::<f64>()
                })
                .sum::<f64>() as f32
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Deterministic pseudo-random values in [-1, 1) (a seeded xorshift),
    /// shared by the kernels' tests.
    pub(crate) fn values(len: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..len)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 40) as f32 / (1u64 << 23) as f32 - 1.0
            })
            .collect()
    }

    /// Convolutions the forward and backward kernels are checked on, as
    /// `(geometry, output channels)`: odd and even sides, 1x1 to 3x3 kernels,
    /// strides 1 and 2, paddings 0, 1 and as wide as the kernel, batches,
    /// tall frames that split into many row tiles (more than the weight
    /// gradient's groups), pointwise ones read in place over two tiles per
    /// image, and frames smaller than the kernel's reach.
    pub(crate) fn kernel_cases() -> Vec<(ConvGeom, usize)> {
        [
            (1, 4, 7, 9, 3, 1, 1, 5),
            (2, 3, 8, 8, 3, 1, 1, 16),
            (3, 5, 11, 6, 3, 2, 1, 4),
            (1, 2, 6, 10, 1, 1, 0, 3),
            (2, 4, 9, 7, 2, 2, 0, 6),
            (2, 3, 6, 5, 2, 1, 0, 4),
            (1, 32, 70, 66, 3, 1, 1, 8),
            (1, 1, 2, 2, 3, 1, 1, 1),
            (1, 2, 5, 4, 3, 1, 0, 3),
            (2, 8, 300, 40, 1, 1, 0, 5),
            (1, 3, 5, 4, 1, 1, 1, 2),
        ]
        .into_iter()
        .map(|(n, ci, h, w, k, s, p, co)| {
            let g = ConvGeom {
                n,
                ci,
                h,
                w,
                kh: k,
                kw: k,
                stride: [s, s],
                pad: [p, p],
            };
            (g, co)
        })
        .collect()
    }

    /// Reference im2col entry by definition.
    fn reference_entry(x: &[f32], g: &ConvGeom, img: usize, r: usize, oy: usize, ox: usize) -> f32 {
        let (c, ky, kx) = (r / (g.kh * g.kw), (r / g.kw) % g.kh, r % g.kw);
        let iy = (oy * g.stride[0] + ky) as isize - g.pad[0] as isize;
        let ix = (ox * g.stride[1] + kx) as isize - g.pad[1] as isize;
        if iy < 0 || ix < 0 || iy >= g.h as isize || ix >= g.w as isize {
            return 0.0;
        }
        x[((img * g.ci + c) * g.h + iy as usize) * g.w + ix as usize]
    }

    fn geometries() -> Vec<ConvGeom> {
        let mut out = Vec::new();
        for (h, w) in [(5, 7), (8, 8), (1, 6), (4, 1)] {
            for (k, s, p) in [
                (3, 1, 1),
                (3, 2, 1),
                (1, 1, 0),
                (3, 1, 0),
                (2, 2, 0),
                (3, 3, 2),
            ] {
                let g = ConvGeom {
                    n: 3,
                    ci: 2,
                    h,
                    w,
                    kh: k,
                    kw: k,
                    stride: [s, s],
                    pad: [p, p],
                };
                if g.out_hw().is_some() {
                    out.push(g);
                }
            }
        }
        out
    }

    #[test]
    fn im2col_matches_its_definition() {
        for g in geometries() {
            let x = values(g.n * g.ci * g.h * g.w, 1);
            let (oh, ow) = g.out_hw().unwrap();
            let images = 1..3;
            let mut col = vec![f32::NAN; g.rows() * 2 * oh * ow];
            im2col(&x, &g, images.clone(), &mut col);
            for r in 0..g.rows() {
                for (j, img) in images.clone().enumerate() {
                    for oy in 0..oh {
                        for ox in 0..ow {
                            let got = col[r * 2 * oh * ow + j * oh * ow + oy * ow + ox];
                            assert_eq!(got, reference_entry(&x, &g, img, r, oy, ox), "{g:?}");
                        }
                    }
                }
            }
        }
    }

    /// A tile written into a reused buffer (longer, full of NaN) holds
    /// exactly the im2col columns of its rows: every value is written.
    #[test]
    fn tiles_overwrite_reused_buffers() {
        for g in geometries() {
            let x = values(g.n * g.ci * g.h * g.w, 6);
            let (oh, ow) = g.out_hw().unwrap();
            let mut col = vec![f32::NAN; g.rows() * g.n * oh * ow + 7];
            let oys = oh / 2..oh;
            im2col_tile(&x, &g, 2, oys.clone(), &mut col);
            let len = oys.len() * ow;
            assert_eq!(col.len(), g.rows() * len, "{g:?}");
            for r in 0..g.rows() {
                for (i, oy) in oys.clone().enumerate() {
                    for ox in 0..ow {
                        let got = col[r * len + i * ow + ox];
                        assert_eq!(got, reference_entry(&x, &g, 2, r, oy, ox), "{g:?}");
                    }
                }
            }
        }
    }

    /// <col2im(d), x> = <d, im2col(x)> for every geometry: the adjoint.
    #[test]
    fn col2im_is_the_adjoint_of_im2col() {
        for g in geometries() {
            let x = values(g.n * g.ci * g.h * g.w, 2);
            let (oh, ow) = g.out_hw().unwrap();
            let mut col = vec![0.0; g.rows() * g.n * oh * ow];
            im2col(&x, &g, 0..g.n, &mut col);
            let d = values(col.len(), 3);
            let mut dx = vec![f32::NAN; x.len()];
            col2im(&d, &g, g.n, &mut dx);
            let lhs: f64 = dx.iter().zip(&x).map(|(a, b)| f64::from(a * b)).sum();
            let rhs: f64 = d.iter().zip(&col).map(|(a, b)| f64::from(a * b)).sum();
            assert!(
                (lhs - rhs).abs() <= 1e-4 * rhs.abs().max(1.0),
                "{g:?}: {lhs} vs {rhs}"
            );
        }
    }

    #[test]
    fn channel_major_layout_and_sums() {
        let (n, c, per) = (3, 5, 7);
        let src = values(n * c * per, 4);
        let mut cm = vec![0.0; src.len()];
        to_channel_major(&src, n, c, per, &mut cm);
        for (j, ch, i) in
            (0..n).flat_map(|j| (0..c).flat_map(move |ch| (0..per).map(move |i| (j, ch, i))))
        {
            assert_eq!(cm[ch * n * per + j * per + i], src[(j * c + ch) * per + i]);
        }
        let sums = channel_sums(&src, n, c, per);
        for (ch, s) in sums.iter().enumerate() {
            let want: f32 = cm[ch * n * per..][..n * per].iter().sum();
            assert!((s - want).abs() < 1e-5, "{s} vs {want}");
        }
    }

    #[test]
    fn chunks_respect_the_budget() {
        let g = ConvGeom {
            n: 8,
            ci: 4,
            h: 16,
            w: 16,
            kh: 3,
            kw: 3,
            stride: [1, 1],
            pad: [1, 1],
        };
        let per_image = 36 * 256 * 4;
        assert_eq!(g.images_per_chunk(3 * per_image + 1), 3);
        assert_eq!(g.images_per_chunk(1), 1);
        assert_eq!(g.images_per_chunk(usize::MAX), 8);
    }
}

//! Structural similarity, computed as scikit-image's
//! `structural_similarity(reference, output, data_range=R, channel_axis=-1)`
//! with its defaults, which is what ELD, PMN and the PGRF paper report:
//!
//! - local means, variances and covariance over a 7x7 uniform window
//!   (`scipy.ndimage.uniform_filter`), with the sample covariance
//!   (`cov_norm = NP / (NP - 1)`, `NP = 49`);
//! - `C1 = (K1 R)^2`, `C2 = (K2 R)^2`, `K1 = 0.01`, `K2 = 0.03`;
//! - the SSIM map averaged over the plane minus a `pad = (7 - 1) / 2` border on
//!   each side, then averaged over channels.
//!
//! Why only "valid" windows are computed: scikit-image filters the whole plane
//! with `mode='reflect'` and then crops `pad` pixels from every side, and every
//! window centred inside that crop lies entirely inside the image. The
//! reflected border values therefore never reach the mean, and computing just
//! the `(H - 6) x (W - 6)` fully contained windows gives the same number with
//! no boundary handling at all.
//!
//! How it is fast: the five window sums (x, y, x^2, y^2, xy) are running sums,
//! first down the columns of a band of rows, then along each row, so each pixel
//! costs a constant amount of work whatever the window size. Bands of rows of
//! every channel run in parallel. Everything is f64: the variance is a
//! difference of two large numbers (`E[x^2] - E[x]^2`, up to 255^2), and in
//! f32 that cancellation alone costs more than the 1e-6 agreement promised
//! (scikit-image's own float32 path drifts by a few 1e-6; see
//! tests/reference/metrics_reference.py).

use super::input::{check_data_range, pair};
use super::psnr::widen;
use super::sum::sum2;
use super::{MetricError, Result};
use ndarray::ArrayView3;
use rayon::prelude::*;

/// Output rows per parallel task. Fixed, so the summation order (and the last
/// bits of the result) do not depend on the thread count; each band re-reads
/// `win - 1` rows to start its column sums, about 5% extra at 128.
const BAND: usize = 128;

/// scikit-image's SSIM parameters. [`SsimOptions::skimage`] gives its defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct SsimOptions {
    /// Side of the square uniform window; odd.
    pub(crate) win_size: usize,
    pub(crate) k1: f64,
    pub(crate) k2: f64,
    /// Dynamic range of the values (255 for x255 images). scikit-image
    /// requires it for float images, so there is no default.
    pub(crate) data_range: f64,
    /// Normalise (co)variances by `NP - 1` instead of `NP`.
    pub(crate) use_sample_covariance: bool,
}

impl SsimOptions {
    /// scikit-image's defaults: 7x7 uniform window, K1 = 0.01, K2 = 0.03,
    /// sample covariance.
    pub fn skimage(data_range: f64) -> Self {
        SsimOptions {
            win_size: 7,
            k1: 0.01,
            k2: 0.03,
            data_range,
            use_sample_covariance: true,
        }
    }

    fn validate(&self) -> Result<()> {
        check_data_range(self.data_range)?;
        let bad = |m: String| Err(MetricError::InvalidOption(m));
        if self.win_size.is_multiple_of(2) {
            return bad(format!("SSIM window must be odd, got {}", self.win_size));
        }
        if self.use_sample_covariance && self.win_size < 3 {
            return bad("SSIM sample covariance needs a window of at least 3".into());
        }
        if !(self.k1 >= 0.0 && self.k1.is_finite() && self.k2 >= 0.0 && self.k2.is_finite()) {
            return bad(format!(
                "SSIM K1 and K2 must be finite and not negative, got {} and {}",
                self.k1, self.k2
            ));
        }
        Ok(())
    }
}

/// Mean SSIM over channels of two `(C, H, W)` images.
pub fn ssim(
    output: ArrayView3<f32>,
    reference: ArrayView3<f32>,
    opts: &SsimOptions,
) -> Result<f64> {
    let per = ssim_channels(output, reference, opts)?;
    Ok(channel_mean(&per))
}

/// SSIM of each channel (scikit-image's per-channel values before its mean).
pub(crate) fn ssim_channels(
    output: ArrayView3<f32>,
    reference: ArrayView3<f32>,
    opts: &SsimOptions,
) -> Result<Vec<f64>> {
    let p = pair(output, reference)?;
    ssim_channels_mapped(&p.output, &p.reference, p.dims, widen, widen, opts)
}

pub(crate) fn channel_mean(per: &[f64]) -> f64 {
    per.iter().sum::<f64>() / per.len() as f64
}

/// Constants of the SSIM formula for one call.
struct Consts {
    inv_np: f64,
    cov_norm: f64,
    c1: f64,
    c2: f64,
}

/// Per-channel SSIM of two row-major `(C, H, W)` buffers whose stored values
/// `fx`/`fy` turn into the measured ones (see `psnr::mse_mapped`).
pub(crate) fn ssim_channels_mapped<FX, FY>(
    x: &[f32],
    y: &[f32],
    dims: (usize, usize, usize),
    fx: FX,
    fy: FY,
    opts: &SsimOptions,
) -> Result<Vec<f64>>
where
    FX: Fn(f32) -> f64 + Sync,
    FY: Fn(f32) -> f64 + Sync,
{
    Ok(ssim_and_sse_mapped(x, y, dims, fx, fy, opts)?.0)
}

/// Per-channel SSIM and, from the same pass over the pixels, the sum of
/// squared differences `(fx(x) - fy(y))^2` over every element (PSNR's
/// numerator for free: each value is transformed once, when its row enters
/// the window).
pub(crate) fn ssim_and_sse_mapped<FX, FY>(
    x: &[f32],
    y: &[f32],
    (c, h, w): (usize, usize, usize),
    fx: FX,
    fy: FY,
    opts: &SsimOptions,
) -> Result<(Vec<f64>, f64)>
where
    FX: Fn(f32) -> f64 + Sync,
    FY: Fn(f32) -> f64 + Sync,
{
    opts.validate()?;
    let win = opts.win_size;
    if h < win || w < win {
        return Err(MetricError::TooSmall { h, w, win });
    }
    debug_assert_eq!(x.len(), c * h * w);
    debug_assert_eq!(y.len(), c * h * w);
    let np = (win * win) as f64;
    let k = Consts {
        inv_np: 1.0 / np,
        cov_norm: if opts.use_sample_covariance {
            np / (np - 1.0)
        } else {
            1.0
        },
        c1: (opts.k1 * opts.data_range).powi(2),
        c2: (opts.k2 * opts.data_range).powi(2),
    };
    let (ho, wo) = (h - win + 1, w - win + 1);
    let bands = ho.div_ceil(BAND);
    let sums: Vec<(f64, f64)> = (0..c * bands)
        .into_par_iter()
        .map(|t| {
            let (ch, b) = (t / bands, t % bands);
            let plane = ch * h * w..(ch + 1) * h * w;
            let r0 = b * BAND;
            let r1 = (r0 + BAND).min(ho);
            let mut band = Band::new(w, win);
            band.run(&x[plane.clone()], &y[plane], r0..r1, b == 0, &fx, &fy, &k)
        })
        .collect();
    let n = (ho * wo) as f64;
    let per = sums
        .chunks(bands)
        .map(|s| s.iter().map(|v| v.0).sum::<f64>() / n)
        .collect();
    let sse = sums.iter().map(|v| v.1).sum();
    Ok((per, sse))
}

/// Working memory of one band of window rows.
struct Band {
    w: usize,
    win: usize,
    /// Column sums over the window's rows, five planes of `w`:
    /// x, y, x^2, y^2, xy.
    acc: Vec<f64>,
    /// The transformed values of the `win` rows in the window, row `r` in
    /// slot `r % win` (so each value is transformed once and the leaving
    /// row's values are at hand).
    ring_x: Vec<f64>,
    ring_y: Vec<f64>,
    /// Window sums along the current row, five planes of `w - win + 1`.
    win_sums: Vec<f64>,
    /// The SSIM map along the current row.
    map: Vec<f64>,
}

impl Band {
    fn new(w: usize, win: usize) -> Self {
        Band {
            w,
            win,
            acc: vec![0.0; 5 * w],
            ring_x: vec![0.0; win * w],
            ring_y: vec![0.0; win * w],
            win_sums: vec![0.0; 5 * (w - win + 1)],
            map: vec![0.0; w - win + 1],
        }
    }

    /// Sum of the SSIM map over the windows whose top rows are `rows`, and
    /// the sum of squared differences over the rows this band owns: all rows
    /// it reads, except the `win - 1` it shares with the band above (`first`
    /// marks the top band, which owns its first rows too). Over all bands
    /// every row is owned exactly once.
    #[allow(clippy::too_many_arguments)]
    fn run<FX, FY>(
        &mut self,
        x: &[f32],
        y: &[f32],
        rows: std::ops::Range<usize>,
        first: bool,
        fx: &FX,
        fy: &FY,
        k: &Consts,
    ) -> (f64, f64)
    where
        FX: Fn(f32) -> f64,
        FY: Fn(f32) -> f64,
    {
        let (w, win) = (self.w, self.win);
        let owned_from = if first { 0 } else { rows.start + win - 1 };
        let mut sse = 0.0;
        for r in rows.start..rows.start + win {
            let row_sse = self.enter(
                &x[r * w..(r + 1) * w],
                &y[r * w..(r + 1) * w],
                r % win,
                false,
                fx,
                fy,
            );
            if r >= owned_from {
                sse += row_sse;
            }
        }
        let mut total = 0.0;
        for r in rows.clone() {
            total += self.row_sum(k);
            if r + 1 == rows.end {
                break;
            }
            // Slide down: row r + win takes row r's ring slot.
            let rn = r + win;
            let row_sse = self.enter(
                &x[rn * w..(rn + 1) * w],
                &y[rn * w..(rn + 1) * w],
                rn % win,
                true,
                fx,
                fy,
            );
            if rn >= owned_from {
                sse += row_sse;
            }
        }
        (total, sse)
    }

    /// Transform one input row into ring slot `slot`, adding it to the column
    /// sums (and, with `replace`, removing the row that held the slot).
    /// Returns the row's sum of squared differences. Products of f32-derived
    /// values are exact in f64, so each update rounds only in the additions.
    fn enter<FX, FY>(
        &mut self,
        xr: &[f32],
        yr: &[f32],
        slot: usize,
        replace: bool,
        fx: &FX,
        fy: &FY,
    ) -> f64
    where
        FX: Fn(f32) -> f64,
        FY: Fn(f32) -> f64,
    {
        let w = self.w;
        let (xr, yr) = (&xr[..w], &yr[..w]);
        let rx = &mut self.ring_x[slot * w..(slot + 1) * w];
        let ry = &mut self.ring_y[slot * w..(slot + 1) * w];
        let (a0, rest) = self.acc.split_at_mut(w);
        let (a1, rest) = rest.split_at_mut(w);
        let (a2, rest) = rest.split_at_mut(w);
        let (a3, a4) = rest.split_at_mut(w);
        let (a4, a3, a2, a1, a0) = (
            &mut a4[..w],
            &mut a3[..w],
            &mut a2[..w],
            &mut a1[..w],
            &mut a0[..w],
        );
        if replace {
            for j in 0..w {
                let (po, qo) = (rx[j], ry[j]);
                let (pn, qn) = (fx(xr[j]), fy(yr[j]));
                a0[j] += pn - po;
                a1[j] += qn - qo;
                a2[j] += pn * pn - po * po;
                a3[j] += qn * qn - qo * qo;
                a4[j] += pn * qn - po * qo;
                rx[j] = pn;
                ry[j] = qn;
            }
        } else {
            for j in 0..w {
                let (p, q) = (fx(xr[j]), fy(yr[j]));
                a0[j] += p;
                a1[j] += q;
                a2[j] += p * p;
                a3[j] += q * q;
                a4[j] += p * q;
                rx[j] = p;
                ry[j] = q;
            }
        }
        sum2(rx, ry, |p, q| (p - q) * (p - q))
    }

    /// Sum of the SSIM map along the current row of windows: window sums by
    /// running sums over the column sums (serial chains), then the SSIM
    /// formula over the whole row (vectorised), then the row's sum.
    fn row_sum(&mut self, k: &Consts) -> f64 {
        let (w, win) = (self.w, self.win);
        let wo = w - win + 1;
        // The five chains advance together so their adds overlap (one chain
        // alone waits on every add).
        let acc = &self.acc;
        let a: [&[f64]; 5] = std::array::from_fn(|q| &acc[q * w..(q + 1) * w]);
        let mut s: [f64; 5] = std::array::from_fn(|q| a[q][..win].iter().sum());
        let (o0, rest) = self.win_sums.split_at_mut(wo);
        let (o1, rest) = rest.split_at_mut(wo);
        let (o2, rest) = rest.split_at_mut(wo);
        let (o3, o4) = rest.split_at_mut(wo);
        // Entering and leaving columns as slices of exactly `wo - 1`, so the
        // loop carries no bounds checks.
        let lead: [&[f64]; 5] = std::array::from_fn(|q| &a[q][win..win + wo - 1]);
        let trail: [&[f64]; 5] = std::array::from_fn(|q| &a[q][..wo - 1]);
        for c in 0..wo - 1 {
            o0[c] = s[0];
            o1[c] = s[1];
            o2[c] = s[2];
            o3[c] = s[3];
            o4[c] = s[4];
            s[0] += lead[0][c] - trail[0][c];
            s[1] += lead[1][c] - trail[1][c];
            s[2] += lead[2][c] - trail[2][c];
            s[3] += lead[3][c] - trail[3][c];
            s[4] += lead[4][c] - trail[4][c];
        }
        (o0[wo - 1], o1[wo - 1], o2[wo - 1], o3[wo - 1], o4[wo - 1]) =
            (s[0], s[1], s[2], s[3], s[4]);
        let ws = &self.win_sums;
        let (sx, sy) = (&ws[..wo], &ws[wo..2 * wo]);
        let (sxx, syy, sxy) = (
            &ws[2 * wo..3 * wo],
            &ws[3 * wo..4 * wo],
            &ws[4 * wo..5 * wo],
        );
        // A plain map over equal-length slices: the loop vectoriser's best case.
        let map = &mut self.map[..wo];
        for c in 0..wo {
            map[c] = ssim_at(sx[c], sy[c], sxx[c], syy[c], sxy[c], k);
        }
        sum2(map, map, |v, _| v)
    }
}

/// SSIM of one window from its five sums, in scikit-image's order of
/// operations.
#[inline(always)]
fn ssim_at(sx: f64, sy: f64, sxx: f64, syy: f64, sxy: f64, k: &Consts) -> f64 {
    let ux = sx * k.inv_np;
    let uy = sy * k.inv_np;
    let uxx = sxx * k.inv_np;
    let uyy = syy * k.inv_np;
    let uxy = sxy * k.inv_np;
    let vx = k.cov_norm * (uxx - ux * ux);
    let vy = k.cov_norm * (uyy - uy * uy);
    let vxy = k.cov_norm * (uxy - ux * uy);
    let a1 = 2.0 * ux * uy + k.c1;
    let a2 = 2.0 * vxy + k.c2;
    let b1 = ux * ux + uy * uy + k.c1;
    let b2 = vx + vy + k.c2;
    (a1 * a2) / (b1 * b2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// Direct O(win^2) evaluation of every valid window, the definition.
    fn naive(x: &Array3<f32>, y: &Array3<f32>, o: &SsimOptions) -> f64 {
        let (c, h, w) = x.dim();
        let win = o.win_size;
        let np = (win * win) as f64;
        let cov = if o.use_sample_covariance {
            np / (np - 1.0)
        } else {
            1.0
        };
        let (c1, c2) = ((o.k1 * o.data_range).powi(2), (o.k2 * o.data_range).powi(2));
        let mut chans = 0.0;
        for ch in 0..c {
            let mut sum = 0.0;
            for i in 0..=h - win {
                for j in 0..=w - win {
                    let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for di in 0..win {
                        for dj in 0..win {
                            let a = x[[ch, i + di, j + dj]] as f64;
                            let b = y[[ch, i + di, j + dj]] as f64;
                            sx += a;
                            sy += b;
                            sxx += a * a;
                            syy += b * b;
                            sxy += a * b;
                        }
                    }
                    let (ux, uy) = (sx / np, sy / np);
                    let vx = cov * (sxx / np - ux * ux);
                    let vy = cov * (syy / np - uy * uy);
                    let vxy = cov * (sxy / np - ux * uy);
                    sum += ((2.0 * ux * uy + c1) * (2.0 * vxy + c2))
                        / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
                }
            }
            chans += sum / ((h - win + 1) * (w - win + 1)) as f64;
        }
        chans / c as f64
    }

    fn image(c: usize, h: usize, w: usize, seed: u32) -> Array3<f32> {
        // Small integer hash: deterministic, no RNG crate needed.
        Array3::from_shape_fn((c, h, w), |(a, b, d)| {
            let mut v =
                (a * 7919 + b * 104_729 + d * 1_299_709) as u32 ^ seed.wrapping_mul(2_654_435_761);
            v ^= v >> 13;
            v = v.wrapping_mul(0x5bd1_e995);
            v ^= v >> 15;
            (v % 256) as f32 + 0.25 * (b as f32 - d as f32)
        })
    }

    #[test]
    fn running_sums_match_the_definition() {
        // Sizes that cross band boundaries (ho > BAND) and odd windows.
        for (c, h, w, win, sample) in [
            (2, 140, 23, 7, true),
            (1, 9, 300, 7, true),
            (3, 11, 11, 3, false),
            (1, 5, 8, 5, true),
            (1, 4, 4, 1, false),
        ] {
            let x = image(c, h, w, 1);
            let y = image(c, h, w, 2).mapv(|v| 0.5 * v + 40.0);
            let mut o = SsimOptions::skimage(255.0);
            o.win_size = win;
            o.use_sample_covariance = sample;
            let fast = ssim(y.view(), x.view(), &o).unwrap();
            let slow = naive(&x, &y, &o);
            assert!(
                (fast - slow).abs() < 1e-12,
                "{c}x{h}x{w} win {win}: {fast} vs {slow}"
            );
        }
    }

    #[test]
    fn fused_squared_differences_count_every_row_once() {
        // Several bands (ho > BAND) so rows shared between bands are involved.
        for (c, h, w) in [(2, 300, 19), (1, 7, 7), (3, 129 + 6, 8)] {
            let x = image(c, h, w, 8);
            let y = image(c, h, w, 9);
            let (xs, ys) = (x.as_slice().unwrap(), y.as_slice().unwrap());
            let o = SsimOptions::skimage(255.0);
            let (_, sse) = ssim_and_sse_mapped(xs, ys, (c, h, w), widen, widen, &o).unwrap();
            let want: f64 = xs
                .iter()
                .zip(ys)
                .map(|(&a, &b)| (a as f64 - b as f64).powi(2))
                .sum();
            assert!(
                (sse - want).abs() <= 1e-12 * want,
                "{c}x{h}x{w}: {sse} vs {want}"
            );
        }
    }

    #[test]
    fn identical_images_score_exactly_one() {
        let x = image(4, 30, 41, 3);
        assert_eq!(
            ssim(x.view(), x.view(), &SsimOptions::skimage(255.0)).unwrap(),
            1.0
        );
    }

    #[test]
    fn symmetric_in_its_arguments() {
        let (x, y) = (image(2, 20, 17, 4), image(2, 20, 17, 5));
        let o = SsimOptions::skimage(255.0);
        let a = ssim(x.view(), y.view(), &o).unwrap();
        let b = ssim(y.view(), x.view(), &o).unwrap();
        assert!((a - b).abs() < 1e-15, "{a} vs {b}");
    }

    #[test]
    fn too_small_and_bad_options_are_refused() {
        let x = Array3::<f32>::zeros((4, 6, 10));
        let o = SsimOptions::skimage(255.0);
        let e = ssim(x.view(), x.view(), &o).unwrap_err();
        assert_eq!(
            e,
            MetricError::TooSmall {
                h: 6,
                w: 10,
                win: 7
            }
        );
        assert!(e.to_string().contains("6x10"), "{e}");
        let x = Array3::<f32>::zeros((1, 9, 9));
        for bad in [
            SsimOptions {
                win_size: 4,
                ..o.clone()
            },
            SsimOptions {
                win_size: 1,
                ..o.clone()
            },
            SsimOptions {
                k1: -0.1,
                ..o.clone()
            },
            SsimOptions {
                data_range: 0.0,
                ..o.clone()
            },
        ] {
            let e = ssim(x.view(), x.view(), &bad).unwrap_err();
            assert!(matches!(e, MetricError::InvalidOption(_)), "{bad:?}: {e}");
        }
    }

    #[test]
    fn strided_views_give_the_same_answer() {
        // A (H, W, C) array viewed as (C, H, W) is not in standard layout.
        let x = image(3, 15, 12, 6);
        let y = image(3, 15, 12, 7);
        let xt = x
            .view()
            .permuted_axes([1, 2, 0])
            .as_standard_layout()
            .into_owned();
        let yt = y
            .view()
            .permuted_axes([1, 2, 0])
            .as_standard_layout()
            .into_owned();
        let o = SsimOptions::skimage(255.0);
        let a = ssim(x.view(), y.view(), &o).unwrap();
        let b = ssim(
            xt.view().permuted_axes([2, 0, 1]),
            yt.view().permuted_axes([2, 0, 1]),
            &o,
        )
        .unwrap();
        assert_eq!(a, b);
    }
}

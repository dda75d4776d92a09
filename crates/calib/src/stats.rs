//! Streaming per-pixel statistics over a frame stack: Welford's running mean
//! and sum of squared deviations in f64, so memory stays at two f64 arrays per
//! frame size however many frames are averaged, and the result does not lose
//! precision to catastrophic cancellation (sum x^2 - n mean^2 in f32 would).
//! Row means are kept per frame (a few thousand numbers) to separate row noise
//! from per-pixel noise afterwards.

use ndarray::Array3;
use rayon::prelude::*;

#[derive(Clone, Debug)]
pub(crate) struct PixelStats {
    pub(crate) ph: usize,
    pub(crate) pw: usize,
    /// Sensor-row parity of each packed plane (from the CFA).
    pub(crate) plane_rows: [usize; 4],
    n: u32,
    mean: Vec<f64>,
    m2: Vec<f64>,
    /// Per frame, the mean of every sensor row (2 * ph values).
    row_means: Vec<Vec<f64>>,
}

impl PixelStats {
    pub(crate) fn new(ph: usize, pw: usize, plane_rows: [usize; 4]) -> PixelStats {
        PixelStats {
            ph,
            pw,
            plane_rows,
            n: 0,
            mean: vec![0.0; 4 * ph * pw],
            m2: vec![0.0; 4 * ph * pw],
            row_means: Vec::new(),
        }
    }

    /// Add one packed frame `(4, ph, pw)` of DN.
    pub(crate) fn push(&mut self, frame: &[u16]) {
        assert_eq!(
            frame.len(),
            self.mean.len(),
            "frame size checked by the caller"
        );
        self.n += 1;
        let n = self.n as f64;
        let pw = self.pw;
        self.mean
            .par_chunks_mut(pw)
            .zip(self.m2.par_chunks_mut(pw))
            .zip(frame.par_chunks(pw))
            .for_each(|((m, s), x)| {
                for j in 0..m.len() {
                    let v = x[j] as f64;
                    let d = v - m[j];
                    m[j] += d / n;
                    s[j] += d * (v - m[j]);
                }
            });
        // Sensor-row means: packed row i of the planes with parity d is sensor row 2i + d.
        let (ph, rows) = (self.ph, &self.plane_rows);
        let mut means = vec![0.0f64; 2 * ph];
        let mut counts = vec![0usize; 2 * ph];
        for p in 0..4 {
            for i in 0..ph {
                let r = 2 * i + rows[p];
                let s: u64 = frame[(p * ph + i) * pw..(p * ph + i + 1) * pw]
                    .iter()
                    .map(|&v| v as u64)
                    .sum();
                means[r] += s as f64;
                counts[r] += pw;
            }
        }
        for (m, c) in means.iter_mut().zip(&counts) {
            if *c > 0 {
                *m /= *c as f64;
            }
        }
        self.row_means.push(means);
    }

    pub(crate) fn mean(&self) -> Array3<f64> {
        Array3::from_shape_vec((4, self.ph, self.pw), self.mean.clone()).expect("shape")
    }

    /// Unbiased temporal variance (n - 1 in the denominator).
    pub(crate) fn var(&self) -> Array3<f64> {
        let d = (self.n.max(2) - 1) as f64;
        Array3::from_shape_vec(
            (4, self.ph, self.pw),
            self.m2.iter().map(|s| s / d).collect(),
        )
        .expect("shape")
    }

    /// Row noise and whole-frame offset drift, separated from each other and
    /// from the per-pixel noise that also moves row means: (sigma_H^2,
    /// sigma_O^2), DN^2. With x = mu + o(frame) + h(frame, row) + e(pixel)
    /// over F frames of R rows of W samples, let D be a row mean's
    /// deviation from its temporal mean, O a frame's average D over its
    /// rows and Z = D - O. Then, from the expectations,
    ///
    ///   A = var(Z) F/(F-1) / (1 - 1/R) = sigma_H^2 + sigma_e^2 / W,
    ///   B = var(O) F/(F-1)             = sigma_O^2 + A / R,
    ///
    /// and each pixel's temporal variance is v = sigma_e^2 + sigma_H^2 +
    /// sigma_O^2, so sigma_O^2 = B - A / R and sigma_H^2 =
    /// (A - (mean(v) - sigma_O^2) / W) / (1 - 1/W). An offset that moves
    /// the whole frame (readout drift, a cooler's cycle) is not row noise.
    pub(crate) fn row_and_frame_variance(&self) -> (f64, f64) {
        let f = self.row_means.len();
        if f < 2 {
            return (0.0, 0.0);
        }
        let rows = self.row_means[0].len();
        let ff = f as f64;
        let col_mean: Vec<f64> = (0..rows)
            .map(|r| self.row_means.iter().map(|v| v[r]).sum::<f64>() / ff)
            .collect();
        let mut ss_z = 0.0;
        let mut offsets = Vec::with_capacity(f);
        for v in &self.row_means {
            let d: Vec<f64> = v.iter().zip(&col_mean).map(|(x, m)| x - m).collect();
            let o = d.iter().sum::<f64>() / rows as f64;
            ss_z += d.iter().map(|x| (x - o).powi(2)).sum::<f64>();
            offsets.push(o);
        }
        let rr = rows as f64;
        // Z has (F - 1)(R - 1) degrees of freedom over F R values.
        let var_z = ss_z / (rr * ff);
        let a = var_z * ff / (ff - 1.0) / (1.0 - 1.0 / rr);
        let om = offsets.iter().sum::<f64>() / ff;
        let var_o = offsets.iter().map(|o| (o - om).powi(2)).sum::<f64>() / ff;
        let b = var_o * ff / (ff - 1.0);
        let frame = (b - a / rr).max(0.0);
        let w = (2 * self.pw) as f64;
        let mean_v = self.m2.iter().sum::<f64>() / self.m2.len() as f64 / (ff - 1.0);
        let row = ((a - (mean_v - frame) / w) / (1.0 - 1.0 / w)).max(0.0);
        (row, frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welford_matches_two_pass_statistics() {
        let (ph, pw) = (3, 5);
        let frames: Vec<Vec<u16>> = (0..7u16)
            .map(|f| {
                (0..4 * ph * pw)
                    .map(|i| 1000 + (i as u16 * 7 + f * f * 13) % 97)
                    .collect()
            })
            .collect();
        let mut s = PixelStats::new(ph, pw, [0, 0, 1, 1]);
        for f in &frames {
            s.push(f);
        }
        let (m, v) = (s.mean(), s.var());
        for i in 0..4 * ph * pw {
            let xs: Vec<f64> = frames.iter().map(|f| f[i] as f64).collect();
            let mean = xs.iter().sum::<f64>() / 7.0;
            let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 6.0;
            assert!((m.as_slice().unwrap()[i] - mean).abs() < 1e-9);
            assert!((v.as_slice().unwrap()[i] - var).abs() < 1e-9);
        }
    }
}

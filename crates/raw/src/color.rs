//! Camera RGB -> sRGB: the colour matrix and the sRGB transfer curve.
//!
//! DNG's ColorMatrix maps XYZ to camera RGB. As dcraw does, we form
//! camera-from-sRGB = ColorMatrix x sRGB->XYZ(D65), normalise its rows so that
//! sRGB white maps to camera white (white balance has already made neutrals
//! equal in camera space), and invert it.

/// Linear sRGB (D65) -> XYZ, IEC 61966-2-1.
pub const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124564, 0.3575761, 0.1804375],
    [0.2126729, 0.7151522, 0.0721750],
    [0.0193339, 0.1191920, 0.9503041],
];

/// A 3x3 colour matrix, row-major.
pub type Mat3 = [[f64; 3]; 3];

pub(crate) const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The product `a x b`.
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

/// Inverse of a 3x3 matrix, or None when it is (numerically) singular.
pub(crate) fn invert(m: &Mat3) -> Option<Mat3> {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    let c = |a: usize, b: usize, x: usize, y: usize| m[a][b] * m[x][y] - m[a][y] * m[x][b];
    let adj = [
        [c(1, 1, 2, 2), -c(0, 1, 2, 2), c(0, 1, 1, 2)],
        [-c(1, 0, 2, 2), c(0, 0, 2, 2), -c(0, 0, 1, 2)],
        [c(1, 0, 2, 1), -c(0, 0, 2, 1), c(0, 0, 1, 1)],
    ];
    let mut inv = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            inv[i][j] = adj[i][j] / det;
        }
    }
    Some(inv)
}

/// Camera-from-sRGB matrix (white-balanced camera RGB from linear sRGB) for
/// a DNG-style XYZ->camera matrix: rows normalised so that sRGB white maps
/// to camera white. None when a row sums to zero.
pub fn camera_from_srgb(xyz_to_cam: &[[f32; 3]; 3]) -> Option<Mat3> {
    let x2c: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| xyz_to_cam[i][j] as f64));
    let mut cam_from_srgb = mul(&x2c, &SRGB_TO_XYZ);
    for row in cam_from_srgb.iter_mut() {
        let s: f64 = row.iter().sum();
        if !s.is_finite() || s.abs() < 1e-9 {
            return None;
        }
        row.iter_mut().for_each(|v| *v /= s);
    }
    Some(cam_from_srgb)
}

/// sRGB-from-camera matrix for a DNG-style XYZ->camera matrix, or None when
/// the matrix cannot be used (singular, or a row that sums to zero): the
/// inverse of [`camera_from_srgb`].
pub fn srgb_from_camera(xyz_to_cam: &[[f32; 3]; 3]) -> Option<Mat3> {
    invert(&camera_from_srgb(xyz_to_cam)?)
}

/// XYZ (D65) from white-balanced camera RGB: sRGB->XYZ x
/// [`srgb_from_camera`], the colour pgrf's preview gives a camera value.
pub fn xyz_from_camera(xyz_to_cam: &[[f32; 3]; 3]) -> Option<Mat3> {
    Some(mul(&SRGB_TO_XYZ, &srgb_from_camera(xyz_to_cam)?))
}

/// sRGB opto-electronic transfer function (linear [0, 1] -> encoded [0, 1]).
#[inline]
pub fn srgb_encode(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Inverse of [`srgb_encode`]: encoded [0, 1] -> linear [0, 1].
#[inline]
pub fn srgb_decode(e: f32) -> f32 {
    let e = e.clamp(0.0, 1.0);
    if e <= 0.040_449_936 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transfer_curve_reference_points() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_encode(0.003_130_8) - 0.040_449_936).abs() < 1e-6);
        // 18% grey encodes to 0.4613561 (118/255).
        assert!((srgb_encode(0.18) - 0.461_356_1).abs() < 1e-6);
        assert!((srgb_encode(0.5) - 0.735_357).abs() < 1e-6);
    }

    #[test]
    fn decode_inverts_encode() {
        for i in 0..=1000 {
            let x = i as f32 / 1000.0;
            assert!((srgb_decode(srgb_encode(x)) - x).abs() < 2e-6, "{x}");
        }
    }

    #[test]
    fn inverse_is_an_inverse() {
        let m = [[2.0, 1.0, 0.5], [0.1, 3.0, 0.2], [0.3, 0.4, 1.5]];
        let i = invert(&m).unwrap();
        let p = mul(&m, &i);
        for r in 0..3 {
            for c in 0..3 {
                assert!((p[r][c] - IDENTITY[r][c]).abs() < 1e-12);
            }
        }
        assert!(invert(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }

    #[test]
    fn camera_white_maps_to_srgb_white() {
        // Canon 550D D65 ColorMatrix (from the sample DNG).
        let cm = [
            [0.6461, -0.1164, -0.0857],
            [-0.3825, 1.1597, 0.2534],
            [-0.0416, 0.154, 0.6039],
        ];
        let m = srgb_from_camera(&cm).unwrap();
        for row in m {
            assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        }
        // And a saturated camera red stays mostly red in sRGB.
        assert!(m[0][0] > 1.0 && m[1][0] < 0.0);
    }
}

//! The homography `H` with `b ~ H a` (`a` in the first image, `b` in the second): normalised direct
//! linear transform on four points (the minimal sample) or more (least squares, for local
//! optimisation), and its residual, the squared transfer error in the second image (COLMAP's
//! `HomographyMatrixEstimator`).

use super::linalg::{Mat3, Normalisation, from_vec9, is_finite3, mul3, null_basis};
use super::ransac::Estimator;

/// Homography estimation for LO-RANSAC: the same DLT is the minimal and the local solver.
pub(crate) struct HomographyEstimator;

impl Estimator for HomographyEstimator {
    type Model = Mat3;
    const SAMPLE_SIZE: usize = 4;
    const LOCAL_MIN_POINTS: usize = 4;

    fn minimal(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
        models.extend(homography_dlt(a, b));
    }

    fn local(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
        models.extend(homography_dlt(a, b));
    }

    fn residual(h: &Mat3, a: [f64; 2], b: [f64; 2]) -> f64 {
        transfer_error_squared(h, a, b)
    }
}

/// The DLT homography of four or more correspondences, in Hartley-normalised coordinates, mapped
/// back: `H = Tb⁻¹ Ĥ Ta`. `None` for coincident points or a non-finite result.
pub(crate) fn homography_dlt(a: &[[f64; 2]], b: &[[f64; 2]]) -> Option<Mat3> {
    let (ta, tb) = (Normalisation::of(a)?, Normalisation::of(b)?);
    // Two rows per point, in the points' order.
    let [v] = null_basis::<1>(2 * a.len(), |i| {
        let ([x1, y1], [x2, y2]) = (ta.apply(a[i / 2]), tb.apply(b[i / 2]));
        if i % 2 == 0 {
            [-x1, -y1, -1.0, 0.0, 0.0, 0.0, x1 * x2, y1 * x2, x2]
        } else {
            [0.0, 0.0, 0.0, -x1, -y1, -1.0, x1 * y2, y1 * y2, y2]
        }
    })?;
    let h = mul3(&mul3(&tb.inverse_matrix(), &from_vec9(&v)), &ta.matrix());
    is_finite3(&h).then_some(h)
}

/// `|b − π(H a)|²`; infinite or NaN (never an inlier) where `H a` is at infinity.
pub(crate) fn transfer_error_squared(h: &Mat3, a: [f64; 2], b: [f64; 2]) -> f64 {
    let u = h[0][0] * a[0] + h[0][1] * a[1] + h[0][2];
    let v = h[1][0] * a[0] + h[1][1] * a[1] + h[1][2];
    let w = h[2][0] * a[0] + h[2][1] * a[1] + h[2][2];
    let inverse_w = 1.0 / w;
    let dx = b[0] - u * inverse_w;
    let dy = b[1] - v * inverse_w;
    dx * dx + dy * dy
}

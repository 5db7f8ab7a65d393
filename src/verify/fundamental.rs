//! The fundamental matrix `F` with `bᵀ F a = 0`: the 7-point solver (the minimal sample: a pencil
//! `F2 + α (F1 − F2)` and the real roots of its determinant, a cubic), the normalised 8-point solver
//! (least squares with rank 2 enforced, for local optimisation), and the squared Sampson error
//! (COLMAP's `FundamentalMatrixSevenPointEstimator` / `EightPointEstimator`).

use super::linalg::{
    Mat3, Normalisation, adjugate3, det3, enforce_rank2, from_vec9, is_finite3, mul3, mul3_vec,
    mul3t_vec, null_basis, trace_of_product3, transpose3,
};
use super::poly::{MAX_DEGREE, real_roots};
use super::ransac::Estimator;

/// Fundamental matrix estimation for LO-RANSAC: 7 points, then 8-point least squares.
pub(crate) struct FundamentalEstimator;

impl Estimator for FundamentalEstimator {
    type Model = Mat3;
    const SAMPLE_SIZE: usize = 7;
    const LOCAL_MIN_POINTS: usize = 8;

    fn minimal(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
        seven_point(a, b, models);
    }

    fn local(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
        models.extend(eight_point(a, b));
    }

    fn residual(f: &Mat3, a: [f64; 2], b: [f64; 2]) -> f64 {
        sampson_error_squared(f, a, b)
    }
}

/// The row of the linear system `bᵀ F a = 0` in F's nine row-major entries.
pub(crate) fn epipolar_row(a: [f64; 2], b: [f64; 2]) -> [f64; 9] {
    let ([x1, y1], [x2, y2]) = (a, b);
    [x2 * x1, x2 * y1, x2, y2 * x1, y2 * y1, y2, x1, y1, 1.0]
}

/// The null-space basis of the normalised epipolar system (rows in the points' order), and the
/// two normalisations.
fn normalised_null_basis<const K: usize>(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
) -> Option<([[f64; 9]; K], Normalisation, Normalisation)> {
    let (ta, tb) = (Normalisation::of(a)?, Normalisation::of(b)?);
    let basis = null_basis::<K>(a.len(), |i| epipolar_row(ta.apply(a[i]), tb.apply(b[i])))?;
    Some((basis, ta, tb))
}

/// `F = Tbᵀ F̂ Ta`: a matrix of the normalised coordinates back in pixels.
fn denormalise(f: &Mat3, ta: &Normalisation, tb: &Normalisation) -> Mat3 {
    mul3(&mul3(&transpose3(&tb.matrix()), f), &ta.matrix())
}

/// The up to three fundamental matrices through seven correspondences, appended to `models` in
/// ascending order of `α`.
pub(crate) fn seven_point(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
    let Some(([v1, v2], ta, tb)) = normalised_null_basis::<2>(a, b) else {
        return;
    };
    let (f1, f2) = (from_vec9(&v1), from_vec9(&v2));
    let d: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| f1[i][j] - f2[i][j]));
    // det(F2 + α D) = det F2 + α tr(adj(F2) D) + α² tr(F2 adj(D)) + α³ det D.
    let cubic = [
        det3(&f2),
        trace_of_product3(&adjugate3(&f2), &d),
        trace_of_product3(&f2, &adjugate3(&d)),
        det3(&d),
    ];
    let mut roots = [0.0; MAX_DEGREE];
    let count = real_roots(&cubic, &mut roots);
    for &alpha in &roots[..count] {
        let f: Mat3 = std::array::from_fn(|i| std::array::from_fn(|j| f2[i][j] + alpha * d[i][j]));
        let f = denormalise(&f, &ta, &tb);
        if is_finite3(&f) {
            models.push(f);
        }
    }
}

/// The normalised 8-point fundamental matrix of eight or more correspondences: the least-squares
/// null vector, its smallest singular value set to zero.
pub(crate) fn eight_point(a: &[[f64; 2]], b: &[[f64; 2]]) -> Option<Mat3> {
    let ([v], ta, tb) = normalised_null_basis::<1>(a, b)?;
    let f = denormalise(&enforce_rank2(&from_vec9(&v)), &ta, &tb);
    is_finite3(&f).then_some(f)
}

/// Squared Sampson error `(bᵀFa)² / ((Fa)₀² + (Fa)₁² + (Fᵀb)₀² + (Fᵀb)₁²)`: NaN (never an inlier)
/// when the denominator is zero.
pub(crate) fn sampson_error_squared(f: &Mat3, a: [f64; 2], b: [f64; 2]) -> f64 {
    let ha = [a[0], a[1], 1.0];
    let hb = [b[0], b[1], 1.0];
    let fa = mul3_vec(f, &ha);
    let ftb = mul3t_vec(f, &hb);
    let btfa = hb[0] * fa[0] + hb[1] * fa[1] + fa[2];
    btfa * btfa / (fa[0] * fa[0] + fa[1] * fa[1] + ftb[0] * ftb[0] + ftb[1] * ftb[1])
}

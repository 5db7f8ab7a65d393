//! A pure translation `b = a + t`: the model COLMAP's watermark test fits to the inliers that lie
//! near the image border (`TranslationTransformEstimator<2>`).

use super::ransac::Estimator;

/// Translation estimation for LO-RANSAC: one correspondence, or the mean shift of many.
pub(crate) struct TranslationEstimator;

impl Estimator for TranslationEstimator {
    type Model = [f64; 2];
    const SAMPLE_SIZE: usize = 1;
    const LOCAL_MIN_POINTS: usize = 1;

    fn minimal(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<[f64; 2]>) {
        models.push([b[0][0] - a[0][0], b[0][1] - a[0][1]]);
    }

    fn local(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<[f64; 2]>) {
        let (mut sx, mut sy) = (0.0, 0.0);
        for (pa, pb) in a.iter().zip(b) {
            sx += pb[0] - pa[0];
            sy += pb[1] - pa[1];
        }
        let count = a.len() as f64;
        models.push([sx / count, sy / count]);
    }

    fn residual(t: &[f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
        let dx = b[0] - (a[0] + t[0]);
        let dy = b[1] - (a[1] + t[1]);
        dx * dx + dy * dy
    }
}

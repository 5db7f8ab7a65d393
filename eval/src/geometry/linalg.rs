//! The few 3-D operations the geometry evaluation needs: 3×3 matrices, rotations as quaternions,
//! and the least-squares similarity between two point sets (Horn 1987, closed form by quaternions).

/// A 3×3 matrix, row-major.
pub type Mat3 = [[f64; 3]; 3];
/// A 3-vector.
pub type Vec3 = [f64; 3];

pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

pub fn apply(m: &Mat3, x: Vec3) -> Vec3 {
    [0, 1, 2].map(|i| m[i][0] * x[0] + m[i][1] * x[1] + m[i][2] * x[2])
}

pub fn transpose(m: &Mat3) -> Mat3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[c][r]))
}

pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn scale(a: Vec3, s: f64) -> Vec3 {
    a.map(|v| v * s)
}

pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

/// `[t]ₓ`, so that `skew(t) · x = t × x`.
pub fn skew(t: Vec3) -> Mat3 {
    [[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]]
}

/// The inverse by cofactors; `None` when singular.
pub fn invert(m: &Mat3) -> Option<Mat3> {
    let cofactor = |r: usize, c: usize| {
        let (r1, r2, c1, c2) = ((r + 1) % 3, (r + 2) % 3, (c + 1) % 3, (c + 2) % 3);
        m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1]
    };
    let det: f64 = (0..3).map(|c| m[0][c] * cofactor(0, c)).sum();
    (det != 0.0 && det.is_finite())
        .then(|| [0, 1, 2].map(|r| [0, 1, 2].map(|c| cofactor(c, r) / det)))
}

/// The rotation of a unit quaternion `(w, x, y, z)`, as COLMAP defines it.
pub use clatch::colmap::two_view::quaternion_rotation as quaternion_to_rotation;

/// The angle of a rotation matrix, degrees.
pub fn rotation_angle_degrees(r: &Mat3) -> f64 {
    ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// A rotation about an axis (unit) by an angle in degrees (Rodrigues).
pub fn axis_angle(axis: Vec3, degrees: f64) -> Mat3 {
    let (s, c) = degrees.to_radians().sin_cos();
    let k = skew(axis);
    let k2 = mul(&k, &k);
    [0, 1, 2]
        .map(|r| [0, 1, 2].map(|col| IDENTITY[r][col] + s * k[r][col] + (1.0 - c) * k2[r][col]))
}

/// The similarity `y ≈ s · R · x + t` of least squares between matched points (Horn 1987: the
/// rotation is the eigenvector of largest eigenvalue of a 4×4 symmetric matrix, found here by
/// Jacobi rotations). `None` with fewer than 3 points or all points at one place.
pub fn similarity(x: &[Vec3], y: &[Vec3]) -> Option<(f64, Mat3, Vec3)> {
    if x.len() < 3 || x.len() != y.len() {
        return None;
    }
    let n = x.len() as f64;
    let mean = |p: &[Vec3]| scale(p.iter().fold([0.0; 3], |a, &b| add(a, b)), 1.0 / n);
    let (mx, my) = (mean(x), mean(y));
    let mut s = [[0.0; 3]; 3];
    let (mut sx, mut sy) = (0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        let (a, b) = (sub(*a, mx), sub(*b, my));
        sx += dot(a, a);
        sy += dot(b, b);
        for r in 0..3 {
            for c in 0..3 {
                s[r][c] += a[r] * b[c];
            }
        }
    }
    if sx == 0.0 || sy == 0.0 {
        return None;
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let mut n4 = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let q = largest_eigenvector(&mut n4);
    let r = quaternion_to_rotation(q);
    // Horn's symmetric scale: independent of which set is called x.
    let s = (sy / sx).sqrt();
    let t = sub(my, scale(apply(&r, mx), s));
    Some((s, r, t))
}

/// The unit eigenvector of the largest eigenvalue of a symmetric 4×4 matrix (cyclic Jacobi).
fn largest_eigenvector(a: &mut [[f64; 4]; 4]) -> [f64; 4] {
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..50 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (row_p, row_q) = (a[p], a[q]);
                a[p] = std::array::from_fn(|k| c * row_p[k] - s * row_q[k]);
                a[q] = std::array::from_fn(|k| s * row_p[k] + c * row_q[k]);
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let best = (0..4)
        .max_by(|&i, &j| a[i][i].total_cmp(&a[j][j]))
        .unwrap_or(0);
    let q = [v[0][best], v[1][best], v[2][best], v[3][best]];
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    q.map(|x| x / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn similarity_recovers_a_known_transform() {
        let r = axis_angle([0.0, 0.6, 0.8], 37.0);
        let t = [1.0, -2.0, 0.5];
        let x: Vec<Vec3> = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [0.0, 0.0, 3.0],
            [1.0, 1.0, 1.0],
        ];
        let y: Vec<Vec3> = x
            .iter()
            .map(|&p| add(scale(apply(&r, p), 2.5), t))
            .collect();
        let (s, r2, t2) = similarity(&x, &y).unwrap();
        assert!((s - 2.5).abs() < 1e-9);
        assert!(rotation_angle_degrees(&mul(&r2, &transpose(&r))) < 1e-6);
        assert!(norm(sub(t2, t)) < 1e-9);
    }

    #[test]
    fn quaternions_and_inverses() {
        let r = quaternion_to_rotation([0.5f64.sqrt(), 0.0, 0.5f64.sqrt(), 0.0]);
        assert!((rotation_angle_degrees(&r) - 90.0).abs() < 1e-9);
        let m = [[2.0, 1.0, 0.0], [0.0, 1.0, 3.0], [1.0, 0.0, 1.0]];
        let p = mul(&m, &invert(&m).unwrap());
        assert!(rotation_angle_degrees(&p) < 1e-6);
    }
}

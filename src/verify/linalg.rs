//! The small linear algebra of the two-view solvers, in `f64` with `+ − × ÷` and `sqrt` only, each
//! sum in the order written (left to right, index order), so that a CUDA kernel compiled with
//! `--fmad=false` that writes the same expressions gets the same bits.
//!
//! - 3x3 products, determinants, adjugates;
//! - Hartley normalisation of a point set (centroid to the origin, RMS distance √2);
//! - null spaces of systems of nine unknowns: Gauss–Jordan elimination for the minimal samples
//!   (exactly `9 − K` rows); for more rows the right singular vectors: Givens QR of the rows
//!   (streamed) to a 9x9 triangle, then one-sided Jacobi with a fixed number of sweeps, whose
//!   rotations come from square roots (never an angle);
//! - rank-2 enforcement of a fundamental matrix and the (σ, σ, 0) projection of an essential matrix,
//!   by the same Jacobi on 3x3.

/// A 3x3 matrix, row-major.
pub(crate) type Mat3 = [[f64; 3]; 3];

/// A 3-vector.
pub(crate) type Vec3 = [f64; 3];

/// One-sided Jacobi sweeps (each visits every column pair once). Nine columns converge to full
/// `f64` precision in 6–8 sweeps; the count is fixed so that every backend stops at the same rotation.
pub(crate) const JACOBI_SWEEPS: usize = 12;

/// `a · b`, each element `(a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j`.
pub(crate) fn mul3(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| {
        std::array::from_fn(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j])
    })
}

/// `aᵀ`.
pub(crate) fn transpose3(a: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

/// `a · v`.
pub(crate) fn mul3_vec(a: &Mat3, v: &Vec3) -> Vec3 {
    std::array::from_fn(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

/// `aᵀ · v`.
pub(crate) fn mul3t_vec(a: &Mat3, v: &Vec3) -> Vec3 {
    std::array::from_fn(|j| a[0][j] * v[0] + a[1][j] * v[1] + a[2][j] * v[2])
}

/// `a · b` of 3-vectors.
pub(crate) fn dot3(a: &Vec3, b: &Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a × b`.
pub(crate) fn cross3(a: &Vec3, b: &Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The adjugate (transposed cofactors): `adj(a) · a = det(a) · I`.
pub(crate) fn adjugate3(a: &Mat3) -> Mat3 {
    let cofactor =
        |r0: usize, r1: usize, c0: usize, c1: usize| a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0];
    [
        [
            cofactor(1, 2, 1, 2),
            -cofactor(0, 2, 1, 2),
            cofactor(0, 1, 1, 2),
        ],
        [
            -cofactor(1, 2, 0, 2),
            cofactor(0, 2, 0, 2),
            -cofactor(0, 1, 0, 2),
        ],
        [
            cofactor(1, 2, 0, 1),
            -cofactor(0, 2, 0, 1),
            cofactor(0, 1, 0, 1),
        ],
    ]
}

/// The determinant, by the first row's cofactors.
pub(crate) fn det3(a: &Mat3) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// `Σ_ij a_ij b_ji` = trace(a · b), in row-major index order.
pub(crate) fn trace_of_product3(a: &Mat3, b: &Mat3) -> f64 {
    let mut sum = 0.0;
    for (i, row) in a.iter().enumerate() {
        for (j, value) in row.iter().enumerate() {
            sum += value * b[j][i];
        }
    }
    sum
}

/// The nine entries row-major as a matrix.
pub(crate) fn from_vec9(v: &[f64; 9]) -> Mat3 {
    [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]
}

/// Whether every entry is finite.
pub(crate) fn is_finite3(a: &Mat3) -> bool {
    a.iter().flatten().all(|v| v.is_finite())
}

/// Hartley's normalising similarity of a point set: `p ↦ s (p − c)`, `c` the centroid, `s` such
/// that the root-mean-square distance from the origin becomes √2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Normalisation {
    centre: [f64; 2],
    scale: f64,
}

impl Normalisation {
    /// The normalisation of `points`; `None` when they all coincide (or are not finite).
    pub(crate) fn of(points: &[[f64; 2]]) -> Option<Self> {
        let count = points.len() as f64;
        let (mut sx, mut sy) = (0.0, 0.0);
        for p in points {
            sx += p[0];
            sy += p[1];
        }
        let centre = [sx / count, sy / count];
        let mut squares = 0.0;
        for p in points {
            let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
            squares += dx * dx + dy * dy;
        }
        let rms = (squares / count).sqrt();
        let scale = std::f64::consts::SQRT_2 / rms;
        // An overflowing spread gives `s = 0`, NaN fails every comparison: no normalisation either way.
        (rms > 0.0 && scale > 0.0 && scale.is_finite()).then_some(Self { centre, scale })
    }

    /// `s (p − c)`.
    pub(crate) fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        [
            (p[0] - self.centre[0]) * self.scale,
            (p[1] - self.centre[1]) * self.scale,
        ]
    }

    /// The map as a matrix on homogeneous points: `[[s, 0, −s cx], [0, s, −s cy], [0, 0, 1]]`.
    pub(crate) fn matrix(&self) -> Mat3 {
        let s = self.scale;
        [
            [s, 0.0, -(s * self.centre[0])],
            [0.0, s, -(s * self.centre[1])],
            [0.0, 0.0, 1.0],
        ]
    }

    /// The inverse map: `[[1/s, 0, cx], [0, 1/s, cy], [0, 0, 1]]`.
    pub(crate) fn inverse_matrix(&self) -> Mat3 {
        let r = 1.0 / self.scale;
        [
            [r, 0.0, self.centre[0]],
            [0.0, r, self.centre[1]],
            [0.0, 0.0, 1.0],
        ]
    }
}

/// One rotation of one-sided Jacobi for the Gram entries `α = |u_p|², β = |u_q|², γ = u_p · u_q`:
/// `(c, s)` with `c² + s² = 1` that makes the two columns orthogonal, from square roots only;
/// `None` when they already are (γ = 0).
fn jacobi_rotation(alpha: f64, beta: f64, gamma: f64) -> Option<(f64, f64)> {
    if gamma == 0.0 {
        return None;
    }
    let zeta = (beta - alpha) / (2.0 * gamma);
    // The smaller root of t² + 2ζt − 1 = 0; an overflowing ζ² gives t = 0 (no rotation), not NaN.
    let t = 1.0 / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
    let t = if zeta < 0.0 { -t } else { t };
    let c = 1.0 / (1.0 + t * t).sqrt();
    Some((c, c * t))
}

/// One-sided Jacobi on the columns `cols` (each of `R` entries), accumulating the rotations into the
/// columns of `v`: afterwards the columns are mutually orthogonal (`A V = U Σ`).
fn jacobi_columns<const R: usize, const C: usize>(cols: &mut [[f64; R]; C], v: &mut [[f64; C]; C]) {
    for _ in 0..JACOBI_SWEEPS {
        for p in 0..C {
            for q in p + 1..C {
                let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
                for i in 0..R {
                    alpha += cols[p][i] * cols[p][i];
                    beta += cols[q][i] * cols[q][i];
                    gamma += cols[p][i] * cols[q][i];
                }
                let Some((c, s)) = jacobi_rotation(alpha, beta, gamma) else {
                    continue;
                };
                rotate_pair(cols, p, q, c, s);
                rotate_pair(v, p, q, c, s);
            }
        }
    }
}

/// Columns `p, q` ← `(c p − s q, s p + c q)`.
fn rotate_pair<const N: usize, const C: usize>(
    cols: &mut [[f64; N]; C],
    p: usize,
    q: usize,
    c: f64,
    s: f64,
) {
    for i in 0..N {
        let (a, b) = (cols[p][i], cols[q][i]);
        cols[p][i] = c * a - s * b;
        cols[q][i] = s * a + c * b;
    }
}

/// `|col|²` of each column.
fn squared_norms<const R: usize, const C: usize>(cols: &[[f64; R]; C]) -> [f64; C] {
    std::array::from_fn(|j| {
        let mut sum = 0.0;
        for value in &cols[j] {
            sum += value * value;
        }
        sum
    })
}

/// Column indices by `(norm, index)` ascending (insertion sort: the order is total and stable, so
/// ties, and NaN which compares false, go by index).
fn ascending_order<const C: usize>(norms: &[f64; C]) -> [usize; C] {
    let mut order: [usize; C] = std::array::from_fn(|j| j);
    for k in 1..C {
        let mut at = k;
        while at > 0 && norms[order[at]] < norms[order[at - 1]] {
            order.swap(at, at - 1);
            at -= 1;
        }
    }
    order
}

/// A matrix of nine columns reduced, row by row, to an upper triangle `R` with the same `AᵀA`
/// (Givens rotations), so that any number of rows costs 9x9 storage.
pub(crate) struct RowReduction {
    r: [[f64; 9]; 9],
}

impl RowReduction {
    /// No rows yet.
    pub(crate) fn new() -> Self {
        Self { r: [[0.0; 9]; 9] }
    }

    /// Rotates `row` into the triangle, eliminating its entries left to right.
    pub(crate) fn add_row(&mut self, row: [f64; 9]) {
        let mut a = row;
        for k in 0..9 {
            if a[k] == 0.0 {
                continue;
            }
            let pivot = self.r[k][k];
            let h = (pivot * pivot + a[k] * a[k]).sqrt();
            let (c, s) = (pivot / h, a[k] / h);
            self.r[k][k] = h;
            a[k] = 0.0;
            for j in k + 1..9 {
                let (rj, aj) = (self.r[k][j], a[j]);
                self.r[k][j] = c * rj + s * aj;
                a[j] = c * aj - s * rj;
            }
        }
    }

    /// The right singular vectors of the rows added, the smallest singular value first, with the
    /// squared singular values in the same order.
    pub(crate) fn right_singular_vectors(&self) -> ([[f64; 9]; 9], [f64; 9]) {
        let mut cols: [[f64; 9]; 9] =
            std::array::from_fn(|j| std::array::from_fn(|i| self.r[i][j]));
        let mut v: [[f64; 9]; 9] =
            std::array::from_fn(|j| std::array::from_fn(|i| if i == j { 1.0 } else { 0.0 }));
        jacobi_columns(&mut cols, &mut v);
        let norms = squared_norms(&cols);
        let order = ascending_order(&norms);
        (order.map(|j| v[j]), order.map(|j| norms[j]))
    }
}

/// A basis of the (least-squares) null space of the `count` rows `row(0), row(1), …` (made in that
/// order, and stored together only for a minimal sample: no allocation), the vector that matters
/// most last: for exactly `9 − K` rows (a minimal sample) the exact [`null_space`]; for more, the
/// `K` right singular vectors with the smallest singular values, the smallest last.
pub(crate) fn null_basis<const K: usize>(
    count: usize,
    mut row: impl FnMut(usize) -> [f64; 9],
) -> Option<[[f64; 9]; K]> {
    if count + K == 9 {
        let mut rows = [[0.0; 9]; 9];
        for (i, r) in rows[..count].iter_mut().enumerate() {
            *r = row(i);
        }
        return null_space::<K>(&rows[..count]);
    }
    let mut reduction = RowReduction::new();
    for i in 0..count {
        reduction.add_row(row(i));
    }
    let (vectors, _) = reduction.right_singular_vectors();
    Some(std::array::from_fn(|k| vectors[K - 1 - k]))
}

/// The null space of `9 − K` rows of nine columns by Gauss–Jordan elimination with full pivoting,
/// for the minimal samples (a fraction of the cost of the Jacobi route of [`null_basis`]): each step
/// takes the largest magnitude among the remaining rows and the columns not yet pivots (scanning rows,
/// then columns, ascending; the first on ties), swaps its row up, divides it by the pivot and clears
/// the pivot's column in every other row. The columns never chosen are free; the vector of free
/// column `f` (ascending) has 1 at `f`, 0 at the other free columns and `−m[i][f]` at the `i`-th
/// pivot's column. `None` for another row count or a zero (or non-finite) pivot: rank below `9 − K`.
pub(crate) fn null_space<const K: usize>(rows: &[[f64; 9]]) -> Option<[[f64; 9]; K]> {
    let rank = 9 - K;
    if rows.len() != rank {
        return None;
    }
    let mut m = [[0.0; 9]; 9];
    m[..rank].copy_from_slice(rows);
    let mut pivot_of_row = [0usize; 9];
    let mut is_pivot = [false; 9];
    for row in 0..rank {
        // The scan keeps the first entry larger than all before it: the first (row-major) place of
        // the largest magnitude. Found in two passes: the largest magnitude, column by column (the
        // maximum of numbers does not depend on their order; NaN never counts), then its first place.
        let mut largest = [-1.0f64; 9];
        for values in &m[row..rank] {
            for c in 0..9 {
                let magnitude = if is_pivot[c] { -1.0 } else { values[c].abs() };
                if magnitude > largest[c] {
                    largest[c] = magnitude;
                }
            }
        }
        let mut best = -1.0;
        for value in largest {
            if value > best {
                best = value;
            }
        }
        // `best < 0`: every candidate is NaN (the scan would go on with column 0 and a NaN model,
        // which no solver keeps).
        if best <= 0.0 || !best.is_finite() {
            return None;
        }
        let (mut best_row, mut best_col) = (row, 0);
        'scan: for r in row..rank {
            for c in 0..9 {
                if !is_pivot[c] && m[r][c].abs() == best {
                    (best_row, best_col) = (r, c);
                    break 'scan;
                }
            }
        }
        m.swap(row, best_row);
        let pivot = m[row][best_col];
        for k in 0..9 {
            m[row][k] /= pivot;
        }
        let pivot_row = m[row];
        for r in 0..rank {
            if r == row {
                continue;
            }
            let factor = m[r][best_col];
            for k in 0..9 {
                m[r][k] -= factor * pivot_row[k];
            }
        }
        pivot_of_row[row] = best_col;
        is_pivot[best_col] = true;
    }
    let mut free = [0usize; K];
    let mut count = 0;
    for (c, pivot) in is_pivot.iter().enumerate() {
        if !pivot {
            free[count] = c;
            count += 1;
        }
    }
    Some(std::array::from_fn(|j| {
        let mut v = [0.0; 9];
        v[free[j]] = 1.0;
        for (i, &p) in pivot_of_row[..rank].iter().enumerate() {
            v[p] = -m[i][free[j]];
        }
        v
    }))
}

/// The SVD of a 3x3 matrix: `A V = W` with orthogonal columns `W_j = σ_j u_j` (all stored as
/// columns), `order` the column indices by singular value ascending, `norms` the `σ_j²`.
struct Svd3 {
    w: [[f64; 3]; 3],
    v: [[f64; 3]; 3],
    order: [usize; 3],
    norms: [f64; 3],
}

fn svd3(a: &Mat3) -> Svd3 {
    let mut cols: [[f64; 3]; 3] = std::array::from_fn(|j| std::array::from_fn(|i| a[i][j]));
    let mut v: [[f64; 3]; 3] =
        std::array::from_fn(|j| std::array::from_fn(|i| if i == j { 1.0 } else { 0.0 }));
    jacobi_columns(&mut cols, &mut v);
    let norms = squared_norms(&cols);
    Svd3 {
        w: cols,
        v,
        order: ascending_order(&norms),
        norms,
    }
}

/// `Σ_j w_j v_jᵀ` over the columns `js`, in that order.
fn outer_sum(w: &[[f64; 3]; 3], v: &[[f64; 3]; 3], js: &[usize]) -> Mat3 {
    let mut m = [[0.0; 3]; 3];
    for &j in js {
        for (r, row) in m.iter_mut().enumerate() {
            for (c, value) in row.iter_mut().enumerate() {
                *value += w[j][r] * v[j][c];
            }
        }
    }
    m
}

/// The nearest matrix of rank 2 (Frobenius): the smallest singular value set to zero.
pub(crate) fn enforce_rank2(a: &Mat3) -> Mat3 {
    let Svd3 { w, v, order, .. } = svd3(a);
    outer_sum(&w, &v, &[order[2], order[1]])
}

// Kept for the relative-pose step that follows verification (COLMAP's `compute_relative_pose`) and
// tested here; the five-point solver's matrices satisfy the constraints already.
#[cfg_attr(not(test), allow(dead_code))]
/// The nearest essential matrix up to scale: singular values `(σ1, σ2, σ3)` become `(σ, σ, 0)` with
/// `σ = (σ1 + σ2) / 2`. `None` when the two larger singular values are zero.
pub(crate) fn project_to_essential(a: &Mat3) -> Option<Mat3> {
    let Svd3 { w, v, order, norms } = svd3(a);
    let (s1, s2) = (norms[order[2]].sqrt(), norms[order[1]].sqrt());
    if s1 == 0.0 || s2 == 0.0 {
        return None;
    }
    let sigma = (s1 + s2) / 2.0;
    // W_j σ / σ_j is σ u_j.
    let mut scaled = w;
    for (j, s) in [(order[2], s1), (order[1], s2)] {
        let factor = sigma / s;
        scaled[j] = scaled[j].map(|x| x * factor);
    }
    Some(outer_sum(&scaled, &v, &[order[2], order[1]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frobenius(a: &Mat3) -> f64 {
        a.iter().flatten().map(|v| v * v).sum::<f64>().sqrt()
    }

    fn singular_values(a: &Mat3) -> [f64; 3] {
        let Svd3 { order, norms, .. } = svd3(a);
        order.map(|j| norms[j].sqrt())
    }

    #[test]
    fn adjugate_times_matrix_is_the_determinant() {
        let a = [[2.0, -1.0, 0.5], [0.3, 4.0, 1.0], [-2.0, 0.25, 3.0]];
        let product = mul3(&adjugate3(&a), &a);
        let det = det3(&a);
        for (i, row) in product.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let expected = if i == j { det } else { 0.0 };
                assert!((v - expected).abs() < 1e-12, "{product:?} det {det}");
            }
        }
    }

    #[test]
    fn normalisation_centres_and_scales_to_root_two() {
        let points = [[10.0, 20.0], [30.0, 20.0], [10.0, 60.0], [50.0, 0.0]];
        let n = Normalisation::of(&points).unwrap();
        let mapped: Vec<_> = points.iter().map(|p| n.apply(*p)).collect();
        let (cx, cy) = mapped
            .iter()
            .fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
        assert!(cx.abs() < 1e-12 && cy.abs() < 1e-12);
        let rms = (mapped
            .iter()
            .map(|p| p[0] * p[0] + p[1] * p[1])
            .sum::<f64>()
            / 4.0)
            .sqrt();
        assert!((rms - 2f64.sqrt()).abs() < 1e-12);
        let round_trip = mul3(&n.inverse_matrix(), &n.matrix());
        assert!((frobenius(&round_trip) - 3f64.sqrt()).abs() < 1e-12);
        assert!(Normalisation::of(&[[1.0, 1.0], [1.0, 1.0]]).is_none());
    }

    #[test]
    fn null_vector_of_eight_rows_is_exact() {
        // Rows orthogonal to a known vector: the null space is that vector, up to sign.
        let truth = [0.1, -0.4, 0.3, 0.2, 0.5, -0.1, 0.7, 0.05, -0.3];
        let norm = truth.iter().map(|v| v * v).sum::<f64>().sqrt();
        let mut rows = Vec::new();
        for k in 0..8 {
            let mut row: [f64; 9] =
                std::array::from_fn(|i| ((i * 7 + k * 3) % 11) as f64 - 5.0 + 0.1 * k as f64);
            let along = row.iter().zip(&truth).map(|(a, b)| a * b).sum::<f64>() / (norm * norm);
            for (r, t) in row.iter_mut().zip(&truth) {
                *r -= along * t;
            }
            rows.push(row);
        }
        let [v] = null_basis::<1>(rows.len(), |i| rows[i]).unwrap();
        let v_norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let cosine = v.iter().zip(&truth).map(|(a, b)| a * b).sum::<f64>() / (norm * v_norm);
        assert!((cosine.abs() - 1.0).abs() < 1e-12, "{cosine}");
    }

    #[test]
    fn gauss_jordan_null_space_is_orthogonal_to_every_row() {
        let rows: Vec<[f64; 9]> = (0..5)
            .map(|k| {
                std::array::from_fn(|i| {
                    (((i + 2) * (k + 5)) % 11) as f64 * 0.5 - 2.0 + 0.01 * (i * k) as f64
                })
            })
            .collect();
        let basis = null_space::<4>(&rows).unwrap();
        for v in &basis {
            for row in &rows {
                let dot: f64 = row.iter().zip(v).map(|(a, b)| a * b).sum();
                assert!(dot.abs() < 1e-12, "{dot}");
            }
        }
        // Independent: each has 1 where the others have 0.
        let ones: Vec<usize> = basis
            .iter()
            .map(|v| v.iter().filter(|x| **x == 1.0).count())
            .collect();
        assert!(ones.iter().all(|&n| n >= 1), "{basis:?}");
        assert!(null_space::<4>(&rows[..4]).is_none(), "wrong row count");
        assert!(
            null_space::<4>(&[[0.0; 9]; 5]).is_none(),
            "rank 0: nine free columns"
        );
    }

    #[test]
    fn singular_vectors_are_orthonormal_and_sorted() {
        let rows: Vec<[f64; 9]> = (0..20)
            .map(|k| std::array::from_fn(|i| (((i + 1) * (k + 3)) % 13) as f64 * 0.37 - 2.0))
            .collect();
        let mut reduction = RowReduction::new();
        rows.iter().for_each(|r| reduction.add_row(*r));
        let (v, sigma2) = reduction.right_singular_vectors();
        for a in 0..9 {
            for b in 0..9 {
                let dot: f64 = v[a].iter().zip(&v[b]).map(|(x, y)| x * y).sum();
                assert!((dot - if a == b { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        assert!(sigma2.windows(2).all(|w| w[0] <= w[1]), "{sigma2:?}");
        // |A v_k|² equals σ_k².
        for k in 0..9 {
            let av: f64 = rows
                .iter()
                .map(|r| r.iter().zip(&v[k]).map(|(a, b)| a * b).sum::<f64>().powi(2))
                .sum();
            assert!(
                (av - sigma2[k]).abs() < 1e-9 * sigma2[8],
                "{av} {}",
                sigma2[k]
            );
        }
    }

    #[test]
    fn rank2_and_essential_projection() {
        let a = [[3.0, 1.0, -2.0], [0.5, 2.0, 1.0], [1.0, -1.0, 4.0]];
        let f = enforce_rank2(&a);
        let before = singular_values(&a);
        let after = singular_values(&f);
        assert!(after[0] < 1e-12 * after[2], "{after:?}");
        assert!((after[1] - before[1]).abs() < 1e-12 && (after[2] - before[2]).abs() < 1e-12);
        let e = project_to_essential(&a).unwrap();
        let s = singular_values(&e);
        let sigma = (before[1] + before[2]) / 2.0;
        assert!(
            s[0] < 1e-12 && (s[1] - sigma).abs() < 1e-12 && (s[2] - sigma).abs() < 1e-12,
            "{s:?}"
        );
    }
}

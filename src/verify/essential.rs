//! The essential matrix `E` with `bᵀ E a = 0` for camera-normalised points (`K⁻¹ x`): Nistér's
//! five-point solver, written out so that every root comes from a polynomial, not an eigen solver.
//!
//! 1. `E = x X + y Y + z Z + W`, with `X, Y, Z, W` the four right singular vectors of the epipolar
//!    system with the smallest singular values (its null space for five points; its least-squares
//!    stand-in for more, COLMAP's local optimisation).
//! 2. The ten cubic constraints `det E = 0` and `E Eᵀ E − ½ tr(E Eᵀ) E = 0` in the twenty monomials
//!    of `x, y, z`, in Nistér's order, so that Gauss–Jordan elimination of the first ten leaves rows
//!    whose differences `⟨e⟩ − z⟨f⟩`, `⟨g⟩ − z⟨h⟩`, `⟨i⟩ − z⟨j⟩` are linear in `x, y, 1`.
//! 3. Those three rows form `B(z) [x y 1]ᵀ = 0`; `det B(z)` is of degree 10, and its real roots
//!    (Sturm, [`super::poly`]) give `z`; `(x, y)` comes from `B(z)`'s null vector (a cross product).
//!
//! Up to ten essential matrices, in ascending order of `z`.

use super::fundamental::{epipolar_row, sampson_error_squared};
use super::linalg::{Mat3, cross3, dot3, from_vec9, is_finite3, null_basis};
use super::poly::{MAX_DEGREE, real_roots};
use super::ransac::Estimator;

/// Essential matrix estimation for LO-RANSAC: the five-point solver on the sample and, as COLMAP
/// does, on all inliers.
pub(crate) struct EssentialEstimator;

impl Estimator for EssentialEstimator {
    type Model = Mat3;
    const SAMPLE_SIZE: usize = 5;
    const LOCAL_MIN_POINTS: usize = 6;

    fn minimal(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
        five_point(a, b, models);
    }

    fn local(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
        five_point(a, b, models);
    }

    fn residual(e: &Mat3, a: [f64; 2], b: [f64; 2]) -> f64 {
        sampson_error_squared(e, a, b)
    }
}

/// A polynomial in `x, y, z` of degree at most 1: coefficients of `x, y, z, 1`.
type Linear = [f64; 4];
/// Degree at most 2, coefficients in [`QUADRATIC`] order.
type Quadratic = [f64; 10];
/// Degree at most 3, coefficients in [`CUBIC`] order.
type Cubic = [f64; 20];

/// Exponents of `x, y, z` of each coefficient of a [`Linear`].
const LINEAR: [[u8; 3]; 4] = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]];
/// Exponents of the [`Quadratic`] coefficients.
const QUADRATIC: [[u8; 3]; 10] = [
    [2, 0, 0],
    [0, 2, 0],
    [0, 0, 2],
    [1, 1, 0],
    [1, 0, 1],
    [0, 1, 1],
    [1, 0, 0],
    [0, 1, 0],
    [0, 0, 1],
    [0, 0, 0],
];
/// Nistér's monomial order: `x³ y³ x²y xy² x²z x² y²z y² xyz xy | xz² xz x yz² yz y z³ z² z 1`.
const CUBIC: [[u8; 3]; 20] = [
    [3, 0, 0],
    [0, 3, 0],
    [2, 1, 0],
    [1, 2, 0],
    [2, 0, 1],
    [2, 0, 0],
    [0, 2, 1],
    [0, 2, 0],
    [1, 1, 1],
    [1, 1, 0],
    [1, 0, 2],
    [1, 0, 1],
    [1, 0, 0],
    [0, 1, 2],
    [0, 1, 1],
    [0, 1, 0],
    [0, 0, 3],
    [0, 0, 2],
    [0, 0, 1],
    [0, 0, 0],
];

/// Where the monomial of `exponents` sits in `table`.
fn position(table: &[[u8; 3]], exponents: [u8; 3]) -> usize {
    table.iter().position(|e| *e == exponents).unwrap_or(0)
}

/// Sum of two exponent triples.
fn add(e: [u8; 3], f: [u8; 3]) -> [u8; 3] {
    [e[0] + f[0], e[1] + f[1], e[2] + f[2]]
}

/// The product table of two monomial lists: `table[i][j]` = where `lhs[i] · rhs[j]` sits in `out`.
fn product_table<const L: usize, const R: usize>(
    lhs: &[[u8; 3]; L],
    rhs: &[[u8; 3]; R],
    out: &[[u8; 3]],
) -> [[usize; R]; L] {
    std::array::from_fn(|i| std::array::from_fn(|j| position(out, add(lhs[i], rhs[j]))))
}

/// The two product tables the constraints need, built once.
struct Products {
    linear_linear: [[usize; 4]; 4],
    quadratic_linear: [[usize; 4]; 10],
}

impl Products {
    fn new() -> Self {
        Self {
            linear_linear: product_table(&LINEAR, &LINEAR, &QUADRATIC),
            quadratic_linear: product_table(&QUADRATIC, &LINEAR, &CUBIC),
        }
    }

    fn linear_linear(&self, p: &Linear, q: &Linear) -> Quadratic {
        multiply_by_table(&self.linear_linear, p, q)
    }

    fn quadratic_linear(&self, p: &Quadratic, q: &Linear) -> Cubic {
        multiply_by_table(&self.quadratic_linear, p, q)
    }
}

/// `p · q` with `table[i][j]` the place of the product of `p`'s term `i` and `q`'s term `j`; terms
/// accumulated with `p`'s index outer, `q`'s inner.
fn multiply_by_table<const P: usize, const Q: usize, const R: usize>(
    table: &[[usize; Q]; P],
    p: &[f64; P],
    q: &[f64; Q],
) -> [f64; R] {
    let mut out = [0.0; R];
    for i in 0..P {
        for j in 0..Q {
            out[table[i][j]] += p[i] * q[j];
        }
    }
    out
}

/// The ten cubic constraints on `(x, y, z)` for the basis `X, Y, Z, W`: row 0 is `det E`, rows 1–9
/// the entries of `E Eᵀ E − ½ tr(E Eᵀ) E`, row-major.
fn constraints(basis: &[[f64; 9]; 4]) -> [Cubic; 10] {
    let products = Products::new();
    let e: [[Linear; 3]; 3] = std::array::from_fn(|i| {
        std::array::from_fn(|j| std::array::from_fn(|k| basis[k][3 * i + j]))
    });
    let mut rows = [[0.0; 20]; 10];

    // det E by the first row's cofactors.
    let minor = |r0: usize, r1: usize, c0: usize, c1: usize| {
        let (p, q) = (
            products.linear_linear(&e[r0][c0], &e[r1][c1]),
            products.linear_linear(&e[r0][c1], &e[r1][c0]),
        );
        std::array::from_fn::<f64, 10, _>(|k| p[k] - q[k])
    };
    let terms = [
        products.quadratic_linear(&minor(1, 2, 1, 2), &e[0][0]),
        products.quadratic_linear(&minor(1, 2, 0, 2), &e[0][1]),
        products.quadratic_linear(&minor(1, 2, 0, 1), &e[0][2]),
    ];
    rows[0] = std::array::from_fn(|k| terms[0][k] - terms[1][k] + terms[2][k]);

    // E Eᵀ and half its trace.
    let eet: [[Quadratic; 3]; 3] = std::array::from_fn(|i| {
        std::array::from_fn(|k| {
            let mut sum = [0.0; 10];
            for l in 0..3 {
                let product = products.linear_linear(&e[i][l], &e[k][l]);
                for (s, p) in sum.iter_mut().zip(product) {
                    *s += p;
                }
            }
            sum
        })
    });
    let half_trace: Quadratic =
        std::array::from_fn(|k| 0.5 * (eet[0][0][k] + eet[1][1][k] + eet[2][2][k]));
    for i in 0..3 {
        for j in 0..3 {
            let mut entry = [0.0; 20];
            for k in 0..3 {
                let product = products.quadratic_linear(&eet[i][k], &e[k][j]);
                for (s, p) in entry.iter_mut().zip(product) {
                    *s += p;
                }
            }
            let trace_term = products.quadratic_linear(&half_trace, &e[i][j]);
            rows[1 + 3 * i + j] = std::array::from_fn(|k| entry[k] - trace_term[k]);
        }
    }
    rows
}

/// `L⁻¹ R` for the 10x20 system `[L | R]`: Gaussian elimination with partial pivoting (the largest
/// magnitude, the lowest row on ties), then back substitution. `None` when a pivot is zero.
fn eliminate(rows: &[Cubic; 10]) -> Option<[[f64; 10]; 10]> {
    let mut m = *rows;
    for col in 0..10 {
        let mut pivot = col;
        for r in col + 1..10 {
            if m[r][col].abs() > m[pivot][col].abs() {
                pivot = r;
            }
        }
        if m[pivot][col] == 0.0 || !m[pivot][col].is_finite() {
            return None;
        }
        m.swap(col, pivot);
        for r in col + 1..10 {
            let factor = m[r][col] / m[col][col];
            for k in col..20 {
                m[r][k] -= factor * m[col][k];
            }
        }
    }
    let mut solution = [[0.0; 10]; 10];
    for row in (0..10).rev() {
        for k in 0..10 {
            let mut value = m[row][10 + k];
            for j in row + 1..10 {
                value -= m[row][j] * solution[j][k];
            }
            solution[row][k] = value / m[row][row];
        }
    }
    Some(solution)
}

/// Coefficients in `z` (lowest first) of `⟨upper⟩ − z⟨lower⟩`, where the reduced rows read
/// `lead + Σ r_k rest_k = 0` over `rest = xz² xz x yz² yz y z³ z² z 1`: the polynomials multiplying
/// `x`, `y` and `1`.
fn difference_row(upper: &[f64; 10], lower: &[f64; 10]) -> ([f64; 4], [f64; 4], [f64; 5]) {
    let (u, l) = (upper, lower);
    let x = [u[2], u[1] - l[2], u[0] - l[1], -l[0]];
    let y = [u[5], u[4] - l[5], u[3] - l[4], -l[3]];
    let one = [u[9], u[8] - l[9], u[7] - l[8], u[6] - l[7], -l[6]];
    (x, y, one)
}

/// Product of two polynomials in `z`, lowest first (`R = P + Q − 1`).
fn multiply<const P: usize, const Q: usize, const R: usize>(
    p: &[f64; P],
    q: &[f64; Q],
) -> [f64; R] {
    debug_assert_eq!(P + Q - 1, R);
    let mut out = [0.0; R];
    for i in 0..P {
        for j in 0..Q {
            out[i + j] += p[i] * q[j];
        }
    }
    out
}

/// `p − q`, elementwise.
fn subtract<const N: usize>(p: &[f64; N], q: &[f64; N]) -> [f64; N] {
    std::array::from_fn(|k| p[k] - q[k])
}

/// Horner, lowest coefficient first.
fn eval<const N: usize>(p: &[f64; N], z: f64) -> f64 {
    let mut value = p[N - 1];
    for k in (0..N - 1).rev() {
        value = value * z + p[k];
    }
    value
}

/// The up to ten essential matrices of five or more correspondences of camera-normalised points,
/// appended to `models`.
pub(crate) fn five_point(a: &[[f64; 2]], b: &[[f64; 2]], models: &mut Vec<Mat3>) {
    // W is the vector that matters most (the smallest singular vector, as COLMAP orders them): with
    // more than five exact points it alone is E, at x = y = z = 0.
    let Some(basis) = null_basis::<4>(a.len(), |i| epipolar_row(a[i], b[i])) else {
        return;
    };
    let Some(reduced) = eliminate(&constraints(&basis)) else {
        return;
    };
    // Rows e..j (4..9) lead with x²z, x², y²z, y², xyz, xy.
    let b_rows = [
        difference_row(&reduced[4], &reduced[5]),
        difference_row(&reduced[6], &reduced[7]),
        difference_row(&reduced[8], &reduced[9]),
    ];
    let [(kx, ky, k1), (lx, ly, l1), (mx, my, m1)] = b_rows;
    // det B(z) by the first row's cofactors.
    let cofactor_x: [f64; 8] = subtract(&multiply(&ly, &m1), &multiply(&l1, &my));
    let cofactor_y: [f64; 8] = subtract(&multiply(&lx, &m1), &multiply(&l1, &mx));
    let cofactor_1: [f64; 7] = subtract(&multiply(&lx, &my), &multiply(&ly, &mx));
    let (tx, ty, t1): ([f64; 11], [f64; 11], [f64; 11]) = (
        multiply(&kx, &cofactor_x),
        multiply(&ky, &cofactor_y),
        multiply(&k1, &cofactor_1),
    );
    let determinant: [f64; 11] = std::array::from_fn(|k| tx[k] - ty[k] + t1[k]);

    let mut roots = [0.0; MAX_DEGREE];
    let count = real_roots(&determinant, &mut roots);
    for &z in &roots[..count] {
        let b_of_z = b_rows.map(|(x, y, one)| [eval(&x, z), eval(&y, z), eval(&one, z)]);
        // (x, y, 1) is orthogonal to every row of B(z): the largest of the three cross products.
        let candidates = [
            cross3(&b_of_z[0], &b_of_z[1]),
            cross3(&b_of_z[0], &b_of_z[2]),
            cross3(&b_of_z[1], &b_of_z[2]),
        ];
        let mut best = candidates[0];
        for c in &candidates[1..] {
            if dot3(c, c) > dot3(&best, &best) {
                best = *c;
            }
        }
        if best[2] == 0.0 {
            continue;
        }
        let (x, y) = (best[0] / best[2], best[1] / best[2]);
        let e = from_vec9(&std::array::from_fn(|k| {
            x * basis[0][k] + y * basis[1][k] + z * basis[2][k] + basis[3][k]
        }));
        if is_finite3(&e) {
            models.push(e);
        }
    }
}

/* verify_math.cuh: the arithmetic of two-view verification (src/verify/), written once for the GPU
 * kernel (kernels/verify.cu) and for a host C++ build that is compared with the Rust reference on
 * random pairs without a GPU (host_twin/). Every function reproduces the Rust function of the same
 * name in src/verify/ operation for operation: f64 `+ - * /` and sqrt only, each sum in the order the
 * Rust source writes it, no FMA (nvcc --fmad=false, g++ -ffp-contract=off). docs/numerics.md,
 * section 7, is the contract.
 *
 * The LO-RANSAC driver is written for a "team" of threads (a warp on the GPU, one thread on the host):
 * the minimal solvers of a batch of trials run one trial per thread, local optimisation on the team's
 * leader, the residuals and the integer support over all threads; the models are then taken in the
 * CPU's order (trial by trial, solver order), so the search is the CPU's, step for step. */
#ifndef CLATCH_VERIFY_MATH_CUH
#define CLATCH_VERIFY_MATH_CUH

#include "clatch.h"

#ifdef __CUDACC__
#define CV_FN __host__ __device__ inline
#else
#include <cmath>
#include <cstring>
#define CV_FN inline
using std::fabs;
using std::sqrt;
#endif

typedef unsigned long long cv_u64;
typedef unsigned int cv_u32;

/* ---- Samples (sampler.rs) ---- */

CV_FN cv_u64 cv_splitmix64(cv_u64 z) {
    z += 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

CV_FN cv_u64 cv_sampler_key(cv_u64 seed, cv_u64 pair, cv_u64 stream) {
    return cv_splitmix64(cv_splitmix64(cv_splitmix64(seed) ^ pair) ^ stream);
}

/* Sampler::sample: `k` distinct indices below `n` (Floyd), in draw order. */
CV_FN void cv_sample(cv_u64 key, cv_u64 trial, cv_u32 n, cv_u32 k, cv_u32* out) {
    for (cv_u32 j = 0; j < k; ++j) {
        cv_u32 m = n - k + j;
        cv_u64 word = cv_splitmix64(key ^ cv_splitmix64((trial << 8) | (cv_u64)j));
        cv_u32 r = (cv_u32)(((word >> 32) * ((cv_u64)m + 1)) >> 32);
        bool taken = false;
        for (cv_u32 i = 0; i < j; ++i) taken = taken || out[i] == r;
        out[j] = taken ? m : r;
    }
}

/* ---- Small linear algebra (linalg.rs) ---- */

struct cv_vec2 {
    double x, y;
};
struct cv_mat3 {
    double m[3][3];
};

CV_FN bool cv_is_finite(double x) { return fabs(x) <= 1.7976931348623157e308; }

CV_FN cv_u64 cv_bits(double x) {
/* nvcc compiles this header for the device only (-ptx), g++ for the host twin; the build refuses
 * a test of the architecture macro in kernel sources (one PTX serves every architecture). */
#ifdef __CUDACC__
    return (cv_u64)__double_as_longlong(x);
#else
    cv_u64 b;
    memcpy(&b, &x, sizeof b);
    return b;
#endif
}

CV_FN cv_mat3 cv_mul3(const cv_mat3& a, const cv_mat3& b) {
    cv_mat3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r.m[i][j] = a.m[i][0] * b.m[0][j] + a.m[i][1] * b.m[1][j] + a.m[i][2] * b.m[2][j];
    return r;
}

CV_FN cv_mat3 cv_transpose3(const cv_mat3& a) {
    cv_mat3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r.m[i][j] = a.m[j][i];
    return r;
}

CV_FN void cv_cross3(const double* a, const double* b, double* out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

CV_FN double cv_dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

CV_FN double cv_cofactor(const cv_mat3& a, int r0, int r1, int c0, int c1) {
    return a.m[r0][c0] * a.m[r1][c1] - a.m[r0][c1] * a.m[r1][c0];
}

CV_FN cv_mat3 cv_adjugate3(const cv_mat3& a) {
    cv_mat3 r;
    r.m[0][0] = cv_cofactor(a, 1, 2, 1, 2);
    r.m[0][1] = -cv_cofactor(a, 0, 2, 1, 2);
    r.m[0][2] = cv_cofactor(a, 0, 1, 1, 2);
    r.m[1][0] = -cv_cofactor(a, 1, 2, 0, 2);
    r.m[1][1] = cv_cofactor(a, 0, 2, 0, 2);
    r.m[1][2] = -cv_cofactor(a, 0, 1, 0, 2);
    r.m[2][0] = cv_cofactor(a, 1, 2, 0, 1);
    r.m[2][1] = -cv_cofactor(a, 0, 2, 0, 1);
    r.m[2][2] = cv_cofactor(a, 0, 1, 0, 1);
    return r;
}

CV_FN double cv_det3(const cv_mat3& a) {
    return a.m[0][0] * (a.m[1][1] * a.m[2][2] - a.m[1][2] * a.m[2][1]) -
           a.m[0][1] * (a.m[1][0] * a.m[2][2] - a.m[1][2] * a.m[2][0]) +
           a.m[0][2] * (a.m[1][0] * a.m[2][1] - a.m[1][1] * a.m[2][0]);
}

CV_FN double cv_trace_of_product3(const cv_mat3& a, const cv_mat3& b) {
    double sum = 0.0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) sum += a.m[i][j] * b.m[j][i];
    return sum;
}

CV_FN cv_mat3 cv_from_vec9(const double* v) {
    cv_mat3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r.m[i][j] = v[3 * i + j];
    return r;
}

CV_FN bool cv_is_finite3(const cv_mat3& a) {
    bool ok = true;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) ok = ok && cv_is_finite(a.m[i][j]);
    return ok;
}

/* Normalisation (Hartley). */
struct cv_normalisation {
    double cx, cy, scale;
};

template <class P>
CV_FN bool cv_normalisation_of(const P& points, bool second, cv_u32 n, cv_normalisation* out) {
    double count = (double)n;
    double sx = 0.0, sy = 0.0;
    for (cv_u32 i = 0; i < n; ++i) {
        cv_vec2 p = second ? points.b(i) : points.a(i);
        sx += p.x;
        sy += p.y;
    }
    double cx = sx / count, cy = sy / count;
    double squares = 0.0;
    for (cv_u32 i = 0; i < n; ++i) {
        cv_vec2 p = second ? points.b(i) : points.a(i);
        double dx = p.x - cx, dy = p.y - cy;
        squares += dx * dx + dy * dy;
    }
    double rms = sqrt(squares / count);
    double scale = 1.4142135623730950488 / rms;
    out->cx = cx;
    out->cy = cy;
    out->scale = scale;
    return rms > 0.0 && scale > 0.0 && cv_is_finite(scale);
}

CV_FN cv_vec2 cv_normalise(const cv_normalisation& t, cv_vec2 p) {
    cv_vec2 r;
    r.x = (p.x - t.cx) * t.scale;
    r.y = (p.y - t.cy) * t.scale;
    return r;
}

CV_FN cv_mat3 cv_normalisation_matrix(const cv_normalisation& t) {
    double s = t.scale;
    cv_mat3 r = {{{s, 0.0, -(s * t.cx)}, {0.0, s, -(s * t.cy)}, {0.0, 0.0, 1.0}}};
    return r;
}

CV_FN cv_mat3 cv_normalisation_inverse(const cv_normalisation& t) {
    double r = 1.0 / t.scale;
    cv_mat3 m = {{{r, 0.0, t.cx}, {0.0, r, t.cy}, {0.0, 0.0, 1.0}}};
    return m;
}

/* One-sided Jacobi on C columns of R entries, rotations accumulated into v (columns). */
#define CV_JACOBI_SWEEPS 12

template <int R, int C>
CV_FN void cv_jacobi_columns(double (*cols)[R], double (*v)[C]) {
    for (int sweep = 0; sweep < CV_JACOBI_SWEEPS; ++sweep) {
        for (int p = 0; p < C; ++p) {
            for (int q = p + 1; q < C; ++q) {
                double alpha = 0.0, beta = 0.0, gamma = 0.0;
                for (int i = 0; i < R; ++i) {
                    alpha += cols[p][i] * cols[p][i];
                    beta += cols[q][i] * cols[q][i];
                    gamma += cols[p][i] * cols[q][i];
                }
                if (gamma == 0.0) continue;
                double zeta = (beta - alpha) / (2.0 * gamma);
                double t = 1.0 / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
                if (zeta < 0.0) t = -t;
                double c = 1.0 / sqrt(1.0 + t * t);
                double s = c * t;
                for (int i = 0; i < R; ++i) {
                    double a = cols[p][i], b = cols[q][i];
                    cols[p][i] = c * a - s * b;
                    cols[q][i] = s * a + c * b;
                }
                for (int i = 0; i < C; ++i) {
                    double a = v[p][i], b = v[q][i];
                    v[p][i] = c * a - s * b;
                    v[q][i] = s * a + c * b;
                }
            }
        }
    }
}

template <int R, int C>
CV_FN void cv_squared_norms(double (*cols)[R], double* norms) {
    for (int j = 0; j < C; ++j) {
        double sum = 0.0;
        for (int i = 0; i < R; ++i) sum += cols[j][i] * cols[j][i];
        norms[j] = sum;
    }
}

template <int C>
CV_FN void cv_ascending_order(const double* norms, int* order) {
    for (int j = 0; j < C; ++j) order[j] = j;
    for (int k = 1; k < C; ++k) {
        int at = k;
        while (at > 0 && norms[order[at]] < norms[order[at - 1]]) {
            int t = order[at];
            order[at] = order[at - 1];
            order[at - 1] = t;
            at -= 1;
        }
    }
}

/* RowReduction: Givens rotations of streamed rows into a 9x9 upper triangle. */
struct cv_row_reduction {
    double r[9][9];
};

CV_FN void cv_row_reduction_init(cv_row_reduction* t) {
    for (int i = 0; i < 9; ++i)
        for (int j = 0; j < 9; ++j) t->r[i][j] = 0.0;
}

CV_FN void cv_row_reduction_add(cv_row_reduction* t, const double* row) {
    double a[9];
    for (int k = 0; k < 9; ++k) a[k] = row[k];
    for (int k = 0; k < 9; ++k) {
        if (a[k] == 0.0) continue;
        double pivot = t->r[k][k];
        double h = sqrt(pivot * pivot + a[k] * a[k]);
        double c = pivot / h, s = a[k] / h;
        t->r[k][k] = h;
        a[k] = 0.0;
        for (int j = k + 1; j < 9; ++j) {
            double rj = t->r[k][j], aj = a[j];
            t->r[k][j] = c * rj + s * aj;
            a[j] = c * aj - s * rj;
        }
    }
}

/* The K right singular vectors with the smallest singular values, the smallest last. */
template <int K>
CV_FN void cv_row_reduction_basis(const cv_row_reduction* t, double (*basis)[9]) {
    double cols[9][9], v[9][9], norms[9];
    int order[9];
    for (int j = 0; j < 9; ++j)
        for (int i = 0; i < 9; ++i) {
            cols[j][i] = t->r[i][j];
            v[j][i] = i == j ? 1.0 : 0.0;
        }
    cv_jacobi_columns<9, 9>(cols, v);
    cv_squared_norms<9, 9>(cols, norms);
    cv_ascending_order<9>(norms, order);
    for (int k = 0; k < K; ++k)
        for (int i = 0; i < 9; ++i) basis[k][i] = v[order[K - 1 - k]][i];
}

/* null_space: Gauss-Jordan with full pivoting of exactly 9 - K rows (m holds them, modified). */
template <int K>
CV_FN bool cv_null_space(double (*m)[9], double (*basis)[9]) {
    const int rank = 9 - K;
    int pivot_of_row[9];
    bool is_pivot[9];
    for (int c = 0; c < 9; ++c) is_pivot[c] = false;
    for (int row = 0; row < rank; ++row) {
        double largest[9];
        for (int c = 0; c < 9; ++c) largest[c] = -1.0;
        for (int r = row; r < rank; ++r)
            for (int c = 0; c < 9; ++c) {
                double magnitude = is_pivot[c] ? -1.0 : fabs(m[r][c]);
                if (magnitude > largest[c]) largest[c] = magnitude;
            }
        double best = -1.0;
        for (int c = 0; c < 9; ++c)
            if (largest[c] > best) best = largest[c];
        if (best <= 0.0 || !cv_is_finite(best)) return false;
        int best_row = row, best_col = 0;
        bool found = false;
        for (int r = row; r < rank && !found; ++r)
            for (int c = 0; c < 9; ++c)
                if (!is_pivot[c] && fabs(m[r][c]) == best) {
                    best_row = r;
                    best_col = c;
                    found = true;
                    break;
                }
        for (int k = 0; k < 9; ++k) {
            double t = m[row][k];
            m[row][k] = m[best_row][k];
            m[best_row][k] = t;
        }
        double pivot = m[row][best_col];
        for (int k = 0; k < 9; ++k) m[row][k] /= pivot;
        for (int r = 0; r < rank; ++r) {
            if (r == row) continue;
            double factor = m[r][best_col];
            for (int k = 0; k < 9; ++k) m[r][k] -= factor * m[row][k];
        }
        pivot_of_row[row] = best_col;
        is_pivot[best_col] = true;
    }
    int free_cols[K] = {0};
    int count = 0;
    for (int c = 0; c < 9; ++c)
        if (!is_pivot[c]) free_cols[count++] = c;
    for (int j = 0; j < K; ++j) {
        for (int i = 0; i < 9; ++i) basis[j][i] = 0.0;
        basis[j][free_cols[j]] = 1.0;
        for (int i = 0; i < rank; ++i) basis[j][pivot_of_row[i]] = -m[i][free_cols[j]];
    }
    return true;
}

/* null_basis: rows made by `rows.row(i, out)`, i < count. */
template <int K, class Rows>
CV_FN bool cv_null_basis(cv_u32 count, const Rows& rows, double (*basis)[9]) {
    if (count + K == 9) {
        double m[9][9];
        for (int i = 0; i < 9 - K; ++i) rows.row((cv_u32)i, m[i]);
        return cv_null_space<K>(m, basis);
    }
    cv_row_reduction t;
    cv_row_reduction_init(&t);
    for (cv_u32 i = 0; i < count; ++i) {
        double row[9];
        rows.row(i, row);
        cv_row_reduction_add(&t, row);
    }
    cv_row_reduction_basis<K>(&t, basis);
    return true;
}

/* enforce_rank2: Jacobi on the 3x3 columns, the two largest kept. */
CV_FN cv_mat3 cv_enforce_rank2(const cv_mat3& a) {
    double cols[3][3], v[3][3], norms[3];
    int order[3];
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) {
            cols[j][i] = a.m[i][j];
            v[j][i] = i == j ? 1.0 : 0.0;
        }
    cv_jacobi_columns<3, 3>(cols, v);
    cv_squared_norms<3, 3>(cols, norms);
    cv_ascending_order<3>(norms, order);
    cv_mat3 m;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m.m[r][c] = 0.0;
    int js[2] = {order[2], order[1]};
    for (int k = 0; k < 2; ++k) {
        int j = js[k];
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) m.m[r][c] += cols[j][r] * v[j][c];
    }
    return m;
}

/* ---- Real roots (poly.rs) ---- */

#define CV_MAX_DEGREE 10
#define CV_BISECTIONS 128
#define CV_NEWTON_STEPS 2

struct cv_poly {
    double c[CV_MAX_DEGREE + 1];
    int degree;
};

CV_FN double cv_poly_eval(const cv_poly& p, double x) {
    double value = p.c[p.degree];
    for (int k = p.degree - 1; k >= 0; --k) value = value * x + p.c[k];
    return value;
}

struct cv_sturm {
    cv_poly chain[CV_MAX_DEGREE + 1];
    int len;
};

CV_FN bool cv_negated_remainder(const cv_poly& a, const cv_poly& b, cv_poly* out) {
    double r[CV_MAX_DEGREE + 1];
    for (int k = 0; k <= CV_MAX_DEGREE; ++k) r[k] = a.c[k];
    double lead = b.c[b.degree];
    for (int shift = a.degree - b.degree; shift >= 0; --shift) {
        double factor = r[shift + b.degree] / lead;
        for (int k = 0; k <= b.degree; ++k) r[shift + k] -= factor * b.c[k];
        r[shift + b.degree] = 0.0;
    }
    int degree = b.degree - 1;
    while (r[degree] == 0.0) {
        if (degree == 0) return false;
        degree -= 1;
    }
    double scale = -1.0 / fabs(r[degree]);
    for (int k = 0; k <= CV_MAX_DEGREE; ++k) out->c[k] = k <= degree ? r[k] * scale : 0.0;
    out->degree = degree;
    return true;
}

CV_FN void cv_sturm_init(cv_sturm* s, const cv_poly& p) {
    for (int i = 0; i <= CV_MAX_DEGREE; ++i) {
        for (int k = 0; k <= CV_MAX_DEGREE; ++k) s->chain[i].c[k] = 0.0;
        s->chain[i].degree = 0;
    }
    s->chain[0] = p;
    s->chain[1].degree = p.degree - 1;
    for (int k = 1; k <= p.degree; ++k) s->chain[1].c[k - 1] = p.c[k] * (double)k;
    int len = 2;
    while (len < CV_MAX_DEGREE + 1 && s->chain[len - 1].degree > 0) {
        if (!cv_negated_remainder(s->chain[len - 2], s->chain[len - 1], &s->chain[len])) break;
        len += 1;
    }
    s->len = len;
}

CV_FN cv_u32 cv_count_changes(const double* values, int len) {
    cv_u32 changes = 0;
    double last = 0.0;
    for (int i = 0; i < len; ++i) {
        double v = values[i];
        if (v != 0.0) {
            if ((last < 0.0 && v > 0.0) || (last > 0.0 && v < 0.0)) changes += 1;
            last = v;
        }
    }
    return changes;
}

CV_FN cv_u32 cv_variations(const cv_sturm& s, double x) {
    double values[CV_MAX_DEGREE + 1];
    for (int i = 0; i < s.len; ++i) values[i] = cv_poly_eval(s.chain[i], x);
    return cv_count_changes(values, s.len);
}

CV_FN cv_u32 cv_variations_at_infinity(const cv_sturm& s, bool at_plus) {
    double values[CV_MAX_DEGREE + 1];
    for (int i = 0; i < s.len; ++i) {
        double lead = s.chain[i].c[s.chain[i].degree];
        values[i] = (at_plus || s.chain[i].degree % 2 == 0) ? lead : -lead;
    }
    return cv_count_changes(values, s.len);
}

/* One bisection step (poly.rs `step`): whether the bracket changed (bit for bit). */
CV_FN bool cv_step(double* a, double* b, double mid, bool left) {
    double new_a = left ? *a : mid;
    double new_b = left ? mid : *b;
    bool changed = cv_bits(new_a) != cv_bits(*a) || cv_bits(new_b) != cv_bits(*b);
    *a = new_a;
    *b = new_b;
    return changed;
}

/* refine: bisection (on the sign of p, or on the Sturm count), then Newton steps in the bracket. */
CV_FN double cv_refine(const cv_poly& p, const cv_sturm& s, double a, double b, cv_u32 va) {
    double pa = cv_poly_eval(p, a), pb = cv_poly_eval(p, b);
    bool sign_change = (pa < 0.0 && pb > 0.0) || (pa > 0.0 && pb < 0.0);
    bool negative_at_a = pa < 0.0;
    for (int i = 0; i < CV_BISECTIONS; ++i) {
        double mid = 0.5 * (a + b);
        bool left;
        if (sign_change) {
            double value = cv_poly_eval(p, mid);
            left = value == 0.0 || (value < 0.0) != negative_at_a;
        } else {
            left = cv_variations(s, mid) < va;
        }
        if (!cv_step(&a, &b, mid, left)) break;
    }
    double x = 0.5 * (a + b);
    for (int i = 0; i < CV_NEWTON_STEPS; ++i) {
        double value = p.c[p.degree];
        double slope = 0.0;
        for (int k = p.degree - 1; k >= 0; --k) {
            slope = slope * x + value;
            value = value * x + p.c[k];
        }
        if (slope == 0.0) break;
        double next = x - value / slope;
        if (cv_is_finite(next) && next >= a && next <= b) x = next;
    }
    return x;
}

/* The recursion of Search::isolate as a stack: left halves first, so the roots come out ascending.
 * A frame with no root does nothing there, so it is never pushed; at most one frame per depth waits. */
struct cv_frame {
    double a, b;
    cv_u32 va, vb, depth;
};

CV_FN int cv_real_roots(const double* coeffs, int ncoeffs, double* roots) {
    for (int k = 0; k < ncoeffs; ++k)
        if (!cv_is_finite(coeffs[k])) return 0;
    int degree = -1;
    for (int k = ncoeffs - 1; k >= 0; --k)
        if (coeffs[k] != 0.0) {
            degree = k;
            break;
        }
    if (degree <= 0) return 0;
    cv_poly p;
    for (int k = 0; k <= CV_MAX_DEGREE; ++k) p.c[k] = 0.0;
    p.degree = degree;
    double lead = coeffs[degree];
    double largest = 0.0;
    for (int k = 0; k < degree; ++k) {
        p.c[k] = coeffs[k] / lead;
        double magnitude = fabs(p.c[k]);
        if (magnitude > largest) largest = magnitude;
    }
    p.c[degree] = 1.0;
    double bound = 1.0 + largest;
    if (!cv_is_finite(bound)) return 0;
    cv_sturm sturm;
    cv_sturm_init(&sturm, p);

    int found = 0;
    cv_frame stack[CV_BISECTIONS + 2];
    int top = 0;
    stack[top++] = cv_frame{-bound, bound, cv_variations_at_infinity(sturm, false), cv_variations_at_infinity(sturm, true), 0};
    while (top > 0) {
        cv_frame f = stack[--top];
        cv_u32 count = f.va > f.vb ? f.va - f.vb : 0;
        if (count == 0) continue;
        if (count == 1 || f.depth == CV_BISECTIONS) {
            if (found < CV_MAX_DEGREE) roots[found++] = cv_refine(p, sturm, f.a, f.b, f.va);
            continue;
        }
        double mid = 0.5 * (f.a + f.b);
        cv_u32 vm = cv_variations(sturm, mid);
        cv_frame right = {mid, f.b, vm, f.vb, f.depth + 1};
        cv_frame left = {f.a, mid, f.va, vm, f.depth + 1};
        if (right.va > right.vb) stack[top++] = right;
        if (left.va > left.vb) stack[top++] = left;
    }
    return found;
}

/* ---- Points ---- */

/* The matched positions of a pair (f32 widened to f64); `camera` maps them to camera-normalised
 * coordinates (Intrinsics::image_to_camera). */
struct cv_pair_points {
    const clatch_verify_point* p;
    cv_u32 n;
    bool camera;
    double ka[4], kb[4]; /* fx fy cx cy */
    CV_FN cv_vec2 a(cv_u32 i) const {
        cv_vec2 v = {(double)p[i].xa, (double)p[i].ya};
        if (camera) {
            v.x = (v.x - ka[2]) / ka[0];
            v.y = (v.y - ka[3]) / ka[1];
        }
        return v;
    }
    CV_FN cv_vec2 b(cv_u32 i) const {
        cv_vec2 v = {(double)p[i].xb, (double)p[i].yb};
        if (camera) {
            v.x = (v.x - kb[2]) / kb[0];
            v.y = (v.y - kb[3]) / kb[1];
        }
        return v;
    }
};

/* The correspondences `list[0..n)` of a base set, in that order. */
template <class Base>
struct cv_listed {
    const Base* base;
    const cv_u32* list;
    cv_u32 n;
    CV_FN cv_vec2 a(cv_u32 i) const { return base->a(list[i]); }
    CV_FN cv_vec2 b(cv_u32 i) const { return base->b(list[i]); }
};

/* A minimal sample, copied. */
struct cv_sample_points {
    cv_vec2 pa[8], pb[8];
    cv_u32 n;
    CV_FN cv_vec2 a(cv_u32 i) const { return pa[i]; }
    CV_FN cv_vec2 b(cv_u32 i) const { return pb[i]; }
};

/* ---- Models ---- */

struct cv_model {
    double m[9]; /* row-major 3x3; a translation in m[0], m[1] */
};

CV_FN cv_model cv_model_of(const cv_mat3& a) {
    cv_model r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r.m[3 * i + j] = a.m[i][j];
    return r;
}

/* fundamental.rs: epipolar_row. */
CV_FN void cv_epipolar_row(cv_vec2 a, cv_vec2 b, double* row) {
    double x1 = a.x, y1 = a.y, x2 = b.x, y2 = b.y;
    row[0] = x2 * x1;
    row[1] = x2 * y1;
    row[2] = x2;
    row[3] = y2 * x1;
    row[4] = y2 * y1;
    row[5] = y2;
    row[6] = x1;
    row[7] = y1;
    row[8] = 1.0;
}

template <class P>
struct cv_normalised_epipolar_rows {
    const P* points;
    cv_normalisation ta, tb;
    CV_FN void row(cv_u32 i, double* out) const {
        cv_epipolar_row(cv_normalise(ta, points->a(i)), cv_normalise(tb, points->b(i)), out);
    }
};

template <class P>
struct cv_epipolar_rows {
    const P* points;
    CV_FN void row(cv_u32 i, double* out) const { cv_epipolar_row(points->a(i), points->b(i), out); }
};

template <class P>
struct cv_homography_rows {
    const P* points;
    cv_normalisation ta, tb;
    CV_FN void row(cv_u32 i, double* out) const {
        cv_vec2 p1 = cv_normalise(ta, points->a(i / 2)), p2 = cv_normalise(tb, points->b(i / 2));
        double x1 = p1.x, y1 = p1.y, x2 = p2.x, y2 = p2.y;
        if (i % 2 == 0) {
            out[0] = -x1; out[1] = -y1; out[2] = -1.0; out[3] = 0.0; out[4] = 0.0; out[5] = 0.0;
            out[6] = x1 * x2; out[7] = y1 * x2; out[8] = x2;
        } else {
            out[0] = 0.0; out[1] = 0.0; out[2] = 0.0; out[3] = -x1; out[4] = -y1; out[5] = -1.0;
            out[6] = x1 * y2; out[7] = y1 * y2; out[8] = y2;
        }
    }
};

/* homography.rs: homography_dlt. */
template <class P>
CV_FN int cv_homography_dlt(const P& points, cv_model* out) {
    cv_homography_rows<P> rows;
    rows.points = &points;
    if (!cv_normalisation_of(points, false, points.n, &rows.ta)) return 0;
    if (!cv_normalisation_of(points, true, points.n, &rows.tb)) return 0;
    double basis[1][9];
    if (!cv_null_basis<1>(2 * points.n, rows, basis)) return 0;
    cv_mat3 h = cv_mul3(cv_mul3(cv_normalisation_inverse(rows.tb), cv_from_vec9(basis[0])), cv_normalisation_matrix(rows.ta));
    if (!cv_is_finite3(h)) return 0;
    out[0] = cv_model_of(h);
    return 1;
}

CV_FN double cv_transfer_error_squared(const cv_model& h, cv_vec2 a, cv_vec2 b) {
    const double* m = h.m;
    double u = m[0] * a.x + m[1] * a.y + m[2];
    double v = m[3] * a.x + m[4] * a.y + m[5];
    double w = m[6] * a.x + m[7] * a.y + m[8];
    double inverse_w = 1.0 / w;
    double dx = b.x - u * inverse_w;
    double dy = b.y - v * inverse_w;
    return dx * dx + dy * dy;
}

CV_FN cv_mat3 cv_denormalise(const cv_mat3& f, const cv_normalisation& ta, const cv_normalisation& tb) {
    return cv_mul3(cv_mul3(cv_transpose3(cv_normalisation_matrix(tb)), f), cv_normalisation_matrix(ta));
}

/* fundamental.rs: seven_point. */
template <class P>
CV_FN int cv_seven_point(const P& points, cv_model* out) {
    cv_normalised_epipolar_rows<P> rows;
    rows.points = &points;
    if (!cv_normalisation_of(points, false, points.n, &rows.ta)) return 0;
    if (!cv_normalisation_of(points, true, points.n, &rows.tb)) return 0;
    double basis[2][9];
    if (!cv_null_basis<2>(points.n, rows, basis)) return 0;
    cv_mat3 f1 = cv_from_vec9(basis[0]), f2 = cv_from_vec9(basis[1]), d;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) d.m[i][j] = f1.m[i][j] - f2.m[i][j];
    double cubic[4] = {cv_det3(f2), cv_trace_of_product3(cv_adjugate3(f2), d), cv_trace_of_product3(f2, cv_adjugate3(d)), cv_det3(d)};
    double roots[CV_MAX_DEGREE];
    int count = cv_real_roots(cubic, 4, roots);
    int models = 0;
    for (int r = 0; r < count; ++r) {
        double alpha = roots[r];
        cv_mat3 f;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) f.m[i][j] = f2.m[i][j] + alpha * d.m[i][j];
        f = cv_denormalise(f, rows.ta, rows.tb);
        if (cv_is_finite3(f)) out[models++] = cv_model_of(f);
    }
    return models;
}

/* fundamental.rs: eight_point. */
template <class P>
CV_FN int cv_eight_point(const P& points, cv_model* out) {
    cv_normalised_epipolar_rows<P> rows;
    rows.points = &points;
    if (!cv_normalisation_of(points, false, points.n, &rows.ta)) return 0;
    if (!cv_normalisation_of(points, true, points.n, &rows.tb)) return 0;
    double basis[1][9];
    if (!cv_null_basis<1>(points.n, rows, basis)) return 0;
    cv_mat3 f = cv_denormalise(cv_enforce_rank2(cv_from_vec9(basis[0])), rows.ta, rows.tb);
    if (!cv_is_finite3(f)) return 0;
    out[0] = cv_model_of(f);
    return 1;
}

CV_FN double cv_sampson_error_squared(const cv_model& f, cv_vec2 a, cv_vec2 b) {
    const double* m = f.m;
    double fa0 = m[0] * a.x + m[1] * a.y + m[2] * 1.0;
    double fa1 = m[3] * a.x + m[4] * a.y + m[5] * 1.0;
    double fa2 = m[6] * a.x + m[7] * a.y + m[8] * 1.0;
    double ftb0 = m[0] * b.x + m[3] * b.y + m[6] * 1.0;
    double ftb1 = m[1] * b.x + m[4] * b.y + m[7] * 1.0;
    double btfa = b.x * fa0 + b.y * fa1 + fa2;
    return btfa * btfa / (fa0 * fa0 + fa1 * fa1 + ftb0 * ftb0 + ftb1 * ftb1);
}

/* ---- essential.rs: Nistér's five-point solver ---- */

/* product_table(LINEAR, LINEAR, QUADRATIC) and product_table(QUADRATIC, LINEAR, CUBIC). */
CV_FN void cv_linear_linear(const double* p, const double* q, double* out) {
    const int table[4][4] = {{0, 3, 4, 6}, {3, 1, 5, 7}, {4, 5, 2, 8}, {6, 7, 8, 9}};
    for (int k = 0; k < 10; ++k) out[k] = 0.0;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) out[table[i][j]] += p[i] * q[j];
}

CV_FN void cv_quadratic_linear(const double* p, const double* q, double* out) {
    const int table[10][4] = {{0, 2, 4, 5},    {3, 1, 6, 7},    {10, 13, 16, 17}, {2, 3, 8, 9},     {4, 8, 10, 11},
                              {8, 6, 13, 14}, {5, 9, 11, 12}, {9, 7, 14, 15},   {11, 14, 17, 18}, {12, 15, 18, 19}};
    for (int k = 0; k < 20; ++k) out[k] = 0.0;
    for (int i = 0; i < 10; ++i)
        for (int j = 0; j < 4; ++j) out[table[i][j]] += p[i] * q[j];
}

CV_FN void cv_constraints(const double (*basis)[9], double (*rows)[20]) {
    double e[3][3][4];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 4; ++k) e[i][j][k] = basis[k][3 * i + j];
    /* det E by the first row's cofactors. */
    double terms[3][20];
    const int minors[3][4] = {{1, 2, 1, 2}, {1, 2, 0, 2}, {1, 2, 0, 1}};
    for (int t = 0; t < 3; ++t) {
        int r0 = minors[t][0], r1 = minors[t][1], c0 = minors[t][2], c1 = minors[t][3];
        double p[10], q[10], minor[10];
        cv_linear_linear(e[r0][c0], e[r1][c1], p);
        cv_linear_linear(e[r0][c1], e[r1][c0], q);
        for (int k = 0; k < 10; ++k) minor[k] = p[k] - q[k];
        cv_quadratic_linear(minor, e[0][t], terms[t]);
    }
    for (int k = 0; k < 20; ++k) rows[0][k] = terms[0][k] - terms[1][k] + terms[2][k];
    double eet[3][3][10];
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) {
            double sum[10];
            for (int m = 0; m < 10; ++m) sum[m] = 0.0;
            for (int l = 0; l < 3; ++l) {
                double product[10];
                cv_linear_linear(e[i][l], e[k][l], product);
                for (int m = 0; m < 10; ++m) sum[m] += product[m];
            }
            for (int m = 0; m < 10; ++m) eet[i][k][m] = sum[m];
        }
    double half_trace[10];
    for (int k = 0; k < 10; ++k) half_trace[k] = 0.5 * (eet[0][0][k] + eet[1][1][k] + eet[2][2][k]);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double entry[20];
            for (int k = 0; k < 20; ++k) entry[k] = 0.0;
            for (int k = 0; k < 3; ++k) {
                double product[20];
                cv_quadratic_linear(eet[i][k], e[k][j], product);
                for (int m = 0; m < 20; ++m) entry[m] += product[m];
            }
            double trace_term[20];
            cv_quadratic_linear(half_trace, e[i][j], trace_term);
            for (int k = 0; k < 20; ++k) rows[1 + 3 * i + j][k] = entry[k] - trace_term[k];
        }
}

/* eliminate: L^-1 R of [L | R] (10x20), partial pivoting. */
CV_FN bool cv_eliminate(double (*m)[20], double (*solution)[10]) {
    for (int col = 0; col < 10; ++col) {
        int pivot = col;
        for (int r = col + 1; r < 10; ++r)
            if (fabs(m[r][col]) > fabs(m[pivot][col])) pivot = r;
        if (m[pivot][col] == 0.0 || !cv_is_finite(m[pivot][col])) return false;
        for (int k = 0; k < 20; ++k) {
            double t = m[col][k];
            m[col][k] = m[pivot][k];
            m[pivot][k] = t;
        }
        for (int r = col + 1; r < 10; ++r) {
            double factor = m[r][col] / m[col][col];
            for (int k = col; k < 20; ++k) m[r][k] -= factor * m[col][k];
        }
    }
    for (int row = 9; row >= 0; --row)
        for (int k = 0; k < 10; ++k) {
            double value = m[row][10 + k];
            for (int j = row + 1; j < 10; ++j) value -= m[row][j] * solution[j][k];
            solution[row][k] = value / m[row][row];
        }
    return true;
}

/* multiply: product of polynomials in z, lowest first. */
CV_FN void cv_multiply(const double* p, int np, const double* q, int nq, double* out) {
    for (int k = 0; k < np + nq - 1; ++k) out[k] = 0.0;
    for (int i = 0; i < np; ++i)
        for (int j = 0; j < nq; ++j) out[i + j] += p[i] * q[j];
}

CV_FN double cv_eval_z(const double* p, int n, double z) {
    double value = p[n - 1];
    for (int k = n - 2; k >= 0; --k) value = value * z + p[k];
    return value;
}

struct cv_b_row {
    double x[4], y[4], one[5];
};

CV_FN cv_b_row cv_difference_row(const double* u, const double* l) {
    cv_b_row r;
    r.x[0] = u[2]; r.x[1] = u[1] - l[2]; r.x[2] = u[0] - l[1]; r.x[3] = -l[0];
    r.y[0] = u[5]; r.y[1] = u[4] - l[5]; r.y[2] = u[3] - l[4]; r.y[3] = -l[3];
    r.one[0] = u[9]; r.one[1] = u[8] - l[9]; r.one[2] = u[7] - l[8]; r.one[3] = u[6] - l[7]; r.one[4] = -l[6];
    return r;
}

template <class P>
CV_FN int cv_five_point(const P& points, cv_model* out) {
    cv_epipolar_rows<P> rows;
    rows.points = &points;
    double basis[4][9];
    if (!cv_null_basis<4>(points.n, rows, basis)) return 0;
    double system[10][20];
    cv_constraints(basis, system);
    double reduced[10][10];
    if (!cv_eliminate(system, reduced)) return 0;
    cv_b_row br[3] = {cv_difference_row(reduced[4], reduced[5]), cv_difference_row(reduced[6], reduced[7]),
                      cv_difference_row(reduced[8], reduced[9])};
    const cv_b_row &k = br[0], &l = br[1], &m = br[2];
    double p1[8], p2[8], cofactor_x[8], cofactor_y[8], q1[7], q2[7], cofactor_1[7];
    cv_multiply(l.y, 4, m.one, 5, p1);
    cv_multiply(l.one, 5, m.y, 4, p2);
    for (int i = 0; i < 8; ++i) cofactor_x[i] = p1[i] - p2[i];
    cv_multiply(l.x, 4, m.one, 5, p1);
    cv_multiply(l.one, 5, m.x, 4, p2);
    for (int i = 0; i < 8; ++i) cofactor_y[i] = p1[i] - p2[i];
    cv_multiply(l.x, 4, m.y, 4, q1);
    cv_multiply(l.y, 4, m.x, 4, q2);
    for (int i = 0; i < 7; ++i) cofactor_1[i] = q1[i] - q2[i];
    double tx[11], ty[11], t1[11], determinant[11];
    cv_multiply(k.x, 4, cofactor_x, 8, tx);
    cv_multiply(k.y, 4, cofactor_y, 8, ty);
    cv_multiply(k.one, 5, cofactor_1, 7, t1);
    for (int i = 0; i < 11; ++i) determinant[i] = tx[i] - ty[i] + t1[i];
    double roots[CV_MAX_DEGREE];
    int count = cv_real_roots(determinant, 11, roots);
    int models = 0;
    for (int r = 0; r < count; ++r) {
        double z = roots[r];
        double bz[3][3];
        for (int i = 0; i < 3; ++i) {
            bz[i][0] = cv_eval_z(br[i].x, 4, z);
            bz[i][1] = cv_eval_z(br[i].y, 4, z);
            bz[i][2] = cv_eval_z(br[i].one, 5, z);
        }
        double candidates[3][3];
        cv_cross3(bz[0], bz[1], candidates[0]);
        cv_cross3(bz[0], bz[2], candidates[1]);
        cv_cross3(bz[1], bz[2], candidates[2]);
        double best[3] = {candidates[0][0], candidates[0][1], candidates[0][2]};
        for (int c = 1; c < 3; ++c)
            if (cv_dot3(candidates[c], candidates[c]) > cv_dot3(best, best))
                for (int i = 0; i < 3; ++i) best[i] = candidates[c][i];
        if (best[2] == 0.0) continue;
        double x = best[0] / best[2], y = best[1] / best[2];
        cv_model e;
        bool finite = true;
        for (int i = 0; i < 9; ++i) {
            e.m[i] = x * basis[0][i] + y * basis[1][i] + z * basis[2][i] + basis[3][i];
            finite = finite && cv_is_finite(e.m[i]);
        }
        if (finite) out[models++] = e;
    }
    return models;
}

/* ---- Estimators (the Estimator trait's implementations) ---- */

#define CV_MAX_MODELS 10

struct cv_homography_estimator {
    enum { SAMPLE_SIZE = 4, LOCAL_MIN_POINTS = 4, MAX_MODELS = 1 };
    template <class P>
    CV_FN static int minimal(const P& p, cv_model* out) { return cv_homography_dlt(p, out); }
    template <class P>
    CV_FN static int local(const P& p, cv_model* out) { return cv_homography_dlt(p, out); }
    CV_FN static double residual(const cv_model& m, cv_vec2 a, cv_vec2 b) { return cv_transfer_error_squared(m, a, b); }
};

struct cv_fundamental_estimator {
    enum { SAMPLE_SIZE = 7, LOCAL_MIN_POINTS = 8, MAX_MODELS = 3 };
    template <class P>
    CV_FN static int minimal(const P& p, cv_model* out) { return cv_seven_point(p, out); }
    template <class P>
    CV_FN static int local(const P& p, cv_model* out) { return cv_eight_point(p, out); }
    CV_FN static double residual(const cv_model& m, cv_vec2 a, cv_vec2 b) { return cv_sampson_error_squared(m, a, b); }
};

struct cv_essential_estimator {
    enum { SAMPLE_SIZE = 5, LOCAL_MIN_POINTS = 6, MAX_MODELS = 10 };
    template <class P>
    CV_FN static int minimal(const P& p, cv_model* out) { return cv_five_point(p, out); }
    template <class P>
    CV_FN static int local(const P& p, cv_model* out) { return cv_five_point(p, out); }
    CV_FN static double residual(const cv_model& m, cv_vec2 a, cv_vec2 b) { return cv_sampson_error_squared(m, a, b); }
};

struct cv_translation_estimator {
    enum { SAMPLE_SIZE = 1, LOCAL_MIN_POINTS = 1, MAX_MODELS = 1 };
    template <class P>
    CV_FN static int minimal(const P& p, cv_model* out) {
        cv_vec2 a = p.a(0), b = p.b(0);
        out[0].m[0] = b.x - a.x;
        out[0].m[1] = b.y - a.y;
        return 1;
    }
    template <class P>
    CV_FN static int local(const P& p, cv_model* out) {
        double sx = 0.0, sy = 0.0;
        for (cv_u32 i = 0; i < p.n; ++i) {
            cv_vec2 a = p.a(i), b = p.b(i);
            sx += b.x - a.x;
            sy += b.y - a.y;
        }
        double count = (double)p.n;
        out[0].m[0] = sx / count;
        out[0].m[1] = sy / count;
        return 1;
    }
    CV_FN static double residual(const cv_model& t, cv_vec2 a, cv_vec2 b) {
        double dx = b.x - (a.x + t.m[0]);
        double dy = b.y - (a.y + t.m[1]);
        return dx * dx + dy * dy;
    }
};

/* ---- LO-RANSAC (ransac.rs) ---- */

struct cv_support {
    cv_u64 inliers, score;
};

CV_FN bool cv_beats(const cv_support& s, const cv_support& other) {
    return s.inliers > other.inliers || (s.inliers == other.inliers && s.score < other.score);
}

/* Rust's saturating `f64 as u64` (the value is in [0, 2^32] here; NaN gives 0). */
CV_FN cv_u64 cv_to_u64(double x) {
    if (!(x > 0.0)) return 0;
    if (x >= 18446744073709551616.0) return ~0ull;
    return (cv_u64)x;
}

CV_FN double cv_power(double x, cv_u32 t) {
    double result = 1.0, base = x;
    while (t > 0) {
        if (t & 1) result *= base;
        base *= base;
        t >>= 1;
    }
    return result;
}

CV_FN bool cv_dynamic_bound_reached(cv_u32 trial, cv_u64 inliers, cv_u32 n, int sample_size, double stop_threshold) {
    double ratio = (double)inliers / (double)n;
    double ratio_power = 1.0;
    for (int i = 0; i < sample_size; ++i) ratio_power *= ratio;
    return cv_power(1.0 - ratio_power, trial) <= stop_threshold;
}

/* What one estimation found: the best model, its support, success, and its inliers in index order
 * in the list the caller gave (inliers[0 .. support.inliers) when has_model). */
struct cv_ransac_report {
    cv_model model;
    cv_support support;
    bool has_model;
    bool success;
};

/* The team a LO-RANSAC runs on. On the host: one thread. */
struct cv_serial_team {
    enum { SIZE = 1 };
    CV_FN cv_u32 lane() const { return 0; }
    CV_FN bool leader() const { return true; }
    CV_FN void sync() const {}
    CV_FN cv_u32 count(bool flag) const { return flag ? 1u : 0u; }
    CV_FN cv_u32 rank(bool) const { return 0; }
    CV_FN cv_u64 sum(cv_u64 x) const { return x; }
};

/* The support of `model` when it beats `best` (`*out`), counted by the whole team; false as soon as
 * fewer than best.inliers are possible (the same answer as counting all, ransac.rs). */
template <class E, class Team, class P>
CV_FN bool cv_better_support(const Team& team, const cv_model& model, const P& points, double max_residual,
                             const cv_support& best, cv_support* out) {
    cv_u32 n = points.n;
    cv_u64 inliers = 0, score = 0;
    for (cv_u32 base = 0; base < n; base += Team::SIZE) {
        cv_u32 i = base + team.lane();
        bool inlier = false;
        if (i < n) {
            double r = E::residual(model, points.a(i), points.b(i));
            inlier = r <= max_residual;
            if (inlier) score += cv_to_u64((r / max_residual) * 4294967296.0);
        }
        inliers += team.count(inlier);
        cv_u32 end = n - base < (cv_u32)Team::SIZE ? n : base + Team::SIZE;
        if (inliers + (cv_u64)(n - end) < best.inliers) return false;
    }
    cv_support s = {inliers, team.sum(score)};
    if (!cv_beats(s, best)) return false;
    *out = s;
    return true;
}

/* The inliers of `model`, ascending, into `list`. */
template <class E, class Team, class P>
CV_FN void cv_write_inliers(const Team& team, const cv_model& model, const P& points, double max_residual, cv_u32* list) {
    cv_u32 n = points.n, written = 0;
    for (cv_u32 base = 0; base < n; base += Team::SIZE) {
        cv_u32 i = base + team.lane();
        bool inlier = i < n && E::residual(model, points.a(i), points.b(i)) <= max_residual;
        cv_u32 rank = team.rank(inlier); /* every lane takes part in the warp's ballot */
        if (inlier) list[written + rank] = i;
        written += team.count(inlier);
    }
    team.sync();
}

/* Trials whose minimal models are solved together, one per lane (a sample and its models are a pure
 * function of the trial's index, so solving ahead changes nothing), and the model slots they fill. */
#define CV_TRIAL_BATCH 32
#define CV_MODEL_SLOTS 128

/* Buffers the solving lanes fill and the team reads: the minimal models of a batch of trials (trial
 * j's at minimal[j * MAX_MODELS]) and the local models. */
struct cv_model_buffers {
    cv_model minimal[CV_MODEL_SLOTS];
    cv_model local[CV_MAX_MODELS];
    int minimal_count[CV_TRIAL_BATCH];
    int local_count;
};

/* lo_ransac over `points` (ransac.rs), the best model's inliers kept in `list` (points.n entries). */
template <class E, class Team, class P>
CV_FN cv_ransac_report cv_lo_ransac(const Team& team, const P& points, const clatch_verify_ransac& settings, cv_u64 seed,
                                    cv_u64 pair, cv_u64 stream, cv_u32* list, cv_model_buffers* buffers) {
    cv_ransac_report report;
    report.has_model = false;
    report.success = false;
    report.support.inliers = 0;
    report.support.score = 0;
    cv_u32 n = points.n;
    if (n < (cv_u32)E::SAMPLE_SIZE) return report;
    cv_u64 key = cv_sampler_key(seed, pair, stream);
    double max_residual = settings.max_residual;
    cv_support best = {0, ~0ull};
    cv_model best_model;
    cv_u32 trials = 0;
    bool done = false;
    const cv_u32 batch_capacity = CV_MODEL_SLOTS / E::MAX_MODELS < CV_TRIAL_BATCH ? CV_MODEL_SLOTS / E::MAX_MODELS : CV_TRIAL_BATCH;
    while (!done && trials < settings.max_trials) {
        cv_u32 batch_start = trials;
        cv_u32 batch = settings.max_trials - trials < batch_capacity ? settings.max_trials - trials : batch_capacity;
        team.sync();
        for (cv_u32 j = team.lane(); j < batch; j += Team::SIZE) {
            cv_u32 indices[8];
            cv_sample(key, batch_start + j, n, E::SAMPLE_SIZE, indices);
            cv_sample_points sample;
            sample.n = E::SAMPLE_SIZE;
            for (int k = 0; k < E::SAMPLE_SIZE; ++k) {
                sample.pa[k] = points.a(indices[k]);
                sample.pb[k] = points.b(indices[k]);
            }
            buffers->minimal_count[j] = E::minimal(sample, buffers->minimal + j * E::MAX_MODELS);
        }
        team.sync();
        for (cv_u32 j = 0; j < batch && !done; ++j) {
        cv_u32 trial = batch_start + j;
        trials = trial + 1;
        int model_count = buffers->minimal_count[j];
        for (int mi = 0; mi < model_count && !done; ++mi) {
            cv_model model = buffers->minimal[j * E::MAX_MODELS + mi];
            cv_support support;
            if (cv_better_support<E>(team, model, points, max_residual, best, &support)) {
                best = support;
                best_model = model;
                report.has_model = true;
                cv_write_inliers<E>(team, model, points, max_residual, list);
                if (support.inliers > (cv_u64)E::SAMPLE_SIZE && support.inliers >= (cv_u64)E::LOCAL_MIN_POINTS) {
                    for (int round = 0; round < 10; ++round) {
                        cv_u64 before = best.inliers;
                        if (team.leader()) {
                            cv_listed<P> inliers = {&points, list, (cv_u32)best.inliers};
                            buffers->local_count = E::local(inliers, buffers->local);
                        }
                        team.sync();
                        int local_count = buffers->local_count;
                        for (int li = 0; li < local_count; ++li) {
                            cv_model local = buffers->local[li];
                            cv_support local_support;
                            if (cv_better_support<E>(team, local, points, max_residual, best, &local_support)) {
                                best = local_support;
                                best_model = local;
                                cv_write_inliers<E>(team, local, points, max_residual, list);
                            }
                        }
                        team.sync();
                        if (best.inliers <= before) break;
                    }
                }
            }
            if (trial >= settings.min_trials && cv_dynamic_bound_reached(trial, best.inliers, n, E::SAMPLE_SIZE, settings.stop_threshold))
                done = true;
        }
        }
    }
    team.sync();
    if (report.has_model) {
        report.model = best_model;
        report.support = best;
        report.success = best.inliers >= (cv_u64)E::SAMPLE_SIZE;
    }
    return report;
}

/* ---- The choice (two_view.rs) ---- */

enum { CV_MASK_F = 0, CV_MASK_H = 1, CV_MASK_E = 2, CV_MASK_NONE = 3 };

/* The inner box test of DetectWatermark for one image: width, height as f64. */
CV_FN bool cv_inside(double w, double h, double border, cv_vec2 p) {
    double x = p.x + 0.5, y = p.y + 0.5;
    return x >= border && x <= w - border && y >= border && y <= h - border;
}

/* Lists of one pair: F, H, E inliers, and the translation's (each `count` entries). */
struct cv_pair_lists {
    cv_u32* f;
    cv_u32* h;
    cv_u32* e;
    cv_u32* t;
};

/* estimate_two_view for one pair; the chosen inliers are copied into `inliers_out`. */
template <class Team>
CV_FN void cv_estimate_two_view(const Team& team, const clatch_verify_settings& s, const clatch_verify_pair& pair,
                                const clatch_verify_point* points, cv_pair_lists lists, cv_u32* inliers_out,
                                cv_model_buffers* buffers, clatch_verify_result* result) {
    cv_u32 n = pair.count;
    if (team.leader()) {
        for (int i = 0; i < 9; ++i) {
            result->f[i] = 0.0;
            result->e[i] = 0.0;
            result->h[i] = 0.0;
        }
        result->config = CLATCH_VERIFY_DEGENERATE;
        result->models = 0;
        result->inliers_e = 0;
        result->inliers_f = 0;
        result->inliers_h = 0;
        result->inlier_count = 0;
        result->pad = 0;
    }
    if ((cv_u64)n < s.min_num_inliers) {
        team.sync();
        return;
    }
    cv_pair_points pixels;
    pixels.p = points;
    pixels.n = n;
    pixels.camera = false;
    for (int i = 0; i < 4; ++i) {
        pixels.ka[i] = pair.intrinsics_a[i];
        pixels.kb[i] = pair.intrinsics_b[i];
    }
    bool calibrated = (pair.flags & CLATCH_VERIFY_INTRINSICS) != 0;
    cv_ransac_report f = cv_lo_ransac<cv_fundamental_estimator>(team, pixels, s.fundamental, s.seed, pair.key, 1, lists.f, buffers);
    cv_ransac_report h = cv_lo_ransac<cv_homography_estimator>(team, pixels, s.homography, s.seed, pair.key, 2, lists.h, buffers);
    cv_ransac_report e;
    e.has_model = false;
    e.success = false;
    e.support.inliers = 0;
    e.support.score = 0;
    if (calibrated) {
        cv_pair_points normalised = pixels;
        normalised.camera = true;
        clatch_verify_ransac es = s.essential;
        es.max_residual = pair.essential_max_residual;
        e = cv_lo_ransac<cv_essential_estimator>(team, normalised, es, s.seed, pair.key, 0, lists.e, buffers);
    }
    cv_u64 ce = calibrated ? e.support.inliers : 0, cf = f.support.inliers, ch = h.support.inliers;
    cv_u64 min = s.min_num_inliers;
    double max_h = s.max_h_inlier_ratio;
    int config = CLATCH_VERIFY_DEGENERATE, mask = CV_MASK_NONE;
    double h_f_ratio = (double)ch / (double)cf;
    if (calibrated) {
        /* choose_calibrated */
        if (!((!e.success && !f.success && !h.success) || (ce < min && cf < min && ch < min))) {
            double e_f_ratio = (double)ce / (double)cf;
            double h_e_ratio = (double)ch / (double)ce;
            if (e.success && e_f_ratio > s.min_e_f_inlier_ratio && ce >= min) {
                cv_u64 best = ce >= cf ? ce : cf;
                mask = ce >= cf ? CV_MASK_E : CV_MASK_F;
                if (h_e_ratio > max_h) {
                    if (ch > best) mask = CV_MASK_H;
                    config = CLATCH_VERIFY_PLANAR_OR_PANORAMIC;
                } else {
                    config = CLATCH_VERIFY_CALIBRATED;
                }
            } else if (f.success && cf >= min) {
                if (h_f_ratio > max_h) {
                    mask = ch > cf ? CV_MASK_H : CV_MASK_F;
                    config = CLATCH_VERIFY_PLANAR_OR_PANORAMIC;
                } else {
                    mask = CV_MASK_F;
                    config = CLATCH_VERIFY_UNCALIBRATED;
                }
            } else if (h.success && ch >= min) {
                mask = CV_MASK_H;
                config = CLATCH_VERIFY_PLANAR_OR_PANORAMIC;
            }
        }
    } else if (!((!f.success && !h.success) || (cf < min && ch < min))) {
        /* choose_uncalibrated: F's mask always */
        config = h_f_ratio > max_h ? CLATCH_VERIFY_PLANAR_OR_PANORAMIC : CLATCH_VERIFY_UNCALIBRATED;
        mask = CV_MASK_F;
    }
    /* planar_inliers */
    if (mask != CV_MASK_NONE && config == CLATCH_VERIFY_PLANAR_OR_PANORAMIC && s.planar_keeps_homography_inliers &&
        h.success && ch >= min)
        mask = CV_MASK_H;
    if (team.leader()) {
        result->inliers_e = ce;
        result->inliers_f = cf;
        result->inliers_h = ch;
    }
    if (mask == CV_MASK_NONE) {
        team.sync();
        return;
    }
    const cv_ransac_report& chosen = mask == CV_MASK_F ? f : mask == CV_MASK_H ? h : e;
    const cv_u32* list = mask == CV_MASK_F ? lists.f : mask == CV_MASK_H ? lists.h : lists.e;
    cv_u32 count = chosen.has_model ? (cv_u32)chosen.support.inliers : 0;
    for (cv_u32 i = team.lane(); i < count; i += Team::SIZE) inliers_out[i] = list[i];
    bool watermark = false;
    if (s.detect_watermark && (pair.flags & CLATCH_VERIFY_CAMERAS) != 0 && count > 0) {
        double wa = pair.size_a[0], ha = pair.size_a[1], wb = pair.size_b[0], hb = pair.size_b[1];
        double border_a = s.watermark_border_size * sqrt(wa * wa + ha * ha);
        double border_b = s.watermark_border_size * sqrt(wb * wb + hb * hb);
        cv_u64 in_border = 0;
        for (cv_u32 base = 0; base < count; base += Team::SIZE) {
            cv_u32 i = base + team.lane();
            bool border = false;
            if (i < count) {
                cv_u32 j = list[i];
                border = !cv_inside(wa, ha, border_a, pixels.a(j)) && !cv_inside(wb, hb, border_b, pixels.b(j));
            }
            in_border += team.count(border);
        }
        double total = (double)count;
        if (!((double)in_border / total < s.watermark_min_inlier_ratio)) {
            cv_listed<cv_pair_points> candidates = {&pixels, list, count};
            cv_ransac_report t =
                cv_lo_ransac<cv_translation_estimator>(team, candidates, s.translation, s.seed, pair.key, 3, lists.t, buffers);
            watermark = (double)t.support.inliers / total >= s.watermark_min_inlier_ratio;
        }
    }
    if (team.leader()) {
        result->config = watermark ? CLATCH_VERIFY_WATERMARK : (cv_u32)config;
        result->inlier_count = count;
        cv_u32 models = 0;
        if (f.success) {
            models |= CLATCH_VERIFY_HAS_F;
            for (int i = 0; i < 9; ++i) result->f[i] = f.model.m[i];
        }
        if (calibrated && e.success) {
            models |= CLATCH_VERIFY_HAS_E;
            for (int i = 0; i < 9; ++i) result->e[i] = e.model.m[i];
        }
        if (h.success) {
            models |= CLATCH_VERIFY_HAS_H;
            for (int i = 0; i < 9; ++i) result->h[i] = h.model.m[i];
        }
        result->models = models;
    }
    team.sync();
}

#endif /* CLATCH_VERIFY_MATH_CUH */

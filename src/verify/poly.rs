//! Real roots of a polynomial of degree at most 10 (the 7-point solver's cubic, the 5-point solver's
//! tenth-degree polynomial) without an eigen solver or a trigonometric formula: a Sturm sequence
//! isolates the roots by halving intervals, each root is then bracketed by a fixed number of
//! bisections and polished by a fixed number of Newton steps. Every step is `+ − × ÷` and
//! comparisons, so every backend finds the same roots.

/// Highest degree handled.
pub(crate) const MAX_DEGREE: usize = 10;

/// Bisections of an isolating interval (and deepest interval split): enough to shrink an interval of
/// width 2·10^20 below 10^-17.
const BISECTIONS: usize = 128;

/// Newton steps after the bisections (kept only when they stay inside the bracket).
const NEWTON_STEPS: usize = 2;

/// A polynomial, lowest coefficient first, with its degree.
#[derive(Clone, Copy)]
struct Poly {
    c: [f64; MAX_DEGREE + 1],
    degree: usize,
}

impl Poly {
    /// Horner, highest coefficient first.
    fn eval(&self, x: f64) -> f64 {
        let mut value = self.c[self.degree];
        for k in (0..self.degree).rev() {
            value = value * x + self.c[k];
        }
        value
    }

    /// [`Poly::eval`] at each of `x` (the same operations for each, side by side).
    fn eval_all<const N: usize>(&self, x: &[f64; N]) -> [f64; N] {
        let mut value = [self.c[self.degree]; N];
        for k in (0..self.degree).rev() {
            for j in 0..N {
                value[j] = value[j] * x[j] + self.c[k];
            }
        }
        value
    }

    /// The sign at +∞ (`at_plus`) or −∞: the leading coefficient's, flipped at −∞ for odd degree.
    fn sign_at_infinity(&self, at_plus: bool) -> f64 {
        let lead = self.c[self.degree];
        if at_plus || self.degree.is_multiple_of(2) {
            lead
        } else {
            -lead
        }
    }
}

/// The Sturm sequence `p, p', −rem(p, p'), …` of a polynomial.
struct Sturm {
    chain: [Poly; MAX_DEGREE + 1],
    len: usize,
}

impl Sturm {
    fn new(p: &Poly) -> Self {
        let mut chain = [Poly {
            c: [0.0; MAX_DEGREE + 1],
            degree: 0,
        }; MAX_DEGREE + 1];
        chain[0] = *p;
        let mut derivative = Poly {
            c: [0.0; MAX_DEGREE + 1],
            degree: p.degree - 1,
        };
        for k in 1..=p.degree {
            derivative.c[k - 1] = p.c[k] * k as f64;
        }
        chain[1] = derivative;
        let mut len = 2;
        while len < chain.len() && chain[len - 1].degree > 0 {
            match negated_remainder(&chain[len - 2], &chain[len - 1]) {
                Some(next) => {
                    chain[len] = next;
                    len += 1;
                }
                None => break,
            }
        }
        Self { chain, len }
    }

    /// Sign changes along the sequence at `x` (zeros skipped).
    fn variations(&self, x: f64) -> u32 {
        self.count(|p| p.eval(x))
    }

    fn variations_at_infinity(&self, at_plus: bool) -> u32 {
        self.count(|p| p.sign_at_infinity(at_plus))
    }

    fn count(&self, value: impl Fn(&Poly) -> f64) -> u32 {
        let mut changes = 0;
        let mut last = 0.0;
        for p in &self.chain[..self.len] {
            let v = value(p);
            if v != 0.0 {
                if (last < 0.0 && v > 0.0) || (last > 0.0 && v < 0.0) {
                    changes += 1;
                }
                last = v;
            }
        }
        changes
    }
}

/// `−(a mod b)`, scaled so that its leading coefficient has magnitude 1 (a positive factor, which
/// keeps every sign); `None` when the remainder is zero.
fn negated_remainder(a: &Poly, b: &Poly) -> Option<Poly> {
    let mut r = a.c;
    let lead = b.c[b.degree];
    for shift in (0..=a.degree - b.degree).rev() {
        let factor = r[shift + b.degree] / lead;
        for k in 0..=b.degree {
            r[shift + k] -= factor * b.c[k];
        }
        r[shift + b.degree] = 0.0;
    }
    let mut degree = b.degree - 1;
    while r[degree] == 0.0 {
        if degree == 0 {
            return None;
        }
        degree -= 1;
    }
    let scale = -1.0 / r[degree].abs();
    let mut c = [0.0; MAX_DEGREE + 1];
    for k in 0..=degree {
        c[k] = r[k] * scale;
    }
    Some(Poly { c, degree })
}

/// The real roots of `Σ coeffs[k] x^k` (lowest first, at most `MAX_DEGREE + 1` coefficients), in
/// ascending order, written to `roots`; returns how many. A multiple root is reported once.
/// Non-finite coefficients give no roots.
pub(crate) fn real_roots(coeffs: &[f64], roots: &mut [f64; MAX_DEGREE]) -> usize {
    if coeffs.len() > MAX_DEGREE + 1 || coeffs.iter().any(|c| !c.is_finite()) {
        return 0;
    }
    let Some(degree) = coeffs.iter().rposition(|&c| c != 0.0) else {
        return 0;
    };
    if degree == 0 {
        return 0;
    }
    // Monic, and Cauchy's bound: every root lies in (−bound, bound).
    let mut p = Poly {
        c: [0.0; MAX_DEGREE + 1],
        degree,
    };
    let lead = coeffs[degree];
    let mut largest = 0.0f64;
    for k in 0..degree {
        p.c[k] = coeffs[k] / lead;
        largest = largest.max(p.c[k].abs());
    }
    p.c[degree] = 1.0;
    let bound = 1.0 + largest;
    if !bound.is_finite() {
        return 0;
    }
    let sturm = Sturm::new(&p);

    let mut search = Search {
        p: &p,
        sturm: &sturm,
        roots,
        found: 0,
    };
    search.isolate(
        -bound,
        bound,
        sturm.variations_at_infinity(false),
        sturm.variations_at_infinity(true),
        0,
    );
    search.found
}

/// The isolation of the roots of `p`, written to `roots` as they are found.
struct Search<'s> {
    p: &'s Poly,
    sturm: &'s Sturm,
    roots: &'s mut [f64; MAX_DEGREE],
    found: usize,
}

impl Search<'_> {
    /// The roots in `(a, b]` (variations `va`, `vb` at its ends), ascending: an interval with one
    /// root (or at depth [`BISECTIONS`]) is refined, one with more is halved, its left half searched
    /// first (depth first: the roots come out ascending).
    fn isolate(&mut self, a: f64, b: f64, va: u32, vb: u32, depth: usize) {
        let count = va.saturating_sub(vb);
        if count == 0 {
            return;
        }
        if count == 1 || depth == BISECTIONS {
            if self.found < MAX_DEGREE {
                self.roots[self.found] = refine(self.p, self.sturm, a, b, va);
                self.found += 1;
            }
            return;
        }
        let mid = 0.5 * (a + b);
        let vm = self.sturm.variations(mid);
        self.isolate(a, mid, va, vm, depth + 1);
        self.isolate(mid, b, vm, vb, depth + 1);
    }
}

/// `BISECTIONS` halvings of `(a, b]`, keeping the left half where `left(midpoint)`. A step that
/// leaves the bracket as it was (its midpoint one of its ends) would repeat itself forever, the
/// bracket being a function of the bracket alone: the remaining steps change nothing and are
/// skipped (a backend may run them all, with the same result).
fn bisect(mut a: f64, mut b: f64, mut left: impl FnMut(f64) -> bool) -> (f64, f64) {
    for _ in 0..BISECTIONS {
        let mid = 0.5 * (a + b);
        if !step(&mut a, &mut b, mid, left(mid)) {
            break;
        }
    }
    (a, b)
}

/// One bisection step to the half `left` of `mid`; whether the bracket changed.
fn step(a: &mut f64, b: &mut f64, mid: f64, left: bool) -> bool {
    // Selected by masks, not branches (the side is as good as random): the same values.
    let (was_a, was_b, mid) = (a.to_bits(), b.to_bits(), mid.to_bits());
    let keep_a = 0u64.wrapping_sub(u64::from(left));
    let new_a = (was_a & keep_a) | (mid & !keep_a);
    let new_b = (mid & keep_a) | (was_b & !keep_a);
    (*a, *b) = (f64::from_bits(new_a), f64::from_bits(new_b));
    new_a != was_a || new_b != was_b
}

/// Levels of bisection whose midpoints are evaluated together by [`bisect_on_sign`].
const LOOKAHEAD: usize = 3;
/// The midpoints of those levels: a binary tree in heap order.
const NODES: usize = (1 << LOOKAHEAD) - 1;

/// [`bisect`] on the sign of `p` (`negative_at_a`: `p(a) < 0`): the left half when `p(mid)` is zero
/// or of the other sign than at `a`. The same steps, faster: the midpoints of the next
/// [`LOOKAHEAD`] levels, every one the value its step would compute (`0.5 · (a + b)` of the bracket
/// the path would have there), are evaluated together (independent evaluations, which the processor
/// overlaps), then the steps take them in order.
fn bisect_on_sign(p: &Poly, mut a: f64, mut b: f64, negative_at_a: bool) -> (f64, f64) {
    let goes_left = |value: f64| value == 0.0 || (value < 0.0) != negative_at_a;
    let mut steps = 0;
    loop {
        let (mut lo, mut hi, mut mid) = ([a; NODES], [b; NODES], [0.0; NODES]);
        mid[0] = 0.5 * (a + b);
        for node in 0..NODES / 2 {
            let (l, r) = (2 * node + 1, 2 * node + 2);
            (lo[l], hi[l]) = (lo[node], mid[node]);
            (lo[r], hi[r]) = (mid[node], hi[node]);
            mid[l] = 0.5 * (lo[l] + hi[l]);
            mid[r] = 0.5 * (lo[r] + hi[r]);
        }
        let values = p.eval_all(&mid);
        let mut node = 0;
        for _ in 0..LOOKAHEAD {
            if steps == BISECTIONS {
                return (a, b);
            }
            steps += 1;
            let left = goes_left(values[node]);
            if !step(&mut a, &mut b, mid[node], left) {
                return (a, b);
            }
            node = 2 * node + 2 - usize::from(left);
        }
    }
}

/// The one root in `(a, b]`: bisection on the sign of `p` where it changes over the interval, on the
/// Sturm count otherwise (a root of even multiplicity), then Newton steps that stay in the bracket.
fn refine(p: &Poly, sturm: &Sturm, a: f64, b: f64, va: u32) -> f64 {
    let (pa, pb) = (p.eval(a), p.eval(b));
    let sign_change = (pa < 0.0 && pb > 0.0) || (pa > 0.0 && pb < 0.0);
    let (a, b) = if sign_change {
        bisect_on_sign(p, a, b, pa < 0.0)
    } else {
        bisect(a, b, |mid| sturm.variations(mid) < va)
    };
    let mut x = 0.5 * (a + b);
    for _ in 0..NEWTON_STEPS {
        let mut value = p.c[p.degree];
        let mut slope = 0.0;
        for k in (0..p.degree).rev() {
            slope = slope * x + value;
            value = value * x + p.c[k];
        }
        if slope == 0.0 {
            break;
        }
        let next = x - value / slope;
        if next.is_finite() && next >= a && next <= b {
            x = next;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Coefficients (lowest first) of Π (x − r).
    fn from_roots(rs: &[f64]) -> Vec<f64> {
        let mut c = vec![1.0];
        for r in rs {
            let mut next = vec![0.0; c.len() + 1];
            for (k, v) in c.iter().enumerate() {
                next[k + 1] += v;
                next[k] -= r * v;
            }
            c = next;
        }
        c
    }

    fn roots_of(c: &[f64]) -> Vec<f64> {
        let mut roots = [0.0; MAX_DEGREE];
        let n = real_roots(c, &mut roots);
        roots[..n].to_vec()
    }

    #[test]
    fn cubic_with_three_real_roots() {
        let found = roots_of(&from_roots(&[-2.5, 0.125, 7.0]));
        assert_eq!(found.len(), 3, "{found:?}");
        for (f, t) in found.iter().zip([-2.5, 0.125, 7.0]) {
            assert!((f - t).abs() < 1e-13, "{found:?}");
        }
    }

    #[test]
    fn cubic_with_one_real_root() {
        // (x − 3)(x² + 1)
        let found = roots_of(&[-3.0, 1.0, -3.0, 1.0]);
        assert_eq!(found.len(), 1);
        assert!((found[0] - 3.0).abs() < 1e-14);
    }

    #[test]
    fn tenth_degree_with_six_real_roots() {
        let real = [-3.2, -1.1, -0.4, 0.05, 0.9, 2.7];
        let mut c = from_roots(&real);
        // Times (x² + 1)(x² + 0.5x + 4): four complex roots.
        for quadratic in [[1.0, 0.0, 1.0], [4.0, 0.5, 1.0]] {
            let mut next = vec![0.0; c.len() + 2];
            for (k, v) in c.iter().enumerate() {
                for (j, q) in quadratic.iter().enumerate() {
                    next[k + j] += v * q;
                }
            }
            c = next;
        }
        assert_eq!(c.len(), 11);
        let found = roots_of(&c);
        assert_eq!(found.len(), 6, "{found:?}");
        for (f, t) in found.iter().zip(real) {
            assert!((f - t).abs() < 1e-11, "{found:?}");
        }
    }

    #[test]
    fn a_double_root_may_be_lost_but_never_invents_roots_and_degenerate_input_gives_none() {
        // In floating point the Sturm chain of a double root does not end in zero: the simple root is
        // found, the double one may not be (a sample with a double root has measure zero).
        let found = roots_of(&from_roots(&[1.5, 1.5, -4.0]));
        assert!(!found.is_empty() && found.len() <= 2, "{found:?}");
        assert!((found[0] + 4.0).abs() < 1e-12, "{found:?}");
        assert!(
            found[1..].iter().all(|r| (r - 1.5).abs() < 1e-6),
            "{found:?}"
        );
        assert!(roots_of(&[0.0, 0.0]).is_empty());
        assert!(roots_of(&[5.0]).is_empty());
        assert!(roots_of(&[1.0, f64::NAN, 1.0]).is_empty());
        assert_eq!(roots_of(&[-6.0, 2.0, 0.0, 0.0]), vec![3.0]);
    }
}

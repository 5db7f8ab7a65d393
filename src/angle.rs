//! Quantised orientation: the only place an angle becomes numbers that decide bits.
//!
//! Every angle is reduced to one of [`ANGLE_BINS`] bins of 1/8 degree by exact IEEE operations
//! (`fmod`, a multiplication by 8, round-half-even), and the rotation used for sampling is read from a
//! table indexed by that bin. The table is computed once on the host with the pure-Rust `libm`
//! (the same on every platform) and uploaded to any device, so no backend evaluates a sine or cosine of
//! its own. Orientations measured by the detector are binned by integer cross products against the
//! table's half-bin directions, so `atan2` never decides a bin either.

use std::sync::OnceLock;

/// Number of orientation bins in a full turn (1/8 degree each).
pub const ANGLE_BINS: usize = 2880;
/// Bins per degree.
pub const BINS_PER_DEGREE: usize = 8;
/// Fractional bits of the rotation table's cosines and sines.
pub const ROTATION_FRAC_BITS: u32 = 16;
/// Fractional bits of the half-bin direction vectors used to bin a measured orientation.
const BOUNDARY_FRAC_BITS: u32 = 30;
/// Bins in a quarter turn: the length of [`quadrant_boundaries`].
pub(crate) const BINS_PER_QUADRANT: usize = ANGLE_BINS / 4;

/// The bin of an angle in degrees: `round_half_even(8 * (angle mod 360)) mod 2880`, where `mod` is the
/// exact IEEE remainder made non-negative. Callers pass finite angles (validated at the API).
pub fn angle_bin(angle_degrees: f32) -> usize {
    let mut reduced = (angle_degrees as f64) % 360.0;
    if reduced < 0.0 {
        reduced += 360.0;
    }
    let bin = (reduced * BINS_PER_DEGREE as f64).round_ties_even() as usize;
    bin % ANGLE_BINS
}

/// The angle in degrees a bin stands for (exact in `f32`).
pub fn bin_degrees(bin: usize) -> f32 {
    bin as f32 / BINS_PER_DEGREE as f32
}

/// `(cos, sin)` of each bin's angle, rounded to 16 fractional bits.
pub fn rotation_table() -> &'static [[i32; 2]; ANGLE_BINS] {
    static TABLE: OnceLock<Box<[[i32; 2]; ANGLE_BINS]>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let one = (1i64 << ROTATION_FRAC_BITS) as f64;
        let mut table = Box::new([[0i32; 2]; ANGLE_BINS]);
        // Fill one quadrant and derive the others exactly, so the table is symmetric bit for bit.
        for k in 0..BINS_PER_QUADRANT {
            let radians = k as f64 * std::f64::consts::PI / (ANGLE_BINS / 2) as f64;
            let c = (libm::cos(radians) * one).round_ties_even() as i32;
            let s = (libm::sin(radians) * one).round_ties_even() as i32;
            table[k] = [c, s];
            table[k + BINS_PER_QUADRANT] = [-s, c];
            table[k + 2 * BINS_PER_QUADRANT] = [-c, -s];
            table[k + 3 * BINS_PER_QUADRANT] = [s, -c];
        }
        table
    })
}

/// Directions at the upper edge of each first-quadrant bin, `(k + 1/2) / 8` degrees, as 2.30 fixed point.
/// The GPU detector bins with this same table, uploaded from the host.
pub(crate) fn quadrant_boundaries() -> &'static [[i64; 2]; BINS_PER_QUADRANT] {
    static TABLE: OnceLock<Box<[[i64; 2]; BINS_PER_QUADRANT]>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let one = (1i64 << BOUNDARY_FRAC_BITS) as f64;
        let mut table = Box::new([[0i64; 2]; BINS_PER_QUADRANT]);
        for (k, entry) in table.iter_mut().enumerate() {
            let radians = (k as f64 + 0.5) * std::f64::consts::PI / (ANGLE_BINS / 2) as f64;
            *entry = [
                (libm::cos(radians) * one).round_ties_even() as i64,
                (libm::sin(radians) * one).round_ties_even() as i64,
            ];
        }
        table
    })
}

/// The bin of the direction of the integer vector `(dx, dy)` (image axes: x right, y down), i.e. the
/// nearest bin to `atan2(dy, dx)`, decided with integer arithmetic only:
/// 1. rotate the vector by a multiple of 90 degrees (exactly) into `x > 0, y >= 0`;
/// 2. count the first-quadrant half-bin directions `b` strictly clockwise of it
///    (`b.x * dy - b.y * dx > 0`, a monotone test, so a binary search);
/// 3. bin = `(quadrant * 720 + count) mod 2880`. A direction exactly on a half-bin edge rounds down.
///
/// The zero vector has bin 0. Every `i64` vector is accepted: the rotation and the products are
/// computed in `i128`, so `-i64::MIN` cannot wrap (which made the rotation loop spin forever).
pub fn direction_bin(dx: i64, dy: i64) -> usize {
    if dx == 0 && dy == 0 {
        return 0;
    }
    let (mut x, mut y, mut quadrant) = (dx as i128, dy as i128, 0usize);
    while !(x > 0 && y >= 0) {
        // Rotate by -90 degrees: (x, y) -> (y, -x).
        (x, y) = (y, -x);
        quadrant += 1;
    }
    let bounds = quadrant_boundaries();
    let (mut lo, mut hi) = (0usize, BINS_PER_QUADRANT);
    while lo < hi {
        let mid = (lo + hi) / 2;
        let [bx, by] = bounds[mid];
        if (bx as i128) * y - (by as i128) * x > 0 {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    (quadrant * BINS_PER_QUADRANT + lo) % ANGLE_BINS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_of_degrees() {
        assert_eq!(angle_bin(0.0), 0);
        assert_eq!(angle_bin(90.0), 720);
        assert_eq!(angle_bin(-90.0), 2160);
        assert_eq!(angle_bin(360.0), 0);
        assert_eq!(angle_bin(720.125), 1);
        assert_eq!(angle_bin(359.99), 0, "rounds to 360, which wraps to 0");
        assert_eq!(angle_bin(0.0625), 0, "half a bin rounds to even");
        assert_eq!(angle_bin(0.1875), 2, "1.5 bins rounds to even");
        assert_eq!(angle_bin(-1.0), 2880 - 8);
        assert_eq!(bin_degrees(angle_bin(123.375)), 123.375);
    }

    #[test]
    fn table_is_exact_at_right_angles_and_symmetric() {
        let t = rotation_table();
        let one = 1 << ROTATION_FRAC_BITS;
        assert_eq!(t[0], [one, 0]);
        assert_eq!(t[720], [0, one]);
        assert_eq!(t[1440], [-one, 0]);
        assert_eq!(t[2160], [0, -one]);
        // 45 degrees: cos = sin = 0.70710678 * 65536 = 46340.95 -> 46341.
        assert_eq!(t[360], [46341, 46341]);
        for k in 0..ANGLE_BINS {
            let [c, s] = t[k];
            let [c2, s2] = t[(k + 720) % ANGLE_BINS];
            assert_eq!((c2, s2), (-s, c), "bin {k}");
            let norm = (c as f64).hypot(s as f64);
            assert!((norm - one as f64).abs() < 1.0, "bin {k} has norm {norm}");
        }
    }

    #[test]
    fn direction_bins_agree_with_atan2_away_from_edges() {
        assert_eq!(direction_bin(0, 0), 0);
        assert_eq!(direction_bin(5, 0), 0);
        assert_eq!(direction_bin(0, 5), 720);
        assert_eq!(direction_bin(-5, 0), 1440);
        assert_eq!(direction_bin(0, -5), 2160);
        assert_eq!(direction_bin(7, 7), 360);
        assert_eq!(direction_bin(-7, 7), 1080);
        let mut checked = 0;
        for dx in (-300i64..=300).step_by(7) {
            for dy in (-300i64..=300).step_by(11) {
                if dx == 0 && dy == 0 {
                    continue;
                }
                let exact = (dy as f64).atan2(dx as f64).to_degrees().rem_euclid(360.0) * 8.0;
                if (exact - exact.floor() - 0.5).abs() < 1e-6 {
                    continue; // on a half-bin edge: rounding direction is the contract, tested below
                }
                let expected = exact.round() as usize % ANGLE_BINS;
                assert_eq!(direction_bin(dx, dy), expected, "({dx}, {dy})");
                checked += 1;
            }
        }
        assert!(checked > 3000);
    }

    #[test]
    fn direction_bins_of_the_extreme_vectors_terminate() {
        assert_eq!(direction_bin(i64::MIN, 0), 1440);
        assert_eq!(direction_bin(0, i64::MIN), 2160);
        assert_eq!(direction_bin(i64::MAX, i64::MAX), 360);
        assert_eq!(direction_bin(i64::MIN, i64::MIN), 1800);
        assert_eq!(direction_bin(i64::MAX, 0), 0);
    }

    #[test]
    fn direction_bins_cover_large_moments() {
        let big = (1i64 << 31) - 1;
        assert_eq!(direction_bin(big, 0), 0);
        assert_eq!(direction_bin(-big, -big), 1800);
    }
}

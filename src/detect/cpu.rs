//! The reference detector (see the parent module for the numeric contract).

use crate::parallel::*;

use super::rows::{LANES, RowKernel};
use super::{DetectorConfig, FAST_ARC, FAST_CIRCLE, ORIENTATION_RADIUS, SUBPIXEL_FRAC_BITS};
use crate::angle::{bin_degrees, direction_bin};
use crate::gray_view::GrayView;
use crate::keypoint::KeyPoint;

/// FAST-9 score of the pixel at `(x, y)`, which must be at least 3 pixels from every border.
pub fn fast_score(img: &GrayView, x: usize, y: usize) -> i32 {
    let p = img.at(x, y) as i32;
    let mut ring = [0i32; 16];
    for (value, [dx, dy]) in ring.iter_mut().zip(FAST_CIRCLE) {
        *value = img.at((x as i32 + dx) as usize, (y as i32 + dy) as usize) as i32 - p;
    }
    let mut best = i32::MIN;
    for k in 0..16 {
        let (mut brighter, mut darker) = (i32::MAX, i32::MAX);
        for j in 0..FAST_ARC {
            let d = ring[(k + j) % 16];
            brighter = brighter.min(d);
            darker = darker.min(-d);
        }
        best = best.max(brighter).max(darker);
    }
    best
}

/// The peak of the parabola through `(-1, l)`, `(0, c)`, `(1, r)` in 1/65536 pixel:
/// `(l - r) / (2 (l - 2c + r)) · 2^16` rounded to the nearest integer (half away from zero), by integer
/// division only; 0 unless `c` is a strict peak (`c > l` and `c > r`: ties and slopes give 0).
///
/// With `a = c - l > 0` and `b = c - r > 0` the offset is `(a - b) · 2^15 / (a + b)`, so
/// `|offset| < 2^15` (less than half a pixel), positive towards `r`. Scores are FAST scores
/// (`|s| ≤ 255`), so `a + b < 2^10` and the quotient is never exactly half an integer: the rounding
/// direction of halves never decides a bit.
pub fn parabola_offset(l: i32, c: i32, r: i32) -> i32 {
    if c <= l || c <= r {
        return 0;
    }
    let (a, b) = (c - l, c - r);
    let numerator = (a - b) << (SUBPIXEL_FRAC_BITS - 1);
    let denominator = a + b;
    numerator.signum() * ((2 * numerator.abs() + denominator) / (2 * denominator))
}

/// The sub-pixel offset `[dx, dy]` (1/65536 pixel) of the keypoint at `(x, y)` under
/// [`super::Subpixel::Score`]: [`parabola_offset`] of the FAST scores ([`fast_score`], whatever their
/// value, threshold or margin) of the left neighbour, the pixel and the right neighbour, and likewise
/// of the one above, the pixel and the one below. `[0, 0]` when a neighbour's circle would leave the
/// image (`(x, y)` closer than 4 pixels to a border; detected keypoints never are).
pub fn subpixel_offset(img: &GrayView, x: usize, y: usize) -> [i32; 2] {
    let inside = x >= 4 && y >= 4 && x + 4 < img.width() && y + 4 < img.height();
    if !inside {
        return [0, 0];
    }
    // `fast_score_in_rows`: the same integers as `fast_score`, by sliding minima.
    let score = |x, y| fast_score_in_rows(img, x, y);
    let c = score(x, y);
    [
        parabola_offset(score(x - 1, y), c, score(x + 1, y)),
        parabola_offset(score(x, y - 1), c, score(x, y + 1)),
    ]
}

/// [`fast_score`] from the circle differences `ring` (circle pixel minus centre), by sliding minima
/// and maxima instead of nine comparisons per arc: `min9[k] = min(min8[k], ring[k + 8])` with
/// `min8 = min(min4[k], min4[k + 4])` and so on (indices modulo 16). Integer comparisons only: the
/// same value as the plain loop, which a test checks on random rings.
#[inline]
fn arc_score(ring: &[i32; 16]) -> i32 {
    let at = |a: &[i32; 16], k: usize| a[k & 15];
    let lo2: [i32; 16] = std::array::from_fn(|k| ring[k].min(at(ring, k + 1)));
    let hi2: [i32; 16] = std::array::from_fn(|k| ring[k].max(at(ring, k + 1)));
    let lo4: [i32; 16] = std::array::from_fn(|k| lo2[k].min(at(&lo2, k + 2)));
    let hi4: [i32; 16] = std::array::from_fn(|k| hi2[k].max(at(&hi2, k + 2)));
    let mut brighter = i32::MIN;
    let mut darker = i32::MIN;
    for k in 0..16 {
        let lo9 = lo4[k].min(at(&lo4, k + 4)).min(at(ring, k + 8));
        let hi9 = hi4[k].max(at(&hi4, k + 4)).max(at(ring, k + 8));
        brighter = brighter.max(lo9);
        darker = darker.max(-hi9);
    }
    brighter.max(darker)
}

/// [`fast_score`] of a pixel known to be inside the circle margin, reading rows directly.
#[inline]
fn fast_score_in_rows(img: &GrayView, x: usize, y: usize) -> i32 {
    let p = img.at(x, y) as i32;
    let ring: [i32; 16] = std::array::from_fn(|i| {
        let [dx, dy] = FAST_CIRCLE[i];
        img.row((y as i32 + dy) as usize)[(x as i32 + dx) as usize] as i32 - p
    });
    arc_score(&ring)
}

/// Cheap necessary condition, for `xs` of row `y` at once (`out[i]` for `x = xs.start + i`): nine
/// contiguous circle pixels always include two adjacent compass pixels (0, 4, 8, 12) beyond the
/// threshold on the same side. Saturating `u8` differences, so the loop vectorises.
fn may_be_corners(img: &GrayView, y: usize, xs: std::ops::Range<usize>, threshold: u8, out: &mut [bool]) {
    let (lo, hi) = (xs.start, xs.end);
    let centre = &img.row(y)[lo..hi];
    let north = &img.row(y - 3)[lo..hi];
    let south = &img.row(y + 3)[lo..hi];
    let east = &img.row(y)[lo + 3..hi + 3];
    let west = &img.row(y)[lo - 3..hi - 3];
    for i in 0..hi - lo {
        let p = centre[i];
        let b = |v: u8| v.saturating_sub(p) > threshold;
        let d = |v: u8| p.saturating_sub(v) > threshold;
        let (bn, be, bs, bw) = (b(north[i]), b(east[i]), b(south[i]), b(west[i]));
        let (dn, de, ds, dw) = (d(north[i]), d(east[i]), d(south[i]), d(west[i]));
        out[i] = (bn & be) | (be & bs) | (bs & bw) | (bw & bn) | (dn & de) | (de & ds) | (ds & dw) | (dw & dn);
    }
}

/// Score map: FAST score of each pixel inside the margin (at least 3) that is a corner, 0 elsewhere.
/// Row-major, `width * height`. Rows of at least [`LANES`] scored pixels go through the vectorised
/// row kernel (`detect/rows.rs`, the same integers); narrower ones through the quick test and
/// [`arc_score`] pixel by pixel.
pub fn score_map(img: &GrayView, threshold: u8, margin: usize) -> Vec<u8> {
    let (w, h) = (img.width(), img.height());
    let t = threshold as i32;
    let mut scores = vec![0u8; w * h];
    // The circle reaches 3 pixels out: pixels nearer a border are never corners.
    let margin = margin.max(3);
    if w <= 2 * margin || h <= 2 * margin {
        return scores;
    }
    let kernel = RowKernel::detect();
    scores
        .par_chunks_mut(w)
        .enumerate()
        .skip(margin)
        .take(h - 2 * margin)
        .for_each_init(Vec::new, |candidates, (y, row)| {
            if w - 2 * margin >= LANES {
                return kernel.score_row(img, y, margin..w - margin, threshold, &mut row[margin..w - margin]);
            }
            candidates.resize(w - 2 * margin, false);
            may_be_corners(img, y, margin..w - margin, threshold, candidates);
            for (i, _) in candidates.iter().enumerate().filter(|&(_, &c)| c) {
                let x = margin + i;
                let s = fast_score_in_rows(img, x, y);
                if s > t {
                    row[x] = s as u8;
                }
            }
        });
    scores
}

/// Corners that survive 3x3 non-maximum suppression (ties go to the first in raster order), as
/// `(x, y, score)` in raster order. Rows are tested [`LANES`] pixels at a time (`detect/rows.rs`),
/// the few pixels left at a row's end one by one.
pub fn suppress_non_maxima(scores: &[u8], width: usize, height: usize) -> Vec<(u32, u32, u8)> {
    let kernel = RowKernel::detect();
    (1..height.saturating_sub(1))
        .into_par_iter()
        .flat_map_iter(|y| {
            let above = &scores[(y - 1) * width..y * width];
            let here = &scores[y * width..(y + 1) * width];
            let below = &scores[(y + 1) * width..(y + 2) * width];
            let mut kept = Vec::new();
            let mut keep = |x: usize| kept.push((x as u32, y as u32, here[x]));
            let tail = kernel.suppress_row([above, here, below], &mut keep);
            for x in tail {
                let s = here[x];
                let earlier = [above[x - 1], above[x], above[x + 1], here[x - 1]];
                let later = [here[x + 1], below[x - 1], below[x], below[x + 1]];
                if s > 0 && earlier.iter().all(|&n| s > n) && later.iter().all(|&n| s >= n) {
                    keep(x);
                }
            }
            kept
        })
        .collect()
}

/// Harris corner response of the pixel at `(x, y)`, scaled by 25 so that it is an exact integer:
/// with the 3x3 Sobel gradients `(gx, gy)` of every pixel of the 7x7 block around `(x, y)` and
/// `A = Σ gx²`, `B = Σ gy²`, `C = Σ gx·gy`, the response is `25 (A B - C²) - (A + B)²`, i.e.
/// `25 · (det - 0.04 · trace²)`, Harris's `k = 0.04` as ORB ranks its corners. `|g| ≤ 1020`, so the
/// sums stay below 2^26 and the result fits `i64` exactly. `(x, y)` must be at least 4 pixels from
/// every border (detected keypoints are, by the margin).
pub fn harris_response(img: &GrayView, x: usize, y: usize) -> i64 {
    const HALF: i32 = 3;
    let p = |dx: i32, dy: i32| img.at((x as i32 + dx) as usize, (y as i32 + dy) as usize) as i64;
    let (mut a, mut b, mut c) = (0i64, 0i64, 0i64);
    for v in -HALF..=HALF {
        for u in -HALF..=HALF {
            let gx = (p(u + 1, v - 1) + 2 * p(u + 1, v) + p(u + 1, v + 1))
                - (p(u - 1, v - 1) + 2 * p(u - 1, v) + p(u - 1, v + 1));
            let gy = (p(u - 1, v + 1) + 2 * p(u, v + 1) + p(u + 1, v + 1))
                - (p(u - 1, v - 1) + 2 * p(u, v - 1) + p(u + 1, v - 1));
            a += gx * gx;
            b += gy * gy;
            c += gx * gy;
        }
    }
    25 * (a * b - c * c) - (a + b) * (a + b)
}

/// The orientation disc's radius as an index.
const DISC_RADIUS: usize = ORIENTATION_RADIUS as usize;

/// Lanes of one disc row: its `2 r + 1 = 31` pixels and a lane of weight 0.
const DISC_LANES: usize = 32;
const _: () = assert!(2 * DISC_RADIUS < DISC_LANES);

/// The rows of the orientation disc: `DISC_ROWS[|dy|][dx + r]` is 1 where `dx² + dy² <= r²`, else 0
/// (0 in the last lane).
static DISC_ROWS: [[i16; DISC_LANES]; DISC_RADIUS + 1] = disc_rows();

const fn disc_rows() -> [[i16; DISC_LANES]; DISC_RADIUS + 1] {
    let r = DISC_RADIUS as i32;
    let mut rows = [[0; DISC_LANES]; DISC_RADIUS + 1];
    let mut dy = 0;
    while dy <= r {
        let mut dx = -r;
        while dx <= r {
            rows[dy as usize][(dx + r) as usize] = (dx * dx + dy * dy <= r * r) as i16;
            dx += 1;
        }
        dy += 1;
    }
    rows
}

/// `dx` of each lane of a disc row.
static DISC_DX: [i16; DISC_LANES] = {
    let mut dx = [0; DISC_LANES];
    let mut i = 0;
    while i < DISC_LANES {
        dx[i] = i as i16 - DISC_RADIUS as i16;
        i += 1;
    }
    dx
};

/// The `2 r + 1` pixels of row `y` around `x`, and a 0.
#[inline(always)]
fn disc_span(img: &GrayView, x: usize, y: usize) -> [u8; DISC_LANES] {
    let mut span = [0u8; DISC_LANES];
    span[..2 * DISC_RADIUS + 1].copy_from_slice(&img.row(y)[x - DISC_RADIUS..=x + DISC_RADIUS]);
    span
}

/// Intensity-centroid moments `(m10, m01)` over the orientation disc around `(x, y)`.
///
/// Rows `y - dy` and `y + dy` are taken together over the whole width of the disc, each pixel times
/// its 0/1 disc weight, in 32 lanes of 16-bit values (`dx (a + b)` and `dy (b - a)` are at most
/// `15 · 510` in magnitude) summed per lane in 32 bits and added up at the end: the same integer sums
/// as pixel by pixel, in another order, in code the compiler vectorises.
pub fn centroid_moments(img: &GrayView, x: usize, y: usize) -> (i64, i64) {
    let span = |row: usize| disc_span(img, x, row);
    let (mut m10, mut m01) = ([0i32; DISC_LANES], [0i32; DISC_LANES]);
    let centre = span(y);
    for i in 0..DISC_LANES {
        m10[i] += (DISC_DX[i] * centre[i] as i16 * DISC_ROWS[0][i]) as i32;
    }
    for (dy, weights) in DISC_ROWS.iter().enumerate().skip(1) {
        let (above, below) = (span(y - dy), span(y + dy));
        let dx = &DISC_DX;
        for i in 0..DISC_LANES {
            let (a, b) = (above[i] as i16 * weights[i], below[i] as i16 * weights[i]);
            m10[i] += (dx[i] * (a + b)) as i32;
            m01[i] += (dy as i16 * (b - a)) as i32;
        }
    }
    let total = |lanes: [i32; DISC_LANES]| lanes.iter().map(|&v| v as i64).sum::<i64>();
    (total(m10), total(m01))
}

/// The angle of the keypoint at `(x, y)`: the intensity centroid's direction bin, in degrees.
pub fn orientation(img: &GrayView, x: usize, y: usize) -> f32 {
    let (m10, m01) = centroid_moments(img, x, y);
    bin_degrees(direction_bin(m10, m01))
}

/// The detector without orientation (every `angle` 0): the strongest `max_keypoints` corners after
/// suppression, score descending, then raster order. For callers that keep only some of them (the
/// pyramid's selection) and orient those with [`orientation`].
pub fn detect_unoriented(img: &GrayView, config: &DetectorConfig) -> Vec<KeyPoint> {
    let margin = config.margin();
    let scores = score_map(img, config.threshold, margin);
    let mut corners = suppress_non_maxima(&scores, img.width(), img.height());
    // Score descending, then raster order: a total order (positions are unique), so keeping the
    // first `max_keypoints` by a partition and sorting only those gives the full sort's prefix.
    let order = |a: &(u32, u32, u8), b: &(u32, u32, u8)| b.2.cmp(&a.2).then(a.1.cmp(&b.1)).then(a.0.cmp(&b.0));
    if corners.len() > config.max_keypoints {
        corners.select_nth_unstable_by(config.max_keypoints, order);
        corners.truncate(config.max_keypoints);
    }
    corners.sort_unstable_by(order);
    corners
        .iter()
        .map(|&(x, y, score)| KeyPoint {
            x: x as f32,
            y: y as f32,
            size: config.keypoint_size,
            angle: 0.0,
            response: score as f32,
            octave: 0,
        })
        .collect()
}

/// Runs the whole detector on the CPU. The image must be larger than twice the margin in both
/// directions (checked by the caller).
pub fn detect(img: &GrayView, config: &DetectorConfig) -> Vec<KeyPoint> {
    let mut keypoints = detect_unoriented(img, config);
    keypoints.par_iter_mut().for_each(|k| {
        k.angle = orientation(img, k.x as usize, k.y as usize);
    });
    keypoints
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator for the equivalence tests.
    fn lcg(state: &mut u64) -> u64 {
        *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        *state >> 33
    }

    #[test]
    fn arc_score_equals_the_plain_arc_loop() {
        let plain = |ring: &[i32; 16]| {
            let mut best = i32::MIN;
            for k in 0..16 {
                let (mut brighter, mut darker) = (i32::MAX, i32::MAX);
                for j in 0..FAST_ARC {
                    brighter = brighter.min(ring[(k + j) % 16]);
                    darker = darker.min(-ring[(k + j) % 16]);
                }
                best = best.max(brighter).max(darker);
            }
            best
        };
        let mut state = 7;
        for trial in 0..200_000 {
            // Narrow value ranges make ties and equal arcs common; wide ones reach +-255.
            let spread = [3u64, 20, 511][trial % 3];
            let ring: [i32; 16] =
                std::array::from_fn(|_| (lcg(&mut state) % spread) as i32 - (spread / 2) as i32);
            assert_eq!(arc_score(&ring), plain(&ring), "{ring:?}");
        }
    }

    #[test]
    fn centroid_moments_equal_the_plain_disc_sums() {
        let (w, h) = (61, 47);
        let mut state = 5;
        for levels in [2u64, 256] {
            let pixels: Vec<u8> = (0..w * h).map(|_| (lcg(&mut state) % levels * 255 / (levels - 1)) as u8).collect();
            let img = GrayView::new(&pixels, w, h, w).unwrap();
            let r = ORIENTATION_RADIUS;
            for y in r as usize..h - r as usize {
                for x in r as usize..w - r as usize {
                    let (mut m10, mut m01) = (0i64, 0i64);
                    for dy in -r..=r {
                        for dx in -r..=r {
                            if dx * dx + dy * dy <= r * r {
                                let v = img.at((x as i32 + dx) as usize, (y as i32 + dy) as usize) as i64;
                                m10 += dx as i64 * v;
                                m01 += dy as i64 * v;
                            }
                        }
                    }
                    assert_eq!(centroid_moments(&img, x, y), (m10, m01), "({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn suppression_equals_the_plain_rule_on_random_maps() {
        let mut state = 3;
        for (w, h) in [(1, 1), (2, 5), (3, 3), (31, 4), (33, 7), (64, 9), (100, 13)] {
            // Sparse maps with runs of equal scores, as score maps are.
            let scores: Vec<u8> = (0..w * h)
                .map(|_| match lcg(&mut state) % 8 {
                    0 => 5,
                    1 => (lcg(&mut state) % 4) as u8 + 4,
                    _ => 0,
                })
                .collect();
            let at = |x: usize, y: usize| scores[y * w + x];
            let mut want = Vec::new();
            for y in 1..h.saturating_sub(1) {
                for x in 1..w.saturating_sub(1) {
                    let s = at(x, y);
                    let earlier = [at(x - 1, y - 1), at(x, y - 1), at(x + 1, y - 1), at(x - 1, y)];
                    let later = [at(x + 1, y), at(x - 1, y + 1), at(x, y + 1), at(x + 1, y + 1)];
                    if s > 0 && earlier.iter().all(|&n| s > n) && later.iter().all(|&n| s >= n) {
                        want.push((x as u32, y as u32, s));
                    }
                }
            }
            assert_eq!(suppress_non_maxima(&scores, w, h), want, "{w}x{h}");
        }
    }

    #[test]
    fn score_map_equals_fast_score_at_every_pixel() {
        let mut state = 11;
        for (w, h, levels, threshold, margin) in
            [(40, 30, 4u64, 1u8, 3usize), (57, 23, 256, 20, 5), (64, 64, 30, 7, 16), (9, 9, 256, 1, 3)]
        {
            let pixels: Vec<u8> = (0..w * h).map(|_| (lcg(&mut state) % levels) as u8 * (255 / (levels - 1).max(1)) as u8).collect();
            let img = GrayView::new(&pixels, w, h, w).unwrap();
            let map = score_map(&img, threshold, margin);
            for y in 0..h {
                for x in 0..w {
                    let inside = x >= margin && y >= margin && x + margin < w && y + margin < h;
                    let s = if inside { fast_score(&img, x, y) } else { 0 };
                    let want = if s > threshold as i32 { s as u8 } else { 0 };
                    assert_eq!(map[y * w + x], want, "({x}, {y}) of {w}x{h}, threshold {threshold}");
                }
            }
        }
    }

    #[test]
    fn harris_response_worked_by_hand() {
        // A vertical step: columns >= 10 are 100. At (10, 10) the 7x7 block covers columns 7..=13;
        // Sobel gx is 4 · 100 = 400 on columns 9 and 10 (their right neighbour is bright, their left
        // one dark) and 0 elsewhere, gy is 0: A = 14 · 400², B = C = 0, response = -(A + B)².
        let pixels: Vec<u8> = (0..400).map(|i| if i % 20 >= 10 { 100 } else { 0 }).collect();
        let img = GrayView::new(&pixels, 20, 20, 20).unwrap();
        let a = 14 * 400 * 400;
        assert_eq!(harris_response(&img, 10, 10), -(a * a));
        // Far from the step: flat, 0.
        assert_eq!(harris_response(&img, 4, 10), 0);
        // A corner (the bright quadrant x, y >= 10) is positive, and transposing the image keeps it.
        let corner: Vec<u8> = (0..400)
            .map(|i| if i % 20 >= 10 && i / 20 >= 10 { 100 } else { 0 })
            .collect();
        let img = GrayView::new(&corner, 20, 20, 20).unwrap();
        let r = harris_response(&img, 10, 10);
        assert!(r > 0);
        let transposed: Vec<u8> = (0..400).map(|i| corner[(i % 20) * 20 + i / 20]).collect();
        let t = GrayView::new(&transposed, 20, 20, 20).unwrap();
        assert_eq!(harris_response(&t, 10, 10), r);
    }

    #[test]
    fn parabola_offsets_worked_by_hand() {
        // f(-1) = 0, f(0) = 10, f(1) = 5: f = -7.5 x² + 2.5 x + 10, peak at 2.5 / 15 = 1/6 px towards
        // the right: 65536 / 6 = 10922.67 -> 10923. Mirrored: -10923.
        assert_eq!(parabola_offset(0, 10, 5), 10_923);
        assert_eq!(parabola_offset(5, 10, 0), -10_923);
        // Negative scores (FAST scores below the threshold can be): -3, -1, -2 is 0, 2, 1 shifted,
        // the same parabola as 0, 10, 5 up to scale: 1/6 px towards the higher neighbour, r.
        assert_eq!(parabola_offset(-3, -1, -2), 10_923);
        // Symmetric: 0. Ties and slopes are no strict peak: 0.
        assert_eq!(parabola_offset(5, 10, 5), 0);
        for (l, c, r) in [(10, 10, 5), (5, 10, 10), (12, 10, 5), (5, 10, 12), (7, 7, 7), (1, 2, 3)] {
            assert_eq!(parabola_offset(l, c, r), 0, "{l} {c} {r}");
        }
        // The largest offsets stay below half a pixel: a = 510, b = 1: 509 · 32768 / 511 = 32639.7.
        assert_eq!(parabola_offset(-255, 255, 254), 32_640);
        assert_eq!(parabola_offset(254, 255, -255), -32_640);
    }

    #[test]
    fn parabola_offsets_are_the_rounded_real_peak() {
        // Against the real-valued peak (l - r) / (2 (l - 2c + r)) in f64 (exact to far below 1/65536
        // here): never more than half a unit away, never half a pixel or more.
        for c in (-255..=255).step_by(17) {
            for l in (-255..=255).step_by(7) {
                for r in (-255..=255).step_by(11) {
                    let got = parabola_offset(l, c, r);
                    if c <= l || c <= r {
                        assert_eq!(got, 0);
                        continue;
                    }
                    let (l, c, r) = (l as f64, c as f64, r as f64);
                    let exact = (l - r) / (2.0 * (l - 2.0 * c + r)) * 65536.0;
                    assert!((got as f64 - exact).abs() < 0.5, "{l} {c} {r}: {got} vs {exact}");
                    assert!(got.abs() < 32_768);
                }
            }
        }
    }

    #[test]
    fn subpixel_offset_of_a_two_pixel_blob_worked_by_hand() {
        // 100 at (8, 8), 60 at (9, 8), 0 elsewhere. Neither blob pixel lies on the other's circle
        // (offsets (±1, 0) are not on it), so: c = score(8, 8) = 100 (every circle pixel 100 darker),
        // r = score(9, 8) = 60, l = score(7, 8) = 0 (centre and circle all 0), and above and below
        // are 0 too. Horizontal peak: (0 - 60) / (2 (0 - 200 + 60)) = 3/14 px = 14043.4 -> 14043.
        let blob = |x0: usize, w: usize| {
            image(w, 17, |x, y| match (x, y) {
                (x, 8) if x == x0 => 100,
                (x, 8) if x == x0 + 1 => 60,
                _ => 0,
            })
        };
        let buf = blob(8, 17);
        let img = GrayView::new(&buf, 17, 17, 17).unwrap();
        assert_eq!(fast_score(&img, 8, 8), 100);
        assert_eq!(subpixel_offset(&img, 8, 8), [14_043, 0]);
        // Transposed: the offset moves to y.
        let t: Vec<u8> = (0..17 * 17).map(|i| buf[(i % 17) * 17 + i / 17]).collect();
        let img = GrayView::new(&t, 17, 17, 17).unwrap();
        assert_eq!(subpixel_offset(&img, 8, 8), [0, 14_043]);
        // A lone dot is symmetric: no offset.
        let dot = image(17, 17, |x, y| if (x, y) == (8, 8) { 100 } else { 0 });
        let img = GrayView::new(&dot, 17, 17, 17).unwrap();
        assert_eq!(subpixel_offset(&img, 8, 8), [0, 0]);
    }

    #[test]
    fn subpixel_offset_at_the_borders() {
        // The same blob as close to the left border as the neighbours' circles allow (x = 4: the left
        // neighbour's circle reaches column 0), and one pixel closer, where it is left whole.
        for (x0, expected) in [(4usize, [14_043, 0]), (3, [0, 0])] {
            let buf = image(17, 17, |x, y| match (x, y) {
                (x, 8) if x == x0 => 100,
                (x, 8) if x == x0 + 1 => 60,
                _ => 0,
            });
            let img = GrayView::new(&buf, 17, 17, 17).unwrap();
            assert_eq!(subpixel_offset(&img, x0, 8), expected, "x = {x0}");
        }
        // Right border: x + 4 must stay inside (x = 12 of 17 columns), even where the keypoint's own
        // circle would fit (x = 13).
        for (x0, expected) in [(11usize, [14_043, 0]), (12, [-14_043, 0]), (13, [0, 0])] {
            // The 60 goes to the left of the 100 when there is no room on the right.
            let buf = image(17, 17, |x, y| match (x, y) {
                (x, 8) if x == x0 => 100,
                (x, 8) if x0 < 12 && x == x0 + 1 => 60,
                (x, 8) if x0 >= 12 && x + 1 == x0 => 60,
                _ => 0,
            });
            let img = GrayView::new(&buf, 17, 17, 17).unwrap();
            assert_eq!(subpixel_offset(&img, x0, 8), expected, "x = {x0}");
        }
        // Top and bottom likewise.
        let buf = vec![9u8; 17 * 17];
        let img = GrayView::new(&buf, 17, 17, 17).unwrap();
        for (x, y) in [(8, 3), (8, 13), (0, 0), (16, 16)] {
            assert_eq!(subpixel_offset(&img, x, y), [0, 0]);
        }
    }

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> u8) -> Vec<u8> {
        (0..w * h).map(|i| f(i % w, i / w)).collect()
    }

    #[test]
    fn score_of_a_bright_dot_is_its_contrast() {
        // A single pixel of 100 on 0: every circle pixel is 100 darker, so score = 100.
        let buf = image(9, 9, |x, y| if (x, y) == (4, 4) { 100 } else { 0 });
        let img = GrayView::new(&buf, 9, 9, 9).unwrap();
        assert_eq!(fast_score(&img, 4, 4), 100);
    }

    #[test]
    fn score_of_a_flat_patch_is_zero() {
        let buf = vec![77u8; 81];
        let img = GrayView::new(&buf, 9, 9, 9).unwrap();
        assert_eq!(fast_score(&img, 4, 4), 0);
    }

    #[test]
    fn exactly_nine_contiguous_is_a_corner_eight_is_not() {
        // Centre 50; circle pixels k..k+n brighter (200), the rest equal to the centre.
        for (run, expected) in [(9usize, 150), (8, 0)] {
            for start in 0..16 {
                let mut buf = vec![50u8; 81];
                for j in 0..run {
                    let [dx, dy] = FAST_CIRCLE[(start + j) % 16];
                    buf[((4 + dy) * 9 + 4 + dx) as usize] = 200;
                }
                let img = GrayView::new(&buf, 9, 9, 9).unwrap();
                assert_eq!(fast_score(&img, 4, 4), expected, "run {run} from {start}");
                if run == 9 {
                    let mut candidate = [false];
                    may_be_corners(&img, 4, 4..5, 20, &mut candidate);
                    assert!(candidate[0], "the quick test must never reject a corner");
                }
            }
        }
    }

    #[test]
    fn the_weakest_arc_pixel_sets_the_score() {
        // Nine darker pixels at 10, 30, ... on a 200 centre: score = 200 - max(arc) = 200 - 90 = 110.
        let mut buf = vec![200u8; 81];
        for j in 0..9 {
            let [dx, dy] = FAST_CIRCLE[(5 + j) % 16];
            buf[((4 + dy) * 9 + 4 + dx) as usize] = 10 + 10 * j as u8;
        }
        let img = GrayView::new(&buf, 9, 9, 9).unwrap();
        assert_eq!(fast_score(&img, 4, 4), 110);
    }

    #[test]
    fn finds_the_corner_of_a_bright_square_and_orients_it() {
        // A 40x40 bright square in a 160x160 dark image; FAST must fire at its four corners only, and the
        // intensity centroid of the top-left corner points into the square: down-right, 45 degrees.
        let buf = image(160, 160, |x, y| {
            if (60..100).contains(&x) && (60..100).contains(&y) {
                200
            } else {
                20
            }
        });
        let img = GrayView::new(&buf, 160, 160, 160).unwrap();
        let config = DetectorConfig {
            keypoint_size: 64.0,
            ..DetectorConfig::default()
        };
        assert_eq!(config.margin(), 48);
        let kps = detect(&img, &config);
        let positions: Vec<(f32, f32)> = kps.iter().map(|k| (k.x, k.y)).collect();
        assert_eq!(kps.len(), 4, "{positions:?}");
        let top_left = kps
            .iter()
            .find(|k| k.x < 80.0 && k.y < 80.0)
            .expect("top-left corner");
        assert!(
            (60.0..=61.0).contains(&top_left.x) && (60.0..=61.0).contains(&top_left.y),
            "{positions:?}"
        );
        assert_eq!(top_left.angle, 45.0);
        let bottom_right = kps.iter().find(|k| k.x > 80.0 && k.y > 80.0).unwrap();
        assert_eq!(
            (bottom_right.x, bottom_right.y),
            (99.0, 97.0),
            "(99, 97) already has nine contiguous darker circle pixels, and comes first"
        );
        assert!(
            (215.0..=235.0).contains(&bottom_right.angle),
            "{}",
            bottom_right.angle
        );
        assert!(kps.iter().all(|k| k.response > 20.0 && k.size == 64.0));
    }

    #[test]
    fn suppression_keeps_one_of_equal_neighbours_and_the_stronger_of_two() {
        let (w, h) = (6, 5);
        let mut scores = vec![0u8; w * h];
        scores[2 * w + 2] = 30;
        scores[2 * w + 3] = 30; // equal right neighbour: the first in raster order wins
        scores[w + 4] = 31; // but a stronger diagonal neighbour of (3, 2) is at (4, 1)
        let kept = suppress_non_maxima(&scores, w, h);
        assert_eq!(kept, vec![(4, 1, 31), (2, 2, 30)]);
    }

    #[test]
    fn top_n_is_by_score_then_raster_order() {
        let buf = crate::synthetic::rectangles(200, 200, 7).expect("synthetic image");
        let img = GrayView::new(&buf, 200, 200, 200).unwrap();
        let all = detect(
            &img,
            &DetectorConfig {
                max_keypoints: usize::MAX,
                ..Default::default()
            },
        );
        let few = detect(
            &img,
            &DetectorConfig {
                max_keypoints: 5,
                ..Default::default()
            },
        );
        assert!(all.len() > 5);
        assert_eq!(&all[..5], &few[..]);
        for pair in all.windows(2) {
            let key = |k: &KeyPoint| (-(k.response as i32), k.y as i32, k.x as i32);
            assert!(key(&pair[0]) < key(&pair[1]));
        }
    }
}

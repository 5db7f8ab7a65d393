//! The reference detector (see the parent module for the numeric contract).

use crate::parallel::*;

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
    let c = fast_score(img, x, y);
    [
        parabola_offset(fast_score(img, x - 1, y), c, fast_score(img, x + 1, y)),
        parabola_offset(fast_score(img, x, y - 1), c, fast_score(img, x, y + 1)),
    ]
}

/// Cheap necessary condition: nine contiguous circle pixels always include two adjacent compass pixels
/// (0, 4, 8, 12) beyond the threshold on the same side.
#[inline]
fn may_be_corner(img: &GrayView, x: usize, y: usize, threshold: i32) -> bool {
    let p = img.at(x, y) as i32;
    let compass = [
        img.at(x, y - 3) as i32,
        img.at(x + 3, y) as i32,
        img.at(x, y + 3) as i32,
        img.at(x - 3, y) as i32,
    ];
    let bright = compass.map(|v| v - p > threshold);
    let dark = compass.map(|v| p - v > threshold);
    (0..4).any(|i| (bright[i] && bright[(i + 1) % 4]) || (dark[i] && dark[(i + 1) % 4]))
}

/// Score map: FAST score of each pixel inside the margin that is a corner, 0 elsewhere. Row-major,
/// `width * height`.
pub fn score_map(img: &GrayView, threshold: u8, margin: usize) -> Vec<u8> {
    let (w, h) = (img.width(), img.height());
    let t = threshold as i32;
    let mut scores = vec![0u8; w * h];
    if w <= 2 * margin || h <= 2 * margin {
        return scores;
    }
    scores
        .par_chunks_mut(w)
        .enumerate()
        .skip(margin)
        .take(h - 2 * margin)
        .for_each(|(y, row)| {
            for (x, score) in row.iter_mut().enumerate().take(w - margin).skip(margin) {
                if may_be_corner(img, x, y, t) {
                    let s = fast_score(img, x, y);
                    if s > t {
                        *score = s as u8;
                    }
                }
            }
        });
    scores
}

/// Corners that survive 3x3 non-maximum suppression (ties go to the first in raster order), as
/// `(x, y, score)` in raster order.
pub fn suppress_non_maxima(scores: &[u8], width: usize, height: usize) -> Vec<(u32, u32, u8)> {
    (1..height.saturating_sub(1))
        .into_par_iter()
        .flat_map_iter(|y| {
            let above = &scores[(y - 1) * width..y * width];
            let here = &scores[y * width..(y + 1) * width];
            let below = &scores[(y + 1) * width..(y + 2) * width];
            (1..width - 1).filter_map(move |x| {
                let s = here[x];
                let earlier = [above[x - 1], above[x], above[x + 1], here[x - 1]];
                let later = [here[x + 1], below[x - 1], below[x], below[x + 1]];
                let kept = s > 0 && earlier.iter().all(|&n| s > n) && later.iter().all(|&n| s >= n);
                kept.then_some((x as u32, y as u32, s))
            })
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

/// Intensity-centroid moments `(m10, m01)` over the orientation disc around `(x, y)`.
pub fn centroid_moments(img: &GrayView, x: usize, y: usize) -> (i64, i64) {
    let r = ORIENTATION_RADIUS;
    let (mut m10, mut m01) = (0i64, 0i64);
    for dy in -r..=r {
        let row = img.row((y as i32 + dy) as usize);
        let mut dx_sum = 0i64;
        let mut sum = 0i64;
        for dx in -r..=r {
            if dx * dx + dy * dy <= r * r {
                let v = row[(x as i32 + dx) as usize] as i64;
                dx_sum += dx as i64 * v;
                sum += v;
            }
        }
        m10 += dx_sum;
        m01 += dy as i64 * sum;
    }
    (m10, m01)
}

/// Runs the whole detector on the CPU. The image must be larger than twice the margin in both
/// directions (checked by the caller).
pub fn detect(img: &GrayView, config: &DetectorConfig) -> Vec<KeyPoint> {
    let margin = config.margin();
    let scores = score_map(img, config.threshold, margin);
    let mut corners = suppress_non_maxima(&scores, img.width(), img.height());
    corners.sort_unstable_by(|a, b| b.2.cmp(&a.2).then(a.1.cmp(&b.1)).then(a.0.cmp(&b.0)));
    corners.truncate(config.max_keypoints);
    corners
        .par_iter()
        .map(|&(x, y, score)| {
            let (m10, m01) = centroid_moments(img, x as usize, y as usize);
            KeyPoint {
                x: x as f32,
                y: y as f32,
                size: config.keypoint_size,
                angle: bin_degrees(direction_bin(m10, m01)),
                response: score as f32,
                octave: 0,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
                    assert!(
                        may_be_corner(&img, 4, 4, 20),
                        "the quick test must never reject a corner"
                    );
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
        let config = DetectorConfig::default();
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

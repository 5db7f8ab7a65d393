//! Helpers shared by the integration tests (each test binary uses a different subset).
#![allow(dead_code)]

pub mod golden;
pub mod gpu;
pub mod reference;
pub mod scale;
pub mod scene_pair;
pub mod two_view;
pub mod verify_cases;

use clatch::synthetic::SplitMix64;
use clatch::{DescriptorSet, DescriptorWidth, GrayView};

/// An owned 8-bit gray image, row-major, stride = width.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Gray {
    pub pixels: Vec<u8>,
    pub width: usize,
    pub height: usize,
}

impl Gray {
    pub fn new(pixels: Vec<u8>, width: usize, height: usize) -> Self {
        assert_eq!(pixels.len(), width * height);
        Self {
            pixels,
            width,
            height,
        }
    }

    pub fn view(&self) -> GrayView<'_> {
        GrayView::new(&self.pixels, self.width, self.height, self.width).expect("valid image")
    }

    pub fn at(&self, x: usize, y: usize) -> u8 {
        self.pixels[y * self.width + x]
    }

    /// The image turned by +90 degrees in image coordinates (y down): a point at offset `(a, b)` from the
    /// centre goes to `(-b, a)`. Pixel `(x, y)` lands on `(height - 1 - y, x)` of the `height x width`
    /// result, so an angle measured by `atan2(dy, dx)` grows by 90 degrees.
    pub fn rotate90(&self) -> Gray {
        let (w, h) = (self.height, self.width);
        let mut out = vec![0u8; w * h];
        for y in 0..self.height {
            for x in 0..self.width {
                let (nx, ny) = rotate90_point(x, y, self.height);
                out[ny * w + nx] = self.at(x, y);
            }
        }
        Gray::new(out, w, h)
    }

    /// [`Gray::rotate90`] applied `turns` times.
    pub fn rotate(&self, turns: usize) -> Gray {
        (0..turns).fold(self.clone(), |img, _| img.rotate90())
    }
}

/// Where pixel `(x, y)` of an image `height` pixels high lands after [`Gray::rotate90`].
pub fn rotate90_point(x: usize, y: usize, height: usize) -> (usize, usize) {
    (height - 1 - y, x)
}

/// The embedded photograph (512x512, 8-bit gray PNG), decoded with the `image` crate.
pub fn astronaut() -> Gray {
    let decoded = image::load_from_memory(include_bytes!("../../assets/astronaut.png"))
        .expect("the embedded PNG decodes");
    let gray = clatch::decode::gray_from_dynamic(&decoded);
    let (w, h) = (gray.width() as usize, gray.height() as usize);
    Gray::new(gray.into_raw(), w, h)
}

/// `clatch::synthetic::rectangles` as a [`Gray`].
pub fn rectangles(width: usize, height: usize, seed: u64) -> Gray {
    Gray::new(
        clatch::synthetic::rectangles(width, height, seed).expect("synthetic image"),
        width,
        height,
    )
}

/// Keypoints anywhere in a `width` x `height` image (border zones included) at sub-pixel positions on a
/// 1/64 grid (half pixels included), with FAST's "no angle" -1, angles on a 0.01-degree grid, and
/// angles with any `f32` mantissa in [-720, 720).
pub fn random_subpixel_keypoints(
    width: usize,
    height: usize,
    count: usize,
    seed: u64,
) -> Vec<clatch::KeyPoint> {
    let mut rng = SplitMix64::new(seed);
    (0..count)
        .map(|i| {
            let x = rng.below(width as u64 * 64) as f32 / 64.0;
            let y = rng.below(height as u64 * 64) as f32 / 64.0;
            let angle = match i % 5 {
                0 => -1.0,
                1 => rng.below(36_000) as f32 / 100.0,
                _ => (rng.below(1 << 24) as f32 / (1 << 24) as f32) * 1440.0 - 720.0,
            };
            clatch::KeyPoint::new(x, y).with_angle(angle)
        })
        .collect()
}

/// Every field's bits, so that even a -0.0 against 0.0 counts as a difference.
pub fn keypoint_bits(k: &clatch::KeyPoint) -> [u32; 6] {
    [
        k.x.to_bits(),
        k.y.to_bits(),
        k.size.to_bits(),
        k.angle.to_bits(),
        k.response.to_bits(),
        k.octave as u32,
    ]
}

/// The first index where two keypoint lists differ in any bit (or in length), if any.
pub fn first_keypoint_difference(a: &[clatch::KeyPoint], b: &[clatch::KeyPoint]) -> Option<usize> {
    a.iter()
        .zip(b)
        .position(|(x, y)| keypoint_bits(x) != keypoint_bits(y))
        .or((a.len() != b.len()).then_some(a.len().min(b.len())))
}

/// Uniformly random descriptors of the given width (bits past the width cleared by the set).
pub fn random_set(width: DescriptorWidth, count: usize, rng: &mut SplitMix64) -> DescriptorSet {
    let words = (0..count * width.words()).map(|_| rng.next_u64()).collect();
    DescriptorSet::from_words(width, words).expect("whole rows")
}

/// Random sets of `bits` bits, one per entry of `sizes`, and a pair list over them in scrambled
/// order: every pair both ways, each set with itself, and `repeats` random pairs more.
pub fn scrambled_collection(
    bits: usize,
    sizes: &[usize],
    repeats: usize,
    rng: &mut SplitMix64,
) -> (Vec<DescriptorSet>, Vec<(usize, usize)>) {
    let width = DescriptorWidth::from_bits(bits).expect("a valid width");
    let owned: Vec<DescriptorSet> = sizes.iter().map(|&n| random_set(width, n, rng)).collect();
    let n = owned.len();
    let mut pairs: Vec<(usize, usize)> = (0..n).flat_map(|a| (0..n).map(move |b| (a, b))).collect();
    pairs
        .extend((0..repeats).map(|_| (rng.below(n as u64) as usize, rng.below(n as u64) as usize)));
    // Fisher-Yates with the caller's generator.
    for i in (1..pairs.len()).rev() {
        pairs.swap(i, rng.below(i as u64 + 1) as usize);
    }
    (owned, pairs)
}

/// Hamming distance computed bit by bit, independent of the crate's popcount.
pub fn naive_hamming(a: &[u64], b: &[u64], bits: usize) -> u32 {
    (0..bits)
        .filter(|&t| (a[t / 64] >> (t % 64)) & 1 != (b[t / 64] >> (t % 64)) & 1)
        .count() as u32
}

/// Flips `count` distinct bits among the first `bits` of a packed row.
pub fn flip_bits(row: &mut [u64], bits: usize, count: usize, rng: &mut SplitMix64) {
    let mut flipped = Vec::new();
    while flipped.len() < count.min(bits) {
        let t = rng.below(bits as u64) as usize;
        if !flipped.contains(&t) {
            flipped.push(t);
            row[t / 64] ^= 1 << (t % 64);
        }
    }
}

/// Every combination of ratio test, cross-check and distance limit the matcher suites run through.
/// Every fifth of them (`.step_by(5)`) still has each ratio, both cross-check settings and each limit.
pub fn match_configs() -> Vec<clatch::MatchConfig> {
    let mut out = Vec::new();
    for ratio in [None, Some(0.8), Some(1.0), Some(0.5), Some(0.95)] {
        for cross_check in [false, true] {
            for max_distance in [None, Some(0), Some(3), Some(100)] {
                out.push(
                    clatch::MatchConfig::default()
                        .with_ratio(ratio)
                        .with_cross_check(cross_check)
                        .with_max_distance(max_distance),
                );
            }
        }
    }
    out
}

/// Runs `work(t)` for `t` in `0..threads`, each on its own thread at once, and sums what they return;
/// the first error (a panic is one) comes back instead.
pub fn on_threads(
    threads: usize,
    work: impl Fn(usize) -> Result<usize, String> + Sync,
) -> Result<usize, String> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let work = &work;
                scope.spawn(move || work(t))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or(Err("thread panicked".into())))
            .sum()
    })
}

/// Sets of `bits` bits, one per entry of `sizes`, full of ties: every row is a row of a small shared
/// pool (so rows repeat within and across sets), that row a few bits off, or fresh random bits.
/// Equal distances, to one query and across queries, are then common at every width.
pub fn tied_collection(bits: usize, sizes: &[usize], rng: &mut SplitMix64) -> Vec<DescriptorSet> {
    let width = DescriptorWidth::from_bits(bits).expect("a valid width");
    let pool = random_set(width, 24, rng);
    sizes
        .iter()
        .map(|&n| {
            let mut words = Vec::with_capacity(n * width.words());
            for _ in 0..n {
                let mut row = pool
                    .rows()
                    .nth(rng.below(24) as usize)
                    .expect("24 rows")
                    .to_vec();
                match rng.below(4) {
                    0 | 1 => {}
                    2 => flip_bits(&mut row, bits, 1 + rng.below(3) as usize, rng),
                    _ => random_set(width, 1, rng).as_words().clone_into(&mut row),
                }
                words.extend(row);
            }
            DescriptorSet::from_words(width, words).expect("whole rows")
        })
        .collect()
}

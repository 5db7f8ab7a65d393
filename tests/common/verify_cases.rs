//! Generated pairs for comparing verification backends (`tests/cuda_verify.rs`, and the host build of
//! the kernel's arithmetic in `host_twin/tests/verify.rs`, which includes this file and
//! `two_view.rs` by path): every shape the CPU reference decides differently (general 3-D, planar,
//! pure rotation, degenerate, watermarks), 0 to 850 matches, 0 to 90 % outliers, with and without
//! cameras and intrinsics, duplicate matches, shuffled keypoint indices, huge coordinates.
#![allow(dead_code)]

use clatch::verify::{
    Camera, Intrinsics, NeighbourConsistency, TwoViewGeometry, VerifyConfig, ViewPair,
};
use clatch::{KeyPoint, Match};

use super::two_view::{Rng, Shape, scene};

/// One generated pair, owning its data.
pub struct Case {
    pub name: String,
    pub a: Vec<KeyPoint>,
    pub b: Vec<KeyPoint>,
    pub matches: Vec<Match>,
    pub cameras: Option<(Camera, Camera)>,
    pub key: u64,
}

impl Case {
    pub fn pair(&self) -> ViewPair<'_> {
        let pair = ViewPair::new(&self.a, &self.b, &self.matches).with_key(self.key);
        match &self.cameras {
            Some((ca, cb)) => pair.with_cameras(ca, cb),
            None => pair,
        }
    }
}

/// Which cameras a case has.
#[derive(Clone, Copy, Debug)]
enum Cameras {
    None,
    Sizes,
    Intrinsics,
}

/// Case `index` of the family drawn from `seed`: the shape, size, outlier share, cameras and
/// oddities cycle through every combination as `index` grows.
pub fn case(seed: u64, index: usize) -> Case {
    let mut rng = Rng::new(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let shapes = [Shape::General, Shape::Planar, Shape::Rotation];
    let shape = shapes[index % 3];
    let sizes = [
        0usize, 1, 3, 4, 5, 6, 7, 8, 9, 12, 15, 16, 24, 40, 100, 250, 850,
    ];
    let n = sizes[(index / 3) % sizes.len()];
    let outliers = [0.0, 0.1, 0.4, 0.6, 0.9][(index / 7) % 5];
    let noise = [0.0, 0.5, 1.5][(index / 5) % 3];
    let cameras = [Cameras::None, Cameras::Sizes, Cameras::Intrinsics][(index / 11) % 3];
    let oddity = (index / 13) % 6;
    let s = scene(rng.next_u64(), shape, n.max(1), outliers, noise);
    let keypoint = |p: [f64; 2]| KeyPoint::new(p[0] as f32, p[1] as f32);
    let mut a: Vec<KeyPoint> = s.a[..n].iter().map(|p| keypoint(*p)).collect();
    let mut b: Vec<KeyPoint> = s.b[..n].iter().map(|p| keypoint(*p)).collect();
    // B's keypoints stored in reverse, so that query and train indices differ.
    b.reverse();
    let mut matches: Vec<Match> = (0..n as u32)
        .map(|i| Match {
            query: i,
            train: n as u32 - 1 - i,
            distance: i % 64,
        })
        .collect();
    let mut what = format!("{shape:?} n={n} outliers={outliers} noise={noise} {cameras:?}");
    match oddity {
        1 if n > 0 => {
            // Duplicate matches: a third of them again, at the end.
            let extra: Vec<Match> = matches.iter().step_by(3).copied().collect();
            matches.extend(extra);
            what.push_str(" duplicates");
        }
        2 => {
            // Huge coordinates: the same scene a million times larger.
            for k in a.iter_mut().chain(b.iter_mut()) {
                k.x *= 1.0e6;
                k.y *= 1.0e6;
            }
            what.push_str(" huge");
        }
        3 if n > 0 => {
            // A degenerate pair: every keypoint of A on one line, B on one point.
            for (i, k) in a.iter_mut().enumerate() {
                *k = KeyPoint::new(10.0 + i as f32, 20.0 + 2.0 * i as f32);
            }
            for k in &mut b {
                *k = KeyPoint::new(300.0, 200.0);
            }
            what.push_str(" collinear");
        }
        4 if n > 0 => {
            // A watermark: every match stays in the bottom band, some moved by a pixel.
            for (i, k) in a.iter_mut().enumerate() {
                *k = KeyPoint::new(
                    rng.uniform(20.0, 1000.0) as f32,
                    rng.uniform(700.0, 760.0) as f32,
                );
                b[n - 1 - i] = KeyPoint::new(k.x + (i % 2) as f32, k.y);
            }
            what.push_str(" watermark");
        }
        _ => {}
    }
    let make = |(f, cx, cy): (f64, f64, f64)| {
        let camera = Camera::new(s.width, s.height);
        match cameras {
            Cameras::Intrinsics => camera.with_intrinsics(Intrinsics::new(f, f, cx, cy)),
            _ => camera,
        }
    };
    Case {
        name: format!("case {index} (seed {seed}): {what}"),
        a,
        b,
        matches,
        cameras: match cameras {
            Cameras::None => None,
            _ => Some((make(s.camera_a), make(s.camera_b))),
        },
        key: rng.next_u64(),
    }
}

/// The bits of a matrix that may be absent.
pub type MatrixBits = Option<[u64; 9]>;

/// Every bit of a geometry: configuration, matrices (`None` kept apart from a matrix), inliers,
/// counts.
pub fn bits(g: &TwoViewGeometry) -> (i32, [MatrixBits; 3], Vec<u32>, [usize; 3]) {
    let m = |m: &Option<[[f64; 3]; 3]>| {
        m.map(|m| {
            let flat: Vec<u64> = m.iter().flatten().map(|v| v.to_bits()).collect();
            <[u64; 9]>::try_from(flat).expect("nine entries")
        })
    };
    (
        g.config.colmap_code(),
        [m(&g.f), m(&g.e), m(&g.h)],
        g.inliers.clone(),
        [g.inlier_counts.e, g.inlier_counts.f, g.inlier_counts.h],
    )
}

/// How many fields of `got` differ from `want` (configuration, F, E, H, inliers, counts), with a
/// description of the first.
pub fn differences(want: &TwoViewGeometry, got: &TwoViewGeometry) -> (usize, Option<String>) {
    let (w, g) = (bits(want), bits(got));
    let fields = [
        ("config", w.0 != g.0),
        ("F", w.1[0] != g.1[0]),
        ("E", w.1[1] != g.1[1]),
        ("H", w.1[2] != g.1[2]),
        ("inliers", w.2 != g.2),
        ("counts", w.3 != g.3),
    ];
    let differing: Vec<&str> = fields.iter().filter(|f| f.1).map(|f| f.0).collect();
    let first = differing.first().map(|field| {
        format!(
            "{field} differs: want {:?} {:?} counts {:?} ({} inliers), got {:?} {:?} counts {:?} ({} inliers)",
            want.config,
            want.f.or(want.h),
            want.inlier_counts,
            want.inliers.len(),
            got.config,
            got.f.or(got.h),
            got.inlier_counts,
            got.inliers.len()
        )
    });
    (differing.len(), first)
}

/// Settings other than the default that every twin is compared under: the neighbour rule on, a
/// planar pair's F inliers, another seed and threshold, few trials and a low confidence, the
/// watermark test off with a higher inlier ratio.
pub fn other_configs() -> Vec<VerifyConfig> {
    vec![
        VerifyConfig::default().with_neighbour_consistency(Some(NeighbourConsistency::default())),
        VerifyConfig::default()
            .with_planar_keeps_homography_inliers(false)
            .with_seed(99)
            .with_max_error(1.0),
        VerifyConfig::default()
            .with_min_num_inliers(4)
            .with_min_num_trials(0)
            .with_max_num_trials(50)
            .with_confidence(0.9),
        VerifyConfig::default()
            .with_detect_watermark(false)
            .with_min_inlier_ratio(0.6),
    ]
}

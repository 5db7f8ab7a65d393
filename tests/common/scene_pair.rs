//! A synthetic scene of `two_view.rs` as the library's inputs: the keypoints of both views, the
//! identity matches (`i ↔ i`) and both cameras with their intrinsics. Included as a sibling of
//! `two_view` by the verification tests, the benches and the timing example.
#![allow(dead_code)]

use clatch::verify::{Camera, Intrinsics};
use clatch::{KeyPoint, Match};

use super::two_view::Scene;

/// One scene's keypoints, matches and cameras (calibrated unless made
/// [`ScenePair::without_intrinsics`]).
pub struct ScenePair {
    pub a: Vec<KeyPoint>,
    pub b: Vec<KeyPoint>,
    pub matches: Vec<Match>,
    pub cameras: (Camera, Camera),
    /// Both images' width and height.
    pub size: (u32, u32),
}

impl ScenePair {
    pub fn new(s: &Scene) -> Self {
        let keypoints = |points: &[[f64; 2]]| {
            points
                .iter()
                .map(|p| KeyPoint::new(p[0] as f32, p[1] as f32))
                .collect()
        };
        let camera = |(f, cx, cy): (f64, f64, f64)| {
            Camera::new(s.width, s.height).with_intrinsics(Intrinsics::new(f, f, cx, cy))
        };
        Self {
            a: keypoints(&s.a),
            b: keypoints(&s.b),
            matches: (0..s.a.len() as u32)
                .map(|i| Match {
                    query: i,
                    train: i,
                    distance: 0,
                })
                .collect(),
            cameras: (camera(s.camera_a), camera(s.camera_b)),
            size: (s.width, s.height),
        }
    }

    /// The same pair with cameras that know only the images' size (uncalibrated: F and H).
    pub fn without_intrinsics(mut self) -> Self {
        let (w, h) = self.size;
        self.cameras = (Camera::new(w, h), Camera::new(w, h));
        self
    }
}

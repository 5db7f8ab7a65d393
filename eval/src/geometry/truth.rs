//! Ground truth of a scene: calibrated cameras with their poses and, for generated scenes, the
//! planes the scene is made of.
//!
//! Two layouts are read:
//! - `scene.json`, written by `clatch-eval facade` (this crate's generator): cameras and planes;
//! - a Strecha-style folder with `gt_dense_cameras/NAME.camera` (K, a distortion row, R camera to
//!   world, the camera centre, `width height`), as `strecha_herzjesu_p8`: cameras only.
//!
//! Pixel coordinates are COLMAP's throughout (the centre of the first pixel at (0.5, 0.5)), the
//! coordinates the database's keypoints are in. A generated scene's K is written in them. Strecha's
//! K is taken as it is, as `clatch colmap --camera-k` and COLMAP's SIFT baseline take it (a half-pixel
//! shift of the principal point moves the epipolar lines by far less than the 1 px threshold; see
//! docs/eval/geometry.md).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{EvalError, IoContext};
use crate::geometry::linalg::{
    Mat3, Vec3, add, apply, cross, dot, invert, mul, norm, scale, skew, sub, transpose,
};

/// The file a generated scene's truth is in.
pub const SCENE_FILE: &str = "scene.json";

/// One calibrated camera: `x ~ K (R X + t)`, `R` world to camera.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrueCamera {
    /// The image's file name (as in the database's `images.name`).
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Intrinsics in COLMAP pixel coordinates.
    pub k: Mat3,
    /// Rotation world to camera.
    pub r: Mat3,
    /// Translation world to camera.
    pub t: Vec3,
}

impl TrueCamera {
    /// The camera centre in the world, `−Rᵀ t`.
    pub fn centre(&self) -> Vec3 {
        scale(apply(&transpose(&self.r), self.t), -1.0)
    }

    /// The pixel of a world point, `None` behind the camera.
    pub fn project(&self, x: Vec3) -> Option<[f64; 2]> {
        let c = add(apply(&self.r, x), self.t);
        if c[2] <= 0.0 {
            return None;
        }
        let p = apply(&self.k, c);
        Some([p[0] / p[2], p[1] / p[2]])
    }

    /// The viewing ray of a pixel: its direction in the world (not normalised).
    pub fn ray(&self, pixel: [f64; 2]) -> Option<Vec3> {
        let k_inv = invert(&self.k)?;
        Some(apply(
            &transpose(&self.r),
            apply(&k_inv, [pixel[0], pixel[1], 1.0]),
        ))
    }
}

/// A planar rectangle of the scene: `origin + a·u + b·v`, `0 ≤ a ≤ width`, `0 ≤ b ≤ height`, with
/// `u` and `v` orthonormal.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Plane {
    pub origin: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub width: f64,
    pub height: f64,
}

impl Plane {
    /// Where a ray from `from` along `direction` meets the rectangle: the distance parameter and
    /// the plane coordinates `(a, b)`.
    pub fn intersect(&self, from: Vec3, direction: Vec3) -> Option<(f64, [f64; 2])> {
        let n = cross(self.u, self.v);
        let denominator = dot(n, direction);
        if denominator.abs() < 1e-12 {
            return None;
        }
        let s = dot(n, sub(self.origin, from)) / denominator;
        if s <= 0.0 {
            return None;
        }
        let hit = sub(add(from, scale(direction, s)), self.origin);
        let (a, b) = (dot(hit, self.u), dot(hit, self.v));
        (0.0..=self.width)
            .contains(&a)
            .then_some(())
            .filter(|_| (0.0..=self.height).contains(&b))
            .map(|_| (s, [a, b]))
    }

    /// The world point of plane coordinates.
    pub fn point(&self, [a, b]: [f64; 2]) -> Vec3 {
        add(self.origin, add(scale(self.u, a), scale(self.v, b)))
    }
}

/// A scene's truth.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Truth {
    /// Where it came from, for the report.
    #[serde(default)]
    pub description: String,
    pub cameras: Vec<TrueCamera>,
    /// The scene's surfaces; empty when unknown (Strecha).
    #[serde(default)]
    pub planes: Vec<Plane>,
}

impl Truth {
    /// Reads `DIR/scene.json`, or a Strecha folder's `DIR/gt_dense_cameras`.
    pub fn read(dir: &Path) -> Result<Self, EvalError> {
        let scene = dir.join(SCENE_FILE);
        if scene.is_file() {
            let text = std::fs::read_to_string(&scene).reading(&scene)?;
            return serde_json::from_str(&text).map_err(|e| EvalError::Input {
                path: scene,
                reason: e.to_string(),
            });
        }
        let strecha = dir.join("gt_dense_cameras");
        if strecha.is_dir() {
            return read_strecha(&strecha);
        }
        Err(EvalError::Input {
            path: dir.to_path_buf(),
            reason: format!("holds neither {SCENE_FILE} nor gt_dense_cameras/"),
        })
    }

    pub fn camera(&self, name: &str) -> Option<&TrueCamera> {
        self.cameras.iter().find(|c| c.name == name)
    }

    /// The nearest scene point seen at a pixel of a camera, if the scene's planes are known and the
    /// pixel sees one.
    pub fn surface_point(&self, camera: &TrueCamera, pixel: [f64; 2]) -> Option<Vec3> {
        let direction = camera.ray(pixel)?;
        let from = camera.centre();
        self.planes
            .iter()
            .filter_map(|p| p.intersect(from, direction).map(|(s, ab)| (s, p.point(ab))))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, x)| x)
    }
}

/// The fundamental matrix of two cameras: `x2ᵀ F x1 = 0`.
pub fn fundamental(a: &TrueCamera, b: &TrueCamera) -> Option<Mat3> {
    let r = mul(&b.r, &transpose(&a.r));
    let t = sub(b.t, apply(&r, a.t));
    if norm(t) == 0.0 {
        return None;
    }
    let e = mul(&skew(t), &r);
    let (ka, kb) = (invert(&a.k)?, invert(&b.k)?);
    Some(mul(&transpose(&kb), &mul(&e, &ka)))
}

/// `gt_dense_cameras/*.camera` of the Strecha et al. (CVPR 2008) data sets.
fn read_strecha(dir: &Path) -> Result<Truth, EvalError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .reading(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "camera"))
        .collect();
    files.sort();
    let mut cameras = Vec::new();
    for path in files {
        let text = std::fs::read_to_string(&path).reading(&path)?;
        let bad = |reason: String| EvalError::Input {
            path: path.clone(),
            reason,
        };
        let numbers = text
            .split_whitespace()
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| bad(format!("{s:?} is not a number")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        if numbers.len() != 26 {
            return Err(bad(format!(
                "{} numbers, a .camera file has 26",
                numbers.len()
            )));
        }
        let m =
            |at: usize| -> Mat3 { [0, 1, 2].map(|r| [0, 1, 2].map(|c| numbers[at + 3 * r + c])) };
        let (k, r_camera_to_world) = (m(0), m(12));
        let centre = [numbers[21], numbers[22], numbers[23]];
        let r = transpose(&r_camera_to_world);
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_suffix(".camera"))
            .unwrap_or_default()
            .to_string();
        let (width, height) = (numbers[24] as u32, numbers[25] as u32);
        cameras.push(TrueCamera {
            name,
            width,
            height,
            k,
            r,
            t: scale(apply(&r, centre), -1.0),
        });
    }
    Ok(Truth {
        description: format!("Strecha ground truth {}", dir.display()),
        cameras,
        planes: Vec::new(),
    })
}

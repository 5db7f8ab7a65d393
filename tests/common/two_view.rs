//! Synthetic two-view scenes with known cameras, for the verification tests and bench: random 3-D
//! points seen by two pinhole cameras, their true F, E and H, optional pixel noise and outliers. The
//! crate's unit tests include this file by path, so it uses std and its parent's `SplitMix64` only.
#![allow(dead_code)]

pub type Mat3 = [[f64; 3]; 3];

/// A reproducible generator with uniform and Gaussian draws, over the includer's
/// `SplitMix64` (`clatch::synthetic::SplitMix64`; this file is included by path from inside the
/// crate too, so it names the generator through its parent module).
pub struct Rng(super::SplitMix64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(super::SplitMix64::new(seed))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }

    /// Standard normal (Box–Muller; tests only).
    pub fn normal(&mut self) -> f64 {
        let u = self.uniform(1e-12, 1.0);
        let v = self.uniform(0.0, 1.0);
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

pub fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

pub fn apply(a: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

pub fn skew(t: [f64; 3]) -> Mat3 {
    [[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]]
}

/// Rotation by `angle` radians about `axis` (Rodrigues).
pub fn rotation(axis: [f64; 3], angle: f64) -> Mat3 {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let k = skew(axis.map(|v| v / n));
    let k2 = mul(&k, &k);
    let (s, c) = angle.sin_cos();
    std::array::from_fn(|i| {
        std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 } + s * k[i][j] + (1.0 - c) * k2[i][j])
    })
}

/// `K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]` and its inverse.
pub fn calibration(f: f64, cx: f64, cy: f64) -> (Mat3, Mat3) {
    (
        [[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]],
        [
            [1.0 / f, 0.0, -cx / f],
            [0.0, 1.0 / f, -cy / f],
            [0.0, 0.0, 1.0],
        ],
    )
}

/// `a / |a|_F` with the sign that makes the largest entry positive: equal matrices up to scale compare
/// equal.
pub fn normalised(a: &Mat3) -> Mat3 {
    let norm = a.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
    let largest = a
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| if v.abs() > m.abs() { *v } else { m });
    let scale = norm * largest.signum();
    a.map(|row| row.map(|v| v / scale))
}

/// Largest entry difference of two matrices after [`normalised`].
pub fn distance_up_to_scale(a: &Mat3, b: &Mat3) -> f64 {
    let (a, b) = (normalised(a), normalised(b));
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Which shape the scene points take.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// Points spread in depth: a general two-view scene (F and E, no H).
    General,
    /// Points on one plane: H explains every match.
    Planar,
    /// The cameras share their centre: H (the infinite homography) explains every match.
    Rotation,
}

/// Two views of random points: `a[i] ↔ b[i]` in pixels; `inlier[i]` false for the outliers, which
/// are random pixels in image B.
pub struct Scene {
    pub a: Vec<[f64; 2]>,
    pub b: Vec<[f64; 2]>,
    pub inlier: Vec<bool>,
    /// `(f, cx, cy)` of both cameras.
    pub camera_a: (f64, f64, f64),
    pub camera_b: (f64, f64, f64),
    pub f: Mat3,
    pub e: Mat3,
    /// The true homography where one exists (planar scene, pure rotation).
    pub h: Option<Mat3>,
    pub width: u32,
    pub height: u32,
}

/// `n` correspondences, a share `outliers` of them (placed at random indices) wrong, Gaussian noise
/// of `noise` pixels on the inliers.
pub fn scene(seed: u64, shape: Shape, n: usize, outliers: f64, noise: f64) -> Scene {
    let mut rng = Rng::new(seed);
    let (width, height) = (1024u32, 768u32);
    let camera_a = (900.0 + rng.uniform(-50.0, 50.0), 511.5, 383.5);
    let camera_b = (1000.0 + rng.uniform(-50.0, 50.0), 515.0, 380.0);
    let (_, ka_inv) = calibration(camera_a.0, camera_a.1, camera_a.2);
    let (kb, kb_inv) = calibration(camera_b.0, camera_b.1, camera_b.2);
    let axis = [
        rng.uniform(-1.0, 1.0),
        rng.uniform(-1.0, 1.0),
        rng.uniform(-1.0, 1.0),
    ];
    let r = rotation(axis, rng.uniform(0.05, 0.25));
    let t = match shape {
        Shape::Rotation => [0.0; 3],
        _ => [
            rng.uniform(0.5, 1.5),
            rng.uniform(-0.3, 0.3),
            rng.uniform(-0.3, 0.3),
        ],
    };
    let e = mul(&skew(t), &r);
    let f = mul(&mul(&transpose(&kb_inv), &e), &ka_inv);
    // The plane n·X = d of the planar scene: z = 6 + 0.2 x − 0.1 y.
    let (normal, d) = ([-0.2, 0.1, 1.0], 6.0);
    let h = match shape {
        Shape::General => None,
        Shape::Rotation => Some(mul(&mul(&kb, &r), &ka_inv)),
        Shape::Planar => {
            let plane: Mat3 =
                std::array::from_fn(|i| std::array::from_fn(|j| r[i][j] + t[i] * normal[j] / d));
            Some(mul(&mul(&kb, &plane), &ka_inv))
        }
    };
    let mut scene = Scene {
        a: Vec::new(),
        b: Vec::new(),
        inlier: Vec::new(),
        camera_a,
        camera_b,
        f,
        e,
        h,
        width,
        height,
    };
    while scene.a.len() < n {
        let (u, v) = (
            rng.uniform(20.0, f64::from(width) - 20.0),
            rng.uniform(20.0, f64::from(height) - 20.0),
        );
        let ray = apply(&ka_inv, [u, v, 1.0]);
        let depth = match shape {
            Shape::General | Shape::Rotation => rng.uniform(4.0, 12.0),
            Shape::Planar => d / (normal[0] * ray[0] + normal[1] * ray[1] + normal[2] * ray[2]),
        };
        let x = ray.map(|c| c * depth);
        let xb = apply(&r, x);
        let xb = [xb[0] + t[0], xb[1] + t[1], xb[2] + t[2]];
        let pb = apply(&kb, xb);
        let (ub, vb) = (pb[0] / pb[2], pb[1] / pb[2]);
        if xb[2] <= 0.0
            || !(0.0..f64::from(width)).contains(&ub)
            || !(0.0..f64::from(height)).contains(&vb)
        {
            continue;
        }
        scene
            .a
            .push([u + noise * rng.normal(), v + noise * rng.normal()]);
        scene
            .b
            .push([ub + noise * rng.normal(), vb + noise * rng.normal()]);
        scene.inlier.push(true);
    }
    let wrong = (outliers * n as f64).round() as usize;
    let mut made = 0;
    while made < wrong {
        let i = (rng.next_u64() % n as u64) as usize;
        if !scene.inlier[i] {
            continue;
        }
        scene.inlier[i] = false;
        // More than 30 pixels off every true model, so that a 4-pixel threshold separates them even
        // after an algebraic least-squares fit pulled towards a near outlier.
        loop {
            let p = [
                rng.uniform(0.0, f64::from(width)),
                rng.uniform(0.0, f64::from(height)),
            ];
            let off_f = shape == Shape::Rotation || sampson(&scene.f, scene.a[i], p) > 900.0;
            let off_h = scene
                .h
                .as_ref()
                .is_none_or(|h| transfer(h, scene.a[i], p) > 900.0);
            if off_f && off_h {
                scene.b[i] = p;
                break;
            }
        }
        made += 1;
    }
    scene
}

/// The squared Sampson error of `a ↔ b` under `f` (pixels²).
pub fn sampson(f: &Mat3, a: [f64; 2], b: [f64; 2]) -> f64 {
    let fa = apply(f, [a[0], a[1], 1.0]);
    let ftb = apply(&transpose(f), [b[0], b[1], 1.0]);
    let e = b[0] * fa[0] + b[1] * fa[1] + fa[2];
    e * e / (fa[0] * fa[0] + fa[1] * fa[1] + ftb[0] * ftb[0] + ftb[1] * ftb[1])
}

/// The squared transfer error of `a ↔ b` under `h` (pixels²).
pub fn transfer(h: &Mat3, a: [f64; 2], b: [f64; 2]) -> f64 {
    let p = apply(h, [a[0], a[1], 1.0]);
    (p[0] / p[2] - b[0]).powi(2) + (p[1] / p[2] - b[1]).powi(2)
}

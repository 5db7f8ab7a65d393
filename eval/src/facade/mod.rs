//! `clatch-eval facade`: a scene of repeated structure with exact ground truth, made from a photo.
//!
//! One crop of the photo (a window, an arch) is tiled into a facade ([`texture::tiled_facade`]),
//! set on a plane (or, with `--corner`, on two walls meeting at a right angle, a courtyard corner,
//! so that the two-view geometry is not a homography) and rendered ([`render::render`]) from
//! `--views` calibrated cameras on an arc: the yaw spread evenly over `--spread` degrees, with small
//! seeded changes of height, distance, aim and roll. Everything is a function of the arguments and
//! the seed.
//!
//! Writes `OUT/images/viewK.png`, `OUT/K.txt` (the shared K, COLMAP pixel coordinates, for
//! `clatch colmap --camera-k` and COLMAP's `--ImageReader.camera_params`) and `OUT/scene.json`
//! (cameras and planes, [`crate::geometry::truth::Truth`]), which `clatch-eval geometry --scene OUT`
//! reads.

mod render;
mod texture;

use std::path::PathBuf;

use clap::Parser;
use clatch::synthetic::SplitMix64;

use crate::error::{EvalError, IoContext};
use crate::geometry::linalg::{Mat3, Vec3, add, apply, axis_angle, cross, mul, norm, scale, sub};
use crate::geometry::truth::{Plane, SCENE_FILE, TrueCamera, Truth};
use render::{TexturedPlane, render};
use texture::{TileVariation, symmetric, tiled_facade};

/// Size of a texture pixel on the facade, metres.
const METRES_PER_PIXEL: f64 = 0.01;

/// Renders a facade of repeated structure from known cameras.
#[derive(Debug, Parser)]
#[command(name = "clatch-eval facade")]
pub struct FacadeArgs {
    /// The photo the tile is cut from.
    #[arg(long, value_name = "FILE")]
    pub photo: PathBuf,
    /// The tile: X,Y,WIDTH,HEIGHT of the crop in the photo, pixels.
    #[arg(long, value_name = "X,Y,W,H", value_parser = parse_crop)]
    pub crop: (u32, u32, u32, u32),
    /// Tiles across the facade (each wall with --corner).
    #[arg(long, default_value_t = 6)]
    pub columns: u32,
    /// Tiles up the facade.
    #[arg(long, default_value_t = 3)]
    pub rows: u32,
    /// Cameras (2 to 6).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(2..=6))]
    pub views: u32,
    /// Yaw between the first and the last camera, degrees.
    #[arg(long, default_value_t = 40.0)]
    pub spread: f64,
    /// Two walls at a right angle (a courtyard corner) instead of one plane.
    #[arg(long)]
    pub corner: bool,
    /// Image width, pixels.
    #[arg(long, default_value_t = 1600)]
    pub width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 1000)]
    pub height: u32,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder (created; an existing scene.json in it is an error).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

fn parse_crop(text: &str) -> Result<(u32, u32, u32, u32), String> {
    let v = text
        .split(',')
        .map(|s| s.trim().parse::<u32>().map_err(|e| format!("{s:?}: {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    match v[..] {
        [x, y, w, h] if w >= 16 && h >= 16 => Ok((x, y, w, h)),
        _ => Err("X,Y,W,H with W and H at least 16".into()),
    }
}

/// How the tiles vary (fixed: the scene's character, not a knob).
const VARIATION: TileVariation = TileVariation {
    jitter_px: 3,
    gain: 0.06,
    grain: 2.0,
    gap_px: 12,
};

/// Runs `clatch-eval facade`.
pub fn run(args: &FacadeArgs) -> Result<(), EvalError> {
    let scene_path = args.out.join(SCENE_FILE);
    if scene_path.exists() {
        return Err(EvalError::Input {
            path: scene_path,
            reason: "exists already; choose another --out".into(),
        });
    }
    let photo = image::open(&args.photo)
        .map_err(|e| EvalError::Input {
            path: args.photo.clone(),
            reason: e.to_string(),
        })?
        .to_rgb8();
    let (x, y, w, h) = args.crop;
    let margin = VARIATION.jitter_px;
    if x < margin || y < margin || x + w + margin > photo.width() || y + h + margin > photo.height()
    {
        return Err(EvalError::Input {
            path: args.photo.clone(),
            reason: format!(
                "the crop {x},{y},{w},{h} with {margin} px to spare on each side is not inside the {}x{} photo",
                photo.width(),
                photo.height()
            ),
        });
    }
    let mut rng = SplitMix64::new(args.seed);
    let walls = if args.corner { 2 } else { 1 };
    let textures: Vec<_> = (0..walls)
        .map(|_| {
            tiled_facade(
                &photo,
                args.crop,
                args.columns,
                args.rows,
                VARIATION,
                &mut rng,
            )
        })
        .collect();
    let (tw, th) = (textures[0].width(), textures[0].height());
    let (wall_w, wall_h) = (
        f64::from(tw) * METRES_PER_PIXEL,
        f64::from(th) * METRES_PER_PIXEL,
    );
    let planes = scene_planes(args.corner, wall_w, wall_h);
    let target = if args.corner {
        [0.0, 0.0, -0.35 * wall_w]
    } else {
        [0.0, 0.0, 0.0]
    };
    let focal = 0.9 * f64::from(args.width);
    let k = [
        [focal, 0.0, f64::from(args.width) / 2.0],
        [0.0, focal, f64::from(args.height) / 2.0],
        [0.0, 0.0, 1.0],
    ];
    let distance = framing_distance(&planes, target, k, args.width, args.height);
    let mut cameras = Vec::new();
    for view in 0..args.views {
        let yaw = -args.spread / 2.0 + args.spread * f64::from(view) / f64::from(args.views - 1);
        let d = distance * (1.0 + 0.05 * f64::from(symmetric(&mut rng)));
        let height = 0.05 * distance * f64::from(symmetric(&mut rng));
        let aim = add(
            target,
            [
                0.03 * wall_w * f64::from(symmetric(&mut rng)),
                0.03 * wall_h * f64::from(symmetric(&mut rng)),
                0.0,
            ],
        );
        let roll = 2.0 * f64::from(symmetric(&mut rng));
        let (s, c) = yaw.to_radians().sin_cos();
        let centre = add(target, [d * s, height, -d * c]);
        let r = look_at(centre, aim, roll);
        cameras.push(TrueCamera {
            name: format!("view{view}.png"),
            width: args.width,
            height: args.height,
            k,
            r,
            t: scale(apply(&r, centre), -1.0),
        });
    }
    let images = args.out.join("images");
    std::fs::create_dir_all(&images).writing(&images)?;
    let textured: Vec<TexturedPlane> = planes
        .iter()
        .zip(&textures)
        .map(|(plane, texture)| TexturedPlane {
            plane: plane.clone(),
            texture,
            metres_per_pixel: METRES_PER_PIXEL,
        })
        .collect();
    for camera in &cameras {
        let path = images.join(&camera.name);
        render(camera, &textured)
            .save(&path)
            .map_err(|source| EvalError::Encode {
                path: path.clone(),
                source,
            })?;
    }
    let k_path = args.out.join("K.txt");
    let k_text: String = k
        .iter()
        .map(|row| format!("{} {} {}\n", row[0], row[1], row[2]))
        .collect();
    std::fs::write(&k_path, k_text).writing(&k_path)?;
    let truth = Truth {
        description: format!(
            "clatch-eval facade: {} of {} x {} tiles of {} crop {x},{y},{w},{h}, {} views over {}°, seed {}",
            if args.corner {
                "two walls at 90°"
            } else {
                "one plane"
            },
            args.columns,
            args.rows,
            args.photo.display(),
            args.views,
            args.spread,
            args.seed
        ),
        cameras,
        planes,
    };
    let text = serde_json::to_string_pretty(&truth).map_err(|e| EvalError::Input {
        path: scene_path.clone(),
        reason: e.to_string(),
    })?;
    std::fs::write(&scene_path, text).writing(&scene_path)?;
    println!("{}", truth.description);
    println!(
        "wrote {} images, K.txt and {SCENE_FILE} in {}",
        truth.cameras.len(),
        args.out.display()
    );
    Ok(())
}

/// The walls: x right, y down, z away from the cameras. One plane at z = 0 centred on the origin,
/// or two walls meeting at the vertical line x = z = 0, each at 45° to the view.
fn scene_planes(corner: bool, width: f64, height: f64) -> Vec<Plane> {
    let down = [0.0, 1.0, 0.0];
    if !corner {
        return vec![Plane {
            origin: [-width / 2.0, -height / 2.0, 0.0],
            u: [1.0, 0.0, 0.0],
            v: down,
            width,
            height,
        }];
    }
    let c = std::f64::consts::FRAC_1_SQRT_2;
    vec![
        Plane {
            origin: [-width * c, -height / 2.0, -width * c],
            u: [c, 0.0, c],
            v: down,
            width,
            height,
        },
        Plane {
            origin: [0.0, -height / 2.0, 0.0],
            u: [c, 0.0, -c],
            v: down,
            width,
            height,
        },
    ]
}

/// The rotation (world to camera) of a camera at `centre` looking at `target`, y down, rolled by
/// `roll` degrees about its axis.
fn look_at(centre: Vec3, target: Vec3, roll: f64) -> Mat3 {
    let forward = sub(target, centre);
    let z = scale(forward, 1.0 / norm(forward));
    let x = cross([0.0, 1.0, 0.0], z);
    let x = scale(x, 1.0 / norm(x));
    let y = cross(z, x);
    mul(&axis_angle([0.0, 0.0, 1.0], roll), &[x, y, z])
}

/// The distance at which a camera facing `target` straight on sees every corner of the planes
/// within the middle 90 % of its image.
fn framing_distance(planes: &[Plane], target: Vec3, k: Mat3, width: u32, height: u32) -> f64 {
    let corners: Vec<Vec3> = planes
        .iter()
        .flat_map(|p| {
            [
                [0.0, 0.0],
                [p.width, 0.0],
                [0.0, p.height],
                [p.width, p.height],
            ]
            .map(|ab| p.point(ab))
        })
        .collect();
    let mut distance = 1.0;
    loop {
        let centre = add(target, [0.0, 0.0, -distance]);
        let r = look_at(centre, target, 0.0);
        let camera = TrueCamera {
            name: String::new(),
            width,
            height,
            k,
            r,
            t: scale(apply(&r, centre), -1.0),
        };
        let fits = corners.iter().all(|&c| {
            camera.project(c).is_some_and(|[u, v]| {
                (0.05..=0.95).contains(&(u / f64::from(width)))
                    && (0.05..=0.95).contains(&(v / f64::from(height)))
            })
        });
        if fits || distance > 1e4 {
            return distance;
        }
        distance *= 1.02;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cameras_look_at_their_target_and_frame_the_planes() {
        let planes = scene_planes(true, 10.0, 6.0);
        let target = [0.0, 0.0, -3.0];
        let k = [[900.0, 0.0, 500.0], [0.0, 900.0, 300.0], [0.0, 0.0, 1.0]];
        let d = framing_distance(&planes, target, k, 1000, 600);
        let centre = add(target, [0.0, 0.0, -d]);
        let r = look_at(centre, target, 0.0);
        let camera = TrueCamera {
            name: String::new(),
            width: 1000,
            height: 600,
            k,
            r,
            t: scale(apply(&r, centre), -1.0),
        };
        let [u, v] = camera.project(target).unwrap();
        assert!((u - 500.0).abs() < 1e-9 && (v - 300.0).abs() < 1e-9);
        for p in &planes {
            let [u, v] = camera.project(p.point([p.width, p.height])).unwrap();
            assert!((0.0..1000.0).contains(&u) && (0.0..600.0).contains(&v));
        }
        assert_eq!(parse_crop("1,2,30,40"), Ok((1, 2, 30, 40)));
        assert!(parse_crop("1,2,3").is_err());
    }
}

//! `clatch-eval geometry`: how true the verified matches of a COLMAP database are, and how far the
//! cameras of its model are from the truth.
//!
//! Per verified pair (`two_view_geometries`, whoever wrote it) and pooled over all pairs:
//! - inliers, and the share of them within 1, 2 and 4 px of the true epipolar lines. The distance
//!   of a match is its **symmetric epipolar distance**, here the larger of its two point-to-line
//!   distances (`x2` to `F x1` and `x1` to `Fᵀ x2`, pixels, F from the true cameras);
//! - on generated scenes, whose surfaces are known, the share within 1, 2 and 4 px of the **true
//!   correspondence** (transfer error: the point of image 1 cast onto the scene's planes and
//!   projected into image 2, and the other way round, the larger of the two). On repeated structure
//!   this is the stricter test: a match one period off along the epipolar line passes the epipolar
//!   test but not this one.
//!
//! With `--model`, the model's registered images, 3-D points, the relative rotation error of every
//! pair of images (no alignment needed), and camera centre and rotation errors after a least-squares
//! similarity alignment of the centres.

pub mod linalg;
pub mod truth;

mod database;
mod model;

use std::path::{Path, PathBuf};

use clap::Parser;
use serde::Serialize;

use crate::error::{EvalError, IoContext};
use crate::geometry::database::{DatabaseContents, read_database};
use crate::geometry::linalg::{Mat3, apply, transpose};
use crate::geometry::model::{PoseErrors, compare_model};
use crate::geometry::truth::{Truth, fundamental};

/// Thresholds of the reported shares, pixels.
pub const THRESHOLDS_PX: [f64; 3] = [1.0, 2.0, 4.0];

/// Verified matches and camera poses of a COLMAP database against a scene's ground truth.
#[derive(Debug, Parser)]
#[command(name = "clatch-eval geometry")]
pub struct GeometryArgs {
    /// The scene: a folder with scene.json (`clatch-eval facade`) or gt_dense_cameras/ (Strecha).
    #[arg(long, value_name = "DIR")]
    pub scene: PathBuf,
    /// The COLMAP 3.8 database whose two_view_geometries are evaluated.
    #[arg(long, value_name = "FILE")]
    pub database: PathBuf,
    /// A COLMAP model of the same images (sparse/N), for the camera errors.
    #[arg(long, value_name = "DIR")]
    pub model: Option<PathBuf>,
    /// The COLMAP executable, for reading the model.
    #[arg(long, default_value = "colmap", value_name = "PROGRAM")]
    pub colmap: PathBuf,
    /// Also write the figures as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Print every pair, not only the pooled figures.
    #[arg(long)]
    pub pairs: bool,
}

/// The figures of one pair or of all pairs pooled.
#[derive(Clone, Debug, Default, Serialize)]
pub struct MatchFigures {
    pub label: String,
    pub config: Option<i64>,
    pub inliers: usize,
    /// Inliers within each of [`THRESHOLDS_PX`] of the true epipolar lines.
    pub epipolar_within: [usize; 3],
    pub epipolar_median_px: f64,
    /// Inliers whose two points both lie on the scene's known surfaces.
    pub on_surface: usize,
    /// Of those, within each threshold of the true correspondence.
    pub transfer_within: [usize; 3],
}

impl MatchFigures {
    fn share(count: usize, of: usize) -> String {
        if of == 0 {
            "–".into()
        } else {
            format!("{:.1} %", 100.0 * count as f64 / of as f64)
        }
    }

    fn row(&self, with_surface: bool) -> String {
        let mut row = format!(
            "| {} | {} | {} | {} | {} | {} | {:.2} |",
            self.label,
            self.config.map_or("".into(), |c| c.to_string()),
            self.inliers,
            Self::share(self.epipolar_within[0], self.inliers),
            Self::share(self.epipolar_within[1], self.inliers),
            Self::share(self.epipolar_within[2], self.inliers),
            self.epipolar_median_px
        );
        if with_surface {
            row += &format!(
                " {} | {} | {} | {} |",
                self.on_surface,
                Self::share(self.transfer_within[0], self.on_surface),
                Self::share(self.transfer_within[1], self.on_surface),
                Self::share(self.transfer_within[2], self.on_surface)
            );
        }
        row
    }
}

/// Everything `geometry` reports.
#[derive(Debug, Serialize)]
pub struct GeometryReport {
    pub scene: String,
    pub database: String,
    pub distance: &'static str,
    pub pairs: Vec<MatchFigures>,
    pub pooled: MatchFigures,
    pub pairs_without_truth: usize,
    pub model: Option<PoseErrors>,
}

/// Runs `clatch-eval geometry`.
pub fn run(args: &GeometryArgs) -> Result<(), EvalError> {
    let truth = Truth::read(&args.scene)?;
    let contents = read_database(&args.database)?;
    let mut report = evaluate(&truth, &contents, &args.database)?;
    report.scene = args.scene.display().to_string();
    report.database = args.database.display().to_string();
    if let Some(model) = &args.model {
        report.model = Some(compare_model(&args.colmap, model, &truth)?);
    }
    print!("{}", render(&report, args.pairs, !truth.planes.is_empty()));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report).map_err(|e| EvalError::Input {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        std::fs::write(path, text).writing(path)?;
    }
    Ok(())
}

/// The larger of the two point-to-epipolar-line distances of a match.
pub fn symmetric_epipolar_distance(f: &Mat3, x1: [f64; 2], x2: [f64; 2]) -> f64 {
    let (p1, p2) = ([x1[0], x1[1], 1.0], [x2[0], x2[1], 1.0]);
    let line2 = apply(f, p1);
    let line1 = apply(&transpose(f), p2);
    let distance = |l: [f64; 3], p: [f64; 3]| {
        (l[0] * p[0] + l[1] * p[1] + l[2]).abs() / (l[0] * l[0] + l[1] * l[1]).sqrt()
    };
    distance(line2, p2).max(distance(line1, p1))
}

fn evaluate(
    truth: &Truth,
    contents: &DatabaseContents,
    database: &Path,
) -> Result<GeometryReport, EvalError> {
    let mut pairs = Vec::new();
    let mut pooled = MatchFigures {
        label: "all pairs".into(),
        ..Default::default()
    };
    let mut all_distances = Vec::new();
    let mut without_truth = 0;
    for pair in &contents.pairs {
        let names = (
            contents.images.get(&pair.image_id1),
            contents.images.get(&pair.image_id2),
        );
        let (Some(name1), Some(name2)) = names else {
            return Err(EvalError::Input {
                path: database.to_path_buf(),
                reason: format!(
                    "pair ({}, {}) names an image that is not in images",
                    pair.image_id1, pair.image_id2
                ),
            });
        };
        let cameras = (truth.camera(name1), truth.camera(name2));
        let (Some(camera1), Some(camera2)) = cameras else {
            without_truth += 1;
            continue;
        };
        let (Some(k1), Some(k2)) = (
            contents.keypoints.get(&pair.image_id1),
            contents.keypoints.get(&pair.image_id2),
        ) else {
            return Err(EvalError::Input {
                path: database.to_path_buf(),
                reason: format!("pair {name1} {name2}: keypoints missing"),
            });
        };
        let Some(f) = fundamental(camera1, camera2) else {
            without_truth += 1;
            continue;
        };
        let mut figures = MatchFigures {
            label: format!("{name1} {name2}"),
            config: Some(pair.config),
            inliers: pair.inliers.len(),
            ..Default::default()
        };
        let mut distances = Vec::new();
        for &[i, j] in &pair.inliers {
            let (Some(&x1), Some(&x2)) = (k1.get(i as usize), k2.get(j as usize)) else {
                return Err(EvalError::Input {
                    path: database.to_path_buf(),
                    reason: format!("pair {name1} {name2}: inlier ({i}, {j}) is not a keypoint"),
                });
            };
            let d = symmetric_epipolar_distance(&f, x1, x2);
            distances.push(d);
            for (count, threshold) in figures.epipolar_within.iter_mut().zip(THRESHOLDS_PX) {
                *count += usize::from(d <= threshold);
            }
            if let Some(e) = transfer_error(truth, (camera1, x1), (camera2, x2)) {
                figures.on_surface += 1;
                for (count, threshold) in figures.transfer_within.iter_mut().zip(THRESHOLDS_PX) {
                    *count += usize::from(e <= threshold);
                }
            }
        }
        figures.epipolar_median_px = median(&mut distances.clone());
        all_distances.extend(distances);
        pooled.inliers += figures.inliers;
        pooled.on_surface += figures.on_surface;
        for k in 0..3 {
            pooled.epipolar_within[k] += figures.epipolar_within[k];
            pooled.transfer_within[k] += figures.transfer_within[k];
        }
        pairs.push(figures);
    }
    pooled.epipolar_median_px = median(&mut all_distances);
    Ok(GeometryReport {
        scene: String::new(),
        database: String::new(),
        distance: "symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px",
        pairs,
        pooled,
        pairs_without_truth: without_truth,
        model: None,
    })
}

/// The larger of the two transfer errors of a match through the scene's surfaces; `None` when the
/// scene has no known surface at either point.
fn transfer_error(
    truth: &Truth,
    (camera1, x1): (&truth::TrueCamera, [f64; 2]),
    (camera2, x2): (&truth::TrueCamera, [f64; 2]),
) -> Option<f64> {
    if truth.planes.is_empty() {
        return None;
    }
    let one_way = |from: &truth::TrueCamera, x: [f64; 2], to: &truth::TrueCamera, y: [f64; 2]| {
        let point = truth.surface_point(from, x)?;
        let seen = to.project(point)?;
        Some(((seen[0] - y[0]).powi(2) + (seen[1] - y[1]).powi(2)).sqrt())
    };
    Some(one_way(camera1, x1, camera2, x2)?.max(one_way(camera2, x2, camera1, x1)?))
}

fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn render(report: &GeometryReport, every_pair: bool, with_surface: bool) -> String {
    let mut text = format!("scene {}, database {}\n", report.scene, report.database);
    text += &format!("distance: {}\n\n", report.distance);
    text += "| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px |";
    if with_surface {
        text += " on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |";
    }
    text += "\n|---|---|---|---|---|---|---|";
    if with_surface {
        text += "---|---|---|---|";
    }
    text += "\n";
    if every_pair {
        for pair in &report.pairs {
            text += &pair.row(with_surface);
            text += "\n";
        }
    }
    text += &report.pooled.row(with_surface);
    text += "\n";
    if report.pairs_without_truth > 0 {
        text += &format!(
            "({} pairs without ground truth left out)\n",
            report.pairs_without_truth
        );
    }
    if let Some(model) = &report.model {
        let (centre_mean, centre_max) = model.centre_mean_max();
        let (rotation_mean, rotation_max) = model.rotation_mean_max();
        let (relative_mean, relative_max) = model.relative_rotation_mean_max();
        text += &format!(
            "\nmodel: {}/{} images registered, {} points\n\
             relative rotation error (every pair of images, no alignment): mean {:.3}° max {:.3}°\n\
             after a similarity alignment of the camera centres: centre error mean {:.4} max {:.4} \
             (scene units), rotation error mean {:.3}° max {:.3}°\n",
            model.registered,
            model.images,
            model.points,
            relative_mean,
            relative_max,
            centre_mean,
            centre_max,
            rotation_mean,
            rotation_max
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::linalg::{add, axis_angle, scale};
    use crate::geometry::truth::{Plane, TrueCamera};
    use clap::CommandFactory;

    fn camera(name: &str, yaw: f64, centre: [f64; 3]) -> TrueCamera {
        let r = axis_angle([0.0, 1.0, 0.0], yaw);
        TrueCamera {
            name: name.into(),
            width: 800,
            height: 600,
            k: [[700.0, 0.0, 400.0], [0.0, 710.0, 300.0], [0.0, 0.0, 1.0]],
            r,
            t: scale(apply(&r, centre), -1.0),
        }
    }

    #[test]
    fn true_projections_are_on_the_true_epipolar_lines_and_transfer() {
        let a = camera("a", 0.0, [0.0, 0.0, -10.0]);
        let b = camera("b", -15.0, [3.0, 0.5, -9.5]);
        let plane = Plane {
            origin: [-4.0, -3.0, 0.0],
            u: [1.0, 0.0, 0.0],
            v: [0.0, 1.0, 0.0],
            width: 8.0,
            height: 6.0,
        };
        let truth = Truth {
            description: String::new(),
            cameras: vec![a.clone(), b.clone()],
            planes: vec![plane.clone()],
        };
        let f = fundamental(&a, &b).unwrap();
        for ab in [[1.0, 1.0], [4.0, 3.0], [7.5, 5.0]] {
            let x = plane.point(ab);
            let (xa, xb) = (a.project(x).unwrap(), b.project(x).unwrap());
            assert!(symmetric_epipolar_distance(&f, xa, xb) < 1e-9);
            assert!(transfer_error(&truth, (&a, xa), (&b, xb)).unwrap() < 1e-6);
            // One pixel across the epipolar line is one pixel off in image b.
            let line = apply(&f, [xa[0], xa[1], 1.0]);
            let n = (line[0] * line[0] + line[1] * line[1]).sqrt();
            let off = [xb[0] + line[0] / n, xb[1] + line[1] / n];
            let d = symmetric_epipolar_distance(&f, xa, off);
            assert!(d >= 1.0 - 1e-9, "{d}");
            // A point off the plane is not on the surface seen there.
            let behind = add(x, [0.0, 0.0, 2.0]);
            let (ya, yb) = (a.project(behind).unwrap(), b.project(behind).unwrap());
            assert!(transfer_error(&truth, (&a, ya), (&b, yb)).unwrap() > 1.0);
        }
    }

    #[test]
    fn the_command_line_is_consistent() {
        GeometryArgs::command().debug_assert();
        crate::facade::FacadeArgs::command().debug_assert();
    }
}

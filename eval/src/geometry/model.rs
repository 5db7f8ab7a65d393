//! A COLMAP model's camera poses against the truth: the model is converted to text by
//! `colmap model_converter`, its camera centres aligned to the true ones by the least-squares
//! similarity ([`similarity`]), and each camera's centre and rotation compared after it.

use std::path::Path;
use std::process::Command;

use crate::error::{EvalError, IoContext};
use crate::geometry::linalg::{
    Mat3, Vec3, apply, mul, norm, quaternion_to_rotation, rotation_angle_degrees, scale,
    similarity, sub, transpose,
};
use crate::geometry::truth::Truth;

/// One registered image of a model.
struct ModelImage {
    name: String,
    /// World to camera.
    r: Mat3,
    t: Vec3,
}

/// A model against the truth.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PoseErrors {
    pub registered: usize,
    pub images: usize,
    pub points: usize,
    /// Per registered image with a true camera: name, centre error (truth's units), rotation error
    /// (degrees), after the alignment.
    pub per_image: Vec<(String, f64, f64)>,
    /// Per pair of registered images: the angle between the model's relative rotation and the
    /// truth's, degrees. Needs no alignment, so it also holds where the centres fix the alignment
    /// poorly (cameras nearly on a line, as on an arc of a few tens of degrees).
    pub relative_rotation_errors: Vec<f64>,
}

impl PoseErrors {
    pub fn centre_mean_max(&self) -> (f64, f64) {
        mean_max(self.per_image.iter().map(|e| e.1))
    }
    pub fn rotation_mean_max(&self) -> (f64, f64) {
        mean_max(self.per_image.iter().map(|e| e.2))
    }
    pub fn relative_rotation_mean_max(&self) -> (f64, f64) {
        mean_max(self.relative_rotation_errors.iter().copied())
    }
}

fn mean_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = values.collect();
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    (
        v.iter().sum::<f64>() / v.len() as f64,
        v.iter().copied().fold(0.0, f64::max),
    )
}

/// Reads the model at `model` (a `sparse/N` folder, binary or text) with `colmap` and compares it.
pub fn compare_model(colmap: &Path, model: &Path, truth: &Truth) -> Result<PoseErrors, EvalError> {
    let text_dir = std::env::temp_dir().join(format!("clatch-eval-model-{}", std::process::id()));
    std::fs::create_dir_all(&text_dir).writing(&text_dir)?;
    let output = Command::new(colmap)
        .args(["model_converter", "--output_type", "TXT", "--input_path"])
        .arg(model)
        .arg("--output_path")
        .arg(&text_dir)
        .output()
        .map_err(|e| EvalError::Script {
            command: format!("{} model_converter", colmap.display()),
            reason: e.to_string(),
        })?;
    if !output.status.success() {
        return Err(EvalError::Script {
            command: format!("{} model_converter {}", colmap.display(), model.display()),
            reason: String::from_utf8_lossy(&output.stderr)
                .lines()
                .last()
                .unwrap_or("failed")
                .into(),
        });
    }
    let images_path = text_dir.join("images.txt");
    let images_text = std::fs::read_to_string(&images_path).reading(&images_path)?;
    let points_path = text_dir.join("points3D.txt");
    let points_text = std::fs::read_to_string(&points_path).reading(&points_path)?;
    std::fs::remove_dir_all(&text_dir).ok();
    let images = parse_images(&images_text, &images_path)?;
    let points = points_text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .count();
    Ok(compare(&images, points, truth))
}

/// `images.txt`: after comments, two lines per image, the first
/// `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`.
fn parse_images(text: &str, path: &Path) -> Result<Vec<ModelImage>, EvalError> {
    let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    let mut images = Vec::new();
    for line in lines.iter().step_by(2) {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() < 10 {
            continue;
        }
        let numbers = fields[1..8]
            .iter()
            .map(|s| s.parse::<f64>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| EvalError::Input {
                path: path.to_path_buf(),
                reason: format!("{line:?}: {e}"),
            })?;
        images.push(ModelImage {
            name: fields[9..].join(" "),
            r: quaternion_to_rotation([numbers[0], numbers[1], numbers[2], numbers[3]]),
            t: [numbers[4], numbers[5], numbers[6]],
        });
    }
    Ok(images)
}

fn centre(r: &Mat3, t: Vec3) -> Vec3 {
    scale(apply(&transpose(r), t), -1.0)
}

fn compare(images: &[ModelImage], points: usize, truth: &Truth) -> PoseErrors {
    let matched: Vec<(&ModelImage, &crate::geometry::truth::TrueCamera)> = images
        .iter()
        .filter_map(|i| truth.camera(&i.name).map(|c| (i, c)))
        .collect();
    let estimated: Vec<Vec3> = matched.iter().map(|(i, _)| centre(&i.r, i.t)).collect();
    let true_centres: Vec<Vec3> = matched.iter().map(|(_, c)| c.centre()).collect();
    let per_image = match similarity(&estimated, &true_centres) {
        Some((s, r_align, t_align)) => matched
            .iter()
            .zip(&estimated)
            .map(|((image, camera), c)| {
                let aligned = crate::geometry::linalg::add(scale(apply(&r_align, *c), s), t_align);
                // A world point maps as X_true = s R_align X_est + t: the camera's rotation in the
                // true world is R_est R_alignᵀ.
                let rotation = mul(&image.r, &transpose(&r_align));
                let error = rotation_angle_degrees(&mul(&rotation, &transpose(&camera.r)));
                (
                    image.name.clone(),
                    norm(sub(aligned, camera.centre())),
                    error,
                )
            })
            .collect(),
        None => Vec::new(),
    };
    let mut relative_rotation_errors = Vec::new();
    for (i, (image_a, camera_a)) in matched.iter().enumerate() {
        for (image_b, camera_b) in &matched[i + 1..] {
            let estimated = mul(&image_b.r, &transpose(&image_a.r));
            let true_relative = mul(&camera_b.r, &transpose(&camera_a.r));
            let error = mul(&estimated, &transpose(&true_relative));
            relative_rotation_errors.push(rotation_angle_degrees(&error));
        }
    }
    PoseErrors {
        relative_rotation_errors,
        registered: images.len(),
        images: truth.cameras.len(),
        points,
        per_image,
    }
}

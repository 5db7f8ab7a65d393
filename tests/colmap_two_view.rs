//! `Database::add_two_view_geometry` against COLMAP 3.8 itself, on a synthetic scene: random 3-D
//! points seen by four cameras of known pose, their exact projections as keypoints.
//!
//! - `colmap mapper` straight on a database whose `matches` and `two_view_geometries` we wrote (no
//!   `matches_importer`, as the folder run writes it) registers every image, with the poses of the
//!   truth;
//! - the `matches` rows we write equal those `matches_importer --match_type raw` writes for the same
//!   putative matches, both image orders and a pair without matches;
//! - the rows we write for matches taken as verified equal the rows `matches_importer --match_type
//!   inliers` writes for the same matches, both image orders;
//! - the geometry COLMAP estimates (`--match_type raw`) reads back through our layout as the true
//!   geometry (F and E row-major, from the smaller image id's image), and written again through our
//!   writer gives COLMAP's bytes (turned round: its values).
//!
//! Without a `colmap` program on PATH (or at `CLATCH_COLMAP`) every test is reported as ignored with
//! `skipped: colmap not installed`, never as passed.

use std::path::{Path, PathBuf};
use std::process::Command;

use clatch::colmap::two_view::{f64s_of_blob, matrix_of_blob, quaternion_rotation};
use clatch::colmap::{Database, Matrix3, PinholeCamera, RelativePose, TwoViewGeometry};
use clatch::synthetic::SplitMix64;
use clatch::verify::GeometryConfig;
use clatch::{KeyPoint, Match};
use libtest_mimic::{Arguments, Failed, Trial};
use rusqlite::Connection;

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;
/// K in COLMAP's pixel coordinates (first pixel centre at 0.5, 0.5).
const FOCAL: f64 = 700.0;
const CX: f64 = 320.0;
const CY: f64 = 240.0;
const CAMERAS: usize = 4;
const POINTS: usize = 400;

fn main() {
    let args = Arguments::from_args();
    let mut trials = vec![
        Trial::test(
            "colmap_mapper_registers_images_from_written_geometries",
            mapper_registers_images,
        ),
        Trial::test(
            "colmap_inliers_import_writes_our_rows",
            inliers_import_writes_our_rows,
        ),
        Trial::test(
            "colmap_estimated_geometry_reads_as_truth_and_writes_back",
            estimated_geometry_round_trip,
        ),
        Trial::test(
            "colmap_failed_pair_is_stored_as_colmap_stores_it",
            failed_pair_as_colmap,
        ),
        Trial::test(
            "colmap_matches_table_is_written_as_colmap_writes_it",
            matches_table_as_colmap,
        ),
    ];
    if let Err(reason) = colmap_version() {
        println!("skipped: colmap not installed ({reason})");
        trials = trials
            .into_iter()
            .map(|t| t.with_ignored_flag(true))
            .collect();
    }
    libtest_mimic::run(&args, trials).exit()
}

fn colmap_program() -> PathBuf {
    std::env::var_os("CLATCH_COLMAP").map_or_else(|| "colmap".into(), PathBuf::from)
}

fn colmap_version() -> Result<(), String> {
    Command::new(colmap_program())
        .arg("help")
        .output()
        .map(|_| ())
        .map_err(|e| format!("cannot run {}: {e}", colmap_program().display()))
}

fn colmap(args: &[&str]) -> Result<String, Failed> {
    let output = Command::new(colmap_program())
        .args(args)
        .output()
        .map_err(|e| format!("colmap {args:?}: {e}"))?;
    let text = String::from_utf8_lossy(&output.stdout).into_owned()
        + &String::from_utf8_lossy(&output.stderr);
    if !output.status.success() {
        return Err(format!("colmap {args:?} failed ({}):\n{text}", output.status).into());
    }
    Ok(text)
}

/// `colmap matches_importer` of a match list (`raw`: COLMAP verifies; `inliers`: taken as verified).
fn import_matches(database: &Path, list: &Path, match_type: &str) -> Result<String, Failed> {
    colmap(&[
        "matches_importer",
        "--database_path",
        s(database),
        "--match_list_path",
        s(list),
        "--match_type",
        match_type,
        "--SiftMatching.use_gpu",
        "0",
    ])
}

/// A fresh folder for one test.
fn workspace(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("clatch-two-view-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(dir.join("images")).unwrap();
    dir
}

/// The scene: camera poses (world to camera: `X_cam = R X + t`) and the points' projections.
struct Scene {
    rotations: Vec<Matrix3>,
    translations: Vec<[f64; 3]>,
    /// `projections[camera][point]`, COLMAP pixel coordinates.
    projections: Vec<Vec<[f64; 2]>>,
}

fn rotation_y(degrees: f64) -> Matrix3 {
    let (s, c) = degrees.to_radians().sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}

fn apply(r: &Matrix3, x: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| r[i][0] * x[0] + r[i][1] * x[1] + r[i][2] * x[2])
}

fn multiply(a: &Matrix3, b: &Matrix3) -> Matrix3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

fn transpose(m: &Matrix3) -> Matrix3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[c][r]))
}

fn skew([x, y, z]: [f64; 3]) -> Matrix3 {
    [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]
}

/// Points in a 4 × 3 × 2 box about (0, 0, 6), cameras on an arc 6 units from it turned 8° apart.
fn scene() -> Scene {
    let mut rng = SplitMix64::new(0x7ee0_2026);
    let mut uniform =
        |lo: f64, hi: f64| lo + (hi - lo) * (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
    let points: Vec<[f64; 3]> = (0..POINTS)
        .map(|_| [uniform(-2.0, 2.0), uniform(-1.5, 1.5), uniform(5.0, 7.0)])
        .collect();
    let centre = [0.0, 0.0, 6.0];
    let (mut rotations, mut translations, mut projections) = (vec![], vec![], vec![]);
    for i in 0..CAMERAS {
        let angle = -12.0 + 8.0 * i as f64;
        // The camera looks at the centre from 6 units away: camera to world is rotation_y(angle).
        let r = transpose(&rotation_y(angle));
        let position = {
            let (s, c) = angle.to_radians().sin_cos();
            [centre[0] - 6.0 * s, centre[1], centre[2] - 6.0 * c]
        };
        let t = apply(&r, position).map(|v| -v);
        let projected = points
            .iter()
            .map(|&p| {
                let x = apply(&r, p);
                let x = [x[0] + t[0], x[1] + t[1], x[2] + t[2]];
                [FOCAL * x[0] / x[2] + CX, FOCAL * x[1] / x[2] + CY]
            })
            .collect::<Vec<_>>();
        assert!(
            projected.iter().all(|p| p[0] > 1.0
                && p[0] < f64::from(WIDTH) - 1.0
                && p[1] > 1.0
                && p[1] < f64::from(HEIGHT) - 1.0),
            "every point must be seen by camera {i}"
        );
        rotations.push(r);
        translations.push(t);
        projections.push(projected);
    }
    Scene {
        rotations,
        translations,
        projections,
    }
}

impl Scene {
    /// Camera `b` from camera `a`.
    fn relative(&self, a: usize, b: usize) -> (Matrix3, [f64; 3]) {
        let r = multiply(&self.rotations[b], &transpose(&self.rotations[a]));
        let ra_t = apply(&r, self.translations[a]);
        let t = [0, 1, 2].map(|i| self.translations[b][i] - ra_t[i]);
        (r, t)
    }

    /// E, F (COLMAP pixels) and the pose of camera `b` from camera `a`, t of unit length.
    fn geometry(&self, a: usize, b: usize) -> (Matrix3, Matrix3, RelativePose) {
        let (r, t) = self.relative(a, b);
        let norm = t.iter().map(|v| v * v).sum::<f64>().sqrt();
        let t = t.map(|v| v / norm);
        let e = multiply(&skew(t), &r);
        let k_inv = [
            [1.0 / FOCAL, 0.0, -CX / FOCAL],
            [0.0, 1.0 / FOCAL, -CY / FOCAL],
            [0.0, 0.0, 1.0],
        ];
        let f = multiply(&transpose(&k_inv), &multiply(&e, &k_inv));
        (
            e,
            f,
            RelativePose {
                qvec: quaternion(&r),
                tvec: t,
            },
        )
    }
}

/// The unit quaternion (w, x, y, z) of a rotation, w ≥ 0 (rotations here are small).
fn quaternion(r: &Matrix3) -> [f64; 4] {
    let w = (1.0 + r[0][0] + r[1][1] + r[2][2]).sqrt() / 2.0;
    [
        w,
        (r[2][1] - r[1][2]) / (4.0 * w),
        (r[0][2] - r[2][0]) / (4.0 * w),
        (r[1][0] - r[0][1]) / (4.0 * w),
    ]
}

fn image_name(i: usize) -> String {
    format!("view{i}.png")
}

/// A database with the scene's camera, images and keypoints (keypoint k of every image is point k),
/// and a gray image file per view (the mapper reads colours from them).
fn scene_database(dir: &Path, name: &str, scene: &Scene) -> (PathBuf, Database, Vec<u32>) {
    let path = dir.join(name);
    let mut db = Database::create(&path).unwrap();
    let camera = PinholeCamera {
        width: WIDTH,
        height: HEIGHT,
        fx: FOCAL,
        fy: FOCAL,
        cx: CX,
        cy: CY,
        focal_is_known: true,
    };
    let camera_id = db.add_camera(&camera).unwrap();
    let mut ids = vec![];
    for (i, projections) in scene.projections.iter().enumerate() {
        let id = db.add_image(&image_name(i), camera_id).unwrap();
        // The database adds COLMAP's half pixel: give clatch coordinates.
        let keypoints: Vec<KeyPoint> = projections
            .iter()
            .map(|p| KeyPoint::new(p[0] as f32 - 0.5, p[1] as f32 - 0.5))
            .collect();
        db.set_keypoints(id, &keypoints).unwrap();
        let image = dir.join("images").join(image_name(i));
        if !image.exists() {
            image::GrayImage::from_pixel(WIDTH, HEIGHT, image::Luma([128]))
                .save(&image)
                .unwrap();
        }
        ids.push(id);
    }
    (path, db, ids)
}

/// Pairs of views, some listed with the larger image id first.
fn pairs() -> Vec<(usize, usize)> {
    vec![(0, 1), (2, 0), (1, 2), (3, 1), (2, 3), (0, 3)]
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn mapper_registers_images() -> Result<(), Failed> {
    let dir = workspace("mapper");
    let scene = scene();
    // As a verifier would: the database written first (as `clatch colmap --no-colmap` does), opened
    // again for the geometries.
    let (path, db, ids) = scene_database(&dir, "written.db", &scene);
    db.finish()?;
    let mut db = Database::open_existing(&path)?;
    for (a, b) in pairs() {
        let (e, f, pose) = scene.geometry(a, b);
        // As the folder run writes a verified pair: its matches, then its geometry.
        let matches: Vec<Match> = putative(a, b)
            .into_iter()
            .map(|[query, train]| Match {
                query,
                train,
                distance: 0,
            })
            .collect();
        db.add_matches(ids[a], ids[b], &matches)?;
        db.add_two_view_geometry(&TwoViewGeometry {
            f: Some(f),
            e: Some(e),
            pose: Some(pose),
            ..TwoViewGeometry::new(
                ids[a],
                ids[b],
                (0..POINTS as u32).map(|k| [k, k]).collect(),
                GeometryConfig::Calibrated,
            )
        })?;
    }
    db.finish()?;
    let sparse = dir.join("sparse");
    std::fs::create_dir_all(&sparse)?;
    colmap(&[
        "mapper",
        "--database_path",
        s(&path),
        "--image_path",
        s(&dir.join("images")),
        "--output_path",
        s(&sparse),
        "--Mapper.ba_refine_focal_length",
        "0",
        "--Mapper.ba_refine_principal_point",
        "0",
        "--Mapper.ba_refine_extra_params",
        "0",
    ])?;
    let model = sparse.join("0");
    let text = dir.join("text");
    std::fs::create_dir_all(&text)?;
    colmap(&[
        "model_converter",
        "--input_path",
        s(&model),
        "--output_path",
        s(&text),
        "--output_type",
        "TXT",
    ])?;
    // images.txt: comment lines, then two lines per registered image (the pose, its points).
    let images = std::fs::read_to_string(text.join("images.txt"))?;
    let poses: Vec<Vec<&str>> = images
        .lines()
        .filter(|l| !l.starts_with('#'))
        .step_by(2)
        .map(|l| l.split_whitespace().collect())
        .filter(|f: &Vec<&str>| f.len() == 10)
        .collect();
    if poses.len() != CAMERAS {
        return Err(format!("{} of {CAMERAS} images registered:\n{images}", poses.len()).into());
    }
    // Every relative rotation as the truth's (within 0.05°).
    let rotation_of = |name: &str| -> Matrix3 {
        let f = poses.iter().find(|f| f[9] == name).expect("registered");
        let q: Vec<f64> = f[1..5].iter().map(|v| v.parse().unwrap()).collect();
        quaternion_rotation([q[0], q[1], q[2], q[3]])
    };
    for (a, b) in pairs() {
        let estimated = multiply(
            &rotation_of(&image_name(b)),
            &transpose(&rotation_of(&image_name(a))),
        );
        let (truth, _) = scene.relative(a, b);
        let error = rotation_angle_degrees(&multiply(&estimated, &transpose(&truth)));
        if error > 0.05 {
            return Err(format!("pair ({a}, {b}): relative rotation {error}° off").into());
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

fn rotation_angle_degrees(r: &Matrix3) -> f64 {
    ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// One `two_view_geometries` row.
#[derive(Debug, PartialEq)]
struct Row {
    rows: i64,
    cols: i64,
    data: Vec<u8>,
    config: i64,
    f: Vec<u8>,
    e: Vec<u8>,
    h: Vec<u8>,
    qvec: Vec<u8>,
    tvec: Vec<u8>,
}

fn read_rows(path: &Path) -> Vec<(i64, Row)> {
    let sql = Connection::open(path).unwrap();
    let mut statement = sql
        .prepare("SELECT pair_id, rows, cols, data, config, F, E, H, qvec, tvec FROM two_view_geometries ORDER BY pair_id")
        .unwrap();
    statement
        .query_map([], |r| {
            Ok((
                r.get(0)?,
                Row {
                    rows: r.get(1)?,
                    cols: r.get(2)?,
                    data: r.get::<_, Option<Vec<u8>>>(3)?.unwrap_or_default(),
                    config: r.get(4)?,
                    f: r.get::<_, Option<Vec<u8>>>(5)?.unwrap_or_default(),
                    e: r.get::<_, Option<Vec<u8>>>(6)?.unwrap_or_default(),
                    h: r.get::<_, Option<Vec<u8>>>(7)?.unwrap_or_default(),
                    qvec: r.get::<_, Option<Vec<u8>>>(8)?.unwrap_or_default(),
                    tvec: r.get::<_, Option<Vec<u8>>>(9)?.unwrap_or_default(),
                },
            ))
        })
        .unwrap()
        .map(Result::unwrap)
        .collect()
}

/// The match list of `pairs`, in their order (so COLMAP turns some round), with `matches(a, b)`.
fn write_match_list(path: &Path, matches: impl Fn(usize, usize) -> Vec<[u32; 2]>) {
    let mut text = String::new();
    for (a, b) in pairs() {
        text += &format!("{} {}\n", image_name(a), image_name(b));
        for [i, j] in matches(a, b) {
            text += &format!("{i} {j}\n");
        }
        text += "\n";
    }
    std::fs::write(path, text).unwrap();
}

/// Inliers of a pair: every third point, offset by the pair so that the pairs differ.
fn chosen_inliers(a: usize, b: usize) -> Vec<[u32; 2]> {
    (0..POINTS as u32)
        .filter(|k| (k + a as u32 + 2 * b as u32).is_multiple_of(3))
        .map(|k| [k, k])
        .collect()
}

fn inliers_import_writes_our_rows() -> Result<(), Failed> {
    let dir = workspace("inliers");
    let scene = scene();
    let (imported, db, _) = scene_database(&dir, "imported.db", &scene);
    db.finish()?;
    let list = dir.join("matches.txt");
    write_match_list(&list, chosen_inliers);
    import_matches(&imported, &list, "inliers")?;
    let (written, mut db, ids) = scene_database(&dir, "written.db", &scene);
    for (a, b) in pairs() {
        db.add_two_view_geometry(&TwoViewGeometry::new(
            ids[a],
            ids[b],
            chosen_inliers(a, b),
            GeometryConfig::Calibrated,
        ))?;
    }
    db.finish()?;
    let (theirs, ours) = (read_rows(&imported), read_rows(&written));
    if theirs.len() != pairs().len() || theirs.len() != ours.len() {
        return Err(format!("{} rows from COLMAP, {} of ours", theirs.len(), ours.len()).into());
    }
    for ((their_id, their), (our_id, our)) in theirs.iter().zip(&ours) {
        let (lo, hi) = clatch::colmap::image_ids_of_pair(*their_id as u64);
        let turned = pairs().iter().any(|&(a, b)| ids[a] == hi && ids[b] == lo);
        if their_id != our_id {
            return Err(format!("pair ids {their_id} and {our_id}").into());
        }
        // Identical bytes, except where COLMAP turns its default geometry round: its H becomes the
        // inverse of a zero matrix (NaN) and its zeros negative; ours stay zeros.
        let comparable = |row: &Row| Row {
            h: if turned { vec![] } else { row.h.clone() },
            f: canonical_zeros(&row.f),
            e: canonical_zeros(&row.e),
            qvec: canonical_zeros(&row.qvec),
            tvec: canonical_zeros(&row.tvec),
            data: row.data.clone(),
            ..*row
        };
        if turned {
            if !f64s_of_blob(&their.h).iter().all(|v| v.is_nan()) {
                return Err(format!("pair {their_id}: COLMAP's turned H is not NaN").into());
            }
        } else if their != our {
            return Err(
                format!("pair {their_id}: bytes differ\nCOLMAP {their:?}\nours   {our:?}").into(),
            );
        }
        if comparable(their) != comparable(our) {
            return Err(
                format!("pair {their_id}: rows differ\nCOLMAP {their:?}\nours   {our:?}").into(),
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

/// Where two tables of rows differ first: the pair and the column, both values.
fn first_difference(theirs: &[(i64, Row)], ours: &[(i64, Row)]) -> Option<String> {
    if theirs.len() != ours.len() {
        return Some(format!(
            "{} rows from COLMAP, {} of ours",
            theirs.len(),
            ours.len()
        ));
    }
    for ((pair, their), (our_pair, our)) in theirs.iter().zip(ours) {
        if pair != our_pair {
            return Some(format!("pair ids {pair} and {our_pair}"));
        }
        let counts = [
            (their.rows, our.rows),
            (their.cols, our.cols),
            (their.config, our.config),
        ];
        if counts.iter().any(|(a, b)| a != b) || their.data != our.data {
            return Some(format!(
                "pair {pair}: rows, cols, config or inliers differ: {counts:?}"
            ));
        }
        for (name, a, b) in [
            ("F", &their.f, &our.f),
            ("E", &their.e, &our.e),
            ("H", &their.h, &our.h),
            ("qvec", &their.qvec, &our.qvec),
            ("tvec", &their.tvec, &our.tvec),
        ] {
            if a != b {
                return Some(format!(
                    "pair {pair}: {name} differs: COLMAP {:?}, ours {:?}",
                    f64s_of_blob(a),
                    f64s_of_blob(b)
                ));
            }
        }
    }
    None
}

/// The blob with −0.0 written as 0.0.
fn canonical_zeros(blob: &[u8]) -> Vec<u8> {
    f64s_of_blob(blob)
        .iter()
        .flat_map(|v| if *v == 0.0 { 0.0f64 } else { *v }.to_le_bytes())
        .collect()
}

/// Putative matches: every point, and a wrong match for every fifth.
fn putative(a: usize, b: usize) -> Vec<[u32; 2]> {
    let mut matches: Vec<[u32; 2]> = (0..POINTS as u32).map(|k| [k, k]).collect();
    let shift = 37 + a as u32 + b as u32;
    matches.extend(
        (0..POINTS as u32)
            .step_by(5)
            .map(|k| [k, (k + shift) % POINTS as u32]),
    );
    matches
}

fn estimated_geometry_round_trip() -> Result<(), Failed> {
    let dir = workspace("raw");
    let scene = scene();
    let (verified, db, ids) = scene_database(&dir, "verified.db", &scene);
    db.finish()?;
    let list = dir.join("matches.txt");
    write_match_list(&list, putative);
    import_matches(&verified, &list, "raw")?;
    let theirs = read_rows(&verified);
    if theirs.len() != pairs().len() {
        return Err(format!(
            "COLMAP verified {} of {} pairs",
            theirs.len(),
            pairs().len()
        )
        .into());
    }
    let view_of = |id: u32| ids.iter().position(|&i| i == id).unwrap();
    let (written, mut db, _) = scene_database(&dir, "written.db", &scene);
    let (turned_path, mut turned_db, _) = scene_database(&dir, "turned.db", &scene);
    for (pair, row) in &theirs {
        let (lo, hi) = clatch::colmap::image_ids_of_pair(*pair as u64);
        let (a, b) = (view_of(lo), view_of(hi));
        let config = GeometryConfig::from_colmap_code(row.config).ok_or("unknown config")?;
        if config != GeometryConfig::Calibrated {
            return Err(format!("pair ({a}, {b}): config {config:?}").into());
        }
        let f = matrix_of_blob(&row.f).ok_or("F is not 3x3")?;
        // Row-major and from the smaller id's image: x_hi' F x_lo nearly vanishes on the true points
        // (COLMAP's RANSAC estimate is not exact: a median within 0.5 px), while the transposed
        // matrix misses them by pixels (at least five times as far).
        let median = sampson_median(&f, &scene.projections[a], &scene.projections[b]);
        let transposed = [0, 1, 2].map(|r| [0, 1, 2].map(|c| f[c][r]));
        let median_transposed =
            sampson_median(&transposed, &scene.projections[a], &scene.projections[b]);
        if median > 0.5 || median_transposed < (5.0 * median).max(1.0) {
            return Err(format!(
                "pair ({a}, {b}): F read row-major misses the points by {median} px (median), \
                 transposed by {median_transposed} px"
            )
            .into());
        }
        // E likewise, in normalised coordinates: K⁻ᵀ E K⁻¹ is an F of the points.
        let e = matrix_of_blob(&row.e).ok_or("E is not 3x3")?;
        let k_inv = [
            [1.0 / FOCAL, 0.0, -CX / FOCAL],
            [0.0, 1.0 / FOCAL, -CY / FOCAL],
            [0.0, 0.0, 1.0],
        ];
        let f_of_e = multiply(&transpose(&k_inv), &multiply(&e, &k_inv));
        let median_e = sampson_median(&f_of_e, &scene.projections[a], &scene.projections[b]);
        if median_e > 1.5 {
            return Err(format!("pair ({a}, {b}): E misses the points by {median_e} px").into());
        }
        // COLMAP 3.8 computes the relative pose only when asked (`compute_relative_pose`, off in
        // matches_importer): it stores zeros, which the writer also stores for an absent pose.
        let (q, t) = (f64s_of_blob(&row.qvec), f64s_of_blob(&row.tvec));
        if q != [0.0; 4] || t != [0.0; 3] {
            return Err(format!("pair ({a}, {b}): COLMAP stored a pose {q:?} {t:?}").into());
        }
        let u32s: Vec<u32> = row
            .data
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let geometry = TwoViewGeometry {
            f: Some(f),
            e: matrix_of_blob(&row.e),
            h: matrix_of_blob(&row.h),
            pose: None,
            ..TwoViewGeometry::new(
                lo,
                hi,
                u32s.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
                config,
            )
        };
        db.add_two_view_geometry(&geometry)?;
        turned_db.add_two_view_geometry(&geometry.inverted()?)?;
    }
    db.finish()?;
    turned_db.finish()?;
    // Written in COLMAP's order: COLMAP's bytes, but for the sign of zero: COLMAP turns its zero
    // pose round for a pair listed the other way, writing −0.0.
    let without_signed_zeros = |rows: Vec<(i64, Row)>| -> Vec<(i64, Row)> {
        rows.into_iter()
            .map(|(pair, row)| {
                let (qvec, tvec) = (canonical_zeros(&row.qvec), canonical_zeros(&row.tvec));
                (pair, Row { qvec, tvec, ..row })
            })
            .collect()
    };
    let ours = without_signed_zeros(read_rows(&written));
    let theirs = without_signed_zeros(theirs);
    if let Some(difference) = first_difference(&theirs, &ours) {
        return Err(difference.into());
    }
    // Written turned round: turned back on writing, the same values up to rounding.
    for ((pair, their), (turned_pair, turned)) in theirs.iter().zip(&read_rows(&turned_path)) {
        let same_inliers = (their.rows, their.cols, &their.data, their.config)
            == (turned.rows, turned.cols, &turned.data, turned.config);
        if pair != turned_pair || !same_inliers {
            return Err(format!("pair {pair}: turned row's inliers differ").into());
        }
        for (name, x, y) in [
            ("F", &their.f, &turned.f),
            ("E", &their.e, &turned.e),
            ("H", &their.h, &turned.h),
            ("qvec", &their.qvec, &turned.qvec),
            ("tvec", &their.tvec, &turned.tvec),
        ] {
            let (x, y) = (f64s_of_blob(x), f64s_of_blob(y));
            let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if x.len() != y.len()
                || x.iter()
                    .zip(&y)
                    .any(|(p, q)| (p - q).abs() > 1e-9 * scale.max(1.0))
            {
                return Err(format!("pair {pair}: turned {name} {y:?}, COLMAP's {x:?}").into());
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

/// A pair that fails verification (3 matches): COLMAP stores `rows` 0, `cols` 2, config 1 and NULL
/// blobs; so does the writer for a pair without inliers.
fn failed_pair_as_colmap() -> Result<(), Failed> {
    let dir = workspace("failed");
    let scene = scene();
    let (imported, db, ids) = scene_database(&dir, "imported.db", &scene);
    db.finish()?;
    let list = dir.join("matches.txt");
    std::fs::write(
        &list,
        format!("{} {}\n0 0\n1 1\n2 2\n\n", image_name(0), image_name(1)),
    )?;
    import_matches(&imported, &list, "raw")?;
    let (written, db, _) = scene_database(&dir, "written.db", &scene);
    db.finish()?;
    let mut db = Database::open_existing(&written)?;
    db.add_two_view_geometry(&TwoViewGeometry::new(
        ids[0],
        ids[1],
        vec![],
        GeometryConfig::Degenerate,
    ))?;
    db.finish()?;
    let describe = |path: &Path| -> Vec<String> {
        let sql = Connection::open(path).unwrap();
        let mut statement = sql
            .prepare(
                "SELECT pair_id, rows, cols, config, typeof(data), typeof(F), typeof(E), \
                 typeof(H), typeof(qvec), typeof(tvec) FROM two_view_geometries",
            )
            .unwrap();
        statement
            .query_map([], |r| {
                Ok((0..10)
                    .map(|i| r.get_ref(i).map(|v| format!("{v:?}")))
                    .collect::<Result<Vec<_>, _>>()?
                    .join(" "))
            })
            .unwrap()
            .map(Result::unwrap)
            .collect()
    };
    let (theirs, ours) = (describe(&imported), describe(&written));
    if theirs.len() != 1 || theirs != ours {
        return Err(format!("COLMAP {theirs:?}\nours   {ours:?}").into());
    }
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

/// The rows of a database's `matches`: pair id, rows, cols, the blob (`None`: NULL).
fn matches_rows(path: &Path) -> Vec<(i64, i64, i64, Option<Vec<u8>>)> {
    let sql = Connection::open(path).unwrap();
    let mut statement = sql
        .prepare("SELECT pair_id, rows, cols, data FROM matches ORDER BY pair_id")
        .unwrap();
    statement
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect()
}

/// COLMAP's `matches_importer` writes the putative matches of every listed pair into `matches`
/// (its own verification's table beside `two_view_geometries`): [`Database::add_matches`] of the
/// same pairs writes the same rows, byte for byte, pairs given with the larger image id first
/// turned round, a pair without matches included.
fn matches_table_as_colmap() -> Result<(), Failed> {
    let dir = workspace("matches");
    let scene = scene();
    let (imported, db, ids) = scene_database(&dir, "imported.db", &scene);
    db.finish()?;
    let list = dir.join("matches.txt");
    let empty = (2, 3);
    let listed = |a: usize, b: usize| {
        if (a, b) == empty {
            vec![]
        } else {
            putative(a, b)
        }
    };
    let mut text = String::new();
    for (a, b) in pairs() {
        text += &format!("{} {}\n", image_name(a), image_name(b));
        for [i, j] in listed(a, b) {
            text += &format!("{i} {j}\n");
        }
        text += "\n";
    }
    std::fs::write(&list, text)?;
    import_matches(&imported, &list, "raw")?;
    let (written, mut db, _) = scene_database(&dir, "written.db", &scene);
    for (a, b) in pairs() {
        let matches: Vec<Match> = listed(a, b)
            .into_iter()
            .map(|[query, train]| Match {
                query,
                train,
                distance: 0,
            })
            .collect();
        db.add_matches(ids[a], ids[b], &matches)?;
    }
    db.finish()?;
    let (theirs, ours) = (matches_rows(&imported), matches_rows(&written));
    if theirs.len() != pairs().len() {
        return Err(format!("COLMAP wrote {} rows of matches", theirs.len()).into());
    }
    for (t, o) in theirs.iter().zip(&ours) {
        if t != o {
            let head = |r: &(i64, i64, i64, Option<Vec<u8>>)| {
                format!(
                    "{} {} {} {:?}",
                    r.0,
                    r.1,
                    r.2,
                    r.3.as_ref().map(|d| &d[..d.len().min(16)])
                )
            };
            return Err(format!("COLMAP {}\nours   {}", head(t), head(o)).into());
        }
    }
    if theirs.len() != ours.len() {
        return Err(format!("{} rows, ours {}", theirs.len(), ours.len()).into());
    }
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

/// The median Sampson distance (pixels) of the true correspondences under `f`.
fn sampson_median(f: &Matrix3, x1: &[[f64; 2]], x2: &[[f64; 2]]) -> f64 {
    let mut distances: Vec<f64> = x1
        .iter()
        .zip(x2)
        .map(|(p, q)| {
            let p = [p[0], p[1], 1.0];
            let q = [q[0], q[1], 1.0];
            let fp = apply(f, p);
            let ftq = apply(&transpose(f), q);
            let e = q[0] * fp[0] + q[1] * fp[1] + fp[2];
            let denominator = fp[0] * fp[0] + fp[1] * fp[1] + ftq[0] * ftq[0] + ftq[1] * ftq[1];
            (e * e / denominator).sqrt()
        })
        .collect();
    distances.sort_by(f64::total_cmp);
    distances[distances.len() / 2]
}

//! The library's one COLMAP folder run, [`FolderJob`]: the same folder and job write the same bytes
//! every time; its stages run apart, as a cluster runs them (photos extracted and pairs matched in
//! any grouping and order), write those bytes too; every refusal comes before any work and leaves
//! nothing behind, and a run that fails keeps the old database.

use std::ops::{ControlFlow, Range};
use std::path::{Path, PathBuf};

use clatch::colmap::{
    ColmapError, FolderCamera, FolderJob, FolderOutput, FolderPlan, FolderProgress, FolderStage,
    Overwrite, PhotoRef, PinholeCamera, extract_photos, match_photo_pairs,
};
use clatch::{Backend, DescriptorSet, Extractor, Matcher};

const PHOTOS: usize = 4;
const PAIRS: usize = PHOTOS * (PHOTOS - 1) / 2;

/// A fresh folder for one test, with `images/` holding [`PHOTOS`] overlapping crops of one generated
/// picture as binary PGM files.
fn workdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "clatch-colmap-folder-{}-{name}",
        std::process::id()
    ));
    std::fs::remove_dir_all(&dir).ok();
    let images = dir.join("images");
    std::fs::create_dir_all(&images).unwrap();
    let (width, height) = (480, 400);
    let picture = clatch::synthetic::rectangles(width, height, 7).unwrap();
    let (side_x, side_y) = (320, 300);
    for i in 0..PHOTOS {
        let (x0, y0) = (i * 40, i * 25);
        let mut pgm = format!("P5\n{side_x} {side_y}\n255\n").into_bytes();
        for y in y0..y0 + side_y {
            pgm.extend_from_slice(&picture[y * width + x0..y * width + x0 + side_x]);
        }
        std::fs::write(images.join(format!("view{i}.pgm")), pgm).unwrap();
    }
    dir
}

/// Every file and folder under `dir`, with the files' bytes, in order.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Option<Vec<u8>>)> {
    let mut entries = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path.clone());
                entries.push((path, None));
            } else {
                let bytes = std::fs::read(&path).unwrap();
                entries.push((path, Some(bytes)));
            }
        }
    }
    entries.sort();
    entries
}

fn names_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Extracts the plan's photos group by group, as workers would, and adds them to `output` in the
/// folder's order, with their descriptors (`described`, which guided matching needs) or without;
/// returns every photo's descriptors.
fn extract_in_groups<const N: usize>(
    job: &FolderJob,
    plan: &FolderPlan,
    output: &mut FolderOutput,
    groups: [Range<usize>; N],
    described: bool,
) -> Vec<DescriptorSet> {
    let extractor = Extractor::new(job.backend, job.extractor_config()).unwrap();
    let folder = plan.folder();
    let mut descriptors = Vec::new();
    for group in groups {
        let (photos, _) = extract_photos(
            &extractor,
            (&folder.paths[group.clone()], &folder.names[group]),
            &job.limits,
            job.refinement,
            &|_| {},
        )
        .unwrap();
        for (photo, set) in photos {
            if described {
                output.add_described_photo(&photo, &set).unwrap();
            } else {
                output.add_photo(&photo).unwrap();
            }
            descriptors.push(set);
        }
    }
    descriptors
}

#[test]
fn a_folder_written_twice_gives_identical_bytes() {
    let dir = workdir("twice");
    let run = |db: &str| {
        FolderJob::new(dir.join("images"), dir.join(db))
            .with_match_list_written(true)
            .run(None)
            .unwrap()
    };
    let (one, two) = (run("one.db"), run("two.db"));
    assert_eq!(one.database, dir.join("one.db"));
    let list = |report: &clatch::colmap::FolderReport| bytes(report.match_list.as_ref().unwrap());
    assert_eq!(
        one.match_list,
        Some(dir.join("one-colmap").join("matches.txt"))
    );
    assert_eq!(bytes(&one.database), bytes(&two.database));
    assert_eq!(list(&one), list(&two));
    assert_eq!(one.counts, two.counts);
    let counts = one.counts;
    assert_eq!((counts.photos, counts.pairs), (PHOTOS, PAIRS));
    assert!(counts.keypoints > 100 * PHOTOS, "{counts:?}");
    assert!(
        counts.pairs_with_matches >= PAIRS - 1 && counts.matches > 100,
        "overlapping photos match: {counts:?}"
    );
    assert_eq!(
        names_in(&dir),
        ["images", "one-colmap", "one.db", "two-colmap", "two.db"],
        "no temporary file left"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The stages as a cluster's driver and workers run them: extraction in two groups, the pairs
/// matched in another grouping and order, each worker holding only the descriptors it needs, the
/// results written in the pairs' order through the plan's output.
#[test]
fn the_stages_run_apart_write_the_single_run_s_bytes() {
    let dir = workdir("apart");
    let job = FolderJob::new(dir.join("images"), dir.join("one.db")).with_match_list_written(true);
    let single = job.run(None).unwrap();

    let job = FolderJob::new(dir.join("images"), dir.join("apart.db"))
        .with_match_list_written(true)
        .with_workspace(dir.join("apart-colmap"));
    let plan = job.plan().unwrap();
    let mut output = plan.open_output().unwrap();
    // The default run matches verified pairs again under their geometry: it needs the descriptors.
    let descriptors = extract_in_groups(&job, &plan, &mut output, [0..3, 3..PHOTOS], true);
    let matcher = Matcher::new(Backend::Cpu, job.matching.clone()).unwrap();
    let pairs = plan.pairs().to_vec();
    let mut found = vec![Vec::new(); pairs.len()];
    for group in [vec![5, 1], vec![4, 0, 2], vec![3]] {
        let held: Vec<(usize, usize)> = group.iter().map(|&p| pairs[p]).collect();
        let worker = |i: usize| {
            held.iter()
                .any(|&(a, b)| a == i || b == i)
                .then(|| &descriptors[i])
        };
        for (&p, matches) in group
            .iter()
            .zip(match_photo_pairs(&matcher, worker, &held).unwrap())
        {
            found[p] = matches;
        }
    }
    for (&(i, j), matches) in pairs.iter().zip(&found) {
        output.add_matches(i, j, matches).unwrap();
    }
    let apart = output.finish().unwrap().commit().unwrap();
    assert_eq!(apart.counts, single.counts);
    assert_eq!(bytes(&apart.database), bytes(&single.database));
    let list = |report: &clatch::colmap::FolderReport| bytes(report.match_list.as_ref().unwrap());
    assert_eq!(list(&apart), list(&single));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn progress_is_told_in_order_and_can_stop_the_run() {
    let dir = workdir("progress");
    let job = FolderJob::new(dir.join("images"), dir.join("out.db"));
    let mut heard: Vec<FolderProgress> = Vec::new();
    job.run(Some(&mut |p| {
        heard.push(p);
        ControlFlow::Continue(())
    }))
    .unwrap();
    let told = |stage| -> Vec<(usize, usize)> {
        heard
            .iter()
            .filter(|p| p.stage == stage)
            .map(|p| (p.done, p.total))
            .collect()
    };
    assert_eq!(
        told(FolderStage::Extraction),
        (0..=PHOTOS).map(|i| (i, PHOTOS)).collect::<Vec<_>>()
    );
    assert_eq!(told(FolderStage::Matching), [(0, PAIRS), (PAIRS, PAIRS)]);
    assert_eq!(heard[0].stage, FolderStage::Extraction);

    // Stopped while matching: nothing at the outputs, the old database kept.
    let db = dir.join("out.db");
    let old = bytes(&db);
    let replace = job.clone().with_overwrite(Overwrite::Replace);
    let e = replace
        .run(Some(&mut |p| match p.stage {
            FolderStage::Matching => ControlFlow::Break(()),
            _ => ControlFlow::Continue(()),
        }))
        .unwrap_err();
    assert!(
        matches!(
            e,
            ColmapError::Stopped {
                stage: FolderStage::Matching
            }
        ),
        "{e}"
    );
    assert_eq!(bytes(&db), old);
    assert_eq!(names_in(&dir), ["images", "out-colmap", "out.db"]);
    // The name of the database the workspace belongs to (the earlier run's); verified, no match list.
    assert_eq!(names_in(&dir.join("out-colmap")), [".clatch-database"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn given_pairs_by_index_or_name_are_written_in_their_order() {
    let dir = workdir("pairs");
    let given = [
        (PhotoRef::from(3), PhotoRef::from("view0.pgm")),
        (PhotoRef::from("view1.pgm"), PhotoRef::from(2)),
    ];
    let report = FolderJob::new(dir.join("images"), dir.join("out.db"))
        .with_pairs(given)
        .with_match_list_written(true)
        .run(None)
        .unwrap();
    assert_eq!(report.counts.pairs, 2);
    let list = String::from_utf8(bytes(report.match_list.as_ref().unwrap())).unwrap();
    let blocks: Vec<&str> = list.split("\n\n").filter(|b| !b.is_empty()).collect();
    let headers: Vec<&str> = blocks
        .iter()
        .filter_map(|block| block.lines().next())
        .collect();
    assert_eq!(headers, ["view3.pgm view0.pgm", "view1.pgm view2.pgm"]);
    // The database's `matches` holds the same rows in COLMAP's order: by pair id (smaller image id
    // first), the columns of a pair listed the other way round swapped.
    let db = rusqlite::Connection::open(&report.database).unwrap();
    let mut query = db
        .prepare("SELECT pair_id, rows, cols, data FROM matches ORDER BY pair_id")
        .unwrap();
    let stored: Vec<(i64, i64, i64, Vec<u8>)> = query
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let rows_of = |block: &str, swap: bool| -> Vec<u8> {
        block
            .lines()
            .skip(1)
            .flat_map(|line| {
                let (p, q) = line.split_once(' ').unwrap();
                let (p, q): (u32, u32) = (p.parse().unwrap(), q.parse().unwrap());
                if swap { [q, p] } else { [p, q] }
            })
            .flat_map(u32::to_le_bytes)
            .collect()
    };
    let pair = |a: u32, b: u32| clatch::colmap::pair_id(a, b) as i64;
    let expected = [
        (pair(1, 4), rows_of(blocks[0], true)),
        (pair(2, 3), rows_of(blocks[1], false)),
    ];
    assert_eq!(stored.len(), 2);
    for ((id, rows, cols, data), (want_id, want)) in stored.iter().zip(&expected) {
        assert_eq!((id, *cols, data), (want_id, 2, want));
        assert_eq!(*rows as usize * 8, want.len());
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Each refusal: an error before any work, nothing written, nothing removed.
#[test]
fn refusals_come_before_any_work_and_leave_nothing_behind() {
    let dir = workdir("refusals");
    let images = dir.join("images");
    let db = dir.join("out.db");
    std::fs::write(&db, "an older database").unwrap();
    let k = dir.join("K.txt");
    std::fs::write(&k, "300 0 160 0 300 150 0 0 1").unwrap();
    let before = snapshot(&dir);
    let job = FolderJob::new(&images, &db);
    let refused = |job: FolderJob, what: &str| {
        let e = job.run(None).unwrap_err();
        assert_eq!(snapshot(&dir), before, "{what}: {e}");
        e
    };

    let e = refused(job.clone(), "an existing database");
    assert!(matches!(e, ColmapError::DatabaseExists { .. }), "{e}");
    let photo = images.join("view1.pgm");
    let e = refused(
        FolderJob::new(&images, &photo).with_overwrite(Overwrite::Replace),
        "a database that is a photo",
    );
    assert!(
        e.to_string().contains("is the same file as the image"),
        "{e}"
    );
    let e = refused(
        job.clone()
            .with_overwrite(Overwrite::Replace)
            .with_match_list(&k)
            .with_camera(FolderCamera::KText {
                text: std::fs::read_to_string(&k).unwrap(),
                file: Some(k.clone()),
            }),
        "a match list that is the camera matrix file",
    );
    assert!(e.to_string().contains("camera matrix"), "{e}");
    let e = refused(
        job.clone().with_match_list(dir.join("images/")),
        "a match list that names a folder",
    );
    assert!(matches!(e, ColmapError::Output(_)), "{e}");
    let e = refused(
        job.clone().with_pairs([(0usize, PHOTOS)]),
        "a pair out of range",
    );
    assert!(matches!(e, ColmapError::PairOutOfRange { .. }), "{e}");
    let camera = PinholeCamera::guess(640, 480).unwrap();
    let e = refused(
        job.clone().with_camera(FolderCamera::Shared(camera)),
        "a camera of another size",
    );
    assert!(matches!(e, ColmapError::ImageSizeMismatch { .. }), "{e}");
    let mut extractor = FolderJob::default_extractor();
    extractor.detector.threshold = 0;
    let e = refused(job.clone().with_extractor(extractor), "a bad setting");
    assert!(matches!(e, ColmapError::Clatch(_)), "{e}");
    std::fs::write(images.join("broken.pgm"), "P5\n").unwrap();
    let before = snapshot(&dir);
    let e = job
        .with_overwrite(Overwrite::Replace)
        .run(None)
        .unwrap_err();
    assert!(e.to_string().contains("broken.pgm"), "{e}");
    assert_eq!(
        snapshot(&dir),
        before,
        "a photo whose header cannot be read"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A photo whose header reads but whose pixels are cut short fails during extraction: the temporary
/// files are removed, the old database kept, the workspace folder left empty.
#[test]
fn a_run_that_fails_keeps_the_old_database_and_leaves_no_file() {
    let dir = workdir("fails");
    let images = dir.join("images");
    let db = dir.join("out.db");
    std::fs::write(&db, "an older database").unwrap();
    let last = images.join(format!("view{}.pgm", PHOTOS - 1));
    let pixels = bytes(&last);
    std::fs::write(&last, &pixels[..pixels.len() - 5000]).unwrap();
    let e = FolderJob::new(&images, &db)
        .with_overwrite(Overwrite::Replace)
        .run(None)
        .unwrap_err();
    assert!(e.to_string().contains(&*last.to_string_lossy()), "{e}");
    assert_eq!(bytes(&db), b"an older database");
    // The match list's folder the run made is gone again: no empty workspace left behind.
    assert_eq!(names_in(&dir), ["images", "out.db"]);
    // A folder that was there before stays, empty or not.
    std::fs::create_dir(dir.join("out-colmap")).unwrap();
    FolderJob::new(&images, &db)
        .with_overwrite(Overwrite::Replace)
        .run(None)
        .unwrap_err();
    assert_eq!(names_in(&dir), ["images", "out-colmap", "out.db"]);
    assert!(names_in(&dir.join("out-colmap")).is_empty());
    std::fs::remove_dir_all(&dir).ok();
}

/// The keypoints (COLMAP's pixel convention) of every image, by image id.
fn keypoints_of(db: &rusqlite::Connection) -> std::collections::HashMap<u32, Vec<[f32; 2]>> {
    let mut query = db
        .prepare("SELECT image_id, cols, data FROM keypoints")
        .unwrap();
    let rows = query
        .query_map([], |row| {
            let (id, cols, data): (u32, i64, Vec<u8>) = (row.get(0)?, row.get(1)?, row.get(2)?);
            let cols = cols as usize;
            let floats: Vec<f32> = data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect();
            Ok((
                id,
                floats.chunks_exact(cols).map(|k| [k[0], k[1]]).collect(),
            ))
        })
        .unwrap();
    rows.map(Result::unwrap).collect()
}

/// With verification, every pair's two-view geometry is in the database, as COLMAP's
/// `matches_importer` would write it, so the mapper runs on it directly: the crops differ by a pure
/// translation, so each pair is a homography (planar or panoramic, COLMAP's code 6), every inlier
/// lies on its true epipolar line and nearly all where the translation puts it; two runs write the
/// same bytes; every pair's matches are in `matches`; without verification both tables stay empty.
#[test]
fn verification_writes_every_pair_s_geometry_and_only_true_inliers() {
    let dir = workdir("verify");
    let run = |db: &str| {
        FolderJob::new(dir.join("images"), dir.join(db))
            .with_verification(clatch::verify::VerifyConfig::default())
            .with_guided_matching(false)
            .run(None)
            .unwrap()
    };
    let (one, two) = (run("one.db"), run("two.db"));
    assert_eq!(bytes(&one.database), bytes(&two.database));
    let counts = one.counts;
    assert_eq!(counts.pairs_verified, PAIRS, "{counts:?}");
    assert!(counts.pairs_with_inliers >= PAIRS - 1, "{counts:?}");
    assert!(
        counts.inliers > counts.matches / 2 && counts.inliers <= counts.matches,
        "{counts:?}"
    );

    let db = rusqlite::Connection::open(&one.database).unwrap();
    let keypoints = keypoints_of(&db);
    let mut query = db
        .prepare("SELECT pair_id, rows, data, config FROM two_view_geometries")
        .unwrap();
    let rows: Vec<(i64, i64, Option<Vec<u8>>, i64)> = query
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(rows.len(), PAIRS);
    let mut inliers = 0;
    let mut errors = Vec::new();
    let mut across_worst = 0.0f32;
    for (pair, count, data, config) in rows {
        let (a, b) = clatch::colmap::image_ids_of_pair(pair as u64);
        if count == 0 {
            continue;
        }
        assert_eq!(config, 6, "pair {a}-{b}: a translation is a homography");
        let shift = (b - a) as f32;
        for index in data.unwrap().chunks_exact(8) {
            let ka = u32::from_le_bytes(index[..4].try_into().unwrap()) as usize;
            let kb = u32::from_le_bytes(index[4..].try_into().unwrap()) as usize;
            let (pa, pb) = (keypoints[&a][ka], keypoints[&b][kb]);
            // The offset from where the translation puts it, and its part across the translation's
            // direction (the epipolar line of a pure translation).
            let (dx, dy) = (
                pb[0] - (pa[0] - 40.0 * shift),
                pb[1] - (pa[1] - 25.0 * shift),
            );
            let error = (dx * dx + dy * dy).sqrt();
            let across = (dx * 25.0 - dy * 40.0).abs() / (40.0f32 * 40.0 + 25.0 * 25.0).sqrt();
            across_worst = across_worst.max(across);
            errors.push(error);
            inliers += 1;
        }
    }
    assert_eq!(inliers, counts.inliers);
    // COLMAP's rules keep the fundamental matrix's inliers unless the homography has more: every
    // inlier lies on its true epipolar line (within the threshold, 4 px), and nearly all where the
    // translation puts it. The few that do not are the repeated rectangles' wrong matches along that
    // line, which no epipolar model can tell from right ones.
    let threshold = clatch::verify::VerifyConfig::default().max_error as f32;
    let close = errors.iter().filter(|&&e| e <= 2.0).count();
    assert!(
        across_worst <= threshold,
        "an inlier {across_worst} px off its epipolar line"
    );
    assert!(
        close as f64 >= 0.97 * errors.len() as f64,
        "{close} of {}",
        errors.len()
    );

    // Every pair's matches are in the database too, and no match list is written.
    let db = rusqlite::Connection::open(&one.database).unwrap();
    let (pairs, matches): (i64, i64) = db
        .query_row("SELECT COUNT(*), SUM(rows) FROM matches", [], |r| {
            Ok((r.get(0)?, r.get(1)?))
        })
        .unwrap();
    assert_eq!((pairs as usize, matches as usize), (PAIRS, counts.matches));
    assert_eq!(one.match_list, None);
    assert!(!dir.join("one-colmap").join("matches.txt").exists());

    // Without verification both tables stay empty: COLMAP's `matches_importer` fills them from the
    // match list.
    let plain = FolderJob::new(dir.join("images"), dir.join("plain.db"))
        .without_verification()
        .run(None)
        .unwrap();
    let db = rusqlite::Connection::open(&plain.database).unwrap();
    let stored = |table: &str| -> i64 {
        db.query_row(&format!("SELECT COUNT(*) FROM {table}"), [], |r| r.get(0))
            .unwrap()
    };
    assert_eq!((stored("two_view_geometries"), stored("matches")), (0, 0));
    assert_eq!(plain.counts.pairs_verified, 0);
    assert!(bytes(plain.match_list.as_ref().unwrap()).len() > 100);
    std::fs::remove_dir_all(&dir).ok();
}

/// How far each verified inlier of the database lies from where its pair's translation puts it,
/// pixels.
fn inlier_offsets(database: &Path) -> Vec<f32> {
    let db = rusqlite::Connection::open(database).unwrap();
    let keypoints = keypoints_of(&db);
    let mut query = db
        .prepare("SELECT pair_id, data FROM two_view_geometries WHERE rows > 0")
        .unwrap();
    let rows: Vec<(i64, Vec<u8>)> = query
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let mut errors = Vec::new();
    for (pair, data) in rows {
        let (a, b) = clatch::colmap::image_ids_of_pair(pair as u64);
        let shift = (b - a) as f32;
        for index in data.chunks_exact(8) {
            let ka = u32::from_le_bytes(index[..4].try_into().unwrap()) as usize;
            let kb = u32::from_le_bytes(index[4..].try_into().unwrap()) as usize;
            let (pa, pb) = (keypoints[&a][ka], keypoints[&b][kb]);
            let (dx, dy) = (
                pb[0] - (pa[0] - 40.0 * shift),
                pb[1] - (pa[1] - 25.0 * shift),
            );
            errors.push((dx * dx + dy * dy).sqrt());
        }
    }
    errors
}

/// Guided matching: every verified pair matched again under its homography (the crops differ by a
/// translation) finds more inliers than verification kept, nearly all where the translation puts
/// them; the stages run apart, each photo added with its descriptors, write the single run's bytes;
/// a photo added without them is refused when its pair is written.
#[test]
fn guided_matching_adds_true_inliers_and_its_stages_apart_write_the_same_bytes() {
    let dir = workdir("guided");
    let job = |db: &str| {
        FolderJob::new(dir.join("images"), dir.join(db))
            .with_workspace(dir.join(format!("{db}-colmap")))
            .with_verification(FolderJob::default_verification())
    };
    let verified = job("verified.db")
        .with_guided_matching(false)
        .run(None)
        .unwrap();
    let guided_job = job("guided.db");
    assert!(guided_job.guided_matching, "on by default");
    let guided = guided_job.run(None).unwrap();
    assert_eq!(guided.counts.matches, verified.counts.matches);
    // Verified runs write no match list unless asked; the putative matches are the same.
    assert_eq!((&guided.match_list, &verified.match_list), (&None, &None));
    assert!(
        guided.counts.inliers > verified.counts.inliers,
        "{:?} against {:?}",
        guided.counts,
        verified.counts
    );
    let errors = inlier_offsets(&guided.database);
    assert_eq!(errors.len(), guided.counts.inliers);
    let close = errors.iter().filter(|&&e| e <= 2.0).count();
    assert!(
        close as f64 >= 0.97 * errors.len() as f64,
        "{close} of {}",
        errors.len()
    );

    for described in [true, false] {
        let job = job(if described { "apart.db" } else { "bare.db" });
        let plan = job.plan().unwrap();
        let mut output = plan.open_output().unwrap();
        let descriptors = extract_in_groups(&job, &plan, &mut output, [0..1, 1..PHOTOS], described);
        let matcher = Matcher::new(Backend::Cpu, job.matching.clone()).unwrap();
        let pairs = plan.pairs().to_vec();
        let found = match_photo_pairs(&matcher, |i| descriptors.get(i), &pairs).unwrap();
        let written: Vec<&[clatch::Match]> = found.iter().map(Vec::as_slice).collect();
        if !described {
            let error = output.add_pairs(&pairs, &written).unwrap_err();
            assert!(
                matches!(
                    error,
                    ColmapError::MissingDescriptors {
                        position: 0,
                        image: 0
                    }
                ),
                "{error}"
            );
            continue;
        }
        // One pair at a time (the single run writes them in groups).
        for (&(i, j), matches) in pairs.iter().zip(&written) {
            output.add_matches(i, j, matches).unwrap();
        }
        let apart = output.finish().unwrap().commit().unwrap();
        assert_eq!(apart.counts, guided.counts);
        assert_eq!(bytes(&apart.database), bytes(&guided.database));
    }
    std::fs::remove_dir_all(&dir).ok();
}

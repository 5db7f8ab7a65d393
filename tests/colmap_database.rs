//! The COLMAP 3.8 database writer, read back through SQL: no COLMAP needed. Three crops of the
//! embedded photograph at known offsets are detected, described and matched; the database must hold
//! COLMAP's ids, pair ids, blob shapes and conventions, and the stored matches must agree with the
//! known offsets (which they only do if the columns are in COLMAP's order).

mod common;

use std::path::PathBuf;

use clatch::colmap::{ColmapError, Database, MatchList, PinholeCamera};
use clatch::{
    Backend, Extractor, ExtractorConfig, Features, KeyPoint, Match, MatchConfig, Matcher,
};
use common::{Gray, astronaut};
use rusqlite::Connection;

const SIDE: usize = 384;
/// Top-left corner of each crop in the photograph.
const OFFSETS: [(usize, usize); 3] = [(0, 0), (48, 32), (96, 80)];

fn crop(img: &Gray, (x0, y0): (usize, usize)) -> Gray {
    let pixels = (y0..y0 + SIDE)
        .flat_map(|y| (x0..x0 + SIDE).map(move |x| (x, y)))
        .map(|(x, y)| img.at(x, y))
        .collect();
    Gray::new(pixels, SIDE, SIDE)
}

fn temp_db(name: &str) -> PathBuf {
    let path = std::env::temp_dir().join(format!("clatch-colmap-{}-{name}.db", std::process::id()));
    std::fs::remove_file(&path).ok();
    path
}

fn features() -> Vec<Features> {
    let photo = astronaut();
    // Full resolution: whole-pixel keypoints, so matches between crops shift by whole pixels.
    let extractor = Extractor::new(Backend::Cpu, ExtractorConfig::single_scale()).unwrap();
    OFFSETS
        .iter()
        .map(|&o| {
            extractor
                .detect_and_describe(&crop(&photo, o).view())
                .unwrap()
        })
        .collect()
}

fn f32s(blob: &[u8]) -> Vec<f32> {
    blob.chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

fn u32s(blob: &[u8]) -> Vec<u32> {
    blob.chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// Column names of a table, in order.
fn columns(db: &Connection, table: &str) -> Vec<String> {
    let mut stmt = db.prepare(&format!("PRAGMA table_info({table})")).unwrap();
    stmt.query_map([], |row| row.get::<_, String>(1))
        .unwrap()
        .map(Result::unwrap)
        .collect()
}

#[test]
fn database_holds_colmap_ids_blobs_and_conventions() {
    let features = features();
    let matcher = Matcher::new(Backend::Cpu, MatchConfig::default()).unwrap();
    let path = temp_db("roundtrip");
    let mut db = Database::create(&path).unwrap();
    let camera = PinholeCamera::from_k_text("500 0 192\n0 510 191\n0 0 1", 384, 384).unwrap();
    let camera_id = db.add_camera(&camera).unwrap();
    let names = ["crop0.png", "crop1.png", "crop2.png"];
    let ids: Vec<u32> = names
        .iter()
        .map(|n| db.add_image(n, camera_id).unwrap())
        .collect();
    for (id, f) in ids.iter().zip(&features) {
        db.set_keypoints(*id, &f.keypoints).unwrap();
    }
    // Pair (1, 2) written in order, pairs (3, 1) and (3, 2) the other way round.
    let written: Vec<(usize, usize, Vec<Match>)> = [(0, 1), (2, 0), (2, 1)]
        .iter()
        .map(|&(a, b)| {
            let m = matcher
                .match_descriptors(&features[a].descriptors, &features[b].descriptors)
                .unwrap();
            assert!(m.len() >= 20, "crops {a} and {b} gave {} matches", m.len());
            (a, b, m)
        })
        .collect();
    for (a, b, m) in &written {
        db.add_matches(ids[*a], ids[*b], m).unwrap();
    }
    db.finish().unwrap();

    let sql = Connection::open(&path).unwrap();
    // COLMAP 3.8's columns.
    assert_eq!(
        columns(&sql, "cameras"),
        [
            "camera_id",
            "model",
            "width",
            "height",
            "params",
            "prior_focal_length"
        ]
    );
    assert_eq!(
        columns(&sql, "images")[..3],
        ["image_id", "name", "camera_id"]
    );
    assert_eq!(columns(&sql, "images").len(), 10);
    assert_eq!(
        columns(&sql, "keypoints"),
        ["image_id", "rows", "cols", "data"]
    );
    assert_eq!(
        columns(&sql, "matches"),
        ["pair_id", "rows", "cols", "data"]
    );
    assert_eq!(columns(&sql, "two_view_geometries").len(), 10);

    // The camera: PINHOLE (model 1), float64 params, a known focal length.
    let (model, width, height, params, prior): (i64, i64, i64, Vec<u8>, i64) = sql
        .query_row(
            "SELECT model, width, height, params, prior_focal_length FROM cameras",
            [],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?)),
        )
        .unwrap();
    assert_eq!((model, width, height, prior), (1, 384, 384, 1));
    let params: Vec<f64> = params
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(params, [500.0, 510.0, 192.0, 191.0]);

    // Images: ids from 1, in insertion order, all on camera 1.
    let mut stmt = sql
        .prepare("SELECT image_id, name, camera_id FROM images ORDER BY image_id")
        .unwrap();
    let images: Vec<(i64, String, i64)> = stmt
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(
        images,
        [
            (1, "crop0.png".into(), 1),
            (2, "crop1.png".into(), 1),
            (3, "crop2.png".into(), 1)
        ]
    );

    // Keypoints: rows x 4 float32, centre of the first pixel at (0.5, 0.5), angle in radians.
    let mut stored_keypoints = Vec::new();
    for (id, f) in ids.iter().zip(&features) {
        let (rows, cols, data): (i64, i64, Vec<u8>) = sql
            .query_row(
                "SELECT rows, cols, data FROM keypoints WHERE image_id = ?1",
                [id],
                |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
            )
            .unwrap();
        assert_eq!((rows as usize, cols), (f.keypoints.len(), 4));
        assert_eq!(data.len(), rows as usize * 4 * 4);
        let values = f32s(&data);
        for (k, row) in f.keypoints.iter().zip(values.chunks_exact(4)) {
            assert_eq!(row[0], k.x + 0.5);
            assert_eq!(row[1], k.y + 0.5);
            assert_eq!(row[2], k.size / 2.0);
            assert!((row[3] - k.angle * std::f32::consts::PI / 180.0).abs() < 1e-6);
            assert!(row[3].abs() <= std::f32::consts::PI * 2.0);
        }
        stored_keypoints.push(values);
    }

    // Matches: one row per pair under 2147483647 * min + max, rows x 2 uint32, first column the
    // smaller image id's keypoint, every index in range, and the pairs agree with the crop offsets.
    let mut stmt = sql
        .prepare("SELECT pair_id, rows, cols, data FROM matches ORDER BY pair_id")
        .unwrap();
    let stored: Vec<(i64, i64, i64, Vec<u8>)> = stmt
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(
        stored.iter().map(|s| s.0).collect::<Vec<_>>(),
        [2147483647 + 2, 2147483647 + 3, 2 * 2147483647 + 3]
    );
    for (a, b, m) in &written {
        let (id_a, id_b) = (ids[*a] as i64, ids[*b] as i64);
        let expected_pair = 2147483647 * id_a.min(id_b) + id_a.max(id_b);
        let (_, rows, cols, data) = stored.iter().find(|s| s.0 == expected_pair).unwrap();
        assert_eq!((*rows as usize, *cols), (m.len(), 2));
        assert_eq!(data.len(), m.len() * 2 * 4);
        let indices = u32s(data);
        let (lo, hi) = if id_a < id_b { (*a, *b) } else { (*b, *a) };
        let mut agreeing = 0;
        for (row, mm) in indices.chunks_exact(2).zip(m) {
            let expected = if id_a < id_b {
                [mm.query, mm.train]
            } else {
                [mm.train, mm.query]
            };
            assert_eq!(row, expected);
            let (kl, kh) = (&stored_keypoints[lo], &stored_keypoints[hi]);
            assert!((row[0] as usize) < kl.len() / 4 && (row[1] as usize) < kh.len() / 4);
            // The same scene point: a pixel of crop `lo` sits OFFSETS[hi] - OFFSETS[lo] further left
            // and up in crop `hi`.
            let dx = kl[4 * row[0] as usize] - kh[4 * row[1] as usize];
            let dy = kl[4 * row[0] as usize + 1] - kh[4 * row[1] as usize + 1];
            let shift = (
                OFFSETS[hi].0 as f32 - OFFSETS[lo].0 as f32,
                OFFSETS[hi].1 as f32 - OFFSETS[lo].1 as f32,
            );
            if (dx, dy) == shift {
                agreeing += 1;
            }
        }
        assert!(
            agreeing * 10 >= m.len() * 9,
            "pair ({a}, {b}): {agreeing} of {} matches agree with the crop offsets",
            m.len()
        );
    }
    std::fs::remove_file(&path).ok();
}

#[test]
fn bad_input_is_a_typed_error() {
    let path = temp_db("errors");
    let mut db = Database::create(&path).unwrap();
    let camera = db
        .add_camera(&PinholeCamera::guess(100, 80).unwrap())
        .unwrap();
    let a = db.add_image("a.png", camera).unwrap();
    let b = db.add_image("b.png", camera).unwrap();
    assert!(matches!(
        db.add_image("a.png", camera),
        Err(ColmapError::InvalidImageName { .. })
    ));
    assert!(matches!(
        db.add_image("/abs.png", camera),
        Err(ColmapError::InvalidImageName { .. })
    ));
    let m = [Match {
        query: 1,
        train: 0,
        distance: 3,
    }];
    // Keypoints first.
    assert!(matches!(
        db.add_matches(a, b, &m),
        Err(ColmapError::UnknownImage { .. })
    ));
    db.set_keypoints(a, &[KeyPoint::new(1.0, 2.0), KeyPoint::new(3.0, 4.0)])
        .unwrap();
    db.set_keypoints(b, &[KeyPoint::new(5.0, 6.0)]).unwrap();
    assert!(matches!(
        db.set_keypoints(b, &[]),
        Err(ColmapError::Duplicate { .. })
    ));
    assert!(matches!(
        db.set_keypoints(99, &[]),
        Err(ColmapError::UnknownImage { image_id: 99 })
    ));
    // Index 1 exists in a (2 keypoints) but not in b (1 keypoint).
    let e = db.add_matches(b, a, &m).unwrap_err();
    assert!(
        matches!(e, ColmapError::MatchOutOfRange { image_id, keypoint: 1, keypoints: 1, .. } if image_id == b),
        "{e}"
    );
    assert!(matches!(
        db.add_matches(a, a, &m),
        Err(ColmapError::SamePair { .. })
    ));
    db.add_matches(a, b, &m).unwrap();
    assert!(matches!(
        db.add_matches(b, a, &[]),
        Err(ColmapError::Duplicate { .. })
    ));
    db.finish().unwrap();
    // An existing file is never overwritten.
    assert!(matches!(
        Database::create(&path),
        Err(ColmapError::DatabaseExists { .. })
    ));
    std::fs::remove_file(&path).ok();
}

#[test]
fn match_list_is_colmaps_text_format() {
    let m = [
        Match {
            query: 4,
            train: 0,
            distance: 1,
        },
        Match {
            query: 2,
            train: 9,
            distance: 5,
        },
    ];
    let mut list = MatchList::new(Vec::new());
    list.add_pair("b.jpg", "a.jpg", &m).unwrap();
    list.add_pair("a.jpg", "c.jpg", &[]).unwrap();
    let text = String::from_utf8(list.into_inner().unwrap()).unwrap();
    assert_eq!(text, "b.jpg a.jpg\n4 0\n2 9\n\na.jpg c.jpg\n\n");
    let mut list = MatchList::new(Vec::new());
    assert!(list.add_pair("a b.jpg", "c.jpg", &m).is_err());
    assert!(list.add_pair("a.jpg", "a.jpg", &m).is_err());
}

/// `open_existing` + `add_two_view_geometry`: the rows a verifier adds to a database written before,
/// every check of a new database kept (COLMAP's own reading of them is in tests/colmap_two_view.rs).
#[test]
fn two_view_geometries_go_into_an_existing_database_checked() {
    use clatch::colmap::TwoViewGeometry;
    use clatch::verify::GeometryConfig;
    let path = temp_db("two-view");
    assert!(matches!(
        Database::open_existing(&path),
        Err(ColmapError::DatabaseMissing { .. })
    ));
    let mut db = Database::create(&path).unwrap();
    let camera = db
        .add_camera(&PinholeCamera::guess(64, 64).unwrap())
        .unwrap();
    let a = db.add_image("a.png", camera).unwrap();
    let b = db.add_image("b.png", camera).unwrap();
    let c = db.add_image("c.png", camera).unwrap();
    let points = |n: usize| -> Vec<KeyPoint> {
        (0..n)
            .map(|i| KeyPoint::new(i as f32, 2.0 * i as f32))
            .collect()
    };
    db.set_keypoints(a, &points(3)).unwrap();
    db.set_keypoints(b, &points(5)).unwrap();
    let first = TwoViewGeometry::new(a, b, vec![[2, 4], [0, 1]], GeometryConfig::Calibrated);
    db.add_two_view_geometry(&first).unwrap();
    db.finish().unwrap();

    let mut db = Database::open_existing(&path).unwrap();
    // c has no keypoints, the pair (b, a) is there already, a has 3 keypoints.
    assert!(matches!(
        db.add_two_view_geometry(&TwoViewGeometry::new(a, c, vec![], GeometryConfig::Degenerate)),
        Err(ColmapError::UnknownImage { image_id }) if image_id == c
    ));
    assert!(matches!(
        db.add_two_view_geometry(&TwoViewGeometry::new(
            b,
            a,
            vec![],
            GeometryConfig::Degenerate
        )),
        Err(ColmapError::Duplicate { .. })
    ));
    assert!(matches!(
        db.add_two_view_geometry(&TwoViewGeometry::new(
            b,
            a,
            vec![[0, 3]],
            GeometryConfig::Calibrated
        )),
        Err(ColmapError::MatchOutOfRange {
            keypoint: 3,
            keypoints: 3,
            ..
        })
    ));
    assert!(matches!(
        db.add_two_view_geometry(&TwoViewGeometry::new(
            a,
            a,
            vec![],
            GeometryConfig::Calibrated
        )),
        Err(ColmapError::SamePair { .. })
    ));
    let not_finite = TwoViewGeometry {
        f: Some([[f64::NAN; 3]; 3]),
        ..TwoViewGeometry::new(b, a, vec![[0, 0]], GeometryConfig::Uncalibrated)
    };
    assert!(matches!(
        db.add_two_view_geometry(&not_finite),
        Err(ColmapError::InvalidGeometry { .. })
    ));
    db.set_keypoints(c, &points(2)).unwrap();
    // Given as (c, b): stored under pair (b, c) with the columns swapped.
    db.add_two_view_geometry(&TwoViewGeometry::new(
        c,
        b,
        vec![[1, 4]],
        GeometryConfig::Planar,
    ))
    .unwrap();
    db.finish().unwrap();

    let sql = Connection::open(&path).unwrap();
    let mut stmt = sql
        .prepare(
            "SELECT pair_id, rows, cols, data, config FROM two_view_geometries ORDER BY pair_id",
        )
        .unwrap();
    let rows: Vec<(i64, i64, i64, Vec<u8>, i64)> = stmt
        .query_map([], |r| {
            Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?))
        })
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(rows.len(), 2);
    assert_eq!(
        (rows[0].0, rows[0].1, rows[0].2, rows[0].4),
        (2147483647 + 2, 2, 2, 2)
    );
    assert_eq!(u32s(&rows[0].3), [2, 4, 0, 1]);
    assert_eq!(
        (rows[1].0, rows[1].1, rows[1].4),
        (2 * 2147483647 + 3, 1, 4)
    );
    assert_eq!(u32s(&rows[1].3), [4, 1]);
    std::fs::remove_file(&path).ok();
}

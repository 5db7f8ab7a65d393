//! Reading what the geometry evaluation needs from a COLMAP 3.8 database, whoever wrote it: the
//! images, their keypoints (COLMAP pixel coordinates) and the verified pairs of
//! `two_view_geometries`.

use std::collections::HashMap;
use std::path::Path;

use rusqlite::{Connection, OpenFlags};

use crate::error::EvalError;

/// One verified pair: inliers as `[keypoint of image_id1, keypoint of image_id2]`, `image_id1` the
/// smaller id (COLMAP's order).
pub struct VerifiedPair {
    pub image_id1: u32,
    pub image_id2: u32,
    /// COLMAP's `TwoViewGeometry::ConfigurationType` code.
    pub config: i64,
    pub inliers: Vec<[u32; 2]>,
}

/// The database's contents the evaluation reads.
pub struct DatabaseContents {
    /// Image id to name.
    pub images: HashMap<u32, String>,
    /// Image id to keypoint positions.
    pub keypoints: HashMap<u32, Vec<[f64; 2]>>,
    /// Pairs of `two_view_geometries`, in pair-id order (pairs without inliers included).
    pub pairs: Vec<VerifiedPair>,
}

fn sql_error(path: &Path) -> impl Fn(rusqlite::Error) -> EvalError + '_ {
    move |e| EvalError::Input {
        path: path.to_path_buf(),
        reason: format!("reading the COLMAP database: {e}"),
    }
}

/// Reads a database without changing it.
pub fn read_database(path: &Path) -> Result<DatabaseContents, EvalError> {
    let fail = sql_error(path);
    let sql = Connection::open_with_flags(path, OpenFlags::SQLITE_OPEN_READ_ONLY).map_err(&fail)?;
    let mut images = HashMap::new();
    let mut statement = sql
        .prepare("SELECT image_id, name FROM images")
        .map_err(&fail)?;
    let rows = statement
        .query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?)))
        .map_err(&fail)?;
    for row in rows {
        let (id, name) = row.map_err(&fail)?;
        images.insert(id as u32, name);
    }
    let mut keypoints = HashMap::new();
    let rows = four_columns(
        &sql,
        "SELECT image_id, rows, cols, data FROM keypoints",
        &fail,
    )?;
    for (id, n, cols, data) in rows {
        let data = data.unwrap_or_default();
        let (n, cols) = (n as usize, cols as usize);
        if cols < 2 || data.len() != n * cols * 4 {
            return Err(EvalError::Input {
                path: path.to_path_buf(),
                reason: format!(
                    "keypoints of image {id}: {n} x {cols} float32 but {} bytes",
                    data.len()
                ),
            });
        }
        let values: Vec<f32> = data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let positions = values
            .chunks_exact(cols)
            .map(|row| [f64::from(row[0]), f64::from(row[1])])
            .collect();
        keypoints.insert(id as u32, positions);
    }
    let mut pairs = Vec::new();
    let rows = four_columns(
        &sql,
        "SELECT pair_id, rows, config, data FROM two_view_geometries ORDER BY pair_id",
        &fail,
    )?;
    for (pair_id, n, config, data) in rows {
        let data = data.unwrap_or_default();
        if data.len() != n as usize * 8 {
            return Err(EvalError::Input {
                path: path.to_path_buf(),
                reason: format!("pair {pair_id}: {n} inliers but {} bytes", data.len()),
            });
        }
        let (image_id1, image_id2) = clatch::colmap::image_ids_of_pair(pair_id as u64);
        let values: Vec<u32> = data
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        pairs.push(VerifiedPair {
            image_id1,
            image_id2,
            config,
            inliers: values.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
        });
    }
    Ok(DatabaseContents {
        images,
        keypoints,
        pairs,
    })
}

/// Three integers and a blob (NULL as `None`): a keypoints or two_view_geometries row.
type BlobRow = (i64, i64, i64, Option<Vec<u8>>);

/// The rows of a query of three integers and a blob.
fn four_columns(
    sql: &Connection,
    query: &str,
    fail: &impl Fn(rusqlite::Error) -> EvalError,
) -> Result<Vec<BlobRow>, EvalError> {
    let mut statement = sql.prepare(query).map_err(fail)?;
    let rows = statement
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
        .map_err(fail)?;
    rows.collect::<Result<_, _>>().map_err(fail)
}

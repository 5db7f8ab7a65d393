//! Verified two-view geometry as COLMAP 3.8 stores it in `two_view_geometries`, the one match table
//! its `mapper` reads.
//!
//! Layout, from COLMAP 3.8's `Database::WriteTwoViewGeometry` (`src/base/database.cc`) and checked
//! against rows that `colmap matches_importer` writes (`tests/colmap_two_view.rs`):
//! - `pair_id` as for matches ([`super::pair_id`]); `rows`/`cols`/`data` the inlier matches, uint32
//!   `(index in the smaller image id's keypoints, index in the larger's)`, `cols` 2;
//! - `config` COLMAP's `TwoViewGeometry::ConfigurationType` ([`GeometryConfig`]);
//! - `F`, `E`, `H`: nine float64 each, row-major (COLMAP transposes its column-major Eigen matrices
//!   before writing), mapping image `min id` to image `max id` (`x_max' F x_min = 0`,
//!   `x_max ~ H x_min`);
//! - `qvec` (w, x, y, z, four float64) and `tvec` (three float64): the pose of the larger id's camera
//!   relative to the smaller's (`X_max = R(qvec) X_min + tvec`);
//! - a pair without inliers (a failed verification, config [`GeometryConfig::Degenerate`] for
//!   COLMAP) has `rows` 0, `cols` 2 and NULL in `data` and every matrix column, as COLMAP writes it;
//! - a matrix or pose not given is stored as zeros: what COLMAP 3.8 stores for a geometry it did not
//!   estimate (`matches_importer --match_type inliers` writes zero F, E, H, qvec and tvec, and
//!   config [`GeometryConfig::Calibrated`]).
//!
//! What COLMAP 3.8's `mapper` reads of a row: the inliers and `config` (it leaves out pairs with
//! fewer than `Mapper.min_num_matches` inliers, 15 by default, and [`GeometryConfig::Watermark`]
//! pairs when `Mapper.ignore_watermarks` is set); it estimates the initial pair's geometry itself and
//! does not read F, E, H or the pose. Checked: a database of the courtyard-corner scene
//! (docs/eval/geometry.md) with those columns zeroed maps to the same model (5/5 images, 1674 points,
//! the same camera errors). They are stored for other readers.
//!
//! A pair given with `image_id1 > image_id2` is turned round as COLMAP's `TwoViewGeometry::Invert`
//! does: inlier columns swapped, `F` and `E` transposed, `H` inverted, the pose inverted.

use crate::colmap::error::ColmapError;
use crate::colmap::pair_id;
use crate::matching::Match;
use crate::verify::GeometryConfig;

/// A 3×3 matrix, row-major: `m[row][column]`.
pub type Matrix3 = [[f64; 3]; 3];

/// A relative pose: camera 2's frame from camera 1's, `X2 = R(qvec) · X1 + tvec`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativePose {
    /// Unit quaternion `(w, x, y, z)` of `R`.
    pub qvec: [f64; 4],
    /// Translation, in the scale of the estimate (COLMAP's is of unit length).
    pub tvec: [f64; 3],
}

impl RelativePose {
    /// The pose of camera 1 from camera 2: `q⁻¹`, `−R⁻¹·t`.
    pub fn inverse(&self) -> Self {
        let [w, x, y, z] = self.qvec;
        let inverse_q = [w, -x, -y, -z];
        let r = quaternion_rotation(inverse_q);
        let t = self.tvec;
        let rotated = [0, 1, 2].map(|i| r[i][0] * t[0] + r[i][1] * t[1] + r[i][2] * t[2]);
        Self {
            qvec: inverse_q,
            tvec: rotated.map(|v| -v),
        }
    }
}

/// The rotation matrix of a unit quaternion `(w, x, y, z)` (COLMAP's `QuaternionToRotationMatrix`).
pub fn quaternion_rotation([w, x, y, z]: [f64; 4]) -> Matrix3 {
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The verified geometry of one image pair, for [`crate::colmap::Database::add_two_view_geometry`]:
/// the record a verification stage hands over, in either image order.
#[derive(Clone, Debug, PartialEq)]
pub struct TwoViewGeometry {
    /// The first image (a `image_id` of the database).
    pub image_id1: u32,
    /// The second image.
    pub image_id2: u32,
    /// Inlier matches: `[index into image_id1's keypoints, index into image_id2's]`.
    pub inliers: Vec<[u32; 2]>,
    /// How the inliers were verified.
    pub config: GeometryConfig,
    /// Fundamental matrix from image 1 to image 2 (`x2ᵀ F x1 = 0`, COLMAP pixel coordinates), if
    /// estimated; stored as zeros otherwise, as COLMAP does.
    pub f: Option<Matrix3>,
    /// Essential matrix from camera 1 to camera 2 (`y2ᵀ E y1 = 0`, normalised coordinates).
    pub e: Option<Matrix3>,
    /// Homography from image 1 to image 2 (`x2 ~ H x1`).
    pub h: Option<Matrix3>,
    /// Camera 2 from camera 1; zeros (not a rotation) are stored when absent, as COLMAP does.
    pub pose: Option<RelativePose>,
}

impl TwoViewGeometry {
    /// A pair verified by `config` with these inliers and no matrices.
    pub fn new(
        image_id1: u32,
        image_id2: u32,
        inliers: Vec<[u32; 2]>,
        config: GeometryConfig,
    ) -> Self {
        Self {
            image_id1,
            image_id2,
            inliers,
            config,
            f: None,
            e: None,
            h: None,
            pose: None,
        }
    }

    /// What [`crate::verify`] found for a pair, as COLMAP stores it: images `image_id1` (whose
    /// keypoints the matches' `query` indexes) and `image_id2` (`train`), the matches verification
    /// kept as inliers, F and H in COLMAP's pixel convention
    /// ([`crate::verify::TwoViewGeometry::in_colmap_pixels`]), E as it is; no relative pose (COLMAP
    /// 3.8's mapper reads only the inliers and the configuration).
    ///
    /// An inlier index that is not one of `matches` is [`ColmapError::InvalidGeometry`].
    pub fn from_verified(
        image_id1: u32,
        image_id2: u32,
        matches: &[Match],
        verified: &crate::verify::TwoViewGeometry,
    ) -> Result<Self, ColmapError> {
        let inliers = verified
            .inliers
            .iter()
            .map(|&m| {
                matches.get(m as usize).map(|m| [m.query, m.train]).ok_or(
                    ColmapError::InvalidGeometry {
                        image_id1,
                        image_id2,
                        reason: "an inlier is not one of the pair's matches",
                    },
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let in_colmap = verified.in_colmap_pixels();
        Ok(Self {
            f: in_colmap.f,
            e: in_colmap.e,
            h: in_colmap.h,
            ..Self::new(image_id1, image_id2, inliers, verified.config)
        })
    }

    /// COLMAP's id of the pair.
    pub fn pair_id(&self) -> u64 {
        pair_id(self.image_id1, self.image_id2)
    }

    /// The same geometry with the images the other way round (COLMAP's `TwoViewGeometry::Invert`).
    /// Fails when `h` is singular or not finite.
    pub fn inverted(&self) -> Result<Self, ColmapError> {
        let h = self
            .h
            .map(|h| {
                invert(&h).ok_or(ColmapError::InvalidGeometry {
                    image_id1: self.image_id1,
                    image_id2: self.image_id2,
                    reason: "the homography is singular, so it cannot be turned round",
                })
            })
            .transpose()?;
        Ok(Self {
            image_id1: self.image_id2,
            image_id2: self.image_id1,
            inliers: self.inliers.iter().map(|&[a, b]| [b, a]).collect(),
            config: self.config,
            f: self.f.map(|m| transpose(&m)),
            e: self.e.map(|m| transpose(&m)),
            h,
            pose: self.pose.map(|p| p.inverse()),
        })
    }

    /// The same geometry with the smaller image id first: the orientation COLMAP stores.
    pub fn in_colmap_order(&self) -> Result<Self, ColmapError> {
        if self.image_id1 > self.image_id2 {
            self.inverted()
        } else {
            Ok(self.clone())
        }
    }

    /// Checks what needs no database: two different images, finite matrices and pose.
    pub fn check(&self) -> Result<(), ColmapError> {
        let bad = |reason| ColmapError::InvalidGeometry {
            image_id1: self.image_id1,
            image_id2: self.image_id2,
            reason,
        };
        if self.image_id1 == self.image_id2 {
            return Err(ColmapError::SamePair {
                image_id: self.image_id1,
            });
        }
        let matrices = [self.f, self.e, self.h];
        if matrices
            .iter()
            .flatten()
            .flatten()
            .flatten()
            .any(|v| !v.is_finite())
        {
            return Err(bad("a matrix holds a value that is not finite"));
        }
        if let Some(pose) = self.pose {
            if pose.qvec.iter().chain(&pose.tvec).any(|v| !v.is_finite()) {
                return Err(bad("the pose holds a value that is not finite"));
            }
            let norm = pose.qvec.iter().map(|v| v * v).sum::<f64>().sqrt();
            if (norm - 1.0).abs() > 1e-6 {
                return Err(bad("the pose's quaternion is not of unit length"));
            }
        }
        Ok(())
    }
}

/// The blobs of one `two_view_geometries` row, in COLMAP's orientation (smaller id first). A pair
/// without inliers has NULL in every blob column, as COLMAP binds its empty matrices (a null data
/// pointer).
pub(crate) struct TwoViewBlobs {
    pub inliers: Option<Vec<u8>>,
    pub f: Option<Vec<u8>>,
    pub e: Option<Vec<u8>>,
    pub h: Option<Vec<u8>>,
    pub qvec: Option<Vec<u8>>,
    pub tvec: Option<Vec<u8>>,
}

impl TwoViewBlobs {
    /// The blobs of a geometry already in COLMAP's order (see [`TwoViewGeometry::in_colmap_order`]).
    pub(crate) fn of(geometry: &TwoViewGeometry) -> Self {
        if geometry.inliers.is_empty() {
            return Self {
                inliers: None,
                f: None,
                e: None,
                h: None,
                qvec: None,
                tvec: None,
            };
        }
        let inliers = geometry
            .inliers
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let zero = [[0.0; 3]; 3];
        let pose = geometry.pose.unwrap_or(RelativePose {
            qvec: [0.0; 4],
            tvec: [0.0; 3],
        });
        Self {
            inliers: Some(inliers),
            f: Some(matrix_blob(&geometry.f.unwrap_or(zero))),
            e: Some(matrix_blob(&geometry.e.unwrap_or(zero))),
            h: Some(matrix_blob(&geometry.h.unwrap_or(zero))),
            qvec: Some(f64s_blob(&pose.qvec)),
            tvec: Some(f64s_blob(&pose.tvec)),
        }
    }
}

/// Nine little-endian float64, row-major.
pub fn matrix_blob(m: &Matrix3) -> Vec<u8> {
    f64s_blob(m.as_flattened())
}

/// The matrix of a 72-byte row-major float64 blob; `None` for any other length (COLMAP's empty
/// blob of a pair without inliers included).
pub fn matrix_of_blob(blob: &[u8]) -> Option<Matrix3> {
    let v = f64s_of_blob(blob);
    (v.len() == 9).then(|| [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]])
}

/// Little-endian float64 values, as COLMAP's blobs hold them.
pub fn f64s_blob(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The float64 values of a blob (a trailing partial value is ignored).
pub fn f64s_of_blob(blob: &[u8]) -> Vec<f64> {
    blob.chunks_exact(8)
        .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
        .collect()
}

fn transpose(m: &Matrix3) -> Matrix3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[c][r]))
}

/// The inverse by cofactors; `None` when singular or not finite.
fn invert(m: &Matrix3) -> Option<Matrix3> {
    let cofactor = |r: usize, c: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
        m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1]
    };
    let det = (0..3).map(|c| m[0][c] * cofactor(0, c)).sum::<f64>();
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // The inverse is the transposed cofactor matrix over the determinant.
    Some([0, 1, 2].map(|r| [0, 1, 2].map(|c| cofactor(c, r) / det)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn multiply(a: &Matrix3, b: &Matrix3) -> Matrix3 {
        [0, 1, 2].map(|r| [0, 1, 2].map(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
    }

    #[test]
    fn configuration_codes_are_colmaps() {
        for (code, config) in GeometryConfig::ALL.iter().enumerate() {
            assert_eq!(i64::from(config.colmap_code()), code as i64);
            assert_eq!(GeometryConfig::from_colmap_code(code as i64), Some(*config));
        }
        assert_eq!(GeometryConfig::Uncalibrated.colmap_code(), 3);
        assert_eq!(GeometryConfig::from_colmap_code(-1), None);
    }

    #[test]
    fn matrices_are_stored_row_major() {
        let m = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]];
        let blob = matrix_blob(&m);
        assert_eq!(blob.len(), 72);
        assert_eq!(
            f64s_of_blob(&blob),
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
        );
        assert_eq!(matrix_of_blob(&blob), Some(m));
        assert_eq!(matrix_of_blob(&[]), None);
    }

    #[test]
    fn turning_a_pair_round_swaps_transposes_and_inverts() {
        let h = [[1.1, 0.02, 5.0], [-0.03, 0.95, -2.0], [1e-4, 2e-5, 1.0]];
        let f = [[0.0, -1e-6, 3e-4], [2e-6, 0.0, -4e-3], [-5e-4, 3e-3, 1.0]];
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let geometry = TwoViewGeometry {
            f: Some(f),
            h: Some(h),
            pose: Some(RelativePose {
                qvec: [half, 0.0, half, 0.0],
                tvec: [1.0, 2.0, 3.0],
            }),
            ..TwoViewGeometry::new(5, 2, vec![[7, 1], [3, 4]], GeometryConfig::Planar)
        };
        let turned = geometry.in_colmap_order().unwrap();
        assert_eq!((turned.image_id1, turned.image_id2), (2, 5));
        assert_eq!(turned.inliers, [[1, 7], [4, 3]]);
        assert_eq!(turned.f.unwrap()[0][2], f[2][0]);
        let identity = multiply(&h, &turned.h.unwrap());
        for (r, row) in identity.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                assert!(
                    (v - f64::from(u8::from(r == c))).abs() < 1e-12,
                    "{identity:?}"
                );
            }
        }
        // X1 = R⁻¹ (X2 − t): the camera-2 origin maps to −R⁻¹ t.
        let back = turned.pose.unwrap().inverse();
        for (a, b) in back.tvec.iter().zip([1.0, 2.0, 3.0]) {
            assert!((a - b).abs() < 1e-12);
        }
        assert_eq!(pair_id(2, 5), turned.pair_id());
        assert_eq!(
            geometry
                .in_colmap_order()
                .unwrap()
                .in_colmap_order()
                .unwrap(),
            turned
        );
    }

    #[test]
    fn a_singular_homography_cannot_be_turned_round() {
        let geometry = TwoViewGeometry {
            h: Some([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]),
            ..TwoViewGeometry::new(3, 1, vec![], GeometryConfig::Planar)
        };
        assert!(matches!(
            geometry.in_colmap_order(),
            Err(ColmapError::InvalidGeometry { .. })
        ));
    }

    #[test]
    fn a_pair_without_inliers_has_null_blobs() {
        let empty = TwoViewGeometry::new(1, 2, vec![], GeometryConfig::Degenerate);
        let blobs = TwoViewBlobs::of(&empty);
        assert!(blobs.inliers.is_none() && blobs.f.is_none() && blobs.h.is_none());
        assert!(blobs.qvec.is_none() && blobs.tvec.is_none());
        let one = TwoViewGeometry::new(1, 2, vec![[0, 1]], GeometryConfig::Uncalibrated);
        let blobs = TwoViewBlobs::of(&one);
        assert_eq!(blobs.inliers.unwrap(), [0, 0, 0, 0, 1, 0, 0, 0]);
        assert_eq!(f64s_of_blob(&blobs.qvec.unwrap()), [0.0; 4]);
        assert_eq!(f64s_of_blob(&blobs.f.unwrap()), [0.0; 9]);
    }
}

//! Planar homographies in `f64`: the ground truth that matches between two views of a plane are
//! checked against (`clatch match --homography`, the evaluation harness), read from the Oxford and
//! HPatches text files or OpenCV's XML; and [`warp`], which makes such a second view of an image.
//!
//! ```
//! use clatch::homography::Homography;
//! use clatch::KeyPoint;
//!
//! let h: Homography = "1 0 5\n0 1 -2\n0 0 1".parse()?; // A's pixels to B's: a shift
//! assert_eq!(h.apply(10.0, 10.0), Some((15.0, 8.0)));
//! assert_eq!(h.transfer_error(&KeyPoint::new(10.0, 10.0), &KeyPoint::new(15.0, 11.0)), 3.0);
//! # Ok::<(), clatch::homography::ParseHomographyError>(())
//! ```

mod parse;
mod warp;

use crate::keypoint::KeyPoint;

pub use parse::ParseHomographyError;
pub use warp::{FILL, warp};

/// A projective map of the plane: `(x, y) -> ((h00 x + h01 y + h02) / w, (h10 x + h11 y + h12) / w)`
/// with `w = h20 x + h21 y + h22`. Pixel centres sit at integer coordinates, as in [`KeyPoint`].
///
/// `Display` writes the Oxford text format (three rows of three numbers) with every digit, so the
/// text parses back ([`str::parse`]) to the same matrix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography([[f64; 3]; 3]);

impl Homography {
    /// The map of a row-major 3x3 matrix.
    pub fn from_rows(rows: [[f64; 3]; 3]) -> Self {
        Self(rows)
    }

    /// The matrix, row-major.
    pub fn rows(&self) -> [[f64; 3]; 3] {
        self.0
    }

    /// The identity map.
    pub fn identity() -> Self {
        Self([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    }

    /// Translation by `(dx, dy)`.
    pub fn translation(dx: f64, dy: f64) -> Self {
        Self([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])
    }

    /// Rotation by `degrees` (from +x towards +y, clockwise on screen) and uniform scaling about the
    /// origin.
    pub fn rotation_scale(degrees: f64, scale: f64) -> Self {
        let (s, c) = degrees.to_radians().sin_cos();
        Self([
            [scale * c, -scale * s, 0.0],
            [scale * s, scale * c, 0.0],
            [0.0, 0.0, 1.0],
        ])
    }

    /// A pure perspective term: `w = 1 + px x + py y`.
    pub fn perspective(px: f64, py: f64) -> Self {
        Self([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [px, py, 1.0]])
    }

    /// The map `self ∘ other`: first `other`, then `self`.
    pub fn after(&self, other: &Homography) -> Homography {
        let (a, b) = (&self.0, &other.0);
        let mut m = [[0.0; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        Homography(m)
    }

    /// This map applied about the centre of a `width` x `height` image instead of about the origin.
    pub fn about_centre(&self, width: usize, height: usize) -> Homography {
        let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
        Homography::translation(cx, cy)
            .after(self)
            .after(&Homography::translation(-cx, -cy))
            .normalized()
    }

    /// The same map scaled so that `h22 = 1` (when `h22` is not tiny).
    pub fn normalized(&self) -> Homography {
        let h22 = self.0[2][2];
        if h22.abs() < 1e-12 {
            return *self;
        }
        Homography(self.0.map(|row| row.map(|v| v / h22)))
    }

    /// Where `(x, y)` goes; `None` when it goes to infinity (`w` is zero).
    pub fn apply(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let m = &self.0;
        let w = m[2][0] * x + m[2][1] * y + m[2][2];
        if w.abs() < 1e-12 || !w.is_finite() {
            return None;
        }
        let u = (m[0][0] * x + m[0][1] * y + m[0][2]) / w;
        let v = (m[1][0] * x + m[1][1] * y + m[1][2]) / w;
        (u.is_finite() && v.is_finite()).then_some((u, v))
    }

    /// Distance in pixels between where this map sends `from` and the keypoint `to`: a match's
    /// reprojection error when the map takes the query image to the train image. Infinite when
    /// `from` goes to infinity.
    pub fn transfer_error(&self, from: &KeyPoint, to: &KeyPoint) -> f64 {
        match self.apply(from.x as f64, from.y as f64) {
            Some((u, v)) => (u - to.x as f64).hypot(v - to.y as f64),
            None => f64::INFINITY,
        }
    }

    /// Determinant of the matrix.
    pub fn determinant(&self) -> f64 {
        let m = &self.0;
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    /// The inverse map, or `None` for a (numerically) singular matrix: a determinant of zero, or an
    /// inverse whose product with the matrix is not the identity to within `1e-8` of the magnitudes
    /// the product sums (the backward check, which a large translation or scale alone passes).
    pub fn inverse(&self) -> Option<Homography> {
        let m = &self.0;
        let det = self.determinant();
        if !det.is_finite() || det == 0.0 {
            return None;
        }
        // Adjugate (transposed cofactors) over the determinant.
        let cof = |r0: usize, r1: usize, c0: usize, c1: usize| {
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        let adj = [
            [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
            [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
            [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
        ];
        let inv = adj.map(|row| row.map(|v| v / det));
        let columns: [[f64; 3]; 3] = std::array::from_fn(|j| m.map(|row| row[j]));
        for (i, row) in inv.iter().enumerate() {
            for (j, column) in columns.iter().enumerate() {
                let (sum, magnitude) = row
                    .iter()
                    .zip(column)
                    .fold((0.0f64, 0.0f64), |(s, a), (r, c)| {
                        (s + r * c, a + (r * c).abs())
                    });
                let identity = if i == j { 1.0 } else { 0.0 };
                if !sum.is_finite() || (sum - identity).abs() > 1e-8 * magnitude.max(1.0) {
                    return None;
                }
            }
        }
        Some(Homography(inv).normalized())
    }
}

impl std::fmt::Display for Homography {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Rust prints the shortest decimal that reads back to the same `f64`.
        for row in &self.0 {
            writeln!(f, "{} {} {}", row[0], row[1], row[2])?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: (f64, f64), b: (f64, f64)) -> bool {
        (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9
    }

    /// Rotation by 30 degrees and scaling by 0.9 about the centre of a 512x512 image, slightly tilted.
    fn tilted() -> Homography {
        Homography::perspective(1.2e-4, -0.8e-4)
            .after(&Homography::rotation_scale(30.0, 0.9))
            .about_centre(512, 512)
    }

    #[test]
    fn apply_known_points() {
        let t = Homography::translation(5.0, -2.0);
        assert_eq!(t.apply(1.0, 1.0), Some((6.0, -1.0)));
        let r = Homography::rotation_scale(90.0, 2.0);
        assert!(close(r.apply(1.0, 0.0).unwrap(), (0.0, 2.0)));
        assert!(close(r.apply(0.0, 1.0).unwrap(), (-2.0, 0.0)));
        let p = Homography::perspective(0.5, 0.0);
        assert!(close(p.apply(2.0, 4.0).unwrap(), (1.0, 2.0)));
        // The line w = 0 goes to infinity.
        assert_eq!(p.apply(-2.0, 0.0), None);
    }

    #[test]
    fn about_centre_turns_about_the_middle_pixel() {
        // 101x81: the centre is pixel (50, 40); a quarter turn sends 10 px right to 10 px down.
        let h = Homography::rotation_scale(90.0, 1.0).about_centre(101, 81);
        assert!(close(h.apply(50.0, 40.0).unwrap(), (50.0, 40.0)));
        assert!(close(h.apply(60.0, 40.0).unwrap(), (50.0, 50.0)));
        let half = Homography::rotation_scale(0.0, 0.5).about_centre(101, 81);
        assert!(close(half.apply(60.0, 30.0).unwrap(), (55.0, 35.0)));
    }

    #[test]
    fn inverse_round_trips() {
        let h = tilted();
        let inv = h.inverse().unwrap();
        for &(x, y) in &[(0.0, 0.0), (255.5, 255.5), (511.0, 0.0), (100.0, 400.0)] {
            let (u, v) = h.apply(x, y).unwrap();
            let back = inv.apply(u, v).unwrap();
            assert!(close(back, (x, y)), "{x},{y} -> {u},{v} -> {back:?}");
        }
        let id = h.after(&inv).normalized();
        for (i, row) in id.rows().iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-12, "{id:?}");
            }
        }
        let singular = Homography::from_rows([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]);
        assert_eq!(singular.inverse(), None);
        assert_eq!(Homography::from_rows([[0.0; 3]; 3]).inverse(), None);
        // A large translation or scale is not singular: the inverse maps back.
        for shift in [1e4, 1e6, 1e9] {
            let h = Homography::from_rows([[1.0, 0.0, shift], [0.0, 1.0, -shift], [0.0, 0.0, 1.0]]);
            let back = h.inverse().expect("a translation inverts");
            let (fx, fy) = h.apply(3.0, 4.0).unwrap();
            let (x, y) = back.apply(fx, fy).unwrap();
            assert!(
                (x - 3.0).abs() < 1e-3 && (y - 4.0).abs() < 1e-3,
                "{shift}: {x} {y}"
            );
        }
        let tiny = Homography::from_rows([[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1.0]]);
        assert!(
            tiny.inverse().is_some(),
            "a 1e-6 scale is a valid (if extreme) map"
        );
    }

    #[test]
    fn transfer_error_is_the_distance_to_the_projection() {
        // Scale by 2 about the origin: (10, 5) goes to (20, 10); (23, 14) is 5 px from it.
        let h = Homography::rotation_scale(0.0, 2.0);
        let a = KeyPoint::new(10.0, 5.0);
        assert_eq!(h.transfer_error(&a, &KeyPoint::new(20.0, 10.0)), 0.0);
        assert_eq!(h.transfer_error(&a, &KeyPoint::new(23.0, 14.0)), 5.0);
        // A point sent to infinity is infinitely far from everything.
        let p = Homography::perspective(0.5, 0.0);
        let e = p.transfer_error(&KeyPoint::new(-2.0, 0.0), &KeyPoint::new(0.0, 0.0));
        assert!(e.is_infinite());
    }

    #[test]
    fn display_reads_back_exactly() {
        let h = tilted();
        assert_eq!(h.to_string().parse::<Homography>().unwrap(), h);
        assert_eq!(
            Homography::translation(5.0, -2.5).to_string(),
            "1 0 5\n0 1 -2.5\n0 0 1\n"
        );
    }
}

//! 3x3 planar homographies in `f64`: building, applying, inverting, reading from a file.

use std::path::Path;

use crate::error::CliError;

/// A projective map of the plane: `(x, y) -> ((h00 x + h01 y + h02) / w, (h10 x + h11 y + h12) / w)`
/// with `w = h20 x + h21 y + h22`. Pixel centres sit at integer coordinates, as in [`clatch::KeyPoint`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography(pub [[f64; 3]; 3]);

impl Homography {
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

    /// Determinant of the matrix.
    pub fn determinant(&self) -> f64 {
        let m = &self.0;
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    /// The inverse map, or `None` for a (numerically) singular matrix.
    pub fn inverse(&self) -> Option<Homography> {
        let m = &self.0;
        let det = self.determinant();
        let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        if !det.is_finite() || scale == 0.0 || det.abs() <= 1e-12 * scale.powi(3) {
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
        Some(Homography(adj.map(|row| row.map(|v| v / det))).normalized())
    }

    /// Parses nine whitespace-separated numbers, row-major (the Oxford `H1to2p` format).
    pub fn parse(text: &str) -> Result<Homography, String> {
        let mut values = Vec::with_capacity(9);
        for token in text.split_whitespace() {
            let v: f64 = token
                .parse()
                .map_err(|_| format!("`{}` is not a number", token.escape_debug()))?;
            if !v.is_finite() {
                return Err(format!("`{}` is not a finite number", token.escape_debug()));
            }
            values.push(v);
        }
        if values.len() != 9 {
            return Err(format!(
                "expected 9 numbers (a 3x3 matrix), found {}",
                values.len()
            ));
        }
        let mut m = [[0.0; 3]; 3];
        for (i, v) in values.into_iter().enumerate() {
            m[i / 3][i % 3] = v;
        }
        let h = Homography(m);
        if h.inverse().is_none() {
            return Err("the matrix is singular".into());
        }
        Ok(h)
    }

    /// Parses a 3x3 matrix from an OpenCV FileStorage XML file (as OpenCV's sample `H1to3p.xml`):
    /// the first `opencv-matrix` element must have 3 rows, 3 columns and its nine numbers in `<data>`.
    pub fn parse_opencv_xml(text: &str) -> Result<Homography, String> {
        let element = |tag: &str| -> Result<&str, String> {
            let (open, close) = (format!("<{tag}>"), format!("</{tag}>"));
            let start = text
                .find(&open)
                .ok_or_else(|| format!("no <{tag}> element"))?
                + open.len();
            let len = text[start..]
                .find(&close)
                .ok_or_else(|| format!("<{tag}> is not closed"))?;
            Ok(text[start..start + len].trim())
        };
        for (tag, want) in [("rows", "3"), ("cols", "3")] {
            let found = element(tag)?;
            if found != want {
                return Err(format!("<{tag}> is {found}, expected {want}"));
            }
        }
        Homography::parse(element("data")?)
    }

    /// Reads and parses a homography file: nine numbers (the Oxford format), or OpenCV FileStorage
    /// XML when the file starts with `<?xml` or `<opencv_storage>`. Only a regular file of at most
    /// [`crate::text_input::MAX_TEXT_BYTES`] is read; a UTF-8 byte-order mark is skipped.
    pub fn from_file(path: &Path) -> Result<Homography, CliError> {
        let text = crate::text_input::read_text(path, "homography")?;
        let start = text.trim_start();
        let parsed = if start.starts_with("<?xml") || start.starts_with("<opencv_storage>") {
            Homography::parse_opencv_xml(&text)
        } else {
            Homography::parse(&text)
        };
        parsed.map_err(|reason| CliError::Homography {
            path: path.to_path_buf(),
            reason,
        })
    }
}

/// `inner` applied about the centre of a `width` x `height` image instead of about the origin.
pub fn about_centre(width: usize, height: usize, inner: &Homography) -> Homography {
    let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    Homography::translation(cx, cy)
        .after(inner)
        .after(&Homography::translation(-cx, -cy))
        .normalized()
}

/// The demo's fixed second view of a `width` x `height` image: rotation by 30 degrees and scaling by
/// 0.9 about the centre, with a slight perspective tilt; the centre stays put.
pub fn demo_homography(width: usize, height: usize) -> Homography {
    // Perspective in centred coordinates: w varies by about ±5 % across a 512-pixel image.
    let tilt = Homography::perspective(1.2e-4, -0.8e-4);
    about_centre(
        width,
        height,
        &tilt.after(&Homography::rotation_scale(30.0, 0.9)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OpenCV's sample `H1to3p.xml` in shape (values shortened).
    const OPENCV_XML: &str = "<?xml version=\"1.0\"?>\n<opencv_storage>\n\
        <H13 type_id=\"opencv-matrix\">\n  <rows>3</rows>\n  <cols>3</cols>\n  <dt>d</dt>\n\
        <data>\n\t2.0e+00 0. 1.5e+01\n\t0. 2. -4.\n\t0. 0. 1. </data></H13>\n</opencv_storage>\n";

    #[test]
    fn parses_opencv_xml() {
        let h = Homography::parse_opencv_xml(OPENCV_XML).unwrap();
        // (x, y) -> (2 x + 15, 2 y - 4).
        assert_eq!(h.apply(1.0, 3.0), Some((17.0, 2.0)));
        let wrong_rows = OPENCV_XML.replace("<rows>3</rows>", "<rows>2</rows>");
        assert!(
            Homography::parse_opencv_xml(&wrong_rows)
                .unwrap_err()
                .contains("<rows> is 2")
        );
        let no_data = OPENCV_XML.replace("</data>", "");
        assert!(
            Homography::parse_opencv_xml(&no_data)
                .unwrap_err()
                .contains("not closed")
        );
        let short = OPENCV_XML.replace("0. 0. 1. ", "0. 0.");
        assert!(
            Homography::parse_opencv_xml(&short)
                .unwrap_err()
                .contains("9")
        );
    }

    #[test]
    fn from_file_reads_both_formats_and_names_bad_files() {
        let dir = std::env::temp_dir().join(format!("clatch-h-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (xml, txt, bad) = (dir.join("h.xml"), dir.join("H1to3p"), dir.join("bad"));
        std::fs::write(&xml, OPENCV_XML).unwrap();
        std::fs::write(&txt, "2 0 15\n0 2 -4\n0 0 1\n").unwrap();
        std::fs::write(&bad, "<opencv_storage><rows>3</rows></opencv_storage>").unwrap();
        let from_xml = Homography::from_file(&xml).unwrap();
        assert_eq!(from_xml, Homography::from_file(&txt).unwrap());
        let e = Homography::from_file(&bad).unwrap_err();
        assert!(matches!(e, CliError::Homography { .. }), "{e}");
        assert!(e.to_string().contains("bad"), "{e}");
        let e = Homography::from_file(&dir.join("missing")).unwrap_err();
        assert!(matches!(e, CliError::Read { .. }), "{e}");
        // Saved by an editor that writes a byte-order mark: read as the same matrix.
        let bom = dir.join("H-bom");
        std::fs::write(&bom, "\u{feff}2 0 15\n0 2 -4\n0 0 1\n").unwrap();
        assert_eq!(Homography::from_file(&bom).unwrap(), from_xml);
        // An invisible character elsewhere is shown escaped.
        std::fs::write(&bom, "2 0 15\n0 2\u{200b} -4\n0 0 1\n").unwrap();
        let e = Homography::from_file(&bom).unwrap_err().to_string();
        assert!(e.contains("`2\\u{200b}`"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    fn close(a: (f64, f64), b: (f64, f64)) -> bool {
        (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9
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
    fn inverse_round_trips() {
        let h = demo_homography(512, 512);
        let inv = h.inverse().unwrap();
        for &(x, y) in &[(0.0, 0.0), (255.5, 255.5), (511.0, 0.0), (100.0, 400.0)] {
            let (u, v) = h.apply(x, y).unwrap();
            let back = inv.apply(u, v).unwrap();
            assert!(close(back, (x, y)), "{x},{y} -> {u},{v} -> {back:?}");
        }
        let id = h.after(&inv).normalized();
        for (i, row) in id.0.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-12, "{id:?}");
            }
        }
        let singular = Homography([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]);
        assert_eq!(singular.inverse(), None);
    }

    #[test]
    fn demo_homography_keeps_the_centre_and_rotates() {
        let h = demo_homography(512, 512);
        assert!(close(h.apply(255.5, 255.5).unwrap(), (255.5, 255.5)));
        // A step to the right turns by about 30 degrees and shrinks by about 0.9.
        let (u, v) = h.apply(265.5, 255.5).unwrap();
        let (dx, dy) = (u - 255.5, v - 255.5);
        assert!((dy.atan2(dx).to_degrees() - 30.0).abs() < 1.0);
        assert!((dx.hypot(dy) - 9.0).abs() < 0.1);
    }

    #[test]
    fn parses_oxford_format() {
        let text = "   1.0 0 5\n0 1 -2.5e0\n  0 0 1  \n";
        let h = Homography::parse(text).unwrap();
        assert_eq!(h.apply(0.0, 0.0), Some((5.0, -2.5)));
        assert!(
            Homography::parse("1 0 0 0 1 0 0 0")
                .unwrap_err()
                .contains("9")
        );
        assert!(
            Homography::parse("1 0 0 0 1 0 0 0 x")
                .unwrap_err()
                .contains("`x`")
        );
        assert!(Homography::parse("1 0 0 0 1 0 0 0 inf").is_err());
        assert!(
            Homography::parse("0 0 0 0 0 0 0 0 0")
                .unwrap_err()
                .contains("singular")
        );
    }
}

//! Reading a homography from text: nine numbers, row-major (the Oxford `H1to2p` and HPatches `H_1_2`
//! files), or OpenCV FileStorage XML (OpenCV's sample `H1to3p.xml`).

use std::str::FromStr;

use super::Homography;

/// Why a text is not a homography.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{reason}")]
pub struct ParseHomographyError {
    reason: String,
}

impl ParseHomographyError {
    fn new(reason: impl Into<String>) -> Self {
        Self {
            reason: reason.into(),
        }
    }
}

/// The UTF-8 byte-order mark some editors write at the start of a file.
const BOM: char = '\u{feff}';

impl FromStr for Homography {
    type Err = ParseHomographyError;

    /// OpenCV FileStorage XML when the text starts with `<?xml` or `<opencv_storage>`, else nine
    /// whitespace-separated finite numbers; a leading byte-order mark is skipped, and a singular
    /// matrix is refused.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let text = text.strip_prefix(BOM).unwrap_or(text);
        let start = text.trim_start();
        if start.starts_with("<?xml") || start.starts_with("<opencv_storage>") {
            nine_numbers(opencv_xml_data(text)?)
        } else {
            nine_numbers(text)
        }
    }
}

/// Nine whitespace-separated numbers, row-major, forming an invertible matrix.
fn nine_numbers(text: &str) -> Result<Homography, ParseHomographyError> {
    let mut values = Vec::with_capacity(9);
    for token in text.split_whitespace() {
        let v: f64 = token.parse().map_err(|_| {
            ParseHomographyError::new(format!("`{}` is not a number", token.escape_debug()))
        })?;
        if !v.is_finite() {
            return Err(ParseHomographyError::new(format!(
                "`{}` is not a finite number",
                token.escape_debug()
            )));
        }
        values.push(v);
    }
    if values.len() != 9 {
        return Err(ParseHomographyError::new(format!(
            "expected 9 numbers (a 3x3 matrix), found {}",
            values.len()
        )));
    }
    let mut m = [[0.0; 3]; 3];
    for (i, v) in values.into_iter().enumerate() {
        m[i / 3][i % 3] = v;
    }
    let h = Homography(m);
    if h.inverse().is_none() {
        return Err(ParseHomographyError::new("the matrix is singular"));
    }
    Ok(h)
}

/// The `<data>` of the first `opencv-matrix` element, which must have 3 rows and 3 columns.
fn opencv_xml_data(text: &str) -> Result<&str, ParseHomographyError> {
    let element = |tag: &str| -> Result<&str, ParseHomographyError> {
        let (open, close) = (format!("<{tag}>"), format!("</{tag}>"));
        let start = text
            .find(&open)
            .ok_or_else(|| ParseHomographyError::new(format!("no <{tag}> element")))?
            + open.len();
        let len = text[start..]
            .find(&close)
            .ok_or_else(|| ParseHomographyError::new(format!("<{tag}> is not closed")))?;
        Ok(text[start..start + len].trim())
    };
    for (tag, want) in [("rows", "3"), ("cols", "3")] {
        let found = element(tag)?;
        if found != want {
            return Err(ParseHomographyError::new(format!(
                "<{tag}> is {found}, expected {want}"
            )));
        }
    }
    element("data")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OpenCV's sample `H1to3p.xml` in shape (values shortened).
    const OPENCV_XML: &str = "<?xml version=\"1.0\"?>\n<opencv_storage>\n\
        <H13 type_id=\"opencv-matrix\">\n  <rows>3</rows>\n  <cols>3</cols>\n  <dt>d</dt>\n\
        <data>\n\t2.0e+00 0. 1.5e+01\n\t0. 2. -4.\n\t0. 0. 1. </data></H13>\n</opencv_storage>\n";

    fn reason(text: &str) -> String {
        text.parse::<Homography>().unwrap_err().to_string()
    }

    #[test]
    fn parses_opencv_xml() {
        let h: Homography = OPENCV_XML.parse().unwrap();
        // (x, y) -> (2 x + 15, 2 y - 4).
        assert_eq!(h.apply(1.0, 3.0), Some((17.0, 2.0)));
        assert_eq!(h, "2 0 15\n0 2 -4\n0 0 1\n".parse().unwrap());
        let wrong_rows = OPENCV_XML.replace("<rows>3</rows>", "<rows>2</rows>");
        assert!(reason(&wrong_rows).contains("<rows> is 2"));
        assert!(reason(&OPENCV_XML.replace("</data>", "")).contains("not closed"));
        assert!(reason(&OPENCV_XML.replace("0. 0. 1. ", "0. 0.")).contains("found 8"));
        assert!(reason("<opencv_storage><rows>3</rows></opencv_storage>").contains("<cols>"));
    }

    #[test]
    fn parses_oxford_format() {
        let h: Homography = "   1.0 0 5\n0 1 -2.5e0\n  0 0 1  \n".parse().unwrap();
        assert_eq!(h.apply(0.0, 0.0), Some((5.0, -2.5)));
        assert!(reason("1 0 0 0 1 0 0 0").contains("found 8"));
        assert!(reason("1 0 0 0 1 0 0 0 x").contains("`x`"));
        assert!(reason("1 0 0 0 1 0 0 0 inf").contains("not a finite number"));
        assert!(reason("0 0 0 0 0 0 0 0 0").contains("singular"));
    }

    #[test]
    fn a_byte_order_mark_is_skipped_and_other_invisible_characters_are_shown() {
        let plain: Homography = "2 0 15\n0 2 -4\n0 0 1\n".parse().unwrap();
        assert_eq!("\u{feff}2 0 15\n0 2 -4\n0 0 1\n".parse(), Ok(plain));
        assert!(reason("2 0 15\n0 2\u{200b} -4\n0 0 1\n").contains("`2\\u{200b}`"));
    }
}

//! Whether a JPEG file holds its whole image: its marker structure is followed to the end-of-image
//! marker. The JPEG decoder fills missing data silently, so a truncated file would otherwise decode
//! into a partly gray picture without a word.

use std::io::{BufRead, ErrorKind};

/// Outcome of following a JPEG file's markers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum JpegEnd {
    /// The end-of-image marker (`FF D9`) is there.
    Complete,
    /// The data stops before the end-of-image marker; `bytes` is the file's length.
    Truncated { bytes: u64 },
}

/// A byte reader that counts what it consumed.
struct Scanner<R> {
    reader: R,
    offset: u64,
}

impl<R: BufRead> Scanner<R> {
    fn byte(&mut self) -> std::io::Result<Option<u8>> {
        let buf = fill(&mut self.reader)?;
        let Some(&b) = buf.first() else {
            return Ok(None);
        };
        self.reader.consume(1);
        self.offset += 1;
        Ok(Some(b))
    }

    /// Skips `n` bytes; `false` if the data ends first.
    fn skip(&mut self, mut n: u64) -> std::io::Result<bool> {
        while n > 0 {
            let available = fill(&mut self.reader)?.len();
            if available == 0 {
                return Ok(false);
            }
            let k = available.min(usize::try_from(n).unwrap_or(usize::MAX));
            self.reader.consume(k);
            self.offset += k as u64;
            n -= k as u64;
        }
        Ok(true)
    }

    /// Consumes everything up to and including the next `FF`; `false` if there is none.
    fn skip_past_ff(&mut self) -> std::io::Result<bool> {
        loop {
            let buf = fill(&mut self.reader)?;
            if buf.is_empty() {
                return Ok(false);
            }
            let (k, found) = match buf.iter().position(|&b| b == 0xFF) {
                Some(i) => (i + 1, true),
                None => (buf.len(), false),
            };
            self.reader.consume(k);
            self.offset += k as u64;
            if found {
                return Ok(true);
            }
        }
    }

    /// The marker code after an `FF` (fill bytes `FF` skipped); `None` at the end of the data.
    fn marker_code(&mut self) -> std::io::Result<Option<u8>> {
        loop {
            match self.byte()? {
                Some(0xFF) => continue,
                other => return Ok(other),
            }
        }
    }
}

/// `fill_buf`, retried when interrupted.
fn fill<R: BufRead>(reader: &mut R) -> std::io::Result<&[u8]> {
    loop {
        match reader.fill_buf() {
            Ok(_) => break,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        }
    }
    reader.fill_buf()
}

/// Follows the markers of the JPEG data in `reader` (which starts at the start-of-image marker):
/// length-prefixed segments are skipped whole (so an EXIF thumbnail's own end marker is never taken
/// for the image's), entropy-coded data is scanned for the next marker (`FF 00` is a stuffed byte,
/// `FF D0`..`FF D7` restart markers), until `FF D9`. Bytes between segments are skipped as libjpeg
/// does.
pub(crate) fn find_end(reader: impl BufRead) -> std::io::Result<JpegEnd> {
    let mut s = Scanner { reader, offset: 0 };
    let mut in_entropy_data = false;
    loop {
        let code = if in_entropy_data {
            loop {
                if !s.skip_past_ff()? {
                    return Ok(JpegEnd::Truncated { bytes: s.offset });
                }
                match s.marker_code()? {
                    None => return Ok(JpegEnd::Truncated { bytes: s.offset }),
                    Some(0x00 | 0xD0..=0xD7) => continue,
                    Some(code) => break code,
                }
            }
        } else {
            if !s.skip_past_ff()? {
                return Ok(JpegEnd::Truncated { bytes: s.offset });
            }
            match s.marker_code()? {
                None => return Ok(JpegEnd::Truncated { bytes: s.offset }),
                Some(code) => code,
            }
        };
        match code {
            0xD9 => return Ok(JpegEnd::Complete),
            // Start of image, restart and TEM markers stand alone.
            0xD8 | 0xD0..=0xD7 | 0x01 => continue,
            _ => {
                let (Some(hi), Some(lo)) = (s.byte()?, s.byte()?) else {
                    return Ok(JpegEnd::Truncated { bytes: s.offset });
                };
                let length = u16::from_be_bytes([hi, lo]);
                if !s.skip(u64::from(length.saturating_sub(2)))? {
                    return Ok(JpegEnd::Truncated { bytes: s.offset });
                }
                // Entropy-coded data follows a start-of-scan header, and ends at the next marker.
                in_entropy_data = code == 0xDA;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jpeg(width: u32, height: u32) -> Vec<u8> {
        let img = image::GrayImage::from_fn(width, height, |x, y| {
            image::Luma([((x * 7 + y * 13) % 251) as u8])
        });
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
            .encode_image(&img)
            .unwrap();
        out
    }

    #[test]
    fn a_whole_jpeg_is_complete_and_every_cut_is_truncated() {
        let data = jpeg(48, 40);
        assert_eq!(find_end(&data[..]).unwrap(), JpegEnd::Complete);
        // Trailing bytes after the end marker (some cameras append data) are fine.
        let mut trailing = data.clone();
        trailing.extend_from_slice(b"appended");
        assert_eq!(find_end(&trailing[..]).unwrap(), JpegEnd::Complete);
        for cut in [2, 20, data.len() / 2, data.len() - 1] {
            assert_eq!(
                find_end(&data[..cut]).unwrap(),
                JpegEnd::Truncated { bytes: cut as u64 },
                "cut at {cut}"
            );
        }
    }

    #[test]
    fn an_end_marker_inside_a_segment_does_not_count() {
        // An APP1 segment holding FF D9 (as an EXIF thumbnail does), then the file stops.
        let mut data = vec![0xFF, 0xD8, 0xFF, 0xE1, 0x00, 0x06, 0xFF, 0xD9, 0xFF, 0xD9];
        assert_eq!(
            find_end(&data[..]).unwrap(),
            JpegEnd::Truncated { bytes: 10 }
        );
        data.extend_from_slice(&[0xFF, 0xD9]);
        assert_eq!(find_end(&data[..]).unwrap(), JpegEnd::Complete);
    }
}

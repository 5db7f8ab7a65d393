//! Writing 2-D `uint8` arrays in NumPy's `.npy` format, version 1.0.
//!
//! Layout: the magic `\x93NUMPY`, version bytes `1, 0`, a little-endian `u16` header length, then an
//! ASCII Python dict literal padded with spaces and ended by `\n` so that the data starts at a multiple
//! of 64 bytes, then the data in C order.

use std::io::Write;

/// The six magic bytes every `.npy` file starts with.
pub const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// Alignment of the data start.
pub const ALIGN: usize = 64;

/// The preamble (magic, version, length, dict) of a C-order `uint8` array of `rows` x `cols`.
pub fn header_u8(rows: usize, cols: usize) -> Vec<u8> {
    let dict = format!("{{'descr': '|u1', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    // magic (6) + version (2) + header length (2) + dict + padding + '\n'
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let total = unpadded.div_ceil(ALIGN) * ALIGN;
    let header_len = total - MAGIC.len() - 4;
    let header_len16 = u16::try_from(header_len).expect("a 2-D shape fits a v1.0 header");
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&header_len16.to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.resize(total - 1, b' ');
    out.push(b'\n');
    out
}

/// Writes a `rows` x `cols` C-order `uint8` array; `data.len()` must be `rows * cols`.
pub fn write_u8(mut w: impl Write, data: &[u8], rows: usize, cols: usize) -> std::io::Result<()> {
    if data.len() != rows * cols {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{} bytes do not form a {rows}x{cols} array", data.len()),
        ));
    }
    w.write_all(&header_u8(rows, cols))?;
    w.write_all(data)?;
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_format() {
        for (rows, cols) in [(0, 64), (3, 32), (123_456_789, 1)] {
            let h = header_u8(rows, cols);
            assert_eq!(&h[..6], MAGIC);
            assert_eq!(&h[6..8], &[1, 0], "version 1.0");
            let len = u16::from_le_bytes([h[8], h[9]]) as usize;
            assert_eq!(10 + len, h.len());
            assert_eq!(h.len() % 64, 0, "data starts at a multiple of 64");
            assert_eq!(*h.last().unwrap(), b'\n');
            let dict = std::str::from_utf8(&h[10..]).unwrap();
            assert!(dict.is_ascii());
            assert_eq!(
                dict.trim_end(),
                format!("{{'descr': '|u1', 'fortran_order': False, 'shape': ({rows}, {cols}), }}")
            );
            // Only spaces between the dict and the final newline.
            let close = dict.rfind('}').unwrap();
            assert!(dict[close + 1..dict.len() - 1].bytes().all(|b| b == b' '));
        }
    }

    #[test]
    fn writes_header_then_data() {
        let mut buf = Vec::new();
        write_u8(&mut buf, &[1, 2, 3, 4, 5, 6], 2, 3).unwrap();
        // The dict is longer than 54 characters, so the data starts at byte 128, as NumPy's own.
        assert_eq!(header_u8(2, 3).len(), 128);
        assert_eq!(buf.len(), 128 + 6);
        assert_eq!(&buf[128..], &[1, 2, 3, 4, 5, 6]);
        assert!(write_u8(Vec::new(), &[1, 2, 3], 2, 2).is_err());
    }
}

//! Palette PNGs written chunk by chunk (the `image` crate writes none): IHDR, PLTE, one IDAT of stored
//! (uncompressed) zlib blocks, IEND. One file for the library's decode tests, `tests/hostile_files.rs`
//! and the command-line tool's tests, each including it with `#[path]`.

/// A `width` x `height` 8-bit palette PNG with the colours `palette` and the pixel indices
/// `index(x, y)` (which may point past the palette: that is what some tests want).
pub fn palette_png(
    width: u32,
    height: u32,
    palette: &[[u8; 3]],
    index: impl Fn(u32, u32) -> u8,
) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = [width.to_be_bytes(), height.to_be_bytes()].concat();
    ihdr.extend_from_slice(&[8, 3, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"PLTE", &palette.concat());
    // Each row: filter byte 0, then the indices.
    let mut rows = Vec::new();
    for y in 0..height {
        rows.push(0u8);
        rows.extend((0..width).map(|x| index(x, y)));
    }
    chunk(&mut out, b"IDAT", &stored_zlib(&rows));
    chunk(&mut out, b"IEND", &[]);
    out
}

/// zlib with stored (uncompressed) deflate blocks of at most 65535 bytes: no compression crate needed.
fn stored_zlib(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = data.chunks(65_535).collect();
    for (i, block) in blocks.iter().enumerate() {
        out.push(u8::from(i + 1 == blocks.len()));
        let len = block.len() as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(block);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &byte in data {
        a = (a + u32::from(byte)) % 65_521;
        b = (b + a) % 65_521;
    }
    out.extend_from_slice(&((b << 16) | a).to_be_bytes());
    out
}

/// Appends one chunk: length, kind, data, CRC-32 of kind and data.
fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32fast::hash(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

//! Palette PNGs whose pixels use indices past the end of their palette. The PNG decoder turns such
//! pixels black without a word; here the palette is extended with a colour the file's palette does not
//! hold (a sentinel), so that after decoding any pixel of that colour is a bad index.

/// The PNG signature.
const SIGNATURE: &[u8; 8] = b"\x89PNG\r\n\x1a\n";
/// PNG colour type of palette images.
const INDEXED: u8 = 3;

/// What the IHDR chunk says (the first chunk of every PNG).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Header {
    pub width: u32,
    pub height: u32,
    pub bit_depth: u8,
    pub colour_type: u8,
}

impl Header {
    /// The header of `start` (the file's first 33 bytes or more), `None` if it is not a PNG header.
    pub fn parse(start: &[u8]) -> Option<Header> {
        let rest = start.strip_prefix(SIGNATURE)?;
        if rest.get(4..8)? != b"IHDR" {
            return None;
        }
        let data = rest.get(8..21)?;
        let be = |i: usize| u32::from_be_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]);
        Some(Header {
            width: be(0),
            height: be(4),
            bit_depth: data[8],
            colour_type: data[9],
        })
    }

    /// Whether pixels can hold an index past a palette of `entries` colours.
    fn can_overflow(&self, entries: usize) -> bool {
        self.colour_type == INDEXED && self.bit_depth <= 8 && entries < 1 << self.bit_depth
    }
}

/// A palette PNG rewritten so that bad indices decode to a colour its palette does not hold.
pub(crate) struct WithSentinel {
    /// The rewritten file.
    pub png: Vec<u8>,
    /// The colour of every index past the original palette.
    pub sentinel: [u8; 3],
    /// Entries of the original palette.
    pub entries: usize,
}

/// The file rewritten with a sentinel colour for bad indices; `None` when the file cannot hold a bad
/// index (not a palette PNG, or its palette is full) or its chunks cannot be followed (the decoder
/// then reports the problem itself).
pub(crate) fn with_sentinel(png: &[u8]) -> Option<WithSentinel> {
    let header = Header::parse(png)?;
    if header.colour_type != INDEXED {
        return None;
    }
    let (start, end, palette) = find_plte(png)?;
    let entries = palette.len() / 3;
    if !header.can_overflow(entries) {
        return None;
    }
    let colours: Vec<&[u8]> = palette.chunks_exact(3).collect();
    // At most 255 entries, so one of these 256 colours is free.
    let sentinel = (0..=255u8)
        .map(|r| [r, 0x5A, 0xA5])
        .find(|c| !colours.contains(&&c[..]))?;
    let mut extended = palette[..entries * 3].to_vec();
    for _ in entries..1 << header.bit_depth {
        extended.extend_from_slice(&sentinel);
    }
    let mut out = Vec::with_capacity(png.len() + extended.len());
    out.extend_from_slice(&png[..start]);
    out.extend_from_slice(&(extended.len() as u32).to_be_bytes());
    let typed_start = out.len();
    out.extend_from_slice(b"PLTE");
    out.extend_from_slice(&extended);
    let crc = crc32fast::hash(&out[typed_start..]);
    out.extend_from_slice(&crc.to_be_bytes());
    out.extend_from_slice(&png[end..]);
    Some(WithSentinel {
        png: out,
        sentinel,
        entries,
    })
}

/// The byte range of the PLTE chunk (length to CRC) and its data.
fn find_plte(png: &[u8]) -> Option<(usize, usize, &[u8])> {
    let mut at = SIGNATURE.len();
    loop {
        let length = u32::from_be_bytes(png.get(at..at + 4)?.try_into().ok()?) as usize;
        let kind = png.get(at + 4..at + 8)?;
        let end = at.checked_add(12)?.checked_add(length)?;
        let data = png.get(at + 8..end - 4)?;
        match kind {
            b"PLTE" => return Some((at, end.min(png.len()), data)),
            b"IDAT" | b"IEND" => return None,
            _ => at = end,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_of_a_known_chunk() {
        // IEND's CRC, in every PNG file: the checksum written is PNG's.
        assert_eq!(crc32fast::hash(b"IEND"), 0xAE42_6082);
    }

    #[test]
    fn header_fields() {
        let mut png = SIGNATURE.to_vec();
        png.extend_from_slice(&13u32.to_be_bytes());
        png.extend_from_slice(b"IHDR");
        png.extend_from_slice(&200_000u32.to_be_bytes());
        png.extend_from_slice(&7u32.to_be_bytes());
        png.extend_from_slice(&[4, 3, 0, 0, 0]);
        assert_eq!(
            Header::parse(&png),
            Some(Header {
                width: 200_000,
                height: 7,
                bit_depth: 4,
                colour_type: 3
            })
        );
        assert_eq!(Header::parse(b"\x89PNG\r\n\x1a\nshort"), None);
        assert!(Header::parse(&png).unwrap().can_overflow(15));
        assert!(!Header::parse(&png).unwrap().can_overflow(16));
    }
}

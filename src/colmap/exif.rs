//! The one EXIF field a folder of photos is read for: the focal length in 35 mm film terms, from which
//! COLMAP too derives a focal length in pixels when a photo carries no better calibration.

/// EXIF tag of the pointer to the Exif sub-IFD (in IFD0).
const EXIF_IFD_POINTER: u16 = 0x8769;
/// EXIF tag `FocalLengthIn35mmFilm` (SHORT, millimetres; 0 means unknown).
const FOCAL_LENGTH_35MM: u16 = 0xA405;

/// `FocalLengthIn35mmFilm` from a raw EXIF block (a TIFF structure, as JPEG's APP1 carries it after
/// `Exif\0\0`), or `None` when it is absent, zero or the block is malformed.
pub fn focal_length_35mm(exif: &[u8]) -> Option<u16> {
    let tiff = exif.strip_prefix(b"Exif\0\0").unwrap_or(exif);
    let little = match tiff.get(..2)? {
        b"II" => true,
        b"MM" => false,
        _ => return None,
    };
    let u16_at = |at: usize| {
        let b: [u8; 2] = tiff.get(at..at + 2)?.try_into().ok()?;
        Some(if little {
            u16::from_le_bytes(b)
        } else {
            u16::from_be_bytes(b)
        })
    };
    let u32_at = |at: usize| {
        let b: [u8; 4] = tiff.get(at..at + 4)?.try_into().ok()?;
        Some(if little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    };
    // The value field (offset 8 of a 12-byte entry) of `tag` in the IFD at `ifd`.
    let find = |ifd: usize, tag: u16| {
        let count = usize::from(u16_at(ifd)?);
        (0..count)
            .map(|i| ifd + 2 + 12 * i)
            .find(|&entry| u16_at(entry) == Some(tag))
            .map(|entry| entry + 8)
    };
    let ifd0 = u32_at(4)? as usize;
    let exif_ifd = u32_at(find(ifd0, EXIF_IFD_POINTER)?)? as usize;
    let focal = u16_at(find(exif_ifd, FOCAL_LENGTH_35MM)?)?;
    (focal > 0).then_some(focal)
}

/// Focal length in pixels of a `width` x `height` photo from its 35 mm equivalent focal length: the
/// 36 mm side of the film frame maps to the photo's larger side.
pub fn focal_pixels(focal_35mm: u16, width: u32, height: u32) -> f64 {
    f64::from(focal_35mm) / 36.0 * f64::from(width.max(height))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little- or big-endian TIFF block: IFD0 with an Exif pointer, the Exif IFD with the focal.
    fn block(little: bool, focal: u16) -> Vec<u8> {
        let w16 = |v: u16| {
            if little {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            }
        };
        let w32 = |v: u32| {
            if little {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            }
        };
        let mut b = b"Exif\0\0".to_vec();
        b.extend(if little { b"II" } else { b"MM" });
        b.extend(w16(42));
        b.extend(w32(8)); // IFD0 at 8
        b.extend(w16(1)); // one entry: the Exif pointer (LONG) to 26
        b.extend(w16(EXIF_IFD_POINTER));
        b.extend(w16(4));
        b.extend(w32(1));
        b.extend(w32(26));
        b.extend(w32(0)); // no next IFD
        b.extend(w16(1)); // Exif IFD at 26: one entry, the focal length (SHORT)
        b.extend(w16(FOCAL_LENGTH_35MM));
        b.extend(w16(3));
        b.extend(w32(1));
        b.extend(w16(focal));
        b.extend([0, 0]);
        b.extend(w32(0));
        b
    }

    #[test]
    fn focal_length_is_read_in_both_byte_orders() {
        assert_eq!(focal_length_35mm(&block(true, 35)), Some(35));
        assert_eq!(focal_length_35mm(&block(false, 28)), Some(28));
        assert_eq!(focal_length_35mm(&block(true, 0)), None);
        assert_eq!(focal_length_35mm(&block(true, 35)[..30]), None);
        assert_eq!(focal_length_35mm(b"nonsense"), None);
        assert_eq!(focal_pixels(36, 3000, 2000), 3000.0);
    }
}

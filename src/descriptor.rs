//! Binary descriptors: one fixed 512-bit type and a dense set of descriptors of any supported width.

use crate::error::{Error, Result};

/// Words of 64 bits in a full 512-bit descriptor.
pub const DESCRIPTOR_WORDS: usize = 8;
/// Bits in a full descriptor (the number of learned triplets).
pub const MAX_DESCRIPTOR_BITS: usize = 512;

/// A descriptor width: `8 * n` bits for `n` in `1..=64`, using the first `8 * n` learned triplets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct DescriptorWidth(u16);

impl DescriptorWidth {
    /// The full 512-bit (64-byte) descriptor.
    pub const FULL: DescriptorWidth = DescriptorWidth(512);

    /// Checks that `bits` is a multiple of 8 in `8..=512`.
    pub fn from_bits(bits: usize) -> Result<Self> {
        if bits == 0 || bits > MAX_DESCRIPTOR_BITS || !bits.is_multiple_of(8) {
            return Err(Error::InvalidDescriptorWidth { bits });
        }
        Ok(Self(bits as u16))
    }

    /// Width in bytes (1..=64).
    pub fn from_bytes(bytes: usize) -> Result<Self> {
        Self::from_bits(bytes.saturating_mul(8))
    }

    /// Number of bits (= number of triplets used).
    pub fn bits(self) -> usize {
        self.0 as usize
    }

    /// Number of bytes.
    pub fn bytes(self) -> usize {
        self.bits() / 8
    }

    /// 64-bit words each descriptor of this width occupies in a [`DescriptorSet`].
    pub fn words(self) -> usize {
        self.bits().div_ceil(64)
    }
}

impl Default for DescriptorWidth {
    fn default() -> Self {
        Self::FULL
    }
}

/// One 512-bit descriptor. Bit `t` (triplet `t`) is bit `t % 64` of word `t / 64`, least significant
/// first; bits past the width it was computed with are zero.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(C, align(64))]
pub struct Descriptor(pub [u64; DESCRIPTOR_WORDS]);

impl Descriptor {
    /// Bit `t` (the outcome of triplet `t`), or `None` for `t >= 512`.
    pub fn bit(&self, t: usize) -> Option<bool> {
        let word = self.0.get(t / 64)?;
        Some((word >> (t % 64)) & 1 == 1)
    }

    /// Hamming distance to another descriptor.
    pub fn hamming(&self, other: &Descriptor) -> u32 {
        hamming(&self.0, &other.0)
    }

    /// The 64 bytes in OpenCV LATCH's layout: triplet `8m + k` in byte `m`, bit `7 - k` (most significant
    /// first), so exported descriptors interchange with OpenCV's.
    pub fn to_opencv_bytes(&self) -> [u8; 64] {
        let mut out = [0u8; 64];
        for (m, byte) in out.iter_mut().enumerate() {
            *byte = ((self.0[m / 8] >> (8 * (m % 8))) as u8).reverse_bits();
        }
        out
    }

    /// Inverse of [`Descriptor::to_opencv_bytes`].
    pub fn from_opencv_bytes(bytes: &[u8; 64]) -> Self {
        let mut words = [0u64; DESCRIPTOR_WORDS];
        for (m, byte) in bytes.iter().enumerate() {
            words[m / 8] |= (byte.reverse_bits() as u64) << (8 * (m % 8));
        }
        Self(words)
    }
}

/// Hamming distance between two equally long word slices.
#[inline]
pub fn hamming(a: &[u64], b: &[u64]) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x ^ y).count_ones()).sum()
}

/// A dense, row-major set of descriptors of one width: descriptor `i` is
/// `words[i * w .. (i + 1) * w]` with `w = width.words()`; bits past the width are zero.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DescriptorSet {
    width: DescriptorWidth,
    words: Vec<u64>,
}

impl DescriptorSet {
    /// An empty set of the given width.
    pub fn empty(width: DescriptorWidth) -> Self {
        Self {
            width,
            words: Vec::new(),
        }
    }

    /// Wraps packed words (see the type docs). Bits past the width are cleared so distances ignore them.
    pub fn from_words(width: DescriptorWidth, mut words: Vec<u64>) -> Result<Self> {
        let per = width.words();
        if !words.len().is_multiple_of(per) {
            return Err(Error::DescriptorBufferLength {
                words: words.len(),
                words_per_descriptor: per,
            });
        }
        let tail_bits = width.bits() % 64;
        if tail_bits != 0 {
            let mask = (1u64 << tail_bits) - 1;
            for row in words.chunks_exact_mut(per) {
                row[per - 1] &= mask;
            }
        }
        Ok(Self { width, words })
    }

    /// Builds a set from full descriptors, keeping the first `width` bits of each.
    pub fn from_descriptors(width: DescriptorWidth, descriptors: &[Descriptor]) -> Self {
        let per = width.words();
        let words = descriptors
            .iter()
            .flat_map(|d| d.0[..per].iter().copied())
            .collect();
        Self::from_words(width, words).expect("whole rows by construction")
    }

    /// The width of every descriptor in the set.
    pub fn width(&self) -> DescriptorWidth {
        self.width
    }

    /// Number of descriptors.
    pub fn len(&self) -> usize {
        self.words.len() / self.width.words()
    }

    /// True when the set holds no descriptor.
    pub fn is_empty(&self) -> bool {
        self.words.is_empty()
    }

    /// The packed words of descriptor `i`, or `None` past the end.
    pub fn get(&self, i: usize) -> Option<&[u64]> {
        let per = self.width.words();
        let start = i.checked_mul(per)?;
        self.words.get(start..start.checked_add(per)?)
    }

    /// Descriptor `i` as a full 512-bit value (zero-padded), or `None` past the end.
    pub fn descriptor(&self, i: usize) -> Option<Descriptor> {
        self.get(i).map(|row| {
            let mut d = Descriptor::default();
            d.0[..row.len()].copy_from_slice(row);
            d
        })
    }

    /// Iterates over the packed rows.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, u64> {
        self.words.chunks_exact(self.width.words())
    }

    /// All packed words, row after row.
    pub fn as_words(&self) -> &[u64] {
        &self.words
    }

    /// All descriptors as bytes in OpenCV LATCH's layout (`len() * width.bytes()` bytes, row-major).
    /// [`DescriptorSet::from_opencv_bytes`] reads them back.
    pub fn to_opencv_bytes(&self) -> Vec<u8> {
        let bytes = self.width.bytes();
        let mut out = Vec::with_capacity(self.len() * bytes);
        for i in 0..self.len() {
            let d = self.descriptor(i).expect("index in range");
            out.extend_from_slice(&d.to_opencv_bytes()[..bytes]);
        }
        out
    }

    /// The set of `width`-bit descriptors held in `bytes`, rows of `width.bytes()` bytes in OpenCV
    /// LATCH's layout (the inverse of [`DescriptorSet::to_opencv_bytes`]; what OpenCV's `LATCH`
    /// computes, what `clatch extract` writes to `.npy`). A length that is not a whole number of rows
    /// is [`Error::DescriptorBytesLength`].
    ///
    /// ```
    /// use clatch::{DescriptorSet, DescriptorWidth, ErrorKind};
    ///
    /// let width = DescriptorWidth::from_bytes(32)?;
    /// let bytes: Vec<u8> = (0..96u8).collect(); // three rows of 32 bytes
    /// let set = DescriptorSet::from_opencv_bytes(width, &bytes)?;
    /// assert_eq!(set.len(), 3);
    /// assert_eq!(set.to_opencv_bytes(), bytes);
    /// let error = DescriptorSet::from_opencv_bytes(width, &bytes[..95]).unwrap_err();
    /// assert_eq!(error.kind(), ErrorKind::DescriptorBytesLength);
    /// # Ok::<(), clatch::Error>(())
    /// ```
    pub fn from_opencv_bytes(width: DescriptorWidth, bytes: &[u8]) -> Result<Self> {
        let per = width.bytes();
        if !bytes.len().is_multiple_of(per) {
            return Err(Error::DescriptorBytesLength {
                bytes: bytes.len(),
                bytes_per_descriptor: per,
            });
        }
        let rows: Vec<Descriptor> = bytes
            .chunks_exact(per)
            .map(|row| {
                let mut full = [0u8; 64];
                full[..per].copy_from_slice(row);
                Descriptor::from_opencv_bytes(&full)
            })
            .collect();
        Ok(Self::from_descriptors(width, &rows))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widths() {
        assert!(DescriptorWidth::from_bits(0).is_err());
        assert!(DescriptorWidth::from_bits(7).is_err());
        assert!(DescriptorWidth::from_bits(520).is_err());
        assert!(DescriptorWidth::from_bytes(usize::MAX).is_err());
        let w = DescriptorWidth::from_bits(72).unwrap();
        assert_eq!((w.bytes(), w.words()), (9, 2));
        assert_eq!(DescriptorWidth::FULL.words(), 8);
    }

    #[test]
    fn opencv_byte_order_round_trips() {
        let mut d = Descriptor::default();
        d.0[0] = 1; // triplet 0
        d.0[7] = 1 << 63; // triplet 511
        let bytes = d.to_opencv_bytes();
        assert_eq!(
            bytes[0], 0x80,
            "triplet 0 is the most significant bit of byte 0"
        );
        assert_eq!(
            bytes[63], 0x01,
            "triplet 511 is the least significant bit of byte 63"
        );
        assert_eq!(Descriptor::from_opencv_bytes(&bytes), d);
    }

    #[test]
    fn set_masks_bits_past_the_width() {
        let w = DescriptorWidth::from_bits(72).unwrap();
        let set = DescriptorSet::from_words(w, vec![u64::MAX, u64::MAX]).unwrap();
        assert_eq!(set.get(0).unwrap(), &[u64::MAX, 0xFF]);
        assert!(matches!(
            DescriptorSet::from_words(w, vec![0; 3]),
            Err(Error::DescriptorBufferLength { .. })
        ));
        assert_eq!(set.to_opencv_bytes().len(), 9);
    }

    #[test]
    fn opencv_bytes_of_a_set_round_trip() {
        for bytes_per in [1, 7, 8, 9, 32, 63, 64] {
            let width = DescriptorWidth::from_bytes(bytes_per).unwrap();
            let words: Vec<u64> = (0..5 * width.words() as u64)
                .map(|i| (i + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15))
                .collect();
            let set = DescriptorSet::from_words(width, words).unwrap();
            let bytes = set.to_opencv_bytes();
            assert_eq!(bytes.len(), 5 * bytes_per);
            assert_eq!(
                DescriptorSet::from_opencv_bytes(width, &bytes).unwrap(),
                set
            );
            // Row by row, the one-descriptor conversion.
            for (i, row) in bytes.chunks_exact(bytes_per).enumerate() {
                let mut full = [0u8; 64];
                full[..bytes_per].copy_from_slice(row);
                let one = Descriptor::from_opencv_bytes(&full);
                assert_eq!(
                    set.descriptor(i).unwrap(),
                    one,
                    "{bytes_per} bytes, row {i}"
                );
            }
        }
        let empty = DescriptorSet::from_opencv_bytes(DescriptorWidth::FULL, &[]).unwrap();
        assert_eq!(empty, DescriptorSet::empty(DescriptorWidth::FULL));
    }

    #[test]
    fn opencv_bytes_of_a_partial_row_are_refused() {
        let width = DescriptorWidth::from_bytes(32).unwrap();
        for len in [1, 31, 33, 95] {
            assert_eq!(
                DescriptorSet::from_opencv_bytes(width, &vec![0xA5; len]),
                Err(Error::DescriptorBytesLength {
                    bytes: len,
                    bytes_per_descriptor: 32,
                })
            );
        }
        assert_eq!(
            Error::DescriptorBytesLength {
                bytes: 95,
                bytes_per_descriptor: 32
            }
            .to_string(),
            "descriptor buffer of 95 bytes is not a multiple of 32 bytes per descriptor"
        );
    }
}

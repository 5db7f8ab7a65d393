//! Reads the fatbins build.rs packs (a test helper: the library hands them to the driver whole): each
//! image's kind and architecture, LZ4-decompressed, and the kernels a native image defines, so that a
//! test proves every kernel has native code for every architecture without NVIDIA's tools.
//!
//! The container, little-endian: a 16-byte header (magic `0xBA55ED50`, version, header size, size of
//! what follows), then images, each a header and its payload. An image's header holds its kind at 0
//! (1 PTX, 2 native code, an ELF file), its header size at 4, its payload size at 8, the compressed size
//! at 16, the architecture at 28, flags at 40 (`0x2000`: LZ4-compressed) and the size decompressed at 56.

use std::borrow::Cow;

const MAGIC: u32 = 0xBA55_ED50;
const KIND_PTX: u16 = 1;
const KIND_ELF: u16 = 2;
const FLAG_LZ4: u64 = 0x2000;
/// Compression fatbinary may use that this reader does not decode (zstd); build.rs asks for LZ4.
const FLAG_ZSTD: u64 = 0x8000;

/// What an image holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// PTX for the driver to JIT-compile on any GPU of this architecture or later.
    Ptx,
    /// Native code (an ELF file) for GPUs of this architecture.
    Native,
}

/// One image of a fatbin, decompressed.
#[derive(Debug)]
pub(crate) struct Image<'a> {
    pub(crate) kind: Kind,
    /// `90` for sm_90 or compute_90.
    pub(crate) arch: u32,
    pub(crate) payload: Cow<'a, [u8]>,
}

/// Every image of `fatbin`, in order (several containers one after another are read as one).
pub(crate) fn images(fatbin: &[u8]) -> Result<Vec<Image<'_>>, String> {
    let mut images = Vec::new();
    let mut at = 0;
    while at < fatbin.len() {
        if u32_at(fatbin, at)? != MAGIC {
            return Err(format!("no fatbin magic at byte {at}"));
        }
        let header = usize::from(u16_at(fatbin, at + 6)?);
        let end = at
            .checked_add(header)
            .and_then(|start| {
                start.checked_add(usize::try_from(u64_at(fatbin, at + 8).ok()?).ok()?)
            })
            .filter(|&end| end <= fatbin.len())
            .ok_or_else(|| format!("the container at byte {at} runs past the end"))?;
        let mut image = at + header;
        while image < end {
            let (parsed, next) = read_image(fatbin, image, end)?;
            images.push(parsed);
            image = next;
        }
        at = end;
    }
    Ok(images)
}

/// The image whose header starts at `at` (its container ends at `end`), and where the next one starts.
fn read_image(fatbin: &[u8], at: usize, end: usize) -> Result<(Image<'_>, usize), String> {
    let kind = match u16_at(fatbin, at)? {
        KIND_PTX => Kind::Ptx,
        KIND_ELF => Kind::Native,
        other => return Err(format!("image at byte {at}: unknown kind {other}")),
    };
    let header = usize::try_from(u32_at(fatbin, at + 4)?).map_err(|e| e.to_string())?;
    let size = usize::try_from(u64_at(fatbin, at + 8)?).map_err(|e| e.to_string())?;
    let start = at + header;
    let next = start
        .checked_add(size)
        .filter(|&next| next <= end)
        .ok_or_else(|| format!("image at byte {at} runs past its container"))?;
    let arch = u32_at(fatbin, at + 28)?;
    let flags = u64_at(fatbin, at + 40)?;
    let body = &fatbin[start..next];
    let payload = if flags & FLAG_LZ4 != 0 {
        let compressed = usize::try_from(u32_at(fatbin, at + 16)?).map_err(|e| e.to_string())?;
        let decompressed = usize::try_from(u64_at(fatbin, at + 56)?).map_err(|e| e.to_string())?;
        let input = body
            .get(..compressed)
            .ok_or_else(|| format!("image at byte {at}: compressed size past its payload"))?;
        Cow::Owned(lz4_block(input, decompressed)?)
    } else if flags & FLAG_ZSTD != 0 {
        return Err(format!("image at byte {at} is zstd-compressed"));
    } else {
        Cow::Borrowed(body)
    };
    Ok((
        Image {
            kind,
            arch,
            payload,
        },
        next,
    ))
}

/// Decodes one LZ4 block (no frame) of `size` bytes decompressed: sequences of a token, literals, and
/// a match copied from `offset` bytes back.
fn lz4_block(input: &[u8], size: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(size);
    let mut at = 0;
    let byte = |at: &mut usize| -> Result<u8, String> {
        let b = *input.get(*at).ok_or("LZ4 block ends inside a sequence")?;
        *at += 1;
        Ok(b)
    };
    let length = |at: &mut usize, short: usize| -> Result<usize, String> {
        let mut length = short;
        if short == 15 {
            loop {
                let b = byte(at)?;
                length += usize::from(b);
                if b != 255 {
                    break;
                }
            }
        }
        Ok(length)
    };
    while at < input.len() {
        let token = byte(&mut at)?;
        let literals = length(&mut at, usize::from(token >> 4))?;
        let literal_bytes = input
            .get(at..at + literals)
            .ok_or("LZ4 literals past the block")?;
        out.extend_from_slice(literal_bytes);
        at += literals;
        if at == input.len() {
            break; // the last sequence has literals only
        }
        let offset = usize::from(byte(&mut at)?) | usize::from(byte(&mut at)?) << 8;
        let matched = length(&mut at, usize::from(token & 15))? + 4;
        if offset == 0 || offset > out.len() {
            return Err(format!("LZ4 match offset {offset} out of range"));
        }
        // Byte by byte: a match may overlap what it produces (a run).
        for _ in 0..matched {
            out.push(out[out.len() - offset]);
        }
    }
    if out.len() == size {
        Ok(out)
    } else {
        Err(format!("LZ4 block gave {} bytes, not {size}", out.len()))
    }
}

/// The ELF machine number of CUDA code.
const EM_CUDA: u16 = 190;
const SHT_SYMTAB: u32 = 2;
const SHT_NOBITS: u32 = 8;
const STT_FUNC: u8 = 2;
/// `st_other` bit of a kernel entry point in CUDA code.
const STO_CUDA_ENTRY: u8 = 0x10;

/// The architecture a native image was compiled for, and the kernels (entry points) it defines.
pub(crate) fn kernels(elf: &[u8]) -> Result<(u32, Vec<String>), String> {
    if elf.get(..4) != Some(b"\x7fELF".as_slice()) || elf.get(4..6) != Some([2, 1].as_slice()) {
        return Err("not a 64-bit little-endian ELF file".into());
    }
    if u16_at(elf, 0x12)? != EM_CUDA {
        return Err("not CUDA code".into());
    }
    // From ABI version 8 (CUDA 12.8) on, the architecture is the second byte of the flags.
    let flags = u32_at(elf, 0x30)?;
    let abi = *elf.get(8).ok_or("ELF header cut short")?;
    let arch = if abi >= 8 { flags >> 8 } else { flags } & 0xff;
    let sections = usize::try_from(u64_at(elf, 0x28)?).map_err(|e| e.to_string())?;
    let entry_size = usize::from(u16_at(elf, 0x3a)?);
    let count = usize::from(u16_at(elf, 0x3c)?);
    let section = |i: usize| -> Result<(u32, &[u8], usize), String> {
        let at = sections + i * entry_size;
        let offset = usize::try_from(u64_at(elf, at + 0x18)?).map_err(|e| e.to_string())?;
        let size = usize::try_from(u64_at(elf, at + 0x20)?).map_err(|e| e.to_string())?;
        let kind = u32_at(elf, at + 4)?;
        // A section of no bits (shared memory, say) has a size and nothing in the file.
        let data = if kind == SHT_NOBITS {
            &[]
        } else {
            elf.get(offset..offset.saturating_add(size))
                .ok_or_else(|| format!("section {i} runs past the file"))?
        };
        let link = usize::try_from(u32_at(elf, at + 0x28)?).map_err(|e| e.to_string())?;
        Ok((kind, data, link))
    };
    let mut kernels = Vec::new();
    for i in 0..count {
        let (kind, symbols, strings) = section(i)?;
        if kind != SHT_SYMTAB {
            continue;
        }
        let (_, names, _) = section(strings)?;
        for symbol in symbols.chunks_exact(24) {
            let (info, other) = (symbol[4], symbol[5]);
            let defined = u16_at(symbol, 6)? != 0;
            if info & 0xf == STT_FUNC && other & STO_CUDA_ENTRY != 0 && defined {
                let name = usize::try_from(u32_at(symbol, 0)?).map_err(|e| e.to_string())?;
                let name = names
                    .get(name..)
                    .and_then(|rest| rest.split(|&b| b == 0).next())
                    .ok_or("symbol name past the string table")?;
                kernels.push(String::from_utf8_lossy(name).into_owned());
            }
        }
    }
    Ok((arch, kernels))
}

fn bytes<const N: usize>(data: &[u8], at: usize) -> Result<[u8; N], String> {
    data.get(at..at.saturating_add(N))
        .and_then(|b| b.try_into().ok())
        .ok_or_else(|| format!("{N} bytes at {at}: past the end ({} bytes)", data.len()))
}

fn u16_at(data: &[u8], at: usize) -> Result<u16, String> {
    bytes(data, at).map(u16::from_le_bytes)
}

fn u32_at(data: &[u8], at: usize) -> Result<u32, String> {
    bytes(data, at).map(u32::from_le_bytes)
}

fn u64_at(data: &[u8], at: usize) -> Result<u64, String> {
    bytes(data, at).map(u64::from_le_bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A literal run, an overlapping match (a run of one byte) and a final literal, decoded by hand:
    /// "ab" + "b" x 6 + "cd".
    #[test]
    fn lz4_block_decodes_literals_and_overlapping_matches() {
        // token: 2 literals, match length 2 + 4 = 6; offset 1; then token: 2 literals, no match.
        let block = [0x22, b'a', b'b', 1, 0, 0x20, b'c', b'd'];
        assert_eq!(lz4_block(&block, 10).unwrap(), b"abbbbbbbcd");
        assert!(lz4_block(&block, 11).is_err(), "a wrong size is refused");
        // An offset reaching before the output.
        assert!(lz4_block(&[0x10, b'a', 2, 0, 0x00], 6).is_err());
        // Cut inside a sequence.
        assert!(lz4_block(&[0xf0], 15).is_err());
    }

    /// A container built by hand: two images, one of them LZ4-compressed; a bad magic and a size past
    /// the end are refused.
    #[test]
    fn images_reads_kinds_arches_and_payloads() {
        let image = |kind: u16, arch: u32, flags: u64, payload: &[u8], sizes: (u32, u64)| {
            let mut header = vec![0u8; 64];
            header[0..2].copy_from_slice(&kind.to_le_bytes());
            header[4..8].copy_from_slice(&64u32.to_le_bytes());
            header[8..16].copy_from_slice(&(payload.len() as u64).to_le_bytes());
            header[16..20].copy_from_slice(&sizes.0.to_le_bytes());
            header[28..32].copy_from_slice(&arch.to_le_bytes());
            header[40..48].copy_from_slice(&flags.to_le_bytes());
            header[56..64].copy_from_slice(&sizes.1.to_le_bytes());
            header.extend_from_slice(payload);
            header
        };
        let mut body = image(2, 86, 0x11, b"native86", (0, 0));
        body.extend(image(
            1,
            75,
            0x11 | FLAG_LZ4,
            &[0x50, b'.', b'p', b't', b'x', b'!'],
            (6, 5),
        ));
        let mut fatbin = Vec::new();
        fatbin.extend_from_slice(&MAGIC.to_le_bytes());
        fatbin.extend_from_slice(&1u16.to_le_bytes());
        fatbin.extend_from_slice(&16u16.to_le_bytes());
        fatbin.extend_from_slice(&(body.len() as u64).to_le_bytes());
        fatbin.extend_from_slice(&body);

        let read = images(&fatbin).unwrap();
        assert_eq!(read.len(), 2);
        assert_eq!((read[0].kind, read[0].arch), (Kind::Native, 86));
        assert_eq!(&*read[0].payload, b"native86");
        assert_eq!((read[1].kind, read[1].arch), (Kind::Ptx, 75));
        assert_eq!(&*read[1].payload, b".ptx!");

        let mut bad = fatbin.clone();
        bad[0] ^= 1;
        assert!(images(&bad).is_err());
        assert!(images(&fatbin[..fatbin.len() - 1]).is_err());
    }
}

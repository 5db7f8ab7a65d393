//! Whether a sequential (baseline or extended) Huffman JPEG holds every block its header promises: the
//! entropy-coded data of each scan is walked, Huffman code by code, through every MCU. The JPEG decoder
//! fills what is missing silently (gray, or zero bits decoded as data), so a file cut and marked as
//! ended again, or a header patched to a larger size, would otherwise decode into flat fill. Malformed
//! Huffman codes are found too. Progressive and arithmetic-coded files are not walked (their decoder
//! checks the markers alone).

/// Why the data is corrupt, in words.
pub(crate) type Corruption = String;

/// One Huffman table: canonical codes (JPEG spec, annex C and F.2.2.3).
#[derive(Clone)]
struct Huffman {
    /// Largest code of each length 1..=16 (`-1`: none), smallest code, index of its first symbol.
    max_code: [i32; 17],
    min_code: [i32; 17],
    first: [usize; 17],
    symbols: Vec<u8>,
    /// Codes of up to [`FAST_BITS`] bits by their first bits: `(length, symbol)`, length 0 if longer.
    fast: Vec<(u8, u8)>,
}

/// Bits looked up at once.
const FAST_BITS: u32 = 9;

impl Huffman {
    fn new(counts: &[u8; 16], symbols: &[u8]) -> Self {
        let mut h = Huffman {
            max_code: [-1; 17],
            min_code: [0; 17],
            first: [0; 17],
            symbols: symbols.to_vec(),
            fast: vec![(0, 0); 1 << FAST_BITS],
        };
        let (mut code, mut k) = (0i32, 0usize);
        for len in 1..=16 {
            let n = usize::from(counts[len - 1]);
            if n > 0 {
                h.first[len] = k;
                h.min_code[len] = code;
                code += n as i32;
                k += n;
                h.max_code[len] = code - 1;
            }
            code <<= 1;
        }
        for len in 1..=FAST_BITS as usize {
            if h.max_code[len] < 0 {
                continue;
            }
            for code in h.min_code[len]..=h.max_code[len] {
                let Some(&symbol) = h
                    .symbols
                    .get(h.first[len] + (code - h.min_code[len]) as usize)
                else {
                    continue;
                };
                let shift = FAST_BITS as usize - len;
                let start = (code as usize) << shift;
                for slot in &mut h.fast[start..start + (1 << shift)] {
                    *slot = (len as u8, symbol);
                }
            }
        }
        h
    }
}

/// Reads bits of entropy-coded data, unstuffing `FF 00`, stopping at any marker.
struct Bits<'a> {
    data: &'a [u8],
    pos: usize,
    buffer: u64,
    count: u32,
    /// A marker (or the end of the file) was reached: no more data.
    ended: bool,
    /// Bits asked for beyond the data.
    overrun: bool,
}

impl<'a> Bits<'a> {
    fn refill(&mut self) {
        while self.count <= 56 && !self.ended {
            let Some(&b) = self.data.get(self.pos) else {
                self.ended = true;
                break;
            };
            if b == 0xFF {
                match self.data.get(self.pos + 1) {
                    Some(0x00) => self.pos += 2,
                    _ => {
                        self.ended = true;
                        break;
                    }
                }
            } else {
                self.pos += 1;
            }
            self.buffer |= u64::from(b) << (56 - self.count);
            self.count += 8;
        }
    }

    /// Consumes `n` (at most 32) bits; past the data, marks the overrun.
    fn skip(&mut self, n: u32) {
        if self.count < n {
            self.refill();
            if self.count < n {
                self.overrun = true;
                self.buffer = 0;
                self.count = 0;
                return;
            }
        }
        self.buffer <<= n;
        self.count -= n;
    }

    fn decode(&mut self, h: &Huffman) -> Option<u8> {
        if self.count < 16 {
            self.refill();
        }
        // Past the data the buffer holds zeros: a code found there overruns in `skip`.
        let (len, symbol) = h.fast[(self.buffer >> (64 - FAST_BITS)) as usize];
        if len > 0 {
            self.skip(u32::from(len));
            return (!self.overrun).then_some(symbol);
        }
        for len in FAST_BITS as usize + 1..=16 {
            let code = (self.buffer >> (64 - len)) as i32;
            if code <= h.max_code[len] {
                self.skip(len as u32);
                if self.overrun {
                    return None;
                }
                return h
                    .symbols
                    .get(h.first[len] + (code - h.min_code[len]) as usize)
                    .copied();
            }
        }
        // No code of any length: a bad code within the data, or zeros past its end.
        if self.count < 16 {
            self.overrun = true;
        }
        None
    }

    /// Drops the bits left in the current byte and the buffered bytes: back to the byte position.
    fn align(&mut self) {
        // Buffered whole bytes go back to the data (none of them is stuffed: a stuffed FF counts 2).
        let mut whole = self.count / 8;
        while whole > 0 {
            self.pos -= 1;
            if self.pos > 0 && self.data[self.pos] == 0x00 && self.data[self.pos - 1] == 0xFF {
                self.pos -= 1;
            }
            whole -= 1;
        }
        self.buffer = 0;
        self.count = 0;
        self.ended = false;
    }
}

#[derive(Clone, Copy)]
struct Component {
    id: u8,
    h: usize,
    v: usize,
}

/// Walks every scan of `jpeg`; `Ok` also for files this walker does not handle (progressive,
/// arithmetic, lossless, malformed headers: the decoder judges those).
pub(crate) fn check_scans(jpeg: &[u8]) -> Result<(), Corruption> {
    let mut dc: [Option<Huffman>; 4] = Default::default();
    let mut ac: [Option<Huffman>; 4] = Default::default();
    let mut frame: Option<(usize, usize, Vec<Component>)> = None;
    let mut restart = 0usize;
    let mut pos = 2; // after SOI
    let u16_at = |p: usize| -> Option<usize> {
        Some(usize::from(*jpeg.get(p)?) << 8 | usize::from(*jpeg.get(p + 1)?))
    };
    loop {
        // The next marker (fill bytes and stray data before it skipped).
        while pos < jpeg.len() && jpeg[pos] != 0xFF {
            pos += 1;
        }
        while pos < jpeg.len() && jpeg[pos] == 0xFF {
            pos += 1;
        }
        let Some(&marker) = jpeg.get(pos) else {
            return Ok(());
        };
        pos += 1;
        match marker {
            0xD9 => return Ok(()),
            0xD0..=0xD7 | 0x01 => continue,
            _ => {}
        }
        let Some(len) = u16_at(pos) else {
            return Ok(());
        };
        let segment = jpeg.get(pos + 2..pos + len).unwrap_or_default();
        match marker {
            0xC4 => {
                let mut s = segment;
                while s.len() >= 17 {
                    let (class, id) = (s[0] >> 4, usize::from(s[0] & 15));
                    let counts: [u8; 16] = s[1..17].try_into().unwrap_or([0; 16]);
                    let n: usize = counts.iter().map(|&c| usize::from(c)).sum();
                    let Some(symbols) = s.get(17..17 + n) else {
                        return Ok(());
                    };
                    if id < 4 {
                        let table = Some(Huffman::new(&counts, symbols));
                        if class == 0 {
                            dc[id] = table
                        } else {
                            ac[id] = table
                        }
                    }
                    s = &s[17 + n..];
                }
            }
            0xC0 | 0xC1 => {
                if segment.len() < 6 {
                    return Ok(());
                }
                let (y, x) = (
                    usize::from(segment[1]) << 8 | usize::from(segment[2]),
                    usize::from(segment[3]) << 8 | usize::from(segment[4]),
                );
                let n = usize::from(segment[5]);
                let components: Vec<Component> = segment[6..]
                    .chunks_exact(3)
                    .take(n)
                    .map(|c| Component {
                        id: c[0],
                        h: usize::from(c[1] >> 4).max(1),
                        v: usize::from(c[1] & 15).max(1),
                    })
                    .collect();
                if x == 0 || y == 0 || components.len() != n {
                    return Ok(());
                }
                frame = Some((x, y, components));
            }
            // Progressive, lossless, hierarchical, arithmetic: not walked.
            0xC2 | 0xC3 | 0xC5..=0xC7 | 0xC9..=0xCB | 0xCD..=0xCF => return Ok(()),
            0xDD if segment.len() >= 2 => {
                restart = usize::from(segment[0]) << 8 | usize::from(segment[1]);
            }
            0xDA => {
                let Some((x, y, components)) = &frame else {
                    return Ok(());
                };
                let ns = usize::from(*segment.first().unwrap_or(&0));
                let mut scan = Vec::new();
                for c in segment
                    .get(1..1 + 2 * ns)
                    .unwrap_or_default()
                    .chunks_exact(2)
                {
                    let Some(comp) = components.iter().find(|k| k.id == c[0]) else {
                        return Ok(());
                    };
                    let (Some(Some(d)), Some(Some(a))) = (
                        dc.get(usize::from(c[1] >> 4)),
                        ac.get(usize::from(c[1] & 15)),
                    ) else {
                        return Err("a scan uses a Huffman table that was never defined".into());
                    };
                    scan.push((*comp, d.clone(), a.clone()));
                }
                if scan.is_empty() {
                    return Ok(());
                }
                pos += len;
                pos = walk_scan(jpeg, pos, (*x, *y, components), &scan, restart)?;
                continue;
            }
            _ => {}
        }
        pos += len;
    }
}

/// Walks one scan's MCUs from `start`; returns where its data ends.
fn walk_scan(
    jpeg: &[u8],
    start: usize,
    (x, y, components): (usize, usize, &[Component]),
    scan: &[(Component, Huffman, Huffman)],
    restart: usize,
) -> Result<usize, Corruption> {
    let hmax = components.iter().map(|c| c.h).max().unwrap_or(1);
    let vmax = components.iter().map(|c| c.v).max().unwrap_or(1);
    let (mcus, per_mcu): (usize, Vec<usize>) = if scan.len() == 1 {
        let c = scan[0].0;
        let w = (x * c.h).div_ceil(hmax).div_ceil(8);
        let h = (y * c.v).div_ceil(vmax).div_ceil(8);
        (w * h, vec![1])
    } else {
        let w = x.div_ceil(8 * hmax);
        let h = y.div_ceil(8 * vmax);
        (w * h, scan.iter().map(|(c, ..)| c.h * c.v).collect())
    };
    let mut bits = Bits {
        data: jpeg,
        pos: start,
        buffer: 0,
        count: 0,
        ended: false,
        overrun: false,
    };
    let short =
        |done: usize| format!("the entropy-coded data stops after {done} of its {mcus} MCUs");
    for mcu in 0..mcus {
        if restart > 0 && mcu > 0 && mcu % restart == 0 {
            bits.align();
            match (jpeg.get(bits.pos), jpeg.get(bits.pos + 1)) {
                (Some(0xFF), Some(0xD0..=0xD7)) => bits.pos += 2,
                _ => return Err(short(mcu)),
            }
        }
        for ((_, dc, ac), &blocks) in scan.iter().zip(&per_mcu) {
            for _ in 0..blocks {
                let Some(s) = bits.decode(dc) else {
                    return Err(if bits.overrun {
                        short(mcu)
                    } else {
                        bad_code(mcu)
                    });
                };
                bits.skip(u32::from(s.min(16)));
                let mut k = 1;
                while k < 64 {
                    let Some(rs) = bits.decode(ac) else {
                        return Err(if bits.overrun {
                            short(mcu)
                        } else {
                            bad_code(mcu)
                        });
                    };
                    let (r, s) = (usize::from(rs >> 4), u32::from(rs & 15));
                    if s == 0 {
                        if r != 15 {
                            break;
                        }
                        k += 16;
                    } else {
                        k += r;
                        bits.skip(s);
                        k += 1;
                    }
                }
                if k > 64 {
                    return Err(format!(
                        "a block of MCU {mcu} holds more than 64 coefficients"
                    ));
                }
                if bits.overrun {
                    return Err(short(mcu));
                }
            }
        }
    }
    bits.align();
    Ok(bits.pos)
}

fn bad_code(mcu: usize) -> Corruption {
    format!("MCU {mcu} holds a code its Huffman table does not have")
}

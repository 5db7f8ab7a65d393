//! AVX2 kernels (x86-64): bilinear sampling with 8-lane gathers, and the 0/1-weight triplet sums with
//! two patch rows per 256-bit register. Same integers as the reference, lane by lane.
//!
//! Why `unsafe`: the intrinsics need AVX2, which [`Avx2::detect`] checks at run time (holding an
//! [`Avx2`] value is the proof), and the loads/gathers read through raw pointers, whose bounds are
//! checked once per window ([`SamplePlan::new`]) or once per crate build (the triplet table,
//! [`OFFSETS`]) instead of per pixel.

use std::arch::x86_64::*;
use std::ops::Range;

use super::Window;
use super::optimized::{OFFSETS, PatchOffsets, PixelMask, SamplePlan};
use crate::describe::{PATCH, WINDOW};
use crate::descriptor::DescriptorWidth;
use crate::gray_view::GrayView;

/// Proof that the CPU runs AVX2 (only [`Avx2::detect`] makes one).
#[derive(Clone, Copy, Debug)]
pub(super) struct Avx2(());

impl Avx2 {
    /// `Some` iff the CPU reports AVX2.
    pub(super) fn detect() -> Option<Self> {
        is_x86_feature_detected!("avx2").then_some(Avx2(()))
    }

    /// Exactly [`super::sample_window`] on window rows `rows`, for a frame whose plan the image
    /// allows.
    pub(super) fn sample_window(
        self,
        img: &GrayView,
        plan: &SamplePlan,
        rows: Range<usize>,
        window: &mut Window,
    ) {
        let data = img.data();
        // A plan made for another image is refused here rather than read out of bounds.
        assert!(plan.end <= data.len() && plan.stride == img.stride());
        if let Some(local) = LocalBox::new(data.len(), plan, &rows) {
            // SAFETY: AVX2 is present (self); `LocalBox::new` checked that the copy reads inside
            // `data`.
            return unsafe { sample_local(data, plan, &local, rows, window) };
        }
        if plan.stride > i16::MAX as usize {
            // Offsets are 16-bit multiply-adds here; rows this long take the portable kernel.
            return super::portable::sample_window(img, plan, rows, window);
        }
        // SAFETY: AVX2 is present (self); every gather reads inside `data` (checked just above, by
        // the plan's construction: see `SamplePlan::end`).
        unsafe { sample_window(data, plan, rows, window) }
    }

    /// Exactly [`super::window_bits`] for 0/1 weights (`mask`).
    pub(super) fn masked_bits(
        self,
        window: &Window,
        width: DescriptorWidth,
        mask: &PixelMask,
        out: &mut [u64],
    ) {
        // Every width is a multiple of 8 bits: whole groups of 8 triplets.
        let offsets = &OFFSETS[..width.bits()];
        assert!(offsets.len().is_multiple_of(8) && out.len() * 64 >= offsets.len());
        // SAFETY: AVX2 is present (self); the offsets come from `OFFSETS`, whose patches lie inside
        // the window (a const assertion), and the loads read only those patches.
        unsafe { masked_bits(window, offsets, mask, out) }
    }
}

/// See [`Avx2::sample_window`].
///
/// # Safety
/// AVX2 must be present, and `plan` must be a plan for an image whose data is `data`.
#[target_feature(enable = "avx2")]
unsafe fn sample_window(data: &[u8], plan: &SamplePlan, rows: Range<usize>, window: &mut Window) {
    // SAFETY: `base` and `base + stride` lie inside `data` (`plan.end` is past both).
    let top = unsafe { data.as_ptr().add(plan.base) } as *const i32;
    let below = unsafe { data.as_ptr().add(plan.base + plan.stride) } as *const i32;
    // (1, stride) in the 16-bit halves of each lane.
    let stride = _mm256_set1_epi32(1 | (plan.stride as i32) << 16);
    // SAFETY: AVX2 is present (this function's contract); the lanes are window samples, whose
    // reads the plan checked.
    unsafe { sample_rows(plan, rows, window, |x, y| bilinear8(top, below, stride, x, y)) }
}

/// Window rows `rows` of `plan`, 8 samples at a time by `eight`, which is given each lane's
/// relative 16.16 position (plus the 24.8 rounding half, see [`SamplePlan`]) and returns the samples
/// as `i32` lanes; packed to `i16` and stored.
///
/// # Safety
/// AVX2 must be present (inlined into the AVX2 samplers, it is compiled with it).
#[inline(always)]
unsafe fn sample_rows(
    plan: &SamplePlan,
    rows: Range<usize>,
    window: &mut Window,
    mut eight: impl FnMut(__m256i, __m256i) -> __m256i,
) {
    // SAFETY: AVX2 is present (the caller's contract); the one store writes the 32 bytes of `out`.
    unsafe {
        let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let lane_x = _mm256_mullo_epi32(lane, _mm256_set1_epi32(plan.step_u[0]));
        let lane_y = _mm256_mullo_epi32(lane, _mm256_set1_epi32(plan.step_u[1]));
        let step = [0, 1].map(|axis| _mm256_set1_epi32(8 * plan.step_u[axis]));
        let (first, end) = (rows.start, rows.end);
        for (v, out_row) in window.chunks_exact_mut(WINDOW).enumerate().take(end).skip(first) {
            let row = [0, 1].map(|axis| plan.start[axis] + v as i32 * plan.step_v[axis]);
            let mut x = _mm256_add_epi32(_mm256_set1_epi32(row[0]), lane_x);
            let mut y = _mm256_add_epi32(_mm256_set1_epi32(row[1]), lane_y);
            for out in out_row.chunks_exact_mut(16) {
                let mut halves = [_mm256_setzero_si256(); 2];
                for half in &mut halves {
                    *half = eight(x, y);
                    x = _mm256_add_epi32(x, step[0]);
                    y = _mm256_add_epi32(y, step[1]);
                }
                // Samples are 0..=255, so the saturating pack is exact; it interleaves 128-bit
                // halves, which the permutation undoes.
                let packed = _mm256_packs_epi32(halves[0], halves[1]);
                let ordered = _mm256_permute4x64_epi64::<0b11_01_10_00>(packed);
                _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, ordered);
            }
        }
    }
}

/// Side of the local copy of [`sample_local`], in pixels.
const LOCAL: usize = 64;

/// The image pixels a window's sampled rows read, when they fit a [`LOCAL`] x [`LOCAL`] copy: whole
/// pixel offsets from the keypoint's pixel of the box's corner, and its size.
struct LocalBox {
    /// Relative `x`, `y` of the top-left pixel any sample takes.
    left: i32,
    top: i32,
    /// Copied rows and columns (each entry also holds the pixel to its right and those below).
    rows: usize,
    columns: usize,
}

impl LocalBox {
    /// The box of window rows `rows` of `plan`, if it fits the copy and the copy's reads (whole
    /// 32-byte chunks of two image rows per copied row, from the box's left pixel, plus one byte)
    /// lie inside the `len` bytes of image data.
    fn new(len: usize, plan: &SamplePlan, rows: &Range<usize>) -> Option<Self> {
        if rows.is_empty() {
            return None;
        }
        let last_u = (WINDOW - 1) as i64;
        let corners = [rows.start, rows.end - 1].map(|v| {
            [0, last_u].map(|u| {
                [0, 1].map(|axis| {
                    (plan.start[axis] as i64 + u * plan.step_u[axis] as i64
                        + v as i64 * plan.step_v[axis] as i64)
                        >> 16
                })
            })
        });
        let whole = corners.iter().flatten();
        let extreme = |axis: usize| {
            let values = whole.clone().map(|p| p[axis]);
            (values.clone().min().expect("corners"), values.max().expect("corners"))
        };
        let ((left, right), (top, bottom)) = (extreme(0), extreme(1));
        let (columns, copied_rows) = ((right - left + 1) as usize, (bottom - top + 1) as usize);
        if columns > LOCAL || copied_rows > LOCAL {
            return None;
        }
        let stride = plan.stride as i64;
        let first = plan.base as i64 + top * stride + left;
        // The last copied row reads its image row and the next, 32-byte chunks up to `columns`
        // (rounded up to 32) plus the neighbour byte.
        let chunks = columns.div_ceil(32) as i64 * 32;
        let end = plan.base as i64 + (bottom + 1) * stride + left + chunks + 1;
        (first >= 0 && end <= len as i64).then_some(Self {
            left: left as i32,
            top: top as i32,
            rows: copied_rows,
            columns,
        })
    }
}

/// [`sample_window`] through a local copy of the pixels the window reads, each entry 4 bytes: the
/// pixel, its right neighbour, the pixel below and its right neighbour. One gather per 8 samples
/// instead of two, from memory the copy just brought into the cache; the same integers (the
/// clamped neighbours of the reference have weight 0 there, as in [`sample_window`]).
///
/// # Safety
/// AVX2 must be present; `local` must be [`LocalBox::new`] of `data.len()`, `plan` and `rows`.
#[target_feature(enable = "avx2")]
unsafe fn sample_local(
    data: &[u8],
    plan: &SamplePlan,
    local: &LocalBox,
    rows: Range<usize>,
    window: &mut Window,
) {
    let mut copy = std::mem::MaybeUninit::<[u32; LOCAL * LOCAL]>::uninit();
    let entries = copy.as_mut_ptr() as *mut u32;
    let stride = plan.stride as isize;
    // SAFETY: the box's first pixel is inside `data` (LocalBox::new).
    let first = unsafe {
        data.as_ptr()
            .offset(plan.base as isize + local.top as isize * stride + local.left as isize)
    };
    for r in 0..local.rows {
        for chunk in (0..local.columns).step_by(32) {
            // SAFETY: LocalBox::new checked that every copied row reads its image row and the
            // next, from `first`, up to the rounded-up column count plus one byte; the stores go to
            // row `r < LOCAL` of the copy, columns `chunk..chunk + 32 <= LOCAL`.
            unsafe {
                let above = first.offset(r as isize * stride + chunk as isize);
                let below = above.offset(stride);
                let load = |p: *const u8| _mm256_loadu_si256(p as *const __m256i);
                let (a0, a1) = (load(above), load(above.add(1)));
                let (b0, b1) = (load(below), load(below.add(1)));
                // Per 128-bit half: pairs (p, right neighbour), then (pair above, pair below).
                let (al, ah) = (_mm256_unpacklo_epi8(a0, a1), _mm256_unpackhi_epi8(a0, a1));
                let (bl, bh) = (_mm256_unpacklo_epi8(b0, b1), _mm256_unpackhi_epi8(b0, b1));
                let e0 = _mm256_unpacklo_epi16(al, bl); // columns 0..4 | 16..20
                let e1 = _mm256_unpackhi_epi16(al, bl); // 4..8 | 20..24
                let e2 = _mm256_unpacklo_epi16(ah, bh); // 8..12 | 24..28
                let e3 = _mm256_unpackhi_epi16(ah, bh); // 12..16 | 28..32
                let out = entries.add(r * LOCAL + chunk) as *mut __m256i;
                _mm256_storeu_si256(out, _mm256_permute2x128_si256::<0x20>(e0, e1));
                _mm256_storeu_si256(out.add(1), _mm256_permute2x128_si256::<0x20>(e2, e3));
                _mm256_storeu_si256(out.add(2), _mm256_permute2x128_si256::<0x31>(e0, e1));
                _mm256_storeu_si256(out.add(3), _mm256_permute2x128_si256::<0x31>(e2, e3));
            }
        }
    }
    // Entry of relative pixel (x, y): `(y - top) LOCAL + (x - left)`; the pointer is moved back by
    // the box's corner so that the gathers index with `x + LOCAL y` (a 16-bit multiply-add).
    let origin = entries
        .wrapping_offset(-(local.top as isize * LOCAL as isize + local.left as isize))
        as *const i32;
    let pitch = _mm256_set1_epi32(1 | (LOCAL as i32) << 16);
    let byte = _mm256_set1_epi32(255);
    // Bytes 0, 1 (the row) and 2, 3 (the row below) of each entry -> 16-bit halves.
    let spread = |first: i8| {
        let (a, b) = (first, first + 1);
        _mm256_setr_epi8(
            a, -128, b, -128, a + 4, -128, b + 4, -128, a + 8, -128, b + 8, -128, a + 12, -128,
            b + 12, -128, a, -128, b, -128, a + 4, -128, b + 4, -128, a + 8, -128, b + 8, -128,
            a + 12, -128, b + 12, -128,
        )
    };
    let (upper_pair, lower_pair) = (spread(0), spread(2));
    let eight = |x, y| {
        let (fx, fy) = (
            _mm256_and_si256(_mm256_srli_epi32::<8>(x), byte),
            _mm256_and_si256(_mm256_srli_epi32::<8>(y), byte),
        );
        let whole = _mm256_blend_epi16::<0b1010_1010>(_mm256_srli_epi32::<16>(x), y);
        let index = _mm256_madd_epi16(whole, pitch);
        // SAFETY: every sample of the sampled rows lies in the box, whose entries were all
        // written above (LocalBox::new took the extremes of these rows).
        let entry = unsafe { _mm256_i32gather_epi32::<4>(origin, index) };
        interpolate(
            _mm256_shuffle_epi8(entry, upper_pair),
            _mm256_shuffle_epi8(entry, lower_pair),
            fx,
            fy,
        )
    };
    // SAFETY: AVX2 is present (this function's contract).
    unsafe { sample_rows(plan, rows, window, eight) }
}

/// Eight bilinear samples at the relative positions `x, y` (see [`SamplePlan`]), as `i32` lanes.
///
/// `stride` holds `(1, stride)` in the 16-bit halves of each lane (`stride` ≤ `i16::MAX`).
///
/// # Safety
/// AVX2; for each lane, 4 bytes at `top + offset` and `below + offset` must be readable.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn bilinear8(
    top: *const i32,
    below: *const i32,
    stride: __m256i,
    x: __m256i,
    y: __m256i,
) -> __m256i {
    let byte = _mm256_set1_epi32(255);
    let (fx, fy) = (
        _mm256_and_si256(_mm256_srli_epi32::<8>(x), byte),
        _mm256_and_si256(_mm256_srli_epi32::<8>(y), byte),
    );
    // The whole-pixel parts `x >> 16`, `y >> 16` are the high halves of the lanes, as i16: put them
    // side by side and `(x >> 16) + (y >> 16) stride` is one 16-bit multiply-add with (1, stride).
    let whole = _mm256_blend_epi16::<0b1010_1010>(_mm256_srli_epi32::<16>(x), y);
    let offset = _mm256_madd_epi16(whole, stride);
    // Each gather brings the sample's pixel in byte 0 and its right neighbour in byte 1 (when the
    // reference clamps that neighbour, fx = 0 and the byte read is multiplied by 0).
    // SAFETY: the caller's contract.
    let (upper, lower) = unsafe {
        (
            _mm256_i32gather_epi32::<1>(top, offset),
            _mm256_i32gather_epi32::<1>(below, offset),
        )
    };
    // Bytes 0, 1 of each lane -> 16-bit halves.
    let spread = _mm256_setr_epi8(
        0, -128, 1, -128, 4, -128, 5, -128, 8, -128, 9, -128, 12, -128, 13, -128, //
        0, -128, 1, -128, 4, -128, 5, -128, 8, -128, 9, -128, 12, -128, 13, -128,
    );
    interpolate(
        _mm256_shuffle_epi8(upper, spread),
        _mm256_shuffle_epi8(lower, spread),
        fx,
        fy,
    )
}

/// The bilinear sum of eight samples from their pixel pairs: `upper` and `lower` hold `(p0, p1)` of
/// the sample's row and of the row below in the 16-bit halves of each lane; `fx`, `fy` the weights.
#[target_feature(enable = "avx2")]
#[inline]
fn interpolate(upper: __m256i, lower: __m256i, fx: __m256i, fy: __m256i) -> __m256i {
    // Times (256 - fx, fx) pairwise: p0 (256 - fx) + p1 fx.
    let weights = _mm256_or_si256(
        _mm256_sub_epi32(_mm256_set1_epi32(256), fx),
        _mm256_slli_epi32::<16>(fx),
    );
    let upper = _mm256_madd_epi16(upper, weights);
    let lower = _mm256_madd_epi16(lower, weights);
    // upper (256 - fy) + lower fy + 2^15, the same integer as the reference, then >> 16.
    let sum = _mm256_add_epi32(
        _mm256_slli_epi32::<8>(upper),
        _mm256_mullo_epi32(_mm256_sub_epi32(lower, upper), fy),
    );
    _mm256_srai_epi32::<16>(_mm256_add_epi32(sum, _mm256_set1_epi32(1 << 15)))
}

/// See [`Avx2::masked_bits`].
///
/// # Safety
/// AVX2 must be present; every patch of `offsets` must lie inside the window.
#[target_feature(enable = "avx2")]
unsafe fn masked_bits(
    window: &Window,
    offsets: &[PatchOffsets],
    mask: &PixelMask,
    out: &mut [u64],
) {
    // Rows of weight 0 need no loads: the default weights' row 0 is skipped.
    // SAFETY: forwarded.
    if mask[..PATCH].iter().all(|&m| m == 0) {
        unsafe { masked_bits_from::<1>(window, offsets, mask, out) }
    } else {
        unsafe { masked_bits_from::<0>(window, offsets, mask, out) }
    }
}

/// Patch rows `FIRST..PATCH` as the kernel loads them: pairs of rows in one register each, then the
/// last row alone when an odd number remain.
struct RowMasks {
    pairs: [__m256i; PATCH / 2],
    last: __m128i,
}

/// [`masked_bits`] summing patch rows `FIRST..PATCH` only (the mask is 0 on the rows before).
///
/// # Safety
/// As [`masked_bits`].
#[target_feature(enable = "avx2")]
unsafe fn masked_bits_from<const FIRST: usize>(
    window: &Window,
    offsets: &[PatchOffsets],
    mask: &PixelMask,
    out: &mut [u64],
) {
    // SAFETY: reads whole rows of the 8 x 8 mask (pair k: rows FIRST + 2k and FIRST + 2k + 1, only
    // for those pairs that lie inside it; the last row).
    let masks = unsafe {
        let row = |r: usize| mask.as_ptr().add(r * PATCH);
        RowMasks {
            pairs: std::array::from_fn(|k| {
                let r = FIRST + 2 * k;
                if r + 1 < PATCH {
                    _mm256_loadu_si256(row(r) as *const __m256i)
                } else {
                    _mm256_setzero_si256()
                }
            }),
            last: _mm_loadu_si128(row(PATCH - 1) as *const __m128i),
        }
    };
    let pixels = window.as_ptr();
    out.fill(0);
    for (group, triplets) in offsets.chunks_exact(8).enumerate() {
        let triplets: &[PatchOffsets; 8] = triplets.try_into().expect("chunks of 8");
        let mut sums = [_mm256_setzero_si256(); 8];
        for (sum, &triplet) in sums.iter_mut().zip(triplets) {
            // SAFETY: the caller's contract (patches inside the window).
            *sum = unsafe { triplet_sums::<FIRST>(pixels, triplet, &masks) };
        }
        // Horizontal sums of the 8 registers, lane j = triplet j: three rounds of pairwise adds.
        let h = |a, b| _mm256_hadd_epi32(a, b);
        let quads = [h(sums[0], sums[1]), h(sums[2], sums[3])];
        let quads_hi = [h(sums[4], sums[5]), h(sums[6], sums[7])];
        let (lo, hi) = (h(quads[0], quads[1]), h(quads_hi[0], quads_hi[1]));
        // lo = [t0..t3 of the low 128 bits | t0..t3 of the high], hi likewise for t4..t7.
        let totals = _mm256_add_epi32(
            _mm256_permute2x128_si256::<0x20>(lo, hi),
            _mm256_permute2x128_si256::<0x31>(lo, hi),
        );
        // Bit j = sign of triplet j's total, i.e. total < 0.
        let bits = _mm256_movemask_ps(_mm256_castsi256_ps(totals)) as u8 as u64;
        out[group / 8] |= bits << (8 * (group % 8));
    }
}

/// Per-lane partial sums of `mask · (a - c)(a + c - 2b)` over rows `FIRST..PATCH` of one triplet's
/// patches (8 lanes whose total is the reference's value when the mask is 0 on the rows before).
///
/// # Safety
/// AVX2; the patches at `offsets` lie inside the window `pixels` points to.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn triplet_sums<const FIRST: usize>(
    pixels: *const i16,
    [a, b, c]: PatchOffsets,
    masks: &RowMasks,
) -> __m256i {
    // Rows `r` (low half) and `r + 1` (high half) of the patch at `at`.
    // SAFETY: both rows lie in the patch, inside the window (the caller's contract).
    let two_rows = |at: usize, r: usize| unsafe {
        let p = pixels.add(at + r * WINDOW);
        _mm256_loadu2_m128i(p.add(WINDOW) as *const __m128i, p as *const __m128i)
    };
    let mut sum = _mm256_setzero_si256();
    for k in 0..(PATCH - FIRST) / 2 {
        let r = FIRST + 2 * k;
        let (ra, rb, rc) = (two_rows(a, r), two_rows(b, r), two_rows(c, r));
        let p = _mm256_and_si256(_mm256_sub_epi16(ra, rc), masks.pairs[k]);
        let q = _mm256_sub_epi16(_mm256_add_epi16(ra, rc), _mm256_add_epi16(rb, rb));
        sum = _mm256_add_epi32(sum, _mm256_madd_epi16(p, q));
    }
    if (PATCH - FIRST) % 2 == 1 {
        // SAFETY: the patch's last row, inside the window.
        let last_row = |at: usize| unsafe {
            _mm_loadu_si128(pixels.add(at + (PATCH - 1) * WINDOW) as *const __m128i)
        };
        let (ra, rb, rc) = (last_row(a), last_row(b), last_row(c));
        let p = _mm_and_si128(_mm_sub_epi16(ra, rc), masks.last);
        let q = _mm_sub_epi16(_mm_add_epi16(ra, rc), _mm_add_epi16(rb, rb));
        sum = _mm256_add_epi32(sum, _mm256_zextsi128_si256(_mm_madd_epi16(p, q)));
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::angle::ANGLE_BINS;
    use crate::describe::SamplingFrame;
    use crate::keypoint::KeyPoint;

    #[test]
    fn default_windows_take_the_local_copy() {
        // Size 40 (the default keypoints) at every angle, away from the borders: the copy is used;
        // size 64 at 45 degrees spans about 91 pixels: it is not.
        let (w, h) = (300, 200);
        let data = vec![0u8; w * h];
        let img = GrayView::new(&data, w, h, w).unwrap();
        let local = |size: f32, bin: usize| {
            let kp = KeyPoint::new(150.0, 100.0).with_angle(bin as f32 / 8.0);
            let frame = SamplingFrame::of(&KeyPoint { size, ..kp });
            let plan = SamplePlan::new(&img, &frame).expect("a plan");
            LocalBox::new(data.len(), &plan, &(5..60)).is_some()
        };
        assert!((0..ANGLE_BINS).all(|bin| local(40.0, bin)));
        assert!(!local(64.0, 360));
    }
}

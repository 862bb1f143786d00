//! The edge search of a whole contour, sixteen search lines side by side.
//!
//! The line-by-line search (`search::reference::search_side`, kept for the tests) pays per
//! line for bookkeeping (the peak loop, the strongest-four insertion per peak, the sub-pixel
//! step per candidate) that costs more than the few dozen samples it reads. Here the contour's lines go
//! in blocks of [`LANES`], whatever side they belong to. Each line's samples are copied into
//! one row of a buffer (a memory copy for a line along an image row, a gather for a column),
//! the buffer is transposed (SSE2 byte shuffles) so that table row `r` holds every lane's
//! sample `r − ORIGIN` steps from its base pixel, and then one sweep over the window rows
//! runs on all sixteen lanes at once with lane-wise arithmetic the compiler vectorises (AVX2
//! where the processor has it, SSE2 otherwise), each row's values kept in registers for the
//! next:
//! - the central difference `D = S[r+1] − S[r−1]` and the score of the lane's polarity;
//! - the peak flags (`score >= min_contrast`, `>` the previous row's, `>=` the next one's);
//! - the grey levels 2-3 samples either side (rounded means);
//! - the strongest four peaks of each lane's window, by a max/min insertion network over
//!   16-bit keys `score << 7 | (127 − row)` (the earlier row first among equals), fed row by
//!   row as the keys are made (no table of keys, no second sweep);
//! - then, per kept peak, five loads from the tables, and the sub-pixel step of all of them
//!   four at a time.
//!
//! Helpers on this path are plain `#[inline(always)]` functions, not closures: a closure is
//! not inlined into the AVX2 copy and runs as a scalar call per row (measured: 10 % more
//! instructions for the whole tracker).
//!
//! It computes exactly what the line-by-line search does, candidate for candidate, bit for bit
//! (`batch_tests.rs` compares them on random images, geometries and polarity rules, on both
//! vector paths).

use crate::cpu::has_avx2;
use super::search::{Appearance, Candidate, PointEdges, SideGeometry, SignRule, MAX_CANDIDATES, MAX_HALF, PAD};
use super::simd::F32x4;
use crate::image::ImageView;

/// Search lines per block.
pub(crate) const LANES: usize = 16;
/// Rows of a block's tables; row `ORIGIN + o` holds the sample `o` steps from the base pixel.
const ROWS: usize = 128;
const ORIGIN: isize = (MAX_HALF + 1 + PAD) as isize;
// Keys hold the row in 7 bits and the score (<= 255) above it, within i16; rows come in
// whole chunks of 16 for the transpose.
const _: () = assert!(2 * ORIGIN < ROWS as isize && ROWS == 128 && ROWS.is_multiple_of(16));
const _: () = assert!(MAX_CANDIDATES == 4);

type RowU8 = [u8; LANES];
type RowI16 = [i16; LANES];
/// Candidate slots of a block, slot-major: slot `s` of lane `l` at `LANES · s + l`.
const SLOTS: usize = LANES * MAX_CANDIDATES;

/// A lane with no window: no row is in `lo..=hi`.
const NO_ROW_LO: i16 = i16::MAX;
const NO_ROW_HI: i16 = i16::MIN;

/// One block's tables. Rows outside a lane's gathered range hold stale values, which no
/// result reads: every row a peak in the lane's window reads is gathered.
#[derive(Clone)]
struct Tables {
    /// Each lane's samples, lane-major (`lines[l][r]`), as gathered.
    lines: [[u8; ROWS]; LANES],
    /// The same transposed: `t[r][l]`.
    t: [RowU8; ROWS],
    /// Central differences `t[r+1] − t[r−1]` of the window rows and one more either side,
    /// written as the strongest four are chosen (the peak keys live in registers only).
    d: [RowI16; ROWS],
    /// The lane's score of that difference: `|D|`, `D` or `−D`.
    s: [RowI16; ROWS],
    /// Rounded means of the samples 2 and 3 rows up, and 2 and 3 rows down (window rows).
    up: [RowU8; ROWS],
    down: [RowU8; ROWS],
}

/// Per lane of a block: where its line is and how a row becomes a normal offset.
#[derive(Clone, Copy)]
struct Lanes {
    /// The line left the image (no samples).
    outside: [bool; LANES],
    /// The window's rows (`NO_ROW_*` for none).
    lo: RowI16,
    hi: RowI16,
    /// Score: 0 either polarity (|D|), ±1 that sign times D.
    mode: [i8; LANES],
    /// Sign of the line's axis along the outward normal (±1).
    axis_sign: [i8; LANES],
    /// `h = h0 + (row − ORIGIN + δ) · step_h`.
    h0: [f32; LANES],
    step_h: [f32; LANES],
    /// Appearance reference (negative: none).
    reference: [f32; LANES],
}

impl Lanes {
    fn empty() -> Self {
        Self {
            outside: [true; LANES],
            lo: [NO_ROW_LO; LANES],
            hi: [NO_ROW_HI; LANES],
            mode: [0; LANES],
            axis_sign: [1; LANES],
            h0: [0.0; LANES],
            step_h: [1.0; LANES],
            reference: [-1.0; LANES],
        }
    }
}

/// Everything that is the same for all the lines of one search.
#[derive(Clone, Copy)]
pub(crate) struct SearchSettings<'a> {
    pub search_px: f64,
    pub signs: SignRule<'a>,
    pub appearance: Appearance<'a>,
    pub min_contrast: i32,
}

/// Where the fit wants the candidates: offsets and penalties, slot-major with `stride`
/// values per slot (slot `k` of point `i` at `k · stride + i`); an empty slot gets offset 0
/// and penalty +∞.
pub(crate) struct FitSlots<'a> {
    pub h: &'a mut [f32],
    pub penalty: &'a mut [f32],
    pub stride: usize,
}

/// The search of one contour's lines. Sized at construction; allocates nothing afterwards.
#[derive(Clone)]
pub(crate) struct ContourSearch {
    tables: Box<Tables>,
    avx2: bool,
}

impl std::fmt::Debug for ContourSearch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ContourSearch").field("avx2", &self.avx2).finish_non_exhaustive()
    }
}

impl Default for ContourSearch {
    fn default() -> Self {
        Self::new()
    }
}

impl ContourSearch {
    pub fn new() -> Self {
        let tables = Box::new(Tables {
            lines: [[0; ROWS]; LANES],
            t: [[0; LANES]; ROWS],
            d: [[0; LANES]; ROWS],
            s: [[0; LANES]; ROWS],
            up: [[0; LANES]; ROWS],
            down: [[0; LANES]; ROWS],
        });
        Self { tables, avx2: has_avx2() }
    }

    /// Searches the normal of every point `i` at `(xs[i], ys[i])` on side `sides[side_of[i]]`
    /// into `out[i]` (the same as the line-by-line search on each side),
    /// and the candidates into `fit` when given.
    #[allow(clippy::too_many_arguments)]
    pub fn search(
        &mut self,
        image: &ImageView<'_>,
        sides: &[SideGeometry],
        side_of: &[u16],
        xs: &[f64],
        ys: &[f64],
        settings: &SearchSettings<'_>,
        out: &mut [PointEdges],
        mut fit: Option<FitSlots<'_>>,
    ) {
        let n = xs.len();
        assert!(ys.len() == n && side_of.len() >= n && out.len() == n, "contour search buffers too small");
        if let Some(fit) = &fit {
            assert!(fit.stride >= n && fit.h.len() >= MAX_CANDIDATES * fit.stride && fit.penalty.len() == fit.h.len());
        }
        for first in (0..n).step_by(LANES) {
            let count = (n - first).min(LANES);
            let range = first..first + count;
            let mut lanes = Lanes::empty();
            let block = BlockInput { image, sides, side_of: &side_of[range.clone()], xs: &xs[range.clone()], ys: &ys[range.clone()], first };
            let fit = fit.as_mut().map(|f| (&mut *f.h, &mut *f.penalty, f.stride, first));
            let out = &mut out[range];
            #[cfg(target_arch = "x86_64")]
            if self.avx2 {
                // SAFETY: the processor has AVX2 (checked at construction).
                unsafe { block_avx2(&block, &mut self.tables, &mut lanes, settings, out, fit) };
                continue;
            }
            block_plain(&block, &mut self.tables, &mut lanes, settings, out, fit);
        }
    }
}

/// Places each lane's line as the line-by-line search does (sixteen lanes at a time in f64), records
/// its window in `lanes` and copies the window's samples (and three more at each end) into
/// its row of `tables.lines`. Returns the rows gathered in any lane (`lo > hi` for none).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn plan_and_gather(
    image: &ImageView<'_>,
    sides: &[SideGeometry],
    side_of: &[u16],
    xs: &[f64],
    ys: &[f64],
    first: usize,
    settings: &SearchSettings<'_>,
    tables: &mut Tables,
    lanes: &mut Lanes,
) -> (usize, usize) {
    let count = xs.len();
    assert!(count <= LANES && ys.len() == count && side_of.len() == count, "one block of lines");
    let (w, h, stride) = (image.width() as f64, image.height() as f64, image.stride() as isize);
    let data = image.data();
    let search_px = settings.search_px;
    // Each lane's point and side (lanes beyond `count` get a point that fails the checks).
    let (mut x, mut y) = ([f64::NAN; LANES], [f64::NAN; LANES]);
    let (mut n0, mut n1, mut inv) = ([0.0f64; LANES], [0.0f64; LANES], [1.0f64; LANES]);
    let (mut reach, mut horizontal, mut n_axis) = ([0.0f64; LANES], [false; LANES], [1.0f64; LANES]);
    for l in 0..count {
        let side = &sides[side_of[l] as usize];
        (x[l], y[l]) = (xs[l], ys[l]);
        (n0[l], n1[l], inv[l], n_axis[l]) = (side.normal[0], side.normal[1], side.inv_n_axis, side.n_axis);
        reach[l] = (side.half + 1 + PAD) as f64;
        horizontal[l] = side.horizontal;
        let i = first + l;
        let axis_sign: i8 = if side.n_axis >= 0.0 { 1 } else { -1 };
        lanes.axis_sign[l] = axis_sign;
        lanes.mode[l] = axis_sign * settings.signs.sign(i).signum() as i8;
        if settings.appearance.gain > 0.0 {
            lanes.reference[l] = settings.appearance.reference.get(i).copied().unwrap_or(-1.0);
        }
    }
    // The base pixel, whether the line lies inside the image, the base pixel's normal offset
    // from the point and the window of offsets within ±search_px (the operations of
    // line-by-line search, lane by lane).
    let mut ok = [false; LANES];
    // The window's first and last rows and where its first gathered sample lies in the image,
    // converted here for all lanes at once (whole numbers, exact in f64; nonsense but
    // harmless in a lane that is not `ok`).
    let (mut row_lo, mut row_hi, mut start_at) = ([0i32; LANES], [0i32; LANES], [0i64; LANES]);
    let stride_f = stride as f64;
    let pad = PAD as f64;
    for l in 0..LANES {
        // Also false for NaN.
        let finite = x[l].abs() <= 1e8 && y[l].abs() <= 1e8;
        let (px, py) = if finite { (x[l], y[l]) } else { (0.0, 0.0) };
        let (bx, by) = ((px + 0.5).floor(), (py + 0.5).floor());
        let (along, across, along_size, across_size) =
            if horizontal[l] { (bx, by, w, h) } else { (by, bx, h, w) };
        let inside = across >= 0.0 && across < across_size && along - reach[l] >= 0.0 && along + reach[l] < along_size;
        let h0 = n0[l] * (bx - px) + n1[l] * (by - py);
        let (k_a, k_b) = ((-search_px - h0) * inv[l], (search_px - h0) * inv[l]);
        let lo = k_a.min(k_b).ceil().max(pad - reach[l]);
        let hi = k_a.max(k_b).floor().min(reach[l] - pad);
        ok[l] = finite & inside;
        lanes.outside[l] = !(finite & inside);
        ok[l] &= lo <= hi;
        (row_lo[l], row_hi[l]) = ((ORIGIN as f64 + lo) as i32, (ORIGIN as f64 + hi) as i32);
        // The first gathered sample is three before the window's first.
        let step = if horizontal[l] { 1.0 } else { stride_f };
        start_at[l] = (by * stride_f + bx + (lo - 3.0) * step) as i64;
        lanes.h0[l] = h0 as f32;
        lanes.step_h[l] = n_axis[l] as f32;
    }
    let (mut gathered_lo, mut gathered_hi) = (ROWS, 0usize);
    for l in 0..count {
        if !ok[l] {
            continue;
        }
        let (r_lo, r_hi) = (row_lo[l] as isize, row_hi[l] as isize);
        lanes.lo[l] = r_lo as i16;
        lanes.hi[l] = r_hi as i16;
        // The window's samples and three more at each end (a peak reads three either side).
        let (g_lo, g_hi) = ((r_lo - 3) as usize, (r_hi + 3) as usize);
        gathered_lo = gathered_lo.min(g_lo);
        gathered_hi = gathered_hi.max(g_hi);
        let step = if horizontal[l] { 1 } else { stride };
        let start = start_at[l] as isize;
        let samples = g_hi - g_lo + 1;
        // The line lies inside the image (checked above), and these samples inside the line.
        assert!(start >= 0 && (start as usize + (samples - 1) * step as usize) < data.len(), "search line outside the image");
        let line = &mut tables.lines[l];
        if horizontal[l] {
            // Whole 16-byte chunks where the image and the row have room for them.
            let chunks = samples.div_ceil(16);
            if start as usize + 16 * chunks <= data.len() && g_lo + 16 * chunks <= ROWS {
                for c in 0..chunks {
                    let at = start as usize + 16 * c;
                    line[g_lo + 16 * c..g_lo + 16 * c + 16].copy_from_slice(&data[at..at + 16]);
                }
            } else {
                line[g_lo..=g_hi].copy_from_slice(&data[start as usize..start as usize + samples]);
            }
        } else {
            // SAFETY: the samples read are start + j · stride for j < samples, inside `data`
            // (asserted above).
            unsafe {
                let mut src = data.as_ptr().offset(start);
                for b in &mut line[g_lo..=g_hi] {
                    *b = *src;
                    src = src.wrapping_offset(stride);
                }
            }
        }
    }
    (gathered_lo, gathered_hi)
}

/// One block's lines.
struct BlockInput<'a, 'b> {
    image: &'a ImageView<'b>,
    sides: &'a [SideGeometry],
    side_of: &'a [u16],
    xs: &'a [f64],
    ys: &'a [f64],
    first: usize,
}

type FitOut<'a> = Option<(&'a mut [f32], &'a mut [f32], usize, usize)>;

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn block_avx2(
    input: &BlockInput<'_, '_>,
    tables: &mut Tables,
    lanes: &mut Lanes,
    settings: &SearchSettings<'_>,
    out: &mut [PointEdges],
    fit: FitOut<'_>,
) {
    block(input, tables, lanes, settings, out, fit);
}

fn block_plain(
    input: &BlockInput<'_, '_>,
    tables: &mut Tables,
    lanes: &mut Lanes,
    settings: &SearchSettings<'_>,
    out: &mut [PointEdges],
    fit: FitOut<'_>,
) {
    block(input, tables, lanes, settings, out, fit);
}

/// One block: place and gather, transpose, scan, select, refine, write out.
#[inline(always)]
fn block(
    input: &BlockInput<'_, '_>,
    tables: &mut Tables,
    lanes: &mut Lanes,
    settings: &SearchSettings<'_>,
    out: &mut [PointEdges],
    fit: FitOut<'_>,
) {
    let (g_lo, g_hi) =
        plan_and_gather(input.image, input.sides, input.side_of, input.xs, input.ys, input.first, settings, tables, lanes);
    let top = if g_lo <= g_hi {
        transpose(tables, g_lo, g_hi);
        strongest(tables, lanes, settings.min_contrast)
    } else {
        [[0; LANES]; MAX_CANDIDATES]
    };
    refine(tables, lanes, &top, settings, out, fit);
}

/// `t[r][l] = lines[l][r]` for the 16-row chunks covering `lo..=hi`.
#[inline(always)]
fn transpose(tables: &mut Tables, lo: usize, hi: usize) {
    for r0 in (lo & !15..=hi).step_by(16) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: SSE2 is part of the x86_64 baseline; r0 + 16 <= ROWS, so every load reads
        // 16 bytes of a lane's row and every store writes one table row.
        unsafe {
            use std::arch::x86_64::*;
            let mut v = [_mm_setzero_si128(); 16];
            for (l, v) in v.iter_mut().enumerate() {
                *v = _mm_loadu_si128(tables.lines[l].as_ptr().add(r0) as *const __m128i);
            }
            // Four rounds of interleaving pairs of rows: bytes, then 2, 4 and 8 bytes. Row i of
            // the result is the input's column bit-reversed(i).
            macro_rules! round {
                ($lo:ident, $hi:ident) => {{
                    let mut w = v;
                    for i in 0..8 {
                        w[i] = $lo(v[2 * i], v[2 * i + 1]);
                        w[i + 8] = $hi(v[2 * i], v[2 * i + 1]);
                    }
                    v = w;
                }};
            }
            round!(_mm_unpacklo_epi8, _mm_unpackhi_epi8);
            round!(_mm_unpacklo_epi16, _mm_unpackhi_epi16);
            round!(_mm_unpacklo_epi32, _mm_unpackhi_epi32);
            round!(_mm_unpacklo_epi64, _mm_unpackhi_epi64);
            for (i, row) in v.iter().enumerate() {
                let r = r0 + BIT_REVERSE_4[i];
                _mm_storeu_si128(tables.t[r].as_mut_ptr() as *mut __m128i, *row);
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        for r in r0..r0 + 16 {
            for l in 0..LANES {
                tables.t[r][l] = tables.lines[l][r];
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
const BIT_REVERSE_4: [usize; 16] = [0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15];

/// Per lane, the masks that turn a difference `D` into the lane's score `(D ^ m) − m`: `m`
/// all ones where D is negated (its sign for either polarity, or −1 for the negative one)
/// and 0 where it is kept. Returns `(neg, either)`; `m = (D >> 15 & either) | neg`.
#[inline(always)]
fn score_masks(lanes: &Lanes) -> (RowI16, RowI16) {
    let (mut neg, mut either) = ([0i16; LANES], [0i16; LANES]);
    for l in 0..LANES {
        neg[l] = -((lanes.mode[l] < 0) as i16);
        either[l] = -((lanes.mode[l] == 0) as i16);
    }
    (neg, either)
}

/// The lanes' scores of the central differences `after − before` (table rows `r + 1` and
/// `r − 1` for row `r`).
#[inline(always)]
fn scores(before: &RowU8, after: &RowU8, neg: &RowI16, either: &RowI16) -> (RowI16, RowI16) {
    let (mut d, mut s) = ([0i16; LANES], [0i16; LANES]);
    for l in 0..LANES {
        d[l] = after[l] as i16 - before[l] as i16;
        let m = (d[l] >> 15 & either[l]) | neg[l];
        s[l] = (d[l] ^ m).wrapping_sub(m);
    }
    (d, s)
}

/// Row `r`'s differences and scores, also into the tables (for the kept peaks' sub-pixel
/// step). A plain function, not a closure: it must inline into the AVX2 path.
#[inline(always)]
fn row_scores(tables: &mut Tables, r: usize, neg: &RowI16, either: &RowI16) -> RowI16 {
    let (d, s) = scores(&tables.t[r - 1], &tables.t[r + 1], neg, either);
    (tables.d[r], tables.s[r]) = (d, s);
    s
}

/// The strongest four peaks of each lane's window, strongest first, as keys
/// `score << 7 | (127 − row)` (the earlier row first among equals; 0: none). One sweep over
/// the window rows of all lanes: each row's scores come from the samples either side, a row
/// is a peak where its score is at least `min_contrast`, above the previous row's and not
/// below the next one's, and its key goes through a max/min insertion network.
#[inline(always)]
fn strongest(tables: &mut Tables, lanes: &Lanes, min_contrast: i32) -> [[i16; LANES]; MAX_CANDIDATES] {
    let mut top = [[0i16; LANES]; MAX_CANDIDATES];
    let (mut lo, mut hi) = (NO_ROW_LO, NO_ROW_HI);
    for l in 0..LANES {
        lo = lo.min(lanes.lo[l]);
        hi = hi.max(lanes.hi[l]);
    }
    if lo > hi {
        return top;
    }
    let (lo, hi) = (lo as usize, hi as usize);
    // A window row's neighbours' scores and its grey levels read three rows either side.
    assert!(lo >= 3 && hi + 3 < ROWS, "window rows within the tables");
    let (neg, either) = score_masks(lanes);
    // Scores reach 255 at most: a threshold above that finds nothing, as it should. A
    // negative one-sided score can be no peak's neighbour that matters: a peak scores >= 1.
    let below = min_contrast.clamp(1, 256) as i16 - 1;
    let mut prev = row_scores(tables, lo - 1, &neg, &either);
    let mut here = row_scores(tables, lo, &neg, &either);
    for r in lo..=hi {
        let next = row_scores(tables, r + 1, &neg, &either);
        let (u2, u3, d2, d3) = (&tables.t[r + 2], &tables.t[r + 3], &tables.t[r - 2], &tables.t[r - 3]);
        let (mut up, mut down) = ([0u8; LANES], [0u8; LANES]);
        for l in 0..LANES {
            up[l] = ((u2[l] as u16 + u3[l] as u16 + 1) >> 1) as u8;
            down[l] = ((d2[l] as u16 + d3[l] as u16 + 1) >> 1) as u8;
        }
        (tables.up[r], tables.down[r]) = (up, down);
        let (row, tag) = (r as i16, 127 - r as i16);
        let mut key = [0i16; LANES];
        for l in 0..LANES {
            let peak = -((here[l] > below) as i16) & -((here[l] > prev[l]) as i16) & !-((next[l] > here[l]) as i16);
            let inside = -((row >= lanes.lo[l]) as i16) & -((row <= lanes.hi[l]) as i16);
            key[l] = peak & inside & (here[l] << 7 | tag);
        }
        for slot in &mut top {
            for l in 0..LANES {
                let better = slot[l].max(key[l]);
                key[l] = slot[l].min(key[l]);
                slot[l] = better;
            }
        }
        (prev, here) = (here, next);
    }
    top
}

/// The kept peaks' sub-pixel offsets, contrasts, grey levels and appearance penalties, into
/// `out` and the fit's slots (the lanes beyond `out.len()` are ignored).
#[inline(always)]
fn refine(
    tables: &Tables,
    lanes: &Lanes,
    top: &[[i16; LANES]; MAX_CANDIDATES],
    settings: &SearchSettings<'_>,
    out: &mut [PointEdges],
    fit: FitOut<'_>,
) {
    // Per kept peak, five loads from the tables (slot-major).
    let mut a = [0.0f32; SLOTS];
    let mut b = [0.0f32; SLOTS];
    let mut c = [0.0f32; SLOTS];
    let mut offset = [0.0f32; SLOTS];
    let mut sign = [1.0f32; SLOTS];
    let mut grey = [0.0f32; SLOTS];
    let mut inside = [0u8; SLOTS];
    let mut outside = [0u8; SLOTS];
    let mut peaks = [0u8; LANES];
    for l in 0..out.len() {
        let upward = lanes.axis_sign[l] < 0; // the interior lies towards higher rows
        let axis_sign = lanes.axis_sign[l] as i32;
        for (s, slot) in top.iter().enumerate() {
            let key = slot[l];
            if key == 0 {
                break;
            }
            peaks[l] = s as u8 + 1;
            let r = (127 - (key & 127)) as usize;
            assert!((3..ROWS - 3).contains(&r), "peak row within the tables");
            let k = s * LANES + l;
            a[k] = tables.s[r - 1][l] as f32;
            b[k] = (key >> 7) as f32;
            c[k] = tables.s[r + 1][l] as f32;
            offset[k] = (r as isize - ORIGIN) as f32;
            // The derivative's sign along the outward normal: that of the axis times D.
            sign[k] = if axis_sign * tables.d[r][l] as i32 >= 0 { 1.0 } else { -1.0 };
            let (up, down) = (tables.up[r][l], tables.down[r][l]);
            (inside[k], outside[k]) = if upward { (up, down) } else { (down, up) };
            grey[k] = inside[k] as f32;
        }
    }
    // The sub-pixel step of all of them, four at a time: the parabola through each peak and
    // its neighbours (the operations of the line-by-line search, in the same order).
    let limit = F32x4::splat(settings.search_px as f32);
    let (gain, tolerance) = (F32x4::splat(settings.appearance.gain), F32x4::splat(settings.appearance.tolerance));
    let (zero, half, two, quarter) = (F32x4::splat(0.0), F32x4::splat(0.5), F32x4::splat(2.0), F32x4::splat(0.25));
    let mut h_px = [0.0f32; SLOTS];
    let mut contrast = [0.0f32; SLOTS];
    let mut penalty = [0.0f32; SLOTS];
    let mut slipped = 0u64;
    for k in (0..SLOTS).step_by(4) {
        let l = k % LANES;
        // SAFETY: k + 4 <= SLOTS and l + 4 <= LANES, so every load and store is in bounds.
        unsafe {
            let at = |v: &[f32; SLOTS]| F32x4::load_ptr(v.as_ptr().add(k));
            let (a, b, c) = (at(&a), at(&b), at(&c));
            let denom = a.sub(two.mul(b)).add(c);
            let vertex = half.mul(a.sub(c)).div(denom).min(half).max(F32x4::splat(-0.5));
            let delta = denom.lt(zero).select(vertex, zero);
            let (h0, step_h) = (F32x4::load_ptr(lanes.h0.as_ptr().add(l)), F32x4::load_ptr(lanes.step_h.as_ptr().add(l)));
            let h = h0.add(at(&offset).add(delta).mul(step_h));
            h.store_ptr(h_px.as_mut_ptr().add(k));
            slipped |= (limit.lt(h.abs()).mask_bits() as u64) << k;
            let peak = b.sub(quarter.mul(a.sub(c)).mul(delta));
            peak.mul(at(&sign)).store_ptr(contrast.as_mut_ptr().add(k));
            let reference = F32x4::load_ptr(lanes.reference.as_ptr().add(l));
            let cost = gain.mul(at(&grey).sub(reference).abs().sub(tolerance).max(zero));
            zero.le(reference).select(cost, zero).store_ptr(penalty.as_mut_ptr().add(k));
        }
    }
    // A peak interpolated just past the window's end is dropped, and the lane's later ones
    // move up a slot.
    let mut lanes_slipped = slipped;
    while lanes_slipped != 0 {
        let l = (lanes_slipped.trailing_zeros() as usize) % LANES;
        let mut kept = 0;
        for s in 0..peaks[l] as usize {
            let (from, to) = (s * LANES + l, kept * LANES + l);
            if slipped >> from & 1 == 0 {
                h_px[to] = h_px[from];
                contrast[to] = contrast[from];
                inside[to] = inside[from];
                outside[to] = outside[from];
                penalty[to] = penalty[from];
                kept += 1;
            }
        }
        peaks[l] = kept as u8;
        // This lane is done, in every slot.
        for s in 0..MAX_CANDIDATES {
            lanes_slipped &= !(1u64 << (s * LANES + l));
        }
    }
    // Slot s of lane l holds a candidate exactly when s < peaks[l].
    for (l, out) in out.iter_mut().enumerate() {
        out.outside = lanes.outside[l];
        out.count = peaks[l];
        for (s, cand) in out.candidates[..peaks[l] as usize].iter_mut().enumerate() {
            let k = s * LANES + l;
            *cand = Candidate { h_px: h_px[k], contrast: contrast[k], inside: inside[k], outside: outside[k], penalty_px: penalty[k] };
        }
    }
    if let Some((h, pen, stride, first)) = fit {
        let count = out.len();
        let quads = count / 4 * 4;
        let mut present_from = [0.0f32; LANES];
        for l in 0..LANES {
            present_from[l] = peaks[l] as f32;
        }
        let infinity = F32x4::splat(f32::INFINITY);
        for s in 0..MAX_CANDIDATES {
            let base = s * stride + first;
            let (h, pen) = (&mut h[base..base + count], &mut pen[base..base + count]);
            let slot = F32x4::splat(s as f32);
            for l in (0..quads).step_by(4) {
                let k = s * LANES + l;
                // SAFETY: l + 4 <= count <= LANES, the length of `h` and `pen` and of the
                // block's lane arrays; k + 4 <= SLOTS.
                unsafe {
                    let present = slot.lt(F32x4::load_ptr(present_from.as_ptr().add(l)));
                    present.select(F32x4::load_ptr(h_px.as_ptr().add(k)), zero).store_ptr(h.as_mut_ptr().add(l));
                    present.select(F32x4::load_ptr(penalty.as_ptr().add(k)), infinity).store_ptr(pen.as_mut_ptr().add(l));
                }
            }
            for l in quads..count {
                let k = s * LANES + l;
                (h[l], pen[l]) = if s < peaks[l] as usize { (h_px[k], penalty[k]) } else { (0.0, f32::INFINITY) };
            }
        }
    }
}

#[cfg(test)]
#[path = "batch_tests.rs"]
mod tests;

//! The edge search of a whole contour, sixteen search lines side by side.
//!
//! [`search_side`](super::search::search_side) handles one line at a time: its per-line
//! bookkeeping (placing the window, the peak loop, the strongest-four insertion per peak, the
//! sub-pixel step per candidate) costs far more than the few dozen samples it reads. Here the
//! contour's lines go in blocks of [`LANES`], whatever side they belong to: each line's samples
//! are gathered into one lane of a table whose rows are offsets from the line's base pixel
//! (row [`ORIGIN`] is the base pixel), and then every step runs row by row on all sixteen lanes
//! at once with plain lane-wise arithmetic the compiler vectorises (AVX2 where the processor
//! has it, SSE2 otherwise):
//! - the central difference `D = S[r+1] − S[r−1]` and the score of the lane's polarity;
//! - the peak flags (`score >= min_contrast`, `>` the previous row's, `>=` the next one's);
//! - the strongest four peaks of each lane's window, by a max/min insertion network over
//!   16-bit keys `score << 7 | (127 − row)` (the earlier row first among equals);
//! - then, per kept peak, a handful of loads from the tables and the sub-pixel step, again
//!   sixteen lanes at a time.
//!
//! It computes exactly what `search_side` does, candidate for candidate, bit for bit (a test
//! compares them on random images, geometries and polarity rules). The tables stay after a
//! search, so a later pass can select again from the same lines ([`ContourSearch::reselect`])
//! without reading the image.

use super::search::{
    ceil_to_isize, floor_to_isize, Appearance, Candidate, PointEdges, SideGeometry, SignRule, MAX_CANDIDATES, MAX_HALF,
    PAD,
};
use super::simd::F32x4;
use crate::image::ImageView;

/// Search lines per block.
pub(crate) const LANES: usize = 16;
/// Rows of a block's tables; row `ORIGIN + o` holds the sample `o` steps from the base pixel.
const ROWS: usize = 128;
const ORIGIN: isize = (MAX_HALF + 1 + PAD) as isize;
// Keys hold the row in 7 bits and the score (<= 255) above it, within i16.
const _: () = assert!(2 * ORIGIN < ROWS as isize && ROWS <= 128);
const _: () = assert!(MAX_CANDIDATES == 4);

type RowU8 = [u8; LANES];
type RowI16 = [i16; LANES];
type Slots<T> = [[T; LANES]; MAX_CANDIDATES];
/// Candidate slots of a block, slot-major.
const SLOTS: usize = LANES * MAX_CANDIDATES;

/// A lane with no window: its rows are never in `lo..=hi`.
const NO_ROW_LO: i16 = i16::MAX;
const NO_ROW_HI: i16 = i16::MIN;

/// One block's sample tables and the lanes' fixed geometry.
#[derive(Clone)]
struct Block {
    /// Samples.
    t: [RowU8; ROWS],
    /// Central differences `t[r+1] − t[r−1]`.
    d: [RowI16; ROWS],
    /// Peak keys (0: no peak at this row), before any window.
    k: [RowI16; ROWS],
    /// Rows whose key is valid: `key_lo..=key_hi` (the block's union).
    key_lo: usize,
    key_hi: usize,
    /// Per lane: the line left the image (no samples); the sample `o` steps from the base
    /// pixel is `data[base + o · step]`.
    outside: [bool; LANES],
    base: [isize; LANES],
    step: [isize; LANES],
    /// Rows gathered, per lane (`NO_ROW_*` for none).
    gathered_lo: RowI16,
    gathered_hi: RowI16,
    /// Score sign per lane: 0 either polarity (|D|), ±1 that sign times D.
    mode: [i8; LANES],
    /// Sign of the line's axis along the outward normal (±1).
    axis_sign: [i8; LANES],
}

impl Block {
    fn new() -> Self {
        Self {
            t: [[0; LANES]; ROWS],
            d: [[0; LANES]; ROWS],
            k: [[0; LANES]; ROWS],
            key_lo: 1,
            key_hi: 0,
            outside: [true; LANES],
            base: [0; LANES],
            step: [0; LANES],
            gathered_lo: [NO_ROW_LO; LANES],
            gathered_hi: [NO_ROW_HI; LANES],
            mode: [0; LANES],
            axis_sign: [1; LANES],
        }
    }
}

/// Where each lane searches in one selection: its window of rows and how a row's offset
/// becomes a normal offset (`h = h0 + (row − ORIGIN − shift + δ) · step_h`).
#[derive(Clone, Copy)]
struct Windows {
    lo: RowI16,
    hi: RowI16,
    shift: [i32; LANES],
    h0: [f32; LANES],
    step_h: [f32; LANES],
    /// Appearance reference per lane (negative: none).
    reference: [f32; LANES],
}

impl Windows {
    fn empty() -> Self {
        Self {
            lo: [NO_ROW_LO; LANES],
            hi: [NO_ROW_HI; LANES],
            shift: [0; LANES],
            h0: [0.0; LANES],
            step_h: [1.0; LANES],
            reference: [-1.0; LANES],
        }
    }
}

/// The search of one contour's lines, with the tables kept for [`reselect`](Self::reselect).
/// Sized at construction for a number of points; allocates nothing afterwards.
#[derive(Clone)]
pub(crate) struct ContourSearch {
    blocks: Vec<Block>,
    /// Lines searched by the last [`search`](Self::search).
    lines: usize,
    avx2: bool,
}

impl std::fmt::Debug for ContourSearch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ContourSearch").field("blocks", &self.blocks.len()).field("lines", &self.lines).finish()
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

impl ContourSearch {
    /// Room for contours of up to `points` points.
    pub fn with_capacity(points: usize) -> Self {
        Self { blocks: vec![Block::new(); points.div_ceil(LANES)], lines: 0, avx2: has_avx2() }
    }

    /// Searches the normal of every point `i` at `(xs[i], ys[i])` on side `sides[side_of[i]]`
    /// into `out[i]`: the same as [`search_side`](super::search::search_side) on each side.
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
    ) {
        let n = xs.len();
        assert!(
            ys.len() == n && side_of.len() >= n && out.len() == n && n <= self.blocks.len() * LANES,
            "contour search buffers too small"
        );
        self.lines = n;
        for (b, block) in self.blocks.iter_mut().enumerate().take(n.div_ceil(LANES)) {
            let first = b * LANES;
            let count = (n - first).min(LANES);
            let mut windows = Windows::empty();
            plan_and_gather(image, sides, &side_of[first..first + count], &xs[first..first + count], &ys[first..first + count], first, settings, block, &mut windows);
            let out = &mut out[first..first + count];
            #[cfg(target_arch = "x86_64")]
            if self.avx2 {
                // SAFETY: the processor has AVX2 (checked at construction).
                unsafe { scan_and_select_avx2(block, &windows, settings, out) };
                continue;
            }
            scan_and_select_plain(block, &windows, settings, out);
        }
    }
}

/// Places each lane's line as `search_side` does, records its window in `windows` and
/// gathers the window's samples (and three more at each end) into the block's table.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn plan_and_gather(
    image: &ImageView<'_>,
    sides: &[SideGeometry],
    side_of: &[u16],
    xs: &[f64],
    ys: &[f64],
    first: usize,
    settings: &SearchSettings<'_>,
    block: &mut Block,
    windows: &mut Windows,
) {
    let (w, h, stride) = (image.width() as isize, image.height() as isize, image.stride() as isize);
    let data = image.data();
    let search_px = settings.search_px;
    block.outside = [true; LANES];
    block.gathered_lo = [NO_ROW_LO; LANES];
    block.gathered_hi = [NO_ROW_HI; LANES];
    let (mut key_lo, mut key_hi) = (ROWS, 0usize);
    for l in 0..xs.len() {
        let side = &sides[side_of[l] as usize];
        let (x, y) = (xs[l], ys[l]);
        let i = first + l;
        let axis_sign: i8 = if side.n_axis >= 0.0 { 1 } else { -1 };
        block.axis_sign[l] = axis_sign;
        block.mode[l] = axis_sign * settings.signs.sign(i).signum() as i8;
        let reference = settings.appearance.reference.get(i).copied().unwrap_or(-1.0);
        windows.reference[l] = if settings.appearance.gain > 0.0 { reference } else { -1.0 };
        // Also false for NaN.
        if !(x.abs() <= 1e8 && y.abs() <= 1e8) {
            continue;
        }
        let reach = (side.half + 1 + PAD) as isize;
        let len = 2 * reach + 1;
        let (bxi, byi) = (floor_to_isize(x + 0.5), floor_to_isize(y + 0.5));
        let (along, across, along_size, across_size) =
            if side.horizontal { (bxi, byi, w, h) } else { (byi, bxi, h, w) };
        if !(across >= 0 && across < across_size && along - reach >= 0 && along + reach < along_size) {
            continue;
        }
        block.outside[l] = false;
        let h0 = side.normal[0] * (bxi as f64 - x) + side.normal[1] * (byi as f64 - y);
        let (k_a, k_b) = ((-search_px - h0) * side.inv_n_axis, (search_px - h0) * side.inv_n_axis);
        let k_lo = (ceil_to_isize(k_a.min(k_b)) + reach).max(PAD as isize);
        let k_hi = (floor_to_isize(k_a.max(k_b)) + reach).min(len - PAD as isize - 1);
        if k_lo > k_hi {
            continue;
        }
        // Rows of the window and of the samples it reads.
        let (r_lo, r_hi) = (ORIGIN + k_lo - reach, ORIGIN + k_hi - reach);
        windows.lo[l] = r_lo as i16;
        windows.hi[l] = r_hi as i16;
        windows.h0[l] = h0 as f32;
        windows.step_h[l] = side.n_axis as f32;
        let step = if side.horizontal { 1 } else { stride };
        let base = byi * stride + bxi;
        block.base[l] = base;
        block.step[l] = step;
        let (g_lo, g_hi) = (r_lo - 3, r_hi + 3);
        block.gathered_lo[l] = g_lo as i16;
        block.gathered_hi[l] = g_hi as i16;
        key_lo = key_lo.min(r_lo as usize);
        key_hi = key_hi.max(r_hi as usize);
        // The line lies inside the image (checked above), and these rows inside the line.
        debug_assert!(g_lo - ORIGIN >= -reach && g_hi - ORIGIN <= reach);
        let start = base + (g_lo - ORIGIN) * step;
        debug_assert!(start >= 0 && start + (g_hi - g_lo) * step < data.len() as isize);
        // SAFETY: the samples read are start + j · step for j <= g_hi − g_lo, inside the line
        // and so inside `data` (asserted above); the rows written are g_lo..=g_hi < ROWS.
        unsafe {
            let src = data.as_ptr().offset(start);
            let dst = (block.t.as_mut_ptr() as *mut u8).add(g_lo as usize * LANES + l);
            let count = (g_hi - g_lo + 1) as usize;
            let mut j = 0;
            while j + 4 <= count {
                let s = src.offset(j as isize * step);
                *dst.add(j * LANES) = *s;
                *dst.add((j + 1) * LANES) = *s.offset(step);
                *dst.add((j + 2) * LANES) = *s.offset(2 * step);
                *dst.add((j + 3) * LANES) = *s.offset(3 * step);
                j += 4;
            }
            while j < count {
                *dst.add(j * LANES) = *src.offset(j as isize * step);
                j += 1;
            }
        }
    }
    block.key_lo = key_lo;
    block.key_hi = key_hi;
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn scan_and_select_avx2(block: &mut Block, windows: &Windows, settings: &SearchSettings<'_>, out: &mut [PointEdges]) {
    scan(block, settings.min_contrast);
    select(block, windows, settings, out);
}

fn scan_and_select_plain(block: &mut Block, windows: &Windows, settings: &SearchSettings<'_>, out: &mut [PointEdges]) {
    scan(block, settings.min_contrast);
    select(block, windows, settings, out);
}

/// Differences, scores and peak keys of the rows `key_lo..=key_hi` (all lanes).
#[inline(always)]
fn scan(block: &mut Block, min_contrast: i32) {
    let (lo, hi) = (block.key_lo, block.key_hi);
    if lo > hi {
        return;
    }
    assert!(lo >= 2 && hi + 2 < ROWS, "key rows within the tables");
    // Score of each lane's polarity: |D|, D or −D; kept as `max(D & pos, −D & neg)`, which
    // clamps a negative one-sided score to 0 (no peak has a score below 1, so no flag
    // changes).
    let (mut pos, mut neg) = ([0i16; LANES], [0i16; LANES]);
    for l in 0..LANES {
        pos[l] = -((block.mode[l] >= 0) as i16);
        neg[l] = -((block.mode[l] <= 0) as i16);
    }
    // Scores reach 255 at most: a threshold above that finds nothing, as it should.
    let below = min_contrast.clamp(1, 256) as i16 - 1;
    // Rows lo-1..=hi+1 of D (the candidates read D beside a peak), scores rolling.
    let (mut s_prev, mut s_here) = ([0i16; LANES], [0i16; LANES]);
    for r in lo - 1..=lo {
        let (t_before, t_after) = (block.t[r - 1], block.t[r + 1]);
        let d = &mut block.d[r];
        for l in 0..LANES {
            d[l] = t_after[l] as i16 - t_before[l] as i16;
            s_prev[l] = s_here[l];
            s_here[l] = (d[l] & pos[l]).max(d[l].wrapping_neg() & neg[l]);
        }
    }
    for r in lo..=hi {
        let (t_before, t_after) = (block.t[r], block.t[r + 2]);
        let mut d = [0i16; LANES];
        let mut s_next = [0i16; LANES];
        let mut key = [0i16; LANES];
        let tag = 127 - r as i16;
        for l in 0..LANES {
            d[l] = t_after[l] as i16 - t_before[l] as i16;
            s_next[l] = (d[l] & pos[l]).max(d[l].wrapping_neg() & neg[l]);
            let peak = -((s_here[l] > below) as i16) & -((s_here[l] > s_prev[l]) as i16) & !-((s_next[l] > s_here[l]) as i16);
            key[l] = peak & (s_here[l] << 7 | tag);
        }
        block.d[r + 1] = d;
        block.k[r] = key;
        s_prev = s_here;
        s_here = s_next;
    }
}

/// The strongest four peaks of each lane's window, their sub-pixel offsets and appearance
/// penalties, into `out` (the lanes beyond `out.len()` are ignored).
#[inline(always)]
fn select(block: &Block, windows: &Windows, settings: &SearchSettings<'_>, out: &mut [PointEdges]) {
    let mut top: Slots<i16> = [[0; LANES]; MAX_CANDIDATES];
    let (mut lo, mut hi) = (block.key_lo as i16, block.key_hi as i16);
    let (mut w_lo, mut w_hi) = (NO_ROW_LO, NO_ROW_HI);
    for l in 0..LANES {
        w_lo = w_lo.min(windows.lo[l]);
        w_hi = w_hi.max(windows.hi[l]);
    }
    lo = lo.max(w_lo);
    hi = hi.min(w_hi);
    for r in lo.max(0)..=hi {
        let row = &block.k[r as usize];
        let mut key = [0i16; LANES];
        for l in 0..LANES {
            let inside = -((r >= windows.lo[l]) as i16) & -((r <= windows.hi[l]) as i16);
            key[l] = row[l] & inside;
        }
        for slot in &mut top {
            for l in 0..LANES {
                let better = slot[l].max(key[l]);
                key[l] = slot[l].min(key[l]);
                slot[l] = better;
            }
        }
    }
    // Per kept peak: the scores beside it, the derivative's sign and the grey levels inside
    // and outside (scalar loads from the tables), slot-major: slot s of lane l at 16 s + l.
    let mut a = [0.0f32; SLOTS];
    let mut b = [0.0f32; SLOTS];
    let mut c = [0.0f32; SLOTS];
    let mut offset = [0.0f32; SLOTS];
    let mut sign = [1.0f32; SLOTS];
    let mut inside_f = [0.0f32; SLOTS];
    let mut outside = [0u8; SLOTS];
    let mut peaks = [0u8; LANES];
    let (t, d) = (block.t.as_ptr() as *const u8, block.d.as_ptr() as *const i16);
    for l in 0..out.len() {
        let mode = block.mode[l] as i32;
        let axis_sign = block.axis_sign[l] as i32;
        // Table steps towards the interior (rows of LANES bytes).
        let inward = -(axis_sign as isize) * LANES as isize;
        let shift = windows.shift[l];
        for (s, slot) in top.iter().enumerate() {
            let key = slot[l];
            if key == 0 {
                break;
            }
            peaks[l] = s as u8 + 1;
            let r = (127 - (key & 127)) as usize;
            assert!(r as i16 >= block.gathered_lo[l] + 3 && r as i16 <= block.gathered_hi[l] - 3, "peak outside its samples");
            let at = r * LANES + l;
            // SAFETY: the row is within the lane's gathered rows, at least three from either
            // end (asserted), and those rows lie inside the tables.
            let (d_before, d_here, d_after, t_in, t_out) = unsafe {
                let (d_before, d_here, d_after) = (*d.add(at - LANES) as i32, *d.add(at) as i32, *d.add(at + LANES) as i32);
                let g = |j: isize| *t.offset(at as isize + j) as u16;
                let t_in = (g(2 * inward) + g(3 * inward) + 1) >> 1;
                let t_out = (g(-2 * inward) + g(-3 * inward) + 1) >> 1;
                (d_before, d_here, d_after, t_in, t_out)
            };
            let (sa, sc) = if mode == 0 { (d_before.abs(), d_after.abs()) } else { (mode * d_before, mode * d_after) };
            let k = s * LANES + l;
            a[k] = sa as f32;
            b[k] = (key >> 7) as f32;
            c[k] = sc as f32;
            offset[k] = (r as i32 - ORIGIN as i32 - shift) as f32;
            sign[k] = if axis_sign * d_here >= 0 { 1.0 } else { -1.0 };
            inside_f[k] = t_in as f32;
            outside[k] = t_out as u8;
        }
    }
    // The sub-pixel step of all of them, four at a time: the parabola through each peak and
    // its neighbours (the operations of `search_side`, in the same order).
    let limit = F32x4::splat(settings.search_px as f32);
    let (gain, tolerance) = (F32x4::splat(settings.appearance.gain), F32x4::splat(settings.appearance.tolerance));
    let (zero, half, two, quarter) = (F32x4::splat(0.0), F32x4::splat(0.5), F32x4::splat(2.0), F32x4::splat(0.25));
    let mut h_px = [0.0f32; SLOTS];
    let mut contrast = [0.0f32; SLOTS];
    let mut penalty = [0.0f32; SLOTS];
    let mut slipped = [0u32; MAX_CANDIDATES];
    for s in 0..MAX_CANDIDATES {
        for l in (0..LANES).step_by(4) {
            let k = s * LANES + l;
            // SAFETY: k + 4 <= SLOTS and l + 4 <= LANES: every load and store is in bounds.
            unsafe {
                let (a, b, c) = (F32x4::load_ptr(a.as_ptr().add(k)), F32x4::load_ptr(b.as_ptr().add(k)), F32x4::load_ptr(c.as_ptr().add(k)));
                let denom = a.sub(two.mul(b)).add(c);
                let vertex = half.mul(a.sub(c)).div(denom).min(half).max(F32x4::splat(-0.5));
                let delta = denom.lt(zero).select(vertex, zero);
                let (h0, step_h) = (F32x4::load_ptr(windows.h0.as_ptr().add(l)), F32x4::load_ptr(windows.step_h.as_ptr().add(l)));
                let h = h0.add(F32x4::load_ptr(offset.as_ptr().add(k)).add(delta).mul(step_h));
                h.store_ptr(h_px.as_mut_ptr().add(k));
                slipped[s] |= limit.lt(h.abs()).mask_bits() << l;
                let peak = b.sub(quarter.mul(a.sub(c)).mul(delta));
                peak.mul(F32x4::load_ptr(sign.as_ptr().add(k))).store_ptr(contrast.as_mut_ptr().add(k));
                let reference = F32x4::load_ptr(windows.reference.as_ptr().add(l));
                let cost = gain.mul(F32x4::load_ptr(inside_f.as_ptr().add(k)).sub(reference).abs().sub(tolerance).max(zero));
                zero.le(reference).select(cost, zero).store_ptr(penalty.as_mut_ptr().add(k));
            }
        }
    }
    for (l, out) in out.iter_mut().enumerate() {
        out.outside = block.outside[l];
        let mut kept = 0;
        for s in 0..peaks[l] as usize {
            if slipped[s] >> l & 1 == 0 {
                let k = s * LANES + l;
                out.candidates[kept] = Candidate {
                    h_px: h_px[k],
                    contrast: contrast[k],
                    inside: inside_f[k] as u8,
                    outside: outside[k],
                    penalty_px: penalty[k],
                };
                kept += 1;
            }
        }
        out.count = kept as u8;
    }
}

/// Whether the processor has AVX2 (checked once per search, when it is made).
fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    return false;
}

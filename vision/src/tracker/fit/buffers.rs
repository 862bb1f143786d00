//! The per-point arrays of one fit: what the search writes (positions, normals, candidates)
//! and the fit's f32 working copies, laid out for four- and eight-lane loops.

use super::histogram::ResidualBins;
use super::types::{RobustLoss, Vec8, LANES};
use crate::cpu::has_avx2;
use crate::tracker::search::{Candidate, MAX_CANDIDATES};

/// Per-point data the fit writes, and its working copies; all sized at construction.
///
/// The working copies are f32, one array per quantity so the loops run four or eight points
/// at a time ([`F32x4`], or AVX where the processor has it), padded to whole groups of
/// [`LANES`] with points that have no candidate. The
/// tracker fills them as it searches ([`set_point`](Self::set_point),
/// [`set_candidates`](Self::set_candidates)); nothing is copied between search and fit.
#[derive(Debug, Clone, Default)]
pub(crate) struct FitBuffers {
    /// Chosen candidate index per point, -1 for none (after [`finish`](Self::finish)).
    pub chosen: Vec<i8>,
    /// Residual of the chosen candidate after the fit, px (0 for none).
    pub residual: Vec<f64>,
    /// Final robust weight (0 for none).
    pub weight: Vec<f64>,
    /// Points, and lanes (points rounded up to a multiple of 4).
    pub(super) n: usize,
    pub(super) lanes: usize,
    // Position relative to the centre, normal and c = n·p of the point's side.
    pub(super) x: Vec<f32>,
    pub(super) y: Vec<f32>,
    pub(super) nx: Vec<f32>,
    pub(super) ny: Vec<f32>,
    pub(super) c: Vec<f32>,
    /// Candidates' offsets and penalties, slot-major (slot k of point i at `k * lanes + i`, so
    /// four neighbouring points of one slot load together); +∞ penalty for an empty slot.
    pub(super) cand_h: Vec<f32>,
    pub(super) cand_pen: Vec<f32>,
    /// Per iteration: the chosen offset, its residual, whether there was one (a lane mask),
    /// and the robust weight.
    pub(super) h: Vec<f32>,
    pub(super) r: Vec<f32>,
    pub(super) valid: Vec<f32>,
    pub(super) w: Vec<f32>,
    /// The chosen candidate per lane (-1: none), from the final association.
    pub(super) chosen_lane: Vec<f32>,
    /// The last fit's motion, robust scale and loss, for [`finish`](Self::finish).
    pub(super) last: Option<(Vec8, f64, RobustLoss)>,
    /// The residual histogram, kept here: clearing all of it per fit would cost more than
    /// the counting.
    pub(super) bins: ResidualBins,
    /// The processor has AVX2: the association runs eight points at a time.
    pub(super) avx2: bool,
}

impl FitBuffers {
    pub fn with_capacity(n: usize) -> Self {
        let lanes = n.div_ceil(LANES) * LANES;
        Self {
            chosen: Vec::with_capacity(n),
            residual: Vec::with_capacity(n),
            weight: Vec::with_capacity(n),
            n: 0,
            lanes: 0,
            x: Vec::with_capacity(lanes),
            y: Vec::with_capacity(lanes),
            nx: Vec::with_capacity(lanes),
            ny: Vec::with_capacity(lanes),
            c: Vec::with_capacity(lanes),
            cand_h: Vec::with_capacity(lanes * MAX_CANDIDATES),
            cand_pen: Vec::with_capacity(lanes * MAX_CANDIDATES),
            h: Vec::with_capacity(lanes),
            r: Vec::with_capacity(lanes),
            valid: Vec::with_capacity(lanes),
            w: Vec::with_capacity(lanes),
            chosen_lane: Vec::with_capacity(lanes),
            last: None,
            bins: ResidualBins::default(),
            avx2: has_avx2(),
        }
    }

    /// Sets the number of points to `n` (no allocation within capacity). The padding lanes
    /// get no candidate; the points' own data is left for the caller to set.
    pub fn resize(&mut self, n: usize) {
        let lanes = n.div_ceil(LANES) * LANES;
        self.chosen.resize(n, -1);
        self.residual.resize(n, 0.0);
        self.weight.resize(n, 0.0);
        for v in [&mut self.x, &mut self.y, &mut self.nx, &mut self.ny, &mut self.c, &mut self.h, &mut self.r, &mut self.valid, &mut self.w, &mut self.chosen_lane] {
            v.resize(lanes, 0.0);
        }
        self.cand_h.resize(lanes * MAX_CANDIDATES, 0.0);
        self.cand_pen.resize(lanes * MAX_CANDIDATES, f32::INFINITY);
        (self.n, self.lanes) = (n, lanes);
        for i in n..lanes {
            self.set_point(i, 0.0, 0.0, 0.0, 0.0, 0.0);
            self.set_candidates(i, &[]);
        }
        self.last = None;
    }

    /// Points the buffers hold now.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Asserts the layout the four-lane loops rely on to read without bounds checks: every
    /// working array holds `lanes` values (per candidate slot), a multiple of 4.
    #[inline]
    pub(super) fn check_lanes(&self) {
        let l = self.lanes;
        assert!(
            l.is_multiple_of(LANES)
                && [&self.x, &self.y, &self.nx, &self.ny, &self.c, &self.h, &self.r, &self.valid, &self.w, &self.chosen_lane]
                    .iter()
                    .all(|v| v.len() == l)
                && self.cand_h.len() == l * MAX_CANDIDATES
                && self.cand_pen.len() == l * MAX_CANDIDATES,
            "fit buffers out of shape"
        );
    }

    /// Point `i`'s position relative to the fit's centre, its side's normal and `c = n·p`.
    #[inline]
    pub fn set_point(&mut self, i: usize, x: f32, y: f32, nx: f32, ny: f32, c: f32) {
        self.x[i] = x;
        self.y[i] = y;
        self.nx[i] = nx;
        self.ny[i] = ny;
        self.c[i] = c;
    }

    /// The points `first..first + x.len()` of one side: positions relative to the fit's
    /// centre, and the side's normal and `c = n·p` as `(n.x, n.y, c)`.
    pub fn set_side(&mut self, first: usize, x: &[f64], y: &[f64], (nx, ny, c): (f32, f32, f32)) {
        let range = first..first + x.len();
        for (d, s) in self.x[range.clone()].iter_mut().zip(x) {
            *d = *s as f32;
        }
        for (d, s) in self.y[range.clone()].iter_mut().zip(y) {
            *d = *s as f32;
        }
        self.nx[range.clone()].fill(nx);
        self.ny[range.clone()].fill(ny);
        self.c[range].fill(c);
    }

    /// Where the search writes the candidates directly: offsets and penalties, slot-major.
    pub fn candidate_slots(&mut self) -> crate::tracker::batch::FitSlots<'_> {
        crate::tracker::batch::FitSlots { h: &mut self.cand_h, penalty: &mut self.cand_pen, stride: self.lanes }
    }

    /// Point `i`'s candidate edges (at most [`MAX_CANDIDATES`]): offsets and penalties.
    #[inline]
    pub fn set_candidates(&mut self, i: usize, candidates: &[Candidate]) {
        let lanes = self.lanes;
        for k in 0..MAX_CANDIDATES {
            let (h, pen) = match candidates.get(k) {
                Some(c) => (c.h_px, c.penalty_px),
                None => (0.0, f32::INFINITY),
            };
            self.cand_h[k * lanes + i] = h;
            self.cand_pen[k * lanes + i] = pen;
        }
    }

    /// Fills the working copies from a pass's points (the tracker sets them as it searches
    /// instead).
    #[cfg(test)]
    pub(super) fn load(&mut self, points: &super::types::FitPoints<'_>, edges: &[crate::tracker::search::PointEdges]) {
        self.resize(points.px.len());
        for side in points.sides {
            for i in side.first..side.first + side.count {
                let (nx, ny, c) = (side.normal.x as f32, side.normal.y as f32, side.np as f32);
                self.set_point(i, points.px[i] as f32, points.py[i] as f32, nx, ny, c);
            }
        }
        for (i, e) in edges.iter().enumerate() {
            self.set_candidates(i, e.as_slice());
        }
    }
}

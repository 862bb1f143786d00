//! Straight line segments from sub-pixel edge points.
//!
//! 1. Linking (after Devernay): each edge point links to the nearest 8-neighbour ahead of it
//!    along the edge tangent whose gradient points the same way (within `link_max_turn_deg`),
//!    when that neighbour's nearest point behind is this one. Chains therefore never join
//!    edges of opposite polarity and break at most junctions.
//! 2. Splitting: Douglas–Peucker on each chain with tolerance `split_tol_px`.
//! 3. Fitting: total least squares per piece; points at either end that sit off the line by
//!    more than `trim_px` (the rounded corners left by smoothing) are trimmed and the line
//!    refitted, so the line is fitted to the straight part only.
//! 4. Merging: consecutive pieces of a chain, and collinear pieces of different chains across
//!    gaps up to `merge_gap_px` (an edge broken by texture or noise), when the joint fit stays
//!    within `max_rms_px`.
//!
//! Segments are oriented by polarity: walking from `p0` to `p1`, the brighter side is at
//! `(−d_v, d_u)` (the `bright_normal`), which lets the matcher reject matches of opposite
//! contrast.
//!
//! ```
//! use handeye_vision::planner::synth::Canvas;
//! use handeye_vision::planner::edges::{EdgeConfig, EdgeDetector};
//! use handeye_vision::planner::segments::{SegmentConfig, SegmentDetector};
//! let mut c = Canvas::new(120, 100, 60.0);
//! c.fill_polygon(&[[20.0, 20.0], [100.0, 20.0], [100.0, 80.0], [20.0, 80.0]], 180.0);
//! let img = c.to_image(0.0, 0);
//! let mut edges = EdgeDetector::new(EdgeConfig::default());
//! let mut segs = SegmentDetector::new(SegmentConfig::default());
//! let found = segs.detect(edges.detect(&img.view()));
//! assert_eq!(found.len(), 4); // the four sides of the rectangle
//! ```

use super::edges::EdgeMap;
use super::geom::{self, LineSums, P2};

/// Tuning of linking, splitting, fitting and merging.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentConfig {
    /// Largest turn of the gradient between linked edge points, degrees.
    pub link_max_turn_deg: f64,
    /// Douglas–Peucker tolerance: largest distance of a chain point from its piece's chord.
    pub split_tol_px: f64,
    /// End points further than this from the fitted line are trimmed (rounded corners).
    pub trim_px: f64,
    /// Shortest segment kept, pixels. (5 px with 4 points keeps the sides of the randomised
    /// cells' ~10 px faces, but together with planes from 15 px it regressed clutter3: see
    /// `PlaneConfig::min_support_px`.)
    pub min_length_px: f64,
    /// Fewest edge points in a kept segment.
    pub min_points: usize,
    /// Largest RMS residual of a (merged) segment, pixels.
    pub max_rms_px: f64,
    /// Largest angle between pieces that may merge, degrees.
    pub merge_angle_deg: f64,
    /// Largest gap between collinear pieces of different chains that may merge, pixels.
    pub merge_gap_px: f64,
}

impl Default for SegmentConfig {
    fn default() -> Self {
        Self {
            link_max_turn_deg: 40.0,
            split_tol_px: 1.0,
            trim_px: 0.45,
            min_length_px: 8.0,
            min_points: 6,
            max_rms_px: 0.5,
            merge_angle_deg: 2.5,
            merge_gap_px: 4.0,
        }
    }
}

/// A straight edge segment (see the module docs for its orientation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Start and end, on the fitted line, pixels.
    pub p0: P2,
    pub p1: P2,
    /// Mean gradient magnitude along the segment, grey levels per pixel.
    pub contrast: f64,
    /// RMS distance of its edge points from the line, pixels.
    pub rms_px: f64,
    /// Number of edge points fitted.
    pub n_points: u32,
}

impl Segment {
    #[inline]
    pub fn length(&self) -> f64 {
        geom::dist(self.p0, self.p1)
    }

    /// Unit direction from `p0` to `p1`.
    #[inline]
    pub fn dir(&self) -> P2 {
        let d = geom::sub(self.p1, self.p0);
        let l = geom::norm(d).max(1e-12);
        [d[0] / l, d[1] / l]
    }

    /// Unit normal pointing to the brighter side.
    #[inline]
    pub fn bright_normal(&self) -> P2 {
        let d = self.dir();
        [-d[1], d[0]]
    }

    #[inline]
    pub fn midpoint(&self) -> P2 {
        geom::mid(self.p0, self.p1)
    }

    /// Signed distance of `p` from the segment's line (positive on the bright side).
    #[inline]
    pub fn line_distance(&self, p: P2) -> f64 {
        geom::dot(self.bright_normal(), geom::sub(p, self.p0))
    }

    /// Position of `p` projected on the line, as a parameter: 0 at `p0`, `length` at `p1`.
    #[inline]
    pub fn along(&self, p: P2) -> f64 {
        geom::dot(self.dir(), geom::sub(p, self.p0))
    }

    /// Acute angle between the lines of two segments, radians in `[0, π/2]`.
    pub fn angle_to(&self, other: &Segment) -> f64 {
        let c = geom::dot(self.dir(), other.dir()).abs().min(1.0);
        c.acos()
    }
}

/// A reusable segment detector owning its scratch buffers.
#[derive(Debug, Clone)]
pub struct SegmentDetector {
    pub config: SegmentConfig,
    fwd: Vec<u32>,
    bwd: Vec<u32>,
    ahead: Vec<u32>,
    behind: Vec<u32>,
    visited: Vec<bool>,
    chain: Vec<u32>,
    pts: Vec<P2>,
    stack: Vec<(usize, usize)>,
    pieces: Vec<(usize, usize)>,
    /// Fitted pieces (segment, sums, gradient sum) before cross-chain merging.
    fitted: Vec<(Segment, LineSums, P2, f64)>,
    segments: Vec<Segment>,
}

const NONE: u32 = u32::MAX;

impl SegmentDetector {
    pub fn new(config: SegmentConfig) -> Self {
        Self {
            config,
            fwd: Vec::new(),
            bwd: Vec::new(),
            ahead: Vec::new(),
            behind: Vec::new(),
            visited: Vec::new(),
            chain: Vec::new(),
            pts: Vec::new(),
            stack: Vec::new(),
            pieces: Vec::new(),
            fitted: Vec::new(),
            segments: Vec::new(),
        }
    }

    /// The result of the last [`detect`](Self::detect).
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Links, splits, fits and merges the edge points of `edges` into segments.
    pub fn detect(&mut self, edges: &EdgeMap) -> &[Segment] {
        self.segments.clear();
        self.fitted.clear();
        let n = edges.points.len();
        self.fwd.clear();
        self.fwd.resize(n, NONE);
        self.bwd.clear();
        self.bwd.resize(n, NONE);
        self.visited.clear();
        self.visited.resize(n, false);
        self.link(edges);
        // Chains start at points with no predecessor; what remains unvisited is closed loops.
        for start in 0..n {
            if !self.visited[start] && self.bwd[start] == NONE {
                self.walk(edges, start as u32);
            }
        }
        for start in 0..n {
            if !self.visited[start] {
                self.walk(edges, start as u32);
            }
        }
        self.merge_across_gaps();
        let min_len = self.config.min_length_px;
        self.segments.retain(|s| s.length() >= min_len);
        &self.segments
    }

    fn link(&mut self, edges: &EdgeMap) {
        let w = edges.width as isize;
        let h = edges.height as isize;
        let cos_turn = self.config.link_max_turn_deg.to_radians().cos() as f32;
        // Best neighbour ahead (forward) and behind (backward) of each point.
        let mut ahead = std::mem::take(&mut self.ahead);
        let mut behind = std::mem::take(&mut self.behind);
        ahead.clear();
        ahead.resize(edges.points.len(), NONE);
        behind.clear();
        behind.resize(edges.points.len(), NONE);
        for (k, e) in edges.points.iter().enumerate() {
            let pix = edges.pixel[k] as isize;
            let (px, py) = (pix % w, pix / w);
            let gn = (e.gx * e.gx + e.gy * e.gy).sqrt();
            if gn <= 0.0 {
                continue;
            }
            // Tangent with the bright side on its left in (u, v): t = (gy, −gx)/|g|.
            let (tx, ty) = (e.gy / gn, -e.gx / gn);
            let (mut best_f, mut df) = (NONE, f32::INFINITY);
            let (mut best_b, mut db) = (NONE, f32::INFINITY);
            for dy in -1..=1isize {
                for dx in -1..=1isize {
                    if dx == 0 && dy == 0 {
                        continue;
                    }
                    let (qx, qy) = (px + dx, py + dy);
                    if qx < 0 || qy < 0 || qx >= w || qy >= h {
                        continue;
                    }
                    let j = edges.index[(qy * w + qx) as usize];
                    if j == EdgeMap::NONE {
                        continue;
                    }
                    let q = &edges.points[j as usize];
                    let qn = (q.gx * q.gx + q.gy * q.gy).sqrt();
                    if q.gx * e.gx + q.gy * e.gy < cos_turn * gn * qn {
                        continue;
                    }
                    let (vx, vy) = (q.x - e.x, q.y - e.y);
                    let along = vx * tx + vy * ty;
                    let d2 = vx * vx + vy * vy;
                    if along > 0.0 && d2 < df {
                        df = d2;
                        best_f = j;
                    } else if along < 0.0 && d2 < db {
                        db = d2;
                        best_b = j;
                    }
                }
            }
            ahead[k] = best_f;
            behind[k] = best_b;
        }
        for k in 0..edges.points.len() {
            let f = ahead[k];
            if f != NONE && behind[f as usize] == k as u32 {
                self.fwd[k] = f;
                self.bwd[f as usize] = k as u32;
            }
        }
        self.ahead = ahead;
        self.behind = behind;
    }

    fn walk(&mut self, edges: &EdgeMap, start: u32) {
        self.chain.clear();
        let mut k = start;
        while k != NONE && !self.visited[k as usize] {
            self.visited[k as usize] = true;
            self.chain.push(k);
            k = self.fwd[k as usize];
        }
        let closed = k == start && self.chain.len() > 2;
        if self.chain.len() < self.config.min_points {
            return;
        }
        self.pts.clear();
        self.pts.extend(self.chain.iter().map(|&i| {
            let p = &edges.points[i as usize];
            [p.x as f64, p.y as f64]
        }));
        if closed {
            // Open the loop at the point farthest from its start, so both halves split well.
            let far = (0..self.pts.len()).max_by(|&a, &b| geom::dist(self.pts[a], self.pts[0]).total_cmp(&geom::dist(self.pts[b], self.pts[0]))).unwrap_or(0);
            self.pts.rotate_left(far);
            self.chain.rotate_left(far);
        }
        self.split();
        // Fit each piece; merge consecutive pieces that are one line after all.
        let mut prev: Option<(Segment, LineSums, P2, f64)> = None;
        let pieces = std::mem::take(&mut self.pieces);
        for &(s, e) in &pieces {
            let Some(piece) = self.fit_range(edges, s, e) else {
                if let Some(p) = prev.take() {
                    self.fitted.push(p);
                }
                continue;
            };
            prev = match prev {
                Some(p) => match self.try_merge(&p, &piece) {
                    Some(m) => Some(m),
                    None => {
                        self.fitted.push(p);
                        Some(piece)
                    }
                },
                None => Some(piece),
            };
        }
        if let Some(p) = prev {
            self.fitted.push(p);
        }
        self.pieces = pieces;
    }

    /// Douglas–Peucker over `self.pts`, leaving index ranges (inclusive) in `self.pieces`.
    fn split(&mut self) {
        self.pieces.clear();
        self.stack.clear();
        self.stack.push((0, self.pts.len() - 1));
        let tol = self.config.split_tol_px;
        while let Some((s, e)) = self.stack.pop() {
            let (a, b) = (self.pts[s], self.pts[e]);
            let d = geom::sub(b, a);
            let l = geom::norm(d);
            let mut worst = (0.0, s);
            for i in s + 1..e {
                let dist = if l > 1e-9 { geom::cross(d, geom::sub(self.pts[i], a)).abs() / l } else { geom::dist(self.pts[i], a) };
                if dist > worst.0 {
                    worst = (dist, i);
                }
            }
            if worst.0 > tol {
                // Process the first half first: push the second half below it.
                self.stack.push((worst.1, e));
                self.stack.push((s, worst.1));
            } else {
                self.pieces.push((s, e));
            }
        }
    }

    /// Fits `pts[s..=e]` with end trimming; `None` when too short or too rough.
    fn fit_range(&self, edges: &EdgeMap, mut s: usize, mut e: usize) -> Option<(Segment, LineSums, P2, f64)> {
        let cfg = &self.config;
        for _ in 0..4 {
            if e + 1 < s + cfg.min_points {
                return None;
            }
            let mut sums = LineSums::default();
            for p in &self.pts[s..=e] {
                sums.add(*p);
            }
            let (c, d, _) = sums.fit()?;
            let nrm = [-d[1], d[0]];
            let off = |p: P2| geom::dot(nrm, geom::sub(p, c)).abs();
            let (s0, e0) = (s, e);
            while s < e && off(self.pts[s]) > cfg.trim_px {
                s += 1;
            }
            while e > s && off(self.pts[e]) > cfg.trim_px {
                e -= 1;
            }
            if (s, e) == (s0, e0) {
                break;
            }
        }
        if e + 1 < s + cfg.min_points {
            return None;
        }
        let mut sums = LineSums::default();
        let mut g = [0.0, 0.0];
        let mut gmag = 0.0;
        for i in s..=e {
            sums.add(self.pts[i]);
            let p = &edges.points[self.chain[i] as usize];
            g[0] += p.gx as f64;
            g[1] += p.gy as f64;
            gmag += ((p.gx * p.gx + p.gy * p.gy) as f64).sqrt();
        }
        let seg = make_segment(&sums, self.pts[s], self.pts[e], g, gmag)?;
        // Short pieces are kept for now: the staircase of a nearly axis-parallel edge (aliased
        // rendering, or a sensor without blur) jogs by a pixel, and the piece beyond the jog
        // may be short; it merges with its neighbour below, and what stays short is dropped
        // at the end.
        (seg.length() >= SHORT_PIECE_PX && seg.rms_px <= cfg.max_rms_px).then_some((seg, sums, g, gmag))
    }

    fn try_merge(&self, a: &(Segment, LineSums, P2, f64), b: &(Segment, LineSums, P2, f64)) -> Option<(Segment, LineSums, P2, f64)> {
        if geom::dot(a.0.dir(), b.0.dir()) <= 0.0 {
            return None;
        }
        // A short piece next to a longer one is often no edge of its own: the staircase of a
        // nearly axis-parallel edge (aliased rendering, a sensor without blur) jogs by a
        // pixel, and smoothing turns the jog and the rounded corner beyond it into a short,
        // tilted piece. It joins when the joint line passes within `JOG_PX` of its ends; a
        // real edge at an angle strays further within a few pixels.
        let shorter = a.0.length().min(b.0.length());
        let jog = shorter < JOG_PIECE_PX && a.0.angle_to(&b.0) < JOG_MAX_ANGLE_DEG.to_radians();
        if !jog && a.0.angle_to(&b.0) > self.merge_angle(shorter) {
            return None;
        }
        let mut sums = a.1;
        sums.merge(&b.1);
        let g = geom::add(a.2, b.2);
        let seg = make_segment(&sums, a.0.p0, b.0.p1, g, a.3 + b.3)?;
        // Both pieces' ends must stay on the joint line.
        let tol = if jog { JOG_PX } else { self.config.split_tol_px };
        let ok = [a.0.p0, a.0.p1, b.0.p0, b.0.p1].iter().all(|p| seg.line_distance(*p).abs() <= tol);
        (ok && seg.rms_px <= self.config.max_rms_px).then_some((seg, sums, g, a.3 + b.3))
    }

    /// Largest angle between two pieces that may merge, the shorter `shorter_px` long,
    /// radians: `merge_angle_deg`, or more for a short piece, whose direction is uncertain
    /// (on a weak edge, noise tilts a 12 px piece by several degrees): as much as turns it
    /// by `split_tol_px` over its length. The joint fit must still pass near all four ends.
    fn merge_angle(&self, shorter_px: f64) -> f64 {
        let cfg = &self.config;
        cfg.merge_angle_deg.to_radians().max((cfg.split_tol_px / shorter_px.max(1.0)).atan())
    }

    /// Merges collinear pieces of different chains whose facing ends are within
    /// `merge_gap_px`, using a grid of end points so the search stays local.
    fn merge_across_gaps(&mut self) {
        let n = self.fitted.len();
        let gap = self.config.merge_gap_px;
        if gap <= 0.0 || n == 0 {
            self.segments.extend(self.fitted.iter().map(|f| f.0));
            return;
        }
        // Sort by start point along a coarse grid of cell size `gap`: any partner's start lies
        // within one cell of our end.
        let cell = gap.max(1.0);
        let key = |p: P2| ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64);
        let mut starts: Vec<((i64, i64), usize)> = self.fitted.iter().enumerate().map(|(i, f)| (key(f.0.p0), i)).collect();
        starts.sort_unstable();
        let mut next = vec![usize::MAX; n];
        let mut has_prev = vec![false; n];
        for i in 0..n {
            let a = &self.fitted[i].0;
            let (kx, ky) = key(a.p1);
            let mut best = (f64::INFINITY, usize::MAX);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let k = (kx + dx, ky + dy);
                    let lo = starts.partition_point(|(kk, _)| *kk < k);
                    for &(kk, j) in &starts[lo..] {
                        if kk != k {
                            break;
                        }
                        if j == i || has_prev[j] {
                            continue;
                        }
                        let b = &self.fitted[j].0;
                        let g = a.along(b.p0) - a.length();
                        if !(-1.0..=gap).contains(&g) || geom::dist(a.p1, b.p0) > gap + 1.0 {
                            continue;
                        }
                        if a.angle_to(b) > self.merge_angle(a.length().min(b.length())) || geom::dot(a.dir(), b.dir()) <= 0.0 {
                            continue;
                        }
                        // Lateral offsets both ways within the split tolerance.
                        if a.line_distance(b.p0).abs() > 0.75 || b.line_distance(a.p1).abs() > 0.75 {
                            continue;
                        }
                        let d = geom::dist(a.p1, b.p0);
                        if d < best.0 {
                            best = (d, j);
                        }
                    }
                }
            }
            if best.1 != usize::MAX {
                next[i] = best.1;
                has_prev[best.1] = true;
            }
        }
        // Follow the chains of merges from heads (no predecessor).
        let mut used = vec![false; n];
        for i in 0..n {
            if has_prev[i] || used[i] {
                continue;
            }
            let mut acc = self.fitted[i];
            used[i] = true;
            let mut j = next[i];
            while j != usize::MAX && !used[j] {
                used[j] = true;
                match self.try_merge(&acc, &self.fitted[j]) {
                    Some(m) => acc = m,
                    None => {
                        self.segments.push(acc.0);
                        acc = self.fitted[j];
                    }
                }
                j = next[j];
            }
            self.segments.push(acc.0);
        }
        // Cycles of merges (impossible for straight pieces, but be safe).
        for i in 0..n {
            if !used[i] {
                self.segments.push(self.fitted[i].0);
            }
        }
    }
}

/// Pieces shorter than this are not kept even for merging, pixels.
const SHORT_PIECE_PX: f64 = 4.0;

/// A piece shorter than this (pixels), turned by less than `JOG_MAX_ANGLE_DEG` from its
/// neighbour in the chain, may be a staircase jog: it merges when the joint line passes
/// within `JOG_PX` of its ends (see `try_merge`).
const JOG_PIECE_PX: f64 = 16.0;
const JOG_MAX_ANGLE_DEG: f64 = 15.0;
const JOG_PX: f64 = 1.6;

/// A segment from its fit sums, the first and last points (projected onto the line) and the
/// summed gradient (for the orientation).
fn make_segment(sums: &LineSums, first: P2, last: P2, g: P2, gmag: f64) -> Option<Segment> {
    let (c, d, rms) = sums.fit()?;
    let proj = |p: P2| geom::add(c, geom::scale(d, geom::dot(d, geom::sub(p, c))));
    let (mut p0, mut p1) = (proj(first), proj(last));
    // Bright side on the left of p0→p1: cross(dir, g) > 0.
    if geom::cross(geom::sub(p1, p0), g) < 0.0 {
        std::mem::swap(&mut p0, &mut p1);
    }
    Some(Segment { p0, p1, contrast: gmag / sums.n, rms_px: rms, n_points: sums.n as u32 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::edges::{EdgeConfig, EdgeDetector};
    use crate::planner::synth::Canvas;

    fn detect(canvas: &Canvas, noise: f32) -> Vec<Segment> {
        let img = canvas.to_image(noise, 11);
        let mut e = EdgeDetector::new(EdgeConfig::default());
        let mut s = SegmentDetector::new(SegmentConfig::default());
        s.detect(e.detect(&img.view())).to_vec()
    }

    /// Distance of `p` from the infinite line through `a`, `b`.
    fn off_line(p: P2, a: P2, b: P2) -> f64 {
        let d = geom::sub(b, a);
        geom::cross(d, geom::sub(p, a)).abs() / geom::norm(d)
    }

    #[test]
    fn quadrilateral_sides_with_accurate_lines_and_endpoints() {
        let quad = [[40.3, 30.2], [150.7, 45.9], [140.1, 120.4], [55.6, 110.8]];
        let mut c = Canvas::new(200, 160, 60.0);
        c.fill_polygon(&quad, 170.0);
        for noise in [0.0, 2.0] {
            let segs = detect(&c, noise);
            assert_eq!(segs.len(), 4, "noise {noise}: {segs:?}");
            for i in 0..4 {
                let (a, b) = (quad[i], quad[(i + 1) % 4]);
                let s = segs
                    .iter()
                    .find(|s| off_line(s.midpoint(), a, b) < 1.0)
                    .unwrap_or_else(|| panic!("side {i} missing at noise {noise}"));
                // The line is accurate to a small fraction of a pixel along its length ...
                for p in [s.p0, s.p1] {
                    assert!(off_line(p, a, b) < 0.12 + 0.05 * noise as f64, "side {i} end off line by {}", off_line(p, a, b));
                }
                // ... and the ends stop short of the (rounded) corners by a few pixels at most.
                let (ea, eb) = (geom::dist(s.p0, a).min(geom::dist(s.p1, a)), geom::dist(s.p0, b).min(geom::dist(s.p1, b)));
                assert!(ea < 4.0 && eb < 4.0, "side {i}: ends {ea:.2} / {eb:.2} px from corners");
                // Bright side (inside) on the left of p0→p1: the centroid is on the bright side.
                let centre = [96.7, 76.8];
                assert!(s.line_distance(centre) > 0.0, "side {i} orientation");
            }
        }
    }

    #[test]
    fn edge_broken_by_a_gap_is_merged_but_a_corner_is_not() {
        // A long horizontal edge interrupted by a 2 px wide dark notch in the bright region
        // breaks the edge chain; the two collinear pieces must come back as one segment.
        let mut c = Canvas::new(200, 80, 60.0);
        c.fill_polygon(&[[20.0, 40.0], [180.0, 40.0], [180.0, 79.0], [20.0, 79.0]], 180.0);
        let with_notch = {
            let mut c2 = c.clone();
            c2.fill_polygon(&[[99.0, 40.0], [101.0, 40.0], [101.0, 79.0], [99.0, 79.0]], 120.0);
            c2
        };
        let segs = detect(&with_notch, 0.0);
        let horiz: Vec<&Segment> = segs.iter().filter(|s| (s.p0[1] - 40.0).abs() < 1.0 && (s.p1[1] - 40.0).abs() < 1.0).collect();
        assert_eq!(horiz.len(), 1, "{horiz:?}");
        assert!(horiz[0].length() > 150.0);
        // The rectangle's corners are not merged: horizontal and vertical sides stay apart.
        let vert = segs.iter().filter(|s| (s.p0[0] - s.p1[0]).abs() < 1.0 && s.length() > 30.0).count();
        assert!(vert >= 2, "{segs:?}");
    }

    #[test]
    fn polarity_separates_opposite_contrast() {
        // Two abutting rectangles, darker and brighter than the background: along their
        // common horizontal line the contrast flips at x = 100, giving two segments with
        // opposite orientation.
        let mut c = Canvas::new(200, 100, 100.0);
        c.fill_polygon(&[[20.0, 50.0], [100.0, 50.0], [100.0, 90.0], [20.0, 90.0]], 30.0);
        c.fill_polygon(&[[100.0, 50.0], [180.0, 50.0], [180.0, 90.0], [100.0, 90.0]], 170.0);
        let segs = detect(&c, 0.0);
        let on_line: Vec<&Segment> = segs.iter().filter(|s| (s.midpoint()[1] - 50.0).abs() < 1.0 && s.length() > 40.0).collect();
        assert_eq!(on_line.len(), 2, "{on_line:?}");
        assert!(geom::dot(on_line[0].dir(), on_line[1].dir()) < -0.99);
    }
}

//! Monocular relations between segments of one view: junctions (L, T, Y), collinears and
//! parallels, found through a uniform grid so the work grows about linearly with the number
//! of segments.
//!
//! A *junction* joins two non-parallel segments whose lines intersect within
//! `junction_gap_px` of an end of the first and of an end (L) or the interior (T) of the
//! second; its point is the intersection of the two fitted lines, which restores the corner
//! that smoothing rounded off. An L-junction whose segment end also takes part in another
//! L-junction at nearly the same point is a *Y* (three or more segments meeting: the corner of
//! a block).

use super::geom::{self, P2};
use super::segments::Segment;

/// Tolerances of the relations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelationConfig {
    /// Largest distance from a segment end to the junction point, pixels. Lines meeting at
    /// a small angle interfere over a longer stretch near their corner (their edges blur into
    /// each other), so the allowance grows as `junction_gap_px · 0.7 / sin(angle)` there, up
    /// to 2.5x.
    pub junction_gap_px: f64,
    /// The reach is at most this fraction of the shorter segment's length ...
    pub junction_gap_rel: f64,
    /// ... but never below this, pixels (three edges meeting at a block's corner round it
    /// off over ~6 px, also on short edges).
    pub junction_gap_min_px: f64,
    /// Width of the gradient of a strong edge that swamps a weak one meeting it (see
    /// `end_reach`), pixels; 0 disables the allowance.
    pub junction_swamp_sigma_px: f64,
    /// Smallest angle between the two lines of a junction, degrees.
    pub junction_min_angle_deg: f64,
    /// Largest angle between collinear or parallel segments, degrees.
    pub parallel_max_angle_deg: f64,
    /// Largest lateral offset between collinear segments, pixels.
    pub collinear_max_offset_px: f64,
    /// Largest gap along the line between collinear segments, pixels.
    pub collinear_max_gap_px: f64,
    /// Largest distance between parallel segments, pixels.
    pub parallel_max_dist_px: f64,
    /// Grid cell size, pixels.
    pub grid_cell_px: f64,
}

impl Default for RelationConfig {
    fn default() -> Self {
        Self {
            junction_gap_px: 8.0,
            junction_gap_rel: 0.2,
            junction_gap_min_px: 6.0,
            junction_swamp_sigma_px: 1.5,
            junction_min_angle_deg: 8.0,
            parallel_max_angle_deg: 3.0,
            collinear_max_offset_px: 1.5,
            collinear_max_gap_px: 30.0,
            parallel_max_dist_px: 40.0,
            grid_cell_px: 16.0,
        }
    }
}

/// Which part of a segment takes part in a junction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum End {
    P0,
    P1,
    Interior,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JunctionKind {
    /// Two segment ends meet.
    L,
    /// An end meets the interior of another segment (typically occlusion).
    T,
    /// An L whose end is shared with another L at the same point: three or more segments meet.
    Y,
}

/// A junction between segments `a` and `b` (`a < b`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Junction {
    pub a: u32,
    pub b: u32,
    pub end_a: End,
    pub end_b: End,
    /// Intersection of the two lines, pixels.
    pub point: P2,
    pub kind: JunctionKind,
}

impl Junction {
    /// The other segment of the junction and its end, seen from segment `s`.
    pub fn other(&self, s: u32) -> (u32, End) {
        if self.a == s { (self.b, self.end_b) } else { (self.a, self.end_a) }
    }

    /// The end of segment `s` in this junction.
    pub fn end_of(&self, s: u32) -> End {
        if self.a == s { self.end_a } else { self.end_b }
    }
}

/// Relations of one view.
#[derive(Debug, Clone, Default)]
pub struct Relations {
    pub junctions: Vec<Junction>,
    /// Collinear pairs `(a, b)`, `a < b`, with a gap between them along the line.
    pub collinears: Vec<(u32, u32)>,
    /// Parallel pairs `(a, b)`, `a < b`, overlapping side by side.
    pub parallels: Vec<(u32, u32)>,
    /// Junction indices per segment (CSR: `junction_index[junction_offsets[s]..junction_offsets[s+1]]`).
    junction_offsets: Vec<u32>,
    junction_index: Vec<u32>,
}

impl Relations {
    /// Indices into `junctions` of the junctions of segment `s`.
    pub fn junctions_of(&self, s: u32) -> &[u32] {
        let s = s as usize;
        if s + 1 >= self.junction_offsets.len() {
            return &[];
        }
        &self.junction_index[self.junction_offsets[s] as usize..self.junction_offsets[s + 1] as usize]
    }
}

/// A uniform grid over the image: each cell lists the segments passing through it.
#[derive(Debug, Clone, Default)]
pub struct SegmentGrid {
    cell: f64,
    nx: usize,
    ny: usize,
    offsets: Vec<u32>,
    items: Vec<u32>,
    stamp: Vec<u32>,
    epoch: u32,
}

impl SegmentGrid {
    /// Builds the grid for `segments` over a `width` x `height` image.
    pub fn build(segments: &[Segment], width: usize, height: usize, cell_px: f64) -> Self {
        let cell = cell_px.max(1.0);
        let nx = ((width as f64 / cell).ceil() as usize).max(1);
        let ny = ((height as f64 / cell).ceil() as usize).max(1);
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(segments.len() * 4);
        for (i, s) in segments.iter().enumerate() {
            let steps = (s.length() / (cell * 0.5)).ceil().max(1.0) as usize;
            let mut last = u32::MAX;
            for k in 0..=steps {
                let p = geom::add(s.p0, geom::scale(geom::sub(s.p1, s.p0), k as f64 / steps as f64));
                let cx = ((p[0] / cell).floor().max(0.0) as usize).min(nx - 1);
                let cy = ((p[1] / cell).floor().max(0.0) as usize).min(ny - 1);
                let c = (cy * nx + cx) as u32;
                if c != last {
                    pairs.push((c, i as u32));
                    last = c;
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut offsets = vec![0u32; nx * ny + 1];
        for &(c, _) in &pairs {
            offsets[c as usize + 1] += 1;
        }
        for i in 0..nx * ny {
            offsets[i + 1] += offsets[i];
        }
        let items = pairs.iter().map(|&(_, s)| s).collect();
        Self { cell, nx, ny, offsets, items, stamp: vec![0; segments.len()], epoch: 0 }
    }

    /// Segments passing through the cells that overlap the box `[lo, hi]`, each once.
    pub fn query(&mut self, lo: P2, hi: P2, out: &mut Vec<u32>) {
        out.clear();
        self.epoch = self.epoch.wrapping_add(1);
        if self.epoch == 0 {
            self.stamp.iter_mut().for_each(|s| *s = 0);
            self.epoch = 1;
        }
        let cx0 = ((lo[0] / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let cy0 = ((lo[1] / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        let cx1 = ((hi[0] / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let cy1 = ((hi[1] / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        for cy in cy0..=cy1 {
            for cx in cx0..=cx1 {
                let c = cy * self.nx + cx;
                for &s in &self.items[self.offsets[c] as usize..self.offsets[c + 1] as usize] {
                    if self.stamp[s as usize] != self.epoch {
                        self.stamp[s as usize] = self.epoch;
                        out.push(s);
                    }
                }
            }
        }
    }
}

/// Only an edge this many times weaker than the one it meets counts as swamped (texture
/// strokes of similar strengths meet at all angles; their ends need no extra reach).
const SWAMP_MIN_RATIO: f64 = 4.0;

/// How far short of a junction point an end of segment `a` may stop, meeting `b` at an angle
/// whose sine is `sin`, pixels. Two edges meeting at a small angle blur into each other over
/// a longer stretch near their corner: `base · 0.7 / sin`, up to 2.5x `base`. And an edge much
/// weaker than the other is swamped by the other's blurred gradient out to where that has
/// fallen to its own strength, `σ √(2 ln(c_b / c_a))` across the strong edge (`sigma_px`,
/// ~1.5 px with the detector's smoothing; less `σ`, which the plain allowance covers), which
/// along `a` is that over `sin` again: a 4-grey-level edge meeting a 50-level one at 25° stops
/// ~10 px short. Capped at half the weak edge's length.
fn end_reach(base: f64, sin: f64, a: &Segment, b: &Segment, sigma_px: f64) -> f64 {
    let ratio = if a.contrast > 0.0 { b.contrast / a.contrast } else { 1.0 };
    // Beyond the interference that any two edges meeting have (the plain allowance).
    let swamp = if ratio >= SWAMP_MIN_RATIO { sigma_px * ((2.0 * ratio.ln()).sqrt() - 1.0) } else { 0.0 };
    let plain = (base * 0.7 / sin).clamp(base, 2.5 * base);
    plain.max(((base * 0.7 + swamp) / sin).min(2.5 * base + 2.0 * swamp).min(0.5 * a.length()))
}

/// Finds junctions, collinears and parallels among `segments` of a `width` x `height` view.
pub fn find_relations(segments: &[Segment], width: usize, height: usize, cfg: &RelationConfig) -> Relations {
    let mut grid = SegmentGrid::build(segments, width, height, cfg.grid_cell_px);
    let mut rel = Relations::default();
    let mut near = Vec::new();
    let gap = cfg.junction_gap_px;
    let min_sin = cfg.junction_min_angle_deg.to_radians().sin();
    let par_sin = cfg.parallel_max_angle_deg.to_radians().sin();

    // Junctions: from each end of each segment, look for lines intersecting near it.
    for (ia, a) in segments.iter().enumerate() {
        for (end, q) in [(End::P0, a.p0), (End::P1, a.p1)] {
            // The other segment comes within 2·gap of this end (end → point → its end).
            let r = 2.0 * gap * 2.5;
            grid.query([q[0] - r, q[1] - r], [q[0] + r, q[1] + r], &mut near);
            for &ib in &near {
                if ib as usize == ia {
                    continue;
                }
                let b = &segments[ib as usize];
                let (da, db) = (a.dir(), b.dir());
                let sin = geom::cross(da, db).abs();
                if sin < min_sin {
                    continue;
                }
                // Short segments (texture) get a proportionally shorter reach.
                let base = (cfg.junction_gap_rel * a.length().min(b.length())).clamp(cfg.junction_gap_min_px, gap);
                let (gap_a, gap_b) = (end_reach(base, sin, a, b, cfg.junction_swamp_sigma_px), end_reach(base, sin, b, a, cfg.junction_swamp_sigma_px));
                let Some((x, s, t)) = geom::intersect_lines(a.p0, da, b.p0, db) else { continue };
                let s_end = if end == End::P0 { 0.0 } else { a.length() };
                if (s - s_end).abs() > gap_a {
                    continue;
                }
                let lb = b.length();
                let end_b = if t.abs() <= gap_b {
                    End::P0
                } else if (t - lb).abs() <= gap_b {
                    End::P1
                } else if t > 0.0 && t < lb && (s - s_end).abs() <= end_reach(base, sin, a, a, 0.0) {
                    // A T: the swamped reach is for corners (an edge running on past the weak
                    // one's end is texture's outline as often as not).
                    End::Interior
                } else {
                    continue;
                };
                let (ja, jb, ea, eb) = if (ia as u32) < ib { (ia as u32, ib, end, end_b) } else { (ib, ia as u32, end_b, end) };
                let kind = if end_b == End::Interior { JunctionKind::T } else { JunctionKind::L };
                rel.junctions.push(Junction { a: ja, b: jb, end_a: ea, end_b: eb, point: x, kind });
            }
        }
    }
    // An L is found from both of its ends: keep one per pair.
    rel.junctions.sort_by_key(|j| (j.a, j.b));
    rel.junctions.dedup_by(|x, y| x.a == y.a && x.b == y.b);

    // Per-segment junction lists.
    let n = segments.len();
    let mut offsets = vec![0u32; n + 1];
    for j in &rel.junctions {
        offsets[j.a as usize + 1] += 1;
        offsets[j.b as usize + 1] += 1;
    }
    for i in 0..n {
        offsets[i + 1] += offsets[i];
    }
    let mut fill = offsets.clone();
    let mut index = vec![0u32; offsets[n] as usize];
    for (k, j) in rel.junctions.iter().enumerate() {
        for s in [j.a, j.b] {
            index[fill[s as usize] as usize] = k as u32;
            fill[s as usize] += 1;
        }
    }
    rel.junction_offsets = offsets;
    rel.junction_index = index;

    // Y: an L sharing a segment end with another L at (nearly) the same point.
    let mut is_y = vec![false; rel.junctions.len()];
    for s in 0..n as u32 {
        let js = rel.junctions_of(s);
        for (x, &j1) in js.iter().enumerate() {
            for &j2 in &js[x + 1..] {
                let (p, q) = (&rel.junctions[j1 as usize], &rel.junctions[j2 as usize]);
                if p.kind == JunctionKind::T || q.kind == JunctionKind::T {
                    continue;
                }
                if p.end_of(s) == q.end_of(s) && geom::dist(p.point, q.point) <= gap {
                    is_y[j1 as usize] = true;
                    is_y[j2 as usize] = true;
                }
            }
        }
    }
    for (j, y) in rel.junctions.iter_mut().zip(is_y) {
        if y {
            j.kind = JunctionKind::Y;
        }
    }

    // Collinears: look ahead of each end along the line, up to the largest gap.
    let cg = cfg.collinear_max_gap_px;
    for (ia, a) in segments.iter().enumerate() {
        let d = a.dir();
        for (q, sign) in [(a.p1, 1.0), (a.p0, -1.0)] {
            let far = geom::add(q, geom::scale(d, sign * cg));
            let lo = [q[0].min(far[0]) - 2.0, q[1].min(far[1]) - 2.0];
            let hi = [q[0].max(far[0]) + 2.0, q[1].max(far[1]) + 2.0];
            grid.query(lo, hi, &mut near);
            for &ib in &near {
                if (ib as usize) <= ia {
                    continue;
                }
                let b = &segments[ib as usize];
                if geom::cross(d, b.dir()).abs() > par_sin {
                    continue;
                }
                if a.line_distance(b.p0).abs() > cfg.collinear_max_offset_px || a.line_distance(b.p1).abs() > cfg.collinear_max_offset_px {
                    continue;
                }
                // Gap between the two intervals along a's line.
                let (t0, t1) = (a.along(b.p0), a.along(b.p1));
                let (lo_b, hi_b) = (t0.min(t1), t0.max(t1));
                let g = if lo_b > a.length() { lo_b - a.length() } else if hi_b < 0.0 { -hi_b } else { -1.0 };
                if g >= -2.0 && g <= cg && !(lo_b < a.length() - 2.0 && hi_b > 2.0) {
                    rel.collinears.push((ia as u32, ib));
                }
            }
        }
    }
    rel.collinears.sort_unstable();
    rel.collinears.dedup();

    // Parallels: side by side within the distance bound, overlapping by a third.
    let pd = cfg.parallel_max_dist_px;
    for (ia, a) in segments.iter().enumerate() {
        let lo = [a.p0[0].min(a.p1[0]) - pd, a.p0[1].min(a.p1[1]) - pd];
        let hi = [a.p0[0].max(a.p1[0]) + pd, a.p0[1].max(a.p1[1]) + pd];
        grid.query(lo, hi, &mut near);
        for &ib in &near {
            if (ib as usize) <= ia {
                continue;
            }
            let b = &segments[ib as usize];
            if geom::cross(a.dir(), b.dir()).abs() > par_sin {
                continue;
            }
            let dist = a.line_distance(b.midpoint()).abs();
            if dist <= cfg.collinear_max_offset_px || dist > pd {
                continue;
            }
            let (t0, t1) = (a.along(b.p0), a.along(b.p1));
            let overlap = t0.max(t1).min(a.length()) - t0.min(t1).max(0.0);
            if overlap >= a.length().min(b.length()) / 3.0 {
                rel.parallels.push((ia as u32, ib));
            }
        }
    }
    rel
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(p0: P2, p1: P2) -> Segment {
        Segment { p0, p1, contrast: 10.0, rms_px: 0.1, n_points: 20 }
    }

    #[test]
    fn a_weak_edge_swamped_by_a_strong_one_reaches_its_corner() {
        // A strong edge from (100, 100) down-left, and a 22 px edge leaving the same corner at
        // 25° to it that the strong edge's blur has cut 10 px short.
        let (d1, d2) = ([(-65.0f64).to_radians().cos(), (-65.0f64).to_radians().sin()], [(-40.0f64).to_radians().cos(), (-40.0f64).to_radians().sin()]);
        let strong = Segment { p0: [100.0, 100.0], p1: geom::add([100.0, 100.0], geom::scale(d1, 60.0)), contrast: 50.0, rms_px: 0.1, n_points: 60 };
        let start = geom::add([100.0, 100.0], geom::scale(d2, 10.0));
        let weak = Segment { p0: start, p1: geom::add(start, geom::scale(d2, 22.0)), contrast: 4.0, rms_px: 0.2, n_points: 22 };
        let rel = find_relations(&[strong, weak], 320, 240, &RelationConfig::default());
        let j = rel.junctions.first().unwrap_or_else(|| panic!("no junction: {:?}", rel.junctions));
        assert_eq!(j.kind, JunctionKind::L);
        assert!(geom::dist(j.point, [100.0, 100.0]) < 1e-6, "{:?}", j.point);
        // As strong as each other, the same gap is no junction (texture strokes that merely
        // point at each other), and without the allowance neither is the weak one's.
        let even = Segment { contrast: 50.0, ..weak };
        assert!(find_relations(&[strong, even], 320, 240, &RelationConfig::default()).junctions.is_empty());
        let off = RelationConfig { junction_swamp_sigma_px: 0.0, ..RelationConfig::default() };
        assert!(find_relations(&[strong, weak], 320, 240, &off).junctions.is_empty());
    }

    #[test]
    fn l_t_and_y_junctions_with_exact_points() {
        let segs = vec![
            // A box corner at (50, 50) with three edges stopping 2-3 px short of it (Y).
            seg([52.0, 50.0], [120.0, 50.0]),
            seg([50.0, 53.0], [50.0, 120.0]),
            seg([48.0, 48.0], [20.0, 20.0]),
            // A T: a segment ending 1.5 px short of the horizontal edge's interior.
            seg([90.0, 90.0], [90.0, 51.5]),
            // An isolated segment far away, and one parallel to the first.
            seg([200.0, 200.0], [260.0, 230.0]),
            seg([30.0, 80.0], [120.0, 80.0]),
        ];
        let rel = find_relations(&segs, 320, 240, &RelationConfig::default());
        let find = |a: u32, b: u32| rel.junctions.iter().find(|j| j.a == a && j.b == b);
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            let j = find(a, b).unwrap_or_else(|| panic!("junction {a}-{b} missing: {:?}", rel.junctions));
            assert_eq!(j.kind, JunctionKind::Y);
            assert!(geom::dist(j.point, [50.0, 50.0]) < 1e-9, "{:?}", j.point);
        }
        let t = find(0, 3).expect("T junction");
        assert_eq!((t.kind, t.end_a, t.end_b), (JunctionKind::T, End::Interior, End::P1));
        assert!(geom::dist(t.point, [90.0, 50.0]) < 1e-9);
        assert!(rel.junctions.iter().all(|j| j.a != 4 && j.b != 4));
        // The vertical through the corner does not make a junction with the parallel at y=80
        // it crosses in its interior (X crossings are not junctions).
        assert!(find(1, 5).is_none());
        assert_eq!(rel.junctions_of(3).len(), 1);
        assert!(rel.parallels.contains(&(0, 5)));
        assert!(!rel.parallels.contains(&(0, 4)));
    }

    #[test]
    fn collinear_pieces_across_a_gap_but_not_side_by_side() {
        let segs = vec![
            seg([10.0, 10.0], [60.0, 10.5]),
            seg([75.0, 10.8], [140.0, 12.1]),
            // Overlapping and offset by 5 px: parallel, not collinear.
            seg([20.0, 15.0], [70.0, 15.5]),
            // Too far along the line.
            seg([200.0, 13.3], [260.0, 14.5]),
        ];
        let rel = find_relations(&segs, 320, 240, &RelationConfig::default());
        assert_eq!(rel.collinears, vec![(0, 1)]);
        assert!(rel.parallels.contains(&(0, 2)));
    }

    #[test]
    fn rendered_corners_are_restored_by_junctions() {
        use crate::planner::edges::{EdgeConfig, EdgeDetector};
        use crate::planner::segments::{SegmentConfig, SegmentDetector};
        use crate::planner::synth::Canvas;
        let quad = [[40.3, 30.2], [150.7, 45.9], [140.1, 120.4], [55.6, 110.8]];
        let mut c = Canvas::new(200, 160, 60.0);
        c.fill_polygon(&quad, 170.0);
        let img = c.to_image(1.0, 5);
        let mut e = EdgeDetector::new(EdgeConfig::default());
        let mut s = SegmentDetector::new(SegmentConfig::default());
        let segs = s.detect(e.detect(&img.view())).to_vec();
        let rel = find_relations(&segs, 200, 160, &RelationConfig::default());
        assert_eq!(rel.junctions.len(), 4, "{:?}", rel.junctions);
        for q in quad {
            let j = rel.junctions.iter().min_by(|a, b| geom::dist(a.point, q).total_cmp(&geom::dist(b.point, q))).unwrap();
            assert_eq!(j.kind, JunctionKind::L);
            // Segment ends stop short of the rounded corner; the junction restores it.
            assert!(geom::dist(j.point, q) < 0.3, "corner {q:?} restored at {:?}", j.point);
        }
    }

    #[test]
    fn grid_query_returns_each_nearby_segment_once() {
        let segs = vec![seg([0.0, 5.0], [300.0, 5.0]), seg([100.0, 100.0], [110.0, 110.0])];
        let mut g = SegmentGrid::build(&segs, 320, 240, 16.0);
        let mut out = Vec::new();
        g.query([0.0, 0.0], [319.0, 30.0], &mut out);
        assert_eq!(out, vec![0]);
        g.query([95.0, 95.0], [120.0, 120.0], &mut out);
        assert_eq!(out, vec![1]);
    }
}

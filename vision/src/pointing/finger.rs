//! The finger as a part of its own in a blob-shaped silhouette: a hand seen from the front
//! (wide knuckles over a short, foreshortened finger, the dark sleeve lost against the scene
//! or cut by the border) is no longer elongated as a whole, although its finger is a clear
//! line. The finger is the silhouette's thin protrusion: what a morphological opening with a
//! disk wider than a finger, narrower than the hand, takes away, and of that the part that
//! hangs off the hand with a free end inside the image (the fingertip).
//!
//! The opening works on the silhouette's bounding box with two chamfer distance transforms
//! (distance to the outside, then to the opening's core), holes filled first (the arm over
//! something of its own grey); outside the image counts as inside the silhouette, so an arm
//! cut by the border is not thin there. Only the caller's fallback (no axis from the whole
//! silhouette) runs it.

use crate::moments::Moments;

/// Chamfer steps (3 for a side, 4 for a diagonal: distances in thirds of a pixel).
const SIDE: u32 = 3;
const DIAGONAL: u32 = 4;

/// A finger part is at least this wide, px, and at least 0.8 times the opening disk's radius
/// (the disk's radius is over half the wide part's half width): narrower protrusions are a
/// hand's or a sleeve's side face seen at a grazing angle (on rendered frames 0.5-0.75 times
/// the radius; fingers 0.85-1.3).
const MIN_WIDTH_PX: f64 = 6.0;

/// The finger part of a silhouette (its pixels go to the caller's buffer).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct FingerPart {
    /// Where it joins the hand: the mean of its pixels next to the opened silhouette, px.
    pub root_px: [f64; 2],
    /// Its length and mean width (from its second moments), px.
    pub length_px: f64,
    pub width_px: f64,
}

/// The opening's disk holds over this many frames: its radius is the largest of theirs.
const HOLD_FRAMES: usize = 10;

/// Reusable buffers, and the disk radii of the last frames.
#[derive(Debug, Clone, Default)]
pub(super) struct FingerFinder {
    /// The widest part's radius in the last [`HOLD_FRAMES`] frames (a ring), chamfer units.
    /// A hand held still has one width, but the silhouette's widest part does not: where the
    /// forearm is lost against the scene in some frames and not in others, the widest half
    /// width jumped 27 to 29 px, and a finger about as wide as the disk came and went as a
    /// protrusion with it (point_clutter3 seed 60: the part flipped between the finger and the
    /// hand's side face, and the hand never held "still"). The largest recent width is the
    /// hand's own; noise and the scene only take pixels away from it.
    radii: Vec<u32>,
    next_radius: usize,
    /// Whether this frame's radius is in `radii` already (the finder runs up to twice a frame).
    radius_held: bool,
    /// Per cell of the box: 0 outside, 1 inside, 2 opened (the hand and forearm), 3 residual.
    cell: Vec<u8>,
    dist: Vec<u32>,
    label: Vec<u32>,
    stack: Vec<usize>,
}

/// A residual component's moments.
#[derive(Debug, Clone, Copy, Default)]
struct Component {
    m: Moments,
    border: bool,
    /// Cells next to the opened silhouette: count and sums.
    root: (f64, f64, f64),
}

impl Component {
    /// Centroid and second central moments `(mx, my, cxx, cxy, cyy)`, px; `None` for fewer
    /// than 3 cells (no meaningful direction).
    fn central_moments(&self) -> Option<(f64, f64, f64, f64, f64)> {
        if self.m.n < 3.0 {
            return None;
        }
        let ([mx, my], cxx, cxy, cyy) = self.m.central();
        Some((mx, my, cxx, cxy, cyy))
    }
}

impl FingerFinder {
    /// A new frame: its first [`find`](Self::find) adds its radius to the held ones.
    pub fn next_frame(&mut self) {
        self.radius_held = false;
    }

    /// The arm has gone: the next one's width is its own.
    pub fn forget(&mut self) {
        self.radii.clear();
        self.next_radius = 0;
        self.radius_held = false;
    }

    /// The finger part of the silhouette `pixels` of a `w` x `h` image, its pixels in `out`:
    /// the largest thin protrusion (elongated at least `min_elongation`, at least
    /// `min_length_px` long, joined to the wide part at one end) that does not touch the image
    /// border. `None` if there is none.
    pub fn find(
        &mut self,
        pixels: &[(u16, u16)],
        w: usize,
        h: usize,
        min_elongation: f64,
        min_length_px: f64,
        out: &mut Vec<(u16, u16)>,
    ) -> Option<FingerPart> {
        out.clear();
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for &(x, y) in pixels {
            (x0, y0, x1, y1) = (
                x0.min(x.into()),
                y0.min(y.into()),
                x1.max(x.into()),
                y1.max(y.into()),
            );
        }
        if pixels.is_empty() {
            return None;
        }
        // The box with a margin of one cell; cells beyond the image count as inside.
        let (bx, by) = (x0 as isize - 1, y0 as isize - 1);
        let (bw, bh) = (x1 - x0 + 3, y1 - y0 + 3);
        let outside_image = |i: usize, j: usize| {
            let (x, y) = (bx + i as isize, by + j as isize);
            x < 1 || y < 1 || x + 1 >= w as isize || y + 1 >= h as isize
        };
        self.cell.clear();
        self.cell.resize(bw * bh, 0);
        for j in 0..bh {
            for i in 0..bw {
                if outside_image(i, j) {
                    self.cell[j * bw + i] = 1;
                }
            }
        }
        for &(x, y) in pixels {
            self.cell[(usize::from(y) - y0 + 1) * bw + usize::from(x) - x0 + 1] = 1;
        }
        self.fill_holes(bw, bh);
        // Distance to the outside; the widest part's half width sets the disk.
        self.chamfer(bw, bh, |c| c == 0);
        let widest = self
            .dist
            .iter()
            .zip(&self.cell)
            .filter(|(_, c)| **c != 0)
            .map(|(d, _)| *d)
            .max()
            .unwrap_or(0);
        let radius = self.held_radius(widest * 55 / 100);
        if radius < 4 * SIDE {
            return None;
        }
        // The opening: the cells within the disk's radius of a cell at least that deep.
        for k in 0..self.cell.len() {
            if self.cell[k] != 0 && self.dist[k] >= radius {
                self.cell[k] = 2;
            }
        }
        self.chamfer(bw, bh, |c| c == 2);
        for k in 0..self.cell.len() {
            if self.cell[k] == 1 {
                self.cell[k] = if self.dist[k] <= radius + SIDE + 1 {
                    2
                } else {
                    3
                };
            }
        }
        // The residual's components; the largest finger-like one.
        self.label.clear();
        self.label.resize(bw * bh, 0);
        let mut best: Option<(u32, Component)> = None;
        let mut next = 0u32;
        for start in 0..self.cell.len() {
            if self.cell[start] != 3 || self.label[start] != 0 {
                continue;
            }
            next += 1;
            let c = self.component(start, next, bw, bh, &outside_image);
            let Some((length, width, elongation)) = shape(&c) else {
                continue;
            };
            // Joined to the hand at one end, not along its side (a sliver the opening left
            // along the hand's edge).
            let at_end = root_along(&c).is_some_and(|s| s.abs() >= 0.3 * length);
            let finger_like = !c.border
                && at_end
                && c.root.0 >= 2.0
                && elongation >= min_elongation
                && length >= min_length_px
                && width >= MIN_WIDTH_PX.max(0.8 * f64::from(radius) / f64::from(SIDE))
                && width <= 2.0 * f64::from(radius) / f64::from(SIDE) + 2.0;
            // The largest: a finger outweighs the slivers a hand's side faces leave.
            if finger_like && best.is_none_or(|(_, b)| b.m.n < c.m.n) {
                best = Some((next, c));
            }
        }
        let (id, c) = best?;
        let (length_px, width_px, _) = shape(&c)?;
        out.extend(
            (0..self.cell.len())
                .filter(|&k| self.label[k] == id)
                .map(|k| (((k % bw) as isize + bx) as u16, ((k / bw) as isize + by) as u16)),
        );
        Some(FingerPart {
            root_px: [
                c.root.1 / c.root.0 + bx as f64,
                c.root.2 / c.root.0 + by as f64,
            ],
            length_px,
            width_px,
        })
    }

    /// The largest of this frame's radius (`now`, held once a frame) and the last frames'.
    fn held_radius(&mut self, now: u32) -> u32 {
        if !self.radius_held {
            self.radius_held = true;
            if self.radii.len() < HOLD_FRAMES {
                self.radii.push(now);
            } else {
                self.radii[self.next_radius] = now;
            }
            self.next_radius = (self.next_radius + 1) % HOLD_FRAMES;
        }
        self.radii.iter().copied().fold(now, u32::max)
    }

    /// Background cells not reachable from the box's edge become inside.
    fn fill_holes(&mut self, bw: usize, bh: usize) {
        const REACHED: u8 = 9;
        self.stack.clear();
        for j in 0..bh {
            for i in 0..bw {
                if (i == 0 || j == 0 || i + 1 == bw || j + 1 == bh) && self.cell[j * bw + i] == 0 {
                    self.cell[j * bw + i] = REACHED;
                    self.stack.push(j * bw + i);
                }
            }
        }
        while let Some(k) = self.stack.pop() {
            let (i, j) = (k % bw, k / bw);
            for (di, dj) in [(-1isize, 0isize), (1, 0), (0, -1), (0, 1)] {
                let (ni, nj) = (i as isize + di, j as isize + dj);
                if ni >= 0 && nj >= 0 && (ni as usize) < bw && (nj as usize) < bh {
                    let n = nj as usize * bw + ni as usize;
                    if self.cell[n] == 0 {
                        self.cell[n] = REACHED;
                        self.stack.push(n);
                    }
                }
            }
        }
        for c in &mut self.cell {
            *c = match *c {
                REACHED => 0,
                0 => 1,
                other => other,
            };
        }
    }

    /// `dist`: chamfer distance (thirds of a pixel) of every cell to the nearest cell that is
    /// a `source`; cells off the box are no source.
    fn chamfer(&mut self, bw: usize, bh: usize, source: impl Fn(u8) -> bool) {
        const FAR: u32 = u32::MAX / 2;
        self.dist.clear();
        self.dist
            .extend(self.cell.iter().map(|&c| if source(c) { 0 } else { FAR }));
        let d = &mut self.dist;
        for j in 0..bh {
            for i in 0..bw {
                let k = j * bw + i;
                let mut v = d[k];
                if i > 0 {
                    v = v.min(d[k - 1] + SIDE);
                }
                if j > 0 {
                    v = v.min(d[k - bw] + SIDE);
                    if i > 0 {
                        v = v.min(d[k - bw - 1] + DIAGONAL);
                    }
                    if i + 1 < bw {
                        v = v.min(d[k - bw + 1] + DIAGONAL);
                    }
                }
                d[k] = v;
            }
        }
        for j in (0..bh).rev() {
            for i in (0..bw).rev() {
                let k = j * bw + i;
                let mut v = d[k];
                if i + 1 < bw {
                    v = v.min(d[k + 1] + SIDE);
                }
                if j + 1 < bh {
                    v = v.min(d[k + bw] + SIDE);
                    if i + 1 < bw {
                        v = v.min(d[k + bw + 1] + DIAGONAL);
                    }
                    if i > 0 {
                        v = v.min(d[k + bw - 1] + DIAGONAL);
                    }
                }
                d[k] = v;
            }
        }
    }

    /// Labels the residual component at `start` with `id` (8-connected); its moments.
    fn component(
        &mut self,
        start: usize,
        id: u32,
        bw: usize,
        bh: usize,
        outside_image: &dyn Fn(usize, usize) -> bool,
    ) -> Component {
        let mut c = Component::default();
        self.stack.clear();
        self.stack.push(start);
        self.label[start] = id;
        while let Some(k) = self.stack.pop() {
            let (i, j) = (k % bw, k / bw);
            let (x, y) = (i as f64, j as f64);
            c.m.add(x, y);
            let mut at_root = false;
            for dj in -1isize..=1 {
                for di in -1isize..=1 {
                    let (ni, nj) = (i as isize + di, j as isize + dj);
                    if ni < 0 || nj < 0 || ni as usize >= bw || nj as usize >= bh {
                        continue;
                    }
                    let (ni, nj) = (ni as usize, nj as usize);
                    let n = nj * bw + ni;
                    if outside_image(ni, nj) {
                        c.border = true;
                    }
                    match self.cell[n] {
                        2 => at_root = true,
                        3 if self.label[n] == 0 => {
                            self.label[n] = id;
                            self.stack.push(n);
                        }
                        _ => {}
                    }
                }
            }
            if at_root {
                c.root.0 += 1.0;
                c.root.1 += x;
                c.root.2 += y;
            }
        }
        c
    }
}

/// Where a component's cells next to the opened silhouette lie along its principal
/// direction, from its centroid, px (`None` without such cells or for a degenerate component).
fn root_along(c: &Component) -> Option<f64> {
    if c.root.0 < 1.0 {
        return None;
    }
    let (mx, my, cxx, cxy, cyy) = c.central_moments()?;
    let theta = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
    Some((c.root.1 / c.root.0 - mx) * theta.cos() + (c.root.2 / c.root.0 - my) * theta.sin())
}

/// A component's length and width (a uniform bar's, from its second moments) and
/// elongation, px; `None` for fewer than 3 cells.
fn shape(c: &Component) -> Option<(f64, f64, f64)> {
    let (_, _, cxx, cxy, cyy) = c.central_moments()?;
    let half_diff = 0.5 * (cxx - cyy);
    let root = (half_diff * half_diff + cxy * cxy).sqrt();
    let (l1, l2) = (
        0.5 * (cxx + cyy) + root,
        (0.5 * (cxx + cyy) - root).max(1.0 / 12.0),
    );
    let (length, width) = ((12.0 * l1).sqrt(), (12.0 * l2).sqrt());
    Some((length, width, length / width))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An upright hand seen from the front, `half_width_px` either side of x = 200 over y
    /// 150-250, and its finger, 14 px either side, over y 250-320.
    fn hand(half_width_px: u16) -> Vec<(u16, u16)> {
        let mut px = Vec::new();
        for y in 150..320u16 {
            let half = if y < 250 { half_width_px } else { 14 };
            px.extend((200 - half..=200 + half).map(|x| (x, y)));
        }
        px
    }

    #[test]
    fn a_finger_stays_a_part_while_the_hand_looks_narrower_for_a_frame() {
        let mut out = Vec::new();
        let find = |f: &mut FingerFinder, half: u16, out: &mut Vec<(u16, u16)>| {
            f.next_frame();
            f.find(&hand(half), 640, 480, 1.5, 20.0, out)
        };
        // A hand 48 px wide alone: its disk (0.55 of its half width) fits the 29 px finger,
        // so the opening keeps the finger and there is no part.
        let mut alone = FingerFinder::default();
        assert_eq!(find(&mut alone, 24, &mut out), None);
        // The same hand a frame after it was seen 60 px wide (the silhouette's widest part
        // came and went with the scene behind it): the disk holds, the finger stays a part.
        let mut held = FingerFinder::default();
        let wide = find(&mut held, 30, &mut out).expect("the finger of the wide hand");
        let narrow = find(&mut held, 24, &mut out).expect("the finger, the disk held");
        for part in [wide, narrow] {
            assert!((part.root_px[0] - 200.0).abs() < 2.0 && part.root_px[1] > 245.0 && part.root_px[1] < 270.0, "{part:?}");
            assert!((part.width_px - 29.0).abs() < 3.0, "{part:?}");
        }
        // Once the arm has gone, the next hand's width is its own.
        held.forget();
        assert_eq!(find(&mut held, 24, &mut out), None);
    }
}

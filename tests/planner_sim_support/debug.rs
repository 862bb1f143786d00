//! Debug images of the planner's simulator test (used by its ignored diagnostics).

use std::path::Path;

use handeye_vision::planner::geom::{self, P2};
use handeye_vision::planner::Plan;

use super::Snapshot;

/// Both views side by side, cropped around some points and scaled up, dimmed so drawn
/// lines stand out.
struct SideBySide {
    img: image::RgbImage,
    origin_px: P2,
    scale: f64,
    view_w: u32,
    view_h: u32,
}

impl SideBySide {
    fn around(snap: &Snapshot, pts: &[P2], margin_px: f64, scale: f64) -> Self {
        let (x0, y0, x1, y1) = pts.iter().fold((f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY), |m, p| (m.0.min(p[0]), m.1.min(p[1]), m.2.max(p[0]), m.3.max(p[1])));
        let (x0, y0) = ((x0 - margin_px).max(0.0), (y0 - margin_px).max(0.0));
        let (x1, y1) = ((x1 + margin_px).min(snap.left.width as f64), (y1 + margin_px).min(snap.left.height as f64));
        let (w, h) = (((x1 - x0) * scale) as u32, ((y1 - y0) * scale) as u32);
        let mut img = image::RgbImage::new(2 * w + 4, h);
        for (v, view) in [&snap.left, &snap.right].into_iter().enumerate() {
            let dx = v as u32 * (w + 4);
            for y in 0..h {
                for x in 0..w {
                    let (sx, sy) = ((x0 + x as f64 / scale) as usize, (y0 + y as f64 / scale) as usize);
                    let g = view.get(sx.min(view.width - 1), sy.min(view.height - 1)) / 2 + 40;
                    img.put_pixel(x + dx, y, image::Rgb([g, g, g]));
                }
            }
        }
        Self { img, origin_px: [x0, y0], scale, view_w: w, view_h: h }
    }

    /// A line from `a` to `b` (image pixels) in view `v` (0 left, 1 right).
    fn line(&mut self, v: usize, a: P2, b: P2, col: [u8; 3]) {
        let (w, h, k) = (self.view_w, self.view_h, self.scale);
        let dx = v as u32 * (w + 4);
        let n = (geom::dist(a, b) * k * 2.0).ceil() as usize + 1;
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let (x, y) = ((a[0] + t * (b[0] - a[0]) - self.origin_px[0]) * k, (a[1] + t * (b[1] - a[1]) - self.origin_px[1]) * k);
            if x >= 0.0 && y >= 0.0 && (x as u32) < w && (y as u32) < h {
                self.img.put_pixel(x as u32 + dx, y as u32, image::Rgb(col));
            }
        }
    }

    fn polygon(&mut self, v: usize, p: &[P2], col: [u8; 3]) {
        for i in 0..p.len() {
            self.line(v, p[i], p[(i + 1) % p.len()], col);
        }
    }

    /// The plan's matched segments in white in both views.
    fn matches(&mut self, plan: &Plan) {
        for m in &plan.matches {
            let (l, r) = (&plan.left_segments[m.left as usize], &plan.right_segments[m.right as usize]);
            self.line(0, l.p0, l.p1, [255, 255, 255]);
            self.line(1, r.p0, r.p1, [255, 255, 255]);
        }
    }
}

/// Debug aid: both views side by side around the blocks, scaled up, truth faces in green,
/// facets in colour, matched segments in white; written to `path`.
pub fn debug_overlay(snap: &Snapshot, plan: &Plan, path: &Path) {
    let pts: Vec<P2> = snap.faces.iter().flat_map(|f| f.polygon[0].iter().chain(&f.polygon[1]).copied()).collect();
    let mut c = SideBySide::around(snap, &pts, 10.0, 3.0);
    for f in &snap.faces {
        for v in 0..2 {
            if f.visible_px[v] > 0.0 {
                c.polygon(v, &f.polygon[v], [0, 160, 0]);
            }
        }
    }
    c.matches(plan);
    const PALETTE: [[u8; 3]; 8] = [[230, 25, 75], [0, 130, 200], [245, 130, 48], [145, 30, 180], [70, 240, 240], [240, 50, 230], [210, 245, 60], [255, 225, 25]];
    for (i, f) in plan.facets.iter().enumerate() {
        let col = PALETTE[i % PALETTE.len()];
        c.polygon(0, &f.facet.left, col);
        c.polygon(1, &f.facet.right, col);
    }
    c.img.save(path).expect("write debug overlay");
}

/// Debug aid: one face's truth (green) and a facet (red) in both views, around the face,
/// scaled 5x, with all matched segments (white) and all segments (dark blue).
pub fn debug_face(snap: &Snapshot, plan: &Plan, face: usize, facet: Option<usize>, path: &Path) {
    let f = &snap.faces[face];
    let pts: Vec<P2> = f.polygon[0].iter().chain(&f.polygon[1]).copied().collect();
    let mut c = SideBySide::around(snap, &pts, 25.0, 5.0);
    for (v, segs) in [(0, &plan.left_segments), (1, &plan.right_segments)] {
        for s in segs.iter() {
            c.line(v, s.p0, s.p1, [40, 40, 200]);
        }
    }
    c.matches(plan);
    for v in 0..2 {
        c.polygon(v, &f.polygon[v], [0, 200, 0]);
    }
    if let Some(fi) = facet {
        let r = &plan.facets[fi];
        c.polygon(0, &r.facet.left, [255, 40, 40]);
        c.polygon(1, &r.facet.right, [255, 40, 40]);
    }
    c.img.save(path).expect("write debug face");
}

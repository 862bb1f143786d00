//! Debug images of the planner's simulator test (used by its ignored diagnostics).

use std::path::Path;

use handeye_vision::planner::geom::{self, P2};
use handeye_vision::planner::Plan;

use super::Snapshot;

/// Debug aid: both views side by side around the blocks, scaled up, truth faces in green,
/// facets in colour, matched segments in white; written to `path`.
pub fn debug_overlay(snap: &Snapshot, plan: &Plan, path: &Path) {
    let pts: Vec<P2> = snap.faces.iter().flat_map(|f| f.polygon[0].iter().chain(&f.polygon[1]).copied()).collect();
    let (x0, y0, x1, y1) = pts.iter().fold((f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY), |m, p| (m.0.min(p[0]), m.1.min(p[1]), m.2.max(p[0]), m.3.max(p[1])));
    let (x0, y0) = ((x0 - 10.0).max(0.0), (y0 - 10.0).max(0.0));
    let (x1, y1) = ((x1 + 10.0).min(snap.left.width as f64), (y1 + 10.0).min(snap.left.height as f64));
    let k = 3.0;
    let (w, h) = (((x1 - x0) * k) as u32, ((y1 - y0) * k) as u32);
    let mut img = image::RgbImage::new(2 * w + 4, h);
    for (v, view) in [&snap.left, &snap.right].into_iter().enumerate() {
        let dx = v as u32 * (w + 4);
        for y in 0..h {
            for x in 0..w {
                let (sx, sy) = ((x0 + x as f64 / k) as usize, (y0 + y as f64 / k) as usize);
                let g = view.get(sx.min(view.width - 1), sy.min(view.height - 1)) / 2 + 40;
                img.put_pixel(x + dx, y, image::Rgb([g, g, g]));
            }
        }
    }
    let mut line = |v: usize, a: P2, b: P2, col: [u8; 3]| {
        let dx = v as f64 * (w + 4) as f64;
        let n = (geom::dist(a, b) * k * 2.0).ceil() as usize + 1;
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let (x, y) = ((a[0] + t * (b[0] - a[0]) - x0) * k, (a[1] + t * (b[1] - a[1]) - y0) * k);
            if x >= 0.0 && y >= 0.0 && (x as u32) < w && (y as u32) < h {
                img.put_pixel(x as u32 + dx as u32, y as u32, image::Rgb(col));
            }
        }
    };
    for f in &snap.faces {
        for v in 0..2 {
            if f.visible_px[v] > 0.0 {
                let p = &f.polygon[v];
                for i in 0..p.len() {
                    line(v, p[i], p[(i + 1) % p.len()], [0, 160, 0]);
                }
            }
        }
    }
    for m in &plan.matches {
        let (l, r) = (&plan.left_segments[m.left as usize], &plan.right_segments[m.right as usize]);
        line(0, l.p0, l.p1, [255, 255, 255]);
        line(1, r.p0, r.p1, [255, 255, 255]);
    }
    const PALETTE: [[u8; 3]; 8] = [[230, 25, 75], [0, 130, 200], [245, 130, 48], [145, 30, 180], [70, 240, 240], [240, 50, 230], [210, 245, 60], [255, 225, 25]];
    for (i, f) in plan.facets.iter().enumerate() {
        let col = PALETTE[i % PALETTE.len()];
        for (v, p) in [(0, &f.facet.left), (1, &f.facet.right)] {
            for j in 0..p.len() {
                line(v, p[j], p[(j + 1) % p.len()], col);
            }
        }
    }
    img.save(path).expect("write debug overlay");
}

/// Debug aid: one face's truth (green) and a facet (red) in both views, around the face,
/// scaled 5x, with all matched segments (white) and all segments (dark blue).
pub fn debug_face(snap: &Snapshot, plan: &Plan, face: usize, facet: Option<usize>, path: &Path) {
    let f = &snap.faces[face];
    let pts: Vec<P2> = f.polygon[0].iter().chain(&f.polygon[1]).copied().collect();
    let (x0, y0, x1, y1) = pts.iter().fold((f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY), |m, p| (m.0.min(p[0]), m.1.min(p[1]), m.2.max(p[0]), m.3.max(p[1])));
    let (x0, y0) = ((x0 - 25.0).max(0.0), (y0 - 25.0).max(0.0));
    let (x1, y1) = ((x1 + 25.0).min(snap.left.width as f64), (y1 + 25.0).min(snap.left.height as f64));
    let k = 5.0;
    let (w, h) = (((x1 - x0) * k) as u32, ((y1 - y0) * k) as u32);
    let mut img = image::RgbImage::new(2 * w + 4, h);
    for (v, view) in [&snap.left, &snap.right].into_iter().enumerate() {
        let dx = v as u32 * (w + 4);
        for y in 0..h {
            for x in 0..w {
                let (sx, sy) = ((x0 + x as f64 / k) as usize, (y0 + y as f64 / k) as usize);
                let g = view.get(sx.min(view.width - 1), sy.min(view.height - 1)) / 2 + 40;
                img.put_pixel(x + dx, y, image::Rgb([g, g, g]));
            }
        }
    }
    let mut line = |v: usize, a: P2, b: P2, col: [u8; 3]| {
        let dx = v as f64 * (w + 4) as f64;
        let n = (geom::dist(a, b) * k * 2.0).ceil() as usize + 1;
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let (x, y) = ((a[0] + t * (b[0] - a[0]) - x0) * k, (a[1] + t * (b[1] - a[1]) - y0) * k);
            if x >= 0.0 && y >= 0.0 && (x as u32) < w && (y as u32) < h {
                img.put_pixel(x as u32 + dx as u32, y as u32, image::Rgb(col));
            }
        }
    };
    for (v, segs) in [(0, &plan.left_segments), (1, &plan.right_segments)] {
        for s in segs.iter() {
            line(v, s.p0, s.p1, [40, 40, 200]);
        }
    }
    for m in &plan.matches {
        let (l, r) = (&plan.left_segments[m.left as usize], &plan.right_segments[m.right as usize]);
        line(0, l.p0, l.p1, [255, 255, 255]);
        line(1, r.p0, r.p1, [255, 255, 255]);
    }
    for v in 0..2 {
        let p = &f.polygon[v];
        for i in 0..p.len() {
            line(v, p[i], p[(i + 1) % p.len()], [0, 200, 0]);
        }
    }
    if let Some(fi) = facet {
        let r = &plan.facets[fi];
        for (v, p) in [(0, &r.facet.left), (1, &r.facet.right)] {
            for j in 0..p.len() {
                line(v, p[j], p[(j + 1) % p.len()], [255, 40, 40]);
            }
        }
    }
    img.save(path).expect("write debug face");
}

//! Synthetic scenes with exact ground truth, for testing and benchmarking trackers: a convex
//! polygon on a shaded background, clutter lines, blur and noise. Deterministic for a seed.

use crate::image::ImageBuf;
use crate::rng::SplitMix64;

/// A straight bar drawn over the scene: a segment `a`–`b` of `width_px`, adding `delta`
/// grey levels (negative: darker).
#[derive(Debug, Clone, Copy)]
pub struct ClutterLine {
    pub a: [f64; 2],
    pub b: [f64; 2],
    pub width_px: f64,
    pub delta: f64,
}

/// What to draw.
#[derive(Debug, Clone)]
pub struct Scene {
    pub width: usize,
    pub height: usize,
    /// Background grey level at the image centre, and its change per pixel along x and y.
    pub background: f64,
    pub background_slope: [f64; 2],
    /// Convex polygon corners (pixels; pixel `(x, y)` covers `x ± ½, y ± ½`).
    pub polygon: Vec<[f64; 2]>,
    /// Grey level inside the polygon.
    pub foreground: f64,
    /// Lines drawn on top of the background (static clutter)...
    pub background_lines: Vec<ClutterLine>,
    /// ...and on top of the polygon, clipped to it (printed texture).
    pub texture_lines: Vec<ClutterLine>,
    /// Edge blur: standard deviation of the edge profile, px.
    pub blur_px: f64,
    /// Standard deviation of additive Gaussian noise, grey levels.
    pub noise: f64,
}

fn coverage(d: f64, blur_px: f64) -> f64 {
    // Smooth step of a blurred straight edge at signed distance `d` (negative inside): the
    // logistic approximation of a Gaussian-blurred box-filtered step. Exactly 0 or 1 beyond
    // 12 scale lengths (below 1e-5), which keeps rendering fast.
    let s = (blur_px * blur_px + 1.0 / 12.0).sqrt() / 1.702;
    let z = d / s;
    if z > 12.0 {
        0.0
    } else if z < -12.0 {
        1.0
    } else {
        1.0 / (1.0 + z.exp())
    }
}

fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    ((p[0] - a[0] - t * dx).powi(2) + (p[1] - a[1] - t * dy).powi(2)).sqrt()
}

impl Scene {
    /// Renders the scene into `out` (resized to fit), drawing noise from `rng`.
    pub fn render_into(&self, rng: &mut SplitMix64, out: &mut ImageBuf) {
        out.width = self.width;
        out.height = self.height;
        out.data.resize(self.width * self.height, 0);
        // Edge lines of the convex polygon, as (unit outward normal, offset).
        let n = self.polygon.len();
        let area: f64 = (0..n)
            .map(|j| {
                let (a, b) = (self.polygon[j], self.polygon[(j + 1) % n]);
                a[0] * b[1] - a[1] * b[0]
            })
            .sum();
        let orient = area.signum();
        let lines: Vec<([f64; 2], f64)> = (0..n)
            .map(|j| {
                let (a, b) = (self.polygon[j], self.polygon[(j + 1) % n]);
                let (tx, ty) = (b[0] - a[0], b[1] - a[1]);
                let len = (tx * tx + ty * ty).sqrt();
                let nrm = [orient * ty / len, -orient * tx / len];
                (nrm, nrm[0] * a[0] + nrm[1] * a[1])
            })
            .collect();
        let (cx, cy) = (self.width as f64 / 2.0, self.height as f64 / 2.0);
        // Beyond this distance a line's coverage is exactly 0 (see `coverage`).
        let far_px = 12.0 * (self.blur_px * self.blur_px + 1.0 / 12.0).sqrt() / 1.702;
        for y in 0..self.height {
            for x in 0..self.width {
                let p = [x as f64, y as f64];
                let mut v = self.background + self.background_slope[0] * (p[0] - cx) + self.background_slope[1] * (p[1] - cy);
                for l in &self.background_lines {
                    let d = segment_distance(p, l.a, l.b) - l.width_px / 2.0;
                    if d < far_px {
                        v += l.delta * coverage(d, self.blur_px);
                    }
                }
                // Signed distance to a convex polygon (exact away from corners).
                let d = lines.iter().map(|(nrm, c)| nrm[0] * p[0] + nrm[1] * p[1] - c).fold(f64::NEG_INFINITY, f64::max);
                let inside = coverage(d, self.blur_px);
                if inside > 0.0 {
                    let mut f = self.foreground;
                    for l in &self.texture_lines {
                        let dl = segment_distance(p, l.a, l.b) - l.width_px / 2.0;
                        if dl < far_px {
                            f += l.delta * coverage(dl, self.blur_px);
                        }
                    }
                    v = v * (1.0 - inside) + f * inside;
                }
                if self.noise > 0.0 {
                    v += self.noise * rng.normal();
                }
                out.data[y * self.width + x] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    }

    /// Renders the scene into a new image.
    pub fn render(&self, rng: &mut SplitMix64) -> ImageBuf {
        let mut out = ImageBuf::new(self.width, self.height);
        self.render_into(rng, &mut out);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygon_edge_sits_at_half_coverage_where_the_corners_say() {
        let scene = Scene {
            width: 40,
            height: 40,
            background: 200.0,
            background_slope: [0.0, 0.0],
            polygon: vec![[10.5, 10.0], [30.5, 10.0], [30.5, 30.0], [10.5, 30.0]],
            foreground: 100.0,
            background_lines: vec![],
            texture_lines: vec![],
            blur_px: 0.7,
            noise: 0.0,
        };
        let img = scene.render(&mut SplitMix64::new(1));
        // The left side runs at x = 10.5: pixels 10 and 11 straddle it symmetrically.
        let (a, b) = (img.get(10, 20) as f64, img.get(11, 20) as f64);
        assert!(((a + b) / 2.0 - 150.0).abs() <= 1.0, "{a} {b}");
        assert_eq!(img.get(20, 20), 100);
        assert_eq!(img.get(2, 2), 200);
    }
}

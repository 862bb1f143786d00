//! Synthetic test scenes with exact ground truth: anti-aliased polygon rendering, and stereo
//! pairs of boxes on a table seen by two affine (scaled orthographic) cameras.
//!
//! Used by the planner's tests and by `handeye bench planner` when no real pair is at hand.
//! Rendering is by area coverage (pixels near an edge are supersampled 16x16), so an edge's
//! true position is known to a few hundredths of a pixel — enough to test sub-pixel edge
//! localisation.
//!
//! ```
//! use handeye_vision::planner::synth::{BoxSpec, SynthScene};
//! let scene = SynthScene::new(vec![BoxSpec { center_m: [0.0, 0.0, 0.02], size_m: [0.06, 0.05, 0.04], yaw_rad: 0.3 }]);
//! let pair = scene.render(7);
//! assert_eq!((pair.left.width, pair.left.height), (640, 480));
//! // The top and two side faces of the box are visible in both views.
//! assert_eq!(pair.faces.len(), 3);
//! ```

use super::geom::{self, P2};
use crate::image::ImageBuf;
use crate::rng::XorShift64;

/// A float canvas that polygons are painted onto with coverage blending.
#[derive(Debug, Clone)]
pub struct Canvas {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl Canvas {
    pub fn new(width: usize, height: usize, value: f32) -> Self {
        Self { width, height, data: vec![value; width * height] }
    }

    /// Paints a simple polygon (any orientation, non-convex allowed) with grey `value`,
    /// blending each pixel by the fraction of its area the polygon covers. Returns the
    /// pixels whose centre is inside (for visibility bookkeeping).
    pub fn fill_polygon(&mut self, poly: &[P2], value: f32) -> Vec<usize> {
        let mut centres = Vec::new();
        if poly.len() < 3 {
            return centres;
        }
        let (mut x0, mut y0, mut x1, mut y1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for p in poly {
            x0 = x0.min(p[0]);
            y0 = y0.min(p[1]);
            x1 = x1.max(p[0]);
            y1 = y1.max(p[1]);
        }
        let xa = (x0.floor().max(0.0)) as usize;
        let ya = (y0.floor().max(0.0)) as usize;
        let xb = (x1.ceil().min(self.width as f64)) as usize;
        let yb = (y1.ceil().min(self.height as f64)) as usize;
        const SS: usize = 16;
        for y in ya..yb {
            for x in xa..xb {
                let c = [x as f64 + 0.5, y as f64 + 0.5];
                let near = (0..poly.len()).any(|i| geom::point_segment_distance(c, poly[i], poly[(i + 1) % poly.len()]) < 0.75);
                let inside_centre = geom::contains(poly, c, 0.0);
                let cover = if near {
                    let mut n = 0;
                    for sy in 0..SS {
                        for sx in 0..SS {
                            let p = [x as f64 + (sx as f64 + 0.5) / SS as f64, y as f64 + (sy as f64 + 0.5) / SS as f64];
                            n += geom::contains(poly, p, 0.0) as usize;
                        }
                    }
                    n as f32 / (SS * SS) as f32
                } else if inside_centre {
                    1.0
                } else {
                    0.0
                };
                if cover > 0.0 {
                    let i = y * self.width + x;
                    self.data[i] = self.data[i] * (1.0 - cover) + value * cover;
                }
                if inside_centre {
                    centres.push(y * self.width + x);
                }
            }
        }
        centres
    }

    /// Quantises to GRAY8, adding deterministic zero-mean noise of standard deviation
    /// `noise_sigma` grey levels (seeded).
    pub fn to_image(&self, noise_sigma: f32, seed: u64) -> ImageBuf {
        let mut rng = XorShift64::new(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
        let data = self
            .data
            .iter()
            .map(|&v| {
                let n = if noise_sigma > 0.0 { noise_sigma * rng.gauss() } else { 0.0 };
                (v + n).round().clamp(0.0, 255.0) as u8
            })
            .collect();
        ImageBuf { data, width: self.width, height: self.height }
    }
}

/// A scaled orthographic camera: `u = s r1·X + cu`, `v = s r2·X + cv` (pixels, v down).
#[derive(Debug, Clone, Copy)]
pub struct AffineCamera {
    /// Rows of the 2x4 projection `[s r1 | cu; s r2 | cv]`.
    pub rows: [[f64; 4]; 2],
    /// Unit viewing direction (from the camera into the scene).
    pub view_dir: [f64; 3],
}

impl AffineCamera {
    /// A camera looking at the origin from azimuth `az_rad` (about the vertical axis, 0 =
    /// from −y) and elevation `el_rad` above the table, `px_per_m` pixels per metre, with the
    /// origin imaged at `centre_px`.
    pub fn looking_at_origin(az_rad: f64, el_rad: f64, px_per_m: f64, centre_px: P2) -> Self {
        let d = [el_rad.cos() * az_rad.sin(), -el_rad.cos() * az_rad.cos(), el_rad.sin()];
        let k = [-d[0], -d[1], -d[2]];
        let up = [0.0, 0.0, 1.0];
        let r1 = normalize3(cross3(k, up));
        let r2 = cross3(k, r1);
        Self {
            rows: [
                [px_per_m * r1[0], px_per_m * r1[1], px_per_m * r1[2], centre_px[0]],
                [px_per_m * r2[0], px_per_m * r2[1], px_per_m * r2[2], centre_px[1]],
            ],
            view_dir: k,
        }
    }

    pub fn project(&self, x: [f64; 3]) -> P2 {
        let r = |row: &[f64; 4]| row[0] * x[0] + row[1] * x[1] + row[2] * x[2] + row[3];
        [r(&self.rows[0]), r(&self.rows[1])]
    }

    /// Depth along the viewing direction (larger is farther).
    pub fn depth(&self, x: [f64; 3]) -> f64 {
        self.view_dir[0] * x[0] + self.view_dir[1] * x[1] + self.view_dir[2] * x[2]
    }
}

fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn normalize3(a: [f64; 3]) -> [f64; 3] {
    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// A box standing on the table (z = 0 is the table top), rotated by `yaw_rad` about z.
#[derive(Debug, Clone, Copy)]
pub struct BoxSpec {
    /// Centre of the box, metres.
    pub center_m: [f64; 3],
    /// Full extents along the box's own x, y, z axes, metres.
    pub size_m: [f64; 3],
    pub yaw_rad: f64,
}

impl BoxSpec {
    /// The 6 faces as (outward normal, 4 corners counter-clockwise seen from outside).
    pub fn faces(&self) -> Vec<([f64; 3], [[f64; 3]; 4])> {
        let (s, c) = self.yaw_rad.sin_cos();
        let ax = [c, s, 0.0];
        let ay = [-s, c, 0.0];
        let az = [0.0, 0.0, 1.0];
        let h = [self.size_m[0] * 0.5, self.size_m[1] * 0.5, self.size_m[2] * 0.5];
        let corner = |i: f64, j: f64, k: f64| {
            let mut p = self.center_m;
            for d in 0..3 {
                p[d] += i * h[0] * ax[d] + j * h[1] * ay[d] + k * h[2] * az[d];
            }
            p
        };
        let neg = |v: [f64; 3]| [-v[0], -v[1], -v[2]];
        vec![
            (az, [corner(-1., -1., 1.), corner(1., -1., 1.), corner(1., 1., 1.), corner(-1., 1., 1.)]),
            (neg(az), [corner(-1., -1., -1.), corner(-1., 1., -1.), corner(1., 1., -1.), corner(1., -1., -1.)]),
            (ax, [corner(1., -1., -1.), corner(1., 1., -1.), corner(1., 1., 1.), corner(1., -1., 1.)]),
            (neg(ax), [corner(-1., -1., -1.), corner(-1., -1., 1.), corner(-1., 1., 1.), corner(-1., 1., -1.)]),
            (ay, [corner(-1., 1., -1.), corner(-1., 1., 1.), corner(1., 1., 1.), corner(1., 1., -1.)]),
            (neg(ay), [corner(-1., -1., -1.), corner(1., -1., -1.), corner(1., -1., 1.), corner(-1., -1., 1.)]),
        ]
    }
}

/// Ground truth for one visible face.
#[derive(Debug, Clone)]
pub struct TruthFace {
    pub block: usize,
    pub face: usize,
    /// Projected polygon (unoccluded) in each view, pixels.
    pub left: Vec<P2>,
    pub right: Vec<P2>,
    pub corners_m: Vec<[f64; 3]>,
    /// Pixels whose centre shows this face after occlusion, per view.
    pub visible_left_px: usize,
    pub visible_right_px: usize,
    /// Polygon area per view, pixels.
    pub area_left_px: f64,
    pub area_right_px: f64,
}

/// A rendered stereo pair with its ground truth.
#[derive(Debug, Clone)]
pub struct StereoPair {
    pub left: ImageBuf,
    pub right: ImageBuf,
    pub cameras: [AffineCamera; 2],
    /// Faces visible (front-facing, some pixels showing) in both views.
    pub faces: Vec<TruthFace>,
    /// Eight calibration points (robot frame, metres) and their `(u, v, u', v')` images.
    pub cage: Vec<([f64; 3], [f64; 4])>,
}

impl StereoPair {
    /// The ground truth in the scorer's form. The scorer compares facets with *visible*
    /// polygons; this renderer only knows the full projection of each face, so a face partly
    /// hidden by another box (less than 97% of its area visible in a view) is reported with
    /// zero visible area there, which keeps it out of the found/missed count (it still counts
    /// against spurious facets).
    pub fn truth(&self) -> Vec<super::score::TruthFace> {
        let shown = |vis: usize, area: f64| if vis as f64 >= 0.97 * area { vis as f64 } else { 0.0 };
        self.faces
            .iter()
            .map(|f| super::score::TruthFace {
                left: f.left.clone(),
                right: f.right.clone(),
                visible_left_px: shown(f.visible_left_px, f.area_left_px),
                visible_right_px: shown(f.visible_right_px, f.area_right_px),
                corners_m: Some(f.corners_m.clone()),
            })
            .collect()
    }
}

/// Boxes on a table, two affine cameras ~20° apart, Lambertian shading.
#[derive(Debug, Clone)]
pub struct SynthScene {
    pub boxes: Vec<BoxSpec>,
    pub width: usize,
    pub height: usize,
    pub cameras: [AffineCamera; 2],
    /// Unit direction towards the light.
    pub light: [f64; 3],
    pub table_grey: f32,
    pub noise_sigma: f32,
}

impl SynthScene {
    /// Default rig: 640x480, cameras at azimuth ±10° and elevation 50°, 2500 px/m (a 40 mm
    /// block spans ~100 px), light from above-left-front.
    pub fn new(boxes: Vec<BoxSpec>) -> Self {
        let centre = [320.0, 260.0];
        Self {
            boxes,
            width: 640,
            height: 480,
            cameras: [
                AffineCamera::looking_at_origin(-10f64.to_radians(), 50f64.to_radians(), 2500.0, centre),
                AffineCamera::looking_at_origin(10f64.to_radians(), 50f64.to_radians(), 2500.0, centre),
            ],
            light: normalize3([-0.4, -0.6, 0.75]),
            table_grey: 40.0,
            noise_sigma: 1.5,
        }
    }

    /// `n` boxes of 20-60 mm placed at random without overlap (seeded).
    pub fn random(n: usize, seed: u64) -> Self {
        let mut rng = XorShift64::new(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) | 1);
        let mut boxes: Vec<BoxSpec> = Vec::new();
        let mut tries = 0;
        while boxes.len() < n && tries < 1000 {
            tries += 1;
            let size = [
                0.02 + 0.04 * rng.uniform() as f64,
                0.02 + 0.04 * rng.uniform() as f64,
                0.02 + 0.04 * rng.uniform() as f64,
            ];
            let center = [(rng.uniform() as f64 - 0.5) * 0.16, (rng.uniform() as f64 - 0.5) * 0.12, size[2] * 0.5];
            let yaw = rng.uniform() as f64 * std::f64::consts::FRAC_PI_2;
            // Keep footprints apart (bounding circles + 10 mm) so painter's order is exact.
            let r = 0.5 * (size[0].hypot(size[1]));
            let clear = boxes.iter().all(|b| {
                let rb = 0.5 * b.size_m[0].hypot(b.size_m[1]);
                (b.center_m[0] - center[0]).hypot(b.center_m[1] - center[1]) > r + rb + 0.01
            });
            if clear {
                boxes.push(BoxSpec { center_m: center, size_m: size, yaw_rad: yaw });
            }
        }
        Self::new(boxes)
    }

    /// Lambertian with ambient: faces turned away from the light still stand out from the
    /// darker table (as the simulator's "distinct face brightness" promises).
    fn shade(&self, normal: [f64; 3]) -> f32 {
        (90.0 + 150.0 * dot3(normal, self.light).max(0.0)) as f32
    }

    /// Renders both views with ground truth; `seed` drives the noise.
    pub fn render(&self, seed: u64) -> StereoPair {
        let mut views = Vec::new();
        for (vi, cam) in self.cameras.iter().enumerate() {
            let mut canvas = Canvas::new(self.width, self.height, self.table_grey);
            let mut label = vec![usize::MAX; self.width * self.height];
            let mut order: Vec<usize> = (0..self.boxes.len()).collect();
            // Painter's algorithm: farthest box first (boxes are kept apart, so it is exact).
            order.sort_by(|&a, &b| cam.depth(self.boxes[b].center_m).total_cmp(&cam.depth(self.boxes[a].center_m)));
            let mut polys = Vec::new();
            for &bi in &order {
                for (fi, (normal, corners)) in self.boxes[bi].faces().iter().enumerate() {
                    if dot3(*normal, cam.view_dir) >= -1e-6 {
                        continue; // back-facing
                    }
                    let poly: Vec<P2> = corners.iter().map(|c| cam.project(*c)).collect();
                    let centres = canvas.fill_polygon(&poly, self.shade(*normal));
                    let id = bi * 6 + fi;
                    for i in centres {
                        label[i] = id;
                    }
                    polys.push((id, poly));
                }
            }
            let img = canvas.to_image(self.noise_sigma, seed.wrapping_add(vi as u64 * 7919));
            views.push((img, label, polys));
        }
        let (right_img, right_label, right_polys) = views.pop().expect("two views");
        let (left_img, left_label, left_polys) = views.pop().expect("two views");
        let mut faces = Vec::new();
        for (id, lp) in &left_polys {
            let Some((_, rp)) = right_polys.iter().find(|(j, _)| j == id) else { continue };
            let vis_l = left_label.iter().filter(|&&l| l == *id).count();
            let vis_r = right_label.iter().filter(|&&l| l == *id).count();
            if vis_l == 0 || vis_r == 0 {
                continue;
            }
            let (bi, fi) = (id / 6, id % 6);
            faces.push(TruthFace {
                block: bi,
                face: fi,
                left: lp.clone(),
                right: rp.clone(),
                corners_m: self.boxes[bi].faces()[fi].1.to_vec(),
                visible_left_px: vis_l,
                visible_right_px: vis_r,
                area_left_px: geom::area(lp),
                area_right_px: geom::area(rp),
            });
        }
        faces.sort_by_key(|f| (f.block, f.face));
        // Calibration cage: a 160 x 120 x 80 mm box, its lower face 10 mm above the table.
        let mut cage = Vec::new();
        for i in 0..8 {
            let x = [
                if i & 1 == 0 { -0.08 } else { 0.08 },
                if i & 2 == 0 { -0.06 } else { 0.06 },
                if i & 4 == 0 { 0.01 } else { 0.09 },
            ];
            let l = self.cameras[0].project(x);
            let r = self.cameras[1].project(x);
            cage.push((x, [l[0], l[1], r[0], r[1]]));
        }
        StereoPair { left: left_img, right: right_img, cameras: self.cameras, faces, cage }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_rendering_puts_the_edge_where_the_polygon_is() {
        // A half-plane x < 10.3: pixel 10 is 30% covered.
        let mut c = Canvas::new(20, 4, 0.0);
        c.fill_polygon(&[[0.0, 0.0], [10.3, 0.0], [10.3, 4.0], [0.0, 4.0]], 100.0);
        assert!((c.data[9] - 100.0).abs() < 1e-3);
        // 16 samples per pixel row: coverage is exact to 1/32 px.
        assert!((c.data[10] - 30.0).abs() < 3.2, "{}", c.data[10]);
        assert_eq!(c.data[11], 0.0);
    }

    #[test]
    fn box_faces_are_visible_when_they_face_the_camera() {
        let scene = SynthScene::new(vec![BoxSpec { center_m: [0.0, 0.0, 0.02], size_m: [0.05, 0.05, 0.04], yaw_rad: 0.5 }]);
        let pair = scene.render(1);
        // Top (face 0) is always visible from above; the bottom (face 1) never is.
        assert!(pair.faces.iter().any(|f| f.face == 0));
        assert!(pair.faces.iter().all(|f| f.face != 1));
        for f in &pair.faces {
            // Unoccluded single box: visible pixels ≈ polygon area.
            let ratio = f.visible_left_px as f64 / f.area_left_px;
            assert!((ratio - 1.0).abs() < 0.05, "face {} ratio {ratio}", f.face);
        }
    }
}

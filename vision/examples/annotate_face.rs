//! How the left face's annotations in `tests/visp_cube_truth/mod.rs` (`LEFT_FACE_TRUTH`) were
//! made, and the tool to redo or check them: each corner is the intersection of straight lines
//! fitted to the face's edges in the image, found near a hand estimate.
//!
//! For each annotated frame the hand estimate (`HAND`, read off magnified crops by eye, about
//! ±3 px) gives the four sides. Along the middle 70 % of each side, 48 points search the image
//! along the side's normal within ±`SEARCH_PX` for the strongest grey-level step of the
//! polarity most of them see (profiles averaged over 3 px along the side, sub-pixel by a
//! parabola through the peak). A line is fitted to the edge points by total least squares,
//! points more than max(0.8 px, 2.5 RMS) off it are dropped and the line refitted (three
//! rounds). Adjacent sides' lines intersect in the corners. The accuracy printed per corner is
//! the statistical one (each line's offset error at the corner from its residuals,
//! combined through the angle between the lines); the cube's bevelled, blurred edges add a
//! systematic part of about half a pixel.
//!
//! Writes one overlay PNG per frame (4x crop: hand estimate blue, edge points green, dropped
//! points red, fitted face yellow; with `ANNOTATE_COMPARE=FILE`, a tracker's left face from
//! `tracker_profile`'s per-frame output in magenta) to check by eye, and prints the Rust
//! constant.
//!
//! ```text
//! cargo run --release -p handeye-vision --example annotate_face -- [DIR [OVERLAY_DIR]]
//! ```
//!
//! `DIR` defaults to `$HANDEYE_DATA/visp-cube`; `OVERLAY_DIR` to `/tmp/left-face-overlays`.

use std::path::{Path, PathBuf};

use image::{GrayImage, Rgb, RgbImage};

#[path = "../../tests/data_support/mod.rs"]
mod data_support;

/// Hand estimates of the left face's corners (order of `faces-frame0.json`: the top face's
/// corner 0, the near top corner, the near bottom corner, the far bottom corner).
const HAND: [(usize, [[f64; 2]; 4]); 5] = [
    (50, [[322.4, 216.0], [390.0, 257.5], [383.5, 316.5], [322.3, 273.9]]),
    (100, [[296.3, 155.8], [351.7, 190.8], [348.3, 247.1], [297.4, 213.6]]),
    (150, [[293.6, 135.7], [362.0, 150.0], [358.7, 204.2], [294.8, 190.7]]),
    (200, [[296.5, 139.0], [361.9, 121.4], [358.3, 180.0], [297.9, 194.0]]),
    (217, [[297.0, 139.0], [357.0, 117.5], [354.7, 175.0], [297.5, 194.7]]),
];

/// How far each side's points search for the edge across the hand estimate, px.
const SEARCH_PX: f64 = 3.0;
/// Points per side.
const POINTS: usize = 48;
/// Overlay magnification (`ANNOTATE_ZOOM` overrides it, to look closer).
fn zoom() -> u32 {
    std::env::var("ANNOTATE_ZOOM").ok().and_then(|z| z.parse().ok()).unwrap_or(4)
}

type P = [f64; 2];

fn bilinear(img: &GrayImage, x: f64, y: f64) -> f64 {
    let (w, h) = (img.width() as f64, img.height() as f64);
    let (x, y) = (x.clamp(0.0, w - 2.0), y.clamp(0.0, h - 2.0));
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let g = |dx: u32, dy: u32| f64::from(img.get_pixel(x0 as u32 + dx, y0 as u32 + dy)[0]);
    (g(0, 0) * (1.0 - fx) + g(1, 0) * fx) * (1.0 - fy) + (g(0, 1) * (1.0 - fx) + g(1, 1) * fx) * fy
}

/// A fitted line: a point on it, its unit direction, and its fit's statistics.
struct Line {
    centre: P,
    dir: P,
    rms_px: f64,
    /// Inlier positions along `dir` relative to `centre` (for the offset error elsewhere).
    along: Vec<f64>,
}

impl Line {
    /// Standard error of the line's normal offset at `p` (the fit's residual spread,
    /// widening away from the inliers' centre).
    fn offset_sigma_at(&self, p: P) -> f64 {
        let n = self.along.len() as f64;
        let t = (p[0] - self.centre[0]) * self.dir[0] + (p[1] - self.centre[1]) * self.dir[1];
        let s2: f64 = self.along.iter().map(|a| a * a).sum();
        self.rms_px * (1.0 / n + t * t / s2).sqrt()
    }
}

fn fit_line(points: &[P]) -> (P, P) {
    let n = points.len() as f64;
    let c = points.iter().fold([0.0, 0.0], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n]);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in points {
        let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    (c, [angle.cos(), angle.sin()])
}

/// Edge points of one side, found near the hand estimate `a` -> `b`; returns them with the
/// polarity used (+1: brighter on the normal's side).
fn edge_points(img: &GrayImage, a: P, b: P) -> Vec<P> {
    let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    let t = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
    let n = [-t[1], t[0]];
    let steps = (2.0 * SEARCH_PX / 0.25) as usize + 1;
    let mut found: Vec<(f64, f64, P)> = Vec::new(); // (signed gradient, sub-pixel offset, base)
    for i in 0..POINTS {
        let s = 0.15 + 0.7 * i as f64 / (POINTS - 1) as f64;
        let base = [a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s];
        let profile: Vec<f64> = (0..steps)
            .map(|k| {
                let h = -SEARCH_PX + 0.25 * k as f64;
                (-1..=1)
                    .map(|j| bilinear(img, base[0] + n[0] * h + t[0] * j as f64, base[1] + n[1] * h + t[1] * j as f64))
                    .sum::<f64>()
                    / 3.0
            })
            .collect();
        // Gradient over 1 px (4 samples apart).
        let grad: Vec<f64> = (0..steps).map(|k| if k < 2 || k + 2 >= steps { 0.0 } else { profile[k + 2] - profile[k - 2] }).collect();
        for sign in [1.0, -1.0] {
            let (k, g) = grad.iter().enumerate().map(|(k, g)| (k, sign * g)).fold((0, f64::MIN), |m, x| if x.1 > m.1 { x } else { m });
            let sub = if k > 0 && k + 1 < steps {
                let (l, r) = (sign * grad[k - 1], sign * grad[k + 1]);
                let d = l - 2.0 * g + r;
                if d < 0.0 { 0.5 * (l - r) / d } else { 0.0 }
            } else {
                0.0
            };
            found.push((sign * g, -SEARCH_PX + 0.25 * (k as f64 + sub), base));
        }
    }
    // The polarity most points see more strongly; a silhouette whose background changes from
    // lighter to darker than the face along the side has no such majority (fewer than 3 in 4
    // agree): there each point keeps its stronger step.
    let pos = found.chunks(2).filter(|c| c[0].0 >= -c[1].0).count();
    let mixed = pos * 4 < 3 * POINTS && pos * 4 > POINTS;
    let keep = usize::from(pos * 2 < POINTS);
    found
        .chunks(2)
        .map(|c| if mixed { if c[0].0 >= -c[1].0 { c[0] } else { c[1] } } else { c[keep] })
        .filter(|(g, _, _)| g.abs() >= 8.0)
        .map(|(_, h, base)| [base[0] + n[0] * h, base[1] + n[1] * h])
        .collect()
}

/// Fits a line to `points` with outlier rounds; returns it and the outliers.
fn robust_line(points: &[P]) -> (Line, Vec<P>) {
    let mut inliers = points.to_vec();
    let mut outliers = Vec::new();
    let (mut c, mut d) = fit_line(&inliers);
    for _ in 0..3 {
        let res = |p: &P| (p[0] - c[0]) * -d[1] + (p[1] - c[1]) * d[0];
        let rms = (inliers.iter().map(|p| res(p).powi(2)).sum::<f64>() / inliers.len() as f64).sqrt();
        let limit = (2.5 * rms).max(0.8);
        let (keep, drop): (Vec<P>, Vec<P>) = points.iter().partition(|p| res(p).abs() <= limit);
        inliers = keep;
        outliers = drop;
        (c, d) = fit_line(&inliers);
    }
    let res = |p: &P| (p[0] - c[0]) * -d[1] + (p[1] - c[1]) * d[0];
    let rms = (inliers.iter().map(|p| res(p).powi(2)).sum::<f64>() / (inliers.len() as f64 - 2.0)).sqrt();
    let along = inliers.iter().map(|p| (p[0] - c[0]) * d[0] + (p[1] - c[1]) * d[1]).collect();
    (Line { centre: c, dir: d, rms_px: rms, along }, outliers)
}

fn intersect(l: &Line, m: &Line) -> (P, f64) {
    // l.centre + s l.dir = m.centre + u m.dir
    let det = l.dir[0] * -m.dir[1] + m.dir[0] * l.dir[1];
    let (rx, ry) = (m.centre[0] - l.centre[0], m.centre[1] - l.centre[1]);
    let s = (rx * -m.dir[1] + m.dir[0] * ry) / det;
    let p = [l.centre[0] + s * l.dir[0], l.centre[1] + s * l.dir[1]];
    let sin = det.abs();
    let sigma = (l.offset_sigma_at(p).powi(2) + m.offset_sigma_at(p).powi(2)).sqrt() / sin;
    (p, sigma)
}

fn draw_line(out: &mut RgbImage, origin: P, a: P, b: P, colour: Rgb<u8>) {
    let z = f64::from(zoom());
    let (ax, ay) = ((a[0] - origin[0]) * z, (a[1] - origin[1]) * z);
    let (bx, by) = ((b[0] - origin[0]) * z, (b[1] - origin[1]) * z);
    let n = ((bx - ax).abs().max((by - ay).abs()).ceil() as usize).max(1);
    for k in 0..=n {
        let f = k as f64 / n as f64;
        let (x, y) = (ax + (bx - ax) * f, ay + (by - ay) * f);
        if x >= 0.0 && y >= 0.0 && (x as u32) < out.width() && (y as u32) < out.height() {
            out.put_pixel(x as u32, y as u32, colour);
        }
    }
}

fn dot(out: &mut RgbImage, origin: P, p: P, colour: Rgb<u8>) {
    let z = f64::from(zoom());
    let (x, y) = (((p[0] - origin[0]) * z) as i64, ((p[1] - origin[1]) * z) as i64);
    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        let (x, y) = (x + dx, y + dy);
        if x >= 0 && y >= 0 && (x as u32) < out.width() && (y as u32) < out.height() {
            out.put_pixel(x as u32, y as u32, colour);
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let dir = args.next().map(PathBuf::from).unwrap_or_else(|| data_support::data_dir().join("visp-cube"));
    let overlays = args.next().map(PathBuf::from).unwrap_or_else(|| PathBuf::from("/tmp/left-face-overlays"));
    std::fs::create_dir_all(&overlays).unwrap_or_else(|e| panic!("{}: {e}", overlays.display()));
    let mut constant = String::new();
    for (frame, hand) in HAND {
        let path: &Path = &dir.join(format!("image{frame:04}.png"));
        let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
        let mut lines = Vec::new();
        let mut points = Vec::new();
        for s in 0..4 {
            let pts = edge_points(&img, hand[s], hand[(s + 1) % 4]);
            let (line, outliers) = robust_line(&pts);
            points.push((pts, outliers));
            lines.push(line);
        }
        let mut corners = [[0.0; 2]; 4];
        let mut report = Vec::new();
        for c in 0..4 {
            let (p, sigma) = intersect(&lines[(c + 3) % 4], &lines[c]);
            corners[c] = p;
            let moved = ((p[0] - hand[c][0]).powi(2) + (p[1] - hand[c][1]).powi(2)).sqrt();
            report.push(format!("corner {c} ({:.1}, {:.1}) ±{sigma:.2} px, {moved:.1} px from the hand estimate", p[0], p[1]));
        }
        let sides: Vec<String> = lines
            .iter()
            .zip(&points)
            .enumerate()
            .map(|(s, (l, (pts, out)))| format!("side {s}: {} of {} points, rms {:.2} px", pts.len() - out.len(), POINTS, l.rms_px))
            .collect();
        println!("frame {frame}: {}\n  {}", sides.join("; "), report.join("\n  "));
        constant += &format!(
            "    ({frame}, [{}]),\n",
            corners.iter().map(|p| format!("[{:.1}, {:.1}]", p[0], p[1])).collect::<Vec<_>>().join(", ")
        );

        // Overlay: the face's bounding box and 15 px around it, magnified.
        let all: Vec<P> = hand.iter().chain(corners.iter()).copied().collect();
        let x0 = all.iter().map(|p| p[0]).fold(f64::MAX, f64::min).floor() - 15.0;
        let y0 = all.iter().map(|p| p[1]).fold(f64::MAX, f64::min).floor() - 15.0;
        let x1 = all.iter().map(|p| p[0]).fold(f64::MIN, f64::max).ceil() + 15.0;
        let y1 = all.iter().map(|p| p[1]).fold(f64::MIN, f64::max).ceil() + 15.0;
        // `ANNOTATE_CROP=x0,y0,w,h`: that window instead, to look closer at a corner.
        let window: Option<Vec<f64>> = std::env::var("ANNOTATE_CROP").ok().map(|v| v.split(',').map(|x| x.parse().expect("ANNOTATE_CROP")).collect());
        let (x0, y0, x1, y1) = match window.as_deref() {
            Some([x, y, w, h]) => (*x, *y, x + w, y + h),
            _ => (x0, y0, x1, y1),
        };
        let (w, h) = ((x1 - x0) as u32, (y1 - y0) as u32);
        let zoom = zoom();
        let mut out = RgbImage::from_fn(w * zoom, h * zoom, |x, y| {
            let (px, py) = ((x0 as u32 + x / zoom).min(img.width() - 1), (y0 as u32 + y / zoom).min(img.height() - 1));
            let g = img.get_pixel(px, py)[0];
            Rgb([g, g, g])
        });
        let origin = [x0, y0];
        for c in 0..4 {
            draw_line(&mut out, origin, hand[c], hand[(c + 1) % 4], Rgb([60, 120, 255]));
        }
        for (pts, outl) in &points {
            for p in pts {
                let colour = if outl.contains(p) { Rgb([255, 40, 40]) } else { Rgb([40, 220, 40]) };
                dot(&mut out, origin, *p, colour);
            }
        }
        for c in 0..4 {
            draw_line(&mut out, origin, corners[c], corners[(c + 1) % 4], Rgb([255, 230, 0]));
        }
        // `ANNOTATE_COMPARE=FILE`: a tracker's corners (`tracker_profile`'s third argument's
        // output) drawn in magenta, to see where a run was on the face.
        if let Ok(path) = std::env::var("ANNOTATE_COMPARE") {
            let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
            let prefix = format!("left {frame} ");
            if let Some(line) = text.lines().find(|l| l.starts_with(&prefix)) {
                let v: Vec<f64> = line.split(' ').skip(4).map(|x| x.parse().expect("ANNOTATE_COMPARE corners")).collect();
                for c in 0..4 {
                    let (a, b) = ([v[2 * c], v[2 * c + 1]], [v[2 * ((c + 1) % 4)], v[2 * ((c + 1) % 4) + 1]]);
                    draw_line(&mut out, origin, a, b, Rgb([255, 0, 255]));
                }
            }
        }
        let file = overlays.join(format!("left-face-{frame:03}.png"));
        out.save(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    }
    println!("\npub const LEFT_FACE_TRUTH: [(usize, [[f64; 2]; 4]); {}] = [\n{constant}];", HAND.len());
    println!("overlays in {}", overlays.display());
}

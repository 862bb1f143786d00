//! The run report: overlay PNGs of both views at key moments with the trackers drawn, the
//! plan, and the servo convergence plot ([`crate::servo_plot`]: the remaining translation
//! in mm and yaw in degrees against servo step, SVG). Images are copied out of shared memory
//! at those few moments only and encoded on a separate thread ([`ReportWriter`]), never in
//! the hard loop.
//!
//! Overlay colours: gripper plate trackers green, target trackers red (yellow when lost).

use std::path::{Path, PathBuf};

use handeye_vision::image::{ImageBuf, ImageView};
use handeye_wire::{Telemetry, TELEMETRY_TRACKERS};
use image::{Rgb, RgbImage};

use crate::mission::ServoTraceRow;
use crate::worker::Worker;

/// A moment worth a picture: both views and the trackers as telemetry reported them.
pub struct Snapshot {
    pub label: &'static str,
    pub frame_id: u64,
    pub left: ImageBuf,
    pub right: ImageBuf,
    pub corners: [[[f32; 2]; 8]; TELEMETRY_TRACKERS],
    pub tracker_state: [u32; TELEMETRY_TRACKERS],
    /// The pointing finger's line (`a u + b v + c = 0`) and tip per view, as telemetry
    /// reported them (NaN: none).
    pub finger_line_px: [[f32; 3]; 2],
    pub finger_tip_px: [[f32; 2]; 2],
    /// The indicated point in each view, px, when the caller knows it (observe mode's plane
    /// maps): marked with a cross.
    pub point_px: Option<[[f64; 2]; 2]>,
}

impl Snapshot {
    /// Copies both views (allocates; call at key moments only).
    pub fn take(label: &'static str, left: &ImageView<'_>, right: &ImageView<'_>, t: &Telemetry) -> Self {
        Self {
            label,
            frame_id: t.frame_id,
            left: left.to_owned(),
            right: right.to_owned(),
            corners: t.tracker_corners_px,
            tracker_state: t.tracker_state,
            finger_line_px: t.pointing_line_px,
            finger_tip_px: t.pointing_tip_px,
            point_px: None,
        }
    }
}

/// What the report thread does.
pub enum ReportJob {
    Overlay(Box<Snapshot>),
    /// The servo convergence plot (`servo_convergence.svg`): the trace and the convergence
    /// tolerances, mm and degrees.
    ServoPlot { rows: Vec<ServoTraceRow>, tolerance_mm: f64, tolerance_deg: f64 },
    /// The planner's facets and grasp sites on both views (`NN_plan.png`) and `plan.json`.
    Plan(Box<crate::planning::PlanOutput>),
}

/// Writes report files on its own thread; the loop hands jobs over without waiting.
pub struct ReportWriter {
    worker: Worker<ReportJob, Result<PathBuf, String>>,
    dir: PathBuf,
    dropped: u32,
}

impl ReportWriter {
    pub fn new(dir: &Path) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let out = dir.to_path_buf();
        let mut count = 0u32;
        let worker = Worker::spawn("handeye-report", 8, move |job: ReportJob| match job {
            ReportJob::Overlay(s) => {
                count += 1;
                let path = out.join(format!("{count:02}_{}.png", s.label));
                overlay(&s).save(&path).map(|_| path.clone()).map_err(|e| format!("{}: {e}", path.display()))
            }
            ReportJob::ServoPlot { rows, tolerance_mm, tolerance_deg } => {
                let path = out.join("servo_convergence.svg");
                let svg = crate::servo_plot::servo_plot_svg(&rows, tolerance_mm, tolerance_deg).map_err(|e| format!("{}: {e}", path.display()))?;
                std::fs::write(&path, svg).map(|_| path.clone()).map_err(|e| format!("{}: {e}", path.display()))
            }
            ReportJob::Plan(p) => {
                count += 1;
                let json = out.join("plan.json");
                let text = serde_json::to_string_pretty(&p.summary).map_err(|e| format!("{}: {e}", json.display()))?;
                std::fs::write(&json, text).map_err(|e| format!("{}: {e}", json.display()))?;
                // The pair as the planner saw it, for `handeye plan --calib plan.json`.
                for (name, img) in [("plan_left.png", &p.images[0]), ("plan_right.png", &p.images[1])] {
                    let path = out.join(name);
                    image::GrayImage::from_raw(img.width as u32, img.height as u32, img.data.clone())
                        .ok_or_else(|| format!("{}: bad image size", path.display()))?
                        .save(&path)
                        .map_err(|e| format!("{}: {e}", path.display()))?;
                }
                let path = out.join(format!("{count:02}_plan.png"));
                plan_overlay(&p).save(&path).map(|_| path.clone()).map_err(|e| format!("{}: {e}", path.display()))
            }
        })?;
        Ok(Self { worker, dir: dir.to_path_buf(), dropped: 0 })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Queues a job; a full queue drops it (counted) rather than wait.
    pub fn submit(&mut self, job: ReportJob) {
        if self.worker.try_submit(job).is_err() {
            self.dropped += 1;
        }
    }

    /// Waits for the queued images (at shutdown) and returns the files written and errors.
    pub fn finish(self) -> (Vec<PathBuf>, Vec<String>) {
        let mut files = Vec::new();
        let mut errors = Vec::new();
        if self.dropped > 0 {
            errors.push(format!("{} report images dropped (queue full)", self.dropped));
        }
        for r in self.worker.finish() {
            match r {
                Ok(p) => files.push(p),
                Err(e) => errors.push(e),
            }
        }
        (files, errors)
    }
}

const GRIPPER: Rgb<u8> = Rgb([40, 230, 60]);
const TARGET: Rgb<u8> = Rgb([240, 40, 40]);
const LOST: Rgb<u8> = Rgb([250, 220, 0]);

/// Both views side by side in colour with the tracker polygons drawn.
pub fn overlay(s: &Snapshot) -> RgbImage {
    let (w, h) = (s.left.view().width() as u32, s.left.view().height() as u32);
    let mut img = RgbImage::new(2 * w, h);
    for (k, view) in [s.left.view(), s.right.view()].iter().enumerate() {
        for y in 0..h {
            let row = view.row(y as usize);
            for x in 0..w {
                let g = row[x as usize];
                img.put_pixel(k as u32 * w + x, y, Rgb([g, g, g]));
            }
        }
    }
    for tracker in 0..TELEMETRY_TRACKERS {
        let view = tracker % 2;
        let colour = if s.tracker_state[tracker] == 2 {
            LOST
        } else if tracker < 2 {
            GRIPPER
        } else {
            TARGET
        };
        let pts: Vec<[f64; 2]> = s.corners[tracker]
            .iter()
            .filter(|c| c[0].is_finite() && c[1].is_finite())
            .map(|c| [f64::from(c[0]) + (view as u32 * w) as f64, f64::from(c[1])])
            .collect();
        for i in 0..pts.len() {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            draw_line(&mut img, a, b, colour);
        }
    }
    // The pointing finger's line across each view (it runs on to the pointed point), and
    // its tip.
    for v in 0..2 {
        let [a, b, c] = s.finger_line_px[v].map(f64::from);
        let dx = (v as u32 * w) as f64;
        if [a, b, c].iter().all(|x| x.is_finite()) && a.hypot(b) > 1e-9 {
            let (wf, hf) = (f64::from(w), f64::from(h));
            let ends = if b.abs() > a.abs() {
                [[0.0, -c / b], [wf - 1.0, -(c + a * (wf - 1.0)) / b]]
            } else {
                [[-c / a, 0.0], [-(c + b * (hf - 1.0)) / a, hf - 1.0]]
            };
            // Only inside this view's half.
            let steps = ((ends[1][0] - ends[0][0]).abs().max((ends[1][1] - ends[0][1]).abs()).ceil() as usize).clamp(1, 10_000);
            for i in 0..=steps {
                let f = i as f64 / steps as f64;
                let (x, y) = ((ends[0][0] + f * (ends[1][0] - ends[0][0])).round(), (ends[0][1] + f * (ends[1][1] - ends[0][1])).round());
                if (0.0..wf).contains(&x) && (0.0..hf).contains(&y) {
                    img.put_pixel((x + dx) as u32, y as u32, FINGER);
                }
            }
        }
        let tip = s.finger_tip_px[v].map(f64::from);
        if tip.iter().all(|x| x.is_finite()) {
            ring(&mut img, tip, dx, 5.0, FINGER);
        }
        if let Some(p) = s.point_px.map(|p| p[v]).filter(|p| p.iter().all(|x| x.is_finite())) {
            cross(&mut img, p, dx, 7.0, FINGER);
        }
    }
    img
}

const FINGER: Rgb<u8> = Rgb([0, 255, 255]);

/// Distinct colours for the planner's facets.
const FACET_COLOURS: [Rgb<u8>; 8] = [
    Rgb([60, 180, 75]),
    Rgb([0, 130, 200]),
    Rgb([245, 130, 48]),
    Rgb([145, 30, 180]),
    Rgb([70, 240, 240]),
    Rgb([240, 50, 230]),
    Rgb([210, 245, 60]),
    Rgb([0, 128, 128]),
];
const CHOSEN: Rgb<u8> = Rgb([255, 30, 30]);
const CANDIDATE: Rgb<u8> = Rgb([255, 255, 255]);
const REJECTED: Rgb<u8> = Rgb([255, 200, 0]);
const MASK: Rgb<u8> = Rgb([90, 90, 160]);
const INDICATED: Rgb<u8> = Rgb([255, 0, 255]);
const HYPOTHESISED: Rgb<u8> = Rgb([255, 150, 150]);

fn polygon(img: &mut RgbImage, poly: &[[f64; 2]], dx: f64, colour: Rgb<u8>) {
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        draw_line(img, [a[0] + dx, a[1]], [b[0] + dx, b[1]], colour);
    }
}

fn cross(img: &mut RgbImage, p: [f64; 2], dx: f64, r: f64, colour: Rgb<u8>) {
    draw_line(img, [p[0] + dx - r, p[1] - r], [p[0] + dx + r, p[1] + r], colour);
    draw_line(img, [p[0] + dx - r, p[1] + r], [p[0] + dx + r, p[1] - r], colour);
}

fn ring(img: &mut RgbImage, p: [f64; 2], dx: f64, r: f64, colour: Rgb<u8>) {
    let n = 24;
    for i in 0..n {
        let (a0, a1) = (std::f64::consts::TAU * i as f64 / n as f64, std::f64::consts::TAU * (i + 1) as f64 / n as f64);
        draw_line(img, [p[0] + dx + r * a0.cos(), p[1] + r * a0.sin()], [p[0] + dx + r * a1.cos(), p[1] + r * a1.sin()], colour);
    }
}

/// The plan on both views (as the planner saw them, the gripper masked): the masked region
/// (blue-grey), every facet in its own colour (grey when it was left out of the grasp
/// scene, pink when hypothesised below a top face's front edge), the target facet's tracker outline (red), rejected sites (yellow crosses),
/// candidate sites (white rings), the chosen site (red ring and cross) and the indicated
/// point (magenta cross).
pub fn plan_overlay(p: &crate::planning::PlanOutput) -> RgbImage {
    let (w, h) = (p.images[0].width as u32, p.images[0].height as u32);
    let mut img = RgbImage::new(2 * w, h);
    for (k, view) in p.images.iter().enumerate() {
        for y in 0..h {
            for x in 0..w {
                let g = view.get(x as usize, y as usize);
                img.put_pixel(k as u32 * w + x, y, Rgb([g, g, g]));
            }
        }
    }
    let s = &p.summary;
    for k in 0..2 {
        let dx = f64::from(k as u32 * w);
        polygon(&mut img, &s.inputs.masks_px[k], dx, MASK);
        for (i, f) in s.scene.facets.iter().enumerate() {
            let colour = if f.hypothesised {
                HYPOTHESISED
            } else if f.component.is_some() {
                FACET_COLOURS[i % FACET_COLOURS.len()]
            } else {
                Rgb([120, 120, 120])
            };
            polygon(&mut img, if k == 0 { &f.left_px } else { &f.right_px }, dx, colour);
        }
        if let Some(t) = &p.target {
            polygon(&mut img, if k == 0 { &t.left_px } else { &t.right_px }, dx, CHOSEN);
        }
        let at = |site: &crate::planning::SiteSummary| if k == 0 { site.place.site_left_px } else { site.place.site_right_px };
        for r in &s.sites.rejected_sites {
            cross(&mut img, at(r), dx, 2.0, REJECTED);
        }
        for c in &s.sites.candidates {
            ring(&mut img, at(c), dx, 4.0, CANDIDATE);
        }
        if let Some(c) = &s.sites.chosen {
            ring(&mut img, at(c), dx, 6.0, CHOSEN);
            cross(&mut img, at(c), dx, 3.0, CHOSEN);
        }
        if let Some(ip) = s.inputs.indicated_px {
            cross(&mut img, ip[k], dx, 5.0, INDICATED);
        }
    }
    img
}

/// Draws a line segment (clipped to the image).
pub fn draw_line(img: &mut RgbImage, a: [f64; 2], b: [f64; 2], colour: Rgb<u8>) {
    let steps = ((b[0] - a[0]).abs().max((b[1] - a[1]).abs()).ceil() as usize).clamp(1, 10_000);
    for i in 0..=steps {
        let f = i as f64 / steps as f64;
        let (x, y) = ((a[0] + f * (b[0] - a[0])).round(), (a[1] + f * (b[1] - a[1])).round());
        if x >= 0.0 && y >= 0.0 && (x as u32) < img.width() && (y as u32) < img.height() {
            img.put_pixel(x as u32, y as u32, colour);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlay_draws_the_polygons_where_telemetry_put_them() {
        let left = ImageBuf::filled(100, 80, 50);
        let right = ImageBuf::filled(100, 80, 50);
        let mut corners = [[[f32::NAN; 2]; 8]; 4];
        corners[0][..4].copy_from_slice(&[[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [10.0, 30.0]]);
        corners[3][..3].copy_from_slice(&[[50.0, 50.0], [70.0, 50.0], [60.0, 70.0]]);
        let s = Snapshot {
            label: "t",
            frame_id: 1,
            left,
            right,
            corners,
            tracker_state: [1, 0, 0, 2],
            // A horizontal finger line at v = 40 in the right view, its tip at u = 60.
            finger_line_px: [[f32::NAN; 3], [0.0, 1.0, -40.0]],
            finger_tip_px: [[f32::NAN; 2], [60.0, 40.0]],
            // The indicated point marked in the left view only (the right one off the image).
            point_px: Some([[50.0, 20.0], [f64::NAN, 5.0]]),
        };
        let img = overlay(&s);
        assert_eq!(img.dimensions(), (200, 80));
        assert_eq!(*img.get_pixel(20, 10), GRIPPER, "gripper left edge");
        assert_eq!(*img.get_pixel(160, 50), LOST, "target right (lost), shifted into the right half");
        assert_eq!(*img.get_pixel(60, 50), Rgb([50, 50, 50]), "nothing drawn in the left half for a right tracker");
        assert_eq!(*img.get_pixel(100 + 20, 40), FINGER, "the finger's line across the right view");
        assert_eq!(*img.get_pixel(20, 40), Rgb([50, 50, 50]), "no finger line in the left view");
        assert_eq!(*img.get_pixel(50, 20), FINGER, "the indicated point's cross in the left view");
        assert_eq!(*img.get_pixel(155, 15), Rgb([50, 50, 50]), "no cross for a point that is not finite");
    }
}

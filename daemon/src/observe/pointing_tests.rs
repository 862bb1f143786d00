//! Observe mode's pointing in-process: [`super::ObserveLoop`] with a plane file and no
//! target, on synthetic perspective frames of an arm that points, goes, points again
//! elsewhere, and then points along a plane through both cameras. Each gesture is reported
//! once (answers within millimetres of the point meant, the refusal with its reason), live in
//! telemetry, and watching goes on after every one.

use std::path::Path;

use handeye_vision::image::ImageBuf;
use handeye_wire::{PointingState, Telemetry};
use nalgebra::{Matrix3x4, Vector3};

use super::plane::WorkingPlane;
use crate::test_cameras::{camera, px};
use super::{ObserveLoop, ObserveOptions};
use crate::config::DaemonConfig;

const W: usize = 640;
const H: usize = 480;
const PLANE_Z_M: f64 = 0.06;
const PERIOD_NS: u64 = 33_333_333;

struct Rig {
    cams: [Matrix3x4<f64>; 2],
    eyes: [Vector3<f64>; 2],
}

impl Rig {
    fn new() -> Self {
        let at = Vector3::new(0.35, 0.0, 0.16);
        let eyes = [Vector3::new(1.695, -0.241, 0.9), Vector3::new(1.695, 0.241, 0.9)];
        Self { cams: eyes.map(|e| camera(e, at)), eyes }
    }

    /// The plane file an operator would write: four table marks and their pixels.
    fn plane_file(&self) -> WorkingPlane {
        let mut text = format!("plane_z_m = {PLANE_Z_M}\n");
        for [x, y] in [[0.27, -0.1], [0.45, -0.1], [0.45, 0.1], [0.27, 0.1]] {
            let p = Vector3::new(x, y, PLANE_Z_M);
            let (l, r) = (px(&self.cams[0], &p), px(&self.cams[1], &p));
            text.push_str(&format!("[[points]]\nplane_m = [{x}, {y}]\nleft_px = [{}, {}]\nright_px = [{}, {}]\n", l[0], l[1], r[0], r[1]));
        }
        WorkingPlane::parse(&text, Path::new("plane.toml")).unwrap()
    }

    /// Both views of `scene` with an arm whose finger ends `back` from `target` (the
    /// fingertip `tip_m` back along it, the elbow 0.45 m further).
    fn arm(&self, scene: &[ImageBuf; 2], target: Vector3<f64>, back: Vector3<f64>, tip_m: f64) -> [ImageBuf; 2] {
        let tip = target + back * tip_m;
        let elbow = tip + back * 0.45;
        std::array::from_fn(|v| with_arm(&scene[v], px(&self.cams[v], &tip), px(&self.cams[v], &elbow)))
    }
}

/// Back along a finger coming from `azimuth_deg` at `elevation_deg`.
fn back(azimuth_deg: f64, elevation_deg: f64) -> Vector3<f64> {
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
}

/// A dark table with lighter blocks.
fn scene(seed: usize) -> ImageBuf {
    let mut img = ImageBuf::filled(W, H, 40);
    for k in 0..6 {
        let (x0, y0) = ((seed * 97 + k * 211) % (W - 60), (seed * 53 + k * 137) % (H - 60));
        for y in y0..y0 + 50 {
            for x in x0..x0 + 50 {
                img.set(x, y, 90 + (k * 25) as u8);
            }
        }
    }
    img
}

/// `base` with an arm from `tip` to `elbow`: a finger (5 px half-width) for the first fifth,
/// a forearm (14 px) beyond; grey 190.
fn with_arm(base: &ImageBuf, tip: [f64; 2], elbow: [f64; 2]) -> ImageBuf {
    let mut img = base.clone();
    let (dx, dy) = (elbow[0] - tip[0], elbow[1] - tip[1]);
    let len = dx.hypot(dy);
    let (ux, uy) = (dx / len, dy / len);
    for y in 0..H {
        for x in 0..W {
            let (qx, qy) = (x as f64 - tip[0], y as f64 - tip[1]);
            let (s, t) = (qx * ux + qy * uy, (-qx * uy + qy * ux).abs());
            if (0.0..=len).contains(&s) && t <= if s < 0.2 * len { 5.0 } else { 14.0 } {
                img.set(x, y, 190);
            }
        }
    }
    img
}

/// The stream: frames in order, each cycled like the service does, in lockstep with the
/// gesture thread (`timing.worker_wait_ms`): the same frames answered on any machine.
struct Stream {
    ol: ObserveLoop,
    id: u64,
    moments: Vec<(u64, &'static str)>,
    seen: Vec<Telemetry>,
}

impl Stream {
    /// Observe mode with `rig`'s plane file and no target, in lockstep with its gesture
    /// thread.
    fn new(rig: &Rig) -> Self {
        let options = ObserveOptions { hint: None, gripper_hint: None, mono: false, epipolar: None, plane: Some(rig.plane_file()) };
        let mut cfg = DaemonConfig::default();
        cfg.timing.worker_wait_ms = 5_000;
        Self { ol: ObserveLoop::new(cfg, options).unwrap(), id: 0, moments: Vec::new(), seen: Vec::new() }
    }

    fn show(&mut self, views: &[ImageBuf; 2], frames: usize) {
        for _ in 0..frames {
            let (l, r) = (views[0].view(), views[1].view());
            self.ol.start_pointing(&l, &r, capture_ns(self.id)).unwrap();
            if let Some(m) = self.ol.cycle(self.id, capture_ns(self.id), &l, &r) {
                self.moments.push((self.id, m));
            }
            self.seen.push(*self.ol.finish_cycle(1));
            self.id += 1;
        }
    }
}

fn capture_ns(id: u64) -> u64 {
    5_000 + id * PERIOD_NS
}

#[test]
fn each_gesture_is_answered_or_refused_once_live_and_watching_goes_on() {
    let rig = Rig::new();
    let mut s = Stream::new(&rig);
    let table = [scene(1), scene(2)];
    let targets = [Vector3::new(0.40, 0.03, PLANE_Z_M), Vector3::new(0.33, -0.05, PLANE_Z_M)];
    s.show(&table, 5);
    assert_eq!(PointingState::from_u32(s.seen[4].pointing_state), Some(PointingState::Absent));
    s.show(&rig.arm(&table, targets[0], back(160.0, 50.0), 0.14), 40);
    let held = *s.seen.last().unwrap();
    s.show(&table, 20);
    s.show(&rig.arm(&table, targets[1], back(-140.0, 40.0), 0.18), 40);
    s.show(&table, 20);
    // The third: along the plane through the target and both camera centres, tilted away
    // from the cameras within it: the two plane lines barely cross.
    let (l, r) = ((rig.eyes[0] - targets[0]).normalize(), (rig.eyes[1] - targets[0]).normalize());
    let side = l.cross(&r).normalize();
    let along = ((l + r).normalize() + 0.6 * Vector3::<f64>::new(-1.0, 0.0, 0.0)).normalize();
    let along = (along - side * side.dot(&along)).normalize();
    s.show(&rig.arm(&table, targets[0], along, 0.12), 40);
    s.show(&table, 20);
    // A camera of another size comes: not handed to the gesture tracker (its plane pixels and
    // background belong to the first), counted, no harm done.
    s.show(&[ImageBuf::filled(320, 240, 40), ImageBuf::filled(320, 240, 40)], 2);

    let report = s.ol.report(1.0, "stream ended").pointing.expect("a pointing section");
    assert_eq!(report.gestures_seen, 3, "{report:?}");
    assert_eq!(report.answered.len(), 2, "{report:#?}");
    for (a, (target, n)) in report.answered.iter().zip(targets.iter().zip([1, 2])) {
        let p = a.point_m.unwrap();
        let err = (p[0] - target.x).hypot(p[1] - target.y);
        assert!(err < 0.004 && p[2] == PLANE_Z_M, "gesture {n}: {:.1} mm off: {a:?}", err * 1e3);
        assert_eq!((a.gesture, a.outcome.as_str()), (n, "indicated"));
        assert_eq!(a.capture_time_ns, capture_ns(a.frame_id), "the answered frame's own capture stamp");
        assert!(a.sigma_mm.unwrap() > 0.0 && a.sigma_mm.unwrap() < 8.0, "{a:?}");
    }
    assert_eq!(report.refused.len(), 1, "{report:#?}");
    let refusal = &report.refused[0];
    assert_eq!((refusal.gesture, refusal.outcome.as_str(), refusal.point_m), (3, "degenerate", None), "{refusal:?}");
    assert!(refusal.detail.contains("both cameras"), "{refusal:?}");
    assert!(report.update.cycles > 0 && report.frames_submitted > 0 && report.frames_not_submitted >= 2, "{report:?}");
    // One overlay moment per answer and per refusal, in order.
    let labels: Vec<&str> = s.moments.iter().map(|m| m.1).collect();
    assert_eq!(labels, ["pointed", "pointed", "point_refused"]);
    // Live: while the first hand held, telemetry carried its point and the reason said so.
    assert_eq!(PointingState::from_u32(held.pointing_state), Some(PointingState::Indicated), "{}", held.reason_text());
    let err = (f64::from(held.pointing_point_m[0]) - targets[0].x).hypot(f64::from(held.pointing_point_m[1]) - targets[0].y);
    assert!(err < 0.004 && held.pointing_sigma_m > 0.0 && held.pointing_update_ns > 0, "{:?}", held.pointing_point_m);
    assert!(held.reason_text().starts_with("pointing: at (0.40"), "{}", held.reason_text());
    // And after the last hand went: watching for the next.
    let last = s.seen.last().unwrap();
    assert_eq!(PointingState::from_u32(last.pointing_state), Some(PointingState::Absent));
    assert_eq!(last.reason_text(), "pointing: no hand");
}

/// `scene` with one more block where there was none: moved there for good.
fn with_block(scene: &ImageBuf) -> ImageBuf {
    let mut img = scene.clone();
    for y in 300..340 {
        for x in 420..470 {
            img.set(x, y, 150);
        }
    }
    img
}

#[test]
fn a_scene_changed_for_good_becomes_the_scene_and_a_hand_coming_in_at_the_start_is_not_it() {
    let rig = Rig::new();
    let mut s = Stream::new(&rig);
    let table = [scene(1), scene(2)];
    let target = Vector3::new(0.40, 0.03, PLANE_Z_M);
    // Observing starts while a hand comes in (each frame a little further): not the scene.
    for k in 0..6 {
        s.show(&rig.arm(&table, target, back(160.0, 50.0), 0.30 - 0.02 * k as f64), 1);
    }
    s.show(&table, 5);
    assert!(s.seen[10].reason_text().starts_with("pointing: no hand"), "started on the table only: {}", s.seen[10].reason_text());
    // A block is put down in view and stays: a change, but no hand; after RENEW_AFTER_S it is
    // the scene, and the next hand is read against it.
    let moved = [with_block(&table[0]), with_block(&table[1])];
    let frames_to_renew = (super::pointing::RENEW_AFTER_S * 1e9 / PERIOD_NS as f64) as usize + 5;
    s.show(&moved, frames_to_renew);
    assert_eq!(PointingState::from_u32(s.seen.last().unwrap().pointing_state), Some(PointingState::Absent), "{}", s.seen.last().unwrap().reason_text());
    s.show(&rig.arm(&moved, target, back(160.0, 50.0), 0.14), 40);
    s.show(&moved, 20);
    let report = s.ol.report(1.0, "stream ended").pointing.expect("a pointing section");
    assert_eq!(report.scene_renewals, 1, "{report:#?}");
    assert_eq!(report.answered.len(), 1, "only the hand is answered: {report:#?}");
    let p = report.answered[0].point_m.unwrap();
    assert!((p[0] - target.x).hypot(p[1] - target.y) < 0.004, "{p:?}");
    assert_eq!(PointingState::from_u32(s.seen.last().unwrap().pointing_state), Some(PointingState::Absent));
}

//! The gesture on synthetic perspective images: a textured table scene, and an arm drawn as
//! a finger (narrow) continuing into a forearm (wide) along the projected 3-D pointing line.

use nalgebra::Vector3;

use super::*;
use crate::image::ImageBuf;
use crate::rng::SplitMix64;
use crate::servo::testcam::{PinholeCamera, Rig, cage};

const PLANE_Z_M: f64 = 0.05;
const W: usize = 640;
const H: usize = 480;

fn pointing(rig: &Rig) -> Pointing {
    let lower: Vec<Vector3<f64>> = cage().into_iter().filter(|p| p.z < 0.1).collect();
    let plane: Vec<[f64; 2]> = lower.iter().map(|p| [p.x, p.y]).collect();
    let fit = |cam: &PinholeCamera| PlaneHomography::fit(&plane, &lower.iter().map(|p| cam.project(p)).collect::<Vec<_>>()).unwrap();
    Pointing::new(fit(&rig.left), fit(&rig.right))
}

/// A scene: a grey table with a few darker and lighter rectangles (blocks), plus noise.
fn scene(seed: u64) -> ImageBuf {
    let mut rng = SplitMix64::new(seed);
    let mut img = ImageBuf::filled(W, H, 40);
    for _ in 0..6 {
        let (x0, y0) = (rng.below(W - 60), rng.below(H - 60));
        let g = 80 + rng.below(150) as u8;
        for y in y0..y0 + 50 {
            for x in x0..x0 + 50 {
                img.set(x, y, g);
            }
        }
    }
    img
}

fn noisy(img: &ImageBuf, rng: &mut SplitMix64) -> ImageBuf {
    let mut out = img.clone();
    for p in &mut out.data {
        *p = (f64::from(*p) + 1.5 * rng.normal()).round().clamp(0.0, 255.0) as u8;
    }
    out
}

/// `base` with an arm from `tip` to `elbow` (pixels): 5 px half-width for the first fifth
/// (the finger), 14 px beyond; grey 190.
fn with_arm(base: &ImageBuf, tip: [f64; 2], elbow: [f64; 2]) -> ImageBuf {
    let mut img = base.clone();
    let (dx, dy) = (elbow[0] - tip[0], elbow[1] - tip[1]);
    let len = dx.hypot(dy);
    let (ux, uy) = (dx / len, dy / len);
    for y in 0..H {
        for x in 0..W {
            let (px, py) = (x as f64 - tip[0], y as f64 - tip[1]);
            let s = px * ux + py * uy;
            let t = (-px * uy + py * ux).abs();
            let half = if s < 0.2 * len { 5.0 } else { 14.0 };
            if (0.0..=len).contains(&s) && t <= half {
                img.set(x, y, 190);
            }
        }
    }
    img
}

/// The arm's tip and elbow in both views for a finger `height_m` above `target` (on the
/// plane), coming from `azimuth_deg` at `elevation_deg`.
fn arm(rig: &Rig, target: Vector3<f64>, azimuth_deg: f64, elevation_deg: f64, height_m: f64) -> [[[f64; 2]; 2]; 2] {
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let back = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    let tip = target + back * (height_m / el.sin());
    let elbow = tip + back * 0.45;
    [[rig.left.project(&tip), rig.left.project(&elbow)], [rig.right.project(&tip), rig.right.project(&elbow)]]
}

/// Runs a tracker over `frames` frames of the arm (after 3 empty ones); the last state.
fn run(tracker: &mut PointingTracker, bg: &[ImageBuf; 2], arms: impl Fn(usize) -> [[[f64; 2]; 2]; 2], frames: usize, seed: u64) -> GestureState {
    let mut rng = SplitMix64::new(seed);
    tracker.set_background(&noisy(&bg[0], &mut rng).view(), &noisy(&bg[1], &mut rng).view());
    for _ in 0..3 {
        let state = tracker.update(&noisy(&bg[0], &mut rng).view(), &noisy(&bg[1], &mut rng).view());
        assert_eq!(state, GestureState::Absent);
    }
    let mut last = GestureState::Absent;
    for f in 0..frames {
        let a = arms(f);
        let (l, r) = (noisy(&with_arm(&bg[0], a[0][0], a[0][1]), &mut rng), noisy(&with_arm(&bg[1], a[1][0], a[1][1]), &mut rng));
        last = tracker.update(&l.view(), &r.view());
    }
    last
}

#[test]
fn a_steady_finger_indicates_its_point_on_the_plane_with_an_honest_uncertainty() {
    let rig = Rig::standard(1500.0);
    let bg = [scene(1), scene(2)];
    let mut rng = SplitMix64::new(5);
    let mut done = 0;
    for k in 0..8 {
        let target = Vector3::new(rng.range(0.42, 0.58), rng.range(-0.08, 0.08), PLANE_Z_M);
        let (az, el, h) = (rng.range(-150.0, 150.0), rng.range(35.0, 70.0), rng.range(0.08, 0.15));
        let a = arm(&rig, target, az, el, h);
        let mut tracker = PointingTracker::new(pointing(&rig), GestureConfig::default());
        match run(&mut tracker, &bg, |_| a, 12, k) {
            GestureState::Indicated(p) => {
                let err = (p.point_m[0] - target.x).hypot(p.point_m[1] - target.y);
                eprintln!("gesture {k}: {:.2} mm off, sigma {:.2} mm, crossing {:.1}°", err * 1e3, p.sigma_m * 1e3, p.crossing_rad.to_degrees());
                assert!(err < 0.004, "gesture {k}: {err} m off (az {az:.0}°, el {el:.0}°)");
                assert!(p.sigma_m > 0.0 && p.sigma_m < 0.01 && err < 4.0 * p.sigma_m + 0.001, "gesture {k}: {err} m off, sigma {} m", p.sigma_m);
                // The tip end is found, on the line.
                for (v, (axis, seen)) in p.axes.iter().zip(&a).enumerate() {
                    let d = (axis.tip_px[0] - seen[0][0]).hypot(axis.tip_px[1] - seen[0][1]);
                    assert!(d < 3.0, "gesture {k} view {v}: tip {d} px off");
                }
                done += 1;
            }
            GestureState::Degenerate { crossing_rad } => assert!(crossing_rad < 3f64.to_radians()),
            other => panic!("gesture {k}: {other:?}"),
        }
    }
    assert!(done >= 6, "only {done} of 8 gestures indicated a point");
}

#[test]
fn a_finger_in_a_plane_through_both_cameras_is_reported_degenerate() {
    let rig = Rig::standard(1500.0);
    let target = Vector3::new(0.5, 0.0, PLANE_Z_M);
    // Back along the finger: in the plane of the target and both camera centres, upwards.
    let (l, r) = ((rig.left.centre_m - target).normalize(), (rig.right.centre_m - target).normalize());
    let back = (l + r).normalize();
    let tip = target + back * 0.2;
    let elbow = tip + back * 0.45;
    let a = [[rig.left.project(&tip), rig.left.project(&elbow)], [rig.right.project(&tip), rig.right.project(&elbow)]];
    let mut tracker = PointingTracker::new(pointing(&rig), GestureConfig::default());
    // Looking straight along the arm, each camera sees it foreshortened to a short blob: at
    // most a degenerate report, never a point.
    match run(&mut tracker, &[scene(3), scene(4)], |_| a, 12, 1) {
        GestureState::Degenerate { crossing_rad } => assert!(crossing_rad < 3f64.to_radians()),
        GestureState::Moving { .. } => {}
        other => panic!("{other:?}"),
    }
    // Tilted a little out of that plane, sideways, it is still not answered.
    let side = (l.cross(&r)).normalize();
    let back = (back + 0.6 * Vector3::<f64>::new(-1.0, 0.0, 0.0)).normalize();
    let back = (back - side * side.dot(&back)).normalize();
    let tip = target + back * 0.12;
    let elbow = tip + back * 0.45;
    let a = [[rig.left.project(&tip), rig.left.project(&elbow)], [rig.right.project(&tip), rig.right.project(&elbow)]];
    let mut tracker = PointingTracker::new(pointing(&rig), GestureConfig::default());
    match run(&mut tracker, &[scene(3), scene(4)], |_| a, 12, 2) {
        GestureState::Degenerate { crossing_rad } => assert!(crossing_rad < 3f64.to_radians()),
        other => panic!("a finger in the cameras' plane gave {other:?}"),
    }
}

#[test]
fn a_hand_that_does_not_hold_still_is_reported_unsteady() {
    let rig = Rig::standard(1500.0);
    let target = Vector3::new(0.5, 0.02, PLANE_Z_M);
    let a = arm(&rig, target, 60.0, 50.0, 0.1);
    let config = GestureConfig { unsteady_after_frames: 30, ..GestureConfig::default() };
    let mut tracker = PointingTracker::new(pointing(&rig), config);
    // The hand sways by 3 px, frame to frame.
    let sway = |f: usize| {
        let d = if f.is_multiple_of(2) { 3.0 } else { -3.0 };
        a.map(|v| v.map(|p| [p[0] + d, p[1]]))
    };
    assert_eq!(run(&mut tracker, &[scene(5), scene(6)], sway, 40, 3), GestureState::Unsteady { frames: 40 });
}

#[test]
fn an_empty_scene_is_absent_and_a_blob_is_not_an_arm() {
    let rig = Rig::standard(1500.0);
    let bg = [scene(7), scene(8)];
    let mut tracker = PointingTracker::new(pointing(&rig), GestureConfig::default());
    let mut rng = SplitMix64::new(1);
    assert_eq!(tracker.update(&noisy(&bg[0], &mut rng).view(), &noisy(&bg[1], &mut rng).view()), GestureState::Absent);
    assert_eq!(tracker.update(&noisy(&bg[0], &mut rng).view(), &noisy(&bg[1], &mut rng).view()), GestureState::Absent);
    // A square block put down in view: it changed, but it has no axis.
    let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
    let mut moved = bg[0].clone();
    for y in 200..260 {
        for x in 300..360 {
            moved.set(x, y, 250);
        }
    }
    assert_eq!(finder.find(&bg[0].view(), &moved.view()), Err(SilhouetteError::NotElongated));
}

/// `base` with parts of an arm drawn along the unit direction `u` from `tip` (pixels): each
/// part `(from, to, half width)` px along and across; grey 190.
fn with_parts(base: &ImageBuf, tip: [f64; 2], u: [f64; 2], parts: &[(f64, f64, f64)]) -> ImageBuf {
    let mut img = base.clone();
    for y in 0..H {
        for x in 0..W {
            let (px, py) = (x as f64 - tip[0], y as f64 - tip[1]);
            let (s, t) = (px * u[0] + py * u[1], -px * u[1] + py * u[0]);
            if parts.iter().any(|&(a, b, half)| (a..=b).contains(&s) && t.abs() <= half) {
                img.set(x, y, 190);
            }
        }
    }
    img
}

#[test]
fn a_hand_seen_from_the_front_gives_its_finger_line() {
    // The hand from the front: knuckles 110 px wide over a foreshortened finger 22 px wide and
    // 55 px long; the sleeve lost against the scene. As a whole a blob (no axis before the
    // finger was found as a part of its own); the finger is a clear line.
    let bg = scene(11);
    let mut rng = SplitMix64::new(3);
    for (k, angle_deg) in [-100.0f64, -80.0, -60.0, -115.0].into_iter().enumerate() {
        let u = [angle_deg.to_radians().cos(), angle_deg.to_radians().sin()];
        let tip = [320.0 + 3.0 * k as f64, 330.0];
        let frame = noisy(&with_parts(&bg, tip, u, &[(0.0, 55.0, 11.0), (55.0, 125.0, 55.0)]), &mut rng);
        let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
        let axis = finder.find(&noisy(&bg, &mut rng).view(), &frame.view()).unwrap_or_else(|e| panic!("{angle_deg}°: {e}"));
        assert!(!finder.finger_part_pixels().is_empty(), "{angle_deg}°: the whole silhouette gave an axis: not a blob");
        // The line is the finger's axis: through the tip and the hand's middle.
        let l = axis.line.0;
        let off = |p: [f64; 2]| l[0] * p[0] + l[1] * p[1] + l[2];
        let hand = [tip[0] + 90.0 * u[0], tip[1] + 90.0 * u[1]];
        assert!(off(tip).abs() < 1.0 && off(hand).abs() < 2.0, "{angle_deg}°: line {:.2} px off the tip, {:.2} px off the hand", off(tip), off(hand));
        assert!((axis.tip_px[0] - tip[0]).hypot(axis.tip_px[1] - tip[1]) < 3.0, "{angle_deg}°: tip {:?}", axis.tip_px);
        // Measured on the finger alone: its angle is no surer than its length allows.
        let length = (axis.tip_px[0] - axis.tail_px[0]).hypot(axis.tip_px[1] - axis.tail_px[1]);
        assert!(length < 60.0 && axis.angle_sigma_rad >= 0.5 / length, "{angle_deg}°: {length} px, angle sigma {}", axis.angle_sigma_rad);
    }
}

#[test]
fn a_sliver_off_a_blob_is_not_taken_for_a_finger() {
    // A hand seen from the front whose only protrusion is its side face at a grazing angle
    // (6 px wide): no line, rather than a line along the sliver.
    let bg = scene(12);
    let mut rng = SplitMix64::new(4);
    let u = [0.0, -1.0];
    let hand = with_parts(&bg, [300.0, 300.0], u, &[(0.0, 75.0, 55.0)]);
    let frame = noisy(&with_parts(&hand, [300.0 + 52.0, 300.0 - 75.0], u, &[(0.0, 50.0, 3.0)]), &mut rng);
    let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
    assert_eq!(finder.find(&noisy(&bg, &mut rng).view(), &frame.view()), Err(SilhouetteError::NotElongated));
}

#[test]
fn a_finger_in_front_of_a_scene_edge_keeps_its_sections() {
    // A finger crossing a grey strip of the scene as wide as itself (the robot's base seen
    // along the finger): the finger's edges lie on the strip's edges there. The finger is in
    // front, so those sections keep its width and its middle; dropping them (as if the strip
    // hid the finger) left too little finger, and the line followed the hand, bent 20°.
    let mut bg = scene(13);
    let tip = [150.0, 240.0];
    for y in 235..=245 {
        for x in 168..200 {
            bg.set(x, y, 120);
        }
    }
    let mut rng = SplitMix64::new(5);
    let finger = with_parts(&bg, tip, [1.0, 0.0], &[(0.0, 70.0, 5.0)]);
    let bend = 20f64.to_radians();
    let frame = noisy(&with_parts(&finger, [tip[0] + 70.0, tip[1]], [bend.cos(), bend.sin()], &[(0.0, 200.0, 14.0)]), &mut rng);
    let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
    let axis = finder.find(&noisy(&bg, &mut rng).view(), &frame.view()).unwrap_or_else(|e| panic!("{e}"));
    let l = axis.line.0;
    let off = |p: [f64; 2]| l[0] * p[0] + l[1] * p[1] + l[2];
    let knuckle = [tip[0] + 65.0, tip[1]];
    assert!(off(tip).abs() < 1.5 && off(knuckle).abs() < 1.5, "line {:.2} px off the tip, {:.2} px off the knuckle", off(tip), off(knuckle));
}

#[test]
fn a_finger_seen_end_on_in_one_view_still_indicates_its_point() {
    // The finger points at the target from the right camera's side, along the right camera's
    // ray through the target: the left view sees the arm as a line; the right view sees a hand
    // blob with a stub of a finger (20 px wide, 26 px long: not 1.5 times longer than wide),
    // drawn here turned 25° off any line through the tip, as a stub's direction is unknown.
    // The right view's ray through the tip meets the plane at the target, so the stub's line,
    // turned about the tip, hardly moves the point: it is answered, within its sigma.
    let rig = Rig::standard(1500.0);
    let bg = [scene(21), scene(22)];
    let target = Vector3::new(0.5, 0.02, PLANE_Z_M);
    let back = (rig.right.centre_m - target).normalize();
    let tip = target + back * 0.12;
    let elbow = tip + back * 0.45;
    let (tl, el, tr) = (rig.left.project(&tip), rig.left.project(&elbow), rig.right.project(&tip));
    let turn = 25f64.to_radians();
    let u = [turn.sin(), -turn.cos()];
    let mut tracker = PointingTracker::new(pointing(&rig), GestureConfig::default());
    let mut rng = SplitMix64::new(8);
    tracker.set_background(&noisy(&bg[0], &mut rng).view(), &noisy(&bg[1], &mut rng).view());
    let (left, right) = (with_arm(&bg[0], tl, el), with_parts(&bg[1], tr, u, &[(0.0, 26.0, 10.0), (26.0, 110.0, 45.0)]));
    let mut last = GestureState::Absent;
    for _ in 0..12 {
        last = tracker.update(&noisy(&left, &mut rng).view(), &noisy(&right, &mut rng).view());
    }
    let GestureState::Indicated(p) = last else { panic!("{last:?}") };
    let err = (p.point_m[0] - target.x).hypot(p.point_m[1] - target.y);
    eprintln!("end-on: {:.2} mm off, sigma {:.2} mm, right angle sigma {:.3} rad, tip {:?} drawn at {tr:?}", err * 1e3, p.sigma_m * 1e3, p.axes[1].angle_sigma_rad, p.axes[1].tip_px);
    assert_eq!(p.axes[1].sections, 0, "the right view's line is the stub's");
    assert!(p.axes[1].angle_sigma_rad > 0.2, "a stub's angle is not known better than its root: {}", p.axes[1].angle_sigma_rad);
    assert!(p.sigma_m < 0.008 && err < 2.0 * p.sigma_m + 0.0005, "{err} m off at sigma {} m", p.sigma_m);
}

#[test]
fn views_whose_fingers_point_apart_are_refused_as_disagreeing() {
    // The same image line in both views as a finger pointing at the target, but in the right
    // view the narrow end (the fingertip) is at the other end: the lines meet at the target,
    // which lies behind the right view's fingertip. No finger points there; refused.
    let rig = Rig::standard(1500.0);
    let target = Vector3::new(0.5, 0.02, PLANE_Z_M);
    let mut a = arm(&rig, target, 60.0, 50.0, 0.1);
    let mut tracker = PointingTracker::new(pointing(&rig), GestureConfig::default());
    assert!(matches!(run(&mut tracker, &[scene(23), scene(24)], |_| a, 12, 6), GestureState::Indicated(_)));
    // Reversed: the narrow end drawn 40 % of the way to the elbow, so that the whole arm
    // stays inside the image (an arm that runs out of the image has its tail there,
    // whichever end is narrower).
    let [tip, elbow] = a[1];
    let far = [tip[0] + 0.4 * (elbow[0] - tip[0]), tip[1] + 0.4 * (elbow[1] - tip[1])];
    assert!([tip, far].iter().all(|p| p[0] > 20.0 && p[1] > 20.0 && p[0] < W as f64 - 20.0 && p[1] < H as f64 - 20.0), "{tip:?} {far:?}");
    a[1] = [far, tip];
    let mut tracker = PointingTracker::new(pointing(&rig), GestureConfig::default());
    match run(&mut tracker, &[scene(23), scene(24)], |_| a, 12, 6) {
        GestureState::Disagree { view, behind_px } => assert!(view == 1 && behind_px > 50.0, "view {view}, {behind_px} px behind"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_finger_cut_by_the_border_has_its_tip_inside_the_image() {
    // Only the finger in view, the hand beyond the image border (seen from the side, a finger
    // 10 px wide runs out of the image): both ends are as wide, and the width rule flipped the
    // tip between the fingertip and the border from frame to frame on noise, so the hand
    // never held "still" (point_clutter3 seed 57). The end that runs out of the image is the
    // tail: the arm belongs to someone outside it.
    let bg = scene(31);
    let mut rng = SplitMix64::new(9);
    for (tip, angle_deg) in [([200.0, 240.0], 200.0f64), ([420.0, 260.0], -15.0), ([300.0, 200.0], -80.0)] {
        let u = [angle_deg.to_radians().cos(), angle_deg.to_radians().sin()];
        let frame = with_parts(&bg, tip, u, &[(0.0, 600.0, 5.0)]);
        let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
        for _ in 0..8 {
            let axis = finder.find(&noisy(&bg, &mut rng).view(), &noisy(&frame, &mut rng).view()).unwrap_or_else(|e| panic!("{angle_deg}°: {e}"));
            let off = |p: [f64; 2]| (p[0] - tip[0]).hypot(p[1] - tip[1]);
            assert!(off(axis.tip_px) < 3.0 && off(axis.end_px) < 3.0, "{angle_deg}°: tip {:?}, end {:?}, drawn at {tip:?}", axis.tip_px, axis.end_px);
        }
    }
}

#[test]
fn a_finger_that_fades_out_just_short_of_the_border_has_its_tip_inside_the_image() {
    // As above, but the silhouette stops 5 px short of the border (a sleeve nearly the
    // scene's grey changes only some of its pixels; point_clutter3 seed 64): no pixel on the
    // border, and the width rule flipped the tip to the end at the border. An end that close
    // to the border runs out of the image.
    let bg = scene(32);
    let mut rng = SplitMix64::new(10);
    for (tip, angle_deg) in [([200.0, 240.0], 180.0f64), ([420.0, 260.0], 0.0), ([300.0, 200.0], -90.0)] {
        let u = [angle_deg.to_radians().cos(), angle_deg.to_radians().sin()];
        // Along u from the tip to the border, less 5 px.
        let to_border = [(-tip[0] / u[0]), ((W as f64 - 1.0 - tip[0]) / u[0]), (-tip[1] / u[1]), ((H as f64 - 1.0 - tip[1]) / u[1])]
            .into_iter()
            .filter(|d| d.is_finite() && *d > 0.0)
            .fold(f64::INFINITY, f64::min);
        let frame = with_parts(&bg, tip, u, &[(0.0, to_border - 5.0, 5.0)]);
        let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
        for _ in 0..8 {
            let axis = finder.find(&noisy(&bg, &mut rng).view(), &noisy(&frame, &mut rng).view()).unwrap_or_else(|e| panic!("{angle_deg}°: {e}"));
            let off = |p: [f64; 2]| (p[0] - tip[0]).hypot(p[1] - tip[1]);
            assert!(off(axis.tip_px) < 3.0 && off(axis.end_px) < 3.0, "{angle_deg}°: tip {:?}, end {:?}, drawn at {tip:?}", axis.tip_px, axis.end_px);
        }
    }
}

#[test]
fn an_arm_whose_narrow_end_runs_out_of_the_image_has_no_fingertip_in_view() {
    // A hand seen from the back, 60 px wide, on a 30 px forearm that runs out of the image, and
    // no finger to be seen: the narrow end is the forearm's, at the border. The width rule
    // alone put the tip there (a "finger" pointing out of the image, on the hand's midline);
    // the arm is someone's from outside the image, so no fingertip is in view and no line.
    let bg = scene(51);
    let mut rng = SplitMix64::new(11);
    for angle_deg in [-60.0f64, -120.0, 200.0] {
        let u = [angle_deg.to_radians().cos(), angle_deg.to_radians().sin()];
        let frame = with_parts(&bg, [320.0, 300.0], u, &[(0.0, 70.0, 30.0), (70.0, 700.0, 15.0)]);
        let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
        match finder.find(&noisy(&bg, &mut rng).view(), &noisy(&frame, &mut rng).view()) {
            Err(SilhouetteError::NarrowEndOutside { narrow_px, wide_px }) => assert!(narrow_px < wide_px, "{angle_deg}°: {narrow_px} vs {wide_px} px"),
            other => panic!("{angle_deg}°: {other:?}"),
        }
    }
}

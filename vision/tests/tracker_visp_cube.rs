//! The tracker on real frames: the `visp-cube` sequence (218 frames of a textured cube seen by
//! a hand-held camera; `$HANDEYE_DATA/visp-cube`, see `data_support`). The top face, initialised
//! from `faces-frame0.json`, must be tracked through every frame without being lost, and its
//! corners must stay within 4 px of ground truth annotated by eye on frames spread over the
//! sequence. Reports itself skipped when the data set is absent.

use std::path::Path;

use handeye_vision::image::ImageBuf;
use handeye_vision::tracker::{ContourTracker, TrackState, TrackerConfig};
use nalgebra::Vector2;

#[path = "../../tests/data_support/mod.rs"]
mod data_support;
mod visp_cube_truth;
use visp_cube_truth::{GROUND_TRUTH, LEFT_FACE_TRUTH, TOP_FACE_FRAME0};

fn load(dir: &Path, k: usize) -> ImageBuf {
    let path = dir.join(format!("image{k:04}.png"));
    let img = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    ImageBuf::from_vec(img.into_raw(), w, h).unwrap()
}


#[test]
fn top_face_is_tracked_through_all_frames_within_4_px_of_ground_truth() {
    let Some(dir) = data_support::visp_cube(&["image0000.png", "image0217.png"]) else { return };
    let mut tracker = ContourTracker::new(TrackerConfig::default(), &TOP_FACE_FRAME0).unwrap();
    let mut checked = 0;
    let mut worst: f64 = 0.0;
    for k in 0..218 {
        let frame = load(&dir, k);
        let state = tracker.update(&frame.view(), if k == 0 { 0.0 } else { 1.0 / 30.0 });
        assert_eq!(state, TrackState::Tracking, "frame {k}: {state:?}");
        if let Some((_, truth)) = GROUND_TRUTH.iter().find(|(f, _)| *f == k) {
            for (j, (c, t)) in tracker.corners().zip(truth).enumerate() {
                let err = (c - Vector2::new(t[0], t[1])).norm();
                worst = worst.max(err);
                assert!(err < 4.0, "frame {k}, corner {j}: {err:.2} px off ({c:?} vs {t:?})");
            }
            checked += 1;
        }
    }
    assert_eq!(checked, GROUND_TRUTH.len());
    eprintln!("top face: all 218 frames tracked, worst corner error {worst:.2} px on {checked} annotated frames");
}

/// Starts of the top face from which the tracker used to lock onto a texture edge inside the
/// face, 7-10 px from its true back edge, and report `tracking` there until frame 60 (8-9 px
/// off the annotated corners on frame 50): from `examples/tracker_profile.rs`'s wide grid
/// (points, corner margin, start offset in px).
const WRONG_LOCK_STARTS: [(usize, f64, [f64; 2]); 3] = [(100, 0.06, [1.0, 3.0]), (100, 0.065, [3.0, 3.0]), (96, 0.065, [3.0, 3.0])];

/// Frames in a row a tracker may report `tracking` while >= 6 px off the face before it says
/// it lost it: the wrong-lock check's 10 updates and the start's snap onto the edges.
const FEW_FRAMES: usize = 12;

/// A wrong lock is a loss: from each of those starts the tracker either stays on the face or
/// reports it lost, and never tracks >= 6 px off it (from the annotated corners on their
/// frames, and from the track started on the annotated corners on every frame: the test above
/// holds that one within 4 px of them) for more than a few frames.
#[test]
fn a_contour_locked_on_a_texture_edge_is_reported_lost_within_a_few_frames() {
    let Some(dir) = data_support::visp_cube(&["image0000.png", "image0217.png"]) else { return };
    let frames: Vec<ImageBuf> = (0..218).map(|k| load(&dir, k)).collect();
    let dt = |k: usize| if k == 0 { 0.0 } else { 1.0 / 30.0 };
    for (points, corner_margin, [dx, dy]) in WRONG_LOCK_STARTS {
        let config = TrackerConfig { points, corner_margin, ..TrackerConfig::default() };
        let mut reference = ContourTracker::new(config, &TOP_FACE_FRAME0).unwrap();
        let start: Vec<[f64; 2]> = TOP_FACE_FRAME0.iter().map(|c| [c[0] + dx, c[1] + dy]).collect();
        let mut tracker = ContourTracker::new(config, &start).unwrap();
        let run = format!("{points} points, margin {corner_margin}, start ({dx}, {dy}) px off");
        let mut off_in_a_row = 0;
        let mut outcome = "tracked to the end".to_string();
        for (k, frame) in frames.iter().enumerate() {
            assert!(reference.update(&frame.view(), dt(k)).is_tracking(), "{run}: the reference lost the face at frame {k}");
            let state = tracker.update(&frame.view(), dt(k));
            if let Some(reason) = state.lost_reason() {
                outcome = format!("lost at frame {k}: {reason}");
                break;
            }
            let from_reference = tracker.corners().zip(reference.corners()).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
            off_in_a_row = if from_reference >= 6.0 { off_in_a_row + 1 } else { 0 };
            assert!(off_in_a_row <= FEW_FRAMES, "{run}: tracking {from_reference:.1} px off the face for {off_in_a_row} frames (frame {k})");
            if let Some((_, truth)) = GROUND_TRUTH.iter().find(|(f, _)| *f == k && *f > 0) {
                for (j, (c, t)) in tracker.corners().zip(truth).enumerate() {
                    let err = (c - Vector2::new(t[0], t[1])).norm();
                    assert!(err < 6.0, "{run}: tracking with corner {j} {err:.1} px off the annotation on frame {k}");
                }
            }
        }
        eprintln!("{run}: {outcome}");
    }
}

/// The left face's corners in `faces-frame0.json` (about ±3 px).
const LEFT_FACE_FRAME0: [[f64; 2]; 4] = [[315.0, 234.0], [365.0, 291.0], [361.0, 350.0], [317.0, 289.0]];

/// Settings and starts from which the left face's contour shears off its far bottom corner
/// (10-14 px up the face's far edge on frame 50; `examples/tracker_profile.rs`'s wide grid:
/// points, corner margin, start offset in px): the wrong-lock check counting updates in a
/// row let them report `tracking` to the last frame.
const LEFT_SHEAR_STARTS: [(usize, f64, [f64; 2]); 4] =
    [(96, 0.055, [0.0, 0.0]), (96, 0.055, [3.0, 0.0]), (100, 0.065, [0.0, 0.0]), (104, 0.065, [2.0, 2.0])];

/// The left face (the closed loop's target) is held or reported lost, never tracked >= 6 px
/// off its annotated corners; and from the annotated start with the default settings it is
/// tracked through every frame within 4 px of them (a check that fires there is wrong).
#[test]
fn the_left_face_is_tracked_within_4_px_or_its_shear_is_reported_lost() {
    let Some(dir) = data_support::visp_cube(&["image0000.png", "image0217.png"]) else { return };
    let frames: Vec<ImageBuf> = (0..218).map(|k| load(&dir, k)).collect();
    let dt = |k: usize| if k == 0 { 0.0 } else { 1.0 / 30.0 };
    let default = (TrackerConfig::default().points, TrackerConfig::default().corner_margin, [0.0, 0.0]);
    for (points, corner_margin, [dx, dy]) in std::iter::once(default).chain(LEFT_SHEAR_STARTS) {
        let config = TrackerConfig { points, corner_margin, ..TrackerConfig::default() };
        let start: Vec<[f64; 2]> = LEFT_FACE_FRAME0.iter().map(|c| [c[0] + dx, c[1] + dy]).collect();
        let mut tracker = ContourTracker::new(config, &start).unwrap();
        let run = format!("left face, {points} points, margin {corner_margin}, start ({dx}, {dy}) px off");
        let mut outcome = "tracked to the end".to_string();
        let mut worst: f64 = 0.0;
        for (k, frame) in frames.iter().enumerate() {
            let state = tracker.update(&frame.view(), dt(k));
            if let Some(reason) = state.lost_reason() {
                assert!((points, corner_margin, [dx, dy]) != default, "{run}: lost at frame {k}: {reason}");
                outcome = format!("lost at frame {k}: {reason}");
                break;
            }
            if let Some((_, truth)) = LEFT_FACE_TRUTH.iter().find(|(f, _)| *f == k) {
                for (j, (c, t)) in tracker.corners().zip(truth).enumerate() {
                    let err = (c - Vector2::new(t[0], t[1])).norm();
                    worst = worst.max(err);
                    assert!(err < 6.0, "{run}: tracking with corner {j} {err:.1} px off the annotation on frame {k}");
                }
            }
        }
        if (points, corner_margin, [dx, dy]) == default {
            assert!(worst < 4.0, "{run}: worst corner error {worst:.2} px");
        }
        eprintln!("{run}: {outcome} (worst annotated corner error while tracking {worst:.2} px)");
    }
}

/// The wide grid's three frame-150 slides (issue 18 item 5): from frame 147 the top face's
/// side 2 turns onto the right face's silhouette and side 0 onto a texture line while side 3
/// slides along itself, 12.2-12.7 px off on frame 150 with the default settings. The
/// experimental `min_shape_support_points` (a wide pass's change of shape kept only where it
/// does not explain fewer edges than the predicted shape) holds the face through them.
#[test]
fn the_top_faces_frame_150_slides_are_held_when_the_wide_pass_may_keep_the_predicted_shape() {
    let Some(dir) = data_support::visp_cube(&["image0000.png", "image0160.png"]) else { return };
    let frames: Vec<ImageBuf> = (0..=160).map(|k| load(&dir, k)).collect();
    let starts = [(100, [1.0, 3.0]), (104, [-2.0, 2.0]), (104, [-2.0, 3.0])];
    for (points, [dx, dy]) in starts {
        let config = TrackerConfig { points, corner_margin: 0.065, min_shape_support_points: 3, ..TrackerConfig::default() };
        let start: Vec<[f64; 2]> = TOP_FACE_FRAME0.iter().map(|c| [c[0] + dx, c[1] + dy]).collect();
        let mut tracker = ContourTracker::new(config, &start).unwrap();
        let run = format!("top face, {points} points, margin 0.065, start ({dx}, {dy}) px off");
        for (k, frame) in frames.iter().enumerate() {
            let state = tracker.update(&frame.view(), if k == 0 { 0.0 } else { 1.0 / 30.0 });
            assert!(state.is_tracking(), "{run}: lost at frame {k}: {state:?}");
            if let Some((_, truth)) = GROUND_TRUTH.iter().find(|(f, _)| *f == k && *f > 0) {
                for (j, (c, t)) in tracker.corners().zip(truth).enumerate() {
                    let err = (c - Vector2::new(t[0], t[1])).norm();
                    assert!(err < 4.0, "{run}: corner {j} {err:.1} px off the annotation on frame {k}");
                }
            }
        }
    }
}

/// The same three slides with the side-band check (`max_crossed_side_updates`, on by default;
/// issue 18 item 5): the turned side 2 has the right face, the grey level it had learnt lies outside it, on
/// its inside from frame 149, and the contour is reported lost (`wrong_lock`) by frame 150,
/// never tracking >= 6 px off an annotation. Without the check all three report `tracking`
/// 12.2-12.7 px off on frame 150.
#[test]
fn the_top_faces_frame_150_slides_are_reported_lost_when_a_side_has_its_outside_inside() {
    let Some(dir) = data_support::visp_cube(&["image0000.png", "image0160.png"]) else { return };
    let frames: Vec<ImageBuf> = (0..=160).map(|k| load(&dir, k)).collect();
    let starts = [(100, [1.0, 3.0]), (104, [-2.0, 2.0]), (104, [-2.0, 3.0])];
    for (points, [dx, dy]) in starts {
        let config = TrackerConfig { points, corner_margin: 0.065, max_crossed_side_updates: 2, ..TrackerConfig::default() };
        let start: Vec<[f64; 2]> = TOP_FACE_FRAME0.iter().map(|c| [c[0] + dx, c[1] + dy]).collect();
        let mut tracker = ContourTracker::new(config, &start).unwrap();
        let run = format!("top face, {points} points, margin 0.065, start ({dx}, {dy}) px off");
        let mut lost = None;
        for (k, frame) in frames.iter().enumerate() {
            let state = tracker.update(&frame.view(), if k == 0 { 0.0 } else { 1.0 / 30.0 });
            if let Some(reason) = state.lost_reason() {
                lost = Some((k, reason));
                break;
            }
            if let Some((_, truth)) = GROUND_TRUTH.iter().find(|(f, _)| *f == k && *f > 0) {
                for (j, (c, t)) in tracker.corners().zip(truth).enumerate() {
                    let err = (c - Vector2::new(t[0], t[1])).norm();
                    assert!(err < 6.0, "{run}: tracking with corner {j} {err:.1} px off the annotation on frame {k}");
                }
            }
        }
        let Some((k, reason)) = lost else { panic!("{run}: tracked to frame 160") };
        assert!(k > 140 && k <= 150 && reason.code() == "wrong_lock", "{run}: lost at frame {k}: {reason}");
        eprintln!("{run}: lost at frame {k}: {reason}");
    }
}

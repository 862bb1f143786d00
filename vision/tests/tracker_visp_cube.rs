//! The tracker on real frames: the `visp-cube` sequence (218 frames of a textured cube seen by
//! a hand-held camera; `../shared/data/visp-cube`). The top face, initialised from
//! `faces-frame0.json`, must be tracked through every frame without being lost, and its
//! corners must stay within 4 px of ground truth annotated by eye on frames spread over the
//! sequence. Skips (with a message) when the data set is absent.

use std::path::{Path, PathBuf};

use handeye_vision::image::ImageBuf;
use handeye_vision::tracker::{ContourTracker, TrackState, TrackerConfig};
use nalgebra::Vector2;

fn data_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/visp-cube");
    dir.join("image0000.png").is_file().then_some(dir)
}

fn load(dir: &Path, k: usize) -> ImageBuf {
    let path = dir.join(format!("image{k:04}.png"));
    let img = image::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    ImageBuf::from_vec(img.into_raw(), w, h).unwrap()
}

/// The top face's corners in `faces-frame0.json` (annotated by eye, about ±3 px).
const TOP_FACE_FRAME0: [[f64; 2]; 4] = [[315.0, 234.0], [385.0, 205.0], [443.0, 251.0], [365.0, 291.0]];

/// Ground truth for the top face, annotated by eye on magnified crops (about ±1.5 px), in
/// the JSON's corner order. The camera circles the cube, so the corners trade places in the
/// image: by frame 200 corner 0 is the near corner. In frame 217 the tall cylinder in front
/// hides corner 1; its annotation is the intersection of the two visible sides.
const GROUND_TRUTH: [(usize, [[f64; 2]; 4]); 6] = [
    (0, [[314.8, 234.0], [384.0, 204.8], [443.0, 253.0], [366.5, 291.0]]),
    (50, [[322.4, 216.0], [374.4, 178.4], [443.0, 212.4], [390.0, 257.5]]),
    (100, [[296.3, 155.8], [345.3, 128.0], [402.5, 155.0], [351.7, 190.8]]),
    (150, [[293.6, 135.7], [313.6, 101.4], [380.0, 110.7], [362.0, 150.0]]),
    (200, [[296.5, 139.0], [275.0, 104.0], [336.0, 92.5], [361.9, 121.4]]),
    (217, [[297.0, 139.0], [265.3, 106.1], [323.0, 91.0], [357.0, 117.5]]),
];

#[test]
fn top_face_is_tracked_through_all_frames_within_4_px_of_ground_truth() {
    let Some(dir) = data_dir() else {
        eprintln!("skipping: ../shared/data/visp-cube not found");
        return;
    };
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

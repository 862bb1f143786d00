//! The visp-cube sequence's top face: its corners in `faces-frame0.json` and ground truth
//! annotated by eye, shared by `tracker_visp_cube.rs` and `examples/tracker_profile.rs`.
#![allow(dead_code)] // Each includer uses part of it.

/// The top face's corners in `faces-frame0.json` (annotated by eye, about ±3 px).
pub const TOP_FACE_FRAME0: [[f64; 2]; 4] = [[315.0, 234.0], [385.0, 205.0], [443.0, 251.0], [365.0, 291.0]];

/// Ground truth for the top face, annotated by eye on magnified crops (about ±1.5 px), in
/// the JSON's corner order. The camera circles the cube, so the corners trade places in the
/// image: by frame 200 corner 0 is the near corner. In frame 217 the tall cylinder in front
/// hides corner 1; its annotation is the intersection of the two visible sides.
pub const GROUND_TRUTH: [(usize, [[f64; 2]; 4]); 6] = [
    (0, [[314.8, 234.0], [384.0, 204.8], [443.0, 253.0], [366.5, 291.0]]),
    (50, [[322.4, 216.0], [374.4, 178.4], [443.0, 212.4], [390.0, 257.5]]),
    (100, [[296.3, 155.8], [345.3, 128.0], [402.5, 155.0], [351.7, 190.8]]),
    (150, [[293.6, 135.7], [313.6, 101.4], [380.0, 110.7], [362.0, 150.0]]),
    (200, [[296.5, 139.0], [275.0, 104.0], [336.0, 92.5], [361.9, 121.4]]),
    (217, [[297.0, 139.0], [265.3, 106.1], [323.0, 91.0], [357.0, 117.5]]),
];

/// Ground truth for the left face (the target in the closed loop), in the order of
/// `faces-frame0.json` (the top face's corner 0, the near top corner, the near bottom corner,
/// the far bottom corner), on the top face's annotated frames after 0. Each corner is the
/// intersection of straight lines fitted to the face's edges in the image near a hand
/// estimate (`examples/annotate_face.rs`, which also draws an overlay per frame to check by
/// eye): ±0.1-0.6 px statistically; the two corners shared with the top face agree with its
/// annotations above within 0.1-1.7 px, so take about ±1.5 px.
pub const LEFT_FACE_TRUTH: [(usize, [[f64; 2]; 4]); 5] = [
    (50, [[321.3, 216.7], [391.5, 258.2], [383.5, 315.9], [322.0, 274.4]]),
    (100, [[295.2, 157.1], [351.6, 190.1], [347.7, 247.1], [297.9, 213.3]]),
    (150, [[293.3, 134.7], [362.7, 148.6], [358.8, 203.9], [295.0, 190.9]]),
    (200, [[295.6, 139.5], [362.0, 121.3], [358.6, 179.8], [297.9, 194.1]]),
    (217, [[295.9, 139.7], [357.3, 117.8], [354.6, 175.0], [297.6, 194.5]]),
];

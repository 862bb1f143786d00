//! The visp-cube sequence's top face: its corners in `faces-frame0.json` and ground truth
//! annotated by eye, shared by `tracker_visp_cube.rs` and `examples/tracker_profile.rs`.

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

//! A vertical face standing on the table, from its outline in one view. A planner facet whose
//! corners were matched to the wrong edges in the other view comes out reaching far below
//! the table and is dropped (clutter3 seed 104: a bar's long front face, 54 px wide on the
//! left, matched to a 28 px stretch on the right, "from −46 to 30 mm high"); its outline in
//! the view it came from may still be right. A block's face stands on the table, so its
//! bottom corners are where their pixels' rays meet the table and its top corners where
//! theirs meet the vertical plane through the bottom: the whole face from one view. It is
//! kept only where the other view shows it, every side an edge there ([`super::edge_support`]
//! at least [`MIN_SUPPORT`]): the view that failed to match it is the check.

use handeye_vision::image::ImageBuf;
use nalgebra::{Matrix2, Matrix3x4, Vector2, Vector3};

use super::edge_support;

/// The support every side of the face needs in the other view (as a hypothesised face's
/// bottom edge).
pub const MIN_SUPPORT: f64 = 0.6;

/// The robot point on the ray of pixel `px` (camera `cam`, the planner's pixels) at height `z`.
fn at_height(cam: &Matrix3x4<f64>, px: [f64; 2], z: f64) -> Option<Vector3<f64>> {
    // (P0 − u P2) · (x, y, z, 1) = 0 and (P1 − v P2) · (x, y, z, 1) = 0: two equations in x, y.
    let r0 = cam.row(0) - px[0] * cam.row(2);
    let r1 = cam.row(1) - px[1] * cam.row(2);
    let a = Matrix2::new(r0[0], r0[1], r1[0], r1[1]);
    let b = Vector2::new(-(r0[2] * z + r0[3]), -(r1[2] * z + r1[3]));
    let xy = a.try_inverse()? * b;
    Some(Vector3::new(xy.x, xy.y, z))
}

/// The face, robot frame, bottom corners first (`[b0, b1, t1, t0]`), from its quadrilateral
/// outline `poly_px` in the view of camera `cam`, standing on the table at `table_z_m`; `None`
/// for an outline that is not a quadrilateral with a bottom side at least 10 mm long and
/// a top side within 30° of horizontal, between 10 mm and `max_height_m` high.
pub fn face_on_table(cam: &Matrix3x4<f64>, poly_px: &[[f64; 2]], table_z_m: f64, max_height_m: f64) -> Option<[Vector3<f64>; 4]> {
    if poly_px.len() != 4 {
        return None;
    }
    // The bottom side: the two corners lowest in the image (largest v).
    let mut order: Vec<usize> = (0..4).collect();
    order.sort_by(|&i, &j| poly_px[j][1].total_cmp(&poly_px[i][1]));
    let (mut b0, mut b1) = (order[0], order[1]);
    if (b0 + 1) % 4 != b1 && (b1 + 1) % 4 != b0 {
        return None; // the two lowest corners are not a side
    }
    if poly_px[b0][0] > poly_px[b1][0] {
        std::mem::swap(&mut b0, &mut b1);
    }
    // Each bottom corner's neighbour that is not the other bottom corner is its top corner.
    let top_of = |b: usize, other: usize| if (b + 1) % 4 == other { (b + 3) % 4 } else { (b + 1) % 4 };
    let (t0, t1) = (top_of(b0, b1), top_of(b1, b0));
    let bottom = [at_height(cam, poly_px[b0], table_z_m)?, at_height(cam, poly_px[b1], table_z_m)?];
    if (bottom[1] - bottom[0]).norm() < 0.010 {
        return None;
    }
    let normal = (bottom[1] - bottom[0]).cross(&Vector3::z()).normalize();
    // The top corner's ray, as points at two heights, meets the face's vertical plane.
    let top = |t: usize| {
        let (p, q) = (at_height(cam, poly_px[t], table_z_m)?, at_height(cam, poly_px[t], table_z_m + 0.1)?);
        let (dp, dq) = (normal.dot(&(p - bottom[0])), normal.dot(&(q - bottom[0])));
        ((dq - dp).abs() > 1e-12).then(|| p + (q - p) * (-dp / (dq - dp)))
    };
    let (top0, top1) = (top(t0)?, top(t1)?);
    let (h0, h1) = (top0.z - table_z_m, top1.z - table_z_m);
    let along = (top1 - top0).norm();
    let level = along > 0.0 && (top1.z - top0.z).abs() / along <= 30f64.to_radians().sin();
    let height_ok = |h: f64| (0.010..=max_height_m).contains(&h);
    (level && height_ok(h0) && height_ok(h1)).then_some([bottom[0], bottom[1], top1, top0])
}

/// Whether the other view shows the face: its projection there (`other_px`, tracker pixels,
/// `[b0, b1, t1, t0]`) has its bottom and top sides on edges, and at least one of its
/// vertical sides. The top side is what tells a face standing on the table from a patch lying
/// on it (from one view they are alike; in the other their tops are apart by the disparity of
/// the patch's depth, ~12 px for 30 mm here); one end may be off where the view the face
/// came from saw its outline run on into the next face (seed 104: 5 mm).
pub fn seen_in_other_view(other: &ImageBuf, other_px: &[[f64; 2]; 4]) -> bool {
    let side = |i: usize| edge_support(other, other_px[i], other_px[(i + 1) % 4]) >= MIN_SUPPORT;
    side(0) && side(2) && (side(1) || side(3))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector4;

    /// A camera 1.2 m in front of the origin (towards +x), 0.8 m up, looking at it.
    fn camera() -> Matrix3x4<f64> {
        let c = Vector3::new(1.2, 0.0, 0.8);
        let fwd = (-c).normalize();
        let right = fwd.cross(&Vector3::z()).normalize();
        let down = fwd.cross(&right);
        let r = nalgebra::Matrix3::from_rows(&[right.transpose(), down.transpose(), fwd.transpose()]);
        let k = nalgebra::Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
        let t = -(r * c);
        k * Matrix3x4::from_columns(&[r.column(0).into(), r.column(1).into(), r.column(2).into(), t])
    }

    fn project(cam: &Matrix3x4<f64>, p: &Vector3<f64>) -> [f64; 2] {
        let x = cam * Vector4::new(p.x, p.y, p.z, 1.0);
        [x[0] / x[2], x[1] / x[2]]
    }

    #[test]
    fn a_face_standing_on_the_table_comes_back_from_one_view() {
        let cam = camera();
        // A 42 mm long, 30 mm high face on the table, facing the camera, a little turned.
        let (b0, b1) = (Vector3::new(0.02, -0.021, 0.0), Vector3::new(0.01, 0.021, 0.0));
        let (t0, t1) = (b0 + Vector3::new(0.0, 0.0, 0.03), b1 + Vector3::new(0.0, 0.0, 0.03));
        // Outline as the planner gives it: any start, either direction.
        let poly = [project(&cam, &t1), project(&cam, &t0), project(&cam, &b0), project(&cam, &b1)];
        let face = face_on_table(&cam, &poly, 0.0, 0.1).expect("a face");
        let want = [b0, b1, t1, t0];
        let ordered = if (face[0] - b0).norm() < (face[0] - b1).norm() { want } else { [b1, b0, t0, t1] };
        for (got, want) in face.iter().zip(ordered) {
            assert!((got - want).norm() < 1e-6, "{got} vs {want}");
        }
    }

    #[test]
    fn an_outline_taller_than_the_arm_clearance_is_no_face() {
        // (A patch of table reads as a face from one view too, 20 mm high here: the other
        // view tells them apart, `seen_in_other_view`.)
        let cam = camera();
        let tall = [
            project(&cam, &Vector3::new(0.0, -0.02, 0.0)),
            project(&cam, &Vector3::new(0.0, 0.02, 0.0)),
            project(&cam, &Vector3::new(0.0, 0.02, 0.3)),
            project(&cam, &Vector3::new(0.0, -0.02, 0.3)),
        ];
        assert!(face_on_table(&cam, &tall, 0.0, 0.1).is_none(), "taller than the arm's clearance");
    }
}

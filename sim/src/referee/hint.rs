//! The operator hint: the target facet's outline in both views, as an operator would click
//! it on the two images (each corner off by up to ±3 px, seeded), and the block's extent
//! behind the facet as the operator would measure it (±2 mm). It stands in for the grasp
//! planner until that exists: the daemon reads it once at start-up, never as a live stream.
//!
//! The facet is the target block's face that a parallel-jaw grasp across it can use and the
//! cameras see best: near-vertical (within 20°), with a parallel opposite face (the jaws close
//! along its normal), front-facing in both views, largest smaller-of-two projected area.

use glam::DVec3;
use handeye_wire::hint::{HINT_VERSION, OperatorHint};

use crate::render::camera::signed_area_px2;
use handeye_vision::rng::SplitMix64;
use crate::simulator::Simulator;

/// Largest corner error of the hint in each image coordinate, pixels.
pub const HINT_CORNER_ERROR_PX: f64 = 3.0;
/// Largest error of the hint's depth, millimetres.
pub const HINT_DEPTH_ERROR_MM: f64 = 2.0;

/// The facet the hint describes (ground truth, kept by the simulator for judging).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HintFacet {
    pub block: usize,
    pub face: usize,
    /// Outward unit normal at the time of the hint, robot frame.
    pub normal: DVec3,
    /// True depth behind the facet, metres.
    pub depth_m: f64,
}

/// Why no hint could be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HintFacetError {
    #[error("block '{0}' has no near-vertical face with a parallel opposite face that both cameras see")]
    NoGraspableFacet(String),
}

/// The hint for the scenario's target as things stand now, with seeded operator errors.
pub fn operator_hint(sim: &Simulator, seed: u64) -> Result<(OperatorHint, HintFacet), HintFacetError> {
    let block = sim.target_index();
    let b = &sim.world.blocks[block];
    let (_, pose) = sim.block_pose(block);
    let cams = &sim.events.cameras;
    let world_corners: Vec<DVec3> = b.shape.corners.iter().map(|&c| pose.transform_point3(c)).collect();
    // (smaller-of-two image area, face, left polygon, right polygon, depth)
    type Candidate = (f64, usize, Vec<[f64; 2]>, Vec<[f64; 2]>, f64);
    let mut best: Option<Candidate> = None;
    for (fi, face) in b.shape.faces.iter().enumerate() {
        let n = pose.matrix3 * face.normal;
        if n.z.abs() > 20f64.to_radians().sin() {
            continue;
        }
        let pts: Vec<DVec3> = face.corners.iter().map(|&c| world_corners[c]).collect();
        let centre = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
        // The opposite face: antiparallel normal; depth = distance between the planes.
        let Some(depth) = b
            .shape
            .faces
            .iter()
            .filter(|o| (pose.matrix3 * o.normal).dot(n) < -0.999)
            .map(|o| n.dot(centre - world_corners[o.corners[0]]))
            .reduce(f64::max)
        else {
            continue;
        };
        let mut views = Vec::new();
        for cam in cams.iter() {
            if n.dot(cam.position_m - centre) <= 0.0 {
                break;
            }
            let proj: Option<Vec<[f64; 2]>> = pts.iter().map(|&p| cam.project(p)).collect();
            match proj {
                Some(p) => views.push(p),
                None => break,
            }
        }
        if views.len() != 2 {
            continue;
        }
        let area = signed_area_px2(&views[0]).abs().min(signed_area_px2(&views[1]).abs());
        if best.as_ref().is_none_or(|b| area > b.0) {
            let right = views.pop().unwrap_or_default();
            let left = views.pop().unwrap_or_default();
            best = Some((area, fi, left, right, depth));
        }
    }
    let Some((_, face, mut left, mut right, depth_m)) = best else {
        return Err(HintFacetError::NoGraspableFacet(b.name.clone()));
    };
    let mut rng = SplitMix64::new(handeye_vision::rng::mix64(seed ^ 0x4849_4e54));
    let mut jitter = |v: f64, e: f64| v + (2.0 * rng.next_f64() - 1.0) * e;
    for p in left.iter_mut().chain(right.iter_mut()) {
        p[0] = jitter(p[0], HINT_CORNER_ERROR_PX);
        p[1] = jitter(p[1], HINT_CORNER_ERROR_PX);
    }
    let depth_mm = jitter(depth_m * 1e3, HINT_DEPTH_ERROR_MM);
    let normal = pose.matrix3 * b.shape.faces[face].normal;
    let note = format!(
        "block '{}' face '{}', clicked with up to ±{HINT_CORNER_ERROR_PX} px per corner, depth measured ±{HINT_DEPTH_ERROR_MM} mm (seed {seed})",
        b.name, b.shape.faces[face].name
    );
    Ok((OperatorHint { version: HINT_VERSION, left_px: left, right_px: right, depth_mm, note }, HintFacet { block, face, normal, depth_m }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sim(file: &str) -> Simulator {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios").join(file);
        Simulator::new(crate::Scenario::load(path).unwrap()).unwrap()
    }

    #[test]
    fn cube_hint_is_a_visible_vertical_face_within_the_error_bounds() {
        let s = sim("pick_cube.toml");
        let (hint, facet) = operator_hint(&s, 7).unwrap();
        assert_eq!(hint.left_px.len(), 4);
        assert!(facet.normal.z.abs() < 1e-6, "{:?}", facet.normal);
        assert!((facet.depth_m - 0.04).abs() < 1e-9);
        assert!((hint.depth_mm - 40.0).abs() <= HINT_DEPTH_ERROR_MM);
        // The cameras stand at +x: the chosen face must face them.
        assert!(facet.normal.x > 0.5, "{:?}", facet.normal);
        // Corner errors are bounded and seeded (another seed gives other errors).
        let b = &s.world.blocks[facet.block];
        let (_, pose) = s.block_pose(facet.block);
        for (i, &c) in b.shape.faces[facet.face].corners.iter().enumerate() {
            let p = s.events.cameras[0].project(pose.transform_point3(b.shape.corners[c])).unwrap();
            assert!((p[0] - hint.left_px[i][0]).abs() <= HINT_CORNER_ERROR_PX + 1e-9);
            assert!((p[1] - hint.left_px[i][1]).abs() <= HINT_CORNER_ERROR_PX + 1e-9);
        }
        let (other, _) = operator_hint(&s, 8).unwrap();
        assert_ne!(other.left_px, hint.left_px);
        assert_eq!(operator_hint(&s, 7).unwrap().0, hint);
    }

    #[test]
    fn wedge_hint_is_a_triangle_end() {
        let s = sim("pick_wedge.toml");
        let (hint, facet) = operator_hint(&s, 1).unwrap();
        let name = s.world.blocks[facet.block].shape.faces[facet.face].name;
        assert!(name == "-y" || name == "+y", "{name}");
        assert_eq!(hint.left_px.len(), 3);
    }
}

//! Whether the target has a grasp the rules allow, judged from ground truth: the block's true
//! faces and edges (robot frame) as a [`GraspScene`], planned with the very rules the daemon
//! plans with ([`plan_grasps`], thesis ch. 6: vertical facets, top edges within 30° of
//! horizontal, a parallel edge behind within the fingers' reach, a width the jaws span, no
//! collision). A batch tells a right refusal from a wrong one with it.
//!
//! The scene is the whole block but its bottom: every face a facet (the hidden ones give the
//! true rear edges and are obstacles to the fingers), but only a face the cameras see may
//! carry the grasp (a face turned away cannot be servoed onto). The rules
//! are the thesis's ([`GraspConfig::default`]: 50 mm jaws, any facet that faces the cameras),
//! not a daemon's settings.

use glam::DVec3;
use handeye_vision::grasp::{plan_grasps, why_no_grasp, GraspConfig, GraspScene, SceneFacet, Segment3};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::cell::geometry::BlockShape;
use crate::scenario::BlockConfig;

/// The judge's answer for one block.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Graspability {
    /// The rules allow at least one grasp of the block from the side the cameras see.
    pub graspable: bool,
    /// Why not, in words ("its top edges slope 34°"); `None` when graspable.
    pub reason: Option<String>,
}

/// Judges `block` as it stands, seen from cameras at `cameras_m` (robot frame).
pub fn judge_block(block: &BlockConfig, cameras_m: &[[f64; 3]]) -> Graspability {
    let shape = BlockShape::new(block.kind, DVec3::from_array(block.size_mm) * 1e-3);
    let (sin, cos) = block.yaw_deg.to_radians().sin_cos();
    let centre = DVec3::new(block.position_m[0], block.position_m[1], 0.5e-3 * block.size_mm[2]);
    let turn = |v: DVec3| DVec3::new(cos * v.x - sin * v.y, sin * v.x + cos * v.y, v.z);
    let corner = |i: usize| {
        let p = centre + turn(shape.corners[i]);
        Vector3::new(p.x, p.y, p.z)
    };
    let viewer = cameras_m.iter().fold(DVec3::ZERO, |a, c| a + DVec3::from_array(*c)) / cameras_m.len().max(1) as f64;
    let toward = (viewer - centre).normalize_or_zero();
    // Every face but the bottom (on the table) is a facet, so that the hidden ones are
    // obstacles to the fingers as the real block is; only a face the cameras see may carry
    // the grasp.
    let mut facets = Vec::new();
    let mut names = Vec::new();
    let mut seen = Vec::new();
    for face in shape.faces.iter().filter(|f| f.name != "bottom") {
        let ring: Vec<Vector3<f64>> = face.corners.iter().map(|&i| corner(i)).collect();
        let edges: Vec<Segment3> = (0..ring.len()).map(|k| Segment3::new(ring[k], ring[(k + 1) % ring.len()])).collect();
        facets.push(SceneFacet { polygon_m: ring, edges, component: 0 });
        names.push(face.name);
        // Seen: facing the cameras by more than ~3°, as the layout randomiser judged it.
        seen.push(turn(face.normal).dot(toward) > 0.05);
    }
    let scene = GraspScene { facets, edges: Vec::new(), toward_viewer: Vector3::new(toward.x, toward.y, toward.z) };
    let config = GraspConfig::default();
    match plan_grasps(&scene, None, &config) {
        Ok(plan) if plan.candidates.iter().any(|g| seen[g.site.facet]) => Graspability { graspable: true, reason: None },
        Ok(plan) => Graspability { graspable: false, reason: Some(why_no_grasp(&plan.rejected, |f| seen[f].then(|| format!("{} face", names[f])), &config)) },
        // A true block is always a valid scene; if it is not, say so rather than guess.
        Err(e) => Graspability { graspable: false, reason: Some(format!("cannot be judged: {e}")) },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::BlockKind;

    fn block(kind: BlockKind, size_mm: [f64; 3], yaw_deg: f64) -> BlockConfig {
        BlockConfig { name: "b".into(), kind, size_mm, position_m: [0.35, 0.0], yaw_deg, shades: None, shade_seed: None, density_kg_m3: 600.0, friction: 0.9 }
    }

    /// The shipped scenarios' cameras: at +x, 20° apart, 30° up.
    const CAMERAS: [[f64; 3]; 2] = [[1.695, -0.241, 0.9], [1.695, 0.241, 0.9]];

    #[test]
    fn a_cube_is_graspable_at_any_yaw() {
        for yaw in (0..360).step_by(15) {
            let j = judge_block(&block(BlockKind::Cube, [30.0; 3], f64::from(yaw)), &CAMERAS);
            assert_eq!(j, Graspability { graspable: true, reason: None }, "yaw {yaw}");
        }
    }

    #[test]
    fn a_wedge_sloping_34_degrees_is_not_graspable_and_says_why() {
        // 40 mm long, 27 mm high: the slope rises atan(27/40) = 34°; its vertical back face's
        // only parallel edge behind is the slope's foot, 27 mm down (the fingers reach 25).
        let reason = |yaw: f64| {
            let j = judge_block(&block(BlockKind::Wedge, [40.0, 30.0, 27.0], yaw), &CAMERAS);
            assert!(!j.graspable, "yaw {yaw}: {j:?}");
            j.reason.unwrap()
        };
        // A triangle in view: its top edge is the slope.
        for yaw in [90.0, -90.0, 30.0, -45.0] {
            assert!(reason(yaw).starts_with("its top edges slope 34°, more than 30°"), "yaw {yaw}: {}", reason(yaw));
        }
        // The vertical back towards the cameras as well: its only parallel edge behind is the
        // slope's foot, 27 mm down, where the 25 mm fingers do not reach.
        assert!(reason(0.0).contains("behind its +x face the nearest parallel edge is 27 mm lower, past the fingers' 25 mm"), "{}", reason(0.0));
        // Only the slope in view (the triangles edge-on): no vertical face to grasp.
        assert_eq!(reason(180.0), "none of its faces is within 20° of vertical");
        // A gentle wedge (25° slope) is graspable across its triangles.
        let gentle = judge_block(&block(BlockKind::Wedge, [45.0, 30.0, 21.0], 90.0), &CAMERAS);
        assert!(gentle.graspable, "{gentle:?}");
    }

    #[test]
    fn a_bar_too_wide_every_way_is_not_graspable() {
        // 60 x 60 mm footprint: wider than the 50 mm jaws across either pair of faces.
        let j = judge_block(&block(BlockKind::Bar, [60.0, 60.0, 30.0], 20.0), &CAMERAS);
        assert!(!j.graspable);
        assert!(j.reason.as_deref().unwrap().contains("60 mm wide, more than the jaws' 50 mm"), "{j:?}");
        // Narrow one way: graspable.
        assert!(judge_block(&block(BlockKind::Bar, [60.0, 40.0, 30.0], 20.0), &CAMERAS).graspable);
    }

    #[test]
    fn l_blocks_in_the_gripper_range_are_graspable() {
        for yaw in (0..360).step_by(30) {
            let j = judge_block(&block(BlockKind::LBlock, [40.0, 30.0, 40.0], f64::from(yaw)), &CAMERAS);
            assert!(j.graspable, "yaw {yaw}: {j:?}");
        }
    }
}

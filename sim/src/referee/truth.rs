//! Ground truth, for judging and testing only (never published on the daemon's services):
//! block poses, the camera matrices, the image polygon and visible pixel area of every block
//! face and of the gripper plate in both views, the blocks' 3-D edges, and the calibration
//! cage's projections.
//!
//! Polygons are projected with [`Camera::project`], the same matrix the renderer's clip
//! transform is derived from, so they lie on the rendered edges. A polygon is the whole face
//! projected (occlusion is not clipped away); `visible_px` counts the pixels where that face
//! is what the camera sees (from the renderer's face-id pass), so "visible faces larger than
//! 400 px in both views" is `views.iter().all(|v| v.visible_px > 400)`.

use glam::{DAffine3, DVec3};
use serde::Serialize;

use crate::pointer::PointerTruth;
use crate::render::camera::{Camera, CameraInfo, signed_area_px2};
use crate::render::cell_scene::{PLATE_NORMAL_IN_PALM, plate_corners_in_palm};
use crate::render::scene::{ID_PLATE, block_face_id, decode_block_face};
use crate::simulator::Simulator;

/// One block's pose.
#[derive(Debug, Clone, Serialize)]
pub struct BlockTruth {
    pub name: String,
    pub kind: String,
    pub size_mm: [f64; 3],
    /// Origin of the block frame (centre of its bounding box), robot frame.
    pub position_m: [f64; 3],
    /// Rotation block → robot, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Rotation about z of the block's x axis, degrees.
    pub yaw_deg: f64,
    /// Height of the block origin above its resting height, millimetres.
    pub lift_mm: f64,
}

/// A face in one view.
#[derive(Debug, Clone, Serialize)]
pub struct FaceView {
    /// The face's corners projected to pixels (pixel centres at integers), in the face's
    /// corner order; empty if a corner is behind the camera.
    pub polygon_px: Vec<[f64; 2]>,
    /// Area of that polygon, pixels².
    pub projected_area_px: f64,
    /// The face turns towards the camera.
    pub front_facing: bool,
    /// Pixels where this face is what the camera sees.
    pub visible_px: u32,
}

/// One planar face of a block.
#[derive(Debug, Clone, Serialize)]
pub struct FaceTruth {
    /// Index into `blocks`.
    pub block: usize,
    /// Index of the face within its block, and its name (`top`, `+x`, `slope`, ...).
    pub face: usize,
    pub name: String,
    /// Id in the renderer's face-id pass.
    pub id: u32,
    /// Corners in the robot frame.
    pub corners_m: Vec<[f64; 3]>,
    /// Outward unit normal in the robot frame.
    pub normal: [f64; 3],
    /// Left and right view.
    pub views: [FaceView; 2],
}

/// A 3-D edge of a block (where two faces meet).
#[derive(Debug, Clone, Serialize)]
pub struct EdgeTruth {
    pub block: usize,
    pub a_m: [f64; 3],
    pub b_m: [f64; 3],
    /// The two faces that meet here (face indices within the block).
    pub faces: [usize; 2],
    /// Endpoints projected into the left and right view.
    pub views_px: [[[f64; 2]; 2]; 2],
    /// At least one of its faces is visible in the view.
    pub visible: [bool; 2],
}

/// The gripper as the cameras see it.
#[derive(Debug, Clone, Serialize)]
pub struct GripperTruth {
    pub tool_m: [f64; 3],
    pub yaw_deg: f64,
    pub width_mm: f64,
    /// The plate's light rectangle (the tracked face): corners in the robot frame ...
    pub plate_corners_m: [[f64; 3]; 4],
    /// ... and per view.
    pub plate_views: [FaceView; 2],
}

/// Everything `truth.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct GroundTruth {
    pub scenario: String,
    pub frame: u64,
    pub time_s: f64,
    pub cameras: [CameraInfo; 2],
    /// Index of the task's target block.
    pub target: usize,
    pub blocks: Vec<BlockTruth>,
    pub faces: Vec<FaceTruth>,
    pub edges: Vec<EdgeTruth>,
    pub gripper: GripperTruth,
    /// The operator's pointing gesture, if the scenario has one (`[pointer]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pointer: Option<PointerTruth>,
}

/// The calibration cage (`cage.json`).
#[derive(Debug, Clone, Serialize)]
pub struct CageTruth {
    pub points_m: Vec<[f64; 3]>,
    pub left_px: Vec<[f64; 2]>,
    pub right_px: Vec<[f64; 2]>,
}

fn polygon_view(camera: &Camera, corners: &[DVec3], normal: DVec3, visible_px: u32) -> FaceView {
    let projected: Option<Vec<[f64; 2]>> = corners.iter().map(|&c| camera.project(c)).collect();
    let polygon_px = projected.unwrap_or_default();
    let centre = corners.iter().copied().sum::<DVec3>() / corners.len().max(1) as f64;
    FaceView {
        projected_area_px: signed_area_px2(&polygon_px).abs(),
        front_facing: normal.dot(camera.position_m - centre) > 0.0,
        polygon_px,
        visible_px,
    }
}

/// Pixel counts per face id in each view of a face-id image (left rows, then right rows).
fn count_ids(ids: &[u32], view_len: usize) -> [std::collections::HashMap<u32, u32>; 2] {
    let mut counts = [std::collections::HashMap::new(), std::collections::HashMap::new()];
    for (v, chunk) in ids.chunks(view_len.max(1)).take(2).enumerate() {
        for &id in chunk {
            if id != 0 {
                *counts[v].entry(id).or_insert(0) += 1;
            }
        }
    }
    counts
}

fn arr(v: DVec3) -> [f64; 3] {
    v.to_array()
}

impl GroundTruth {
    /// Ground truth of the simulator's current state; `ids` is the renderer's face-id image
    /// of the same moment (see [`crate::render::Renderer::render_ids`]).
    pub fn compute(sim: &Simulator, ids: &[u32]) -> Self {
        let cams = &sim.events.cameras;
        let view_len = (cams[0].width_px * cams[0].height_px) as usize;
        let counts = count_ids(ids, view_len);
        let visible = |view: usize, id: u32| counts[view].get(&id).copied().unwrap_or(0);

        let mut blocks = Vec::new();
        let mut faces = Vec::new();
        let mut edges = Vec::new();
        for (bi, block) in sim.world.blocks.iter().enumerate() {
            let (_, pose): (&str, DAffine3) = sim.block_pose(bi);
            let rot = pose.matrix3;
            let corners: Vec<DVec3> = block.shape.corners.iter().map(|&c| pose.transform_point3(c)).collect();
            blocks.push(BlockTruth {
                name: block.name.clone(),
                kind: block.shape.kind.name().to_string(),
                size_mm: (block.shape.size_m * 1e3).to_array(),
                position_m: arr(pose.translation),
                rotation: [rot.row(0).to_array(), rot.row(1).to_array(), rot.row(2).to_array()],
                yaw_deg: rot.x_axis.y.atan2(rot.x_axis.x).to_degrees(),
                lift_mm: (pose.translation.z - block.rest_z_m) * 1e3,
            });
            for (fi, face) in block.shape.faces.iter().enumerate() {
                let pts: Vec<DVec3> = face.corners.iter().map(|&c| corners[c]).collect();
                let normal = rot * face.normal;
                let id = block_face_id(bi, fi);
                faces.push(FaceTruth {
                    block: bi,
                    face: fi,
                    name: face.name.to_string(),
                    id,
                    corners_m: pts.iter().map(|&p| arr(p)).collect(),
                    normal: arr(normal),
                    views: [0, 1].map(|v| polygon_view(&cams[v], &pts, normal, visible(v, id))),
                });
            }
            for e in &block.shape.edges {
                let (a, b) = (corners[e.a], corners[e.b]);
                let proj = |v: usize, p: DVec3| cams[v].project(p).unwrap_or([f64::NAN; 2]);
                let seen = |v: usize| e.faces.iter().any(|&f| visible(v, block_face_id(bi, f)) > 0);
                edges.push(EdgeTruth {
                    block: bi,
                    a_m: arr(a),
                    b_m: arr(b),
                    faces: e.faces,
                    views_px: [[proj(0, a), proj(0, b)], [proj(1, a), proj(1, b)]],
                    visible: [seen(0), seen(1)],
                });
            }
        }

        let reading = sim.arm_reading();
        let (palm_pos, palm_rot) = sim.world.body_pose(sim.world.arm.links[4]);
        let plate = plate_corners_in_palm().map(|c| palm_pos + palm_rot * c);
        let plate_normal = palm_rot * PLATE_NORMAL_IN_PALM;
        let gripper = GripperTruth {
            tool_m: arr(reading.tool_m),
            yaw_deg: reading.yaw_rad().to_degrees(),
            width_mm: reading.gripper_width_m() * 1e3,
            plate_corners_m: plate.map(arr),
            plate_views: [0, 1].map(|v| polygon_view(&cams[v], &plate, plate_normal, visible(v, ID_PLATE))),
        };
        debug_assert!(counts.iter().all(|c| c.keys().all(|&id| id >= ID_PLATE || decode_block_face(id).is_some())));

        Self {
            scenario: sim.scenario.name.clone(),
            frame: sim.frames(),
            time_s: sim.now_ns() as f64 * 1e-9,
            cameras: [cams[0].info("left"), cams[1].info("right")],
            target: sim.target_index(),
            blocks,
            faces,
            edges,
            gripper,
            pointer: sim.pointer.as_ref().map(|p| p.truth(cams, sim.now_ns())),
        }
    }
}

impl CageTruth {
    /// The scenario's cage points and where the current cameras see them.
    pub fn compute(sim: &Simulator) -> Self {
        let cams = &sim.events.cameras;
        let pts: Vec<DVec3> = sim.scenario.cage.points_m.iter().map(|p| DVec3::from_array(*p)).collect();
        let proj = |c: &Camera| pts.iter().map(|&p| c.project(p).unwrap_or([f64::NAN; 2])).collect();
        Self { points_m: pts.iter().map(|&p| arr(p)).collect(), left_px: proj(&cams[0]), right_px: proj(&cams[1]) }
    }
}

//! Watching the daemon from ground truth: the simulator reads the daemon's telemetry (never
//! the other way round) and judges what it claims. When the daemon's telemetry first reports
//! that the servo converged (phase `grasp` after `servo`), it measures the coplanarity the
//! servo achieved with the hinted facet (the thesis's servo makes a surface of the gripper
//! coplanar with the target facet; the grasp then follows open-loop):
//!
//! - `final_plane_error_mm`: distance of the gripper plate's centre from the target facet's
//!   plane (the plate is the surface made coplanar; 0 is perfect);
//! - `final_angle_error_deg`: angle between the gripper plate's normal (the jaws' closing
//!   axis) and the target facet's normal.
//!
//! When the jaws start to close (the daemon's reason says `grasp: closing`; else at phase
//! `lift`) it measures the grasp itself:
//! `grasp_plane_error_mm`, the distance of the **jaw-centre plane** (through the tool point,
//! normal to the closing axis) from the block's mid-plane parallel to the facet (halfway
//! between the facet and the face opposite it), and the tool point's lateral offset from
//! the facet's centre.
//!
//! The facet judged is the one the daemon's target trackers were put on: when they first
//! appear in telemetry, their outlines are matched against every block face's projection
//! (ground truth) in both views ([`DaemonWatch::targeted`]: which block and face, and whether
//! it is the task's target). With an operator hint that is the hinted facet; when the daemon
//! plans its own grasp it is whatever the planner chose.
//!
//! While the daemon plans (phase `plan`), it records how many frames the planner worked
//! (telemetry `planning` = 1) and how far the gripper trackers' update counts rose
//! meanwhile ([`PlanWatch`]): the daemon must keep tracking while it plans.
//!
//! It also records when each phase first appeared, when the daemon stopped or failed (and
//! why), the first `Stop` command, and, when the scenario has an occluder, the first frame on
//! which an occluder hides the target facet (fewer than half of its pixels at hint time
//! visible in either view while an occluder crosses the scene), so a test can tell how quickly the daemon reacted.
//!
//! And it checks every command against the telemetry of the frame it answered
//! ([`crate::referee::blind_moves`]): a move answering a frame on which a tracker the daemon's
//! phase works with was not tracking is counted in `moves_on_lost_track` (issue 18).

use glam::DVec3;
use handeye_wire::{CommandKind, Phase, RobotCommand, Telemetry};
use serde::{Deserialize, Serialize};

use crate::referee::blind_moves::BlindMoves;
use crate::referee::hint::HintFacet;
use crate::render::cell_scene::{PLATE_NORMAL_IN_PALM, plate_corners_in_palm};
use crate::simulator::Simulator;

/// The gripper's placement when the servo converged, from ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConvergedPlacement {
    pub frame: u64,
    pub final_plane_error_mm: f64,
    pub final_angle_error_deg: f64,
    /// Signed distance of the plate centre from the facet plane along its normal, mm.
    pub plate_offset_mm: f64,
    /// Signed distance of the tool point from the block's mid-plane along the facet normal, mm.
    pub jaw_plane_offset_mm: f64,
    /// Tool point's horizontal offset within the facet plane from the facet's centre, mm.
    pub lateral_error_mm: f64,
    /// Tool point height above the table, mm.
    pub tool_z_mm: f64,
}

/// The facet the daemon's target trackers were (last) put on, from ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetedFacet {
    pub frame: u64,
    pub block: String,
    pub face: String,
    /// Whether that block is the task's target.
    pub is_task_target: bool,
    /// Mean distance of the trackers' corners from the face's projected outline, px (both
    /// views): how well the daemon placed them.
    pub outline_error_px: f64,
}

/// The daemon's telemetry during its plan phase.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanWatch {
    /// Telemetry samples with phase `plan`.
    pub frames: u64,
    /// ... of which with `planning` = 1 (the planner busy).
    pub planning_frames: u64,
    /// Gripper tracker updates (left, right) from the first to the last `planning` frame.
    pub gripper_updates_while_planning: [u64; 2],
    /// Largest jump of a gripper tracker's update count between consecutive `planning`
    /// frames (1 when it updated on every frame).
    pub max_update_step: u64,
    /// Simulated time from the first to the last `planning` frame, s.
    pub planning_window_s: f64,
    /// Gripper tracker updates per second of simulated time over that window (left,
    /// right): the camera frame rate when the trackers kept up with every frame, 0 for a
    /// tracker frozen while the planner works.
    pub gripper_update_rate_hz: [f64; 2],
    /// The camera frame rate, for comparison, Hz.
    pub frame_rate_hz: f64,
    #[serde(skip)]
    first_frame: Option<u64>,
    #[serde(skip)]
    first: Option<[u64; 2]>,
    #[serde(skip)]
    last: Option<[u64; 2]>,
}

/// What the simulator saw of the daemon (the `daemon` part of [`super::report::SimReport`];
/// read back by `handeye run`, which gets only the serialised fields: the judging state is
/// skipped).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonWatch {
    /// First frame on which each phase was reported, by name, in order of appearance.
    pub phases: Vec<(String, u64)>,
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub converged: Option<ConvergedPlacement>,
    /// The placement when the jaws started closing.
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub grasped: Option<ConvergedPlacement>,
    /// First frame with phase `stopped` or `failed`, and the reason the daemon gave.
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub stopped_frame: Option<u64>,
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub stop_reason: Option<String>,
    /// First frame answered by a `Stop` command.
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub first_stop_command_frame: Option<u64>,
    /// First frame on which the target facet was hidden (occluder scenarios only).
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub target_hidden_frame: Option<u64>,
    /// Move commands answering a frame on which a tracker the phase used was not tracking
    /// (must stay 0), and the first such frame.
    #[serde(default)]
    pub moves_on_lost_track: u64,
    #[serde(default)]
    pub first_move_on_lost_track_frame: Option<u64>,
    /// Telemetry samples read.
    pub telemetry: u64,
    /// The facet the target trackers were put on.
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub targeted: Option<TargetedFacet>,
    pub plan: PlanWatch,
    #[serde(skip)]
    facet: Option<HintFacet>,
    #[serde(skip)]
    target_present: bool,
    #[serde(skip)]
    last_phase: Option<u32>,
    #[serde(skip)]
    facet_px_at_hint: Option<[u32; 2]>,
    #[serde(skip)]
    blind: BlindMoves,
}

impl DaemonWatch {
    /// Judge placements against `facet` (the one the operator hint described).
    pub fn set_facet(&mut self, facet: HintFacet) {
        self.facet = Some(facet);
    }

    pub fn facet(&self) -> Option<HintFacet> {
        self.facet
    }

    /// Pixels of the target facet visible at hint time, per view (the occlusion baseline).
    pub fn set_facet_baseline(&mut self, px: [u32; 2]) {
        self.facet_px_at_hint = Some(px);
    }

    pub fn wants_visibility(&self) -> bool {
        self.facet_px_at_hint.is_some() && self.target_hidden_frame.is_none()
    }

    /// The target facet's visible pixels now (face-id pass), per view.
    pub fn visibility(&mut self, frame: u64, px: [u32; 2]) {
        if let Some(base) = self.facet_px_at_hint
            && self.target_hidden_frame.is_none()
            && (0..2).any(|v| 2 * px[v] < base[v])
        {
            self.target_hidden_frame = Some(frame);
        }
    }

    /// A command that answered or arrived during `frame`.
    pub fn command(&mut self, frame: u64, cmd: &RobotCommand) {
        if cmd.kind == CommandKind::Stop as u32 && self.first_stop_command_frame.is_none() {
            self.first_stop_command_frame = Some(frame);
        }
        self.blind.command(cmd);
        self.moves_on_lost_track = self.blind.count;
        self.first_move_on_lost_track_frame = self.blind.first_frame;
    }

    /// A telemetry sample read while the simulator was at `frame` (before stepping past it).
    pub fn telemetry(&mut self, sim: &Simulator, frame: u64, t: &Telemetry) {
        self.telemetry += 1;
        let Some(phase) = Phase::from_u32(t.phase) else { return };
        self.blind.telemetry(t);
        self.moves_on_lost_track = self.blind.count;
        self.first_move_on_lost_track_frame = self.blind.first_frame;
        if phase == Phase::Plan {
            self.plan.frames += 1;
            if t.planning == 1 {
                self.plan.planning_frames += 1;
                let now = [t.tracker_updates[0], t.tracker_updates[1]];
                if let Some(last) = self.plan.last {
                    let step = (0..2).map(|k| now[k].saturating_sub(last[k])).max().unwrap_or(0);
                    self.plan.max_update_step = self.plan.max_update_step.max(step);
                }
                let first = *self.plan.first.get_or_insert(now);
                let first_frame = *self.plan.first_frame.get_or_insert(frame);
                self.plan.last = Some(now);
                let updates = [now[0].saturating_sub(first[0]), now[1].saturating_sub(first[1])];
                self.plan.gripper_updates_while_planning = updates;
                let fps = f64::from(sim.scenario.render.frame_rate_hz);
                self.plan.frame_rate_hz = fps;
                self.plan.planning_window_s = frame.saturating_sub(first_frame) as f64 / fps;
                if self.plan.planning_window_s > 0.0 {
                    self.plan.gripper_update_rate_hz = updates.map(|u| u as f64 / self.plan.planning_window_s);
                }
            }
        }
        // Identified when the target trackers appear, and again if they are put on another
        // facet (the daemon may give a target up for the plan's next grasp site).
        let present = t.tracker_state[2] != 0 && t.tracker_state[3] != 0;
        let appeared = present && !self.target_present;
        self.target_present = present;
        if appeared {
            let poly = |i: usize| -> Vec<[f64; 2]> {
                t.tracker_corners_px[i].iter().filter(|c| c[0].is_finite() && c[1].is_finite()).map(|c| [f64::from(c[0]), f64::from(c[1])]).collect()
            };
            let (l, r) = (poly(2), poly(3));
            if l.len() >= 3
                && r.len() >= 3
                && let Some((facet, error)) = identify_facet(sim, &l, &r)
            {
                let b = &sim.world.blocks[facet.block];
                self.targeted = Some(TargetedFacet {
                    frame,
                    block: b.name.clone(),
                    face: b.shape.faces[facet.face].name.to_string(),
                    is_task_target: facet.block == sim.target_index(),
                    outline_error_px: error,
                });
                // Judge the placement against the facet the daemon actually works on.
                self.facet = Some(facet);
            }
        }
        if self.last_phase != Some(t.phase) {
            if !self.phases.iter().any(|(n, _)| n == phase.name()) {
                self.phases.push((phase.name().to_string(), frame));
            }
            if phase == Phase::Grasp && self.last_phase == Some(Phase::Servo as u32) && self.converged.is_none() {
                self.converged = self.placement(sim, frame);
            }
            if phase == Phase::Lift && self.grasped.is_none() {
                self.grasped = self.placement(sim, frame);
            }
            if matches!(phase, Phase::Stopped | Phase::Failed) && self.stopped_frame.is_none() {
                self.stopped_frame = Some(frame);
                self.stop_reason = Some(t.reason_text());
            }
            self.last_phase = Some(t.phase);
        }
        // The jaws are about to close (the daemon says so in its reason): where they are now
        // is the grasp (once closed, the jaws centre the block and hide any error).
        if phase == Phase::Grasp && self.grasped.is_none() && t.reason_text().starts_with("grasp: closing") {
            self.grasped = self.placement(sim, frame);
        }
    }

    fn placement(&self, sim: &Simulator, frame: u64) -> Option<ConvergedPlacement> {
        let facet = self.facet?;
        let b = &sim.world.blocks[facet.block];
        let (_, pose) = sim.block_pose(facet.block);
        let face = &b.shape.faces[facet.face];
        let n = (pose.matrix3 * face.normal).normalize();
        let pts: Vec<DVec3> = face.corners.iter().map(|&c| pose.transform_point3(b.shape.corners[c])).collect();
        let centre = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
        let mid = centre - n * (facet.depth_m / 2.0);
        let reading = sim.arm_reading();
        let tool = reading.tool_m;
        let plate_normal = (reading.palm_rot * PLATE_NORMAL_IN_PALM).normalize();
        let (palm_pos, palm_rot) = sim.world.body_pose(sim.world.arm.links[4]);
        let plate_centre = plate_corners_in_palm().iter().map(|&c| palm_pos + palm_rot * c).sum::<DVec3>() / 4.0;
        let plate_offset = n.dot(plate_centre - centre);
        let offset = n.dot(tool - mid);
        let horizontal = n.cross(DVec3::Z).normalize_or_zero();
        Some(ConvergedPlacement {
            frame,
            final_plane_error_mm: plate_offset.abs() * 1e3,
            final_angle_error_deg: plate_normal.dot(n).abs().clamp(0.0, 1.0).acos().to_degrees(),
            plate_offset_mm: plate_offset * 1e3,
            jaw_plane_offset_mm: offset * 1e3,
            lateral_error_mm: horizontal.dot(tool - centre) * 1e3,
            tool_z_mm: tool.z * 1e3,
        })
    }
}

/// Distance of point `p` from the closed polygon's outline.
fn outline_distance(poly: &[[f64; 2]], p: [f64; 2]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let l2 = dx * dx + dy * dy;
            let t = if l2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0) } else { 0.0 };
            (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
        })
        .fold(f64::INFINITY, f64::min)
}

/// The block face whose projected outline best fits the tracked polygons (both views, pixel
/// centres at integers, as the daemon's trackers report them): the smallest mean distance
/// of the tracked corners from the face's outline, over faces facing both cameras. With the
/// face, that mean distance in pixels. The facet's depth is the block's extent behind it.
pub fn identify_facet(sim: &Simulator, left: &[[f64; 2]], right: &[[f64; 2]]) -> Option<(HintFacet, f64)> {
    let cams = &sim.events.cameras;
    let mut best: Option<(HintFacet, f64)> = None;
    for (bi, b) in sim.world.blocks.iter().enumerate() {
        let (_, pose) = sim.block_pose(bi);
        let corners: Vec<DVec3> = b.shape.corners.iter().map(|&c| pose.transform_point3(c)).collect();
        for (fi, face) in b.shape.faces.iter().enumerate() {
            let n = (pose.matrix3 * face.normal).normalize();
            let pts: Vec<DVec3> = face.corners.iter().map(|&c| corners[c]).collect();
            let centre = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
            if cams.iter().any(|cam| n.dot(cam.position_m - centre) <= 0.0) {
                continue;
            }
            let mut error = 0.0;
            let mut count = 0;
            for (cam, tracked) in cams.iter().zip([left, right]) {
                let Some(proj) = pts.iter().map(|&p| cam.project(p)).collect::<Option<Vec<[f64; 2]>>>() else { continue };
                for &c in tracked {
                    error += outline_distance(&proj, c);
                    count += 1;
                }
            }
            if count == 0 {
                continue;
            }
            let error = error / count as f64;
            if best.as_ref().is_none_or(|(_, e)| error < *e) {
                let depth_m = corners.iter().map(|&c| n.dot(centre - c)).fold(0.0, f64::max);
                best = Some((HintFacet { block: bi, face: fi, normal: n, depth_m }, error));
            }
        }
    }
    best
}


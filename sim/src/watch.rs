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
//! It also records when each phase first appeared, when the daemon stopped or failed (and
//! why), the first `Stop` command, and, when the scenario has an occluder, the first frame on
//! which an occluder hides the target facet (fewer than half of its pixels at hint time
//! visible in either view while an occluder crosses the scene), so a test can tell how quickly the daemon reacted.

use glam::DVec3;
use handeye_wire::{CommandKind, Phase, RobotCommand, Telemetry};
use serde::Serialize;

use crate::hint::HintFacet;
use crate::simulator::Simulator;

/// The gripper's placement when the servo converged, from ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
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

/// What the simulator saw of the daemon (serialised into the sim's verdict).
#[derive(Debug, Clone, Default, Serialize)]
pub struct DaemonWatch {
    /// First frame on which each phase was reported, by name, in order of appearance.
    pub phases: Vec<(String, u64)>,
    pub converged: Option<ConvergedPlacement>,
    /// The placement when the jaws started closing.
    pub grasped: Option<ConvergedPlacement>,
    /// First frame with phase `stopped` or `failed`, and the reason the daemon gave.
    pub stopped_frame: Option<u64>,
    pub stop_reason: Option<String>,
    /// First frame answered by a `Stop` command.
    pub first_stop_command_frame: Option<u64>,
    /// First frame on which the target facet was hidden (occluder scenarios only).
    pub target_hidden_frame: Option<u64>,
    /// Telemetry samples read.
    pub telemetry: u64,
    #[serde(skip)]
    facet: Option<HintFacet>,
    #[serde(skip)]
    last_phase: Option<u32>,
    #[serde(skip)]
    facet_px_at_hint: Option<[u32; 2]>,
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
    }

    /// A telemetry sample read while the simulator was at `frame` (before stepping past it).
    pub fn telemetry(&mut self, sim: &Simulator, frame: u64, t: &Telemetry) {
        self.telemetry += 1;
        let Some(phase) = Phase::from_u32(t.phase) else { return };
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
        let plate_normal = (reading.palm_rot * crate::scene::PLATE_NORMAL_IN_PALM).normalize();
        let (palm_pos, palm_rot) = sim.world.body_pose(sim.world.arm.links[4]);
        let plate_centre = crate::scene::plate_corners_in_palm().iter().map(|&c| palm_pos + palm_rot * c).sum::<DVec3>() / 4.0;
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

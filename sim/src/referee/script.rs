//! A scripted pick that reads the block's pose from ground truth. It is a **physics check**
//! (can the arm and gripper pick this block at all?) and a demo driver, never a vision
//! result: the daemon must find blocks with its cameras.
//!
//! Sequence: open and move above the block → descend → close → wait for the jaws → lift →
//! hold. It sends one command per frame (a `Hold` while waiting, which also keeps the
//! controller's watchdog fed), as a lockstep daemon would.

use glam::DVec3;
use handeye_wire::{CommandKind, GripperCommand, RobotCommand, WIRE_VERSION, robot_flags};

use crate::cell::kinematics::wrap_angle;
use crate::scenario::BlockKind;
use crate::simulator::Simulator;

/// Height of the tool point (finger tips) above the table when grasping, metres.
pub const GRASP_TOOL_Z_M: f64 = 0.008;
/// Clearance above the block's top for the approach, metres.
pub const APPROACH_CLEARANCE_M: f64 = 0.05;

/// Where the scripted pick is (its own steps, not the daemon's `handeye_wire::Phase`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PickPhase {
    Approach,
    Descend,
    Close,
    Lift,
    Hold,
    Done,
    /// The controller refused a move or faulted.
    Failed,
}

/// The scripted pick of one block.
#[derive(Debug, Clone)]
pub struct GroundTruthPick {
    pub block: usize,
    pub phase: PickPhase,
    /// Tool pose at the grasp.
    pub grasp_m: DVec3,
    pub grasp_yaw_rad: f64,
    lift_m: f64,
    hold_ns: u64,
    phase_start_ns: u64,
    sent_move: bool,
    seq: u64,
}

impl GroundTruthPick {
    /// Plans a top-down grasp of block `block` from its true pose: the fingers close across
    /// the block's two parallel faces that are closest together (for wedges and L-blocks the
    /// two end faces of the prism), lift by `lift_m`, then hold for `hold_s`.
    pub fn new(sim: &Simulator, block: usize, lift_m: f64, hold_s: f64) -> Self {
        let b = &sim.world.blocks[block];
        let (_, pose) = sim.block_pose(block);
        let size = b.shape.size_m;
        // Grasp point in the block frame: the centre, or the middle of the tall half for the
        // wedge and L-block (more contact area, closer to the centre of mass).
        let local = match b.shape.kind {
            BlockKind::Wedge | BlockKind::LBlock => DVec3::new(size.x / 4.0, 0.0, 0.0),
            _ => DVec3::ZERO,
        };
        let centre = pose.transform_point3(local);
        let x_axis = pose.matrix3.x_axis;
        let block_yaw = x_axis.y.atan2(x_axis.x);
        // Fingers close along the tool y axis, (-sin yaw, cos yaw): yaw = block yaw closes
        // them along the block's y; +90° along its x.
        let across_x = matches!(b.shape.kind, BlockKind::Cube | BlockKind::Bar) && size.x < size.y;
        let yaw = block_yaw + if across_x { std::f64::consts::FRAC_PI_2 } else { 0.0 };
        // The jaws are symmetric (yaw + 180° grasps the same faces) and a square footprint
        // can be grasped across either pair of sides (yaw + 90°): pick the equivalent yaw
        // nearest -90°, where the plate (on the palm's side, normal along the closing axis)
        // faces +x, the cameras of the shipped scenarios, and the wrist roll is mid-range.
        let square = (size.x - size.y).abs() < 1e-3 && matches!(b.shape.kind, BlockKind::Cube | BlockKind::Bar);
        let turns: &[f64] = if square { &[0.0, 0.5, 1.0, 1.5] } else { &[0.0, 1.0] };
        let target = -std::f64::consts::FRAC_PI_2;
        let yaw = turns
            .iter()
            .map(|k| target + wrap_angle(yaw + k * std::f64::consts::PI - target))
            .min_by(|a, b| (a - target).abs().total_cmp(&(b - target).abs()))
            .unwrap_or(yaw);
        Self {
            block,
            phase: PickPhase::Approach,
            grasp_m: DVec3::new(centre.x, centre.y, GRASP_TOOL_Z_M),
            grasp_yaw_rad: yaw,
            lift_m,
            hold_ns: crate::scenario::s_to_ns(hold_s),
            phase_start_ns: sim.now_ns(),
            sent_move: false,
            seq: 0,
        }
    }

    fn make(&mut self, kind: CommandKind, target: DVec3, yaw: f64, gripper: GripperCommand, frame_id: u64) -> RobotCommand {
        self.seq += 1;
        RobotCommand {
            version: WIRE_VERSION,
            kind: kind as u32,
            seq: self.seq,
            frame_id,
            time_ns: 0,
            target_m: target.as_vec3().to_array(),
            yaw_rad: yaw as f32,
            speed_limit_mps: 0.0,
            gripper: gripper as u32,
        }
    }

    fn next_phase(&mut self, phase: PickPhase, now_ns: u64) {
        self.phase = phase;
        self.phase_start_ns = now_ns;
        self.sent_move = false;
    }

    /// The command for the current frame (`frame_id` is echoed, as a lockstep daemon does).
    pub fn next_command(&mut self, sim: &mut Simulator, frame_id: u64) -> RobotCommand {
        let state = sim.robot_state();
        let now = sim.now_ns();
        let hold = |s: &mut Self| s.make(CommandKind::Hold, DVec3::ZERO, 0.0, GripperCommand::Keep, frame_id);
        if state.flags & (robot_flags::FAULT | robot_flags::REJECTED) != 0 && self.phase != PickPhase::Done {
            self.phase = PickPhase::Failed;
        }
        let arrived = state.flags & robot_flags::ARRIVED != 0;
        let top_z = sim.world.blocks[self.block].shape.size_m.z;
        let above = DVec3::new(self.grasp_m.x, self.grasp_m.y, top_z + APPROACH_CLEARANCE_M);
        let elapsed = now.saturating_sub(self.phase_start_ns);
        match self.phase {
            PickPhase::Approach | PickPhase::Descend | PickPhase::Lift => {
                if !self.sent_move {
                    self.sent_move = true;
                    let (target, gripper) = match self.phase {
                        PickPhase::Approach => (above, GripperCommand::Open),
                        PickPhase::Descend => (self.grasp_m, GripperCommand::Keep),
                        _ => (self.grasp_m + DVec3::Z * self.lift_m, GripperCommand::Keep),
                    };
                    return self.make(CommandKind::MoveTo, target, self.grasp_yaw_rad, gripper, frame_id);
                }
                if arrived {
                    let next = match self.phase {
                        PickPhase::Approach => PickPhase::Descend,
                        PickPhase::Descend => PickPhase::Close,
                        _ => PickPhase::Hold,
                    };
                    self.next_phase(next, now);
                    if next == PickPhase::Close {
                        self.sent_move = true;
                        return self.make(CommandKind::Hold, DVec3::ZERO, 0.0, GripperCommand::Close, frame_id);
                    }
                }
                hold(self)
            }
            PickPhase::Close => {
                // Let the jaws close and settle (at least 0.5 s).
                if elapsed >= 500_000_000 && state.flags & robot_flags::GRIPPER_SETTLED != 0 {
                    self.next_phase(PickPhase::Lift, now);
                }
                hold(self)
            }
            PickPhase::Hold => {
                if elapsed >= self.hold_ns {
                    self.next_phase(PickPhase::Done, now);
                }
                hold(self)
            }
            PickPhase::Done | PickPhase::Failed => hold(self),
        }
    }
}

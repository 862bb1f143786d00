//! The simulated robot controller, driven the way a daemon drives it: one command per frame.
//! Accuracy is measured on the physical finger bodies, not on what the controller reports.

use handeye_sim::glam::DVec3;
use handeye_sim::cell::arm::FINGER_TRAVEL_M;
use handeye_sim::cell::kinematics::{FINGER_LENGTH_M, wrap_angle};
use handeye_sim::{Scenario, Simulator};
use handeye_wire::{CommandKind, GripperCommand, NO_FRAME, RejectReason, RobotCommand, WIRE_VERSION, robot_flags};

fn scenario_path(name: &str) -> String {
    format!("{}/scenarios/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn sim() -> Simulator {
    Simulator::new(Scenario::load(scenario_path("pick_cube.toml")).expect("scenario")).expect("simulator")
}

/// pick_cube with the cube moved out of the arm's way (to the table's far corner), so
/// targets low over the table are free.
fn sim_clear() -> Simulator {
    let mut s = Scenario::load(scenario_path("pick_cube.toml")).expect("scenario");
    s.blocks[0].position_m = [0.85, 0.42];
    Simulator::new(s).expect("simulator")
}

struct Driver {
    seq: u64,
}

impl Driver {
    fn cmd(&mut self, kind: CommandKind, target: [f32; 3], yaw: f32, speed: f32, gripper: GripperCommand) -> RobotCommand {
        self.seq += 1;
        RobotCommand {
            version: WIRE_VERSION,
            kind: kind as u32,
            seq: self.seq,
            frame_id: NO_FRAME,
            time_ns: 0,
            target_m: target,
            yaw_rad: yaw,
            speed_limit_mps: speed,
            gripper: gripper as u32,
        }
    }

    fn hold(&mut self) -> RobotCommand {
        self.cmd(CommandKind::Hold, [0.0; 3], 0.0, 0.0, GripperCommand::Keep)
    }

    /// Sends `Hold` every frame until `done(state)` or `timeout_s`; returns frames taken.
    fn run_until(&mut self, sim: &mut Simulator, timeout_s: f64, done: impl Fn(u32) -> bool) -> Option<u64> {
        let frames = (timeout_s * 30.0) as u64;
        for f in 0..frames {
            let c = self.hold();
            sim.command(&c);
            sim.step_frame();
            if done(sim.robot_state().flags) {
                return Some(f);
            }
        }
        None
    }
}

/// Tool point and yaw from the finger bodies: the midpoint of the two fingers' inner tip
/// edges, and the direction from one finger to the other (the closing axis).
fn measured_tool(sim: &Simulator) -> (DVec3, f64) {
    let tip = |i: usize| {
        let (pos, rot) = sim.world.body_pose(sim.world.arm.fingers[i]);
        pos + rot * DVec3::new(FINGER_LENGTH_M, 0.0, 0.0)
    };
    let (a, b) = (tip(0), tip(1));
    let axis = a - b;
    ((a + b) / 2.0, (-axis.x).atan2(axis.y))
}

#[test]
fn cartesian_targets_across_the_workspace_are_reached_within_1mm_and_1deg() {
    let mut sim = sim_clear();
    let mut d = Driver { seq: 0 };
    let mut worst_mm: f64 = 0.0;
    let mut worst_deg: f64 = 0.0;
    let mut count = 0;
    for (i, &x) in [0.25, 0.35, 0.47].iter().enumerate() {
        for (j, &y) in [-0.15, 0.0, 0.15].iter().enumerate() {
            for (k, &z) in [0.03, 0.16].iter().enumerate() {
                let yaw = [-0.6, 0.0, 0.5][(i + j + k) % 3];
                let c = d.cmd(CommandKind::MoveTo, [x as f32, y as f32, z as f32], yaw as f32, 0.25, GripperCommand::Keep);
                sim.command(&c);
                let target = DVec3::new(x, y, z);
                d.run_until(&mut sim, 8.0, |f| f & robot_flags::ARRIVED != 0)
                    .unwrap_or_else(|| panic!("target {target} yaw {yaw} not reached in 8 s; state {:?}", sim.robot_state()));
                let state = sim.robot_state();
                assert_eq!(state.flags & robot_flags::MOVING, 0, "arrived implies not moving");
                // At arrival and after holding half a second more.
                for check in 0..2 {
                    let (tool, tool_yaw) = measured_tool(&sim);
                    let err_mm = (tool - target).length() * 1e3;
                    let err_deg = wrap_angle(tool_yaw - yaw).to_degrees().abs();
                    assert!(err_mm <= 1.0, "target {target}: tool at {tool}, {err_mm:.3} mm off (check {check})");
                    assert!(err_deg <= 1.0, "target {target}: yaw off by {err_deg:.3}° (check {check})");
                    worst_mm = worst_mm.max(err_mm);
                    worst_deg = worst_deg.max(err_deg);
                    d.run_until(&mut sim, 0.5, |_| false);
                }
                // The controller's own report agrees with the fingers.
                let s = sim.robot_state();
                let reported = DVec3::new(f64::from(s.tool_pos_m[0]), f64::from(s.tool_pos_m[1]), f64::from(s.tool_pos_m[2]));
                assert!((reported - measured_tool(&sim).0).length() < 1e-4);
                count += 1;
            }
        }
    }
    assert_eq!(count, 18);
    eprintln!("worst error over {count} targets: {worst_mm:.3} mm, {worst_deg:.3}°");
}

#[test]
fn unreachable_and_malformed_commands_are_refused_with_a_reason_and_the_arm_stays() {
    let mut sim = sim();
    let mut d = Driver { seq: 0 };
    d.run_until(&mut sim, 0.3, |_| false);
    let (start, _) = measured_tool(&sim);
    let cases: [([f32; 3], f32, CommandKind, RejectReason); 6] = [
        ([0.9, 0.0, 0.1], 0.0, CommandKind::MoveTo, RejectReason::Unreachable), // beyond reach
        ([0.35, 0.0, -0.05], 0.0, CommandKind::MoveTo, RejectReason::Unreachable), // under the table
        ([0.02, 0.0, 0.2], 0.0, CommandKind::MoveTo, RejectReason::Unreachable), // inside the base
        ([0.35, 0.0, 0.1], 3.0, CommandKind::MoveTo, RejectReason::JointLimit), // wrist roll past 170°
        ([0.0, 0.0, 0.5], 0.0, CommandKind::MoveBy, RejectReason::Unreachable), // relative, too high
        ([f32::NAN, 0.0, 0.1], 0.0, CommandKind::MoveTo, RejectReason::Malformed),
    ];
    for (target, yaw, kind, why) in cases {
        let c = d.cmd(kind, target, yaw, 0.0, GripperCommand::Keep);
        sim.command(&c);
        sim.step_frame();
        let s = sim.robot_state();
        assert_ne!(s.flags & robot_flags::REJECTED, 0, "{kind:?} {target:?} must be refused");
        assert_eq!(RejectReason::from_u32(s.reject), Some(why), "{kind:?} {target:?}");
        assert_eq!(s.last_command_seq, c.seq);
    }
    // Unknown command kind and wrong wire version.
    let mut c = d.hold();
    c.kind = 99;
    sim.command(&c);
    assert_eq!(RejectReason::from_u32(sim.robot_state().reject), Some(RejectReason::Malformed));
    let mut c = d.hold();
    c.version = WIRE_VERSION + 1;
    sim.command(&c);
    assert_eq!(RejectReason::from_u32(sim.robot_state().reject), Some(RejectReason::Malformed));

    d.run_until(&mut sim, 0.5, |_| false);
    let (now, _) = measured_tool(&sim);
    assert!((now - start).length() < 1e-4, "refused commands must not move the arm ({start} -> {now})");
    // A good command afterwards is accepted and clears the refusal.
    let c = d.cmd(CommandKind::MoveBy, [0.02, 0.0, 0.0], 0.0, 0.0, GripperCommand::Keep);
    sim.command(&c);
    let s = sim.robot_state();
    assert_eq!(s.flags & robot_flags::REJECTED, 0);
    assert_eq!(RejectReason::from_u32(s.reject), Some(RejectReason::None));
}

#[test]
fn watchdog_stops_a_moving_arm_when_commands_stop() {
    let mut sim = sim();
    let mut d = Driver { seq: 0 };
    let (start, _) = measured_tool(&sim);
    let target = [0.45f32, 0.12, 0.05];
    let c = d.cmd(CommandKind::MoveTo, target, 0.0, 0.05, GripperCommand::Keep);
    sim.command(&c);
    // Fed for 0.5 s: moving.
    d.run_until(&mut sim, 0.5, |_| false);
    assert_ne!(sim.robot_state().flags & robot_flags::MOVING, 0);
    // Then silence: no commands at all.
    let mut stopped_at = None;
    for f in 0..60 {
        sim.step_frame();
        let s = sim.robot_state();
        if s.flags & robot_flags::WATCHDOG_STOP != 0 && stopped_at.is_none() {
            stopped_at = Some(f);
        }
    }
    let f = stopped_at.expect("watchdog must trip");
    // 200 ms = 6 frames at 30 Hz (plus the frame in which it trips).
    assert!((5..=8).contains(&f), "watchdog tripped after {f} frames");
    let s = sim.robot_state();
    assert_eq!(s.flags & robot_flags::MOVING, 0, "stopped arm reports not moving: {:#x}", s.flags);
    assert_eq!(s.flags & robot_flags::ARRIVED, 0, "it never got there");
    let (here, _) = measured_tool(&sim);
    let goal = DVec3::new(0.45, 0.12, 0.05);
    assert!((here - goal).length() > 0.1, "it stopped well short of the target");
    assert!((here - start).length() > 0.01, "it had been moving");
    // And it stays stopped.
    for _ in 0..30 {
        sim.step_frame();
    }
    assert!((measured_tool(&sim).0 - here).length() < 2e-4, "no creeping after a watchdog stop");
    // A fresh command resumes.
    let c = d.cmd(CommandKind::MoveTo, target, 0.0, 0.3, GripperCommand::Keep);
    sim.command(&c);
    d.run_until(&mut sim, 6.0, |f| f & robot_flags::ARRIVED != 0).expect("resumes after a new command");
    assert_eq!(sim.robot_state().flags & robot_flags::WATCHDOG_STOP, 0);
}

#[test]
fn stop_command_halts_and_a_blocked_arm_faults_until_cleared() {
    let mut sim = sim();
    let mut d = Driver { seq: 0 };
    let c = d.cmd(CommandKind::MoveTo, [0.45, -0.1, 0.1], 0.0, 0.1, GripperCommand::Keep);
    sim.command(&c);
    d.run_until(&mut sim, 0.4, |_| false);
    let c = d.cmd(CommandKind::Stop, [0.0; 3], 0.0, 0.0, GripperCommand::Keep);
    sim.command(&c);
    d.run_until(&mut sim, 0.5, |_| false);
    let s = sim.robot_state();
    assert_ne!(s.flags & robot_flags::STOPPED, 0);
    assert_eq!(s.flags & robot_flags::MOVING, 0);
    let here = measured_tool(&sim).0;
    d.run_until(&mut sim, 0.5, |_| false);
    assert!((measured_tool(&sim).0 - here).length() < 2e-4, "stopped means still");

    // Close the jaws and drive them down onto the cube's top: the arm is blocked, the
    // tracking error grows, and the controller faults and holds still.
    let (_, cube) = sim.block_pose(0);
    let (cx, cy) = (cube.translation.x as f32, cube.translation.y as f32);
    let c = d.cmd(CommandKind::MoveTo, [cx, cy, 0.10], 0.0, 0.0, GripperCommand::Close);
    sim.command(&c);
    d.run_until(&mut sim, 6.0, |f| f & robot_flags::ARRIVED != 0).expect("above the cube");
    let c = d.cmd(CommandKind::MoveTo, [cx, cy, 0.005], 0.0, 0.05, GripperCommand::Keep);
    sim.command(&c);
    d.run_until(&mut sim, 6.0, |f| f & robot_flags::FAULT != 0).expect("blocked arm must fault");
    let s = sim.robot_state();
    assert_eq!(s.fault, handeye_sim::cell::controller::fault::TRACKING);
    assert!(s.tool_pos_m[2] > 0.03, "the fingers stopped on the cube top, z = {}", s.tool_pos_m[2]);
    // While faulted, motion is refused; ClearFault is accepted.
    let c = d.cmd(CommandKind::MoveTo, [0.3, 0.0, 0.2], 0.0, 0.0, GripperCommand::Keep);
    sim.command(&c);
    assert_eq!(RejectReason::from_u32(sim.robot_state().reject), Some(RejectReason::Faulted));
    let c = d.cmd(CommandKind::ClearFault, [0.0; 3], 0.0, 0.0, GripperCommand::Keep);
    sim.command(&c);
    sim.step_frame();
    assert_eq!(sim.robot_state().flags & robot_flags::FAULT, 0);
    let c = d.cmd(CommandKind::MoveTo, [0.3, 0.0, 0.2], 0.0, 0.0, GripperCommand::Open);
    sim.command(&c);
    d.run_until(&mut sim, 6.0, |f| f & robot_flags::ARRIVED != 0).expect("moves again after ClearFault");
    d.run_until(&mut sim, 1.0, |_| false);
    let width = sim.robot_state().gripper_width_m;
    assert!((f64::from(width) - 2.0 * FINGER_TRAVEL_M).abs() < 1e-3, "gripper open again: {width}");
}

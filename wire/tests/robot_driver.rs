//! Runs the `robot_driver` example as its own process and commands it over the wire as the
//! daemon would: every reply and flag a driver owes the daemon (README, "Connecting a real
//! robot"). The example is the template for real drivers, so it must keep doing all of it.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use handeye_wire::domain::remove_domain_files;
use handeye_wire::message::{MessageEvent, MessagePublisher, MessageSubscriber};
use handeye_wire::{
    monotonic_ns, robot_flags as f, CommandKind, Domain, GripperCommand, RejectReason, RobotCommand, RobotState, WireNode, NO_FRAME,
    WIRE_VERSION,
};

/// The example binary, built by `cargo test` next to the test binaries.
fn example_binary() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(|d| d.parent()).unwrap();
    let bin = profile_dir.join("examples").join("robot_driver");
    assert!(
        bin.is_file(),
        "{} is missing: run `cargo test -p handeye-wire` (it builds the examples) or \
         `cargo build -p handeye-wire --examples` first",
        bin.display()
    );
    bin
}

const HOME: [f32; 3] = [0.30, 0.0, 0.25];

/// The daemon's side of the wire: a command publisher and a state subscriber.
struct Daemon {
    commands: MessagePublisher<RobotCommand>,
    states: MessageSubscriber<RobotState>,
    seq: u64,
    last: RobotState,
}

impl Daemon {
    fn send(&mut self, kind: CommandKind, target_m: [f32; 3], yaw_rad: f32, gripper: GripperCommand) -> u64 {
        self.seq += 1;
        let c = RobotCommand {
            version: WIRE_VERSION,
            kind: kind as u32,
            seq: self.seq,
            frame_id: 1000 + self.seq,
            time_ns: monotonic_ns(),
            target_m,
            yaw_rad,
            speed_limit_mps: 0.0,
            gripper: gripper as u32,
        };
        self.commands.send(&c).unwrap();
        self.seq
    }

    /// Waits (up to 10 s) for a state that satisfies `ok`, feeding the watchdog with `Hold`
    /// every 50 ms when `feed` is set.
    fn until(&mut self, what: &str, feed: bool, ok: impl Fn(&RobotState) -> bool) -> RobotState {
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut fed = Instant::now();
        while Instant::now() < deadline {
            if feed && fed.elapsed() > Duration::from_millis(50) {
                self.send(CommandKind::Hold, [0.0; 3], 0.0, GripperCommand::Keep);
                fed = Instant::now();
            }
            if let MessageEvent::Message(s) = self.states.wait(Duration::from_millis(20)).unwrap() {
                // +1 per sample; a lagging subscriber may lose the oldest queued ones.
                assert!(s.seq > self.last.seq && s.time_ns >= self.last.time_ns, "{s:?} after {:?}", self.last);
                self.last = s;
                if ok(&s) {
                    return s;
                }
            }
        }
        panic!("no state with {what} within 10 s; last: {:?}", self.last);
    }
}

fn near(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5)
}

fn spawn(domain: &Domain) -> Child {
    Command::new(example_binary())
        .args(["--home", "0.30,0,0.25", "--home-yaw-deg", "0", "--rate-hz", "240"])
        .env("HANDEYE_DOMAIN", domain.name())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn example_robot_driver_answers_every_command_with_the_flags_the_daemon_relies_on() {
    let domain = Domain::unique("driver");
    let node = WireNode::create(&domain, "driver-test").unwrap();
    let states = MessageSubscriber::<RobotState>::create(&node).unwrap();
    let commands = MessagePublisher::<RobotCommand>::create(&node).unwrap();
    let mut child = spawn(&domain);
    let mut d = Daemon { commands, states, seq: 0, last: RobotState::default() };

    // At rest at home: arrived, not moving, gripper open and settled. (The first state seen
    // may be the history sample: take its seq as the start.)
    let first = loop {
        match d.states.wait(Duration::from_secs(20)).unwrap() {
            MessageEvent::Message(s) => break s,
            MessageEvent::Timeout => panic!("no robot state from the driver within 20 s"),
            _ => {}
        }
    };
    d.last = first;
    let s = d.until("the gripper settled", false, |s| s.flags & f::GRIPPER_SETTLED != 0);
    assert_eq!(s.flags & (f::MOVING | f::REJECTED | f::GRIPPER_CLOSED), 0, "{s:?}");
    assert_ne!(s.flags & f::ARRIVED, 0, "{s:?}");
    assert!(near(s.tool_pos_m, HOME) && s.tool_yaw_rad == 0.0, "{s:?}");
    assert!((s.gripper_width_m - 0.08).abs() < 1e-6);
    assert_eq!(s.last_command_frame_id, NO_FRAME);

    // MoveTo: processed (seq, frame id), MOVING on the way, then ARRIVED exactly there, and
    // joints that are the arm's IK (base yaw towards the tool, roll = base - yaw).
    let target = [0.35, 0.05, 0.10];
    let seq = d.send(CommandKind::MoveTo, target, 0.3, GripperCommand::Keep);
    let s = d.until("the move processed", true, |s| s.last_command_seq >= seq);
    assert_eq!(s.last_command_frame_id, 1000 + seq);
    assert_ne!(s.flags & f::MOVING, 0, "{s:?}");
    assert_eq!(s.flags & f::ARRIVED, 0, "{s:?}");
    let s = d.until("arrival at the MoveTo target", true, |s| s.flags & f::ARRIVED != 0);
    assert_eq!(s.flags & f::MOVING, 0, "{s:?}");
    assert!(near(s.tool_pos_m, target) && (s.tool_yaw_rad - 0.3).abs() < 1e-6, "{s:?}");
    assert!((s.joints_rad[0] - (0.05f32).atan2(0.35)).abs() < 1e-5 && (s.joints_rad[4] - (s.joints_rad[0] - 0.3)).abs() < 1e-5, "{s:?}");

    // MoveBy is relative to the current target.
    let seq = d.send(CommandKind::MoveBy, [0.0, 0.0, 0.02], -0.3, GripperCommand::Keep);
    let s = d.until("arrival after MoveBy", true, |s| s.last_command_seq >= seq && s.flags & f::ARRIVED != 0);
    assert!(near(s.tool_pos_m, [0.35, 0.05, 0.12]) && s.tool_yaw_rad.abs() < 1e-6, "{s:?}");

    // Refusals: below the table (unreachable), a wrist roll past 170° (joint limit), each reported
    // with REJECTED, the reason, and the arm left where it was; the next good command clears it.
    for (target, yaw, why) in [([0.35, 0.05, -0.02], 0.0, RejectReason::Unreachable), ([0.35, 0.05, 0.12], 3.2, RejectReason::JointLimit)] {
        let seq = d.send(CommandKind::MoveTo, target, yaw, GripperCommand::Close);
        let s = d.until("the refusal", true, |s| s.last_command_seq >= seq);
        assert_ne!(s.flags & f::REJECTED, 0, "{s:?}");
        assert_eq!(s.reject, why as u32, "{s:?}");
        assert_eq!(s.flags & (f::MOVING | f::GRIPPER_CLOSED), 0, "a refused move changes nothing: {s:?}");
        assert!(near(s.tool_pos_m, [0.35, 0.05, 0.12]));
    }
    let seq = d.send(CommandKind::Hold, [0.0; 3], 0.0, GripperCommand::Keep);
    let s = d.until("the hold", true, |s| s.last_command_seq >= seq);
    assert_eq!(s.flags & f::REJECTED, 0, "{s:?}");
    assert_eq!(s.reject, RejectReason::None as u32);

    // A malformed command (wrong version, then a NaN target) is dropped by the subscriber and
    // reported as REJECTED, malformed.
    for bad in [
        RobotCommand { version: WIRE_VERSION + 1, kind: CommandKind::MoveTo as u32, seq: 900, ..Default::default() },
        RobotCommand { version: WIRE_VERSION, kind: CommandKind::MoveTo as u32, seq: 901, target_m: [f32::NAN, 0.0, 0.1], ..Default::default() },
    ] {
        d.commands.send_unchecked(&bad).unwrap();
        let s = d.until("the malformed refusal", false, |s| s.flags & f::REJECTED != 0);
        assert_eq!(s.reject, RejectReason::Malformed as u32, "{s:?}");
        assert!(near(s.tool_pos_m, [0.35, 0.05, 0.12]));
        d.send(CommandKind::Hold, [0.0; 3], 0.0, GripperCommand::Keep);
        d.until("the refusal cleared", false, |s| s.flags & f::REJECTED == 0);
    }

    // Gripper: closed as commanded, the width runs to 0, then settles; opens again.
    d.send(CommandKind::Hold, [0.0; 3], 0.0, GripperCommand::Close);
    let s = d.until("the jaws closed", true, |s| s.flags & f::GRIPPER_CLOSED != 0);
    assert_eq!(s.flags & f::GRIPPER_SETTLED, 0, "the jaws are still moving: {s:?}");
    let s = d.until("the jaws settled closed", true, |s| s.flags & f::GRIPPER_SETTLED != 0);
    assert_eq!(s.gripper_width_m, 0.0);
    d.send(CommandKind::Hold, [0.0; 3], 0.0, GripperCommand::Open);
    let s = d.until("the jaws settled open", true, |s| s.flags & f::GRIPPER_CLOSED == 0 && s.flags & f::GRIPPER_SETTLED != 0);
    assert!((s.gripper_width_m - 0.08).abs() < 1e-6);

    // Stop mid-move: STOPPED at once, the tool halts short of the target and stays.
    let seq = d.send(CommandKind::MoveTo, [0.45, -0.10, 0.20], 0.0, GripperCommand::Keep);
    d.until("moving", true, |s| s.last_command_seq >= seq && s.flags & f::MOVING != 0);
    let seq = d.send(CommandKind::Stop, [0.0; 3], 0.0, GripperCommand::Keep);
    let s = d.until("the stop", false, |s| s.last_command_seq >= seq);
    assert_ne!(s.flags & f::STOPPED, 0, "{s:?}");
    assert_eq!(s.flags & (f::MOVING | f::ARRIVED), 0, "{s:?}");
    let held = s.tool_pos_m;
    assert!(!near(held, [0.45, -0.10, 0.20]));
    let later = d.last.seq + 20;
    let s = d.until("a later state", false, |s| s.seq >= later);
    assert_eq!(s.tool_pos_m, held, "a stopped arm stays");

    // Watchdog: a long move with no command after it stops by itself after ~200 ms of silence.
    let seq = d.send(CommandKind::MoveTo, [0.30, 0.15, 0.05], 0.0, GripperCommand::Keep);
    let moving = d.until("moving", false, |s| s.last_command_seq >= seq && s.flags & f::MOVING != 0);
    let s = d.until("the watchdog stop", false, |s| s.flags & f::WATCHDOG_STOP != 0);
    assert!(s.time_ns - moving.time_ns >= 150_000_000, "stopped {} ms after the move began", (s.time_ns - moving.time_ns) / 1_000_000);
    assert_eq!(s.flags & (f::MOVING | f::ARRIVED), 0, "{s:?}");
    assert!(!near(s.tool_pos_m, [0.30, 0.15, 0.05]), "stopped short of the target");
    // A new move clears it.
    let seq = d.send(CommandKind::MoveTo, HOME, 0.0, GripperCommand::Keep);
    d.until("the watchdog stop cleared", true, |s| s.last_command_seq >= seq && s.flags & f::WATCHDOG_STOP == 0);

    // SIGTERM: a clean exit with the counts of what it did.
    // SAFETY: kill(2) on the child we spawned.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let out = wait_with_timeout(&mut child, Duration::from_secs(10));
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{text}");
    for want in ["unreachable 1", "joint limit 1", "malformed 2", "(malformed by field: version 1, enum 0, non_finite 1, range 0)", "watchdog stops 1", "stop 1"] {
        assert!(text.contains(want), "driver summary lacks '{want}':\n{text}");
    }
    drop(d);
    drop(node);
    let _ = remove_domain_files(&domain);
}

fn wait_with_timeout(child: &mut Child, timeout: Duration) -> std::process::Output {
    let deadline = Instant::now() + timeout;
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("the driver did not exit on SIGTERM");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut stderr = String::new();
    use std::io::Read;
    child.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
    std::process::Output { status: child.wait().unwrap(), stdout: Vec::new(), stderr: stderr.into_bytes() }
}

#[test]
fn example_robot_driver_refuses_a_home_it_cannot_reach() {
    let out = Command::new(example_binary()).args(["--home", "0.9,0,0.1"]).env("HANDEYE_DOMAIN", Domain::unique("driver-bad").name()).output().unwrap();
    assert!(!out.status.success());
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(text.contains("--home") && text.contains("unreachable"), "{text}");
}

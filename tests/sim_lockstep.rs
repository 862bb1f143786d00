//! `handeye sim` as a separate process on the shared-memory services: lockstep determinism
//! through the CLI, a stand-in daemon in this process driving the arm frame by frame, and
//! scenario errors reported by the CLI.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use handeye_wire::domain::remove_domain_files;
use handeye_wire::message::{MessageEvent, MessagePublisher, MessageSubscriber};
use handeye_wire::stereo::{StereoEvent, StereoSubscriber};
use handeye_wire::{CommandKind, Domain, GripperCommand, RobotCommand, RobotState, WIRE_VERSION, WireNode, robot_flags};
use handeye_sim::referee::report::SimReport;

const BIN: &str = env!("CARGO_BIN_EXE_handeye");

fn scenario(name: &str) -> String {
    format!("{}/scenarios/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// A unique domain whose files are removed at the end.
struct TestDomain(Domain);

impl Drop for TestDomain {
    fn drop(&mut self) {
        let _ = remove_domain_files(&self.0);
    }
}

fn sim_json(args: &[&str], domain: &Domain) -> SimReport {
    let out = Command::new(BIN)
        .arg("sim")
        .args(args)
        .args(["--json", "--domain", domain.name()])
        .env("RUST_LOG", "warn")
        .output()
        .expect("run handeye sim");
    assert!(out.status.success(), "handeye sim failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("bad JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

#[test]
fn cli_lockstep_runs_publish_identical_frames_for_100_frames() {
    let (d1, d2) = (TestDomain(Domain::unique("simdet")), TestDomain(Domain::unique("simdet")));
    let a = sim_json(&[&scenario("pick_cube.toml"), "--lockstep", "--frames", "100"], &d1.0);
    let b = sim_json(&[&scenario("pick_cube.toml"), "--lockstep", "--frames", "100"], &d2.0);
    assert_eq!(a.frames, 100);
    assert!(a.fps > 0.0);
    assert_eq!(a.reply_timeouts, 0, "no daemon attached: no waiting");
    let hash = &a.frames_hash;
    assert_eq!(hash.len(), 16);
    assert_eq!(a.frames_hash, b.frames_hash, "two lockstep runs of one scenario and seed");
    // A different scene gives a different hash (the hash covers the pixels).
    let d3 = TestDomain(Domain::unique("simdet"));
    let c = sim_json(&[&scenario("clutter3.toml"), "--lockstep", "--frames", "100"], &d3.0);
    assert_ne!(c.frames_hash, a.frames_hash);
}

fn command(seq: u64, frame_id: u64, kind: CommandKind, target: [f32; 3], gripper: GripperCommand) -> RobotCommand {
    RobotCommand {
        version: WIRE_VERSION,
        kind: kind as u32,
        seq,
        frame_id,
        time_ns: handeye_wire::monotonic_ns(),
        target_m: target,
        yaw_rad: 0.0,
        speed_limit_mps: 0.3,
        gripper: gripper as u32,
    }
}

#[test]
fn lockstep_waits_for_the_daemon_and_follows_its_commands() {
    let d = TestDomain(Domain::unique("simstep"));
    // The stand-in daemon joins first, so the simulator sees a command publisher at once.
    let node = WireNode::create(&d.0, "test-daemon").expect("node");
    let mut frames = StereoSubscriber::create(&node, 2).expect("stereo subscriber");
    let mut commands = MessagePublisher::<RobotCommand>::create(&node).expect("command publisher");
    let mut states = MessageSubscriber::<RobotState>::create(&node).expect("state subscriber");

    let child = Command::new(BIN)
        .args(["sim", &scenario("pick_cube.toml"), "--lockstep", "--frames", "60", "--reply-timeout-s", "5", "--json"])
        .args(["--domain", d.0.name()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn handeye sim");

    let target = [0.40f32, 0.10, 0.12];
    let mut ids = Vec::new();
    let mut last_state: Option<RobotState> = None;
    let start = Instant::now();
    while ids.len() < 60 && start.elapsed() < Duration::from_secs(60) {
        match frames.wait(Duration::from_secs(10)).expect("wait") {
            StereoEvent::Frame(f) => {
                let id = f.frame_id();
                assert_eq!(f.layout().width, 640);
                drop(f);
                // The state published with the frame (and every control tick before it): the
                // simulator is blocked until we answer, so these are all from before the answer.
                if let MessageEvent::Message(s) = states.wait(Duration::from_secs(2)).expect("state wait") {
                    last_state = Some(s);
                }
                while let Some(s) = states.try_receive() {
                    last_state = Some(s);
                }
                // Answer every frame: the first with the move, then Hold.
                let (kind, gripper) = if id == 0 { (CommandKind::MoveTo, GripperCommand::Close) } else { (CommandKind::Hold, GripperCommand::Keep) };
                commands.send(&command(id + 1, id, kind, target, gripper)).expect("send");
                ids.push(id);
            }
            StereoEvent::PublisherUp => {}
            StereoEvent::Timeout => panic!("no frame for 10 s after {} frames", ids.len()),
            StereoEvent::PublisherGone => break,
            StereoEvent::Interrupted => panic!("interrupted"),
        }
    }
    let out = child.wait_with_output().expect("sim output");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: SimReport = serde_json::from_slice(&out.stdout).expect("the simulator's report");

    // Lockstep: every frame reached us, in order, none skipped, and every one was answered.
    assert_eq!(ids, (0..60).collect::<Vec<u64>>());
    assert_eq!(report.reply_timeouts, 0, "{report:?}");
    assert!(report.commands >= 60);
    // The arm went where it was told (2 s of simulated time at 0.3 m/s) and closed its jaws.
    let s = last_state.expect("robot state received");
    assert_eq!(s.version, WIRE_VERSION);
    assert_eq!(s.last_command_frame_id, 58, "the state with frame 59 reflects the answer to frame 58");
    let d_m = ((s.tool_pos_m[0] - target[0]).powi(2) + (s.tool_pos_m[1] - target[1]).powi(2) + (s.tool_pos_m[2] - target[2]).powi(2)).sqrt();
    assert!(d_m < 0.002, "tool {:?} not at {target:?}", s.tool_pos_m);
    assert_ne!(s.flags & robot_flags::ARRIVED, 0, "flags {:#x}", s.flags);
    assert_ne!(s.flags & robot_flags::GRIPPER_CLOSED, 0);
    assert!(s.gripper_width_m < 0.001, "jaws closed on nothing: width {}", s.gripper_width_m);
}

#[test]
fn lockstep_times_out_on_unanswered_frames_and_goes_on() {
    let d = TestDomain(Domain::unique("simlate"));
    let node = WireNode::create(&d.0, "silent-daemon").expect("node");
    // A command publisher that never answers.
    let _commands = MessagePublisher::<RobotCommand>::create(&node).expect("command publisher");
    let start = Instant::now();
    let report = sim_json(&[&scenario("pick_cube.toml"), "--lockstep", "--frames", "5", "--reply-timeout-s", "0.1"], &d.0);
    assert_eq!(report.frames, 5);
    assert_eq!(report.reply_timeouts, 5, "{report:?}");
    assert!(start.elapsed() >= Duration::from_millis(500), "it waited for each frame");
}

#[test]
fn bad_scenario_files_are_reported_with_file_line_and_field() {
    let dir = std::env::temp_dir().join(format!("handeye-badscen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = std::fs::read_to_string(scenario("pick_cube.toml")).unwrap();
    let cases = [
        ("unknown.toml", good.replace("friction = 0.8", "friction = 0.8\nfrictoin = 0.7"), "frictoin"),
        ("missing.toml", good.replace("frame_rate_hz = 30", ""), "frame_rate_hz"),
        ("type.toml", good.replace("seed = 1", "seed = \"one\""), "seed"),
        ("range.toml", good.replace("size_mm = [40.0, 40.0, 40.0]", "size_mm = [40.0, 40.0, 4.0]"), "blocks[0].size_mm"),
        ("kind.toml", good.replace("kind = \"cube\"", "kind = \"sphere\""), "sphere"),
    ];
    for (file, text, field) in cases {
        assert_ne!(text, good, "{file}: the edit applied");
        let path = dir.join(file);
        std::fs::write(&path, &text).unwrap();
        for sub in ["sim", "snapshot"] {
            let mut cmd = Command::new(BIN);
            cmd.arg(sub).arg(&path);
            if sub == "snapshot" {
                cmd.args(["--out", dir.join("snap").to_str().unwrap()]);
            }
            let out = cmd.output().expect("run");
            assert!(!out.status.success(), "{sub} {file} must fail");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(err.contains(&format!("{}:", path.display())), "{sub} {file}: no file:line in {err}");
            assert!(err.contains(field), "{sub} {file}: field {field} not named in {err}");
            assert!(!err.contains("panicked"), "{sub} {file}: {err}");
        }
    }
    let _ = std::fs::remove_dir_all(dir);
}

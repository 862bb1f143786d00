//! The closed loop under a random kill: `handeye sim --lockstep` (cameras and arm) and
//! `handeye daemon` in a fresh domain, as `handeye run` starts them; the test process listens
//! to telemetry, commands and robot states in the same domain.
//!
//! Killing the simulator: the daemon must stop on its stale-frame guard (its `Stopped`
//! telemetry within 100 ms of the kill, plus scheduling), exit, and a fresh simulator and
//! daemon in the same domain must run. Killing the daemon: the arm's 200 ms watchdog must stop
//! a moving arm (measured in the arm's own clock, the robot state's `time_ns`, because a
//! lockstep simulator's time only moves when it steps), the tool must stay where it stopped,
//! and a fresh daemon in the same domain must get frames and command the arm.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use handeye_wire::message::{MessageEvent, MessageSubscriber};
use handeye_wire::{monotonic_ns, robot_flags, Domain, Phase, RobotCommand, RobotState, Telemetry, WireNode};

use super::*;
use crate::e2e_support::{scenario_without_antialias, TempDir};
use crate::wire_support::{Proc, TestDomain};

/// Lockstep frames wait this long for the daemon's reply: with the daemon dead, the
/// simulator keeps stepping (and the watchdog keeps counting) at about a frame per 0.1 s.
const REPLY_TIMEOUT_S: &str = "0.1";

fn handeye(domain: &Domain) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_handeye"));
    c.env("HANDEYE_DOMAIN", domain.name()).env("HANDEYE_LOG", "warn").env_remove("IOX2_LOG_LEVEL");
    c
}

fn start_sim(dir: &Path, domain: &Domain, scenario: &Path, hint: &Path) -> Proc {
    let _ = std::fs::remove_file(hint);
    let mut c = handeye(domain);
    // `--frames`: the simulator outlives the task (and its time-out), so a fresh daemon always
    // finds it running.
    c.arg("sim").arg(scenario);
    c.args(["--lockstep", "--wait-daemon-s", "60", "--reply-timeout-s", REPLY_TIMEOUT_S, "--frames", "10000000", "--hint-out"]).arg(hint);
    c.current_dir(dir);
    let sim = Proc::spawn("sim", c);
    poll(Duration::from_secs(60), || hint.exists().then_some(())).expect("the simulator wrote no hint within 60 s");
    sim
}

fn start_daemon(domain: &Domain, hint: &Path) -> Proc {
    let mut c = handeye(domain);
    c.args(["daemon", "--json", "--hint"]).arg(hint);
    Proc::spawn("daemon", c)
}

/// The test's own ports in the loop's domain.
struct Listener {
    _node: WireNode,
    tel: MessageSubscriber<Telemetry>,
    cmds: MessageSubscriber<RobotCommand>,
    states: MessageSubscriber<RobotState>,
    /// The newest robot state received.
    last_state: Option<RobotState>,
    /// The robot states of the last few seconds, oldest first.
    recent: std::collections::VecDeque<RobotState>,
}

impl Listener {
    fn new(domain: &Domain) -> Self {
        let node = WireNode::create(domain, "kill-test").unwrap();
        let tel = MessageSubscriber::<Telemetry>::create(&node).unwrap();
        let cmds = MessageSubscriber::<RobotCommand>::create(&node).unwrap();
        let states = MessageSubscriber::<RobotState>::create(&node).unwrap();
        Self { _node: node, tel, cmds, states, last_state: None, recent: Default::default() }
    }

    /// Takes every queued robot state, keeping the newest; returns them.
    fn drain_states(&mut self) -> Vec<RobotState> {
        let mut v = Vec::new();
        while let Some(s) = self.states.try_receive() {
            v.push(s);
        }
        if let Some(s) = v.last() {
            self.last_state = Some(*s);
        }
        self.recent.extend(v.iter().copied());
        while self.recent.len() > 20_000 {
            self.recent.pop_front();
        }
        v
    }

    /// The next telemetry sample within `timeout`, keeping robot states drained meanwhile.
    fn telemetry(&mut self, timeout: Duration) -> Option<Telemetry> {
        let t0 = Instant::now();
        while t0.elapsed() < timeout {
            self.drain_states();
            if let MessageEvent::Message(t) = self.tel.wait(Duration::from_millis(10)).unwrap() {
                return Some(t);
            }
        }
        None
    }
}

fn phase_name(raw: u32) -> String {
    Phase::from_u32(raw).map_or_else(|| format!("phase {raw}"), |p| format!("{p:?}").to_lowercase())
}

/// A running loop, up for the seed's number of daemon cycles.
/// Fields drop in order: the processes die first, then the domain's files and the folder go
/// (also when a case panics).
struct Running {
    sim: Proc,
    daemon: Proc,
    listener: Listener,
    /// The daemon's newest telemetry before the kill.
    last: Telemetry,
    scenario: std::path::PathBuf,
    hint: std::path::PathBuf,
    domain: TestDomain,
    dir: TempDir,
}

/// Starts the loop and lets the daemon run the seed's number of cycles. A daemon
/// that stops before the kill (a render slowed past its 100 ms guard by other load on the
/// machine) failed the set-up, not the case: up to three fresh starts.
fn start(plan: &Plan, result: &mut CaseResult) -> Running {
    for attempt in 1..=3 {
        let dir = TempDir::new(&format!("kill{}", plan.seed));
        let domain = TestDomain::new(&format!("kill{}", plan.seed));
        let mut listener = Listener::new(&domain.0);
        let scenario = scenario_without_antialias("pick_cube.toml", &dir.0);
        let hint = dir.0.join("hint.json");
        let sim = start_sim(&dir.0, &domain.0, &scenario, &hint);
        let daemon = start_daemon(&domain.0, &hint);
        let Some(mut last) = listener.telemetry(Duration::from_secs(120)) else {
            panic!("seed {}: the daemon sent no telemetry within 120 s", plan.seed);
        };
        let mut cycles = 1;
        let mut stopped_early = last.phase == Phase::Stopped as u32;
        // A daemon that finished its task (done) is killed then, while it holds the lift.
        while !stopped_early && cycles < plan.loop_cycles() && last.phase != Phase::Done as u32 {
            let Some(t) = listener.telemetry(Duration::from_secs(30)) else {
                panic!("seed {}: the daemon's telemetry stopped after {cycles} cycles", plan.seed);
            };
            stopped_early = t.phase == Phase::Stopped as u32;
            last = t;
            cycles += 1;
        }
        if !stopped_early {
            return Running { sim, daemon, listener, last, scenario, hint, domain, dir };
        }
        assert!(attempt < 3, "seed {}: the daemon stopped on its own three times before the kill ({})", plan.seed, last.reason_text());
        result.setup_retries += 1;
        result.notes.push(format!("set-up {attempt}: the daemon stopped before the kill ({})", last.reason_text()));
        drop((sim, daemon, listener, domain));
    }
    unreachable!()
}

pub fn run(plan: Plan) -> CaseResult {
    let mut result = CaseResult::new(plan);
    let mut r = start(&plan, &mut result);
    result.at = phase_name(r.last.phase);
    match plan.victim {
        Victim::Simulator => kill_simulator(&mut r, &mut result),
        Victim::Daemon => kill_daemon(&mut r, &mut result),
        _ => unreachable!("not a closed-loop process"),
    }
    drop(r);
    result
}

fn kill_simulator(r: &mut Running, result: &mut CaseResult) {
    let killed_ns = monotonic_ns();
    let _ = r.sim.child.kill();
    let _ = r.sim.child.wait();
    let daemon_done = r.last.phase == Phase::Done as u32;
    let stopped = if daemon_done {
        None
    } else {
        let t0 = Instant::now();
        let mut seen = None;
        while seen.is_none() && t0.elapsed() < Duration::from_secs(5) {
            seen = r.listener.telemetry(Duration::from_millis(100)).filter(|t| t.phase == Phase::Stopped as u32);
        }
        seen
    };
    match (stopped, daemon_done) {
        (Some(t), _) => {
            result.detections.push(Detection::new("daemon", "Stopped telemetry", ms_between(killed_ns, t.time_ns), STALE_FRAME_MS + SCHEDULING_ALLOWANCE_MS));
            result.notes.push(format!("daemon: {}", t.reason_text()));
        }
        (None, true) => result.notes.push("the daemon had finished its task before the kill".into()),
        (None, false) => result.detections.push(Detection::new("daemon", "Stopped telemetry", f64::INFINITY, STALE_FRAME_MS)),
    }
    // The daemon ends by itself (its frames are gone).
    let exited = poll(Duration::from_secs(10), || r.daemon.child.try_wait().unwrap());
    if exited.is_none() {
        result.notes.push("the daemon did not exit within 10 s of the kill".into());
    }
    // A fresh simulator and daemon in the same domain: the dead simulator's node must not be
    // in the way. Up means the new daemon publishes telemetry, i.e. it got a frame.
    r.sim = start_sim(&r.dir.0, &r.domain.0, &r.scenario, &r.hint);
    r.daemon = start_daemon(&r.domain.0, &r.hint);
    result.restart_ok = r.listener.telemetry(Duration::from_secs(120)).is_some();
}

fn kill_daemon(r: &mut Running, result: &mut CaseResult) {
    r.listener.drain_states();
    let arm_clock_at_kill_ns = r.listener.last_state.expect("robot states flowed before the kill").time_ns;
    let _ = r.daemon.child.kill();
    let _ = r.daemon.child.wait();
    // Everything the arm reports for 1.2 s of its own time after the kill: the watchdog's
    // 200 ms, the stop, and a second of standing still. Without the daemon the simulator
    // runs flat out (8 states a frame) and the test reads the newest four: a tight poll
    // sees most of them.
    let mut after: Vec<RobotState> = Vec::new();
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(60) && after.last().is_none_or(|s| s.time_ns < arm_clock_at_kill_ns + 1_200_000_000) {
        std::thread::sleep(Duration::from_micros(300));
        after.extend(r.listener.drain_states());
    }
    assert!(!after.is_empty(), "seed {}: the simulator published no robot state after the daemon died", result.plan.seed);
    let moving = after.iter().any(|s| s.flags & robot_flags::MOVING != 0);
    result.arm_was_moving = Some(moving);
    let flagged = |s: &RobotState| s.flags & robot_flags::WATCHDOG_STOP != 0;
    let watchdog = after.iter().position(flagged);
    if let Some(i) = watchdog {
        // The watchdog counts from the last command the arm took (one still in flight at the
        // kill lands after it). The test reads only the newest four robot states, so both
        // ends are sampled. A lockstep simulator applies commands only where a frame starts
        // (a multiple of `substeps` physics steps), after the last state that lacks the
        // command and before the first that has it; the watchdog fired after the last state
        // without its flag and by the first with it. Reported: the longest the samples
        // allow; judged: the shortest, which must be within the bound, or it was surely late.
        let sc = handeye_sim::scenario::Scenario::load(&r.scenario).expect("the scenario loads");
        let (rate_hz, substeps) = (u128::from(sc.physics.rate_hz), u128::from(sc.substeps_per_frame()));
        let frame_start_ns = |k: u128| (k * substeps * 1_000_000_000 / rate_hz) as u64;
        let seen: Vec<RobotState> = r.listener.recent.iter().copied().collect();
        let last_seq = after.iter().map(|s| s.last_command_seq).max().unwrap_or(0);
        let first_with = seen.iter().position(|s| s.last_command_seq == last_seq).unwrap_or(0);
        let cmd_hi = seen[first_with].time_ns;
        let cmd_lo = if first_with > 0 { seen[first_with - 1].time_ns } else { 0 };
        // Frame starts in [cmd_lo, cmd_hi): the earliest and the latest the command can have landed.
        // (Frame starts are whole nanoseconds rounded down, as the simulator's clock is.)
        let first_at_or_after = |t: u64| {
            let mut k = u128::from(t) * rate_hz / (substeps * 1_000_000_000);
            while frame_start_ns(k) < t {
                k += 1;
            }
            k
        };
        let k_lo = first_at_or_after(cmd_lo);
        let k_hi = first_at_or_after(cmd_hi).saturating_sub(1).max(k_lo);
        let (cmd_earliest, cmd_latest) = (frame_start_ns(k_lo).max(cmd_lo), frame_start_ns(k_hi).min(cmd_hi));
        let fire_hi = after[i].time_ns;
        let fire_lo = if i > 0 { after[i - 1].time_ns } else { arm_clock_at_kill_ns.min(fire_hi) };
        let tick_ms = 1e3 / sc.physics.rate_hz as f64;
        let longest = ms_between(cmd_earliest, fire_hi);
        // The controller stops in the first step that starts more than 200 ms after the
        // command, and a state carries the time after its step: two ticks at most.
        let mut d = Detection::new("arm", "watchdog stop after its last command (arm clock)", longest, WATCHDOG_MS + 2.0 * tick_ms);
        d.sampling_ms = longest - ms_between(cmd_latest, fire_lo);
        result.detections.push(d);
    } else if moving {
        // No watchdog stop: the set-point reached the last commanded target within 200 ms
        // and the arm settled there (ARRIVED), which the watchdog rightly lets happen.
        result.notes.push("the last commanded move ended before the watchdog's 200 ms; the arm settled on it".into());
    }
    // Ground truth from the simulator: once at rest (after the watchdog's stop, after
    // settling on its last target, or at once if it was not moving), the tool stays put.
    let rest = match watchdog {
        Some(i) => after[i..].iter().find(|s| s.flags & robot_flags::MOVING == 0),
        None if moving => after.iter().find(|s| s.flags & robot_flags::MOVING == 0),
        None => after.first(),
    };
    match rest {
        Some(rest) => {
            let moves = after
                .iter()
                .filter(|s| s.time_ns > rest.time_ns)
                .filter(|s| (0..3).map(|i| (s.tool_pos_m[i] - rest.tool_pos_m[i]).powi(2)).sum::<f32>().sqrt() > STILL_M)
                .count();
            result.moves_after_death = Some(moves as u32);
            let span_ms = ms_between(rest.time_ns, after.last().unwrap().time_ns);
            result.notes.push(format!("arm watched for {span_ms:.0} ms of its time at rest"));
        }
        None => {
            result.moves_after_death = Some(u32::MAX);
            result.notes.push("the arm never came to rest".into());
        }
    }
    // A fresh daemon in the same domain: its ports must work, i.e. the arm takes a command
    // from it (its states name a command sequence number the dead daemon's did not). Its
    // telemetry is no proof either way: a daemon that stops at once exits, and iceoryx2 drops
    // the samples of a publisher that is gone before a subscriber took them.
    let dead_seq = r.listener.last_state.map_or(0, |s| s.last_command_seq);
    r.daemon = start_daemon(&r.domain.0, &r.hint);
    let took = poll(Duration::from_secs(60), || r.listener.drain_states().into_iter().find(|s| s.last_command_seq != dead_seq));
    // What it made of the arm the dead daemon left behind: it must take over, not stop at
    // once (the dead daemon's watchdog stop is not its fault).
    let stopped_at_once = poll(Duration::from_millis(500), || r.daemon.child.try_wait().unwrap()).is_some();
    result.restart_ok = took.is_some() && !stopped_at_once;
    if stopped_at_once {
        let fresh = std::mem::replace(&mut r.daemon, Proc::spawn("true", Command::new("true")));
        let (_, out, err) = fresh.finish(Duration::from_secs(10));
        let reason = out.lines().rev().find_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()).map(|v| v["failure_reason"].to_string());
        let last_err = err.lines().last().unwrap_or("").to_owned();
        result.notes.push(format!("the fresh daemon stopped at once: {}", reason.unwrap_or(last_err)));
    }
}

//! A minimal robot driver for handeye: serves `handeye/robot/state` and takes
//! `handeye/robot/command` for a kinematic arm with no physics, exactly as a driver for a real
//! arm would. Copy it, and replace [`Arm::reachable`] and [`Arm::advance`] with calls into
//! your robot's own inverse kinematics and motion interface (the `kinematics` module is
//! the simulator's arm, so that this driver refuses what the simulated arm cannot do).
//!
//! ```text
//! cargo run -p handeye-wire --example robot_driver -- --home 0.30,0,0.25 --home-yaw-deg -90
//! handeye daemon --hint hint.json   # in another terminal, with cameras publishing
//! ```
//!
//! Flags: `--home X,Y,Z` (metres, robot frame; default 0.30,0,0.25), `--home-yaw-deg DEG`
//! (default 0), `--rate-hz HZ` (state samples per second, default 240: the simulator's
//! control rate), `--speed-mps V` (tool speed when a command asks for none, default 0.15),
//! `--watchdog-ms MS` (default 200), `--exit-after-s S` (0 = until Ctrl-C, the default).
//! The domain comes from `HANDEYE_DOMAIN` (default `handeye`).
//!
//! What the daemon relies on (README, "Connecting a real robot"):
//! - one `RobotState` per control tick, `seq` +1 each, `time_ns` on `CLOCK_MONOTONIC`;
//! - `last_command_seq` / `last_command_frame_id` of the last command processed;
//! - `MOVING` while the tool has not reached the last accepted target, `ARRIVED` once it has;
//! - `REJECTED` + `reject` for a command refused (out of reach, beyond a joint, malformed);
//! - `GRIPPER_CLOSED` as commanded, `GRIPPER_SETTLED` once the jaws stopped moving;
//! - `STOPPED` after `Stop`, `WATCHDOG_STOP` when commands stopped arriving while moving.
//!
//! On exit it prints what it did: commands by kind, refusals by reason, watchdog stops.

use std::time::{Duration, Instant};

use handeye_wire::message::{MessageEvent, MessagePublisher, MessageReject, MessageSubscriber};
use handeye_wire::{
    monotonic_ns, robot_flags, CommandKind, Domain, GripperCommand, RejectReason, RobotCommand, RobotState, WireNode, NO_FRAME,
    WIRE_VERSION,
};

/// The arm's geometry: the simulator's 5-DOF arm (base yaw, shoulder, elbow, wrist pitch,
/// wrist roll; gripper pointing down), so that this driver accepts what the simulator's arm
/// can do. A real driver has its own kinematics; this module is what it replaces.
mod kinematics {
    use std::f64::consts::{FRAC_PI_2, PI};

    use handeye_wire::RejectReason;

    const SHOULDER_HEIGHT_M: f64 = 0.30;
    const UPPER_ARM_M: f64 = 0.30;
    const FOREARM_M: f64 = 0.28;
    /// Wrist pitch axis to the tool point (wrist link, palm, fingers).
    const WRIST_TO_TOOL_M: f64 = 0.17;
    const MIN_TOOL_Z_M: f64 = 0.004;
    const MIN_RADIUS_M: f64 = 0.15;
    /// Kept from a stretched (singular) arm.
    const REACH_MARGIN_M: f64 = 0.01;
    const JOINT_MIN_DEG: [f64; 5] = [-170.0, -20.0, -165.0, -150.0, -170.0];
    const JOINT_MAX_DEG: [f64; 5] = [170.0, 135.0, -5.0, 60.0, 170.0];

    /// Joint angles (radians) that put the tool point at `pos_m` with yaw `yaw_rad`, elbow
    /// up, or why the arm cannot.
    pub fn ik(pos_m: [f64; 3], yaw_rad: f64) -> Result<[f64; 5], RejectReason> {
        let [x, y, z] = pos_m;
        let r = x.hypot(y);
        if z < MIN_TOOL_Z_M || r < MIN_RADIUS_M {
            return Err(RejectReason::Unreachable);
        }
        let wz = z + WRIST_TO_TOOL_M - SHOULDER_HEIGHT_M;
        let d2 = r * r + wz * wz;
        let d = d2.sqrt();
        if d > UPPER_ARM_M + FOREARM_M - REACH_MARGIN_M || d < (UPPER_ARM_M - FOREARM_M).abs() + REACH_MARGIN_M {
            return Err(RejectReason::Unreachable);
        }
        let base = y.atan2(x);
        let c2 = ((d2 - UPPER_ARM_M * UPPER_ARM_M - FOREARM_M * FOREARM_M) / (2.0 * UPPER_ARM_M * FOREARM_M)).clamp(-1.0, 1.0);
        let elbow = -c2.acos();
        let shoulder = wz.atan2(r) - (FOREARM_M * elbow.sin()).atan2(UPPER_ARM_M + FOREARM_M * elbow.cos());
        let pitch = -FRAC_PI_2 - shoulder - elbow;
        let roll = super::wrap(base - yaw_rad);
        let q = [base, shoulder, elbow, pitch, roll];
        let inside = |j: usize| q[j].to_degrees() >= JOINT_MIN_DEG[j] && q[j].to_degrees() <= JOINT_MAX_DEG[j];
        if !(0..5).all(inside) {
            return Err(RejectReason::JointLimit);
        }
        debug_assert!(roll.abs() <= PI);
        Ok(q)
    }
}

/// Gripper: 0..80 mm between the pads, each jaw moving at 50 mm/s.
const GRIPPER_OPEN_M: f64 = 0.080;
const GRIPPER_SPEED_MPS: f64 = 0.100;
/// Jaws still this long before `GRIPPER_SETTLED`.
const GRIPPER_SETTLE_NS: u64 = 50_000_000;
/// Highest tool speed any command may ask for, m/s, and the yaw rate, rad/s.
const MAX_SPEED_MPS: f64 = 0.5;
const YAW_RATE_RADPS: f64 = 1.5;

/// Tool pose with the gripper pointing down.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pose {
    pos_m: [f64; 3],
    yaw_rad: f64,
}

/// Counts of what the driver did, printed at exit.
#[derive(Debug, Default)]
struct Counts {
    commands: [u64; 5],
    refused: [u64; 5],
    watchdog_stops: u64,
    states: u64,
}

/// A kinematic arm: the tool moves in a straight line towards the goal at the commanded
/// speed; yaw turns at a fixed rate; the gripper width ramps towards open or closed.
struct Arm {
    pose: Pose,
    goal: Pose,
    speed_mps: f64,
    default_speed_mps: f64,
    gripper_width_m: f64,
    gripper_closed: bool,
    gripper_still_since_ns: Option<u64>,
    arrived: bool,
    stopped: bool,
    watchdog_stop: bool,
    reject: RejectReason,
    rejected: bool,
    last_command_ns: u64,
    last_command_seq: u64,
    last_command_frame_id: u64,
    watchdog_ns: u64,
    seq: u64,
}

impl Arm {
    fn new(home: Pose, default_speed_mps: f64, watchdog_ns: u64) -> Self {
        Self {
            pose: home,
            goal: home,
            speed_mps: default_speed_mps,
            default_speed_mps,
            gripper_width_m: GRIPPER_OPEN_M,
            gripper_closed: false,
            gripper_still_since_ns: Some(0),
            arrived: true,
            stopped: false,
            watchdog_stop: false,
            reject: RejectReason::None,
            rejected: false,
            last_command_ns: monotonic_ns(),
            last_command_seq: 0,
            last_command_frame_id: NO_FRAME,
            watchdog_ns,
            seq: 0,
        }
    }

    /// Whether the arm can hold the tool at `p`. A real driver calls its IK here and maps its
    /// failure to `Unreachable` or `JointLimit`.
    fn reachable(p: Pose) -> Result<(), RejectReason> {
        kinematics::ik(p.pos_m, p.yaw_rad).map(|_| ())
    }

    /// Applies one valid command (the subscriber already dropped malformed ones).
    fn command(&mut self, c: &RobotCommand, counts: &mut Counts) {
        self.last_command_seq = c.seq;
        self.last_command_frame_id = c.frame_id;
        // Validated by the subscriber: both enums are known values.
        let kind = CommandKind::from_u32(c.kind).unwrap_or(CommandKind::Hold);
        let gripper = GripperCommand::from_u32(c.gripper).unwrap_or(GripperCommand::Keep);
        counts.commands[kind as usize] += 1;
        // Every command feeds the watchdog, `Hold` included: the daemon sends one per frame.
        self.last_command_ns = monotonic_ns();
        match kind {
            CommandKind::Hold => {}
            // Stop: halt where the tool is now and forget the target. A real arm brakes on
            // its normal deceleration ramp; this one has no mass and halts at once.
            CommandKind::Stop => {
                self.goal = self.pose;
                self.stopped = true;
                self.arrived = false;
                return self.accept();
            }
            // Nothing in this arm faults; a real driver clears its fault here and holds still.
            CommandKind::ClearFault => return self.accept(),
            CommandKind::MoveTo | CommandKind::MoveBy => {
                let t = c.target_m.map(f64::from);
                let goal = if kind == CommandKind::MoveTo {
                    Pose { pos_m: t, yaw_rad: f64::from(c.yaw_rad) }
                } else {
                    // Relative to the current *target*, so a stream of small moves adds up.
                    let g = self.goal.pos_m;
                    Pose { pos_m: [g[0] + t[0], g[1] + t[1], g[2] + t[2]], yaw_rad: self.goal.yaw_rad + f64::from(c.yaw_rad) }
                };
                // The straight path must stay reachable, checked every 5 mm and 3° (a real
                // driver checks the path its planner makes).
                let dist = distance(self.pose.pos_m, goal.pos_m);
                let n = (dist / 0.005).max((goal.yaw_rad - self.pose.yaw_rad).abs() / 3f64.to_radians()).ceil().clamp(1.0, 2000.0) as u32;
                if let Some(why) = (0..=n).find_map(|k| Self::reachable(lerp(self.pose, goal, f64::from(k) / f64::from(n))).err()) {
                    counts.refused[why as usize] += 1;
                    self.rejected = true;
                    self.reject = why;
                    return; // a refused move leaves the gripper alone too
                }
                self.goal = goal;
                self.speed_mps = if c.speed_limit_mps > 0.0 { f64::from(c.speed_limit_mps).min(MAX_SPEED_MPS) } else { self.default_speed_mps };
                self.arrived = false;
                self.stopped = false;
                self.watchdog_stop = false;
            }
        }
        match gripper {
            GripperCommand::Keep => {}
            GripperCommand::Open => self.gripper_closed = false,
            GripperCommand::Close => self.gripper_closed = true,
        }
        self.accept();
    }

    fn accept(&mut self) {
        self.rejected = false;
        self.reject = RejectReason::None;
    }

    /// A command the subscriber dropped as malformed: refused, reason counted.
    fn malformed(&mut self, counts: &mut Counts) {
        counts.refused[RejectReason::Malformed as usize] += 1;
        self.rejected = true;
        self.reject = RejectReason::Malformed;
    }

    fn moving(&self) -> bool {
        self.pose != self.goal
    }

    /// One control tick of `dt_s`: the watchdog, then motion. A real driver sends the new
    /// set-point to its motion controller here.
    fn advance(&mut self, dt_s: f64, now_ns: u64, counts: &mut Counts) {
        if self.moving() && now_ns.saturating_sub(self.last_command_ns) > self.watchdog_ns {
            // Stale command stream while moving: stop where we are and say why.
            self.goal = self.pose;
            self.watchdog_stop = true;
            counts.watchdog_stops += 1;
        }
        let (p, g) = (self.pose.pos_m, self.goal.pos_m);
        let d = [g[0] - p[0], g[1] - p[1], g[2] - p[2]];
        let dist = distance(p, g);
        let step = self.speed_mps * dt_s;
        self.pose.pos_m = if dist <= step { g } else { [p[0] + d[0] * step / dist, p[1] + d[1] * step / dist, p[2] + d[2] * step / dist] };
        let dyaw = self.goal.yaw_rad - self.pose.yaw_rad;
        let turn = YAW_RATE_RADPS * dt_s;
        self.pose.yaw_rad = if dyaw.abs() <= turn { self.goal.yaw_rad } else { self.pose.yaw_rad + turn * dyaw.signum() };
        if !self.moving() && !self.stopped && !self.watchdog_stop {
            self.arrived = true;
        }
        let target_width = if self.gripper_closed { 0.0 } else { GRIPPER_OPEN_M };
        let jaw_step = GRIPPER_SPEED_MPS * dt_s;
        let before = self.gripper_width_m;
        self.gripper_width_m += (target_width - before).clamp(-jaw_step, jaw_step);
        if self.gripper_width_m == before {
            self.gripper_still_since_ns.get_or_insert(now_ns);
        } else {
            self.gripper_still_since_ns = None;
        }
    }

    /// The state sample of this tick.
    fn state(&mut self, now_ns: u64) -> RobotState {
        self.seq += 1;
        let mut flags = 0;
        if self.moving() || (!self.arrived && !self.stopped && !self.watchdog_stop) {
            flags |= robot_flags::MOVING;
        }
        if self.arrived {
            flags |= robot_flags::ARRIVED;
        }
        if self.rejected {
            flags |= robot_flags::REJECTED;
        }
        if self.gripper_closed {
            flags |= robot_flags::GRIPPER_CLOSED;
        }
        if self.gripper_still_since_ns.is_some_and(|t| now_ns.saturating_sub(t) >= GRIPPER_SETTLE_NS) {
            flags |= robot_flags::GRIPPER_SETTLED;
        }
        if self.watchdog_stop {
            flags |= robot_flags::WATCHDOG_STOP;
        }
        if self.stopped {
            flags |= robot_flags::STOPPED;
        }
        RobotState {
            version: WIRE_VERSION,
            flags,
            seq: self.seq,
            time_ns: now_ns,
            last_command_seq: self.last_command_seq,
            last_command_frame_id: self.last_command_frame_id,
            tool_pos_m: self.pose.pos_m.map(|v| v as f32),
            tool_yaw_rad: self.pose.yaw_rad as f32,
            joints_rad: joints(self.pose),
            gripper_width_m: self.gripper_width_m as f32,
            reject: self.reject as u32,
            fault: 0,
        }
    }
}

/// Joint angles for the state sample: this arm's IK of the tool pose (always reachable: only
/// reachable goals are accepted and paths to them are checked). A real driver reports its
/// encoders.
fn joints(p: Pose) -> [f32; 5] {
    kinematics::ik(p.pos_m, p.yaw_rad).map_or([0.0; 5], |q| q.map(|a| a as f32))
}

fn lerp(a: Pose, b: Pose, s: f64) -> Pose {
    let l = |x: f64, y: f64| x + (y - x) * s;
    Pose { pos_m: [l(a.pos_m[0], b.pos_m[0]), l(a.pos_m[1], b.pos_m[1]), l(a.pos_m[2], b.pos_m[2])], yaw_rad: l(a.yaw_rad, b.yaw_rad) }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let a = a.rem_euclid(t);
    if a > std::f64::consts::PI { a - t } else { a }
}

struct Options {
    home: Pose,
    rate_hz: f64,
    speed_mps: f64,
    watchdog_ms: u64,
    exit_after_s: f64,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options { home: Pose { pos_m: [0.30, 0.0, 0.25], yaw_rad: 0.0 }, rate_hz: 240.0, speed_mps: 0.15, watchdog_ms: 200, exit_after_s: 0.0 };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let mut value = || args.next().ok_or(format!("{flag} needs a value"));
        let number = |v: String, flag: &str| v.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or(format!("{flag}: '{v}' is not a number"));
        match flag.as_str() {
            "--home" => {
                let v = value()?;
                let xyz: Vec<f64> = v.split(',').map(|s| s.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|e| format!("--home {v}: {e}"))?;
                o.home.pos_m = xyz.try_into().map_err(|_| format!("--home wants X,Y,Z in metres, got {v}"))?;
            }
            "--home-yaw-deg" => o.home.yaw_rad = number(value()?, "--home-yaw-deg")?.to_radians(),
            "--rate-hz" => o.rate_hz = number(value()?, "--rate-hz")?,
            "--speed-mps" => o.speed_mps = number(value()?, "--speed-mps")?,
            "--watchdog-ms" => o.watchdog_ms = value()?.parse().map_err(|e| format!("--watchdog-ms: {e}"))?,
            "--exit-after-s" => o.exit_after_s = number(value()?, "--exit-after-s")?,
            other => return Err(format!("unknown flag {other} (see the example's source for its flags)")),
        }
    }
    if o.rate_hz <= 0.0 || o.speed_mps <= 0.0 || o.watchdog_ms == 0 {
        return Err("--rate-hz, --speed-mps and --watchdog-ms must be > 0".into());
    }
    if let Err(why) = Arm::reachable(o.home) {
        return Err(format!("--home {:?} yaw {:.1}°: the arm cannot hold it ({})", o.home.pos_m, o.home.yaw_rad.to_degrees(), why.text()));
    }
    Ok(o)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let o = parse_args()?;
    // 1. Join the domain: one node per process; the state publisher (one per domain) and a
    //    command subscriber (which validates every command and counts what it drops).
    let domain = Domain::from_env()?;
    let node = WireNode::create(&domain, "robot-driver")?;
    let mut states = MessagePublisher::<RobotState>::create(&node)?;
    let mut commands = MessageSubscriber::<RobotCommand>::create(&node)?;
    let mut arm = Arm::new(o.home, o.speed_mps, o.watchdog_ms * 1_000_000);
    let mut counts = Counts::default();
    eprintln!("robot_driver: serving handeye/robot/state at {} Hz in domain '{domain}'", o.rate_hz);

    // 2. The control loop: take every command that came in, advance the arm by the time that
    //    passed, publish the state. Commands wake the loop early, so a Stop acts at once.
    let period = Duration::from_secs_f64(1.0 / o.rate_hz);
    let start = Instant::now();
    let mut last_tick = Instant::now();
    let mut next = last_tick;
    let mut dropped = 0;
    'run: loop {
        next += period;
        loop {
            let left = next.saturating_duration_since(Instant::now());
            match commands.wait(left)? {
                MessageEvent::Message(c) => arm.command(&c, &mut counts),
                MessageEvent::Timeout => break,
                MessageEvent::Interrupted => break 'run,
                MessageEvent::PublisherUp => eprintln!("robot_driver: a command publisher attached"),
                // The daemon left: nothing more will come. The watchdog stops a move under way.
                MessageEvent::PublisherGone => eprintln!("robot_driver: the command publisher left"),
            }
        }
        // Malformed commands never reach `arm.command`: the subscriber dropped and counted
        // them (by reason: version, enum, non_finite, range). Report each as REJECTED.
        let now_dropped = commands.stats().rejected_total();
        for _ in dropped..now_dropped {
            arm.malformed(&mut counts);
        }
        dropped = now_dropped;
        let now = Instant::now();
        arm.advance((now - last_tick).as_secs_f64(), monotonic_ns(), &mut counts);
        last_tick = now;
        states.send(&arm.state(monotonic_ns()))?;
        counts.states += 1;
        if now > next + 10 * period {
            next = now; // fell far behind (machine stalled): do not burst to catch up
        }
        if o.exit_after_s > 0.0 && start.elapsed().as_secs_f64() >= o.exit_after_s {
            break;
        }
    }

    // 3. What happened, for the operator.
    let kinds = ["hold", "move_to", "move_by", "stop", "clear_fault"];
    let by_kind: Vec<String> = kinds.iter().zip(counts.commands).map(|(k, n)| format!("{k} {n}")).collect();
    let reasons = [RejectReason::Unreachable, RejectReason::JointLimit, RejectReason::Malformed];
    let refused: Vec<String> = reasons.iter().map(|&r| format!("{} {}", r.text(), counts.refused[r as usize])).collect();
    let malformed: Vec<String> = MessageReject::KEYS.iter().zip(commands.stats().rejected).map(|(k, n)| format!("{k} {n}")).collect();
    eprintln!(
        "robot_driver: {} states; commands: {}; refused: {} (malformed by field: {}); watchdog stops {}",
        counts.states,
        by_kind.join(", "),
        refused.join(", "),
        malformed.join(", "),
        counts.watchdog_stops
    );
    Ok(())
}

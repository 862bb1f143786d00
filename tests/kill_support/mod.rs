//! The random-kill harness (`tests/kill_random.rs`): which process a seed kills and when, what
//! each case measured, and the bounds it is judged by.
//!
//! Two groups of processes are exercised: the closed loop (`handeye sim --lockstep` and
//! `handeye daemon`, as `handeye run` starts them; [`closed_loop`]) and the camera chain
//! (`handeye camera` on a GStreamer test pattern, `handeye record` and `handeye monitor`;
//! [`camera_chain`]). A seed picks one process of the five and a moment; the case kills it with
//! SIGKILL (no clean-up code runs, as in a crash or an OOM kill), measures how long each
//! survivor takes to notice by its own report, checks that the arm stays where it stopped, and
//! starts the killed process again in the same domain.
#![allow(dead_code)]

pub mod closed_loop;
#[cfg(feature = "camera")]
pub mod camera_chain;

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use handeye_vision::rng::SplitMix64;

/// A subscriber's bound for noticing its publisher gone (wire liveness checks every 100 ms,
/// and the issue allows 500 ms).
pub const PUBLISHER_GONE_MS: f64 = 500.0;
/// The daemon's stale-frame guard (`timing.stale_frame_ms`, default 100 ms): no frame for that
/// long stops the arm. Measured from the kill, the stop can only come later by how long the
/// daemon's thread takes to be scheduled once its wait times out; this allowance is for a
/// shared 2-core machine running other tests (the same 200 ms in all that `e2e_faults`
/// allows). BENCHMARKS.md keeps what was measured.
pub const STALE_FRAME_MS: f64 = 100.0;
pub const SCHEDULING_ALLOWANCE_MS: f64 = 100.0;
/// The simulated arm's command watchdog (`ControllerConfig::watchdog_ns`), in the arm's own
/// clock; its bound adds two control ticks (the scenario's physics step): one to exceed the
/// 200 ms, one because a state is stamped at the end of its step.
pub const WATCHDOG_MS: f64 = 200.0;
/// A tool displacement below this after the arm stopped is sensor-level jitter, not a move.
pub const STILL_M: f32 = 0.001;

/// The processes a seed can kill.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Victim {
    Simulator,
    Daemon,
    Camera,
    Record,
    Monitor,
}

impl Victim {
    pub const ALL: [Victim; 5] = [Victim::Simulator, Victim::Daemon, Victim::Camera, Victim::Record, Victim::Monitor];

    pub fn name(self) -> &'static str {
        match self {
            Victim::Simulator => "sim",
            Victim::Daemon => "daemon",
            Victim::Camera => "camera",
            Victim::Record => "record",
            Victim::Monitor => "monitor",
        }
    }

    /// The processes this build can run: the camera chain needs the `camera` feature.
    pub fn available() -> Vec<Victim> {
        Self::ALL.into_iter().filter(|v| cfg!(feature = "camera") || matches!(v, Victim::Simulator | Victim::Daemon)).collect()
    }
}

/// What a seed decides: the process, and when it dies.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    pub seed: u64,
    pub victim: Victim,
    /// Where in the run the kill comes, in `[0, 1)`: see [`Plan::loop_cycles`] and
    /// [`Plan::camera_delay`].
    pub moment: f64,
}

/// The closed loop is killed after 1 to this many daemon cycles (its telemetry samples):
/// pick_cube lifts the block after about 1100 frames, so every phase up to the grasp can be
/// hit. Counted in cycles, not seconds, so that a loaded machine hits the same phase.
pub const LOOP_CYCLES_MAX: u32 = 1000;
/// The camera chain is in steady state at once: killed up to this long after its first frame.
pub const CAMERA_DELAY_MAX_S: f64 = 3.0;

impl Plan {
    pub fn from_seed(seed: u64) -> Self {
        let mut rng = SplitMix64::new(seed);
        let victims = Victim::available();
        let victim = victims[rng.below(victims.len())];
        Self { seed, victim, moment: rng.next_f64() }
    }

    /// The daemon cycle after which a closed-loop process dies (1 ..= [`LOOP_CYCLES_MAX`]).
    pub fn loop_cycles(&self) -> u32 {
        1 + (self.moment * f64::from(LOOP_CYCLES_MAX)) as u32
    }

    /// How long after the first frame a camera-chain process dies.
    pub fn camera_delay(&self) -> Duration {
        Duration::from_secs_f64(self.moment * CAMERA_DELAY_MAX_S)
    }

    fn moment_text(&self) -> String {
        match self.victim {
            Victim::Simulator | Victim::Daemon => format!("after {} daemon cycles", self.loop_cycles()),
            _ => format!("{:.2} s after the first frame", self.camera_delay().as_secs_f64()),
        }
    }

    /// The first seed at or after `from` that kills each available process: a short run that
    /// still kills every kind of process once.
    pub fn one_per_victim(from: u64) -> Vec<Plan> {
        let mut plans: Vec<Plan> = Vec::new();
        let mut seed = from;
        while plans.len() < Victim::available().len() {
            let p = Plan::from_seed(seed);
            if !plans.iter().any(|q| q.victim == p.victim) {
                plans.push(p);
            }
            seed += 1;
        }
        plans
    }
}

/// How long one survivor took to notice, by its own report, against its bound.
#[derive(Debug, Clone)]
pub struct Detection {
    pub survivor: &'static str,
    pub what: &'static str,
    pub measured_ms: f64,
    pub bound_ms: f64,
    /// How much shorter it may really have been: `measured_ms` is the longest the samples
    /// allow when the report was sampled rather than seen as it was made (robot states: the
    /// test reads the newest four, so some are never seen).
    pub sampling_ms: f64,
}

impl Detection {
    pub fn new(survivor: &'static str, what: &'static str, measured_ms: f64, bound_ms: f64) -> Self {
        Self { survivor, what, measured_ms, bound_ms, sampling_ms: 0.0 }
    }

    /// Noticed too late for certain: even at the earliest moment the samples allow. A
    /// survivor that never noticed (NaN or infinite) is late too.
    pub fn late(&self) -> bool {
        let earliest = self.measured_ms - self.sampling_ms;
        earliest.is_nan() || earliest > self.bound_ms
    }
}

/// Everything one case measured.
#[derive(Debug, Clone)]
pub struct CaseResult {
    pub plan: Plan,
    /// What the system was doing when the kill came (a phase, or "streaming").
    pub at: String,
    pub detections: Vec<Detection>,
    /// Robot states after the arm had stopped that put the tool more than [`STILL_M`] away
    /// (`None` when the arm was not involved).
    pub moves_after_death: Option<u32>,
    /// Whether the arm was moving when its commander died (a watchdog stop was due).
    pub arm_was_moving: Option<bool>,
    pub restart_ok: bool,
    /// Fresh starts of the set-up before the kill (a daemon that stopped on its own first).
    pub setup_retries: u32,
    pub notes: Vec<String>,
}

impl CaseResult {
    pub fn new(plan: Plan) -> Self {
        Self { plan, at: String::new(), detections: Vec::new(), moves_after_death: None, arm_was_moving: None, restart_ok: false, setup_retries: 0, notes: Vec::new() }
    }

    /// Every way this case broke the rules, in words (empty = passed).
    pub fn violations(&self) -> Vec<String> {
        let mut v = Vec::new();
        for d in &self.detections {
            if d.late() {
                v.push(format!("{} noticed ({}) after {:.0} ms (sampled to {:.0} ms), bound {:.0} ms", d.survivor, d.what, d.measured_ms, d.sampling_ms, d.bound_ms));
            }
        }
        if let Some(n) = self.moves_after_death
            && n > 0
        {
            v.push(format!("the arm moved in {n} state(s) after it had stopped"));
        }
        if !self.restart_ok {
            v.push(format!("restarting {} in the same domain failed", self.plan.victim.name()));
        }
        v
    }

    pub fn describe(&self) -> String {
        let mut s = format!("seed {} killed {} {} ({})", self.plan.seed, self.plan.victim.name(), self.plan.moment_text(), self.at);
        for d in &self.detections {
            let _ = write!(s, "; {} {} {:.0} ms", d.survivor, d.what, d.measured_ms);
            if d.sampling_ms > 0.0 {
                let _ = write!(s, " (-{:.0} sampling)", d.sampling_ms);
            }
            let _ = write!(s, " (<= {:.0})", d.bound_ms);
        }
        if let Some(m) = self.moves_after_death {
            let _ = write!(s, "; moves after stop {m}");
        }
        let _ = write!(s, "; restart {}", if self.restart_ok { "ok" } else { "FAILED" });
        for n in &self.notes {
            let _ = write!(s, "; {n}");
        }
        s
    }
}

/// Runs one seed's case.
pub fn run_case(plan: Plan) -> CaseResult {
    match plan.victim {
        Victim::Simulator | Victim::Daemon => closed_loop::run(plan),
        #[cfg(feature = "camera")]
        Victim::Camera | Victim::Record | Victim::Monitor => camera_chain::run(plan),
        #[cfg(not(feature = "camera"))]
        _ => unreachable!("Victim::available() leaves the camera chain out without the camera feature"),
    }
}

/// The BENCHMARKS.md table: per process killed, cases, detection p50/max per survivor, moves
/// after death and restarts.
pub fn table(results: &[CaseResult]) -> String {
    let mut out = String::from(
        "| killed | cases | survivor: what it noticed | detection p50 / max (ms) | of which sampling, max (ms) | bound (ms) | arm moving at kill | moves after stop | restarts ok |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for victim in Victim::available() {
        let cases: Vec<&CaseResult> = results.iter().filter(|r| r.plan.victim == victim).collect();
        if cases.is_empty() {
            continue;
        }
        let mut survivors: Vec<(&str, &str, f64)> = Vec::new();
        for d in cases.iter().flat_map(|c| &c.detections) {
            if !survivors.iter().any(|s| s.0 == d.survivor && s.1 == d.what) {
                survivors.push((d.survivor, d.what, d.bound_ms));
            }
        }
        let moving = cases.iter().filter(|c| c.arm_was_moving == Some(true)).count();
        let arm = cases.iter().any(|c| c.arm_was_moving.is_some());
        let moves: u32 = cases.iter().filter_map(|c| c.moves_after_death).sum();
        let restarts = cases.iter().filter(|c| c.restart_ok).count();
        let rows = if survivors.is_empty() { vec![("-", "-", f64::NAN)] } else { survivors };
        for (i, (survivor, what, bound)) in rows.iter().enumerate() {
            let ds: Vec<&Detection> = cases.iter().flat_map(|c| &c.detections).filter(|d| d.survivor == *survivor && d.what == *what).collect();
            let mut ms: Vec<f64> = ds.iter().map(|d| d.measured_ms).collect();
            let sampling = ds.iter().map(|d| d.sampling_ms).fold(0.0, f64::max);
            let sampling = if sampling > 0.0 { format!("{sampling:.0}") } else { "-".to_owned() };
            ms.sort_by(f64::total_cmp);
            let stat = if ms.is_empty() { "-".to_owned() } else { format!("{:.0} / {:.0}", ms[(ms.len() - 1) / 2], ms[ms.len() - 1]) };
            let (name, n, mv, mvs, rs) = if i == 0 {
                (
                    victim.name().to_owned(),
                    cases.len().to_string(),
                    if arm { format!("{moving} of {}", cases.len()) } else { "-".into() },
                    if arm { moves.to_string() } else { "-".into() },
                    format!("{restarts} of {}", cases.len()),
                )
            } else {
                Default::default()
            };
            let _ = writeln!(out, "| {name} | {n} | {survivor}: {what} | {stat} | {sampling} | {bound:.0} | {mv} | {mvs} | {rs} |");
        }
    }
    out
}

/// Polls `f` every 10 ms until it gives `Some`, or `timeout` passes.
pub fn poll<T>(timeout: Duration, mut f: impl FnMut() -> Option<T>) -> Option<T> {
    let t0 = Instant::now();
    loop {
        if let Some(v) = f() {
            return Some(v);
        }
        if t0.elapsed() >= timeout {
            return None;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Milliseconds from `from_ns` to `to_ns` (CLOCK_MONOTONIC), negative if `to` came first.
pub fn ms_between(from_ns: u64, to_ns: u64) -> f64 {
    (to_ns as i128 - from_ns as i128) as f64 * 1e-6
}

//! Running the simulator against a transport: lockstep (publish frame N, wait for the
//! daemon's command stamped N or a time-out, then step physics by one frame period; with no
//! daemon attached it steps straight on) and real time (frames at the camera rate, stamped
//! with their capture time, commands applied as they arrive).
//!
//! [`Runner`] is the part without I/O (simulate, render, hash); [`Transport`] is whatever
//! carries frames, state and commands (iceoryx2 services in `handeye sim`, or nothing).

use std::time::{Duration, Instant};

use handeye_wire::{RobotCommand, RobotState, Telemetry};

use crate::hash::FramesHash;
use crate::render::{RenderError, Renderer};
use crate::simulator::Simulator;

/// Describes one published stereo frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameMeta {
    pub frame_id: u64,
    /// Simulated time of the frame, ns.
    pub sim_time_ns: u64,
    pub width: u32,
    pub height: u32,
}

/// Why a run stopped early.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error("transport: {0}")]
    Transport(String),
    /// SIGINT/SIGTERM: the run ends cleanly.
    #[error("interrupted")]
    Interrupted,
}

/// Carries frames and robot state out and commands in.
pub trait Transport {
    /// Publishes one frame; `fill` renders it into the payload buffer it is given
    /// (`2 * width * height` bytes, left rows then right rows). Returns the frame id the
    /// frame went out with (what a lockstep reply must carry).
    fn publish_frame(&mut self, meta: &FrameMeta, fill: &mut dyn FnMut(&mut [u8]) -> Result<(), RenderError>) -> Result<u64, RunError>;
    fn publish_state(&mut self, state: &RobotState) -> Result<(), RunError>;
    /// Appends the commands that have arrived (without blocking).
    fn receive_commands(&mut self, out: &mut Vec<RobotCommand>) -> Result<(), RunError>;
    /// Blocks until a command may have arrived, or `timeout` passes.
    fn wait_for_commands(&mut self, timeout: Duration) -> Result<(), RunError>;
    /// Whether anyone publishes commands (a daemon is attached).
    fn daemon_attached(&mut self) -> bool;
    /// Whether the process was asked to stop (SIGINT/SIGTERM).
    fn interrupted(&self) -> bool {
        false
    }
    /// Appends the daemon's telemetry samples that have arrived (without blocking), for the
    /// [`DaemonWatch`](crate::referee::watch::DaemonWatch). A transport without telemetry has none.
    fn receive_telemetry(&mut self, _out: &mut Vec<Telemetry>) -> Result<(), RunError> {
        Ok(())
    }
    /// With an external robot driver, its newest state (`None` without one, or before its
    /// first). `answering = Some(n)` (lockstep): first wait up to `timeout` for a state in
    /// which the driver has processed the command that answered frame `n`.
    fn external_robot_state(&mut self, _answering: Option<u64>, _timeout: Duration) -> Result<Option<RobotState>, RunError> {
        Ok(None)
    }
}

/// A transport that carries nothing: frames are rendered (and hashed) but go nowhere, and
/// no commands arrive. Used by `handeye bench render` and by tests.
pub struct NoTransport {
    buffer: Vec<u8>,
}

impl NoTransport {
    pub fn new() -> Self {
        Self { buffer: Vec::new() }
    }
}

impl Default for NoTransport {
    fn default() -> Self {
        Self::new()
    }
}

impl Transport for NoTransport {
    fn publish_frame(&mut self, meta: &FrameMeta, fill: &mut dyn FnMut(&mut [u8]) -> Result<(), RenderError>) -> Result<u64, RunError> {
        self.buffer.resize((meta.width * meta.height * 2) as usize, 0);
        fill(&mut self.buffer)?;
        Ok(meta.frame_id)
    }
    fn publish_state(&mut self, _: &RobotState) -> Result<(), RunError> {
        Ok(())
    }
    fn receive_commands(&mut self, _: &mut Vec<RobotCommand>) -> Result<(), RunError> {
        Ok(())
    }
    fn wait_for_commands(&mut self, _: Duration) -> Result<(), RunError> {
        Ok(())
    }
    fn daemon_attached(&mut self) -> bool {
        false
    }
}

/// An in-process source of commands that answers every frame (instead of a daemon on the
/// transport): the ground-truth scripted pick ([`crate::referee::script::GroundTruthPick`]) is one.
pub trait Driver {
    /// The command answering frame `frame_id`, or `None` to send nothing.
    fn command(&mut self, sim: &mut Simulator, frame_id: u64) -> Option<RobotCommand>;
}

impl Driver for crate::referee::script::GroundTruthPick {
    fn command(&mut self, sim: &mut Simulator, frame_id: u64) -> Option<RobotCommand> {
        Some(self.next_command(sim, frame_id))
    }
}

/// Simulation + rendering + the hash over every published pixel.
pub struct Runner {
    pub sim: Simulator,
    pub renderer: Renderer,
    poses: Vec<Option<glam::DAffine3>>,
    pub hash: FramesHash,
    /// Hash of each published frame, in order (kept only when `keep_frame_hashes`).
    pub frame_hashes: Vec<u64>,
    pub keep_frame_hashes: bool,
    /// What the daemon claims, judged from ground truth.
    pub watch: crate::referee::watch::DaemonWatch,
    ids: Vec<u32>,
    telemetry: Vec<Telemetry>,
}

impl Runner {
    pub fn new(sim: Simulator) -> Result<Self, RenderError> {
        let renderer = Renderer::for_scene_with(&sim.scene, &sim.events.cameras, sim.scenario.render.antialias)?;
        Ok(Self {
            sim,
            renderer,
            poses: Vec::new(),
            hash: FramesHash::default(),
            frame_hashes: Vec::new(),
            keep_frame_hashes: false,
            watch: crate::referee::watch::DaemonWatch::default(),
            ids: Vec::new(),
            telemetry: Vec::new(),
        })
    }

    /// Metadata of the frame the current state would give.
    pub fn meta(&self) -> FrameMeta {
        FrameMeta {
            frame_id: self.sim.frames(),
            sim_time_ns: self.sim.now_ns(),
            width: self.renderer.width(),
            height: self.renderer.height(),
        }
    }

    /// Renders the current state into `out` and hashes it.
    pub fn render_into(&mut self, out: &mut [u8]) -> Result<(), RenderError> {
        self.sim.object_poses(&mut self.poses);
        let frame = self.sim.frame_input(&self.poses);
        self.renderer.render(&frame, out)?;
        let h = self.hash.add(out);
        if self.keep_frame_hashes {
            self.frame_hashes.push(h);
        }
        Ok(())
    }

    /// Visible pixels of face `face` of block `block` now, per view (face-id pass).
    pub fn face_visible_px(&mut self, block: usize, face: usize) -> Result<[u32; 2], RenderError> {
        self.sim.object_poses(&mut self.poses);
        let frame = self.sim.frame_input(&self.poses);
        let n = (self.renderer.width() * self.renderer.height()) as usize;
        self.ids.resize(2 * n, 0);
        self.renderer.render_ids(&frame, &mut self.ids)?;
        let id = crate::render::scene::block_face_id(block, face);
        Ok([0, 1].map(|v| self.ids[v * n..(v + 1) * n].iter().filter(|&&x| x == id).count() as u32))
    }

    /// Reads the daemon's telemetry that has arrived and judges it at frame `frame`; while an
    /// occluder crosses the scene, renders the face-id pass to see whether it hides the target.
    pub fn watch_daemon(&mut self, transport: &mut dyn Transport, frame: u64) -> Result<(), RunError> {
        self.telemetry.clear();
        transport.receive_telemetry(&mut self.telemetry)?;
        for t in &self.telemetry {
            self.watch.telemetry(&self.sim, frame, t);
        }
        let now = self.sim.now_ns();
        let occluded = (0..self.sim.scenario.events.len()).any(|i| self.sim.events.occluder_position(i, now).is_some());
        if occluded
            && self.watch.wants_visibility()
            && let Some(f) = self.watch.facet()
        {
            let px = self.face_visible_px(f.block, f.face)?;
            self.watch.visibility(frame, px);
        }
        Ok(())
    }

    /// Renders and publishes the current frame and the robot state; the returned meta
    /// carries the frame id the transport used.
    pub fn publish(&mut self, transport: &mut dyn Transport) -> Result<FrameMeta, RunError> {
        let mut meta = self.meta();
        meta.frame_id = transport.publish_frame(&meta, &mut |buf| self.render_into(buf))?;
        let state = self.sim.robot_state();
        transport.publish_state(&state)?;
        Ok(meta)
    }

    /// With an external robot driver: poses the arm over the next frame where the driver's
    /// newest state says (see [`Transport::external_robot_state`]).
    fn follow_driver(&mut self, transport: &mut dyn Transport, answering: Option<u64>, timeout: Duration) -> Result<(), RunError> {
        if self.sim.follower.is_none() {
            return Ok(());
        }
        match transport.external_robot_state(answering, timeout)? {
            Some(s) => self.sim.external_state(&s),
            None if self.sim.frames() == 30 => tracing::warn!(
                "no robot state from an external driver after 30 frames: is one publishing handeye/robot/state in this domain? \
                 The arm stays at its home pose"
            ),
            None => {}
        }
        Ok(())
    }

    /// One frame period of physics, publishing the robot state after every step (the
    /// controller reports once per control tick). `before_step` runs before each step.
    fn step_frame_publishing(
        &mut self,
        transport: &mut dyn Transport,
        mut before_step: impl FnMut(&mut Simulator, &mut dyn Transport) -> Result<(), RunError>,
    ) -> Result<(), RunError> {
        for _ in 0..self.sim.scenario.substeps_per_frame() {
            before_step(&mut self.sim, transport)?;
            self.sim.step();
            let state = self.sim.robot_state();
            transport.publish_state(&state)?;
        }
        self.sim.count_frame();
        Ok(())
    }
}

/// Options of a run.
#[derive(Debug, Clone, Copy)]
pub struct RunOptions {
    /// Frames to publish; `None` = until the scenario's time-out or success.
    pub frames: Option<u64>,
    /// Lockstep: longest wait for the daemon's command for a frame.
    pub reply_timeout: Duration,
    /// Without `frames`: stop as soon as the success rule is met (else at the time-out).
    pub stop_on_success: bool,
}

/// What a run did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RunStats {
    pub frames: u64,
    pub wall_s: f64,
    /// Frames per wall-clock second.
    pub fps: f64,
    pub frames_hash: u64,
    pub commands: u64,
    /// Lockstep frames whose reply did not come in time.
    pub reply_timeouts: u64,
    /// Real time: frames published later than their slot.
    pub late_frames: u64,
}

fn done(runner: &Runner, options: &RunOptions, published: u64) -> bool {
    use crate::referee::judge::Verdict;
    match (options.frames, runner.sim.verdict()) {
        (Some(n), _) => published >= n,
        (None, Verdict::TimedOut) => true,
        (None, Verdict::Success { .. }) => options.stop_on_success,
        (None, Verdict::Pending) => false,
    }
}

/// Lockstep: publish frame N, wait for a command stamped N (or the time-out; at once if no
/// daemon is attached), apply the commands, step one frame period. Deterministic for a seed.
/// With a `driver`, its command answers each frame and nothing waits for the transport
/// (commands arriving there, e.g. an operator's Stop, still apply). With an external robot
/// driver (`Simulator::follow_external_robot`) frames go out no faster than real time, and
/// after the daemon's answer the simulator waits for the driver to report it processed.
pub fn run_lockstep(
    runner: &mut Runner,
    transport: &mut dyn Transport,
    options: &RunOptions,
    mut driver: Option<&mut dyn Driver>,
) -> Result<RunStats, RunError> {
    let start = Instant::now();
    let mut stats = RunStats::default();
    let mut commands = Vec::new();
    let result = (|| {
        while !done(runner, options, stats.frames) && !transport.interrupted() {
            if runner.sim.follower.is_some() {
                // An external robot driver moves on the wall clock: never let simulated time
                // run ahead of it (a quick renderer would make the driver's arm look slow).
                let due = start + Duration::from_nanos(runner.sim.now_ns());
                let now = Instant::now();
                if due > now {
                    std::thread::sleep(due - now);
                }
            }
            let meta = runner.publish(transport)?;
            stats.frames += 1;
            let deadline = Instant::now() + options.reply_timeout;
            let mut answered = driver.is_some() || !transport.daemon_attached();
            let mut replied = false;
            if let Some(d) = driver.as_mut()
                && let Some(c) = d.command(&mut runner.sim, meta.frame_id)
            {
                runner.sim.command(&c);
                stats.commands += 1;
            }
            loop {
                commands.clear();
                transport.receive_commands(&mut commands)?;
                for c in &commands {
                    runner.watch.command(meta.frame_id, c);
                    runner.sim.command(c);
                    stats.commands += 1;
                    replied |= c.frame_id == meta.frame_id;
                    answered |= replied;
                }
                if answered {
                    break;
                }
                let now = Instant::now();
                if now >= deadline {
                    stats.reply_timeouts += 1;
                    break;
                }
                transport.wait_for_commands(deadline - now)?;
                if !transport.daemon_attached() {
                    break; // the daemon left while we waited
                }
            }
            // The daemon sends its telemetry before the command that answers the frame, so
            // what it says about frame N is here now, and the arm is still where frame N
            // showed it.
            runner.watch_daemon(transport, meta.frame_id)?;
            runner.follow_driver(transport, replied.then_some(meta.frame_id), options.reply_timeout)?;
            runner.step_frame_publishing(transport, |_, _| Ok(()))?;
        }
        Ok(())
    })();
    match result {
        Ok(()) | Err(RunError::Interrupted) => finish(runner, stats, start),
        Err(e) => Err(e),
    }
}

/// Real time: one frame per camera period of wall-clock time; commands are applied at the
/// next physics step after they arrive. A `driver` answers each frame as it is published.
pub fn run_realtime(
    runner: &mut Runner,
    transport: &mut dyn Transport,
    options: &RunOptions,
    mut driver: Option<&mut dyn Driver>,
) -> Result<RunStats, RunError> {
    let start = Instant::now();
    let period = Duration::from_secs_f64(1.0 / f64::from(runner.sim.scenario.render.frame_rate_hz));
    let mut stats = RunStats::default();
    let mut commands = Vec::new();
    let mut next = start;
    let result = (|| {
        while !done(runner, options, stats.frames) && !transport.interrupted() {
            let meta = runner.publish(transport)?;
            stats.frames += 1;
            next += period;
            let mut received = 0;
            if let Some(d) = driver.as_mut()
                && let Some(c) = d.command(&mut runner.sim, meta.frame_id)
            {
                runner.sim.command(&c);
                received += 1;
            }
            let mut stops = 0u32;
            runner.follow_driver(transport, None, Duration::ZERO)?;
            runner.step_frame_publishing(transport, |sim, transport| {
                commands.clear();
                transport.receive_commands(&mut commands)?;
                for c in &commands {
                    stops += u32::from(c.kind == handeye_wire::CommandKind::Stop as u32);
                    sim.command(c);
                    received += 1;
                }
                Ok(())
            })?;
            if stops > 0 {
                let stop = RobotCommand { kind: handeye_wire::CommandKind::Stop as u32, ..RobotCommand::default() };
                runner.watch.command(meta.frame_id, &stop);
            }
            runner.watch_daemon(transport, meta.frame_id)?;
            stats.commands += received;
            let now = Instant::now();
            if now > next {
                stats.late_frames += 1;
                next = now; // a camera does not catch up in a burst
            } else {
                // Sleep until the next frame (commands that arrive meanwhile wait in the
                // queue and act at the next step).
                std::thread::sleep(next - now);
            }
        }
        Ok(())
    })();
    match result {
        Ok(()) | Err(RunError::Interrupted) => finish(runner, stats, start),
        Err(e) => Err(e),
    }
}

fn finish(runner: &Runner, mut stats: RunStats, start: Instant) -> Result<RunStats, RunError> {
    stats.wall_s = start.elapsed().as_secs_f64();
    stats.fps = if stats.wall_s > 0.0 { stats.frames as f64 / stats.wall_s } else { 0.0 };
    stats.frames_hash = runner.hash.value;
    Ok(stats)
}

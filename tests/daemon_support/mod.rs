//! In-process closed loop for daemon tests: the simulator renders each frame into a buffer,
//! the daemon's [`HardLoop`] answers it, the command goes straight to the simulator. Same
//! code as the two-process run, minus shared memory, so tests can look inside the loop.
#![allow(dead_code)]

use std::path::Path;

use handeye_daemon::{DaemonConfig, HardLoop, OperatorHint};
use handeye_sim::referee::hint::{operator_hint, HintFacet};
use handeye_sim::run::Runner;
use handeye_sim::{Scenario, Simulator};
use handeye_vision::image::ImageView;
use handeye_wire::RobotCommand;

pub struct InProcess {
    pub runner: Runner,
    pub daemon: HardLoop,
    pub facet: HintFacet,
    pub hint: OperatorHint,
    buf: Vec<u8>,
    pub frame: u64,
}

pub fn scenario(file: &str) -> Scenario {
    Scenario::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios").join(file)).unwrap()
}

impl InProcess {
    pub fn new(scenario: Scenario, cfg: DaemonConfig) -> Self {
        let runner = Runner::new(Simulator::new(scenario).unwrap()).unwrap();
        let (h, facet) = operator_hint(&runner.sim, runner.sim.scenario.seed).unwrap();
        let text = serde_json::to_string(&h).unwrap();
        let hint = OperatorHint::parse(&text, Path::new("hint.json")).unwrap();
        let daemon = HardLoop::new(cfg, Some(hint.clone())).unwrap();
        let mut runner = runner;
        runner.watch.set_facet(facet);
        let n = (runner.renderer.width() * runner.renderer.height() * 2) as usize;
        Self { runner, daemon, facet, hint, buf: vec![0; n], frame: 0 }
    }

    /// The same loop with the daemon planning its own grasp (no hint): the indicated point
    /// is the scenario's (`[task] point_m`, or the named target's centre).
    pub fn planning(scenario: Scenario, cfg: DaemonConfig) -> Self {
        let point = scenario.indicated_point_m();
        let mut run = Self::new(scenario, cfg.clone());
        run.daemon = HardLoop::new(cfg, None).unwrap();
        run.daemon.set_indicated_point(Some(point));
        run
    }

    /// One frame: render, robot state, daemon cycle, command, physics. Returns the command.
    /// `inside` runs around the daemon's cycle only (e.g. to count its allocations).
    pub fn step_with(&mut self, inside: &mut dyn FnMut(&mut dyn FnMut())) -> RobotCommand {
        self.runner.render_into(&mut self.buf).unwrap();
        let state = self.runner.sim.robot_state();
        self.daemon.robot_state(&state);
        let (w, h) = (self.runner.renderer.width() as usize, self.runner.renderer.height() as usize);
        let (l, r) = self.buf.split_at(w * h);
        let left = ImageView::new(l, w, h, w).unwrap();
        let right = ImageView::new(r, w, h, w).unwrap();
        let frame = self.frame;
        // Stamped as the simulator's transport stamps its frames: simulated time.
        let capture_time_ns = self.runner.sim.now_ns();
        let daemon = &mut self.daemon;
        let mut cmd = RobotCommand::default();
        inside(&mut || {
            cmd = daemon.cycle(frame, capture_time_ns, &left, &right).command;
            daemon.finish_cycle(1);
        });
        let t = *self.daemon.telemetry();
        self.runner.watch.telemetry(&self.runner.sim, frame, &t);
        self.runner.watch.command(frame, &cmd);
        self.runner.sim.command(&cmd);
        self.runner.sim.step_frame();
        self.frame += 1;
        cmd
    }

    pub fn step(&mut self) -> RobotCommand {
        self.step_with(&mut |f| f())
    }
}

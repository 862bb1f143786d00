//! The simulator without I/O: physics, the arm's controller, scripted events and the success
//! judge, advanced in fixed steps of simulated time. Rendering ([`crate::render`]) and the
//! transport loop ([`crate::run`]) sit on top.
//!
//! Determinism: the step is fixed, commands take effect only at step boundaries, events fire
//! on simulated time, and nothing reads the wall clock, so the same scenario and the same
//! commands give bit-identical results on one machine.

use glam::{DAffine3, DVec3};
use handeye_wire::{RobotCommand, RobotState};

use crate::cell::arm::ArmReading;
use crate::cell::controller::{Controller, ControllerConfig};
use crate::cell::follower::Follower;
use crate::cell::kinematics::{IkError, ToolPose};
use crate::cell::world::World;
use crate::events::EventState;
use crate::pointer::{PointerGesture, PointerOperator};
use crate::referee::judge::{SuccessJudge, Verdict};
use crate::render::scene::{Attach, Scene};
use crate::render::{FrameInput, Sensor};
use crate::scenario::Scenario;

/// Why a simulator could not be built.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("scenario {scenario:?}: the arm's home pose is not reachable: {source}")]
    HomeUnreachable { scenario: String, source: IkError },
}

/// A running simulation.
pub struct Simulator {
    pub scenario: Scenario,
    pub world: World,
    pub controller: Controller,
    pub events: EventState,
    pub scene: Scene,
    /// With an external robot driver: the motors follow its reported pose, and the
    /// controller above is idle (see [`Self::follow_external_robot`]).
    pub follower: Option<Follower>,
    /// The operator's pointing gesture (`[pointer]`), if any.
    pub pointer: Option<PointerGesture>,
    /// The person pointing: repeats a gesture the robot did not react to.
    pub operator: Option<PointerOperator>,
    judge: SuccessJudge,
    target: usize,
    reading: ArmReading,
    steps: u64,
    frames: u64,
}

impl Simulator {
    /// Builds the work cell of `scenario`, the arm at its home pose with the gripper open.
    pub fn new(scenario: Scenario) -> Result<Self, SimError> {
        let home = ToolPose { pos_m: DVec3::from_array(scenario.arm.home_m), yaw_rad: scenario.arm.home_yaw_deg.to_radians() };
        let cfg = ControllerConfig { default_speed_mps: scenario.arm.default_speed_mps, ..ControllerConfig::default() };
        let controller = Controller::new(cfg, home)
            .map_err(|source| SimError::HomeUnreachable { scenario: scenario.name.clone(), source })?;
        let world = World::new(&scenario, controller.joint_setpoint());
        let target = scenario.target_index();
        let judge = SuccessJudge::new(&scenario.success, world.blocks[target].rest_z_m);
        let reading = world.arm.read(&world.physics);
        let events = EventState::new(&scenario);
        let scene = Scene::build(&scenario, &world);
        let pointer = PointerGesture::of_scenario(&scenario);
        let operator = PointerOperator::of_scenario(&scenario);
        Ok(Self { scenario, world, controller, events, scene, follower: None, pointer, operator, judge, target, reading, steps: 0, frames: 0 })
    }

    /// Simulated time now, ns (exact: steps × 10⁹ / rate).
    pub fn now_ns(&self) -> u64 {
        (u128::from(self.steps) * 1_000_000_000 / u128::from(self.scenario.physics.rate_hz)) as u64
    }

    /// Physics steps taken so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Frames completed so far ([`Self::step_frame`] calls).
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// From now on the arm follows an external robot driver's reported pose
    /// ([`Self::external_state`]) instead of the simulator's controller, which then ignores
    /// commands: they are the driver's to carry out.
    pub fn follow_external_robot(&mut self) -> Result<(), IkError> {
        let home = ToolPose { pos_m: DVec3::from_array(self.scenario.arm.home_m), yaw_rad: self.scenario.arm.home_yaw_deg.to_radians() };
        self.follower = Some(Follower::new(home)?);
        Ok(())
    }

    /// The external driver's newest state, reached over the next frame's physics steps.
    pub fn external_state(&mut self, s: &RobotState) {
        let steps = self.scenario.substeps_per_frame();
        if let Some(f) = self.follower.as_mut() {
            f.follow(s, steps);
            if f.states == 1 && f.jump_m() > 0.01 {
                tracing::warn!(
                    "the robot driver's tool is {:.0} mm from the simulated arm's home {:?}: start the driver at the scenario's [arm] home_m and home_yaw_deg",
                    f.jump_m() * 1e3,
                    self.scenario.arm.home_m
                );
            }
        }
    }

    /// Hands a command to the controller; it takes effect at the next step. Ignored while an
    /// external driver moves the arm.
    pub fn command(&mut self, cmd: &RobotCommand) {
        if self.follower.is_some() {
            return;
        }
        let now = self.now_ns();
        self.controller.command(cmd, now, &self.reading);
    }

    /// One physics step: events, controller tick, motors, physics, sensors, judge.
    pub fn step(&mut self) {
        let now = self.now_ns();
        self.events.update(now, &mut self.world);
        let dt = self.scenario.physics_dt_s();
        let targets = match self.follower.as_mut() {
            Some(f) => f.tick(),
            None => self.controller.tick(now, dt, &self.reading),
        };
        self.world.arm.drive(&mut self.world.physics, &targets);
        self.world.step();
        self.steps += 1;
        self.reading = self.world.arm.read(&self.world.physics);
        let z = self.block_pose(self.target).1.translation.z;
        self.judge.observe(self.now_ns(), z);
        let now = self.now_ns();
        if let (Some(op), Some(g)) = (self.operator.as_mut(), self.pointer.as_mut())
            && let Some(next) = op.watch(now, g, self.reading.tool_m)
        {
            op.earlier.push(std::mem::replace(g, next));
        }
    }

    /// Counts a frame whose physics steps were taken one by one with [`Self::step`].
    pub fn count_frame(&mut self) {
        self.frames += 1;
    }

    /// Advances one camera frame period (`physics.rate_hz / render.frame_rate_hz` steps).
    pub fn step_frame(&mut self) {
        for _ in 0..self.scenario.substeps_per_frame() {
            self.step();
        }
        self.frames += 1;
    }

    /// The robot state the controller reports now.
    pub fn robot_state(&mut self) -> RobotState {
        let now = self.now_ns();
        self.controller.state(now, &self.reading)
    }

    /// The latest sensor reading of the arm (physical truth).
    pub fn arm_reading(&self) -> &ArmReading {
        &self.reading
    }

    /// Index of the target block.
    pub fn target_index(&self) -> usize {
        self.target
    }

    /// Name and pose (robot frame) of block `i`.
    pub fn block_pose(&self, i: usize) -> (&str, DAffine3) {
        let b = &self.world.blocks[i];
        let (pos, rot) = self.world.body_pose(b.body);
        (&b.name, DAffine3::from_mat3_translation(rot, pos))
    }

    /// The success verdict so far.
    pub fn verdict(&self) -> Verdict {
        self.judge.verdict()
    }

    /// The judge (lift and hold so far).
    pub fn judge(&self) -> &SuccessJudge {
        &self.judge
    }

    /// Sensor models of the two cameras.
    pub fn sensors(&self) -> [Sensor; 2] {
        let s = |i: usize| Sensor {
            noise_sigma: self.scenario.cameras[i].noise_sigma,
            blur_sigma_px: self.scenario.cameras[i].blur_sigma_px,
        };
        [s(0), s(1)]
    }

    /// What to render now; `poses` from [`Self::object_poses`]. The noise seed depends only
    /// on the scenario seed and the frame count, so frames are reproducible.
    pub fn frame_input<'a>(&'a self, poses: &'a [Option<DAffine3>]) -> FrameInput<'a> {
        FrameInput {
            scene: &self.scene,
            poses,
            cameras: &self.events.cameras,
            lighting: &self.events.lighting,
            background: self.scenario.render.background,
            sensors: self.sensors(),
            noise_seed: handeye_vision::rng::mix64(self.scenario.seed) ^ self.frames,
        }
    }

    /// Pose of every scene object now (`None`: not drawn, e.g. an occluder not crossing).
    pub fn object_poses(&self, out: &mut Vec<Option<DAffine3>>) {
        out.clear();
        let now = self.now_ns();
        for o in &self.scene.objects {
            out.push(match o.attach {
                Attach::Fixed(a) => Some(a),
                Attach::Body(h) => {
                    let (pos, rot) = self.world.body_pose(h);
                    Some(DAffine3::from_mat3_translation(rot, pos))
                }
                Attach::Occluder(i) => self.events.occluder_position(i, now).map(DAffine3::from_translation),
                Attach::Pointer => self.pointer.as_ref().and_then(|p| p.pose(now)),
            });
        }
    }
}

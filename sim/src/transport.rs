//! The simulator on the shared-memory services (`wire/README.md`): it publishes stereo frames
//! on `handeye/stereo` (rendered straight into the loaned sample) and the robot state on
//! `handeye/robot/state`, and takes commands from `handeye/robot/command`, exactly as a
//! camera pair and a robot controller would.
//!
//! With an external robot ([`RobotSide::External`], `handeye sim --robot external`) it is the
//! camera pair only: a robot driver (e.g. `wire/examples/robot_driver.rs`) serves the robot
//! services, and the simulator subscribes to its state to pose the arm it renders. It still
//! reads the commands, only to know when the daemon has answered a lockstep frame and to
//! judge the daemon; it never carries them out.

use std::collections::VecDeque;
use std::time::Duration;

use handeye_wire::message::{MessageEvent, MessagePublisher, MessageSubscriber};
use handeye_wire::stereo::{Delivery, StereoFormat, StereoPublisher, StereoPublisherOptions};
use handeye_wire::{Domain, RobotCommand, RobotState, Telemetry, WireNode};

use crate::render::RenderError;
use crate::run::{FrameMeta, RunError, Transport};

/// Why the services could not be joined.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error(transparent)]
    Node(#[from] handeye_wire::NodeError),
    #[error(transparent)]
    Stereo(#[from] handeye_wire::stereo::StereoPublisherError),
    #[error(transparent)]
    Message(#[from] handeye_wire::message::MessagePortError),
}

/// Who serves the robot services.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RobotSide {
    /// The simulator's own controller: it publishes the state and carries out the commands.
    #[default]
    Simulated,
    /// An external driver: the simulator subscribes to its state and poses the arm there.
    External,
}

/// The robot state port: published by the simulator, or read from an external driver.
enum StatePort {
    Publisher(MessagePublisher<RobotState>),
    Subscriber { states: Box<MessageSubscriber<RobotState>>, newest: Option<RobotState> },
}

/// Publisher of frames and state, subscriber of commands, in one domain.
pub struct WireTransport {
    // Ports before the node: they are dropped first.
    frames: StereoPublisher,
    state: StatePort,
    commands: MessageSubscriber<RobotCommand>,
    /// The daemon's telemetry, read only to judge it against ground truth.
    telemetry: MessageSubscriber<Telemetry>,
    /// Commands taken out of the subscriber while waiting, not yet handed over.
    pending: VecDeque<RobotCommand>,
    node: WireNode,
    geometry: StereoFormat,
}

impl WireTransport {
    /// Joins `domain` as the camera pair (`width` x `height` GRAY8 views) and the robot.
    pub fn new(domain: &Domain, width: u32, height: u32) -> Result<Self, TransportError> {
        Self::with_robot(domain, width, height, RobotSide::Simulated)
    }

    /// Joins `domain` as the camera pair, and as the robot unless `robot` is external.
    pub fn with_robot(domain: &Domain, width: u32, height: u32, robot: RobotSide) -> Result<Self, TransportError> {
        let node = WireNode::create(domain, "handeye-sim")?;
        let geometry = StereoFormat::gray8_pair(width, height);
        // Latest-frame delivery, like a camera: in lockstep the simulator waits for the
        // daemon's reply to each frame anyway, so the daemon never falls behind.
        let frames = StereoPublisher::create(&node, geometry, StereoPublisherOptions { delivery: Delivery::Latest, ..Default::default() })?;
        let state = match robot {
            RobotSide::Simulated => StatePort::Publisher(MessagePublisher::<RobotState>::create(&node)?),
            RobotSide::External => StatePort::Subscriber { states: Box::new(MessageSubscriber::<RobotState>::create(&node)?), newest: None },
        };
        let commands = MessageSubscriber::<RobotCommand>::create(&node)?;
        let telemetry = MessageSubscriber::<Telemetry>::create(&node)?;
        Ok(Self { frames, state, commands, telemetry, pending: VecDeque::new(), node, geometry })
    }

    /// Waits up to `timeout` for a command publisher (a daemon) to attach, so that a lockstep
    /// run's first frame is not stepped past before the daemon is there. `true` if one did.
    pub fn wait_for_daemon(&mut self, timeout: Duration) -> Result<bool, RunError> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if self.daemon_attached() {
                return Ok(true);
            }
            let now = std::time::Instant::now();
            if now >= deadline {
                return Ok(false);
            }
            if self.node.termination_requested() {
                return Err(RunError::Interrupted);
            }
            match self.commands.wait((deadline - now).min(Duration::from_millis(20))).map_err(|e| RunError::Transport(e.to_string()))? {
                MessageEvent::Message(m) => self.pending.push_back(m),
                MessageEvent::Interrupted => return Err(RunError::Interrupted),
                _ => {}
            }
        }
    }

    /// The domain joined.
    pub fn domain(&self) -> &Domain {
        self.node.domain()
    }

    /// Counters of the command subscriber (received, rejected by reason).
    pub fn command_stats(&self) -> &handeye_wire::message::MessageStats {
        self.commands.stats()
    }

    /// Number of subscribers of the stereo service now.
    pub fn frame_subscribers(&self) -> usize {
        self.frames.subscriber_count()
    }

    /// Drains liveness events and messages that are due, without blocking.
    fn poll(&mut self) -> Result<(), RunError> {
        loop {
            match self.commands.wait(Duration::ZERO).map_err(|e| RunError::Transport(e.to_string()))? {
                MessageEvent::Message(m) => self.pending.push_back(m),
                MessageEvent::PublisherUp => tracing::info!("a command publisher (daemon) attached"),
                MessageEvent::PublisherGone => tracing::info!("the command publisher (daemon) left"),
                MessageEvent::Timeout => return Ok(()),
                MessageEvent::Interrupted => return Err(RunError::Interrupted),
            }
        }
    }
}

impl Transport for WireTransport {
    fn publish_frame(&mut self, meta: &FrameMeta, fill: &mut dyn FnMut(&mut [u8]) -> Result<(), RenderError>) -> Result<u64, RunError> {
        let mut rendered = Ok(());
        let frame_id = self
            .frames
            // Stamped with simulated time: the daemon's clock is the frames' capture time, so
            // a lockstep run keeps its simulated timing whatever the machine's speed.
            .publish(meta.sim_time_ns, |payload| {
                // The geometry is tightly packed (stride = width): the renderer's layout.
                debug_assert_eq!(payload.len(), (self.geometry.width * self.geometry.height * 2) as usize);
                rendered = fill(payload);
            })
            .map_err(|e| match e {
                handeye_wire::stereo::PublishError::Interrupted => RunError::Interrupted,
                e => RunError::Transport(e.to_string()),
            })?;
        rendered?;
        Ok(frame_id)
    }

    fn publish_state(&mut self, state: &RobotState) -> Result<(), RunError> {
        match &mut self.state {
            StatePort::Publisher(p) => p.send(state).map(|_| ()).map_err(|e| RunError::Transport(e.to_string())),
            StatePort::Subscriber { .. } => Ok(()), // the external driver publishes its own
        }
    }

    fn external_robot_state(&mut self, answering: Option<u64>, timeout: Duration) -> Result<Option<RobotState>, RunError> {
        let StatePort::Subscriber { states, newest } = &mut self.state else { return Ok(None) };
        while let Some(s) = states.try_receive() {
            *newest = Some(s);
        }
        let Some(frame) = answering else { return Ok(*newest) };
        // Lockstep: the daemon answered frame `frame`; wait until the driver has processed
        // that command, so the next frame shows the arm after it.
        let deadline = std::time::Instant::now() + timeout;
        while !newest.is_some_and(|s| s.last_command_frame_id == frame) {
            let now = std::time::Instant::now();
            if now >= deadline {
                break;
            }
            match states.wait(deadline - now).map_err(|e| RunError::Transport(e.to_string()))? {
                MessageEvent::Message(s) => *newest = Some(s),
                MessageEvent::Interrupted => return Err(RunError::Interrupted),
                MessageEvent::PublisherGone => tracing::warn!("the robot driver left"),
                MessageEvent::PublisherUp | MessageEvent::Timeout => {}
            }
        }
        Ok(*newest)
    }

    fn receive_commands(&mut self, out: &mut Vec<RobotCommand>) -> Result<(), RunError> {
        self.poll()?;
        out.extend(self.pending.drain(..));
        Ok(())
    }

    fn wait_for_commands(&mut self, timeout: Duration) -> Result<(), RunError> {
        if !self.pending.is_empty() {
            return Ok(());
        }
        match self.commands.wait(timeout).map_err(|e| RunError::Transport(e.to_string()))? {
            MessageEvent::Message(m) => self.pending.push_back(m),
            MessageEvent::Interrupted => return Err(RunError::Interrupted),
            MessageEvent::PublisherUp | MessageEvent::PublisherGone | MessageEvent::Timeout => {}
        }
        Ok(())
    }

    fn daemon_attached(&mut self) -> bool {
        if self.poll().is_err() {
            return false;
        }
        self.commands.publisher_alive() == Some(true)
    }

    fn interrupted(&self) -> bool {
        self.node.termination_requested()
    }

    fn receive_telemetry(&mut self, out: &mut Vec<Telemetry>) -> Result<(), RunError> {
        while let Some(t) = self.telemetry.try_receive() {
            out.push(t);
        }
        Ok(())
    }
}

//! Typed publish-subscribe for the fixed-size messages: robot state, robot commands and
//! telemetry. Messages are small, so subscribers copy each one out and release the slot at
//! once; every message is validated (version, known enum values, finite numbers) on both
//! sides — a sender refuses to send an invalid one, a receiver counts and drops it.

use std::marker::PhantomData;
use std::time::{Duration, Instant};

use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use iceoryx2::service::port_factory::event::PortFactory as EventFactory;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use thiserror::Error;

use crate::domain::WireNode;
use crate::liveness::{
    create_publisher, wait_on, ListeningPort, Liveness, LivenessChange, PublisherSlotError, RateLimitedLog, Waited,
};
use crate::services::{
    event_id, open_event_service, open_message_service, OpenError, ServiceSizing, ROBOT_COMMAND_SIZING, ROBOT_STATE_SIZING,
    TELEMETRY_SIZING,
};
use crate::types::*;

/// Why a message was rejected. [`MessageReject::key`] names the counter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum MessageReject {
    #[error("version {found}, expected {WIRE_VERSION}")]
    Version { found: u32 },
    #[error("field {field} has unknown value {value}")]
    UnknownEnum { field: &'static str, value: u32 },
    #[error("field {field} is not finite")]
    NonFinite { field: &'static str },
    #[error("field {field} is out of range")]
    OutOfRange { field: &'static str },
}

impl MessageReject {
    /// All counter keys, in the order of [`MessageReject::index`].
    pub const KEYS: [&'static str; 4] = ["version", "enum", "non_finite", "range"];

    pub fn key(&self) -> &'static str {
        Self::KEYS[self.index()]
    }

    pub fn index(&self) -> usize {
        match self {
            Self::Version { .. } => 0,
            Self::UnknownEnum { .. } => 1,
            Self::NonFinite { .. } => 2,
            Self::OutOfRange { .. } => 3,
        }
    }
}

/// A message type of the contract: its service, its sizing and its validation rules.
pub trait WireMessage: Copy + std::fmt::Debug + ZeroCopySend + 'static {
    /// The iceoryx2 service name.
    const SERVICE: &'static str;
    /// The settings the service is opened with.
    const SIZING: ServiceSizing;
    /// Checks everything a receiver relies on.
    fn validate(&self) -> Result<(), MessageReject>;
}

fn version(found: u32) -> Result<(), MessageReject> {
    if found == WIRE_VERSION { Ok(()) } else { Err(MessageReject::Version { found }) }
}

fn finite(field: &'static str, values: &[f32]) -> Result<(), MessageReject> {
    if values.iter().all(|v| v.is_finite()) { Ok(()) } else { Err(MessageReject::NonFinite { field }) }
}

/// NaN marks "unused"; infinities are never valid.
fn finite_or_nan<'a>(field: &'static str, values: impl IntoIterator<Item = &'a f32>) -> Result<(), MessageReject> {
    if values.into_iter().all(|v| !v.is_infinite()) { Ok(()) } else { Err(MessageReject::NonFinite { field }) }
}

/// Every bit of [`robot_flags`] that is defined.
pub const ROBOT_FLAGS_ALL: u32 = (1 << 8) - 1;

impl WireMessage for RobotState {
    const SERVICE: &'static str = service::ROBOT_STATE;
    const SIZING: ServiceSizing = ROBOT_STATE_SIZING;

    fn validate(&self) -> Result<(), MessageReject> {
        version(self.version)?;
        if self.flags & !ROBOT_FLAGS_ALL != 0 {
            return Err(MessageReject::OutOfRange { field: "flags" });
        }
        if RejectReason::from_u32(self.reject).is_none() {
            return Err(MessageReject::UnknownEnum { field: "reject", value: self.reject });
        }
        finite("tool_pos_m", &self.tool_pos_m)?;
        finite("tool_yaw_rad", &[self.tool_yaw_rad])?;
        finite("joints_rad", &self.joints_rad)?;
        finite("gripper_width_m", &[self.gripper_width_m])?;
        if self.gripper_width_m < 0.0 {
            return Err(MessageReject::OutOfRange { field: "gripper_width_m" });
        }
        Ok(())
    }
}

impl WireMessage for RobotCommand {
    const SERVICE: &'static str = service::ROBOT_COMMAND;
    const SIZING: ServiceSizing = ROBOT_COMMAND_SIZING;

    fn validate(&self) -> Result<(), MessageReject> {
        version(self.version)?;
        if CommandKind::from_u32(self.kind).is_none() {
            return Err(MessageReject::UnknownEnum { field: "kind", value: self.kind });
        }
        if GripperCommand::from_u32(self.gripper).is_none() {
            return Err(MessageReject::UnknownEnum { field: "gripper", value: self.gripper });
        }
        finite("target_m", &self.target_m)?;
        finite("yaw_rad", &[self.yaw_rad])?;
        finite("speed_limit_mps", &[self.speed_limit_mps])?;
        if self.speed_limit_mps < 0.0 {
            return Err(MessageReject::OutOfRange { field: "speed_limit_mps" });
        }
        Ok(())
    }
}

impl WireMessage for Telemetry {
    const SERVICE: &'static str = service::TELEMETRY;
    const SIZING: ServiceSizing = TELEMETRY_SIZING;

    fn validate(&self) -> Result<(), MessageReject> {
        version(self.version)?;
        if Phase::from_u32(self.phase).is_none() {
            return Err(MessageReject::UnknownEnum { field: "phase", value: self.phase });
        }
        if let Some(&bad) = self.tracker_state.iter().find(|&&s| s > 2) {
            return Err(MessageReject::UnknownEnum { field: "tracker_state", value: bad });
        }
        if self.tracker_state.iter().zip(&self.tracker_update_ns).any(|(&state, &ns)| state == 0 && ns != 0) {
            // A tracker that is off was not updated: its update time must be 0.
            return Err(MessageReject::OutOfRange { field: "tracker_update_ns" });
        }
        finite("tracker_confidence", &self.tracker_confidence)?;
        if self.tracker_confidence.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return Err(MessageReject::OutOfRange { field: "tracker_confidence" });
        }
        finite_or_nan("tracker_corners_px", self.tracker_corners_px.iter().flatten().flatten())?;
        finite_or_nan("servo_error", &self.servo_error)?;
        if self.planning > 1 {
            return Err(MessageReject::OutOfRange { field: "planning" });
        }
        if PointingState::from_u32(self.pointing_state).is_none() {
            return Err(MessageReject::UnknownEnum { field: "pointing_state", value: self.pointing_state });
        }
        finite_or_nan("pointing_point_m", &self.pointing_point_m)?;
        finite_or_nan("pointing_sigma_m", &[self.pointing_sigma_m, self.pointing_crossing_rad])?;
        finite_or_nan("pointing_tip_px", self.pointing_tip_px.iter().flatten())?;
        finite_or_nan("pointing_line_px", self.pointing_line_px.iter().flatten())?;
        Ok(())
    }
}

/// Why a message publisher or subscriber could not be created.
#[derive(Debug, Error)]
pub enum MessagePortError {
    #[error(transparent)]
    Open(#[from] OpenError),
    #[error("all {max} publisher slots of '{service}' in domain '{domain}' are taken")]
    PublisherSlotsTaken { service: &'static str, domain: String, max: usize },
    #[error("could not create the {port} port on '{service}': {detail}")]
    Port { port: &'static str, service: &'static str, detail: String },
}

/// Why a message could not be sent.
#[derive(Debug, Error)]
pub enum MessageSendError {
    #[error("refusing to send an invalid {service} message: {reason}")]
    Invalid { service: &'static str, reason: MessageReject },
    #[error("could not send on '{service}': {detail}")]
    Send { service: &'static str, detail: String },
    #[error("could not notify the subscribers of '{service}': {detail}")]
    Notify { service: &'static str, detail: String },
}

/// Why waiting for a message failed.
#[derive(Debug, Error)]
pub enum MessageWaitError {
    #[error("waiting on the '{service}' event listener failed: {detail}")]
    Listener { service: &'static str, detail: String },
}

/// Publishes messages of type `T` and wakes their subscribers.
///
/// ```no_run
/// use handeye_wire::{Domain, WireNode, RobotCommand, CommandKind, WIRE_VERSION, NO_FRAME};
/// use handeye_wire::message::MessagePublisher;
/// let node = WireNode::create(&Domain::new("handeye")?, "estop")?;
/// let mut commands = MessagePublisher::<RobotCommand>::create(&node)?;
/// commands.send(&RobotCommand { version: WIRE_VERSION, kind: CommandKind::Stop as u32,
///     frame_id: NO_FRAME, time_ns: handeye_wire::monotonic_ns(), ..Default::default() })?;
/// # Ok::<_, Box<dyn std::error::Error>>(())
/// ```
pub struct MessagePublisher<T: WireMessage> {
    // Publisher before notifier: see StereoPublisher.
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, T, ()>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    service: PubSubFactory<ipc::Service, T, ()>,
    _events: EventFactory<ipc::Service>,
    _marker: PhantomData<T>,
}

impl<T: WireMessage> MessagePublisher<T> {
    pub fn create(node: &WireNode) -> Result<Self, MessagePortError> {
        let service = open_message_service::<T>(node, T::SERVICE, &T::SIZING)?;
        let events = open_event_service(node, T::SERVICE, &T::SIZING)?;
        let create = || service.publisher_builder().max_loaned_samples(T::SIZING.publisher_max_loaned_samples).create();
        let publisher = create_publisher(node, &service, Duration::from_secs(2), create).map_err(|e| match e {
            PublisherSlotError::Taken => MessagePortError::PublisherSlotsTaken {
                service: T::SERVICE,
                domain: node.domain().to_string(),
                max: T::SIZING.max_publishers,
            },
            PublisherSlotError::Create(e) => MessagePortError::Port { port: "publisher", service: T::SERVICE, detail: format!("{e:?}") },
        })?;
        let notifier = events
            .notifier_builder()
            .default_event_id(EventId::new(event_id::SAMPLE))
            .create()
            .map_err(|e| MessagePortError::Port { port: "notifier", service: T::SERVICE, detail: format!("{e:?}") })?;
        Ok(Self { publisher, notifier, service, _events: events, _marker: PhantomData })
    }

    /// Validates `msg` and sends it; returns the number of subscribers reached.
    pub fn send(&mut self, msg: &T) -> Result<usize, MessageSendError> {
        msg.validate().map_err(|reason| MessageSendError::Invalid { service: T::SERVICE, reason })?;
        self.send_unchecked(msg)
    }

    /// Sends `msg` without validating it (for tests of receivers).
    pub fn send_unchecked(&mut self, msg: &T) -> Result<usize, MessageSendError> {
        let n = self
            .publisher
            .send_copy(*msg)
            .map_err(|e| MessageSendError::Send { service: T::SERVICE, detail: format!("{e:?}") })?;
        self.notifier.notify().map_err(|e| MessageSendError::Notify { service: T::SERVICE, detail: format!("{e:?}") })?;
        Ok(n)
    }

    /// Connects subscribers that arrived since the last send and hands them the history
    /// (the last message, for services with history). Every send does this too.
    pub fn update_connections(&self) {
        let _ = self.publisher.update_connections();
    }

    /// Number of subscribers connected now.
    pub fn subscriber_count(&self) -> usize {
        self.service.try_cleanup_dead_nodes();
        self.service.dynamic_config().number_of_subscribers()
    }
}

/// Counters of a [`MessageSubscriber`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MessageStats {
    pub received: u64,
    /// Rejected messages by reason, indexed like [`MessageReject::KEYS`].
    pub rejected: [u64; MessageReject::KEYS.len()],
    pub receive_errors: u64,
    pub publisher_up: u64,
    pub publisher_gone: u64,
}

impl MessageStats {
    pub fn rejected_total(&self) -> u64 {
        self.rejected.iter().sum()
    }
}

/// What [`MessageSubscriber::wait`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MessageEvent<T> {
    Message(T),
    PublisherUp,
    PublisherGone,
    Timeout,
    Interrupted,
}

/// How [`MessageSubscriber::wait_until`] ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WaitUntil<T> {
    /// The predicate accepted this message.
    Matched(T),
    Timeout,
    Interrupted,
}

/// Receives messages of type `T`, validated, in the order they were sent.
pub struct MessageSubscriber<T: WireMessage> {
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>,
    listener: iceoryx2::port::listener::Listener<ipc::Service>,
    service: PubSubFactory<ipc::Service, T, ()>,
    _events: EventFactory<ipc::Service>,
    node: WireNode,
    stats: MessageStats,
    liveness: Liveness,
    log: RateLimitedLog,
}

impl<T: WireMessage> MessageSubscriber<T> {
    /// Subscribes with the longest queue the service allows, so nothing is lost to short stalls.
    pub fn create(node: &WireNode) -> Result<Self, MessagePortError> {
        let service = open_message_service::<T>(node, T::SERVICE, &T::SIZING)?;
        let events = open_event_service(node, T::SERVICE, &T::SIZING)?;
        let port_err = |port: &'static str, detail: String| MessagePortError::Port { port, service: T::SERVICE, detail };
        let listener = events.listener_builder().create().map_err(|e| port_err("listener", format!("{e:?}")))?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(T::SIZING.subscriber_max_buffer_size)
            .create()
            .map_err(|e| port_err("subscriber", format!("{e:?}")))?;
        Ok(Self {
            subscriber,
            listener,
            service,
            _events: events,
            node: node.clone(),
            stats: MessageStats::default(),
            liveness: Liveness::new(),
            log: RateLimitedLog::new(MessageReject::KEYS.len() + 1),
        })
    }

    pub fn stats(&self) -> &MessageStats {
        &self.stats
    }

    pub fn publisher_alive(&self) -> Option<bool> {
        self.liveness.alive()
    }

    /// The next valid queued message, without waiting; invalid ones are counted and dropped.
    pub fn try_receive(&mut self) -> Option<T> {
        loop {
            let msg = match self.subscriber.receive() {
                Ok(Some(sample)) => *sample.payload(),
                Ok(None) => return None,
                Err(e) => {
                    self.stats.receive_errors += 1;
                    self.log.log(MessageReject::KEYS.len(), |suppressed| {
                        tracing::warn!(service = T::SERVICE, ?e, suppressed, "receive failed");
                    });
                    return None;
                }
            };
            match msg.validate() {
                Ok(()) => {
                    self.stats.received += 1;
                    return Some(msg);
                }
                Err(reason) => {
                    self.stats.rejected[reason.index()] += 1;
                    let count = self.stats.rejected[reason.index()];
                    self.log.log(reason.index(), |suppressed| {
                        tracing::warn!(service = T::SERVICE, reason = reason.key(), count, suppressed, "rejected message: {reason}");
                    });
                }
            }
        }
    }

    /// Waits up to `timeout` for the next valid message or a change of publisher liveness,
    /// sleeping on the event listener in between.
    pub fn wait(&mut self, timeout: Duration) -> Result<MessageEvent<T>, MessageWaitError> {
        let waited = wait_on(self, timeout).map_err(|detail| MessageWaitError::Listener { service: T::SERVICE, detail })?;
        Ok(match waited {
            Waited::Received(msg) => MessageEvent::Message(msg),
            Waited::Publisher(LivenessChange::Up) => {
                self.stats.publisher_up += 1;
                MessageEvent::PublisherUp
            }
            Waited::Publisher(LivenessChange::Gone) => {
                self.stats.publisher_gone += 1;
                MessageEvent::PublisherGone
            }
            Waited::Interrupted => MessageEvent::Interrupted,
            Waited::Timeout => MessageEvent::Timeout,
        })
    }

    /// Passes every valid message, in order, to `accept` until it returns `true` (that message
    /// is returned) or `timeout` passes. This is the lockstep wait: the simulator applies every
    /// command it gets and stops waiting at the one that answers frame N.
    ///
    /// ```no_run
    /// # use std::time::Duration;
    /// # use handeye_wire::{Domain, WireNode, RobotCommand};
    /// # use handeye_wire::message::{MessageSubscriber, WaitUntil};
    /// # let node = WireNode::create(&Domain::new("handeye")?, "sim")?;
    /// let mut commands = MessageSubscriber::<RobotCommand>::create(&node)?;
    /// let frame_n = 41;
    /// match commands.wait_until(Duration::from_millis(200), |cmd| {
    ///     /* apply cmd */
    ///     cmd.frame_id == frame_n
    /// })? {
    ///     WaitUntil::Matched(_) => { /* render frame N + 1 */ }
    ///     WaitUntil::Timeout => { /* the daemon is late: hold and go on */ }
    ///     WaitUntil::Interrupted => return Ok(()),
    /// }
    /// # Ok::<_, Box<dyn std::error::Error>>(())
    /// ```
    pub fn wait_until(&mut self, timeout: Duration, mut accept: impl FnMut(&T) -> bool) -> Result<WaitUntil<T>, MessageWaitError> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.wait(left)? {
                MessageEvent::Message(m) => {
                    if accept(&m) {
                        return Ok(WaitUntil::Matched(m));
                    }
                }
                MessageEvent::Timeout => return Ok(WaitUntil::Timeout),
                MessageEvent::Interrupted => return Ok(WaitUntil::Interrupted),
                MessageEvent::PublisherUp | MessageEvent::PublisherGone => {}
            }
        }
    }
}

impl<T: WireMessage> ListeningPort for MessageSubscriber<T> {
    type Item = T;

    fn try_receive(&mut self) -> Option<T> {
        MessageSubscriber::try_receive(self)
    }

    fn check_liveness(&mut self) -> Option<LivenessChange> {
        self.liveness.check_if_due(&self.service)
    }

    fn termination_requested(&self) -> bool {
        self.node.termination_requested()
    }

    fn nap(&mut self, deadline: Instant) -> Result<(), String> {
        self.liveness.nap(&self.listener, deadline)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn command() -> RobotCommand {
        RobotCommand { version: WIRE_VERSION, kind: CommandKind::MoveTo as u32, frame_id: 3, target_m: [0.1, 0.2, 0.3], ..Default::default() }
    }

    fn state() -> RobotState {
        RobotState { version: WIRE_VERSION, gripper_width_m: 0.05, ..Default::default() }
    }

    #[test]
    fn valid_messages_pass() {
        assert_eq!(command().validate(), Ok(()));
        assert_eq!(state().validate(), Ok(()));
        assert_eq!(Telemetry::default().validate(), Ok(()));
    }

    #[test]
    fn commands_are_checked_field_by_field() {
        let bad: Vec<(RobotCommand, &str)> = vec![
            (RobotCommand { version: 0, ..command() }, "version"),
            (RobotCommand { kind: 99, ..command() }, "enum"),
            (RobotCommand { gripper: 3, ..command() }, "enum"),
            (RobotCommand { target_m: [0.0, f32::NAN, 0.0], ..command() }, "non_finite"),
            (RobotCommand { yaw_rad: f32::INFINITY, ..command() }, "non_finite"),
            (RobotCommand { speed_limit_mps: f32::NEG_INFINITY, ..command() }, "non_finite"),
            (RobotCommand { speed_limit_mps: -0.1, ..command() }, "range"),
        ];
        for (c, key) in bad {
            assert_eq!(c.validate().map_err(|e| e.key()), Err(key), "{c:?}");
        }
    }

    #[test]
    fn states_are_checked_field_by_field() {
        let bad: Vec<(RobotState, &str)> = vec![
            (RobotState { version: WIRE_VERSION + 1, ..state() }, "version"),
            (RobotState { reject: 17, ..state() }, "enum"),
            (RobotState { flags: 1 << 8, ..state() }, "range"),
            (RobotState { joints_rad: [0.0, 0.0, f32::NAN, 0.0, 0.0], ..state() }, "non_finite"),
            (RobotState { tool_pos_m: [f32::INFINITY, 0.0, 0.0], ..state() }, "non_finite"),
            (RobotState { gripper_width_m: -0.01, ..state() }, "range"),
        ];
        for (s, key) in bad {
            assert_eq!(s.validate().map_err(|e| e.key()), Err(key), "{s:?}");
        }
    }

    #[test]
    fn telemetry_allows_nan_as_unused_but_not_infinity() {
        let mut t = Telemetry::default();
        assert!(t.servo_error[0].is_nan());
        assert_eq!(t.validate(), Ok(()));
        t.servo_error[2] = f32::INFINITY;
        assert_eq!(t.validate().unwrap_err().key(), "non_finite");
        let mut t = Telemetry::default();
        t.tracker_corners_px[1][3][0] = f32::NEG_INFINITY;
        assert_eq!(t.validate().unwrap_err().key(), "non_finite");
        let t = Telemetry { tracker_confidence: [0.5, 1.5, 0.0, 0.0], ..Telemetry::default() };
        assert_eq!(t.validate().unwrap_err().key(), "range");
        let t = Telemetry { tracker_confidence: [f32::NAN, 0.0, 0.0, 0.0], ..Telemetry::default() };
        assert_eq!(t.validate().unwrap_err().key(), "non_finite");
        let t = Telemetry { phase: 13, ..Telemetry::default() };
        assert_eq!(t.validate().unwrap_err().key(), "enum");
        let t = Telemetry { phase: Phase::Point as u32, pointing_state: PointingState::Indicated as u32, pointing_point_m: [0.4, 0.02], ..Telemetry::default() };
        assert_eq!(t.validate(), Ok(()));
        let t = Telemetry { pointing_state: 9, ..Telemetry::default() };
        assert_eq!(t.validate().unwrap_err().key(), "enum");
        let t = Telemetry { pointing_line_px: [[0.0, 1.0, f32::INFINITY], [f32::NAN; 3]], ..Telemetry::default() };
        assert_eq!(t.validate().unwrap_err().key(), "non_finite");
        let t = Telemetry { tracker_state: [0, 1, 2, 3], ..Telemetry::default() };
        assert_eq!(t.validate().unwrap_err().key(), "enum");
        let t = Telemetry { tracker_state: [1, 2, 0, 0], tracker_update_ns: [9_000, 8_000, 0, 0], ..Telemetry::default() };
        assert_eq!(t.validate(), Ok(()));
        let t = Telemetry { tracker_state: [1, 0, 0, 0], tracker_update_ns: [9_000, 8_000, 0, 0], ..Telemetry::default() };
        assert_eq!(t.validate(), Err(MessageReject::OutOfRange { field: "tracker_update_ns" }));
    }

    #[test]
    fn every_defined_robot_flag_is_in_the_mask() {
        use crate::types::robot_flags::*;
        let all = MOVING | ARRIVED | FAULT | REJECTED | GRIPPER_CLOSED | GRIPPER_SETTLED | WATCHDOG_STOP | STOPPED;
        assert_eq!(all, ROBOT_FLAGS_ALL);
    }
}

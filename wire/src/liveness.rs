//! Publisher liveness as seen by a subscriber, the one wait loop every subscriber runs on it,
//! and rate-limited logging of rejections.

use std::time::{Duration, Instant};

use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::publisher::PublisherCreateError;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;

use crate::domain::WireNode;
use crate::services::{event_id, LIVENESS_PERIOD};

/// A change in whether any publisher is connected to a service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LivenessChange {
    /// A publisher appeared (the first one, or one after all had gone).
    Up,
    /// The last publisher went away: a clean exit, or a dead process whose node was cleaned up.
    Gone,
}

/// Tracks whether a service has a live publisher. Checked on the publisher's created, dropped
/// and dead events and every [`LIVENESS_PERIOD`] while waiting, so a SIGKILLed publisher (which
/// sends nothing) is still noticed: the check removes dead nodes, which emits the dead event and
/// drops the publisher count.
#[derive(Debug)]
pub(crate) struct Liveness {
    alive: Option<bool>,
    next_check: Instant,
}

impl Liveness {
    pub(crate) fn new() -> Self {
        Self { alive: None, next_check: Instant::now() }
    }

    /// Whether a publisher was present at the last check (`None` before the first check).
    pub(crate) fn alive(&self) -> Option<bool> {
        self.alive
    }

    /// Makes the next [`Liveness::check_if_due`] run now (after a lifecycle event).
    pub(crate) fn force(&mut self) {
        self.next_check = Instant::now();
    }

    /// Time until the next periodic check.
    pub(crate) fn until_due(&self) -> Duration {
        self.next_check.saturating_duration_since(Instant::now())
    }

    /// Sleeps on `listener` until an event arrives, `deadline` passes or the next periodic
    /// check is due (at least 1 ms). A publisher's arrival or departure makes the next check
    /// due at once. An interrupt signal ends the nap early without error: the caller's loop
    /// then sees the termination request. The error is the listener's failure, as text.
    pub(crate) fn nap(&mut self, listener: &Listener<ipc::Service>, deadline: Instant) -> Result<(), String> {
        let nap = deadline.saturating_duration_since(Instant::now()).min(self.until_due()).max(Duration::from_millis(1));
        let mut lifecycle = false;
        match listener.timed_wait(|ev| lifecycle |= is_lifecycle_event(ev.id.as_value()), nap) {
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
            Err(e) => return Err(format!("{e:?}")),
        }
        if lifecycle {
            self.force();
        }
        Ok(())
    }

    pub(crate) fn check_if_due<P, H>(&mut self, service: &PubSubFactory<ipc::Service, P, H>) -> Option<LivenessChange>
    where
        P: std::fmt::Debug + iceoryx2::prelude::IceoryxSend + ?Sized + 'static,
        H: std::fmt::Debug + ZeroCopySend + 'static,
    {
        let now = Instant::now();
        if now < self.next_check {
            return None;
        }
        self.next_check = now + LIVENESS_PERIOD;
        // Removing dead nodes is what turns a SIGKILLed publisher into a dropped publisher
        // count (and a dead event for every listener of the service).
        service.try_cleanup_dead_nodes();
        let alive = service.dynamic_config().number_of_publishers() > 0;
        let change = match (self.alive, alive) {
            (Some(true), false) => Some(LivenessChange::Gone),
            (Some(false) | None, true) => Some(LivenessChange::Up),
            _ => None,
        };
        self.alive = Some(alive);
        change
    }
}

/// How [`wait_on`] ended, before the port turns it into its own event.
#[derive(Debug)]
pub(crate) enum Waited<T> {
    /// The next valid item (a frame, a message).
    Received(T),
    /// The publisher appeared or went.
    Publisher(LivenessChange),
    /// SIGINT or SIGTERM.
    Interrupted,
    Timeout,
}

/// A subscriber port that sleeps on its service's event listener between items: what
/// [`wait_on`] needs of it.
pub(crate) trait ListeningPort {
    type Item;
    /// The next valid queued item, without waiting; invalid ones are counted and dropped.
    fn try_receive(&mut self) -> Option<Self::Item>;
    /// The port's [`Liveness::check_if_due`] on its service.
    fn check_liveness(&mut self) -> Option<LivenessChange>;
    /// Whether the process was asked to stop.
    fn termination_requested(&self) -> bool;
    /// The port's [`Liveness::nap`] on its listener.
    fn nap(&mut self, deadline: Instant) -> Result<(), String>;
}

/// Waits up to `timeout` for the port's next valid item or a change of publisher liveness,
/// sleeping on the event listener in between (no busy polling). Queued items come first;
/// liveness is re-checked at least every [`LIVENESS_PERIOD`], so a killed publisher is
/// reported within about that period. The error is the listener's failure, as text.
pub(crate) fn wait_on<P: ListeningPort>(port: &mut P, timeout: Duration) -> Result<Waited<P::Item>, String> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(item) = port.try_receive() {
            return Ok(Waited::Received(item));
        }
        if let Some(change) = port.check_liveness() {
            return Ok(Waited::Publisher(change));
        }
        if port.termination_requested() {
            return Ok(Waited::Interrupted);
        }
        if Instant::now() >= deadline {
            return Ok(Waited::Timeout);
        }
        port.nap(deadline)?;
    }
}

/// Why [`create_publisher`] gave up.
#[derive(Debug)]
pub(crate) enum PublisherSlotError {
    /// Every publisher slot stayed taken for the whole wait (or the process was asked to stop).
    Taken,
    /// iceoryx2 refused the port for another reason.
    Create(PublisherCreateError),
}

/// Creates a publisher with `create`, retrying every 50 ms for up to `timeout` while all of
/// the service's publisher slots are taken: maybe by a publisher that was just killed, whose
/// slot the dead-node cleanup before each retry frees.
pub(crate) fn create_publisher<Port, Payload, Header>(
    node: &WireNode,
    service: &PubSubFactory<ipc::Service, Payload, Header>,
    timeout: Duration,
    mut create: impl FnMut() -> Result<Port, PublisherCreateError>,
) -> Result<Port, PublisherSlotError>
where
    Payload: std::fmt::Debug + iceoryx2::prelude::IceoryxSend + ?Sized + 'static,
    Header: std::fmt::Debug + ZeroCopySend + 'static,
{
    let start = Instant::now();
    loop {
        match create() {
            Ok(port) => return Ok(port),
            Err(PublisherCreateError::ExceedsMaxSupportedPublishers) => {
                service.try_cleanup_dead_nodes();
                if start.elapsed() >= timeout || !node.sleep(Duration::from_millis(50)) {
                    return Err(PublisherSlotError::Taken);
                }
            }
            Err(e) => return Err(PublisherSlotError::Create(e)),
        }
    }
}

/// True for the event ids that announce a publisher's arrival or departure.
pub(crate) fn is_lifecycle_event(id: usize) -> bool {
    matches!(id, event_id::PUBLISHER_CREATED | event_id::PUBLISHER_DROPPED | event_id::PUBLISHER_DEAD)
}

/// Logs at most one line per reason per second, and says how many were suppressed.
#[derive(Debug)]
pub(crate) struct RateLimitedLog {
    last: Vec<Option<Instant>>,
    suppressed: Vec<u64>,
}

impl RateLimitedLog {
    pub(crate) fn new(reasons: usize) -> Self {
        Self { last: vec![None; reasons], suppressed: vec![0; reasons] }
    }

    /// Calls `log(suppressed_since_last)` if reason `index` was not logged in the last second.
    pub(crate) fn log(&mut self, index: usize, log: impl FnOnce(u64)) {
        let now = Instant::now();
        let due = self.last[index].is_none_or(|t| now.duration_since(t) >= Duration::from_secs(1));
        if due {
            log(self.suppressed[index]);
            self.suppressed[index] = 0;
            self.last[index] = Some(now);
        } else {
            self.suppressed[index] += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_limited_log_keeps_quiet_within_a_second_per_reason() {
        let mut l = RateLimitedLog::new(2);
        let mut lines = Vec::new();
        for _ in 0..5 {
            l.log(0, |s| lines.push((0, s)));
        }
        l.log(1, |s| lines.push((1, s)));
        assert_eq!(lines, vec![(0, 0), (1, 0)]);
        assert_eq!(l.suppressed[0], 4);
    }
}

//! How each service is sized, and the event service that wakes its subscribers.
//!
//! iceoryx2 checks these settings when a second process opens a service: every participant
//! (including a third-party driver) must open them with the same values, or the open fails
//! with an "incompatible" error. They are listed in `wire/README.md`.

use std::time::Duration;

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::event::PortFactory as EventFactory;
use thiserror::Error;

use crate::domain::WireNode;

/// Event ids on every handeye event service (same name as the publish-subscribe service).
pub mod event_id {
    /// A publisher sent a sample; sent by the publisher after every `send`.
    pub const SAMPLE: usize = 1;
    /// A publisher's notifier was created (emitted by iceoryx2 itself).
    pub const PUBLISHER_CREATED: usize = 2;
    /// A publisher's notifier was dropped: clean exit (emitted by iceoryx2 itself).
    pub const PUBLISHER_DROPPED: usize = 3;
    /// A publisher's process died and its node was cleaned up (emitted by the cleaner).
    pub const PUBLISHER_DEAD: usize = 4;
    /// Highest event id the services accept.
    pub const MAX: usize = 7;
}

/// The settings of one publish-subscribe service and its event service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceSizing {
    pub max_publishers: usize,
    pub max_subscribers: usize,
    /// Queue length a subscriber may ask for (per publisher connection).
    pub subscriber_max_buffer_size: usize,
    /// Samples a subscriber may hold at once.
    pub subscriber_max_borrowed_samples: usize,
    /// Samples a late subscriber receives on connection.
    pub history_size: usize,
    /// Samples a publisher may loan at once.
    pub publisher_max_loaned_samples: usize,
    /// Processes that may open the service at once.
    pub max_nodes: usize,
}

impl ServiceSizing {
    /// Shared-memory slots one publisher reserves: iceoryx2 pre-allocates the worst case.
    pub fn slots_per_publisher(&self) -> usize {
        self.max_subscribers * (self.subscriber_max_buffer_size + self.subscriber_max_borrowed_samples)
            + self.history_size
            + self.publisher_max_loaned_samples
    }
}

/// `handeye/stereo`: one camera source per domain; the daemon, a monitor and two spare
/// subscribers (recorders, viewers). Safe overflow is on: a subscriber that lags loses its
/// oldest queued frame, never the newest.
pub const STEREO_SIZING: ServiceSizing = ServiceSizing {
    max_publishers: 1,
    max_subscribers: 4,
    subscriber_max_buffer_size: 2,
    subscriber_max_borrowed_samples: 2,
    history_size: 0,
    publisher_max_loaned_samples: 1,
    max_nodes: 12,
};

/// `handeye/robot/state`: one controller; history 1 so a late subscriber sees the current state.
pub const ROBOT_STATE_SIZING: ServiceSizing = ServiceSizing {
    max_publishers: 1,
    max_subscribers: 4,
    subscriber_max_buffer_size: 4,
    subscriber_max_borrowed_samples: 1,
    history_size: 1,
    publisher_max_loaned_samples: 1,
    max_nodes: 12,
};

/// `handeye/robot/command`: the daemon plus one operator tool (e.g. an emergency stop); a
/// queue of 16 so a controller that stalls briefly still sees every command in order.
pub const ROBOT_COMMAND_SIZING: ServiceSizing = ServiceSizing {
    max_publishers: 2,
    max_subscribers: 3,
    subscriber_max_buffer_size: 16,
    subscriber_max_borrowed_samples: 1,
    history_size: 0,
    publisher_max_loaned_samples: 1,
    max_nodes: 12,
};

/// `handeye/telemetry`: the daemon; history 1 so a late monitor sees the current phase.
pub const TELEMETRY_SIZING: ServiceSizing = ServiceSizing {
    max_publishers: 1,
    max_subscribers: 4,
    subscriber_max_buffer_size: 8,
    subscriber_max_borrowed_samples: 1,
    history_size: 1,
    publisher_max_loaned_samples: 1,
    max_nodes: 12,
};

/// How often subscribers re-check publisher liveness (and clean up dead nodes) while waiting.
/// A SIGKILLed publisher is reported within about this period (the contract promises 500 ms).
pub const LIVENESS_PERIOD: Duration = Duration::from_millis(100);

/// Why a service could not be opened.
#[derive(Debug, Error)]
pub enum OpenError {
    #[error("service name '{service}' is not valid for iceoryx2")]
    BadName { service: String },
    #[error(
        "could not open {pattern} service '{service}' in domain '{domain}': {detail} \
         (a process built with other wire settings or an older handeye may hold it; \
         stop it, or use another --domain)"
    )]
    Open { service: String, domain: String, pattern: &'static str, detail: String },
}

pub(crate) fn service_name(service: &str) -> Result<ServiceName, OpenError> {
    ServiceName::new(service).map_err(|_| OpenError::BadName { service: service.to_owned() })
}

/// Opens (or creates) the event service that goes with publish-subscribe service `service`.
pub(crate) fn open_event_service(
    node: &WireNode,
    service: &str,
    sizing: &ServiceSizing,
) -> Result<EventFactory<ipc::Service>, OpenError> {
    let name = service_name(service)?;
    node.iceoryx2()
        .service_builder(&name)
        .event()
        .max_notifiers(sizing.max_publishers + 2)
        .max_listeners(sizing.max_subscribers + 2)
        .max_nodes(sizing.max_nodes)
        .event_id_max_value(event_id::MAX)
        .notifier_created_event(EventId::new(event_id::PUBLISHER_CREATED))
        .notifier_dropped_event(EventId::new(event_id::PUBLISHER_DROPPED))
        .notifier_dead_event(EventId::new(event_id::PUBLISHER_DEAD))
        .open_or_create()
        .map_err(|e| OpenError::Open {
            service: service.to_owned(),
            domain: node.domain().to_string(),
            pattern: "event",
            detail: format!("{e:?}"),
        })
}

/// Opens (or creates) a publish-subscribe service of fixed-size messages.
pub(crate) fn open_message_service<T>(
    node: &WireNode,
    service: &str,
    sizing: &ServiceSizing,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>, OpenError>
where
    T: std::fmt::Debug + ZeroCopySend + 'static,
{
    let name = service_name(service)?;
    node.iceoryx2()
        .service_builder(&name)
        .publish_subscribe::<T>()
        .max_publishers(sizing.max_publishers)
        .max_subscribers(sizing.max_subscribers)
        .subscriber_max_buffer_size(sizing.subscriber_max_buffer_size)
        .subscriber_max_borrowed_samples(sizing.subscriber_max_borrowed_samples)
        .history_size(sizing.history_size)
        .max_nodes(sizing.max_nodes)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| OpenError::Open {
            service: service.to_owned(),
            domain: node.domain().to_string(),
            pattern: "publish-subscribe",
            detail: format!("{e:?}"),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stereo_reserves_seventeen_slots_per_publisher() {
        // 4 subscribers x (2 queued + 2 held) + 0 history + 1 loan: 17 x 614 400 B = 10.4 MB
        // for a 640x480 pair. wire/README.md quotes this number; change both together.
        assert_eq!(STEREO_SIZING.slots_per_publisher(), 17);
    }

    #[test]
    fn message_services_reserve_the_slots_the_readme_lists() {
        assert_eq!(ROBOT_STATE_SIZING.slots_per_publisher(), 22);
        assert_eq!(ROBOT_COMMAND_SIZING.slots_per_publisher(), 52);
        assert_eq!(TELEMETRY_SIZING.slots_per_publisher(), 38);
    }

    #[test]
    fn history_fits_in_every_subscriber_queue() {
        // iceoryx2 refuses to create a service whose history exceeds the subscriber buffer.
        for s in [STEREO_SIZING, ROBOT_STATE_SIZING, ROBOT_COMMAND_SIZING, TELEMETRY_SIZING] {
            assert!(s.history_size <= s.subscriber_max_buffer_size, "{s:?}");
        }
    }
}

//! The stereo subscriber: waits for frames without polling, validates every sample, and hands
//! out borrowed views of the valid ones.

use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::port_factory::event::PortFactory as EventFactory;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use thiserror::Error;

use super::publisher::open_stereo_service;
use super::{validate_stereo, StereoLayout, StereoReject};
use crate::domain::WireNode;
use crate::liveness::{wait_on, ListeningPort, Liveness, LivenessChange, RateLimitedLog, Waited};
use crate::services::{open_event_service, OpenError, STEREO_SIZING};
use crate::types::{monotonic_ns, service, StereoHeader};

/// Why a stereo subscriber could not be created.
#[derive(Debug, Error)]
pub enum StereoSubscriberError {
    #[error(transparent)]
    Open(#[from] OpenError),
    #[error("queue length {requested} is outside 1..={max}")]
    BufferSize { requested: usize, max: usize },
    #[error("could not create the {port} port on '{service}': {detail}")]
    Port { port: &'static str, service: &'static str, detail: String },
}

/// Why waiting for a frame failed (rejected samples are counted, not errors).
#[derive(Debug, Error)]
pub enum StereoWaitError {
    #[error("waiting on the '{service}' event listener failed: {detail}")]
    Listener { service: &'static str, detail: String },
}

/// Counters of a [`StereoSubscriber`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct StereoStats {
    /// Valid frames handed out.
    pub received: u64,
    /// Rejected samples by reason, indexed like [`StereoReject::KEYS`].
    pub rejected: [u64; StereoReject::KEYS.len()],
    /// Frame ids skipped between consecutive valid frames of one publisher.
    pub missed: u64,
    /// `receive` calls that failed inside iceoryx2 (e.g. a connection to a dead publisher).
    pub receive_errors: u64,
    /// Times a publisher appeared (first one included).
    pub publisher_up: u64,
    /// Times the last publisher went away (clean exit or death).
    pub publisher_gone: u64,
}

impl StereoStats {
    pub fn rejected_total(&self) -> u64 {
        self.rejected.iter().sum()
    }

    /// `(key, count)` for every rejection reason.
    pub fn rejected_by_reason(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        StereoReject::KEYS.iter().copied().zip(self.rejected.iter().copied())
    }
}

/// What [`StereoSubscriber::wait`] found.
pub enum StereoEvent {
    /// A valid frame.
    Frame(StereoFrame),
    /// A publisher appeared.
    PublisherUp,
    /// The last publisher went away (clean exit, or a killed process).
    PublisherGone,
    /// Nothing arrived within the time-out.
    Timeout,
    /// SIGINT or SIGTERM was received.
    Interrupted,
}

/// One valid stereo sample, borrowed from shared memory (no copy). The slot goes back to the
/// publisher when this is dropped, so hold it only as long as needed.
pub struct StereoFrame {
    sample: Sample<ipc::Service, [u8], StereoHeader>,
    header: StereoHeader,
    layout: StereoLayout,
    pixels: *const u8,
    receive_time_ns: u64,
}

impl StereoFrame {
    /// The (validated copy of the) header.
    pub fn header(&self) -> &StereoHeader {
        &self.header
    }

    pub fn layout(&self) -> &StereoLayout {
        &self.layout
    }

    pub fn frame_id(&self) -> u64 {
        self.header.frame_id
    }

    /// The whole payload: `camera_count` planes of `height` rows of `stride` bytes.
    pub fn payload(&self) -> &[u8] {
        // SAFETY: `pixels` is the start of the sample's payload, which iceoryx2 reported to be
        // `layout.payload_len` bytes long when the sample was validated (the length is read
        // once, so a publisher rewriting the sample header later cannot change it). The
        // mapping lives as long as `self.sample`, which `self` owns.
        unsafe { std::slice::from_raw_parts(self.pixels, self.layout.payload_len) }
    }

    /// Camera `index`'s image: `height` rows of `stride` bytes (the first `width` bytes of each
    /// row are pixels). `None` if there is no such camera.
    pub fn camera(&self, index: usize) -> Option<&[u8]> {
        if index >= self.layout.camera_count {
            return None;
        }
        let start = index * self.layout.plane_len;
        self.payload().get(start..start + self.layout.plane_len)
    }

    /// The pixels of row `y` of camera `camera` (`width * bytes_per_pixel` bytes).
    pub fn row(&self, camera: usize, y: usize) -> Option<&[u8]> {
        if y >= self.layout.height {
            return None;
        }
        let plane = self.camera(camera)?;
        plane.get(y * self.layout.stride..y * self.layout.stride + self.layout.row_len)
    }

    /// `CLOCK_MONOTONIC` ns when this subscriber took the sample.
    pub fn receive_time_ns(&self) -> u64 {
        self.receive_time_ns
    }

    /// Publish stamp to receive, ns; `None` if the publish stamp lies in the future (a
    /// publisher on another clock).
    pub fn latency_ns(&self) -> Option<u64> {
        self.receive_time_ns.checked_sub(self.header.publish_time_ns)
    }

    /// The iceoryx2 id of the publisher that sent this frame.
    pub fn publisher_id(&self) -> u128 {
        self.sample.origin().value()
    }
}

/// Subscribes to `handeye/stereo`.
///
/// ```no_run
/// use std::time::Duration;
/// use handeye_wire::{Domain, WireNode};
/// use handeye_wire::stereo::{StereoEvent, StereoSubscriber};
/// let node = WireNode::create(&Domain::new("handeye")?, "viewer")?;
/// let mut frames = StereoSubscriber::create(&node, 2)?;
/// loop {
///     match frames.wait(Duration::from_secs(1))? {
///         StereoEvent::Frame(f) => println!("frame {} left row 0 = {:?}", f.frame_id(), &f.row(0, 0).unwrap()[..4]),
///         StereoEvent::PublisherGone => println!("camera gone"),
///         StereoEvent::Interrupted => break,
///         _ => {}
///     }
/// }
/// # Ok::<_, Box<dyn std::error::Error>>(())
/// ```
pub struct StereoSubscriber {
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, [u8], StereoHeader>,
    listener: iceoryx2::port::listener::Listener<ipc::Service>,
    service: PubSubFactory<ipc::Service, [u8], StereoHeader>,
    _events: EventFactory<ipc::Service>,
    node: WireNode,
    stats: StereoStats,
    /// (publisher id, frame id) of the last valid frame.
    last: Option<(u128, u64)>,
    liveness: Liveness,
    log: RateLimitedLog,
}

impl StereoSubscriber {
    /// Subscribes with a queue of `buffer_size` frames (1..=2). A real-time consumer that
    /// only wants the newest frame uses 1; a recorder or monitor uses 2.
    pub fn create(node: &WireNode, buffer_size: usize) -> Result<Self, StereoSubscriberError> {
        let max = STEREO_SIZING.subscriber_max_buffer_size;
        if buffer_size == 0 || buffer_size > max {
            return Err(StereoSubscriberError::BufferSize { requested: buffer_size, max });
        }
        let service = open_stereo_service(node)?;
        let events = open_event_service(node, service::STEREO, &STEREO_SIZING)?;
        let port_err = |port: &'static str, e: String| StereoSubscriberError::Port { port, service: service::STEREO, detail: e };
        let listener = events.listener_builder().create().map_err(|e| port_err("listener", format!("{e:?}")))?;
        let subscriber =
            service.subscriber_builder().buffer_size(buffer_size).create().map_err(|e| port_err("subscriber", format!("{e:?}")))?;
        Ok(Self {
            subscriber,
            listener,
            service,
            _events: events,
            node: node.clone(),
            stats: StereoStats::default(),
            last: None,
            liveness: Liveness::new(),
            log: RateLimitedLog::new(StereoReject::KEYS.len() + 1),
        })
    }

    pub fn stats(&self) -> &StereoStats {
        &self.stats
    }

    /// Whether a publisher was connected at the last liveness check (`None` before it).
    pub fn publisher_alive(&self) -> Option<bool> {
        self.liveness.alive()
    }

    /// The next valid frame already queued, if any, without waiting. Invalid samples on the
    /// way are counted, logged (at most once a second per reason) and released.
    pub fn try_receive(&mut self) -> Option<StereoFrame> {
        loop {
            let sample = match self.subscriber.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return None,
                Err(e) => {
                    self.stats.receive_errors += 1;
                    let errors = self.stats.receive_errors;
                    self.log.log(StereoReject::KEYS.len(), |suppressed| {
                        tracing::warn!(service = service::STEREO, ?e, errors, suppressed, "receive failed");
                    });
                    return None;
                }
            };
            let receive_time_ns = monotonic_ns();
            match self.check(&sample) {
                Ok((header, layout, pixels)) => {
                    self.stats.received += 1;
                    return Some(StereoFrame { sample, header, layout, pixels, receive_time_ns });
                }
                Err(reason) => {
                    self.stats.rejected[reason.index()] += 1;
                    let count = self.stats.rejected[reason.index()];
                    self.log.log(reason.index(), |suppressed| {
                        tracing::warn!(
                            service = service::STEREO,
                            reason = reason.key(),
                            count,
                            suppressed,
                            "rejected stereo sample: {reason}"
                        );
                    });
                }
            }
        }
    }

    fn check(&mut self, sample: &Sample<ipc::Service, [u8], StereoHeader>) -> Result<(StereoHeader, StereoLayout, *const u8), StereoReject> {
        // Copy the header out of shared memory once and judge only the copy.
        let header = *sample.user_header();
        let payload = sample.payload();
        let layout = validate_stereo(&header, payload.len())?;
        let origin = sample.origin().value();
        if let Some((last_origin, last_id)) = self.last
            && last_origin == origin
        {
            if header.frame_id <= last_id {
                return Err(StereoReject::FrameIdNotIncreasing { previous: last_id, found: header.frame_id });
            }
            self.stats.missed += header.frame_id - last_id - 1;
        }
        // A new publisher starts a new id sequence: no gap is counted across publishers.
        self.last = Some((origin, header.frame_id));
        Ok((header, layout, payload.as_ptr()))
    }

    /// Waits up to `timeout` for the next valid frame or a change of publisher liveness,
    /// sleeping on the service's event listener in between (no busy polling). Queued frames
    /// come first; liveness is re-checked at least every [`crate::LIVENESS_PERIOD`], so a
    /// killed publisher is reported within about that period.
    pub fn wait(&mut self, timeout: Duration) -> Result<StereoEvent, StereoWaitError> {
        let waited = wait_on(self, timeout).map_err(|detail| StereoWaitError::Listener { service: service::STEREO, detail })?;
        Ok(match waited {
            Waited::Received(frame) => StereoEvent::Frame(frame),
            Waited::Publisher(LivenessChange::Up) => {
                self.stats.publisher_up += 1;
                StereoEvent::PublisherUp
            }
            Waited::Publisher(LivenessChange::Gone) => {
                self.stats.publisher_gone += 1;
                // The next publisher starts a new sequence.
                self.last = None;
                StereoEvent::PublisherGone
            }
            Waited::Interrupted => StereoEvent::Interrupted,
            Waited::Timeout => StereoEvent::Timeout,
        })
    }
}

impl ListeningPort for StereoSubscriber {
    type Item = StereoFrame;

    fn try_receive(&mut self) -> Option<StereoFrame> {
        StereoSubscriber::try_receive(self)
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

//! The stereo publisher: loans one shared-memory slot per frame, lets the caller write the
//! pixels into it once, stamps and sends it, and wakes the subscribers.

use std::mem::MaybeUninit;
use std::time::{Duration, Instant};

use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::LoanError;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use iceoryx2::service::port_factory::event::PortFactory as EventFactory;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use thiserror::Error;

use super::{StereoFormat, StereoLayout, StereoReject};
use crate::domain::WireNode;
use crate::liveness::{create_publisher, PublisherSlotError};
use crate::services::{event_id, open_event_service, service_name, OpenError, STEREO_SIZING};
use crate::types::{monotonic_ns, service, StereoHeader};

/// How a publisher behaves when a subscriber has not yet taken its earlier frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delivery {
    /// A camera: never wait. A subscriber whose queue is full loses its oldest queued frame
    /// (iceoryx2 safe overflow), so it always finds the newest frame. The default.
    Latest,
    /// Never lose a frame: at most `in_flight` frames (1..) may be sent and not yet released
    /// by every subscriber; `publish` waits (up to `timeout`) for a slot. With `in_flight` no
    /// larger than the smallest subscriber queue (1 is always safe), nothing can overflow.
    /// This is `handeye feed --rate-hz 0`: as fast as the slowest subscriber allows.
    Lossless { in_flight: usize, timeout: Duration },
}

/// Options of a [`StereoPublisher`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StereoPublisherOptions {
    pub delivery: Delivery,
    /// How long `create` retries when the service's one publisher slot is still held by a
    /// process that just died (its node is cleaned up meanwhile).
    pub create_timeout: Duration,
}

impl Default for StereoPublisherOptions {
    fn default() -> Self {
        Self { delivery: Delivery::Latest, create_timeout: Duration::from_secs(2) }
    }
}

/// Why a stereo publisher could not be created.
#[derive(Debug, Error)]
pub enum StereoPublisherError {
    #[error("invalid stereo geometry {geometry:?}: {reason}")]
    Geometry { geometry: StereoFormat, reason: StereoReject },
    #[error(transparent)]
    Open(#[from] OpenError),
    #[error(
        "another publisher already sends on '{service}' in domain '{domain}' (one camera source \
         per domain): stop it, or use another --domain"
    )]
    PublisherSlotTaken { service: &'static str, domain: String },
    #[error("could not create the {port} port on '{service}': {detail}")]
    Port { port: &'static str, service: &'static str, detail: String },
    #[error("Delivery::Lossless needs in_flight >= 1")]
    ZeroInFlight,
}

/// Why one frame could not be published.
#[derive(Debug, Error)]
pub enum PublishError {
    #[error("payload of {len} bytes exceeds this publisher's slot of {max} bytes")]
    PayloadTooLarge { len: usize, max: usize },
    #[error("could not loan a shared-memory slot: {0:?}")]
    Loan(LoanError),
    #[error("no subscriber released a frame for {waited:?} (lossless delivery): is the subscriber stuck?")]
    NoCapacity { waited: Duration },
    #[error("interrupted (SIGINT/SIGTERM) while waiting for a free slot")]
    Interrupted,
    #[error("frame id {frame_id} is below the next id {next}: ids must strictly increase")]
    FrameIdNotIncreasing { frame_id: u64, next: u64 },
    #[error("could not send the sample: {detail}")]
    Send { detail: String },
    #[error("could not notify the subscribers: {detail}")]
    Notify { detail: String },
}

/// Publishes frames of one [`StereoFormat`] on `handeye/stereo`.
///
/// ```no_run
/// use handeye_wire::{Domain, WireNode};
/// use handeye_wire::stereo::{StereoFormat, StereoPublisher, StereoPublisherOptions};
/// let node = WireNode::create(&Domain::new("handeye")?, "my-camera")?;
/// let mut publisher = StereoPublisher::create(&node, StereoFormat::gray8_pair(640, 480),
///     StereoPublisherOptions::default())?;
/// let capture_time_ns = handeye_wire::monotonic_ns();
/// publisher.publish(capture_time_ns, |pixels| pixels.fill(128))?; // left rows, then right rows
/// # Ok::<_, Box<dyn std::error::Error>>(())
/// ```
pub struct StereoPublisher {
    // Field order is drop order: the publisher port goes before the notifier, so a subscriber
    // woken by the notifier's "dropped" event already sees no publisher.
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, [u8], StereoHeader>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    service: PubSubFactory<ipc::Service, [u8], StereoHeader>,
    _events: EventFactory<ipc::Service>,
    node: WireNode,
    geometry: StereoFormat,
    layout: StereoLayout,
    max_payload: usize,
    delivery: Delivery,
    next_frame_id: u64,
}

impl StereoPublisher {
    /// Opens `handeye/stereo` in the node's domain and creates a publisher whose slots hold
    /// exactly one frame of `geometry`.
    pub fn create(node: &WireNode, geometry: StereoFormat, options: StereoPublisherOptions) -> Result<Self, StereoPublisherError> {
        let layout = geometry.layout().map_err(|reason| StereoPublisherError::Geometry { geometry, reason })?;
        Self::create_with_slot(node, geometry, layout, layout.payload_len, options)
    }

    /// A publisher for tests and driver authors that may send any header and any payload
    /// length up to `max_payload` bytes with [`StereoPublisher::publish_raw`]. `publish`
    /// still sends `geometry`.
    pub fn create_raw(
        node: &WireNode,
        geometry: StereoFormat,
        max_payload: usize,
        options: StereoPublisherOptions,
    ) -> Result<Self, StereoPublisherError> {
        let layout = geometry.layout().map_err(|reason| StereoPublisherError::Geometry { geometry, reason })?;
        Self::create_with_slot(node, geometry, layout, max_payload.max(layout.payload_len), options)
    }

    fn create_with_slot(
        node: &WireNode,
        geometry: StereoFormat,
        layout: StereoLayout,
        max_payload: usize,
        options: StereoPublisherOptions,
    ) -> Result<Self, StereoPublisherError> {
        if let Delivery::Lossless { in_flight: 0, .. } = options.delivery {
            return Err(StereoPublisherError::ZeroInFlight);
        }
        let service = open_stereo_service(node)?;
        let events = open_event_service(node, service::STEREO, &STEREO_SIZING)?;
        let create = || {
            let mut builder = service
                .publisher_builder()
                .initial_max_slice_len(max_payload)
                .allocation_strategy(AllocationStrategy::Static)
                .max_loaned_samples(STEREO_SIZING.publisher_max_loaned_samples);
            if let Delivery::Lossless { in_flight, .. } = options.delivery {
                // The credit pool: only `in_flight` slots exist, and a slot comes back only when
                // every subscriber has released the frame in it. `flush` loans them all at once.
                builder = builder.max_loaned_samples(in_flight).override_sample_preallocation(move |_| in_flight);
            }
            builder.create()
        };
        let publisher = create_publisher(node, &service, options.create_timeout, create).map_err(|e| match e {
            PublisherSlotError::Taken => {
                StereoPublisherError::PublisherSlotTaken { service: service::STEREO, domain: node.domain().to_string() }
            }
            PublisherSlotError::Create(e) => {
                StereoPublisherError::Port { port: "publisher", service: service::STEREO, detail: format!("{e:?}") }
            }
        })?;
        let notifier = events
            .notifier_builder()
            .default_event_id(EventId::new(event_id::SAMPLE))
            .create()
            .map_err(|e| StereoPublisherError::Port { port: "notifier", service: service::STEREO, detail: format!("{e:?}") })?;
        Ok(Self {
            publisher,
            notifier,
            service,
            _events: events,
            node: node.clone(),
            geometry,
            layout,
            max_payload,
            delivery: options.delivery,
            next_frame_id: 0,
        })
    }

    pub fn geometry(&self) -> &StereoFormat {
        &self.geometry
    }

    pub fn layout(&self) -> &StereoLayout {
        &self.layout
    }

    /// The id the next [`StereoPublisher::publish`] will use (starts at 0, +1 per frame).
    pub fn next_frame_id(&self) -> u64 {
        self.next_frame_id
    }

    /// Counts one frame that this publisher captured but did not send (a camera pair dropped
    /// for skew, say): the next frame id skips it, and the gap tells every subscriber (and the
    /// daemon, which reads a gap in the ids as a dropped frame) that a frame is missing.
    pub fn skip_frame_id(&mut self) {
        self.next_frame_id += 1;
    }

    /// Number of subscribers connected now (dead ones removed first).
    pub fn subscriber_count(&self) -> usize {
        self.service.try_cleanup_dead_nodes();
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Waits until at least `n` subscribers are connected. Returns `Ok(false)` on time-out and
    /// `Err(Interrupted)` on SIGINT/SIGTERM.
    pub fn wait_for_subscribers(&self, n: usize, timeout: Duration) -> Result<bool, PublishError> {
        let start = Instant::now();
        loop {
            if self.subscriber_count() >= n {
                return Ok(true);
            }
            if start.elapsed() >= timeout {
                return Ok(false);
            }
            if !self.node.sleep(Duration::from_millis(20)) {
                return Err(PublishError::Interrupted);
            }
        }
    }

    /// Publishes one frame: loans a slot of exactly the payload size, calls `fill` with the
    /// payload (camera 0's rows, then camera 1's, ..., `stride` bytes apart) to write the
    /// pixels in place, stamps the header (`frame_id`, `capture_time_ns`, `publish_time_ns`)
    /// and sends it. Returns the frame id.
    ///
    /// `fill` must write every pixel: bytes it skips keep whatever an earlier frame left there.
    pub fn publish(&mut self, capture_time_ns: u64, fill: impl FnOnce(&mut [u8])) -> Result<u64, PublishError> {
        self.publish_with_id(self.next_frame_id, capture_time_ns, fill)
    }

    /// Like [`StereoPublisher::publish`], with the frame id chosen by the caller: a replay of
    /// a recording keeps the recorded ids, gaps included, so a subscriber counts the same
    /// missed frames the recorder did. `frame_id` must be at least
    /// [`StereoPublisher::next_frame_id`] (ids strictly increase); later `publish` calls go on
    /// from `frame_id + 1`.
    pub fn publish_with_id(&mut self, frame_id: u64, capture_time_ns: u64, fill: impl FnOnce(&mut [u8])) -> Result<u64, PublishError> {
        if frame_id < self.next_frame_id {
            return Err(PublishError::FrameIdNotIncreasing { frame_id, next: self.next_frame_id });
        }
        let mut header = self.geometry.header();
        header.frame_id = frame_id;
        header.capture_time_ns = capture_time_ns;
        self.send(header, self.layout.payload_len, fill)?;
        self.next_frame_id = frame_id.saturating_add(1);
        Ok(frame_id)
    }

    /// Sends `header` as given (only `publish_time_ns` is stamped) with a payload of
    /// `payload_len` bytes written by `fill`: no checks, so tests can send malformed samples.
    pub fn publish_raw(&mut self, header: StereoHeader, payload_len: usize, fill: impl FnOnce(&mut [u8])) -> Result<(), PublishError> {
        self.send(header, payload_len, fill)
    }

    fn send(&mut self, mut header: StereoHeader, payload_len: usize, fill: impl FnOnce(&mut [u8])) -> Result<(), PublishError> {
        if payload_len > self.max_payload {
            return Err(PublishError::PayloadTooLarge { len: payload_len, max: self.max_payload });
        }
        let timeout = match self.delivery {
            Delivery::Latest => Duration::ZERO,
            Delivery::Lossless { timeout, .. } => timeout,
        };
        let mut sample = self.loan(payload_len, timeout)?;
        {
            let payload: &mut [MaybeUninit<u8>] = sample.payload_mut();
            // SAFETY: the slot lives in a shared-memory mapping, which the kernel zero-fills
            // when it is created and which later holds earlier samples: its bytes are always
            // initialised, and every bit pattern is a valid u8. `MaybeUninit<u8>` has the
            // layout of `u8`.
            let bytes: &mut [u8] = unsafe { &mut *(payload as *mut [MaybeUninit<u8>] as *mut [u8]) };
            fill(bytes);
        }
        // SAFETY: see above; all bytes are initialised.
        let mut sample = unsafe { sample.assume_init() };
        header.publish_time_ns = monotonic_ns();
        *sample.user_header_mut() = header;
        sample.send().map_err(|e| PublishError::Send { detail: format!("{e:?}") })?;
        self.notifier.notify().map_err(|e| PublishError::Notify { detail: format!("{e:?}") })?;
        Ok(())
    }

    /// With lossless delivery, waits until every frame sent so far has been released by every
    /// subscriber, so that dropping the publisher now loses nothing (iceoryx2 discards frames
    /// still queued when their publisher goes away). Returns `Ok(false)` on time-out. With
    /// latest delivery there is nothing to wait for and it returns `Ok(true)` at once.
    pub fn flush(&mut self, timeout: Duration) -> Result<bool, PublishError> {
        let Delivery::Lossless { in_flight, .. } = self.delivery else { return Ok(true) };
        let deadline = Instant::now() + timeout;
        let mut held = Vec::with_capacity(in_flight);
        for _ in 0..in_flight {
            match self.loan(self.layout.payload_len, deadline.saturating_duration_since(Instant::now())) {
                Ok(s) => held.push(s),
                Err(PublishError::NoCapacity { .. }) => return Ok(false),
                Err(e) => return Err(e),
            }
        }
        Ok(true) // dropping `held` returns the slots unsent
    }

    fn loan(
        &mut self,
        payload_len: usize,
        timeout: Duration,
    ) -> Result<iceoryx2::sample_mut_uninit::SampleMutUninit<ipc::Service, [MaybeUninit<u8>], StereoHeader>, PublishError> {
        let in_lossless = matches!(self.delivery, Delivery::Lossless { .. });
        let start = Instant::now();
        let mut next_cleanup = start + Duration::from_millis(100);
        loop {
            match self.publisher.loan_slice_uninit(payload_len) {
                Ok(s) => return Ok(s),
                Err(LoanError::OutOfMemory) if in_lossless => {
                    // Every slot is still held by a subscriber. Drop departed subscribers (and
                    // the frames they held), then look again shortly.
                    let _ = self.publisher.update_connections();
                    let now = Instant::now();
                    if now >= next_cleanup {
                        self.service.try_cleanup_dead_nodes();
                        next_cleanup = now + Duration::from_millis(100);
                    }
                    let waited = now - start;
                    if waited >= timeout {
                        return Err(PublishError::NoCapacity { waited });
                    }
                    if !self.node.sleep(Duration::from_micros(100)) {
                        return Err(PublishError::Interrupted);
                    }
                }
                Err(e) => return Err(PublishError::Loan(e)),
            }
        }
    }
}

/// Opens `handeye/stereo` with the contract's settings.
pub(crate) fn open_stereo_service(node: &WireNode) -> Result<PubSubFactory<ipc::Service, [u8], StereoHeader>, OpenError> {
    let s = &STEREO_SIZING;
    node.iceoryx2()
        .service_builder(&service_name(service::STEREO)?)
        .publish_subscribe::<[u8]>()
        .user_header::<StereoHeader>()
        .max_publishers(s.max_publishers)
        .max_subscribers(s.max_subscribers)
        .subscriber_max_buffer_size(s.subscriber_max_buffer_size)
        .subscriber_max_borrowed_samples(s.subscriber_max_borrowed_samples)
        .history_size(s.history_size)
        .max_nodes(s.max_nodes)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| OpenError::Open {
            service: service::STEREO.to_owned(),
            domain: node.domain().to_string(),
            pattern: "publish-subscribe",
            detail: format!("{e:?}"),
        })
}

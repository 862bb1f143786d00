//! The capture loop: take frames from the sources, pair them, publish, watch the sources.
//!
//! One thread does it all, waking on whichever comes first (a frame, a source's end, a
//! retry or progress time), so a source's end is reported as soon as GStreamer posts it.

use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use crossbeam::channel::Select;
use gstreamer as gst;
use gstreamer::prelude::*;
use handeye_wire::stereo::{PublishError, StereoPublisher};
use handeye_wire::{monotonic_ns, WireNode};

use super::clock::Stamp;
use super::pairing::{DropReason, Paired, Pairer, Stamped};
use super::pipeline::Side;
use super::source::{CapturedFrame, Source, SourceEnd, SourceEvent};
use super::args::CameraArgs;
use super::summary::{record, CameraStats, ReportedEnd};

/// Left or right frames that may wait for a partner; a side that runs further ahead is held
/// back (lossless) or loses its oldest frame (live).
pub(super) const MAX_WAITING: usize = 8;

/// One side's source: running, or waiting to be rebuilt (--reconnect).
pub(super) enum Slot {
    Running(Source),
    Retrying { at: Instant, attempt: u32 },
}

impl Slot {
    pub(super) fn source(&self) -> Option<&Source> {
        match self {
            Slot::Running(s) => Some(s),
            Slot::Retrying { .. } => None,
        }
    }
}

/// How the run ended.
pub(super) enum End {
    Completed,
    Interrupted,
    /// A file source ended with --count 0: the natural end.
    SourceDone,
    SourceFailed(String),
}

/// One run of `handeye camera`: its sources, the pairer, the publisher and the counts. Built
/// by `start`, driven by [`Capture::run_loop`].
pub(super) struct Capture<'a> {
    pub(super) args: &'a CameraArgs,
    pub(super) clock: gst::Clock,
    pub(super) descriptions: [Option<String>; 2],
    pub(super) slots: [Option<Slot>; 2],
    pub(super) pairer: Pairer<CapturedFrame>,
    pub(super) publisher: StereoPublisher,
    pub(super) node: WireNode,
    pub(super) lossless: bool,
    pub(super) stats: CameraStats,
    /// Busy drops already accounted for, per side.
    pub(super) busy_seen: [u64; 2],
    /// Whether each side's source was live when last started.
    pub(super) live: [Option<bool>; 2],
    /// CLOCK_MONOTONIC ns when each side last started playing, and of its last frame: a live
    /// source silent for longer than --stall-timeout-s has stalled.
    pub(super) playing_since_ns: [u64; 2],
    pub(super) last_frame_ns: [Option<u64>; 2],
}

/// A live source may take this long to deliver its first frame (cameras negotiate, focus).
const FIRST_FRAME_TIMEOUT_NS: u64 = 5_000_000_000;

pub(super) fn index(side: Side) -> usize {
    match side {
        Side::Left => 0,
        Side::Right => 1,
    }
}

pub(super) const SIDES: [Side; 2] = [Side::Left, Side::Right];

impl Capture<'_> {
    fn source(&self, side: Side) -> Option<&Source> {
        self.slots[index(side)].as_ref().and_then(Slot::source)
    }

    /// Plays every prepared source on one base time (see `Source::play`).
    pub(super) fn play_all(&mut self) -> Result<()> {
        let base_time = self.clock.time();
        self.playing_since_ns = [monotonic_ns(); 2];
        for side in SIDES {
            let slot = &mut self.slots[index(side)];
            if matches!(slot, Some(Slot::Running(_)))
                && let Some(Slot::Running(source)) = slot.take()
            {
                *slot = Some(match source.play(base_time) {
                    Ok(s) => Slot::Running(s),
                    Err(e) if self.args.reconnect => {
                        eprintln!("camera: {side} source: {e:#}; retrying in {:.1} s (attempt 1)", self.args.reconnect_delay_s);
                        Slot::Retrying { at: Instant::now() + Duration::from_secs_f64(self.args.reconnect_delay_s), attempt: 1 }
                    }
                    Err(e) => bail!("{side} source: {e:#}"),
                });
            }
        }
        Ok(())
    }

    pub(super) fn run_loop(&mut self) -> Result<End> {
        let start = Instant::now();
        let progress_every = (self.args.progress_s > 0.0).then(|| Duration::from_secs_f64(self.args.progress_s));
        let mut next_progress = progress_every.map(|p| start + p);
        let mut next_subscriber_check = start;
        loop {
            if self.args.count > 0 && self.stats.published >= self.args.count {
                return Ok(End::Completed);
            }
            if self.node.termination_requested() {
                return Ok(End::Interrupted);
            }
            let now = Instant::now();
            if let Some(t) = next_progress.filter(|t| now >= *t) {
                eprintln!("{}", self.stats.progress_line(self.args.mono));
                next_progress = progress_every.map(|p| (t + p).max(now));
            }
            if self.lossless && self.args.wait_subscriber_s > 0.0 && now >= next_subscriber_check {
                // Frames sent while no one listens would be lost: wait for a subscriber.
                next_subscriber_check = now + Duration::from_millis(250);
                if self.publisher.subscriber_count() == 0 {
                    eprintln!("camera: no subscriber left after {} frames", self.stats.published);
                    let wait = Duration::from_secs_f64(self.args.wait_subscriber_s);
                    if !self.wait_for_subscriber(wait)? {
                        return Ok(End::Interrupted);
                    }
                }
            }
            if let Some(end) = self.retry_sources()? {
                return Ok(end);
            }
            if let Some(end) = self.check_stalls()? {
                return Ok(end);
            }
            self.account_busy_drops();

            // Wait for a frame or an end, at most until the next retry or progress line.
            let mut deadline = now + Duration::from_millis(250);
            if let Some(t) = next_progress {
                deadline = deadline.min(t);
            }
            for slot in self.slots.iter().flatten() {
                if let Slot::Retrying { at, .. } = slot {
                    deadline = deadline.min(*at);
                }
            }
            for side in SIDES {
                if let Some(stall_ns) = self.stall_deadline_ns(side) {
                    deadline = deadline.min(now + Duration::from_nanos(stall_ns.saturating_sub(monotonic_ns())));
                }
            }
            let mut sel = Select::new();
            let mut handles: Vec<(Side, bool)> = Vec::new(); // (side, is_event)
            for side in SIDES {
                let Some(src) = self.source(side) else { continue };
                sel.recv(&src.events);
                handles.push((side, true));
                let waiting = match side {
                    Side::Left => self.pairer.waiting_left(),
                    Side::Right => self.pairer.waiting_right(),
                };
                // A lossless side that ran ahead waits (its queue fills, its decoder pauses).
                if !(self.lossless && waiting >= MAX_WAITING) {
                    sel.recv(&src.frames);
                    handles.push((side, false));
                }
            }
            let Ok(op) = sel.select_deadline(deadline) else { continue };
            let (side, is_event) = handles[op.index()];
            let src = self.source(side).ok_or_else(|| anyhow!("{side} source vanished"))?;
            if is_event {
                let event = op.recv(&src.events);
                if let Ok(event) = event
                    && let Some(end) = self.on_source_end(side, event)?
                {
                    return Ok(end);
                }
            } else if let Ok(frame) = op.recv(&src.frames) {
                self.on_frame(side, frame)?;
            }
        }
    }

    /// Frames a live source dropped because this loop was busy: a dropped left frame is an id.
    fn account_busy_drops(&mut self) {
        for side in SIDES {
            let Some(n) = self.source(side).map(Source::dropped_busy) else { continue };
            let new = n.saturating_sub(self.busy_seen[index(side)]);
            self.busy_seen[index(side)] = n;
            match side {
                Side::Left => {
                    self.stats.dropped_busy_left += new;
                    for _ in 0..new {
                        self.publisher.skip_frame_id();
                    }
                }
                Side::Right => self.stats.dropped_busy_right += new,
            }
        }
    }

    /// Waits for a subscriber, saying so. `Ok(false)` when interrupted; an error on time-out.
    pub(super) fn wait_for_subscriber(&self, wait: Duration) -> Result<bool> {
        if self.publisher.subscriber_count() > 0 {
            return Ok(true);
        }
        let domain = &self.args.domain.domain;
        eprintln!(
            "camera: waiting up to {:.0} s for a subscriber on handeye/stereo in domain '{domain}' \
             (start `handeye monitor` or the daemon with the same --domain)",
            wait.as_secs_f64()
        );
        match self.publisher.wait_for_subscribers(1, wait) {
            Ok(true) => Ok(true),
            Ok(false) => bail!("no subscriber on handeye/stereo in domain '{domain}' within {:.0} s (--wait-subscriber-s)", wait.as_secs_f64()),
            Err(PublishError::Interrupted) => Ok(false),
            Err(e) => Err(e.into()),
        }
    }

    /// Rebuilds the sources whose retry time has come (--reconnect).
    fn retry_sources(&mut self) -> Result<Option<End>> {
        for side in SIDES {
            let i = index(side);
            let Some(Slot::Retrying { at, attempt }) = self.slots[i] else { continue };
            if Instant::now() < at {
                continue;
            }
            let Some(description) = &self.descriptions[i] else { continue };
            let started = Source::prepare(side, description, &self.clock).and_then(|source| {
                if source.live && self.lossless {
                    bail!("came back live, but this run delivers lossless (its sources were not live); restart the camera");
                }
                source.set_lossless(self.lossless);
                source.play(self.clock.time())
            });
            match started {
                Ok(source) => {
                    eprintln!("camera: {side} source: running again (attempt {attempt})");
                    self.live[i] = Some(source.live);
                    self.playing_since_ns[i] = monotonic_ns();
                    self.last_frame_ns[i] = None;
                    self.busy_seen[i] = 0;
                    self.stats.reconnects += 1;
                    self.slots[i] = Some(Slot::Running(source));
                }
                Err(e) => {
                    eprintln!("camera: {side} source: {e:#}; retrying in {:.1} s (attempt {})", self.args.reconnect_delay_s, attempt + 1);
                    let at = Instant::now() + Duration::from_secs_f64(self.args.reconnect_delay_s);
                    self.slots[i] = Some(Slot::Retrying { at, attempt: attempt + 1 });
                }
            }
        }
        Ok(None)
    }

    /// When `side`'s source will count as stalled if no frame comes (live sources only).
    fn stall_deadline_ns(&self, side: Side) -> Option<u64> {
        let stall_ns = (self.args.stall_timeout_s * 1e9) as u64;
        if stall_ns == 0 || !self.source(side)?.live {
            return None;
        }
        let i = index(side);
        Some(match self.last_frame_ns[i] {
            Some(t) => t + stall_ns,
            None => self.playing_since_ns[i] + stall_ns.max(FIRST_FRAME_TIMEOUT_NS),
        })
    }

    /// A live source that went silent is handled like one that failed.
    fn check_stalls(&mut self) -> Result<Option<End>> {
        for side in SIDES {
            let Some(deadline_ns) = self.stall_deadline_ns(side) else { continue };
            let now_ns = monotonic_ns();
            if now_ns < deadline_ns {
                continue;
            }
            let since_ns = self.last_frame_ns[index(side)].unwrap_or(self.playing_since_ns[index(side)]);
            let silent_s = now_ns.saturating_sub(since_ns) as f64 / 1e9;
            let event = SourceEvent { end: SourceEnd::Stalled { silent_s }, posted_ns: deadline_ns };
            if let Some(end) = self.on_source_end(side, event)? {
                return Ok(Some(end));
            }
        }
        Ok(None)
    }

    /// A source ended: take the frames it delivered before, report it, and decide.
    fn on_source_end(&mut self, side: Side, event: SourceEvent) -> Result<Option<End>> {
        while let Some(frame) = self.source(side).and_then(Source::try_frame) {
            self.on_frame(side, frame)?;
        }
        let reported = ReportedEnd { side, event, reported_ns: monotonic_ns() };
        let message = format!("{side} source: {}", reported.event.end);
        eprintln!("camera: {message} (reported {:.1} ms after GStreamer posted it)", reported.detection_ns() as f64 / 1e6);
        let eos = matches!(reported.event.end, SourceEnd::Eos);
        self.stats.ends.push(reported);
        if self.args.count > 0 && self.stats.published >= self.args.count {
            return Ok(Some(End::Completed));
        }
        if self.args.reconnect {
            let i = index(side);
            if let Some(src) = self.source(side) {
                self.stats.unreadable += src.unreadable();
            }
            self.slots[i] = None; // stops the pipeline
            let waiting = match side {
                Side::Left => self.pairer.clear_left().len() as u64,
                Side::Right => self.pairer.clear_right().len() as u64,
            };
            match side {
                Side::Left => {
                    self.stats.dropped_stale += waiting;
                    for _ in 0..waiting {
                        self.publisher.skip_frame_id();
                    }
                }
                Side::Right => self.stats.right_unpaired += waiting,
            }
            eprintln!("camera: {side} source: rebuilding in {:.1} s (--reconnect)", self.args.reconnect_delay_s);
            let at = Instant::now() + Duration::from_secs_f64(self.args.reconnect_delay_s);
            self.slots[i] = Some(Slot::Retrying { at, attempt: 1 });
            return Ok(None);
        }
        let file_done = eos && self.args.count == 0 && self.live[index(side)] == Some(false);
        Ok(Some(if file_done { End::SourceDone } else { End::SourceFailed(message) }))
    }

    fn on_frame(&mut self, side: Side, frame: CapturedFrame) -> Result<()> {
        self.last_frame_ns[index(side)] = Some(monotonic_ns());
        if frame.stamp == Stamp::Arrival {
            self.stats.arrival_stamped += 1;
        }
        let stamped = Stamped { capture_ns: frame.capture_ns, item: frame };
        if self.args.mono {
            self.stats.left_frames += 1;
            return self.publish(&stamped, &stamped, None);
        }
        match side {
            Side::Left => {
                self.stats.left_frames += 1;
                self.pairer.push_left(stamped);
            }
            Side::Right => {
                self.stats.right_frames += 1;
                self.pairer.push_right(stamped);
            }
        }
        while let Some(decision) = self.pairer.next() {
            match decision {
                Paired::Pair { left, right, skew_ns } => self.publish(&left, &right, Some(skew_ns))?,
                Paired::DroppedLeft { reason, .. } => {
                    match reason {
                        DropReason::NoPartner => self.stats.dropped_skew += 1,
                        DropReason::Stale => self.stats.dropped_stale += 1,
                    }
                    self.publisher.skip_frame_id();
                }
                Paired::DroppedRight { .. } => self.stats.right_unpaired += 1,
            }
        }
        Ok(())
    }

    /// Publishes one pair, writing both images straight into the loaned shared-memory slot.
    /// The pair's capture time is the left frame's.
    fn publish(&mut self, left: &Stamped<CapturedFrame>, right: &Stamped<CapturedFrame>, skew_ns: Option<u64>) -> Result<()> {
        let layout = *self.publisher.layout();
        let mut copied = Ok(());
        let result = self.publisher.publish(left.capture_ns, |payload| {
            let (l, r) = payload.split_at_mut(layout.plane_len);
            copied = left
                .item
                .copy_rows(l, layout.row_len, layout.height, layout.stride)
                .and_then(|()| right.item.copy_rows(r, layout.row_len, layout.height, layout.stride));
        });
        let publish_ns = monotonic_ns();
        copied.context("copying a frame into shared memory")?;
        match result {
            Ok(id) => {
                let s = &mut self.stats;
                s.published += 1;
                s.first_frame_id.get_or_insert(id);
                s.last_frame_id = Some(id);
                s.first_publish_ns.get_or_insert(publish_ns);
                s.last_publish_ns = Some(publish_ns);
                record(&mut s.latencies_ns, publish_ns.saturating_sub(left.capture_ns));
                if let Some(k) = skew_ns {
                    record(&mut s.skews_ns, k);
                }
                Ok(())
            }
            Err(PublishError::Interrupted) => Ok(()), // the loop sees the termination request
            Err(PublishError::Loan(e)) if !self.lossless => {
                tracing::warn!("no free shared-memory slot ({e:?}): frame dropped");
                self.stats.dropped_publish += 1;
                self.publisher.skip_frame_id();
                Ok(())
            }
            Err(e) => Err(e).context(format!("publishing frame {}", self.publisher.next_frame_id())),
        }
    }

    /// Lets the subscribers take the last frames before the publisher goes away.
    pub(super) fn finish(&mut self, end: &End) -> Result<()> {
        for side in SIDES {
            if let Some(src) = self.source(side) {
                self.stats.unreadable += src.unreadable();
            }
        }
        self.account_busy_drops();
        self.stats.pending_left = self.pairer.waiting_left() as u64;
        self.stats.pending_right = self.pairer.waiting_right() as u64;
        self.stats.next_frame_id = self.publisher.next_frame_id();
        if matches!(end, End::Interrupted) {
            return Ok(());
        }
        if self.lossless {
            if !self.publisher.flush(Duration::from_secs(10))? {
                eprintln!("camera: the subscriber did not take the last frame within 10 s");
            }
        } else {
            // Like a camera: give a subscriber that keeps up a moment for the last frame.
            self.node.sleep(Duration::from_millis(100));
        }
        Ok(())
    }
}

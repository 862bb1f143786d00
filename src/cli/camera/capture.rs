//! The capture loop: take frames from the sources, pair them, publish, watch the sources.
//!
//! One thread does it all, waking on whichever comes first (a frame, a source's end, a
//! retry or progress time), so a source's end is reported as soon as GStreamer posts it.

use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use crossbeam::channel::Select;
use gstreamer as gst;
use gstreamer::prelude::*;
use handeye_wire::stereo::{Delivery, PublishError, StereoFormat, StereoPublisher, StereoPublisherOptions};
use handeye_wire::{monotonic_ns, WireNode};

use super::clock::{monotonic_clock, Stamp};
use super::pairing::{DropReason, Paired, Pairer, Stamped};
use super::pipeline::{full_description, Side};
use super::source::{CapturedFrame, Source, SourceEvent};
use super::summary::{CameraStats, ReportedEnd};
use super::args::{CameraArgs, DeliveryMode};

/// Left or right frames that may wait for a partner; a side that runs further ahead is held
/// back (lossless) or loses its oldest frame (live).
const MAX_WAITING: usize = 8;

/// One side's source: running, or waiting to be rebuilt (--reconnect).
enum Slot {
    Running(Source),
    Retrying { at: Instant, attempt: u32 },
}

impl Slot {
    fn source(&self) -> Option<&Source> {
        match self {
            Slot::Running(s) => Some(s),
            Slot::Retrying { .. } => None,
        }
    }
}

/// How the run ended.
enum End {
    Completed,
    Interrupted,
    /// A file source ended with --count 0: the natural end.
    SourceDone,
    SourceFailed(String),
}

struct Capture<'a> {
    args: &'a CameraArgs,
    clock: gst::Clock,
    descriptions: [Option<String>; 2],
    slots: [Option<Slot>; 2],
    pairer: Pairer<CapturedFrame>,
    publisher: StereoPublisher,
    node: WireNode,
    lossless: bool,
    stats: CameraStats,
    /// Busy drops already accounted for, per side.
    busy_seen: [u64; 2],
    /// Whether each side's source was live when last started.
    live: [Option<bool>; 2],
}

fn index(side: Side) -> usize {
    match side {
        Side::Left => 0,
        Side::Right => 1,
    }
}

const SIDES: [Side; 2] = [Side::Left, Side::Right];

pub fn run(args: &CameraArgs) -> Result<()> {
    gst::init().context("cannot initialise GStreamer (scripts/setup.sh installs it)")?;
    let clock = monotonic_clock();
    let (w, h) = (args.width_px, args.height_px);
    let descriptions = [
        Some(full_description(Side::Left, &args.left, w, h)?),
        match (&args.right, args.mono) {
            (Some(r), false) => Some(full_description(Side::Right, r, w, h)?),
            _ => None,
        },
    ];
    let retry_at = || Instant::now() + Duration::from_secs_f64(args.reconnect_delay_s);
    let mut slots: [Option<Slot>; 2] = [None, None];
    for side in SIDES {
        if let Some(d) = &descriptions[index(side)] {
            slots[index(side)] = Some(match Source::prepare(side, d, &clock) {
                Ok(s) => Slot::Running(s),
                Err(e) if args.reconnect => {
                    eprintln!("camera: {side} source: {e:#}; retrying in {:.1} s (attempt 1)", args.reconnect_delay_s);
                    Slot::Retrying { at: retry_at(), attempt: 1 }
                }
                Err(e) => bail!("{side} source: {e:#}"),
            });
        }
    }
    let live = [0, 1].map(|i| slots[i].as_ref().and_then(Slot::source).map(|s| s.live));
    let any_live = live.contains(&Some(true));
    let lossless = match args.delivery {
        DeliveryMode::Auto => !any_live && live.iter().any(Option::is_some),
        DeliveryMode::Latest => false,
        DeliveryMode::Lossless if any_live => {
            bail!("--delivery lossless: a live source (a camera) cannot wait for the subscribers; use latest or auto")
        }
        DeliveryMode::Lossless => true,
    };
    for s in slots.iter().flatten().filter_map(Slot::source) {
        s.set_lossless(lossless);
    }

    let domain = &args.domain.domain;
    let node = WireNode::create(domain, "handeye-camera")?;
    let wait = Duration::from_secs_f64(args.wait_subscriber_s);
    let delivery = if lossless {
        Delivery::Lossless { in_flight: 1, timeout: if wait.is_zero() { Duration::from_secs(30) } else { wait } }
    } else {
        Delivery::Latest
    };
    let publisher = StereoPublisher::create(&node, StereoFormat::gray8_pair(w, h), StereoPublisherOptions { delivery, ..Default::default() })?;
    let live_text = |i: usize| match live[i] {
        Some(true) => "live",
        Some(false) => "not live",
        None => "not started",
    };
    eprintln!(
        "camera: {} {w}x{h} GRAY8 on handeye/stereo, domain '{domain}', {} delivery; left {}{}",
        if args.mono { "mono (left as both views)" } else { "stereo" },
        if lossless { "lossless" } else { "latest" },
        live_text(0),
        if args.mono { String::new() } else { format!(", right {}", live_text(1)) }
    );
    let mut capture = Capture {
        args,
        clock,
        descriptions,
        slots,
        pairer: Pairer::new((args.max_skew_ms * 1e6).round() as u64, MAX_WAITING),
        publisher,
        node,
        lossless,
        stats: CameraStats::default(),
        busy_seen: [0, 0],
        live,
    };
    let start = Instant::now();
    // The sources play once someone listens: no frame is captured only to be thrown away.
    let end = if !wait.is_zero() && !capture.wait_for_subscriber(wait)? {
        End::Interrupted
    } else {
        capture.play_all()?;
        capture.run_loop()?
    };
    capture.finish(&end)?;
    let completed = matches!(end, End::Completed);
    let duration_s = start.elapsed().as_secs_f64();
    // Stop the pipelines before reporting; the publisher goes last, and subscribers see it gone.
    capture.slots = [None, None];
    let live_pair = (capture.live[0].unwrap_or(false), (!args.mono).then(|| capture.live[1].unwrap_or(false)));
    if args.json {
        let delivery = if capture.lossless { "lossless" } else { "latest" };
        println!("{}", capture.stats.json(delivery, live_pair, completed, duration_s));
    } else {
        print!("{}", capture.stats.text(args.mono, completed, duration_s));
    }
    drop(capture);
    match end {
        End::SourceFailed(why) => Err(anyhow!(why)),
        End::Completed | End::Interrupted | End::SourceDone => Ok(()),
    }
}

impl Capture<'_> {
    fn source(&self, side: Side) -> Option<&Source> {
        self.slots[index(side)].as_ref().and_then(Slot::source)
    }

    /// Plays every prepared source on one base time (see `Source::play`).
    fn play_all(&mut self) -> Result<()> {
        let base_time = self.clock.time();
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

    fn run_loop(&mut self) -> Result<End> {
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
            if self.lossless && now >= next_subscriber_check {
                // Frames sent while no one listens would be lost: wait for a subscriber.
                next_subscriber_check = now + Duration::from_millis(250);
                if self.publisher.subscriber_count() == 0 {
                    eprintln!("camera: no subscriber left after {} frames", self.stats.published);
                    let wait = Duration::from_secs_f64(self.args.wait_subscriber_s.max(1.0));
                    if !self.wait_for_subscriber(wait)? {
                        return Ok(End::Interrupted);
                    }
                }
            }
            if let Some(end) = self.retry_sources()? {
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
    fn wait_for_subscriber(&self, wait: Duration) -> Result<bool> {
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

    /// A source ended: take the frames it delivered before, report it, and decide.
    fn on_source_end(&mut self, side: Side, event: SourceEvent) -> Result<Option<End>> {
        while let Some(frame) = self.source(side).and_then(Source::try_frame) {
            self.on_frame(side, frame)?;
        }
        let reported = ReportedEnd { side, event, reported_ns: monotonic_ns() };
        let message = format!("{side} source: {}", reported.event.end);
        eprintln!("camera: {message} (reported {:.1} ms after GStreamer posted it)", reported.detection_ns() as f64 / 1e6);
        let eos = matches!(reported.event.end, super::source::SourceEnd::Eos);
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
                s.latencies_ns.push(publish_ns.saturating_sub(left.capture_ns));
                if let Some(k) = skew_ns {
                    s.skews_ns.push(k);
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
    fn finish(&mut self, end: &End) -> Result<()> {
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

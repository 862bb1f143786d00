//! One running GStreamer source: the pipeline, its frames, and how it ended.
//!
//! Frames leave GStreamer's streaming thread through the appsink's `new_sample` callback into
//! a short channel; the end of the source (an error, or the end of the stream) leaves through
//! the bus's *sync* handler, which GStreamer calls in the thread that posts the message, so
//! the command hears of it at once rather than at the next poll of the bus. Both stamp
//! CLOCK_MONOTONIC on the way out, so the command can report how long it took to notice.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use crossbeam::channel::{bounded, Receiver, RecvTimeoutError, SendTimeoutError, Sender};
use gstreamer as gst;
use gstreamer::prelude::*;
use gstreamer_app as gst_app;
use gstreamer_video as gst_video;
use gstreamer_video::prelude::*;
use handeye_wire::monotonic_ns;

use super::clock::{capture_time_ns, Stamp};
use super::pipeline::{Side, SINK_NAME};

/// Frames that may wait between GStreamer and the command. Short: a lossless source blocks
/// behind it (back-pressure reaches the decoder), a live one drops and counts.
const FRAME_QUEUE: usize = 4;

/// One frame in 8-bit gray, mapped for reading, and when it was captured.
pub struct CapturedFrame {
    pub frame: gst_video::VideoFrame<gst_video::video_frame::Readable>,
    /// CLOCK_MONOTONIC ns (see `clock`).
    pub capture_ns: u64,
    pub stamp: Stamp,
}

impl CapturedFrame {
    /// Copies the image's rows (`row_len` pixels each) into `dst`, rows `dst_stride` apart.
    pub fn copy_rows(&self, dst: &mut [u8], row_len: usize, height: usize, dst_stride: usize) -> Result<()> {
        let data = self.frame.plane_data(0).map_err(|e| anyhow!("cannot read the frame's pixels: {e}"))?;
        let src_stride = usize::try_from(self.frame.plane_stride()[0]).context("negative stride")?;
        if self.frame.width() as usize != row_len || self.frame.height() as usize != height {
            return Err(anyhow!("frame is {}x{}, expected {row_len}x{height}", self.frame.width(), self.frame.height()));
        }
        for y in 0..height {
            dst[y * dst_stride..y * dst_stride + row_len].copy_from_slice(&data[y * src_stride..y * src_stride + row_len]);
        }
        Ok(())
    }
}

/// How a source ended.
#[derive(Debug, Clone)]
pub enum SourceEnd {
    /// GStreamer's error: its message, and the element and details it names.
    Error { message: String, detail: String },
    /// The end of the stream (a file's end, `num-buffers` reached, a camera closed).
    Eos,
    /// A live source delivered no frame for this long, and GStreamer said nothing: a camera
    /// or network source that hangs or was killed without closing its stream.
    Stalled { silent_s: f64 },
}

impl std::fmt::Display for SourceEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SourceEnd::Error { message, detail } if detail.is_empty() => write!(f, "{message}"),
            SourceEnd::Error { message, detail } => write!(f, "{message} ({detail})"),
            SourceEnd::Eos => write!(f, "ended (end of stream)"),
            SourceEnd::Stalled { silent_s } => write!(f, "stalled: no frame for {silent_s:.2} s (--stall-timeout-s)"),
        }
    }
}

/// The end of a source, stamped when GStreamer posted it.
#[derive(Debug, Clone)]
pub struct SourceEvent {
    pub end: SourceEnd,
    /// CLOCK_MONOTONIC ns when GStreamer posted the message.
    pub posted_ns: u64,
}

/// What the appsink callback shares with the command.
struct Shared {
    /// Set while the command stops the pipeline, so that a callback blocked on a full queue
    /// gives up instead of holding the streaming thread (and `set_state(Null)`) forever.
    stopping: AtomicBool,
    /// Wait for room in the queue (lossless) rather than dropping the frame (live).
    block_when_full: AtomicBool,
    /// Frames dropped because the queue was full (live sources only).
    dropped_busy: AtomicU64,
    /// Frames that could not be mapped as GRAY8 of the requested size (should not happen:
    /// the caps are fixed), or had no buffer.
    unreadable: AtomicU64,
}

/// A running pipeline whose frames and end arrive on channels.
pub struct Source {
    /// Live sources (cameras, `is-live=true`) run on their own clock; the others (files) are
    /// played at their own frame rate and can be slowed down without losing frames.
    pub live: bool,
    pipeline: gst::Pipeline,
    pub frames: Receiver<CapturedFrame>,
    pub events: Receiver<SourceEvent>,
    shared: Arc<Shared>,
}

impl Source {
    /// Parses `description` (the full pipeline, see `pipeline::full_description`), and brings
    /// it to PAUSED on `clock`: a file has its first frame decoded (prerolled), a live source
    /// says it is live. [`Source::play`] starts it. A pipeline that does not parse or cannot
    /// start is an error with GStreamer's text.
    pub fn prepare(side: Side, description: &str, clock: &gst::Clock) -> Result<Source> {
        let element = gst::parse::launch_full(description, None, gst::ParseFlags::FATAL_ERRORS)
            .map_err(|e| anyhow!("cannot build the pipeline '{description}': {e}"))?;
        let pipeline = element.downcast::<gst::Pipeline>().map_err(|_| anyhow!("'{description}' is not a pipeline"))?;
        // Every stamp is read from this clock (see `clock` for why it is CLOCK_MONOTONIC).
        pipeline.use_clock(Some(clock));
        let sink = pipeline
            .by_name(SINK_NAME)
            .and_then(|e| e.downcast::<gst_app::AppSink>().ok())
            .ok_or_else(|| anyhow!("the pipeline has no appsink named {SINK_NAME}"))?;
        // A file is delivered at its own frame rate, like a camera: its buffers wait for their
        // time on the clock. A live source is switched to `sync=false` below.
        sink.set_property("sync", true);

        let shared = Arc::new(Shared {
            stopping: AtomicBool::new(false),
            block_when_full: AtomicBool::new(false),
            dropped_busy: AtomicU64::new(0),
            unreadable: AtomicU64::new(0),
        });
        let (frame_tx, frames) = bounded::<CapturedFrame>(FRAME_QUEUE);
        let (event_tx, events) = bounded::<SourceEvent>(16);
        sink.set_callbacks(
            gst_app::app_sink::AppSinkCallbacks::builder()
                .new_sample({
                    let shared = shared.clone();
                    move |sink| on_sample(sink, &frame_tx, &shared)
                })
                .build(),
        );
        let bus = pipeline.bus().ok_or_else(|| anyhow!("the pipeline has no bus"))?;
        bus.set_sync_handler(move |_, msg| {
            on_message(side, msg, &event_tx);
            // Nobody pops this bus: drop every message here so none pile up.
            gst::BusSyncReply::Drop
        });

        let source = |live| Source { live, pipeline: pipeline.clone(), frames: frames.clone(), events: events.clone(), shared: shared.clone() };
        let paused = pipeline.set_state(gst::State::Paused);
        let live = match paused {
            Ok(gst::StateChangeSuccess::NoPreroll) => true,
            Ok(_) => false,
            Err(_) => return Err(source(false).failure("could not start")),
        };
        if live {
            // A live source stamps its buffers at capture: deliver them as soon as they come.
            sink.set_property("sync", false);
        } else if let (Err(_), ..) = pipeline.state(gst::ClockTime::from_seconds(10)) {
            // Waits for the preroll, so that `play` starts the clock when the frames are ready.
            return Err(source(false).failure("could not preroll"));
        }
        Ok(source(live))
    }

    /// Plays the pipeline with running time 0 at `base_time` on the clock. The two sides of a
    /// pair get the same base time, so two files (a stereo recording) have frame k of both
    /// due at the same moment and pair by time; for a live source, which stamps buffers with
    /// the clock at capture, the base time cancels out of the capture time.
    pub fn play(self, base_time: gst::ClockTime) -> Result<Source> {
        self.pipeline.set_start_time(gst::ClockTime::NONE);
        self.pipeline.set_base_time(base_time);
        if self.pipeline.set_state(gst::State::Playing).is_err() {
            return Err(self.failure("could not play"));
        }
        Ok(self)
    }

    /// The error GStreamer posted while a state change failed, or `what` when it posted none.
    fn failure(self, what: &str) -> anyhow::Error {
        // The sync handler ran in the thread that failed, so the message is already queued.
        match self.events.recv_timeout(Duration::from_millis(200)) {
            Ok(SourceEvent { end, .. }) => anyhow!("{end}"),
            Err(_) => anyhow!("{what} (GStreamer gave no reason)"),
        }
    }

    /// Lossless sources hold their streaming thread while the frame queue is full; the others
    /// drop the frame and count it.
    pub fn set_lossless(&self, lossless: bool) {
        self.shared.block_when_full.store(lossless, Ordering::Relaxed);
    }

    /// Frames dropped so far because the command did not take them in time (live only).
    pub fn dropped_busy(&self) -> u64 {
        self.shared.dropped_busy.load(Ordering::Relaxed)
    }

    /// Frames that could not be read as GRAY8 of the requested size.
    pub fn unreadable(&self) -> u64 {
        self.shared.unreadable.load(Ordering::Relaxed)
    }

    /// Takes a frame already waiting, if any.
    pub fn try_frame(&self) -> Option<CapturedFrame> {
        match self.frames.recv_timeout(Duration::ZERO) {
            Ok(f) => Some(f),
            Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => None,
        }
    }
}

impl Drop for Source {
    fn drop(&mut self) {
        self.shared.stopping.store(true, Ordering::Relaxed);
        let _ = self.pipeline.set_state(gst::State::Null);
        if let Some(bus) = self.pipeline.bus() {
            bus.unset_sync_handler();
        }
    }
}

fn on_sample(sink: &gst_app::AppSink, tx: &Sender<CapturedFrame>, shared: &Shared) -> Result<gst::FlowSuccess, gst::FlowError> {
    let arrival_ns = monotonic_ns();
    let sample = sink.pull_sample().map_err(|_| gst::FlowError::Flushing)?;
    let (capture_ns, stamp) = match capture_time_ns(&sample, sink.base_time()) {
        Some(t) => (t, Stamp::Buffer),
        None => (arrival_ns, Stamp::Arrival),
    };
    let frame = sample
        .caps()
        .and_then(|caps| gst_video::VideoInfo::from_caps(caps).ok())
        .and_then(|info| sample.buffer_owned().and_then(|b| gst_video::VideoFrame::from_buffer_readable(b, &info).ok()));
    let Some(frame) = frame else {
        shared.unreadable.fetch_add(1, Ordering::Relaxed);
        return Ok(gst::FlowSuccess::Ok);
    };
    let mut captured = CapturedFrame { frame, capture_ns, stamp };
    loop {
        if !shared.block_when_full.load(Ordering::Relaxed) {
            return match tx.try_send(captured) {
                Ok(()) => Ok(gst::FlowSuccess::Ok),
                Err(crossbeam::channel::TrySendError::Full(_)) => {
                    shared.dropped_busy.fetch_add(1, Ordering::Relaxed);
                    Ok(gst::FlowSuccess::Ok)
                }
                Err(crossbeam::channel::TrySendError::Disconnected(_)) => Err(gst::FlowError::Flushing),
            };
        }
        match tx.send_timeout(captured, Duration::from_millis(50)) {
            Ok(()) => return Ok(gst::FlowSuccess::Ok),
            Err(SendTimeoutError::Timeout(back)) if !shared.stopping.load(Ordering::Relaxed) => captured = back,
            Err(_) => return Err(gst::FlowError::Flushing),
        }
    }
}

fn on_message(side: Side, msg: &gst::Message, tx: &Sender<SourceEvent>) {
    let end = match msg.view() {
        gst::MessageView::Error(e) => {
            let element = msg.src().map(|s| s.path_string().to_string()).unwrap_or_default();
            let debug = e.debug().map(|d| d.replace('\n', " ")).unwrap_or_default();
            let detail = [element.as_str(), debug.as_str()].iter().filter(|s| !s.is_empty()).copied().collect::<Vec<_>>().join(": ");
            SourceEnd::Error { message: e.error().to_string(), detail }
        }
        gst::MessageView::Eos(_) => SourceEnd::Eos,
        gst::MessageView::Warning(w) => {
            tracing::warn!("{side} source: {} ({})", w.error(), w.debug().unwrap_or_default());
            return;
        }
        _ => return,
    };
    let _ = tx.try_send(SourceEvent { end, posted_ns: monotonic_ns() });
}

//! The flags of `handeye camera`, and its help.

use clap::{Args, ValueEnum};

use crate::cli::domain::DomainArgs;
use crate::cli::units::parse_seconds;

const EXAMPLES: &str = "\
Each --left/--right is a GStreamer pipeline in gst-launch-1.0 syntax that ends where raw video
comes out; handeye appends `videoconvert ! videoscale ! video/x-raw,format=GRAY8,width=W,height=H
! appsink`. Frames are scaled to exactly W x H (aspect not kept: pick the camera's own mode in
the pipeline to avoid scaling). A frame's capture time is its buffer timestamp mapped onto
CLOCK_MONOTONIC (the pipelines run on a monotonic system clock); the left frame's is the pair's.

Pairing: a left and a right frame form a pair when their capture times differ by at most
--max-skew-ms; a left frame without such a partner is dropped, and so is a right one. Frame ids
count left frames (frames, with --mono): a dropped left frame leaves a gap in the ids, which every
subscriber (and the daemon) reads as a dropped frame.

Delivery: `lossless` waits for the subscribers to take each frame (nothing is lost; the source
is slowed down instead; only possible for files and other non-live sources); `latest` never waits,
like a camera (a lagging subscriber loses its oldest frame). `auto` (default): lossless when no
source is live.

A source that fails or ends is reported by name with GStreamer's text (\"left source: ...\") as
soon as GStreamer posts it, and a live source that stops delivering after --stall-timeout-s; the
command then exits with status 1, or with --reconnect rebuilds that source's pipeline and goes
on. A file that ends with --count 0 is the end of the run (status 0). Progress goes to stderr
once a second; the summary to stdout at the end.

Examples:
  # two USB cameras (see README.md, \"Real cameras\")
  handeye camera --left 'v4l2src device=/dev/video0 ! video/x-raw,width=640,height=480' \\
                 --right 'v4l2src device=/dev/video2 ! video/x-raw,width=640,height=480'
  # a video file as both views, every frame delivered, 100 frames
  handeye camera --left 'filesrc location=cube.mp4 ! decodebin' --mono --count 100
  # test patterns at two rates: pairs within 5 ms, the rest dropped and counted
  handeye camera --left 'videotestsrc is-live=true ! video/x-raw,framerate=30/1' \\
                 --right 'videotestsrc is-live=true pattern=ball ! video/x-raw,framerate=20/1' \\
                 --max-skew-ms 5 --count 60 --json
  # a network camera that may drop out
  handeye camera --left 'rtspsrc location=rtsp://cam/stream ! decodebin' --mono --reconnect

JSON keys: frames (published), first_frame_id, last_frame_id, left_frames, right_frames (that
reached handeye), dropped (ids skipped = dropped_skew + dropped_stale + dropped_busy_left +
dropped_publish), dropped_busy_right, right_unpaired, arrival_stamped (no buffer timestamp:
stamped on arrival), unreadable, reconnects, pending_left, pending_right (waiting for a partner
at the end), next_frame_id (= frames + dropped), fps, skew_ns_p50/p99/max,
latency_ns_p50/p99/max (capture stamp to publish; percentiles over the newest million frames at
least), delivery, left_live, right_live, source_ends [{side, kind (error, eos or stalled), message,
posted_ns, reported_ns, detection_ns}], completed (--count reached), duration_s.";

/// How frames are handed to the subscribers.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeliveryMode {
    /// Lossless when no source is live (files), latest otherwise.
    Auto,
    /// Wait for every subscriber to take each frame; the sources are slowed down instead.
    Lossless,
    /// Never wait, like a camera: a lagging subscriber loses its oldest frame.
    Latest,
}

/// Publish one or two GStreamer sources (USB/V4L2 cameras, network cameras, video files, test
/// patterns) as GRAY8 stereo frames on `handeye/stereo`.
///
/// Left and right frames are paired by capture time (CLOCK_MONOTONIC); pairs further apart
/// than --max-skew-ms are dropped and counted. A failing or ending source is reported by name
/// at once; --reconnect retries it.
#[derive(Args, Debug)]
#[command(after_help = EXAMPLES)]
pub struct CameraArgs {
    /// The left camera's pipeline up to raw video, e.g. 'v4l2src device=/dev/video0'.
    #[arg(long, value_name = "PIPELINE")]
    pub left: String,

    /// The right camera's pipeline (not with --mono).
    #[arg(long, value_name = "PIPELINE", required_unless_present = "mono", conflicts_with = "mono")]
    pub right: Option<String>,

    /// One source only: its frames are sent as both the left and the right view.
    #[arg(long)]
    pub mono: bool,

    /// Width of the published images; every frame is scaled to it.
    #[arg(long, default_value_t = 640, value_name = "PX")]
    pub width_px: u32,

    /// Height of the published images; every frame is scaled to it.
    #[arg(long, default_value_t = 480, value_name = "PX")]
    pub height_px: u32,

    /// Stop after N published frames (0 = until Ctrl-C, or until a file source ends).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub count: u64,

    /// Largest capture time difference of a published pair, milliseconds. The default, half a
    /// frame at 30 frames/s, always pairs two free-running 30 frames/s cameras; lower it for
    /// cameras triggered together.
    #[arg(long, default_value_t = 17.0, value_name = "MS")]
    pub max_skew_ms: f64,

    /// Lossless, latest, or auto (lossless when no source is live).
    #[arg(long, value_enum, default_value_t = DeliveryMode::Auto)]
    pub delivery: DeliveryMode,

    /// When a source fails or ends, rebuild its pipeline (every --reconnect-delay-s) and go on
    /// instead of exiting. Frame ids keep counting up.
    #[arg(long)]
    pub reconnect: bool,

    /// A live source that delivers no frame for this many seconds (after its first frame;
    /// 5 s for the first) has stalled: reported and handled like a failed source. Catches a
    /// camera or network source that hangs without an error. Raise it for sources slower
    /// than about 4 frames/s. 0 = never.
    #[arg(long, default_value_t = 0.5, value_name = "S", value_parser = parse_seconds)]
    pub stall_timeout_s: f64,

    /// Seconds between attempts to rebuild a failed source (with --reconnect).
    #[arg(long, default_value_t = 1.0, value_name = "S", value_parser = parse_seconds)]
    pub reconnect_delay_s: f64,

    /// Seconds to wait for a subscriber before the first frame (and, with lossless delivery,
    /// whenever none is left) before giving up with an error. 0 = start at once.
    #[arg(long, default_value_t = 30.0, value_name = "S", value_parser = parse_seconds)]
    pub wait_subscriber_s: f64,

    /// Print the summary as one JSON object (keys below).
    #[arg(long)]
    pub json: bool,

    /// Seconds between progress lines on stderr (0 = none).
    #[arg(long, default_value_t = 1.0, value_name = "S", value_parser = parse_seconds)]
    pub progress_s: f64,

    #[command(flatten)]
    pub domain: DomainArgs,
}

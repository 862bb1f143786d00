//! `handeye record`: writes what arrives on `handeye/stereo` (and, when present,
//! `handeye/robot/state` and `handeye/telemetry`) into a folder that `handeye feed --dir`
//! replays (the format: `super::recording`).
//!
//! The subscriber loop only copies each frame out of shared memory (releasing the slot at
//! once) into one of a bounded set of buffers and hands it to the writer thread (`writer`),
//! which encodes the PNGs; messages are written by threads of their own (`messages`). When
//! every buffer waits for the writer, the loop holds the frame up to [`WRITER_WAIT`] for one
//! to come free: a lossless publisher (`feed --rate-hz 0`) then simply waits for the writer,
//! and a camera's frames overflow the subscriber queue meanwhile (counted as missed). So the
//! recorder loses nothing it could keep, and what it could not keep is counted, by reason.

mod messages;
mod writer;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_wire::stereo::{StereoEvent, StereoFrame, StereoSubscriber};
use handeye_wire::{RobotState, Telemetry, WireNode};
use serde_json::{json, Map, Value};

use self::messages::MessageRecorder;
use self::writer::{FrameJob, FrameWriter};
use super::domain::DomainArgs;
use super::recording::{FrameRecord, RecordingSummary, ROBOT_STATE_FILE, SUMMARY_FILE, TELEMETRY_FILE};
use super::units::parse_seconds;

const EXAMPLES: &str = "\
DIR gets left/<id>.png and right/<id>.png per frame (GRAY8, the frame id zero-padded to 8
digits), frames.jsonl (one line per kept frame: id, capture_time_ns, publish_time_ns,
receive_time_ns, left, right, missed_before = ids that never arrived since the previous line,
not_kept_before = frames that arrived but could not be kept), robot_state.jsonl and
telemetry.jsonl (one line per message, when any arrive), and at the end recording.json:
frames, received, missed, not_kept by reason (writer_behind: --buffer-frames frames waited for
the writer for 2 s more; size_changed; write_failed), rejected, robot_states, telemetry,
first/last frame id, width, height, cameras, checksum (as `handeye monitor --checksum` over
the kept frames), ended_by, error, duration_s.

The recording ends after --count frames, after --timeout-s without a frame, when the camera
publisher goes away (or a new one starts), or on Ctrl-C; everything received is written first.
One recording holds one publisher's stream.

Examples:
  # record a simulator run (lockstep without a daemon steps on by itself)
  handeye record --out rec/sim1 &
  handeye sim scenarios/pick_cube.toml --lockstep --frames 300
  # record 600 frames of the cameras and what the daemon does meanwhile
  handeye record --out rec/cube --count 600
  # replay it: at its recorded timing, or losslessly as fast as the subscriber takes it
  handeye feed --dir rec/cube
  handeye feed --dir rec/cube --rate-hz 0";

/// Record the stereo stream (and robot state and telemetry) into a folder `handeye feed`
/// replays.
///
/// Writes PNG pairs, frames.jsonl, robot_state.jsonl, telemetry.jsonl and a recording.json
/// summary. Frames are copied out of shared memory at once and encoded on a writer thread;
/// what could not be kept is counted, never waited for.
#[derive(Args, Debug)]
#[command(after_help = EXAMPLES)]
pub struct RecordArgs {
    /// Folder to write (created; must not hold a recording already).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Stop after N frames received, kept or not (0 = no limit).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub count: u64,

    /// Stop after this many seconds without a frame, the first one included (0 = never).
    #[arg(long, default_value_t = 10.0, value_name = "S", value_parser = parse_seconds)]
    pub timeout_s: f64,

    /// Frames that may wait for the PNG writer (each holds one copy of the pixels: 64 x a
    /// 640x480 pair = 39 MB). When all wait, the next frame is held (up to 2 s) until one
    /// is written: a lossless feed waits, a camera's frames overflow (counted as missed).
    #[arg(long, default_value_t = 64, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub buffer_frames: u32,

    /// Print recording.json to stdout at the end instead of the text summary.
    #[arg(long)]
    pub json: bool,

    /// Seconds between progress lines on stderr (0 = none).
    #[arg(long, default_value_t = 1.0, value_name = "S", value_parser = parse_seconds)]
    pub progress_s: f64,

    #[command(flatten)]
    pub domain: DomainArgs,
}

/// How long a frame is held waiting for the writer to free a buffer before it is counted
/// as not kept (`writer_behind`): bounded, so a stuck writer never stalls the stream for good.
const WRITER_WAIT: Duration = Duration::from_secs(2);

/// Reasons a received frame was not kept, as keys of `not_kept_by_reason`.
const NOT_KEPT_REASONS: [&str; 3] = ["writer_behind", "size_changed", "write_failed"];

/// The subscriber side's account of the frames.
#[derive(Default)]
struct FrameTally {
    received: u64,
    /// Indexed like [`NOT_KEPT_REASONS`].
    not_kept: [u64; 3],
    first_id: Option<u64>,
    last_id: Option<u64>,
    /// Lost since the last kept frame: ids that never arrived, frames not kept.
    missed_since_kept: u64,
    not_kept_since_kept: u64,
    /// Width, height, cameras of the first frame; later frames must match.
    geometry: Option<(u32, u32, u32)>,
}

fn prepare_folder(dir: &Path) -> Result<()> {
    for file in [super::recording::FRAMES_FILE, SUMMARY_FILE] {
        if dir.join(file).exists() {
            bail!("{} already holds a recording ({file}): choose another --out", dir.display());
        }
    }
    for sub in ["left", "right"] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).with_context(|| format!("cannot create {}", d.display()))?;
    }
    Ok(())
}

/// Copies `frame` into a buffer from the writer and queues it; `Err(reason index)` when it
/// cannot be kept.
fn keep(frame: &StereoFrame, tally: &mut FrameTally, writer: &mut FrameWriter) -> Result<(), usize> {
    let l = *frame.layout();
    let h = frame.header();
    let geometry = (h.width, h.height, h.camera_count);
    if *tally.geometry.get_or_insert(geometry) != geometry || l.camera_count > 2 || l.row_len != l.width {
        return Err(1); // another size, more than two cameras, or not GRAY8
    }
    let Some(mut pixels) = writer.buffer(WRITER_WAIT) else { return Err(0) };
    pixels.clear();
    for camera in 0..l.camera_count {
        for y in 0..l.height {
            pixels.extend_from_slice(frame.row(camera, y).unwrap_or_default());
        }
    }
    let (left, right) = FrameRecord::file_names(h.frame_id, l.camera_count);
    let record = FrameRecord {
        id: h.frame_id,
        capture_time_ns: h.capture_time_ns,
        publish_time_ns: h.publish_time_ns,
        receive_time_ns: frame.receive_time_ns(),
        left,
        right,
        missed_before: tally.missed_since_kept,
        not_kept_before: tally.not_kept_since_kept,
    };
    writer.submit(FrameJob { record, width: h.width, height: h.height, pixels });
    Ok(())
}

pub fn run(args: RecordArgs) -> Result<()> {
    let dir = &args.out;
    prepare_folder(dir)?;
    let domain = &args.domain.domain;
    let node = WireNode::create(domain, "handeye-record")?;
    let mut sub = StereoSubscriber::create(&node, 2)?;
    let stop = Arc::new(AtomicBool::new(false));
    let states = MessageRecorder::start::<RobotState>(domain, dir.join(ROBOT_STATE_FILE), stop.clone())?;
    let telemetry = MessageRecorder::start::<Telemetry>(domain, dir.join(TELEMETRY_FILE), stop.clone())?;
    let mut writer = FrameWriter::start(dir, args.buffer_frames as usize)?;
    eprintln!("record: listening on handeye/stereo, handeye/robot/state, handeye/telemetry in domain '{domain}', writing {}", dir.display());

    let start = Instant::now();
    let idle_limit = (args.timeout_s > 0.0).then(|| Duration::from_secs_f64(args.timeout_s));
    let progress_every = (args.progress_s > 0.0).then(|| Duration::from_secs_f64(args.progress_s));
    let mut next_progress = progress_every.map(|p| start + p);
    let mut last_activity = start;
    let mut tally = FrameTally::default();
    let ended_by = loop {
        if args.count > 0 && tally.received >= args.count {
            break "count";
        }
        if writer.failed() {
            break "write_failed";
        }
        let mut slice = Duration::from_millis(250);
        if let Some(limit) = idle_limit {
            let left = limit.saturating_sub(last_activity.elapsed());
            if left.is_zero() {
                break "timeout";
            }
            slice = slice.min(left);
        }
        match sub.wait(slice)? {
            StereoEvent::Frame(frame) => {
                last_activity = Instant::now();
                let id = frame.frame_id();
                if tally.last_id.is_some_and(|last| id <= last) {
                    break "new_publisher"; // its ids start again: another recording
                }
                tally.received += 1;
                tally.first_id.get_or_insert(id);
                tally.missed_since_kept += tally.last_id.map_or(0, |last| id - last - 1);
                tally.last_id = Some(id);
                match keep(&frame, &mut tally, &mut writer) {
                    Ok(()) => (tally.missed_since_kept, tally.not_kept_since_kept) = (0, 0),
                    Err(reason) => {
                        tally.not_kept[reason] += 1;
                        tally.not_kept_since_kept += 1;
                    }
                }
            }
            StereoEvent::PublisherUp => {
                last_activity = Instant::now();
                eprintln!("record: camera publisher up");
            }
            StereoEvent::PublisherGone => break "publisher_gone",
            StereoEvent::Timeout => {}
            StereoEvent::Interrupted => break "interrupted",
        }
        if let (Some(at), Some(every)) = (next_progress, progress_every)
            && Instant::now() >= at
        {
            next_progress = Some(at + every);
            let not_kept: u64 = tally.not_kept.iter().sum();
            if tally.received == 0 {
                eprintln!("record: waiting for frames ({:.0} s)", start.elapsed().as_secs_f64());
                continue;
            }
            eprintln!(
                "record: {} frames ({} kept so far, {} missed, {} not kept), {:.1} frames/s, writer queue {}/{}, {} robot states, {} telemetry",
                tally.received,
                tally.received - not_kept - writer.queued() as u64,
                sub.stats().missed,
                not_kept,
                tally.received as f64 / start.elapsed().as_secs_f64(),
                writer.queued(),
                args.buffer_frames,
                states.received.load(Ordering::Relaxed),
                telemetry.received.load(Ordering::Relaxed),
            );
        }
    };
    if writer.queued() > 0 {
        eprintln!("record: {ended_by}; writing the {} frames still queued", writer.queued());
    }
    let written = writer.finish();
    stop.store(true, Ordering::Relaxed);
    let (states, telemetry) = (states.finish(), telemetry.finish());
    let mut not_kept = tally.not_kept;
    not_kept[2] += written.failed;
    let error = [&written.error, &states.error, &telemetry.error].into_iter().flatten().next().cloned();
    let summary = RecordingSummary {
        frames: written.written,
        received: tally.received,
        missed: sub.stats().missed,
        not_kept: not_kept.iter().sum(),
        not_kept_by_reason: NOT_KEPT_REASONS.iter().zip(not_kept).map(|(k, n)| (k.to_string(), json!(n))).collect::<Map<String, Value>>(),
        rejected: sub.stats().rejected_total(),
        robot_states: states.written,
        telemetry: telemetry.written,
        messages_not_kept: states.not_kept + telemetry.not_kept,
        first_frame_id: tally.first_id,
        last_frame_id: tally.last_id,
        width: tally.geometry.map(|g| g.0),
        height: tally.geometry.map(|g| g.1),
        cameras: tally.geometry.map(|g| g.2),
        checksum: format!("{:016x}", written.checksum.value()),
        ended_by: ended_by.to_owned(),
        error: error.clone(),
        duration_s: start.elapsed().as_secs_f64(),
    };
    let path = dir.join(SUMMARY_FILE);
    let text = serde_json::to_string_pretty(&summary)?;
    std::fs::write(&path, format!("{text}\n")).with_context(|| format!("cannot write {}", path.display()))?;
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!("frames:    {} kept of {} received ({} missed, {} not kept)", summary.frames, summary.received, summary.missed, summary.not_kept);
        println!("messages:  {} robot states, {} telemetry", summary.robot_states, summary.telemetry);
        println!("checksum:  {}", summary.checksum);
        println!("ended by:  {ended_by}");
        println!("written:   {}", dir.display());
    }
    if let Some(e) = error {
        bail!("the recording is incomplete: {e}");
    }
    if tally.received == 0 {
        bail!("no frame arrived ({ended_by}): is a camera publishing in domain '{domain}'?");
    }
    Ok(())
}

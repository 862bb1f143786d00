//! `handeye feed`: publishes stereo frames from PNG files on `handeye/stereo`, like a camera,
//! or replays a recording of `handeye record` with its frame ids and timing.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use handeye_wire::stereo::{Delivery, PublishError, StereoFormat, StereoPublisher, StereoPublisherOptions};
use handeye_wire::{monotonic_ns, WireNode};

use super::domain::DomainArgs;
use super::recording::{self, RecordedStamp, ReplayClock};
use super::units::parse_seconds;

const EXAMPLES: &str = "\
Images are read in file-name order and sent as 8-bit gray (GRAY8): gray PNGs unchanged, colour
PNGs converted with the image crate's to_luma8 (Y = 0.2126 R + 0.7152 G + 0.0722 B on the stored
sRGB values, alpha dropped, 16-bit scaled to 8-bit). All images must have one size. Frame ids
count up from 0; capture and publish times are CLOCK_MONOTONIC ns at sending. The feed waits for
a subscriber before it starts, prints progress to stderr, lets the subscriber take the last
frame before it exits, and ends cleanly on Ctrl-C.

A recording of `handeye record` (DIR holds frames.jsonl) is replayed with its own frame ids,
gaps included, and its capture-time spacing: frame i is stamped (replay start + its capture
time - the first frame's), so recording the replay again gives the same ids and the same
capture-time differences. Its default rate is `recorded` (each frame sent at its recorded
offset); --rate-hz 0 sends them as fast as the subscriber takes them, none lost; --rate-hz HZ
paces them at HZ, stamps unchanged.

Examples:
  # the cube sequence as both views, 30 frames/s, forever (stop with Ctrl-C)
  handeye feed --mono --dir ../shared/data/visp-cube --loop
  # 200 frames, as fast as the subscriber takes them, none lost
  handeye feed --mono --dir ../shared/data/visp-cube --count 200 --rate-hz 0
  # a stereo pair sequence: DIR/left/*.png and DIR/right/*.png with matching names
  handeye feed --dir pairs/run3 --rate-hz 15
  # a camera that loses every third frame (ids 0 1 _ 3 4 _ 6 ...), at 30 frames/s
  handeye feed --mono --dir ../shared/data/visp-cube --drop-every 3
  # replay a recording at its recorded timing, then losslessly as fast as possible
  handeye feed --dir recordings/run3
  handeye feed --dir recordings/run3 --rate-hz 0";

/// Publish stereo frames from PNG files on `handeye/stereo`, like a camera would.
///
/// Images are read in file-name order and sent as 8-bit gray (GRAY8): gray PNGs unchanged,
/// colour PNGs converted with the `image` crate's `to_luma8` (Y = 0.2126 R + 0.7152 G +
/// 0.0722 B on the stored sRGB values, alpha dropped, 16-bit scaled to 8-bit). All images
/// must have the same size. Frame ids count up from 0; capture and publish times are
/// CLOCK_MONOTONIC at sending (a recording keeps its ids and capture-time spacing). The
/// command waits for a subscriber before it starts, prints progress to stderr, and ends
/// cleanly on Ctrl-C.
#[derive(Args, Debug)]
#[command(after_help = EXAMPLES)]
pub struct FeedArgs {
    /// Folder of PNGs: with `left/` and `right/` sub-folders (a left image and its right image
    /// share a file name), or, with --mono, a flat folder. A folder with `frames.jsonl` is a
    /// recording (`handeye record`): its lines give the frames, ids and capture times.
    #[arg(long, value_name = "DIR")]
    pub dir: PathBuf,

    /// Send each image of the flat folder DIR as both the left and the right view.
    #[arg(long)]
    pub mono: bool,

    /// Frames per second. 0 = as fast as the slowest subscriber takes them, never dropping
    /// one (each frame waits until the previous one was released by every subscriber).
    /// Above 0 the feed behaves like a camera: it never waits, and a subscriber that lags
    /// loses its oldest queued frame. `recorded` (a recording only) = at the recorded
    /// capture-time spacing, like the camera it came from. Default: `recorded` for a
    /// recording, 30 for a PNG folder.
    #[arg(long, value_name = "HZ|recorded", value_parser = parse_rate)]
    pub rate_hz: Option<Rate>,

    /// Stop after N frames (0 = after the last file, or never with --loop).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub count: u64,

    /// After the last file start again at the first (frame ids keep counting up).
    #[arg(long = "loop")]
    pub looping: bool,

    /// Drop every Nth frame, like a camera that loses frames: it is not sent, but its frame
    /// id and its time slot pass (the next frame's id skips it, and its capture stamp is
    /// when it is sent). 0 = drop none. --count counts frames sent.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub drop_every: u64,

    /// Seconds to wait for a subscriber before the first frame (and, at --rate-hz 0, whenever
    /// none is left, or one stops taking frames) before giving up with an error. 0 = start at
    /// once without waiting.
    #[arg(long, default_value_t = 30.0, value_name = "S", value_parser = parse_seconds)]
    pub wait_subscriber_s: f64,

    #[command(flatten)]
    pub domain: DomainArgs,
}

/// How fast frames are sent (`--rate-hz`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// Frames per second; 0 = lossless, as fast as the subscribers take them.
    Hz(f64),
    /// A recording's own capture-time spacing.
    Recorded,
}

fn parse_rate(text: &str) -> Result<Rate, String> {
    if text.trim() == "recorded" {
        return Ok(Rate::Recorded);
    }
    match text.trim().parse::<f64>() {
        Ok(hz) if hz.is_finite() && hz >= 0.0 => Ok(Rate::Hz(hz)),
        _ => Err(format!("'{text}' is neither a rate in Hz (a number >= 0) nor `recorded`")),
    }
}

/// The image files to send, in order, and their common size.
#[derive(Debug)]
pub struct Sequence {
    /// (left, right) per frame; `None` right means "send the left image as both views".
    pub frames: Vec<(PathBuf, Option<PathBuf>)>,
    pub width: u32,
    pub height: u32,
    /// A recording's frame ids and capture times, one per frame (`None`: a PNG folder).
    pub recorded: Option<Vec<RecordedStamp>>,
}

/// PNG files directly in `dir`, sorted by file name.
fn list_pngs(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).with_context(|| format!("cannot read folder {}", dir.display()))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.with_context(|| format!("cannot list folder {}", dir.display()))?.path();
        let is_png = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
        if is_png && path.is_file() {
            files.push(path);
        }
    }
    files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(files)
}

/// Finds the frames of `dir` (see [`FeedArgs::dir`]) and checks that every image exists and
/// has the size of the first, reading only the PNG headers. Errors name the file.
pub fn load_sequence(dir: &Path, mono: bool) -> Result<Sequence> {
    let mut recorded = None;
    let frames: Vec<(PathBuf, Option<PathBuf>)> = if !mono && dir.join(recording::FRAMES_FILE).is_file() {
        let lines = recording::read_frames(dir)?;
        recorded = Some(lines.iter().map(|f| f.stamp).collect());
        lines.into_iter().map(|f| (f.left, f.right)).collect()
    } else if mono {
        list_pngs(dir)?.into_iter().map(|p| (p, None)).collect()
    } else {
        let (left_dir, right_dir) = (dir.join("left"), dir.join("right"));
        if !left_dir.is_dir() || !right_dir.is_dir() {
            bail!(
                "{} has no left/ and right/ sub-folders; for a flat folder of single images use --mono",
                dir.display()
            );
        }
        let lefts = list_pngs(&left_dir)?;
        let rights = list_pngs(&right_dir)?;
        for r in &rights {
            let l = left_dir.join(r.file_name().unwrap_or_default());
            if !l.is_file() {
                bail!("right image {} has no left image {}", r.display(), l.display());
            }
        }
        lefts
            .into_iter()
            .map(|l| {
                let r = right_dir.join(l.file_name().unwrap_or_default());
                if r.is_file() { Ok((l, Some(r))) } else { Err(anyhow!("left image {} has no right image {}", l.display(), r.display())) }
            })
            .collect::<Result<_>>()?
    };
    let Some((first, _)) = frames.first() else {
        bail!("no PNG files in {}", if mono { dir.to_path_buf() } else { dir.join("left") }.display());
    };
    let (width, height) = png_size(first)?;
    for (l, r) in &frames {
        for p in std::iter::once(l).chain(r.iter()) {
            let size = png_size(p)?;
            if size != (width, height) {
                bail!(
                    "{} is {}x{} but {} is {width}x{height}: all images must have one size",
                    p.display(),
                    size.0,
                    size.1,
                    first.display()
                );
            }
        }
    }
    Ok(Sequence { frames, width, height, recorded })
}

fn png_size(path: &Path) -> Result<(u32, u32)> {
    Ok(super::png::read_size(path)?)
}

/// Decodes `path` as 8-bit gray (see [`FeedArgs`] for the conversion), checking its size.
pub fn decode_gray(path: &Path, width: u32, height: u32) -> Result<image::GrayImage> {
    let gray = super::png::read_gray(path)?;
    if gray.dimensions() != (width, height) {
        bail!("{} is {}x{} but the sequence is {width}x{height}", path.display(), gray.width(), gray.height());
    }
    Ok(gray)
}

pub fn run(args: FeedArgs) -> Result<()> {
    if args.drop_every == 1 {
        bail!("--drop-every 1 would drop every frame (use 2 or more, or 0 for none)");
    }
    let seq = load_sequence(&args.dir, args.mono)?;
    let clock = seq.recorded.clone().map(ReplayClock::new);
    let rate = match (args.rate_hz, &clock) {
        (Some(Rate::Recorded), None) => {
            bail!("--rate-hz recorded replays a recording, but {} has no {}", args.dir.display(), recording::FRAMES_FILE)
        }
        (Some(rate), _) => rate,
        (None, Some(_)) => Rate::Recorded,
        (None, None) => Rate::Hz(30.0),
    };
    let domain = &args.domain.domain;
    let node = WireNode::create(domain, "handeye-feed")?;
    let geometry = StereoFormat::gray8_pair(seq.width, seq.height);
    let wait = Duration::from_secs_f64(args.wait_subscriber_s);
    let lossless = rate == Rate::Hz(0.0);
    let delivery = if lossless {
        // One frame in flight fits every subscriber queue, so nothing can overflow.
        let stall = if wait.is_zero() { Duration::from_secs(30) } else { wait };
        Delivery::Lossless { in_flight: 1, timeout: stall }
    } else {
        Delivery::Latest
    };
    let mut publisher = StereoPublisher::create(&node, geometry, StereoPublisherOptions { delivery, ..Default::default() })?;
    eprintln!(
        "feed: {} frames of 2 x {}x{} GRAY8 from {}{} on handeye/stereo, domain '{domain}', {}",
        seq.frames.len(),
        seq.width,
        seq.height,
        args.dir.display(),
        if clock.is_some() { " (a recording: its frame ids and capture-time spacing)" } else { "" },
        match rate {
            Rate::Hz(0.0) => "as fast as the subscriber takes them (--rate-hz 0)".to_owned(),
            Rate::Hz(hz) => format!("{hz} frames/s"),
            Rate::Recorded => "at the recorded timing".to_owned(),
        }
    );
    if !wait.is_zero() && !wait_for_subscriber(&publisher, wait, domain)? {
        return Ok(()); // interrupted
    }

    let period = match rate {
        Rate::Hz(hz) if hz > 0.0 => Some(Duration::from_secs_f64(1.0 / hz)),
        _ => None,
    };
    let start = Instant::now();
    let mut next_send = start;
    let mut next_progress = start + Duration::from_secs(1);
    let mut next_subscriber_check = start;
    let mut sent = 0u64;
    let mut dropped = 0u64;
    // Frames taken from the sequence (sent or dropped): a PNG folder's frame id.
    let mut taken = 0u64;
    let mut index = 0usize;
    let mut pass = 0u64;
    // CLOCK_MONOTONIC ns of the replay's first frame: recorded offsets count from it.
    let mut replay_start_ns: Option<u64> = None;
    let mut interrupted = false;
    loop {
        if args.count > 0 && sent >= args.count {
            break;
        }
        if index == seq.frames.len() {
            if !args.looping {
                if args.count > sent {
                    eprintln!("feed: only {} files, sent them all (add --loop to repeat)", seq.frames.len());
                }
                break;
            }
            index = 0;
            pass += 1;
        }
        let (left_path, right_path) = &seq.frames[index];
        let stamp = clock.as_ref().map(|c| c.stamp(index, pass));
        index += 1;
        taken += 1;
        if args.drop_every > 0 && taken.is_multiple_of(args.drop_every) {
            // Lost like a camera's frame: its slot passes (paced rates), its id is skipped.
            dropped += 1;
            if let Some(period) = period {
                next_send = (next_send + period).max(Instant::now());
            }
            continue;
        }
        let left = decode_gray(left_path, seq.width, seq.height)?;
        let right = match right_path {
            Some(p) => Some(decode_gray(p, seq.width, seq.height)?),
            None => None,
        };
        if let Some(period) = period {
            let now = Instant::now();
            if next_send > now && !node.sleep(next_send - now) {
                interrupted = true;
                break;
            }
            // A camera does not catch up in a burst after a stall.
            next_send = (next_send + period).max(Instant::now());
        } else if let (Rate::Recorded, Some((_, offset_ns)), Some(t0)) = (rate, stamp, replay_start_ns) {
            // Late frames go at once: a replay keeps every frame, and its stamps keep the timing.
            let due_ns = t0.saturating_add(offset_ns);
            let now_ns = monotonic_ns();
            if due_ns > now_ns && !node.sleep(Duration::from_nanos(due_ns - now_ns)) {
                interrupted = true;
                break;
            }
        } else if lossless && !wait.is_zero() && Instant::now() >= next_subscriber_check {
            // Lossless: frames sent while no one listens would be lost, so wait for one.
            next_subscriber_check = Instant::now() + Duration::from_millis(250);
            if publisher.subscriber_count() == 0 {
                eprintln!("feed: no subscriber left after {sent} frames");
                if !wait_for_subscriber(&publisher, wait, domain)? {
                    interrupted = true;
                    break;
                }
            }
        }
        let plane = left.as_raw().len();
        let fill = |payload: &mut [u8]| {
            payload[..plane].copy_from_slice(left.as_raw());
            payload[plane..].copy_from_slice(right.as_ref().unwrap_or(&left).as_raw());
        };
        let result = match stamp {
            Some((id, offset_ns)) => {
                let t0 = *replay_start_ns.get_or_insert_with(monotonic_ns);
                publisher.publish_with_id(id, t0.saturating_add(offset_ns), fill)
            }
            None => publisher.publish_with_id(taken - 1, monotonic_ns(), fill),
        };
        match result {
            Ok(_) => sent += 1,
            Err(PublishError::Interrupted) => {
                interrupted = true;
                break;
            }
            Err(e) => return Err(e).context(format!("publishing frame {sent} ({})", left_path.display())),
        }
        if node.termination_requested() {
            interrupted = true;
            break;
        }
        if Instant::now() >= next_progress {
            next_progress += Duration::from_secs(1);
            let secs = start.elapsed().as_secs_f64();
            eprintln!("feed: {sent} frames, {:.1} frames/s, {} subscriber(s)", sent as f64 / secs, publisher.subscriber_count());
        }
    }
    // At the recorded timing the feed is a camera too: the last frame gets two periods.
    let camera_period = match (rate, &clock) {
        (Rate::Recorded, Some(c)) => Some(Duration::from_nanos(c.mean_period_ns())),
        _ => period,
    };
    finish(&mut publisher, &node, camera_period, interrupted)?;
    let secs = start.elapsed().as_secs_f64().max(1e-9);
    eprintln!(
        "feed: {} after {sent} frames in {secs:.2} s ({:.1} frames/s){}",
        if interrupted { "stopped" } else { "done" },
        sent as f64 / secs,
        if dropped > 0 { format!(", {dropped} dropped (--drop-every {})", args.drop_every) } else { String::new() }
    );
    Ok(())
}

/// Lets the subscribers take the last frames before the publisher goes away (iceoryx2 drops
/// frames still queued when their publisher leaves).
fn finish(publisher: &mut StereoPublisher, node: &WireNode, period: Option<Duration>, interrupted: bool) -> Result<()> {
    if interrupted {
        return Ok(());
    }
    match period {
        None => {
            if !publisher.flush(Duration::from_secs(10))? {
                eprintln!("feed: the subscriber did not take the last frame within 10 s");
            }
        }
        // Like a camera: give a subscriber that keeps up two frame periods for the last frame.
        Some(p) => {
            node.sleep((2 * p).clamp(Duration::from_millis(50), Duration::from_secs(1)));
        }
    }
    Ok(())
}

/// Waits for a subscriber, saying so. `Ok(false)` when interrupted; an error on time-out.
fn wait_for_subscriber(publisher: &StereoPublisher, wait: Duration, domain: &handeye_wire::Domain) -> Result<bool> {
    if publisher.subscriber_count() > 0 {
        return Ok(true);
    }
    eprintln!(
        "feed: waiting up to {:.0} s for a subscriber on handeye/stereo in domain '{domain}' \
         (start `handeye monitor` or the daemon with the same --domain)",
        wait.as_secs_f64()
    );
    match publisher.wait_for_subscribers(1, wait) {
        Ok(true) => Ok(true),
        Ok(false) => bail!("no subscriber on handeye/stereo in domain '{domain}' within {:.0} s (--wait-subscriber-s)", wait.as_secs_f64()),
        Err(PublishError::Interrupted) => Ok(false),
        Err(e) => Err(e.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(path: &Path, w: u32, h: u32, value: u8) {
        image::GrayImage::from_pixel(w, h, image::Luma([value])).save(path).unwrap();
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("handeye-feed-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn mono_files_are_read_in_name_order_and_other_files_ignored() {
        let d = tmp("order");
        for (name, v) in [("b.png", 2), ("a.png", 1), ("c.PNG", 3)] {
            write_png(&d.join(name), 4, 3, v);
        }
        std::fs::write(d.join("notes.txt"), "x").unwrap();
        let s = load_sequence(&d, true).unwrap();
        let names: Vec<_> = s.frames.iter().map(|(l, r)| (l.file_name().unwrap().to_owned(), r.is_none())).collect();
        assert_eq!(names, vec![("a.png".into(), true), ("b.png".into(), true), ("c.PNG".into(), true)]);
        assert_eq!((s.width, s.height), (4, 3));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_size_mismatch_names_the_file() {
        let d = tmp("size");
        write_png(&d.join("0.png"), 4, 3, 0);
        write_png(&d.join("1.png"), 5, 3, 0);
        let e = load_sequence(&d, true).unwrap_err().to_string();
        assert!(e.contains("1.png") && e.contains("5x3") && e.contains("4x3"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn stereo_folders_pair_by_name_and_a_missing_partner_is_named() {
        let d = tmp("pairs");
        std::fs::create_dir_all(d.join("left")).unwrap();
        std::fs::create_dir_all(d.join("right")).unwrap();
        for n in ["0.png", "1.png"] {
            write_png(&d.join("left").join(n), 4, 3, 0);
            write_png(&d.join("right").join(n), 4, 3, 0);
        }
        let s = load_sequence(&d, false).unwrap();
        assert_eq!(s.frames.len(), 2);
        assert!(s.frames.iter().all(|(l, r)| r.as_ref().unwrap().file_name() == l.file_name()));
        write_png(&d.join("left").join("2.png"), 4, 3, 0);
        let e = load_sequence(&d, false).unwrap_err().to_string();
        assert!(e.contains("left image") && e.contains("2.png"), "{e}");
        std::fs::remove_file(d.join("left").join("2.png")).unwrap();
        write_png(&d.join("right").join("3.png"), 4, 3, 0);
        let e = load_sequence(&d, false).unwrap_err().to_string();
        assert!(e.contains("right image") && e.contains("3.png"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
        let e = load_sequence(&tmp("flat"), false).unwrap_err().to_string();
        assert!(e.contains("--mono"), "{e}");
    }

    #[test]
    fn a_recording_is_read_from_frames_jsonl_with_its_ids_and_capture_times() {
        let d = tmp("recording");
        for (dir, v) in [("left", 1), ("right", 2)] {
            std::fs::create_dir_all(d.join(dir)).unwrap();
            for n in ["a.png", "b.png", "c.png"] {
                write_png(&d.join(dir).join(n), 4, 3, v);
            }
        }
        let line = |id: u64, t: u64, n: &str| format!("{{\"id\":{id},\"capture_time_ns\":{t},\"left\":\"left/{n}\",\"right\":\"right/{n}\"}}\n");
        std::fs::write(d.join("frames.jsonl"), line(5, 100, "c.png") + &line(9, 250, "a.png")).unwrap();
        let s = load_sequence(&d, false).unwrap();
        assert_eq!(s.frames, vec![(d.join("left/c.png"), Some(d.join("right/c.png"))), (d.join("left/a.png"), Some(d.join("right/a.png")))]);
        let ids: Vec<(u64, u64)> = s.recorded.unwrap().iter().map(|r| (r.id, r.capture_time_ns)).collect();
        assert_eq!(ids, [(5, 100), (9, 250)]);
        assert_eq!((parse_rate("recorded"), parse_rate("0"), parse_rate("15")), (Ok(Rate::Recorded), Ok(Rate::Hz(0.0)), Ok(Rate::Hz(15.0))));
        assert!(parse_rate("-1").is_err() && parse_rate("fast").unwrap_err().contains("recorded"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn colour_pngs_become_bt709_gray() {
        let d = tmp("colour");
        let p = d.join("rgb.png");
        let img = image::RgbImage::from_fn(3, 1, |x, _| match x {
            0 => image::Rgb([255, 0, 0]),
            1 => image::Rgb([0, 255, 0]),
            _ => image::Rgb([0, 0, 255]),
        });
        img.save(&p).unwrap();
        let g = decode_gray(&p, 3, 1).unwrap();
        // 0.2126 * 255 = 54.2, 0.7152 * 255 = 182.4, 0.0722 * 255 = 18.4 (truncated)
        assert_eq!(g.as_raw(), &vec![54, 182, 18]);
        assert!(decode_gray(&p, 4, 1).unwrap_err().to_string().contains("rgb.png"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_file_that_is_not_a_png_is_named() {
        let d = tmp("junk");
        std::fs::write(d.join("broken.png"), b"not a png at all").unwrap();
        let e = format!("{:#}", load_sequence(&d, true).unwrap_err());
        assert!(e.contains("broken.png"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}

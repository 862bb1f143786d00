//! Starting `handeye camera`: build and preroll the sources, choose the delivery, create the
//! publisher, wait for a subscriber, run the capture loop, report.

use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use gstreamer as gst;
use handeye_wire::stereo::{Delivery, StereoFormat, StereoPublisher, StereoPublisherOptions};
use handeye_wire::WireNode;

use super::args::{CameraArgs, DeliveryMode};
use super::capture::{index, Capture, End, Slot, MAX_WAITING, SIDES};
use super::clock::monotonic_clock;
use super::pairing::Pairer;
use super::pipeline::{full_description, Side};
use super::source::Source;
use super::summary::CameraStats;

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
        playing_since_ns: [0, 0],
        last_frame_ns: [None, None],
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

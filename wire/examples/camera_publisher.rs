//! A minimal stereo camera driver for handeye: publishes a synthetic moving pattern on
//! `handeye/stereo`, exactly as a real driver would publish its images.
//!
//! ```text
//! cargo run -p handeye-wire --example camera_publisher -- --frames 300 --rate-hz 30
//! handeye monitor            # in another terminal: frames, rate, latency
//! ```
//!
//! Flags: `--frames N` (0 = until Ctrl-C, the default), `--rate-hz HZ` (default 30),
//! `--size WxH` (default 640x480), `--lossless` (wait for the subscriber instead of running
//! at a fixed rate). The domain comes from `HANDEYE_DOMAIN` (default `handeye`).
//!
//! The pattern: pixel (x, y) of camera c in frame f is `((x + 4 f + 8 c) mod 256) XOR (y mod
//! 256)` — vertical stripes that move 4 px per frame, the right view shifted by 8 px.

use std::time::{Duration, Instant};

use handeye_wire::stereo::{Delivery, StereoFormat, StereoPublisher, StereoPublisherOptions};
use handeye_wire::{monotonic_ns, Domain, WireNode};

/// The example's pattern (see the module docs).
fn pattern(x: usize, y: usize, camera: usize, frame: u64) -> u8 {
    ((x as u64 + 4 * frame + 8 * camera as u64) as u8) ^ (y as u8)
}

struct Options {
    frames: u64,
    rate_hz: f64,
    width: u32,
    height: u32,
    lossless: bool,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options { frames: 0, rate_hz: 30.0, width: 640, height: 480, lossless: false };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let mut value = || args.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--frames" => o.frames = value()?.parse().map_err(|e| format!("--frames: {e}"))?,
            "--rate-hz" => o.rate_hz = value()?.parse().map_err(|e| format!("--rate-hz: {e}"))?,
            "--size" => {
                let v = value()?;
                let (w, h) = v.split_once('x').ok_or(format!("--size wants WxH, got {v}"))?;
                o.width = w.parse().map_err(|e| format!("--size width: {e}"))?;
                o.height = h.parse().map_err(|e| format!("--size height: {e}"))?;
            }
            "--lossless" => o.lossless = true,
            other => return Err(format!("unknown flag {other} (see the example's source for its flags)")),
        }
    }
    if !(o.rate_hz > 0.0 && o.rate_hz.is_finite()) {
        return Err("--rate-hz must be > 0".into());
    }
    Ok(o)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let o = parse_args()?;
    // 1. Join the domain with one node per process.
    let domain = Domain::from_env()?;
    let node = WireNode::create(&domain, "camera-publisher")?;

    // 2. A publisher for one fixed geometry: two GRAY8 images, tightly packed (stride = width).
    let geometry = StereoFormat::gray8_pair(o.width, o.height);
    let delivery = if o.lossless {
        Delivery::Lossless { in_flight: 1, timeout: Duration::from_secs(30) }
    } else {
        Delivery::Latest // a real camera never waits for its consumers
    };
    let mut publisher = StereoPublisher::create(&node, geometry, StereoPublisherOptions { delivery, ..Default::default() })?;
    if o.lossless && !publisher.wait_for_subscribers(1, Duration::from_secs(30))? {
        return Err("no subscriber within 30 s".into());
    }

    // 3. Per frame: take the exposure time, then write the pixels straight into the loaned
    //    shared-memory slot: camera 0's rows, then camera 1's, `stride` bytes apart.
    let (w, h, stride) = (o.width as usize, o.height as usize, o.width as usize);
    let period = Duration::from_secs_f64(1.0 / o.rate_hz);
    let mut next = Instant::now();
    while o.frames == 0 || publisher.next_frame_id() < o.frames {
        if !o.lossless {
            let now = Instant::now();
            if next > now && !node.sleep(next - now) {
                break; // Ctrl-C
            }
            next += period;
        }
        let frame = publisher.next_frame_id();
        let capture_time_ns = monotonic_ns();
        let sent = publisher.publish(capture_time_ns, |payload| {
            for (c, plane) in payload.chunks_exact_mut(stride * h).enumerate() {
                for (y, row) in plane.chunks_exact_mut(stride).enumerate() {
                    for (x, px) in row[..w].iter_mut().enumerate() {
                        *px = pattern(x, y, c, frame);
                    }
                }
            }
        });
        match sent {
            Ok(_) => {}
            Err(handeye_wire::stereo::PublishError::Interrupted) => break,
            Err(e) => return Err(e.into()),
        }
        if node.termination_requested() {
            break;
        }
    }
    // 4. Let the subscribers take the last frame before the publisher (and its memory) goes.
    publisher.flush(Duration::from_secs(5))?;
    eprintln!("camera_publisher: sent {} frames in domain '{domain}'", publisher.next_frame_id());
    Ok(())
}

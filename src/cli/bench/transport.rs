//! `handeye bench transport`: publish-to-receive latency of stereo samples across processes.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_wire::domain::remove_domain_files;
use handeye_wire::stereo::{Delivery, StereoEvent, StereoFormat, StereoPublisher, StereoPublisherOptions, StereoSubscriber};
use handeye_wire::{monotonic_ns, Domain, WireNode};
use serde_json::json;

/// Measure shared-memory transport latency: a publisher process sends stereo samples (2 x
/// 640x480 GRAY8 by default) and this process receives them, timing each from the publisher's
/// stamp (taken after the pixels are written, just before sending) to the moment the
/// subscriber holds the validated sample, woken by the event service.
///
/// The publisher is this binary started again as a separate process, in a private domain.
/// It paces samples at --rate-hz and waits for the subscriber to release each one, so no sample
/// is lost and none queues behind another. Build with --release for numbers worth recording.
#[derive(Args, Debug)]
#[command(after_help = "Example:\n  cargo build --release && target/release/handeye bench transport --samples 5000 --json")]
pub struct TransportArgs {
    /// Samples to time (after --warmup untimed ones).
    #[arg(long, default_value_t = 3000, value_name = "N")]
    pub samples: u64,

    /// Samples sent first and not timed (first touches of shared memory are slow).
    #[arg(long, default_value_t = 50, value_name = "N")]
    pub warmup: u64,

    /// Samples per second sent by the publisher (0 = back to back).
    #[arg(long, default_value_t = 500.0, value_name = "HZ")]
    pub rate_hz: f64,

    /// Image width, pixels.
    #[arg(long, default_value_t = 640)]
    pub width_px: u32,

    /// Image height, pixels.
    #[arg(long, default_value_t = 480)]
    pub height_px: u32,

    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,

    /// Internal: run as the publisher peer in this domain.
    #[arg(long, hide = true, value_name = "DOMAIN")]
    pub peer_publisher: Option<Domain>,
}

pub fn run(args: TransportArgs) -> Result<()> {
    if !(args.rate_hz >= 0.0 && args.rate_hz.is_finite()) {
        bail!("--rate-hz must be >= 0 (got {})", args.rate_hz);
    }
    if args.samples == 0 {
        bail!("--samples must be at least 1");
    }
    match &args.peer_publisher {
        Some(domain) => publisher(&args, domain),
        None => subscriber(&args),
    }
}

fn publisher(args: &TransportArgs, domain: &Domain) -> Result<()> {
    let node = WireNode::create(domain, "bench-publisher")?;
    let geometry = StereoFormat::gray8_pair(args.width_px, args.height_px);
    let options = StereoPublisherOptions {
        delivery: Delivery::Lossless { in_flight: 1, timeout: Duration::from_secs(30) },
        ..Default::default()
    };
    let mut p = StereoPublisher::create(&node, geometry, options)?;
    if !p.wait_for_subscribers(1, Duration::from_secs(30))? {
        bail!("bench peer: no subscriber within 30 s");
    }
    let period = (args.rate_hz > 0.0).then(|| Duration::from_secs_f64(1.0 / args.rate_hz));
    let mut next = Instant::now();
    for k in 0..args.warmup + args.samples {
        if let Some(period) = period {
            let now = Instant::now();
            if next > now && !node.sleep(next - now) {
                return Ok(());
            }
            next += period;
        }
        // Write every byte, as a camera driver copying its image would.
        p.publish(monotonic_ns(), |b| b.fill(k as u8))?;
    }
    p.flush(Duration::from_secs(30))?;
    Ok(())
}

fn subscriber(args: &TransportArgs) -> Result<()> {
    let domain = Domain::unique("bench-transport");
    let result = measure(args, &domain);
    let _ = remove_domain_files(&domain);
    result
}

fn measure(args: &TransportArgs, domain: &Domain) -> Result<()> {
    let node = WireNode::create(domain, "bench-subscriber")?;
    let mut sub = StereoSubscriber::create(&node, 2)?;
    let exe = std::env::current_exe().context("cannot find the handeye binary to start the publisher")?;
    let mut peer = Command::new(exe)
        .args(["bench", "transport", "--peer-publisher", domain.name()])
        .args(["--samples", &args.samples.to_string(), "--warmup", &args.warmup.to_string()])
        .args(["--rate-hz", &args.rate_hz.to_string(), "--width-px", &args.width_px.to_string(), "--height-px", &args.height_px.to_string()])
        .stdin(Stdio::null())
        .spawn()
        .context("cannot start the publisher process")?;
    let total = args.warmup + args.samples;
    let mut latencies = Vec::with_capacity(args.samples as usize);
    let mut received = 0u64;
    let mut corrupt = 0u64;
    while received < total {
        match sub.wait(Duration::from_secs(10))? {
            StereoEvent::Frame(f) => {
                // The publisher filled the frame with its id: check a byte so we know the
                // memory we time is the memory it wrote.
                if f.payload().last() != Some(&(f.frame_id() as u8)) {
                    corrupt += 1;
                }
                if received >= args.warmup
                    && let Some(l) = f.latency_ns()
                {
                    latencies.push(l);
                }
                received += 1;
            }
            StereoEvent::Timeout => {
                let _ = peer.kill();
                bail!("no sample for 10 s after {received} of {total}");
            }
            StereoEvent::Interrupted => {
                let _ = peer.kill();
                bail!("interrupted");
            }
            StereoEvent::PublisherUp | StereoEvent::PublisherGone => {}
        }
    }
    let status = peer.wait()?;
    if !status.success() {
        bail!("the publisher process failed: {status}");
    }
    let stats = sub.stats().clone();
    if latencies.is_empty() {
        bail!("no sample carried a usable publish stamp");
    }
    if corrupt > 0 || stats.rejected_total() > 0 {
        bail!("{corrupt} samples had wrong content, {} were rejected", stats.rejected_total());
    }
    latencies.sort_unstable();
    let pct = |p: f64| latencies[(((p / 100.0) * latencies.len() as f64).ceil() as usize).clamp(1, latencies.len()) - 1];
    let mean = latencies.iter().sum::<u64>() as f64 / latencies.len() as f64;
    let payload = args.width_px as u64 * args.height_px as u64 * 2;
    if args.json {
        println!(
            "{}",
            json!({
                "samples": latencies.len(),
                "warmup": args.warmup,
                "rate_hz": args.rate_hz,
                "width": args.width_px,
                "height": args.height_px,
                "cameras": 2,
                "payload_bytes": payload,
                "missed": stats.missed,
                "latency_ns_p50": pct(50.0),
                "latency_ns_p90": pct(90.0),
                "latency_ns_p99": pct(99.0),
                "latency_ns_max": latencies.last(),
                "latency_ns_mean": mean,
                "build": if cfg!(debug_assertions) { "debug" } else { "release" },
            })
        );
    } else {
        println!(
            "transport: {} samples of 2 x {}x{} GRAY8 ({} bytes), publisher process -> subscriber process, {}",
            latencies.len(),
            args.width_px,
            args.height_px,
            payload,
            if args.rate_hz > 0.0 { format!("{} samples/s", args.rate_hz) } else { "back to back".to_owned() }
        );
        println!(
            "latency (publish stamp -> received): p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, max {:.1} us, mean {:.1} us",
            pct(50.0) as f64 / 1e3,
            pct(90.0) as f64 / 1e3,
            pct(99.0) as f64 / 1e3,
            *latencies.last().unwrap_or(&0) as f64 / 1e3,
            mean / 1e3
        );
        if cfg!(debug_assertions) {
            println!("(debug build: use --release for numbers worth recording)");
        }
    }
    Ok(())
}

//! Observe mode on a domain's services: subscribes to `handeye/stereo` (queue of one) and
//! publishes `handeye/telemetry` once per frame. It opens no robot service at all: no
//! command publisher (so no command can be sent), no state subscriber.
//!
//! A camera that goes away — its publisher gone, or no frame for `stale_frame_ms` — is
//! reported at once (telemetry reason `camera gone: ...` and a log line), then again every
//! `stale_frame_ms` while it stays away (before the first frame the reason says it waits
//! for one); the daemon keeps running and picks the stream up
//! when a publisher comes back (the subscriber stays attached to the service, and a new
//! publisher's frames reach it). It ends on SIGINT/SIGTERM, or when the camera has been gone
//! for `end_after_gone` (the stream ended). With `--plane`, the first frame's size is checked
//! against the plane file's pixels (a pixel outside the image ends the run with an error
//! naming it) and pointing gestures are read from then on.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use handeye_vision::image::ImageView;
use handeye_wire::message::MessagePublisher;
use handeye_wire::stereo::{StereoEvent, StereoSubscriber};
use handeye_wire::{monotonic_ns, Domain, Telemetry, WireNode};

use super::report::{observe_plot_svg, ObserveReport};
use super::{ObserveLoop, ObserveOptions, SLOTS};
use crate::config::DaemonConfig;
use crate::report::{ReportJob, ReportWriter, Snapshot};
use crate::service::ServiceError;

/// Options of one observe run.
pub struct ObserveServiceOptions {
    pub domain: Domain,
    pub config: DaemonConfig,
    pub observe: ObserveOptions,
    /// Report folder: overlays, `observe_plot.svg`, `observe.json`.
    pub report_dir: Option<PathBuf>,
    /// End when no camera has been there for this long (`None`: run until interrupted).
    pub end_after_gone: Option<Duration>,
}

/// What an observe run produced.
pub struct ObserveResult {
    pub report: ObserveReport,
    pub report_files: Vec<PathBuf>,
    pub report_errors: Vec<String>,
}

/// Runs observe mode until interrupted or the stream ended.
pub fn run(options: ObserveServiceOptions) -> Result<ObserveResult, ServiceError> {
    let start = Instant::now();
    let node = WireNode::create(&options.domain, "handeye-daemon-observe")?;
    let mut frames = StereoSubscriber::create(&node, 1)?;
    let mut telemetry = MessagePublisher::<Telemetry>::create(&node)?;
    let stale = Duration::from_millis(options.config.timing.stale_frame_ms);
    let mut report = options.report_dir.as_deref().map(ReportWriter::new).transpose()?;
    let mono = options.observe.mono;
    let mut ol = ObserveLoop::new(options.config, options.observe).map_err(|e| ServiceError::Setup(e.to_string()))?;
    let mut got_frame = false;
    // Since when no camera has been there (`None`: frames are flowing).
    let mut gone_since: Option<Instant> = None;
    let mut last_snapshot: Option<(ImageBuf2, Telemetry)> = None;
    // Why the camera counts as gone (the first sign: its publisher left, or frames stopped).
    let mut gone_reason = String::new();
    let end = loop {
        let event = frames.wait(stale).map_err(ServiceError::WaitFrames)?;
        match event {
            StereoEvent::Frame(frame) => {
                if got_frame && gone_since.is_some() {
                    tracing::warn!(frame_id = frame.frame_id(), "camera back: tracking resumes");
                }
                got_frame = true;
                gone_since = None;
                let receive_ns = frame.receive_time_ns();
                let layout = *frame.layout();
                let Some(l) = frame.camera(0) else { continue };
                let r = match frame.camera(1) {
                    Some(r) => r,
                    None if mono => l,
                    None => return Err(ServiceError::Setup("the camera stream has one view: observe it with --mono".into())),
                };
                let (Ok(left), Ok(right)) =
                    (ImageView::new(l, layout.width, layout.height, layout.stride), ImageView::new(r, layout.width, layout.height, layout.stride))
                else {
                    return Err(ServiceError::Setup("camera frames are not GRAY8 views".into()));
                };
                // Until it has started (with --plane): the first frame's size checked against
                // the plane's pixels, the gesture tracker started once the view stands still.
                ol.start_pointing(&left, &right, frame.header().capture_time_ns).map_err(|e| ServiceError::Setup(e.to_string()))?;
                let moment = ol.cycle(frame.frame_id(), frame.header().capture_time_ns, &left, &right);
                let t = *ol.finish_cycle(monotonic_ns().saturating_sub(receive_ns));
                telemetry.send(&t)?;
                if let Some(rep) = report.as_mut() {
                    if let Some(label) = moment {
                        let mut snapshot = Snapshot::take(label, &left, &right, &t);
                        snapshot.point_px = ol.pointed_px();
                        rep.submit(ReportJob::Overlay(Box::new(snapshot)));
                    }
                    // The end's picture: the last frame, kept cheaply (copied every 15 frames).
                    if t.frame_id % 15 == 0 || last_snapshot.is_none() {
                        last_snapshot = Some(((left.to_owned(), right.to_owned()), t));
                    }
                }
            }
            StereoEvent::Timeout | StereoEvent::PublisherGone => {
                if !got_frame {
                    // Before the first frame: say what it waits for, every stale period.
                    telemetry.send(&ol.no_frame("waiting for the camera's first frame", false, false))?;
                    continue;
                }
                let first = gone_since.is_none();
                let since = *gone_since.get_or_insert_with(Instant::now);
                if first {
                    gone_reason = if matches!(event, StereoEvent::PublisherGone) {
                        "camera gone: its publisher went away".to_string()
                    } else {
                        format!("camera gone: no frame for {} ms", stale.as_millis())
                    };
                    tracing::warn!(reason = %gone_reason, "still running, waiting for the camera to come back");
                }
                telemetry.send(&ol.no_frame(&gone_reason, first, matches!(event, StereoEvent::PublisherGone)))?;
                if let Some(limit) = options.end_after_gone
                    && since.elapsed() >= limit
                {
                    break "stream ended";
                }
            }
            StereoEvent::PublisherUp => tracing::info!("a camera publisher appeared"),
            StereoEvent::Interrupted => break "interrupted",
        }
    };
    let report_data = ol.report(start.elapsed().as_secs_f64(), end);
    let (report_files, report_errors) = match report {
        Some(mut rep) => {
            if let Some(((l, r), t)) = last_snapshot.take() {
                rep.submit(ReportJob::Overlay(Box::new(Snapshot::take("end", &l.view(), &r.view(), &t))));
            }
            let dir = rep.dir().to_path_buf();
            let (mut files, mut errors) = rep.finish();
            let names = SLOTS.map(|s| s.2);
            let mut write = |name: &str, text: Result<String, String>| {
                let path = dir.join(name);
                match text.and_then(|t| std::fs::write(&path, t).map_err(|e| e.to_string())) {
                    Ok(()) => files.push(path),
                    Err(e) => errors.push(format!("{}: {e}", path.display())),
                }
            };
            write("observe_plot.svg", observe_plot_svg(ol.series(), names));
            write("observe.json", serde_json::to_string_pretty(&report_data).map_err(|e| e.to_string()));
            (files, errors)
        }
        None => (Vec::new(), Vec::new()),
    };
    Ok(ObserveResult { report: report_data, report_files, report_errors })
}

/// A frame's two views, copied out.
type ImageBuf2 = (handeye_vision::image::ImageBuf, handeye_vision::image::ImageBuf);

//! The daemon on the shared-memory services of a domain: subscribes to `handeye/stereo`
//! (queue of one: always the newest frame) and `handeye/robot/state`, publishes
//! `handeye/robot/command` and `handeye/telemetry`. Whoever publishes frames and state — the
//! simulator, or cameras and a robot driver — the daemon cannot tell.
//!
//! Per frame: wait for it on the stereo service's event (no busy polling), drain the robot
//! states, run [`HardLoop::cycle`] over the sample's pixels in place, publish the telemetry
//! and then the command stamped with the frame's id (telemetry first, so whoever waits for
//! the command already has what the daemon said about that frame). Stops the arm (explicit
//! `Stop`) and reports when no frame comes for `stale_frame_ms`, when the camera or robot
//! publisher goes away, or on SIGINT/SIGTERM.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use handeye_vision::image::ImageView;
use handeye_wire::hint::OperatorHint;
use handeye_wire::message::{MessageEvent, MessagePublisher, MessageSendError, MessageSubscriber, MessageWaitError};
use handeye_wire::report::FailureKind;
use handeye_wire::stereo::{StereoEvent, StereoSubscriber, StereoWaitError};
use handeye_wire::{monotonic_ns, Domain, RobotCommand, RobotState, Telemetry, WireNode};

use crate::config::DaemonConfig;
use crate::fault::Fault;
use crate::hard_loop::HardLoop;
use crate::outcome::DaemonOutcome;
use crate::report::{ReportJob, ReportWriter, Snapshot};

#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error(transparent)]
    Node(#[from] handeye_wire::NodeError),
    #[error(transparent)]
    Stereo(#[from] handeye_wire::stereo::StereoSubscriberError),
    #[error(transparent)]
    Message(#[from] handeye_wire::message::MessagePortError),
    #[error("waiting for frames: {0}")]
    WaitFrames(#[source] StereoWaitError),
    #[error("waiting for frames: {0}")]
    WaitStates(#[source] MessageWaitError),
    #[error("publishing: {0}")]
    Send(#[from] MessageSendError),
    #[error("starting a thread: {0}")]
    Thread(#[from] std::io::Error),
    #[error("no stereo frame arrived within {0:.0} s of start-up")]
    NoFrames(f64),
    #[error("{0}")]
    Setup(String),
}

/// Options of one daemon run.
pub struct ServiceOptions {
    pub domain: Domain,
    pub config: DaemonConfig,
    pub hint: Option<OperatorHint>,
    /// The operator's indicated point (robot frame, m): the plan executes the grasp nearest it.
    pub indicated_point_m: Option<[f64; 3]>,
    /// Report folder (overlays, servo plot); `None` = no report images.
    pub report_dir: Option<PathBuf>,
}

/// What a run produced.
pub struct ServiceResult {
    pub outcome: DaemonOutcome,
    pub report_files: Vec<PathBuf>,
    pub report_errors: Vec<String>,
}

/// Runs the daemon until its task ends, the arm had to be stopped, or it is interrupted.
pub fn run(options: ServiceOptions) -> Result<ServiceResult, ServiceError> {
    let start = Instant::now();
    let node = WireNode::create(&options.domain, "handeye-daemon")?;
    let mut frames = StereoSubscriber::create(&node, 1)?;
    let mut states = MessageSubscriber::<RobotState>::create(&node)?;
    let mut commands = MessagePublisher::<RobotCommand>::create(&node)?;
    let mut telemetry = MessagePublisher::<Telemetry>::create(&node)?;
    let stale = Duration::from_millis(options.config.timing.stale_frame_ms);
    let start_timeout = Duration::from_secs_f64(options.config.timing.start_timeout_s);
    let mut report = options.report_dir.as_deref().map(ReportWriter::new).transpose()?;
    let mut hl = HardLoop::new(options.config, options.hint)?;
    hl.set_indicated_point(options.indicated_point_m);
    let mut got_frame = false;
    // The newest frame id taken from the camera stream (a new publisher numbers from its own
    // start, so it is forgotten when one comes up), and the commands stamped with an older
    // one: a phase that answered with the frame a worker job saw would count here.
    let mut newest_frame_id: Option<u64> = None;
    let mut stale_frame_commands = 0u64;
    let send = |commands: &mut MessagePublisher<RobotCommand>, telemetry: &mut MessagePublisher<Telemetry>, cmd: &RobotCommand, t: &Telemetry| {
        telemetry.send(t)?;
        commands.send(cmd)?;
        Ok::<(), ServiceError>(())
    };
    let mut stop_reason: Option<Fault> = None;
    let camera = |detail: &str| Some(Fault::new(FailureKind::Camera, detail));
    loop {
        let timeout = if got_frame { stale } else { start_timeout.saturating_sub(start.elapsed()).max(Duration::from_millis(1)) };
        let event = frames.wait(timeout).map_err(ServiceError::WaitFrames)?;
        match event {
            StereoEvent::Frame(frame) => {
                got_frame = true;
                let receive_ns = frame.receive_time_ns();
                let layout = *frame.layout();
                let (Some(l), Some(r)) = (frame.camera(0), frame.camera(1)) else {
                    stop_reason = camera("camera stream has fewer than two views");
                    break;
                };
                let (Ok(left), Ok(right)) = (
                    ImageView::new(l, layout.width, layout.height, layout.stride),
                    ImageView::new(r, layout.width, layout.height, layout.stride),
                ) else {
                    stop_reason = camera("camera frames are not GRAY8 views");
                    break;
                };
                loop {
                    match states.wait(Duration::ZERO).map_err(ServiceError::WaitStates)? {
                        MessageEvent::Message(s) => hl.robot_state(&s),
                        MessageEvent::PublisherGone => {
                            hl.safety_stop(Fault::new(FailureKind::RobotState, "robot state publisher gone"));
                        }
                        MessageEvent::Timeout | MessageEvent::PublisherUp => break,
                        MessageEvent::Interrupted => break,
                    }
                }
                newest_frame_id = newest_frame_id.max(Some(frame.frame_id()));
                let out = hl.cycle(frame.frame_id(), frame.header().capture_time_ns, &left, &right);
                stale_frame_commands += u64::from(newest_frame_id.is_some_and(|n| out.command.frame_id < n));
                let loop_ns = monotonic_ns().saturating_sub(receive_ns);
                let t = *hl.finish_cycle(loop_ns);
                send(&mut commands, &mut telemetry, &out.command, &t)?;
                if let Some(rep) = report.as_mut() {
                    if let Some(label) = out.reports.snapshot {
                        rep.submit(ReportJob::Overlay(Box::new(Snapshot::take(label, &left, &right, &t))));
                    }
                    if let Some(plan) = out.reports.plan {
                        rep.submit(ReportJob::Plan(plan));
                    }
                }
                drop(frame);
                if hl.finished() {
                    break;
                }
            }
            StereoEvent::Timeout => {
                if !got_frame {
                    return Err(ServiceError::NoFrames(start_timeout.as_secs_f64()));
                }
                stop_reason = Some(Fault::new(FailureKind::Camera, format!("no camera frame for {} ms", stale.as_millis())));
                break;
            }
            StereoEvent::PublisherGone => {
                if hl.phase() == handeye_wire::Phase::Done {
                    break;
                }
                stop_reason = camera("camera stream gone");
                break;
            }
            StereoEvent::PublisherUp => newest_frame_id = None,
            StereoEvent::Interrupted => {
                stop_reason = Some(Fault::new(FailureKind::Interrupted, "interrupted"));
                break;
            }
        }
    }
    if let Some(reason) = stop_reason {
        let done = hl.phase() == handeye_wire::Phase::Done;
        if !done {
            tracing::warn!(%reason, "stopping the arm");
        }
        let (cmd, t) = hl.safety_stop(reason);
        // The robot may be gone too; a failed send changes nothing about the outcome.
        let _ = send(&mut commands, &mut telemetry, &cmd, &t);
    }
    let mut outcome = hl.outcome(start.elapsed().as_secs_f64());
    outcome.stale_frame_commands = stale_frame_commands;
    let (report_files, report_errors) = match report {
        Some(mut rep) => {
            // The fitted camera model, for `handeye daemon --observe --stereo-model`.
            let mut model_file = Vec::new();
            if let Some(cal) = hl.mission().calibration.get() {
                let path = rep.dir().join("stereo_model.json");
                let text = serde_json::to_string_pretty(&crate::stereo_model::StereoModelFile::from_model(&cal.model)).unwrap_or_default();
                match std::fs::write(&path, text) {
                    Ok(()) => model_file.push(path),
                    Err(e) => tracing::warn!(path = %path.display(), error = %e, "stereo model not written"),
                }
            }
            rep.submit(ReportJob::ServoPlot {
                rows: outcome.servo_trace.clone(),
                tolerance_mm: hl.config().servo.convergence.converged_m * 1e3,
                tolerance_deg: hl.config().servo.convergence.converged_deg,
            });
            let (mut files, errors) = rep.finish();
            files.extend(model_file);
            (files, errors)
        }
        None => (Vec::new(), Vec::new()),
    };
    Ok(ServiceResult { outcome, report_files, report_errors })
}

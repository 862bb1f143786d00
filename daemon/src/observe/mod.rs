//! Observe mode (`handeye daemon --observe`): the daemon on a camera stream with no robot at
//! all. It acquires the target (and the gripper plate, when hinted) from operator hints,
//! refines and verifies them as the working daemon does, tracks them at frame rate in both
//! views (or the left one of a mono stream), checks that the two views' tracks agree with a
//! stereo model when one is given, and publishes telemetry every frame. It never publishes a
//! command: it does not even open the command service. A lost track is searched for around
//! its last pose and its predicted one ([`watch`], [`crate::track_search`]) while telemetry
//! says `lost`, and picked up when it reappears. Given the working plane's points
//! (`--plane`, [`plane`]), it also reads the operator's pointing gestures from the frames and
//! reports the pointed point live ([`pointing`]: the point phase's gesture tracker on its own
//! thread), gesture after gesture.
//!
//! [`ObserveLoop`] is the per-frame work without I/O (tests drive it in-process);
//! [`service`] runs it on a domain's services; [`report`] is `observe.json` and its plot.

pub mod plane;
pub mod pointing;
#[cfg(test)]
mod pointing_tests;
pub mod report;
pub mod service;
pub mod watch;

use handeye_vision::affine::EpipolarConstraint;
use handeye_vision::image::ImageView;
use handeye_vision::tracker::{ContourTracker, Role, StereoTrackerSet, TrackerConfig, View};
use handeye_wire::hint::OperatorHint;
use handeye_wire::{monotonic_ns, Phase, Telemetry, NO_FRAME, TELEMETRY_CORNERS};

use crate::camera_clock::CameraClock;
use crate::config::DaemonConfig;
use crate::outcome::TrackerTiming;
use crate::timing::LatencyHistogram;
use plane::WorkingPlane;
use pointing::{PointingStartError, PointingWatch};
use report::{EpipolarStats, LoopTiming, ObserveReport, SeriesRow};
use watch::{TrackWatch, WatchEvent};

/// The telemetry's tracker slots, in its order.
const SLOTS: [(Role, View, &str); 4] = [
    (Role::Gripper, View::Left, "gripper_left"),
    (Role::Gripper, View::Right, "gripper_right"),
    (Role::Target, View::Left, "target_left"),
    (Role::Target, View::Right, "target_right"),
];

/// Rows the plot keeps at most. The plot is 800 px wide, so 2,000 rows are over two per pixel
/// column; the bound is also what the daemon's memory grows by in a long run (56 bytes a
/// row: 110 KiB, full after about a minute of frames at 30/s). 20,000 rows took 1.1 MB and
/// 11 minutes to fill, which the soak (`tests/soak_observe.rs`) measured as steady growth.
const MAX_SERIES_ROWS: usize = 2_000;

/// What observe mode is given besides the daemon's configuration.
#[derive(Debug, Clone)]
pub struct ObserveOptions {
    /// The target facet's outline (`hint.json`), if a target is to be tracked.
    pub hint: Option<OperatorHint>,
    /// The gripper plate's outline, if it is to be tracked too.
    pub gripper_hint: Option<OperatorHint>,
    /// The stream's two views are one camera (`feed --mono`, `camera --mono`): track the
    /// left view only.
    pub mono: bool,
    /// The stereo pair's epipolar constraint: the two views' tracks are checked against it.
    pub epipolar: Option<EpipolarConstraint>,
    /// The working plane's points in both views: read pointing gestures (`--plane`).
    pub plane: Option<WorkingPlane>,
}

/// Why observe mode cannot start with these options.
#[derive(Debug, thiserror::Error)]
pub enum ObserveError {
    /// A hint whose outline cannot start a tracker.
    #[error("{which} hint, {view} view: {detail}")]
    Hint { which: &'static str, view: &'static str, detail: String },
    #[error("--plane needs both views (the pointed point is where the finger's lines of the two views meet on the plane); a --mono stream has one")]
    PlaneNeedsTwoViews,
    #[error("nothing to observe: give a target (--hint), the working plane for pointing (--plane), or both")]
    NothingToWatch,
}

/// Observe mode's state between frames.
pub struct ObserveLoop {
    cfg: DaemonConfig,
    epipolar: Option<EpipolarConstraint>,
    trackers: StereoTrackerSet,
    watches: [TrackWatch; 4],
    clock: CameraClock,
    telemetry: Telemetry,
    loop_timing: LatencyHistogram,
    tracker_timing: LatencyHistogram,
    /// Every `series_stride`-th frame: camera time, confidences, update time (for the
    /// plot). Thinned to every other row whenever it reaches [`MAX_SERIES_ROWS`], so a
    /// day-long run keeps a bounded plot.
    series: Vec<SeriesRow>,
    series_stride: u64,
    /// RMS epipolar residual per checked frame, in thousandths of a pixel (a fixed
    /// histogram: no growth with the run's length).
    epipolar_mpx: LatencyHistogram,
    epipolar_over: u64,
    camera_gone: u32,
    frames: u64,
    /// Pointing gestures (`--plane`).
    pointing: Option<PointingWatch>,
}

impl ObserveLoop {
    pub fn new(cfg: DaemonConfig, options: ObserveOptions) -> Result<Self, ObserveError> {
        if options.plane.is_some() && options.mono {
            return Err(ObserveError::PlaneNeedsTwoViews);
        }
        if options.hint.is_none() && options.plane.is_none() {
            return Err(ObserveError::NothingToWatch);
        }
        let mut trackers = StereoTrackerSet::new();
        let target_min = cfg.target.min_score.max(cfg.safety.min_target_score);
        let mut watches = SLOTS.map(|(_, _, name)| TrackWatch::off(name));
        let hints = [(Role::Target, options.hint.as_ref(), "target"), (Role::Gripper, options.gripper_hint.as_ref(), "gripper")];
        for (role, hint, which) in hints {
            let Some(hint) = hint else { continue };
            let (tracker_cfg, converge, min) = match role {
                // Observe mode knows nothing of how the cameras move (a hand-held camera changes
                // the face's shape with the view), so the target's start shape is no reference
                // for the wrong-lock check here.
                Role::Target => (TrackerConfig { shape_is_fixed: false, ..cfg.tracker.target_tracker_config() }, cfg.target.converge_frames, target_min),
                Role::Gripper => (cfg.plate_tracker_config(), cfg.acquire.converge_frames, cfg.safety.min_tracker_score),
            };
            for (view, poly, side) in [(View::Left, &hint.left_px, "left"), (View::Right, &hint.right_px, "right")] {
                if options.mono && view == View::Right {
                    continue;
                }
                let t = ContourTracker::new(tracker_cfg, poly).map_err(|e| ObserveError::Hint { which, view: side, detail: e.to_string() })?;
                trackers.insert(role, view, t);
                let slot = SLOTS.iter().position(|s| s.0 == role && s.1 == view).unwrap_or(0);
                watches[slot] = TrackWatch::acquiring(SLOTS[slot].2, converge, min);
            }
        }
        let clock = CameraClock::new(cfg.timing.frame_rate_hz);
        let deadline_ns = cfg.timing.deadline_us * 1000;
        let pointing = options.plane.map(|p| PointingWatch::new(p, &cfg));
        Ok(Self {
            cfg,
            epipolar: if options.mono { None } else { options.epipolar },
            trackers,
            watches,
            clock,
            telemetry: Telemetry { phase: Phase::Observe as u32, ..Telemetry::default() },
            loop_timing: LatencyHistogram::new(deadline_ns),
            tracker_timing: LatencyHistogram::new(u64::MAX),
            series: Vec::new(),
            series_stride: 1,
            epipolar_mpx: LatencyHistogram::new(u64::MAX),
            epipolar_over: 0,
            camera_gone: 0,
            frames: 0,
            pointing,
        })
    }

    /// On every frame until it has started, with `--plane`: checks the first frame's size
    /// against the plane's pixels and starts the gesture tracker once the view stands still,
    /// that frame its scene without the hand. Without `--plane`, or once started, nothing.
    pub fn start_pointing(&mut self, left: &ImageView<'_>, right: &ImageView<'_>, capture_time_ns: u64) -> Result<(), PointingStartError> {
        match self.pointing.as_mut() {
            Some(p) if !p.started() => p.start(left, right, capture_time_ns),
            _ => Ok(()),
        }
    }

    /// The newest indicated point in both views, px (`--plane`; `None` without one).
    pub fn pointed_px(&self) -> Option<[[f64; 2]; 2]> {
        self.pointing.as_ref().and_then(PointingWatch::pointed_px)
    }

    /// Processes one frame (id and capture stamp from its header): updates the running
    /// trackers, advances each watch (searching for lost ones), checks the views against the
    /// stereo model, hands the frame to the gesture tracker and takes its due result (once
    /// [`Self::start_pointing`] started it), fills the telemetry. Returns the label of a key
    /// moment worth an overlay (`acquired`, `lost`, `refound`, `pointed`, `point_refused`),
    /// if one happened.
    pub fn cycle(&mut self, frame_id: u64, capture_time_ns: u64, left: &ImageView<'_>, right: &ImageView<'_>) -> Option<&'static str> {
        self.frames += 1;
        let tick = self.clock.tick(frame_id, capture_time_ns);
        for (i, &(role, view, _)) in SLOTS.iter().enumerate() {
            if self.trackers.get(role, view).is_some() {
                self.trackers.set_active(role, view, self.watches[i].runs());
            }
        }
        let (states, update_ns) = self.trackers.update_timed(left, right, tick.dt_s, monotonic_ns);
        let mut moment = None;
        for (i, &(role, view, _)) in SLOTS.iter().enumerate() {
            let Some(tracker) = self.trackers.get_mut(role, view) else { continue };
            let image = if view == View::Left { left } else { right };
            let event = self.watches[i].step(tracker, states.get(role, view).as_ref(), image, frame_id, tick.now_ns);
            moment = moment.or(event.map(|e| match e {
                WatchEvent::Acquired => "acquired",
                WatchEvent::Lost => "lost",
                WatchEvent::Refound => "refound",
            }));
            if let Some(e) = event {
                tracing::info!(tracker = SLOTS[i].2, frame_id, event = ?e, "observe");
            }
        }
        if let Some(p) = self.pointing.as_mut() {
            let event = p.frame(self.frames, frame_id, capture_time_ns, tick.now_ns, left, right);
            moment = moment.or(event);
        }
        let epipolar_px = self.check_epipolar();
        self.fill_telemetry(frame_id, update_ns, epipolar_px);
        let update_sum: u64 = self.telemetry.tracker_update_ns.iter().sum();
        if update_sum > 0 {
            self.tracker_timing.record_ns(update_sum);
        }
        if self.frames.is_multiple_of(self.series_stride) {
            if self.series.len() >= MAX_SERIES_ROWS {
                let mut keep = false;
                self.series.retain(|_| {
                    keep = !keep;
                    keep
                });
                self.series_stride *= 2;
            }
            let mut confidence = SLOTS.map(|_| f64::NAN);
            for (i, w) in self.watches.iter().enumerate() {
                if w.telemetry_state() != 0 {
                    confidence[i] = if w.is_lost() { 0.0 } else { f64::from(self.telemetry.tracker_confidence[i]) };
                }
            }
            self.series.push(SeriesRow { frame_id, time_s: tick.now_ns as f64 * 1e-9, confidence, update_us: update_sum as f64 * 1e-3 });
        }
        moment
    }

    /// RMS epipolar residual of each role tracked in both views, the larger one, px.
    fn check_epipolar(&mut self) -> Option<f64> {
        let model = self.epipolar.as_ref()?;
        let mut worst: Option<f64> = None;
        for role in [Role::Target, Role::Gripper] {
            let both = [View::Left, View::Right].iter().all(|&v| {
                let i = SLOTS.iter().position(|s| s.0 == role && s.1 == v).unwrap_or(0);
                matches!(self.watches[i].state, watch::WatchState::Tracking)
            });
            let (Some(l), Some(r)) = (self.trackers.get(role, View::Left), self.trackers.get(role, View::Right)) else { continue };
            if !both {
                continue;
            }
            let (mut sum, mut n) = (0.0, 0);
            for (a, b) in l.corners().zip(r.corners()) {
                sum += model.residual_px(&[a.x, a.y, b.x, b.y]).powi(2);
                n += 1;
            }
            if n > 0 {
                let rms = (sum / f64::from(n)).sqrt();
                worst = Some(worst.map_or(rms, |w: f64| w.max(rms)));
            }
        }
        if let Some(rms) = worst {
            self.epipolar_mpx.record_ns((rms * 1e3).round().min(u64::MAX as f64) as u64);
            if rms > self.cfg.target.max_epipolar_px {
                self.epipolar_over += 1;
            }
        }
        worst
    }

    fn fill_telemetry(&mut self, frame_id: u64, update_ns: [u64; 4], epipolar_px: Option<f64>) {
        let t = &mut self.telemetry;
        t.phase = Phase::Observe as u32;
        t.frame_id = frame_id;
        t.dropped_frames = self.clock.dropped_frames();
        for (i, &(role, view, _)) in SLOTS.iter().enumerate() {
            let w = &self.watches[i];
            t.tracker_state[i] = w.telemetry_state();
            t.tracker_update_ns[i] = if w.runs() || matches!(w.state, watch::WatchState::Confirming { .. }) { update_ns[i] } else { 0 };
            t.tracker_corners_px[i] = [[f32::NAN; 2]; TELEMETRY_CORNERS];
            t.tracker_confidence[i] = 0.0;
            let Some(tr) = self.trackers.get(role, view) else { continue };
            t.tracker_updates[i] = tr.update_count();
            if w.is_lost() {
                continue;
            }
            let score = tr.confidence().score;
            t.tracker_confidence[i] = if score.is_finite() { score.clamp(0.0, 1.0) as f32 } else { 0.0 };
            for (k, c) in tr.corners().take(TELEMETRY_CORNERS).enumerate() {
                if c.x.is_finite() && c.y.is_finite() {
                    t.tracker_corners_px[i][k] = [c.x as f32, c.y as f32];
                }
            }
        }
        let lost: Vec<&str> = SLOTS.iter().zip(&self.watches).filter(|(_, w)| w.is_lost()).map(|(s, _)| s.2).collect();
        let acquiring = self.watches.iter().any(|w| matches!(w.state, watch::WatchState::Acquiring { .. }));
        let confirming: Vec<&str> =
            SLOTS.iter().zip(&self.watches).filter(|(_, w)| matches!(w.state, watch::WatchState::Confirming { .. })).map(|(s, _)| s.2).collect();
        let watching = self.watches.iter().any(|w| w.telemetry_state() != 0);
        let mut reason = if !watching {
            String::new()
        } else if !lost.is_empty() {
            format!("lost: {} (searching)", lost.join(", "))
        } else if !confirming.is_empty() {
            format!("found again, confirming: {}", confirming.join(", "))
        } else if acquiring {
            "acquiring from the hint".to_string()
        } else {
            "tracking".to_string()
        };
        if let Some(px) = epipolar_px.filter(|&px| px > self.cfg.target.max_epipolar_px) {
            reason.push_str(&format!("; views disagree ({px:.1} px epipolar)"));
        }
        if let Some(p) = self.pointing.as_mut() {
            p.fill_telemetry(t);
            let status = p.status();
            reason = if reason.is_empty() { status } else { format!("{reason}; {status}") };
        }
        t.set_reason(&reason);
    }

    /// Records the cycle's duration and returns the telemetry to publish.
    pub fn finish_cycle(&mut self, loop_ns: u64) -> &Telemetry {
        self.loop_timing.record_ns(loop_ns);
        self.telemetry.loop_ns = loop_ns;
        self.telemetry.deadline_misses = self.loop_timing.deadline_misses();
        self.telemetry.time_ns = monotonic_ns();
        &self.telemetry
    }

    /// No frame came (none yet, or the camera went away): the telemetry saying `reason` (no
    /// frame, no tracker updated). `gone_now`: the camera just went away: counted.
    /// `publisher_left`: its publisher is gone, so the clock takes the next frame as a new
    /// stream; a publisher that only went quiet (a stall) keeps its numbering, and the ids it
    /// skipped meanwhile are dropped frames. The trackers keep their last state.
    pub fn no_frame(&mut self, reason: &str, gone_now: bool, publisher_left: bool) -> Telemetry {
        if gone_now {
            self.camera_gone += 1;
        }
        if publisher_left {
            self.clock.restart();
        }
        let t = &mut self.telemetry;
        t.frame_id = NO_FRAME;
        t.tracker_update_ns = [0; 4];
        t.set_reason(reason);
        t.time_ns = monotonic_ns();
        *t
    }

    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// The watched contours' counts, in telemetry order (off slots included).
    pub fn watches(&self) -> impl Iterator<Item = &watch::WatchCounts> {
        self.watches.iter().map(|w| &w.counts)
    }

    /// Per-frame rows for the plot.
    pub fn series(&self) -> &[SeriesRow] {
        &self.series
    }

    /// `observe.json`.
    pub fn report(&self, wall_s: f64, end: &str) -> ObserveReport {
        let tt = &self.tracker_timing;
        let us = |ns: u64| ns as f64 / 1000.0;
        let e = &self.epipolar_mpx;
        let px = |mpx: u64| (e.count() > 0).then_some(mpx as f64 * 1e-3);
        ObserveReport {
            frames: self.frames,
            camera: self.clock.stats(),
            camera_gone: self.camera_gone,
            trackers: self.watches.iter().filter(|w| w.telemetry_state() != 0 || w.counts.tracked_frames > 0).map(|w| w.counts.clone()).collect(),
            tracker_update: TrackerTiming {
                us_p50: us(tt.percentile_ns(50.0)),
                us_p99: us(tt.percentile_ns(99.0)),
                us_max: us(tt.max_ns()),
                us_mean: tt.mean_ns() / 1000.0,
                cycles: tt.count(),
            },
            loop_us: LoopTiming { p50: us(self.loop_timing.percentile_ns(50.0)), p99: us(self.loop_timing.percentile_ns(99.0)) },
            epipolar: self.epipolar.map(|_| EpipolarStats {
                frames: e.count(),
                rms_px_p50: px(e.percentile_ns(50.0)),
                rms_px_max: px(e.max_ns()),
                limit_px: self.cfg.target.max_epipolar_px,
                over_limit_frames: self.epipolar_over,
            }),
            pointing: self.pointing.as_ref().map(PointingWatch::report),
            end: end.to_string(),
            wall_s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;
    use nalgebra::Vector4;

    /// A dark square (the target) at `(x, y)` and a bright plate in a dark border (the
    /// gripper) above it.
    fn view(x: usize, y: usize) -> ImageBuf {
        let mut img = ImageBuf::filled(320, 240, 150);
        let mut rect = |x0: usize, y0: usize, x1: usize, y1: usize, v: u8| {
            for yy in y0..y1 {
                for xx in x0..x1 {
                    img.set(xx, yy, v);
                }
            }
        };
        rect(x, y, x + 40, y + 40, 40);
        rect(x - 8, 20, x + 48, 80, 10);
        rect(x, 28, x + 40, 72, 230);
        img
    }

    fn square(x: f64, y: f64, size: f64) -> Vec<[f64; 2]> {
        vec![[x - 0.5, y - 0.5], [x + size - 0.5, y - 0.5], [x + size - 0.5, y + size - 0.5], [x - 0.5, y + size - 0.5]]
    }

    fn hint(l: Vec<[f64; 2]>, r: Vec<[f64; 2]>) -> OperatorHint {
        OperatorHint { version: 1, left_px: l, right_px: r, depth_mm: 40.0, note: String::new() }
    }

    /// Rectified views: a point's rows agree (`v' = v`).
    fn same_rows() -> EpipolarConstraint {
        EpipolarConstraint::from_normal(Vector4::new(0.0, 1.0, 0.0, -1.0), 0.0)
    }

    fn run(left: &ImageBuf, right: &ImageBuf, dy_right: f64) -> (ObserveLoop, Vec<Telemetry>) {
        let options = ObserveOptions {
            hint: Some(hint(square(120.0, 140.0, 40.0), square(100.0, 140.0 + dy_right, 40.0))),
            gripper_hint: Some(hint(square(120.0, 28.0, 40.0), square(100.0, 28.0 + dy_right, 40.0))),
            mono: false,
            epipolar: Some(same_rows()),
            plane: None,
        };
        let mut ol = ObserveLoop::new(DaemonConfig::default(), options).unwrap();
        let mut seen = Vec::new();
        for i in 0..30u64 {
            ol.cycle(i, 1_000 + i * 33_333_333, &left.view(), &right.view());
            seen.push(*ol.finish_cycle(1));
        }
        (ol, seen)
    }

    #[test]
    fn both_roles_are_tracked_in_both_views_and_checked_against_the_stereo_model() {
        // The right view sees everything 20 px to the left, on the same rows.
        let (left, right) = (view(120, 140), view(100, 140));
        let (ol, seen) = run(&left, &right, 0.0);
        let last = seen.last().unwrap();
        assert_eq!(last.phase, Phase::Observe as u32);
        assert_eq!(last.tracker_state, [1, 1, 1, 1], "{:?}", last.reason_text());
        assert_eq!(last.reason_text(), "tracking");
        assert!(last.tracker_update_ns.iter().all(|&ns| ns > 0));
        let r = ol.report(1.0, "stream ended");
        let e = r.epipolar.unwrap();
        assert!(e.frames > 0 && e.over_limit_frames == 0 && e.rms_px_max.unwrap() < 1.0, "{e:?}");
        assert_eq!(r.trackers.len(), 4);
        assert!(r.trackers.iter().all(|t| t.acquired_frame_id.is_some() && t.lost_frames == 0), "{:?}", r.trackers);

        // The right camera 20 px lower: each view tracks, but they are not the same rows.
        let right_low = {
            let mut img = ImageBuf::filled(320, 240, 150);
            let src = view(100, 140);
            for y in 20..240 {
                for x in 0..320 {
                    img.set(x, y, src.view().get(x, y - 20));
                }
            }
            img
        };
        let (ol, seen) = run(&left, &right_low, 20.0);
        let last = seen.last().unwrap();
        assert_eq!(last.tracker_state[2..], [1, 1]);
        assert!(last.reason_text().contains("views disagree"), "{}", last.reason_text());
        assert!(ol.report(1.0, "x").epipolar.unwrap().over_limit_frames > 0);
    }

    #[test]
    fn a_stalled_camera_keeps_its_numbering_and_a_new_publisher_starts_a_new_stream() {
        let (left, right) = (view(120, 140), view(100, 140));
        let (mut ol, _) = run(&left, &right, 0.0);
        let period_ns = 33_333_333;
        // The camera stalls (no frame for the stale time; its publisher still there), then
        // frame 33 arrives: frames 30-32 were dropped, not a new stream.
        ol.no_frame("camera gone: no frame for 100 ms", true, false);
        ol.cycle(33, 1_000 + 33 * period_ns, &left.view(), &right.view());
        assert_eq!(ol.finish_cycle(1).dropped_frames, 3);
        // Its publisher left; a new one numbers from 40: a new stream, nothing dropped.
        ol.no_frame("camera gone: its publisher went away", true, true);
        ol.cycle(40, 5_000_000_000, &left.view(), &right.view());
        assert_eq!(ol.finish_cycle(1).dropped_frames, 3);
        let r = ol.report(1.0, "x");
        assert_eq!((r.camera_gone, r.camera.dropped_frames, r.camera.stream_restarts), (2, 3, 1));
    }
}

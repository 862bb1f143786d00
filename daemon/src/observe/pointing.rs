//! Observe mode's pointing (`--plane FILE`, issue 19): the point phase's gesture tracker on
//! camera frames, with no robot. Every frame goes, copied, to the gesture tracker on its own
//! thread ([`crate::gesture_thread`], as in the point phase): the per-frame contour tracking
//! never waits for it (a frame that finds every buffer in flight is not handed over, and
//! counted), unless `timing.worker_wait_ms` asks for lockstep as in the point phase (a due
//! result is then waited for, so that what is answered on which frame does not depend on the
//! machine's speed: for tests; the default 0 never waits). The plane maps come from the plane file ([`super::plane`]), not from a
//! calibration. The scene without the hand is the first frame after which the view stood still
//! for [`STILL_START_FRAMES`] (a hand coming in as observing starts is not taken for the
//! scene; start with the hand out of view: a hand held still from the very first frame is);
//! quiet frames renew it as the light drifts. A changed scene that then stands still for
//! [`RENEW_AFTER_S`] (a block moved for good, or a hand that was in the first frames and has
//! gone) becomes the scene: a gesture is never that long, and without this no hand would be
//! absent again.
//!
//! Each gesture (a hand in view until it has gone) is reported once it is read: its first
//! answer (`indicated`: the point, its one-sigma radius, the frame and its capture time) and
//! its first refusal with the reason (degenerate, uncertain, unsteady, no line). A gesture
//! first refused and then answered while the hand still holds gets both. Telemetry's
//! `pointing_*` fields show the newest result every frame, as in the point phase; nothing
//! moves and observe mode keeps watching for the next gesture until it ends.

use std::collections::VecDeque;
use std::time::Duration;

use handeye_vision::image::ImageView;
use handeye_vision::pointing::{GestureConfig, GestureState, PointingTracker};
use handeye_wire::Telemetry;
use serde::{Deserialize, Serialize};

use super::plane::{PlaneFileError, WorkingPlane};
use crate::config::DaemonConfig;
use crate::gesture_thread::{GestureResult, GestureThread};
use crate::mission::pointing::{GestureRecord, PointingRecord};
use crate::outcome::TrackerTiming;
use crate::phase::point::record as gesture_record;
use crate::timing::LatencyHistogram;

/// Answers and refusals kept for `observe.json`, each (a day-long run stays bounded; the
/// count of gestures goes on).
pub const MAX_KEPT: usize = 500;

/// Frames handed over whose capture time is remembered until their result comes back: more
/// than the gesture thread keeps in flight.
const CAPTURES_KEPT: usize = 16;

/// Frames the view must stand still (beside the first) before that first frame is taken as
/// the scene without the hand: a hand moving in is never still for 0.1 s at 30 Hz.
pub const STILL_START_FRAMES: u32 = 3;
/// A scene that differs from the gesture tracker's and stands still this long becomes its
/// scene, s of camera time: longer than any gesture holds (a person holds 1-3 s).
pub const RENEW_AFTER_S: f64 = 10.0;
/// Every `STILL_STEP_PX`-th pixel of every `STILL_STEP_PX`-th row is compared between frames.
const STILL_STEP_PX: usize = 4;
/// Samples that may change between frames in a still view (a few hot pixels or a flicker);
/// a hand moving changes hundreds.
const STILL_MAX_CHANGED: usize = 4;

/// Whether the view stands still: a subsampled frame-to-frame difference (~40 kB, a few µs).
#[derive(Debug, Default)]
struct Stillness {
    previous: Vec<u8>,
    current: Vec<u8>,
    /// Grey levels a sample must change by to count (the silhouette's threshold: noise is a
    /// few).
    min_difference: u8,
    /// Frames in a row with (almost) nothing changed, and since when (camera ns).
    still_frames: u32,
    still_since_ns: Option<u64>,
}

impl Stillness {
    fn new(min_difference: u8) -> Self {
        Self { min_difference, ..Self::default() }
    }

    /// One frame at `now_ns`.
    fn frame(&mut self, left: &ImageView<'_>, right: &ImageView<'_>, now_ns: u64) {
        self.current.clear();
        for v in [left, right] {
            for y in (0..v.height()).step_by(STILL_STEP_PX) {
                self.current.extend(v.row(y)[..v.width()].iter().step_by(STILL_STEP_PX));
            }
        }
        let same_size = self.previous.len() == self.current.len();
        let changed = self.previous.iter().zip(&self.current).filter(|(a, b)| a.abs_diff(**b) > self.min_difference).count();
        if same_size && changed <= STILL_MAX_CHANGED {
            self.still_frames = self.still_frames.saturating_add(1);
            self.still_since_ns.get_or_insert(now_ns);
        } else {
            self.still_frames = 0;
            self.still_since_ns = None;
        }
        std::mem::swap(&mut self.previous, &mut self.current);
    }

    /// Still for `frames` frames after the first.
    fn still_for_frames(&self, frames: u32) -> bool {
        self.still_frames >= frames
    }

    /// Still for `s` seconds at `now_ns`.
    fn still_for_s(&self, s: f64, now_ns: u64) -> bool {
        self.still_since_ns.is_some_and(|t| now_ns.saturating_sub(t) as f64 * 1e-9 >= s)
    }

    /// Start counting again (the scene was just taken).
    fn restart(&mut self) {
        self.still_frames = 0;
        self.still_since_ns = None;
    }
}

/// Why pointing could not start on the first frame.
#[derive(Debug, thiserror::Error)]
pub enum PointingStartError {
    /// The plane file does not fit the camera (a pixel outside its image).
    #[error(transparent)]
    Plane(#[from] PlaneFileError),
    #[error("cannot start the gesture thread: {0}")]
    Thread(std::io::Error),
}

/// One gesture's answer or refusal (`observe.json` `pointing.answered[]`, `refused[]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservedGesture {
    /// Which gesture: 1 for the first hand seen, counting on.
    pub gesture: u64,
    /// The frame the answer or refusal was read from, and its capture stamp (the camera's
    /// clock, ns).
    pub frame_id: u64,
    pub capture_time_ns: u64,
    /// `indicated`, `degenerate`, `uncertain`, `disagree`, `unsteady` or `no_line`.
    pub outcome: String,
    /// The indicated point: plane x, y and the plane file's `plane_z_m`, m.
    pub point_m: Option<[f64; 3]>,
    /// One-sigma radius of the point, mm (`indicated`, `uncertain`).
    pub sigma_mm: Option<f64>,
    /// Angle at which the two views' plane lines cross, degrees.
    pub crossing_deg: Option<f64>,
    /// The answer or the refusal's reason, in words.
    pub detail: String,
}

/// `observe.json` `pointing`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointingReport {
    /// The plane file, its number of points and each view's fit residual, px (0 with four).
    pub plane_file: String,
    pub plane_points: usize,
    pub plane_fit_rms_px: [f64; 2],
    /// Hands that came into view (gestures), answered or not.
    pub gestures_seen: u64,
    /// Every answer and every refusal, in order (the first [`MAX_KEPT`] of each).
    pub answered: Vec<ObservedGesture>,
    pub refused: Vec<ObservedGesture>,
    /// Frames handed to the gesture tracker, and frames not handed over (every buffer in
    /// flight: the tracker was behind; or a frame of another size than the first).
    pub frames_submitted: u64,
    pub frames_not_submitted: u64,
    /// The gesture tracker's update (both views, on its thread), µs; `cycles`: results.
    pub update: TrackerTiming,
    /// Times a changed scene that stood still [`RENEW_AFTER_S`] became the scene.
    #[serde(default)]
    pub scene_renewals: u64,
}

/// The gesture tracker and what it saw.
pub struct PointingWatch {
    plane: WorkingPlane,
    config: GestureConfig,
    /// How long a due gesture result is waited for (`timing.worker_wait_ms`; 0: never).
    due_wait: Duration,
    thread: Option<GestureThread>,
    record: PointingRecord,
    update: LatencyHistogram,
    /// (frame id, capture stamp) of frames handed over, newest last.
    captures: VecDeque<(u64, u64)>,
    not_submitted: u64,
    seen: u64,
    /// The current gesture: a hand in view, answered, refused.
    in_view: bool,
    answered_this: bool,
    refused_this: bool,
    answered: Vec<ObservedGesture>,
    refused: Vec<ObservedGesture>,
    /// The newest result's state, for the telemetry's reason and the overlays.
    newest: Option<GestureState>,
    /// The image size the plane file was checked against; frames of another size (a new
    /// camera) are not handed over, and counted.
    size: (usize, usize),
    other_size: u64,
    /// Whether the view stands still: when to take the scene, and when to renew it.
    stillness: Stillness,
    scene_renewals: u64,
}

impl PointingWatch {
    pub fn new(plane: WorkingPlane, cfg: &DaemonConfig) -> Self {
        Self {
            config: GestureConfig { max_sigma_m: cfg.point().max_sigma_m, ..GestureConfig::default() },
            due_wait: Duration::from_millis(cfg.timing.worker_wait_ms),
            plane,
            thread: None,
            record: PointingRecord::default(),
            update: LatencyHistogram::new(u64::MAX),
            captures: VecDeque::with_capacity(CAPTURES_KEPT),
            not_submitted: 0,
            seen: 0,
            in_view: false,
            answered_this: false,
            refused_this: false,
            answered: Vec::new(),
            refused: Vec::new(),
            newest: None,
            size: (0, 0),
            other_size: 0,
            stillness: Stillness::new(GestureConfig::default().silhouette.min_difference),
            scene_renewals: 0,
        }
    }

    /// Whether the gesture tracker runs (it starts on the first frame).
    pub fn started(&self) -> bool {
        self.thread.is_some()
    }

    /// On every frame until it has started (`now_ns`: camera time): the first frame's size
    /// is checked against the plane file's pixels; once the view has stood still for
    /// [`STILL_START_FRAMES`], the gesture thread starts with this frame as the scene without
    /// the hand.
    pub fn start(&mut self, left: &ImageView<'_>, right: &ImageView<'_>, now_ns: u64) -> Result<(), PointingStartError> {
        if self.size == (0, 0) {
            self.plane.check_image_size(left.width(), left.height())?;
            self.size = (left.width(), left.height());
        }
        if (left.width(), left.height()) != self.size {
            return Ok(()); // frame() counts it
        }
        self.stillness.frame(left, right, now_ns);
        if !self.stillness.still_for_frames(STILL_START_FRAMES) {
            return Ok(());
        }
        let tracker = PointingTracker::new(self.plane.pointing, self.config);
        let mut thread = GestureThread::spawn(tracker, left.width(), left.height(), self.due_wait).map_err(PointingStartError::Thread)?;
        // A fresh thread has every buffer free: this cannot be refused.
        thread.set_background(left, right);
        self.thread = Some(thread);
        self.stillness.restart();
        self.record.start(self.plane.plane_z_m, self.plane.fit_rms_px().iter().copied().fold(0.0, f64::max));
        tracing::info!(file = %self.plane.file.display(), points = self.plane.points.len(), "observe: watching for pointing gestures");
        Ok(())
    }

    /// One frame (`frame_index`: frames since the start, `now_ns`: camera time): takes the
    /// result that is due, hands this frame over. Returns the label of a key moment worth an
    /// overlay (`pointed`, `point_refused`), if one happened.
    pub fn frame(&mut self, frame_index: u64, frame_id: u64, capture_time_ns: u64, now_ns: u64, left: &ImageView<'_>, right: &ImageView<'_>) -> Option<&'static str> {
        let thread = self.thread.as_mut()?;
        if (left.width(), left.height()) != self.size {
            // The plane's pixels and the background belong to the first camera's images.
            if self.other_size == 0 {
                tracing::warn!(width = left.width(), height = left.height(), "observe: frames of another size than the first: pointing paused until they are {}x{} again", self.size.0, self.size.1);
            }
            self.other_size += 1;
            self.not_submitted += 1;
            return None;
        }
        self.stillness.frame(left, right, now_ns);
        if self.in_view && self.stillness.still_for_s(RENEW_AFTER_S, now_ns) && thread.set_background(left, right) {
            // Something changed for good (or the first frames held the hand): the scene now.
            self.scene_renewals += 1;
            self.stillness.restart();
            tracing::warn!(frame_id, renewals = self.scene_renewals, "observe: the view changed and stood still {RENEW_AFTER_S} s: it is the scene without the hand now");
        }
        let result = thread.poll(frame_index);
        if thread.submit(frame_index, frame_id, left, right) {
            self.record.submitted();
            if self.captures.len() == CAPTURES_KEPT {
                self.captures.pop_front();
            }
            self.captures.push_back((frame_id, capture_time_ns));
        } else {
            self.not_submitted += 1;
        }
        let r = result?;
        self.record.result(&r);
        self.update.record_ns(r.update_ns.max(1));
        self.newest = Some(r.state);
        self.take(&r, now_ns)
    }

    /// Follows the gestures: a hand in view starts one, `Absent` ends it; its first answer
    /// and its first refusal are kept and logged.
    fn take(&mut self, r: &GestureResult, now_ns: u64) -> Option<&'static str> {
        if matches!(r.state, GestureState::Absent) {
            if self.in_view {
                tracing::info!(gesture = self.seen, frame_id = r.frame_id, "observe: the pointing hand went");
            }
            (self.in_view, self.answered_this, self.refused_this) = (false, false, false);
            return None;
        }
        if !self.in_view {
            self.in_view = true;
            self.seen += 1;
            tracing::info!(gesture = self.seen, frame_id = r.frame_id, "observe: a hand in view");
        }
        let g = gesture_record(r, now_ns, self.plane.plane_z_m)?;
        let answer = g.point_m.is_some();
        if self.answered_this || (!answer && self.refused_this) {
            return None; // the same gesture, already reported
        }
        tracing::info!(gesture = self.seen, outcome = %g.outcome, detail = %g.detail, frame = g.frame_id, "pointing gesture");
        let capture = self.captures.iter().rev().find(|c| c.0 == r.frame_id).map_or(0, |c| c.1);
        let kept = observed(self.seen, capture, g);
        if answer {
            self.answered_this = true;
            if self.answered.len() < MAX_KEPT {
                self.answered.push(kept);
            }
            Some("pointed")
        } else {
            self.refused_this = true;
            if self.refused.len() < MAX_KEPT {
                self.refused.push(kept);
            }
            Some("point_refused")
        }
    }

    /// Writes telemetry's `pointing_*` fields for this frame (the point phase's semantics).
    pub fn fill_telemetry(&mut self, t: &mut Telemetry) {
        self.record.fill_telemetry(t);
    }

    /// The newest result in a few words, for telemetry's reason.
    pub fn status(&self) -> String {
        match self.newest {
            None if self.started() => "pointing: no hand yet".into(),
            None => "pointing: waiting for a still view (the scene without the hand)".into(),
            Some(GestureState::Absent) => "pointing: no hand".into(),
            Some(GestureState::Moving { .. }) => "pointing: a hand, not still yet".into(),
            Some(GestureState::Indicated(p)) => format!("pointing: at ({:.3}, {:.3}) m", p.point_m[0], p.point_m[1]),
            Some(s) => format!("pointing: refused ({})", refusal_name(&s)),
        }
    }

    /// The newest answer's point in both views, px (`None` without one): the overlays mark it.
    pub fn pointed_px(&self) -> Option<[[f64; 2]; 2]> {
        let Some(GestureState::Indicated(p)) = self.newest else { return None };
        match self.plane.project(&p.point_m) {
            [Some(l), Some(r)] => Some([l, r]),
            _ => None,
        }
    }

    /// `observe.json` `pointing`.
    pub fn report(&self) -> PointingReport {
        let us = |ns: u64| ns as f64 / 1000.0;
        let u = &self.update;
        PointingReport {
            plane_file: self.plane.file.display().to_string(),
            plane_points: self.plane.points.len(),
            plane_fit_rms_px: self.plane.fit_rms_px(),
            gestures_seen: self.seen,
            answered: self.answered.clone(),
            refused: self.refused.clone(),
            frames_submitted: self.record.summary().map_or(0, |s| s.frames_submitted),
            frames_not_submitted: self.not_submitted,
            update: TrackerTiming { us_p50: us(u.percentile_ns(50.0)), us_p99: us(u.percentile_ns(99.0)), us_max: us(u.max_ns()), us_mean: u.mean_ns() / 1000.0, cycles: u.count() },
            scene_renewals: self.scene_renewals,
        }
    }
}

fn refusal_name(s: &GestureState) -> &'static str {
    match s {
        GestureState::Degenerate { .. } => "degenerate",
        GestureState::Uncertain { .. } => "uncertain",
        GestureState::Unsteady { .. } => "unsteady",
        GestureState::NoLine { .. } => "no line",
        GestureState::Disagree { .. } => "disagree",
        _ => "",
    }
}

fn observed(gesture: u64, capture_time_ns: u64, g: GestureRecord) -> ObservedGesture {
    ObservedGesture {
        gesture,
        frame_id: g.frame_id,
        capture_time_ns,
        outcome: g.outcome,
        point_m: g.point_m,
        sigma_mm: g.sigma_mm,
        crossing_deg: g.crossing_deg,
        detail: g.detail,
    }
}

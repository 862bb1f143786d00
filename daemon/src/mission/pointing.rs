//! What the point phase saw: each gesture's outcome (the indicated point, or why it was
//! refused), the gesture tracker's update times, and the newest result for telemetry.
//! `daemon.json` carries it as `pointing`.

use handeye_vision::pointing::GestureState;
use handeye_wire::{PointingState, Telemetry};
use serde::{Deserialize, Serialize};

use crate::gesture_thread::GestureResult;
use crate::timing::LatencyHistogram;

/// One gesture that ended in an answer or a refusal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GestureRecord {
    /// The frame the answer or refusal came from.
    pub frame_id: u64,
    /// Camera time of the cycle that took it, s since the daemon's first frame.
    pub time_s: f64,
    /// `indicated`, `degenerate`, `uncertain`, `disagree`, `unsteady` or `no_line`; or
    /// `ambiguous`: answered, but the plan found that the point picks no one block (the
    /// operator was asked to point again).
    pub outcome: String,
    /// The indicated point, robot frame, m (`indicated` only).
    pub point_m: Option<[f64; 3]>,
    /// One-sigma radius of the point, mm (`indicated` and `uncertain`).
    pub sigma_mm: Option<f64>,
    /// Angle at which the two plane lines cross, degrees (`indicated` and `degenerate`).
    pub crossing_deg: Option<f64>,
    /// The fingertip in the left and right views, tracker pixels (`indicated`).
    pub tip_px: Option<[[f64; 2]; 2]>,
    /// The finger's line in each view, `a u + b v + c = 0` (`indicated`).
    pub line_px: Option<[[f64; 3]; 2]>,
    /// The refusal in words.
    pub detail: String,
}

/// `daemon.json` `pointing`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointingSummary {
    /// The point the daemon planned for, robot frame, m (`None`: no gesture answered).
    pub indicated_m: Option<[f64; 3]>,
    /// Every gesture that ended, in order: refusals first, the answer last.
    pub gestures: Vec<GestureRecord>,
    /// Frames handed to the gesture tracker, and results taken.
    pub frames_submitted: u64,
    pub updates: u64,
    /// The gesture tracker's update (both views), µs: p50, p99, max (histogram bucket edges).
    pub update_us_p50: f64,
    pub update_us_p99: f64,
    pub update_us_max: f64,
    /// Height of the working plane the lines were carried onto, m (the lowest cage points').
    pub plane_z_m: f64,
    /// What the gesture tracker said, each time it changed: frame id and state (`absent`,
    /// `moving`, `indicated`, ...), the first 200 changes.
    #[serde(default)]
    pub changes: Vec<(u64, String)>,
    /// RMS distance of the fitted pinhole cameras from the cage pixels they were fitted to,
    /// px: how well the plane maps are grounded.
    pub plane_fit_rms_px: f64,
}

/// The point phase's record; owned by the mission, written by the point phase.
#[derive(Debug)]
pub struct PointingRecord {
    started: bool,
    gestures: Vec<GestureRecord>,
    indicated_m: Option<[f64; 3]>,
    submitted: u64,
    update: LatencyHistogram,
    /// The result taken this cycle (for telemetry), cleared when reported.
    this_cycle: Option<GestureResult>,
    /// The newest result's state, kept between results.
    newest: Option<GestureResult>,
    plane_z_m: f64,
    plane_fit_rms_px: f64,
    changes: Vec<(u64, String)>,
    /// Camera time of the newest result that saw a hand (any state but absent), ns.
    hand_seen_ns: Option<u64>,
}

/// State changes kept for `daemon.json`.
const MAX_CHANGES: usize = 200;

/// A gesture state as telemetry's `pointing_state` carries it.
fn wire_state(s: &GestureState) -> PointingState {
    match s {
        GestureState::Absent => PointingState::Absent,
        GestureState::Moving { .. } => PointingState::Moving,
        GestureState::Indicated(_) => PointingState::Indicated,
        GestureState::Degenerate { .. } => PointingState::Degenerate,
        GestureState::Uncertain { .. } => PointingState::Uncertain,
        GestureState::Unsteady { .. } => PointingState::Unsteady,
        GestureState::NoLine { .. } => PointingState::NoLine,
        GestureState::Disagree { .. } => PointingState::Disagree,
    }
}

impl Default for PointingRecord {
    fn default() -> Self {
        Self {
            started: false,
            gestures: Vec::new(),
            indicated_m: None,
            submitted: 0,
            update: LatencyHistogram::new(u64::MAX),
            this_cycle: None,
            newest: None,
            plane_z_m: f64::NAN,
            plane_fit_rms_px: f64::NAN,
            changes: Vec::new(),
            hand_seen_ns: None,
        }
    }
}

impl PointingRecord {
    /// The gesture tracker started, with plane maps at `plane_z_m` fitted to `fit_rms_px`.
    pub fn start(&mut self, plane_z_m: f64, fit_rms_px: f64) {
        self.started = true;
        self.plane_z_m = plane_z_m;
        self.plane_fit_rms_px = fit_rms_px;
    }

    pub fn submitted(&mut self) {
        self.submitted += 1;
    }

    /// A result taken this cycle.
    pub fn result(&mut self, r: &GestureResult) {
        self.update.record_ns(r.update_ns.max(1));
        let name = wire_state(&r.state).name();
        if self.changes.len() < MAX_CHANGES && self.changes.last().is_none_or(|(_, last)| last != name) {
            self.changes.push((r.frame_id, name.to_string()));
        }
        self.this_cycle = Some(*r);
        self.newest = Some(*r);
    }

    /// The result taken at camera time `time_ns` saw a hand (or saw none).
    pub fn hand_at(&mut self, time_ns: u64, present: bool) {
        if present {
            self.hand_seen_ns = Some(time_ns);
        }
    }

    /// Camera time a hand was last seen while watching, ns (`None`: never, or the watch
    /// ended). A hand in front of the parked plate explains its loss: the hold waits for it
    /// to go before it tries anything else (`hard_loop/hold.rs`).
    pub fn hand_seen_ns(&self) -> Option<u64> {
        self.hand_seen_ns
    }

    /// A gesture ended (answered or refused).
    pub fn gesture(&mut self, g: GestureRecord) {
        if g.outcome == "indicated" {
            self.indicated_m = g.point_m;
        }
        self.gestures.push(g);
    }

    /// The plan found that the answered gesture's point picks no one block (`why`): it is
    /// recorded as `ambiguous`, and the point is forgotten until the next answer.
    /// The plan turned the newest answered gesture's point down (`outcome`: "ambiguous", a
    /// point between blocks; "off_blocks", a point on none); the operator is asked again.
    pub fn turned_down(&mut self, outcome: &str, why: String) {
        if let Some(g) = self.gestures.iter_mut().rev().find(|g| g.outcome == "indicated") {
            g.outcome = outcome.into();
            g.detail = why;
        }
        self.indicated_m = None;
    }

    pub fn gestures(&self) -> &[GestureRecord] {
        &self.gestures
    }

    pub fn indicated_m(&self) -> Option<[f64; 3]> {
        self.indicated_m
    }

    /// Watching has ended: telemetry says off from now on.
    pub fn stop(&mut self) {
        self.newest = None;
        self.this_cycle = None;
        self.hand_seen_ns = None;
    }

    /// `daemon.json` `pointing` (`None`: the phase never watched).
    pub fn summary(&self) -> Option<PointingSummary> {
        self.started.then(|| {
            let us = |ns: u64| ns as f64 / 1000.0;
            PointingSummary {
                indicated_m: self.indicated_m,
                gestures: self.gestures.clone(),
                frames_submitted: self.submitted,
                updates: self.update.count(),
                update_us_p50: us(self.update.percentile_ns(50.0)),
                update_us_p99: us(self.update.percentile_ns(99.0)),
                update_us_max: us(self.update.max_ns()),
                plane_z_m: self.plane_z_m,
                plane_fit_rms_px: self.plane_fit_rms_px,
                changes: self.changes.clone(),
            }
        })
    }

    /// Writes the pointing fields of this cycle's telemetry.
    pub fn fill_telemetry(&mut self, t: &mut Telemetry) {
        let this = self.this_cycle.take();
        t.pointing_update_ns = this.map_or(0, |r| r.update_ns);
        t.pointing_point_m = [f32::NAN; 2];
        t.pointing_sigma_m = f32::NAN;
        t.pointing_crossing_rad = f32::NAN;
        t.pointing_tip_px = [[f32::NAN; 2]; 2];
        t.pointing_line_px = [[f32::NAN; 3]; 2];
        let Some(r) = self.newest else {
            t.pointing_state = if self.started && self.indicated_m.is_none() { PointingState::Absent as u32 } else { PointingState::Off as u32 };
            t.pointing_frame = 0;
            return;
        };
        t.pointing_frame = r.frame_id as u32;
        let f = |x: f64| x as f32;
        t.pointing_state = wire_state(&r.state) as u32;
        match r.state {
            GestureState::Indicated(p) => {
                t.pointing_point_m = p.point_m.map(f);
                t.pointing_sigma_m = f(p.sigma_m);
                t.pointing_crossing_rad = f(p.crossing_rad);
                for v in 0..2 {
                    t.pointing_tip_px[v] = p.axes[v].tip_px.map(f);
                    t.pointing_line_px[v] = [f(p.axes[v].line.0[0]), f(p.axes[v].line.0[1]), f(p.axes[v].line.0[2])];
                }
            }
            GestureState::Degenerate { crossing_rad } => t.pointing_crossing_rad = f(crossing_rad),
            GestureState::Uncertain { sigma_m } => t.pointing_sigma_m = f(sigma_m),
            _ => {}
        }
    }
}

//! The daemon's clock, read from the cameras: every frame carries `capture_time_ns` (the
//! simulator stamps simulated time, a camera its capture instant on `CLOCK_MONOTONIC`), and
//! the daemon's time is the time of the frames it sees. The predictive filter's time step,
//! every time-out and every rate the daemon reports come from it, so a lockstep run (faster
//! or slower than real time) keeps the timing it simulates, and a real camera that drops a
//! frame gives the filter the true, longer step instead of one guessed from a rate.
//!
//! A gap in the frame ids is dropped frames, counted. A stamp that cannot be right — not
//! after the previous one, or more than [`MAX_STEP_NS`] after it — is counted too and
//! replaced by the step the frame ids imply at the measured frame period (the nominal one
//! until a period was measured), so a bad stamp never makes a huge time step and never
//! freezes or rewinds the clock a safety time-out runs on. Frame ids that go back mean a new
//! publisher (a camera restarted): the clock goes on from where it was, one period later.
//!
//! ```
//! use handeye_daemon::camera_clock::CameraClock;
//! let mut clock = CameraClock::new(30.0);
//! let t0 = 5_000_000_000;
//! assert_eq!(clock.tick(10, t0).now_ns, 0);
//! // Frame 11 was dropped: frame 12 comes 66.7 ms later, one step, one drop.
//! let tick = clock.tick(12, t0 + 66_666_667);
//! assert!((tick.dt_s - 0.0667).abs() < 1e-4 && tick.dropped == 1 && !tick.bad_stamp);
//! // A stamp that goes back is not believed: the step is one measured period.
//! let tick = clock.tick(13, t0);
//! assert!(tick.bad_stamp && (tick.dt_s - 0.0333).abs() < 1e-4);
//! assert_eq!((clock.stats().dropped_frames, clock.stats().bad_stamps), (1, 1));
//! ```

use serde::{Deserialize, Serialize};

use crate::timing::LatencyHistogram;

/// The longest step between two consecutive frames believed, ns (1 s). A longer one is a
/// bad stamp (a clock jump), unless the frame ids say that many frames were dropped.
pub const MAX_STEP_NS: u64 = 1_000_000_000;

/// Per-frame periods remembered for the period estimate.
const PERIODS: usize = 16;

/// What the clock says about one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTick {
    /// Camera time since the first frame, ns (never goes back).
    pub now_ns: u64,
    /// Time since the previous frame, s (the filter's time step; > 0).
    pub dt_s: f64,
    /// Frame ids skipped since the previous frame.
    pub dropped: u64,
    /// The frame's stamp was not believed (see the module doc).
    pub bad_stamp: bool,
}

/// The clock's counts, for `daemon.json` and `observe.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClockStats {
    /// Frames seen.
    pub frames: u64,
    /// Frame ids skipped (dropped frames), summed over the stream.
    pub dropped_frames: u64,
    /// Stamps not believed (not after the previous one, or a jump past 1 s).
    pub bad_stamps: u64,
    /// Times the frame ids went back (a new publisher).
    pub stream_restarts: u64,
    /// Camera time from the first to the last frame, s.
    pub span_s: f64,
    /// Frames per second of camera time, counting dropped ones: the camera's rate.
    pub camera_rate_hz: f64,
    /// Frames per second of camera time that reached the daemon.
    pub received_rate_hz: f64,
    /// The filter's time step: median and largest, ms.
    pub dt_ms_p50: f64,
    pub dt_ms_max: f64,
}

/// The daemon's time from the frames' capture stamps.
pub struct CameraClock {
    nominal_period_ns: u64,
    /// (frame id, stamp as received) of the previous frame.
    last: Option<(u64, u64)>,
    /// Whether the previous frame's stamp was believed.
    last_believed: bool,
    /// [`Self::restart`] was called: the next frame starts a new stream.
    restart_pending: bool,
    now_ns: u64,
    periods: [u64; PERIODS],
    period_count: usize,
    dt: LatencyHistogram,
    /// Frame periods (ids) spanned since the first frame, for the rates.
    ids_spanned: u64,
    stats: ClockStats,
}

impl CameraClock {
    /// A clock whose fallback step before any period is measured is `1 / nominal_rate_hz`.
    pub fn new(nominal_rate_hz: f64) -> Self {
        let nominal_period_ns = if nominal_rate_hz.is_finite() && nominal_rate_hz > 0.0 { (1e9 / nominal_rate_hz) as u64 } else { 33_333_333 };
        Self {
            nominal_period_ns: nominal_period_ns.max(1),
            last: None,
            last_believed: true,
            restart_pending: false,
            now_ns: 0,
            periods: [0; PERIODS],
            period_count: 0,
            dt: LatencyHistogram::new(u64::MAX),
            ids_spanned: 0,
            stats: ClockStats::default(),
        }
    }

    /// The measured frame period (median of the last good ones), or the nominal one.
    pub fn period_ns(&self) -> u64 {
        if self.period_count == 0 {
            return self.nominal_period_ns;
        }
        let n = self.period_count.min(PERIODS);
        let mut p = self.periods;
        let p = &mut p[..n];
        p.sort_unstable();
        p[n / 2]
    }

    /// Camera time of the latest frame, ns since the first.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// Takes frame `frame_id` stamped `capture_time_ns`.
    pub fn tick(&mut self, frame_id: u64, capture_time_ns: u64) -> FrameTick {
        self.stats.frames += 1;
        let Some((last_id, last_stamp)) = self.last else {
            self.last = Some((frame_id, capture_time_ns));
            let tick = FrameTick { now_ns: 0, dt_s: self.period_ns() as f64 * 1e-9, dropped: 0, bad_stamp: false };
            return tick;
        };
        if std::mem::take(&mut self.restart_pending) | (frame_id <= last_id) {
            // A new publisher numbering from its own start: one period on, nothing dropped.
            self.stats.stream_restarts += 1;
            self.last = Some((frame_id, capture_time_ns));
            self.last_believed = true;
            return self.advance(self.period_ns(), 1, 0, false);
        }
        let gap = frame_id - last_id;
        let dropped = gap - 1;
        self.stats.dropped_frames += dropped;
        self.last = Some((frame_id, capture_time_ns));
        let step = capture_time_ns.checked_sub(last_stamp).filter(|&d| d > 0);
        // The ids may explain a long step (many frames dropped); nothing explains more.
        let expected = self.period_ns().saturating_mul(gap);
        let limit = MAX_STEP_NS.max(expected.saturating_mul(2));
        // After a bad stamp the next is measured from it: believed only when the step is
        // about what the ids say (a clock that jumped once is believed again from there).
        let plausible = |d: u64| if self.last_believed { d <= limit } else { d >= expected / 2 && d <= expected.saturating_mul(2) };
        let believed = step.is_some_and(plausible);
        self.last_believed = believed;
        match step {
            Some(d) if believed => {
                self.periods[self.period_count % PERIODS] = d / gap;
                self.period_count += 1;
                self.advance(d, gap, dropped, false)
            }
            _ => {
                self.stats.bad_stamps += 1;
                self.advance(self.period_ns().saturating_mul(gap), gap, dropped, true)
            }
        }
    }

    fn advance(&mut self, step_ns: u64, gap: u64, dropped: u64, bad_stamp: bool) -> FrameTick {
        let step_ns = step_ns.max(1);
        self.now_ns = self.now_ns.saturating_add(step_ns);
        self.ids_spanned += gap;
        self.dt.record_ns(step_ns);
        FrameTick { now_ns: self.now_ns, dt_s: step_ns as f64 * 1e-9, dropped, bad_stamp }
    }

    /// The stream went away: the next frame starts a new one (its step is one measured
    /// period; a gap in its id or stamp from the last frame is neither a drop nor bad).
    pub fn restart(&mut self) {
        self.restart_pending = self.last.is_some();
    }

    /// Frame ids skipped so far (cheap: for every cycle's telemetry).
    pub fn dropped_frames(&self) -> u64 {
        self.stats.dropped_frames
    }

    /// The counts and rates so far.
    pub fn stats(&self) -> ClockStats {
        let span_s = self.now_ns as f64 * 1e-9;
        let rate = |n: u64| if span_s > 0.0 { n as f64 / span_s } else { 0.0 };
        ClockStats {
            span_s,
            camera_rate_hz: rate(self.ids_spanned),
            received_rate_hz: rate(self.stats.frames.saturating_sub(1)),
            dt_ms_p50: self.dt.percentile_ns(50.0) as f64 * 1e-6,
            dt_ms_max: self.dt.max_ns() as f64 * 1e-6,
            ..self.stats.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: u64 = 33_333_333;

    #[test]
    fn time_steps_follow_the_stamps_not_the_ids_or_a_rate() {
        // A 25 Hz camera with a nominal 30 Hz configured: the steps are the camera's 40 ms.
        let mut c = CameraClock::new(30.0);
        let t0 = 1_000_000;
        c.tick(0, t0);
        let t = c.tick(1, t0 + 40_000_000);
        assert!((t.dt_s - 0.040).abs() < 1e-9, "{t:?}");
        // Every third frame dropped: a 80 ms step after frame 2, counted as one drop.
        let t = c.tick(3, t0 + 120_000_000);
        assert!((t.dt_s - 0.080).abs() < 1e-9 && t.dropped == 1, "{t:?}");
        // Jitter in the stamps is the true time, not rounded to a period.
        let t = c.tick(4, t0 + 163_000_000);
        assert!((t.dt_s - 0.043).abs() < 1e-9, "{t:?}");
        assert_eq!(t.now_ns, 163_000_000);
        let s = c.stats();
        assert_eq!((s.frames, s.dropped_frames, s.bad_stamps), (4, 1, 0));
        assert!((s.camera_rate_hz - 4.0 / 0.163).abs() < 1e-6 && (s.received_rate_hz - 3.0 / 0.163).abs() < 1e-6, "{s:?}");
    }

    #[test]
    fn bad_stamps_are_counted_and_clamped_to_the_measured_period() {
        let mut c = CameraClock::new(30.0);
        for i in 0..10 {
            c.tick(i, 7 + i * 50_000_000); // a 20 Hz camera
        }
        let before = c.now_ns();
        // Zero, backwards, equal, and a one-hour jump: each one period on, counted.
        for (id, stamp) in [(10, 0), (11, 3), (12, 3), (13, 3_600_000_000_000)] {
            let t = c.tick(id, stamp);
            assert!(t.bad_stamp, "{id}");
            assert!((t.dt_s - 0.050).abs() < 1e-9, "{t:?}");
        }
        assert_eq!(c.now_ns(), before + 4 * 50_000_000, "the clock never freezes nor jumps");
        // Good stamps again: the first step from the last bad stamp that fits the ids.
        let t = c.tick(15, 3_600_000_000_000 + 100_000_000);
        assert!(!t.bad_stamp && t.dropped == 1 && (t.dt_s - 0.1).abs() < 1e-9, "{t:?}");
        assert_eq!(c.stats().bad_stamps, 4);
    }

    #[test]
    fn a_long_gap_explained_by_dropped_ids_is_believed() {
        let mut c = CameraClock::new(30.0);
        for i in 0..5 {
            c.tick(i, i * P);
        }
        // 59 frames lost (two seconds): the ids say so, the stamps agree.
        let t = c.tick(64, 64 * P);
        assert!(!t.bad_stamp && t.dropped == 59 && (t.dt_s - 60.0 * P as f64 * 1e-9).abs() < 1e-6, "{t:?}");
    }

    #[test]
    fn ids_going_back_are_a_new_publisher_not_a_drop() {
        let mut c = CameraClock::new(30.0);
        for i in 0..5 {
            c.tick(100 + i, i * P);
        }
        let t = c.tick(0, 9);
        assert!(!t.bad_stamp && t.dropped == 0 && (t.dt_s - P as f64 * 1e-9).abs() < 1e-6, "{t:?}");
        let t = c.tick(1, 9 + P);
        assert!(!t.bad_stamp && (t.dt_s - P as f64 * 1e-9).abs() < 1e-6, "{t:?}");
        assert_eq!((c.stats().stream_restarts, c.stats().dropped_frames), (1, 0));
        // A camera that comes back after a while with its ids and stamps further on.
        c.restart();
        let t = c.tick(500, 9 + 20 * 1_000_000_000);
        assert!(!t.bad_stamp && t.dropped == 0 && (t.dt_s - P as f64 * 1e-9).abs() < 1e-6, "{t:?}");
        assert_eq!(c.stats().stream_restarts, 2);
    }
}

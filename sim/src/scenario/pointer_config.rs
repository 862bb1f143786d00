//! `[pointer]`: the operator's pointing gesture as the scenario file describes it (plain
//! data and its range checks; the gesture itself is drawn and moved by [`crate::pointer`]).

use serde::Deserialize;

/// `[pointer]`: an operator's forearm and pointing finger that enters the view from above
/// the table at `at_s`, points at what `[task]` names (the target block's centre or
/// `point_m`, at the working plane's height: the lowest cage point's), holds still for
/// `hold_s`, and withdraws. The gesture (approach direction, height, aiming error) is drawn
/// from the scenario seed within the ranges below. The hand is seen, not felt: it has no
/// collider. Only the judge knows where it aimed.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointerConfig {
    /// When the hand starts to enter, seconds of simulated time (after calibration).
    pub at_s: f64,
    /// How long it takes to reach its pointing pose, seconds.
    #[serde(default = "default_pointer_enter_s")]
    pub enter_s: f64,
    /// How long it holds still there, seconds.
    #[serde(default = "default_pointer_hold_s")]
    pub hold_s: f64,
    /// How long it takes to withdraw, seconds.
    #[serde(default = "default_pointer_enter_s")]
    pub withdraw_s: f64,
    /// Direction from the pointed-at point to the hand, about the vertical from +x
    /// (degrees; 90: the hand comes from +y), drawn in this range.
    #[serde(default = "default_pointer_azimuth")]
    pub azimuth_deg: [f64; 2],
    /// Angle of the finger above the table, degrees, drawn in this range.
    #[serde(default = "default_pointer_elevation")]
    pub elevation_deg: [f64; 2],
    /// Height of the fingertip above the working plane, metres, drawn in this range.
    #[serde(default = "default_pointer_height")]
    pub tip_height_m: [f64; 2],
    /// Largest angle between the finger's line and the line to the point meant, degrees:
    /// a person's aim (the angle is drawn in 0..this, its direction at random).
    #[serde(default = "default_pointer_aim_error")]
    pub aim_error_deg: f64,
    /// Amplitude of the hand's tremor while it holds, millimetres.
    #[serde(default = "default_pointer_tremor")]
    pub tremor_mm: f64,
    /// Albedo of the skin (finger and hand), 0..1; the sleeve is darker.
    #[serde(default = "default_pointer_shade")]
    pub shade: f64,
    /// How many times the operator points again when the robot did not react: a gesture
    /// after which the arm stays where it was (within 2 cm) for `repeat_after_s` after the
    /// hand has gone is repeated, from a new direction drawn from the seed. The simulator
    /// watches only the arm, as a person would, never the daemon's telemetry.
    #[serde(default)]
    pub repeats: u32,
    /// Pause between the hand going and the next gesture, s.
    #[serde(default = "default_pointer_repeat_after")]
    pub repeat_after_s: f64,
}

fn default_pointer_repeat_after() -> f64 {
    4.0
}

fn default_pointer_enter_s() -> f64 {
    1.0
}
fn default_pointer_hold_s() -> f64 {
    2.0
}
fn default_pointer_azimuth() -> [f64; 2] {
    [-150.0, 150.0]
}
fn default_pointer_elevation() -> [f64; 2] {
    [35.0, 70.0]
}
fn default_pointer_height() -> [f64; 2] {
    [0.08, 0.15]
}
fn default_pointer_aim_error() -> f64 {
    2.0
}
fn default_pointer_tremor() -> f64 {
    0.3
}
fn default_pointer_shade() -> f64 {
    0.7
}

impl PointerConfig {
    /// Ranges out of order or out of what a person could do: the key and the problem.
    pub(super) fn check(&self) -> Result<(), (&'static str, String)> {
        let f = |v: f64, lo: f64, hi: f64| v.is_finite() && lo <= v && v <= hi;
        if !f(self.at_s, 0.0, 3600.0) {
            return Err(("at_s", "must be 0..3600 s".into()));
        }
        for (key, v) in [("enter_s", self.enter_s), ("withdraw_s", self.withdraw_s)] {
            if !f(v, 0.05, 60.0) {
                return Err((key, "must be 0.05..60 s".into()));
            }
        }
        if !f(self.hold_s, 0.1, 600.0) {
            return Err(("hold_s", "must be 0.1..600 s (the daemon needs a steady hand for a while)".into()));
        }
        let ranges: [(&'static str, [f64; 2], f64, f64); 3] = [
            ("azimuth_deg", self.azimuth_deg, -360.0, 360.0),
            ("elevation_deg", self.elevation_deg, 10.0, 90.0),
            ("tip_height_m", self.tip_height_m, 0.02, 0.5),
        ];
        for (key, [lo, hi], min, max) in ranges {
            if !(lo.is_finite() && hi.is_finite() && min <= lo && lo <= hi && hi <= max) {
                return Err((key, format!("must be [low, high] with {min} <= low <= high <= {max}")));
            }
        }
        if !f(self.aim_error_deg, 0.0, 20.0) {
            return Err(("aim_error_deg", "must be 0..20 degrees".into()));
        }
        if !f(self.tremor_mm, 0.0, 20.0) {
            return Err(("tremor_mm", "must be 0..20 mm".into()));
        }
        if !f(self.shade, 0.0, 1.0) {
            return Err(("shade", "must be an albedo 0..1".into()));
        }
        if self.repeats > 100 {
            return Err(("repeats", "must be 0..100".into()));
        }
        if !f(self.repeat_after_s, 0.5, 600.0) {
            return Err(("repeat_after_s", "must be 0.5..600 s (the robot needs a moment to react)".into()));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use crate::scenario::Scenario;

    const POINT: &str = include_str!("../../../scenarios/point_clutter3.toml");

    #[test]
    fn the_pointing_scenario_parses_and_bad_ranges_name_the_field() {
        let s = Scenario::parse(POINT, Path::new("point.toml")).unwrap();
        assert_eq!(s.pointer.as_ref().map(|p| p.aim_error_deg), Some(2.0));
        for (from, to, field) in [
            ("elevation_deg = [35.0, 70.0]", "elevation_deg = [70.0, 35.0]", "pointer.elevation_deg"),
            ("aim_error_deg = 2.0", "aim_error_deg = -1.0", "pointer.aim_error_deg"),
            ("hold_s = 3.0", "hold_s = 0.0", "pointer.hold_s"),
            ("repeat_after_s = 4.0", "repeat_after_s = 0.0", "pointer.repeat_after_s"),
            ("at_s = 80.0", "at_s = 80.0\nfinger = 1", "finger"),
        ] {
            let err = Scenario::parse(&POINT.replace(from, to), Path::new("point.toml")).unwrap_err().to_string();
            assert!(err.contains(field), "{from} -> {to}: {err}");
        }
    }
}

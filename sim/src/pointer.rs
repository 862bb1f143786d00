//! The operator's pointing gesture (`[pointer]`, thesis ch. 4): a forearm and finger that
//! come in from above the table, point at what the task names, hold still, and go.
//!
//! The gesture is drawn once from the scenario seed: the direction the hand comes from, its
//! height, and a person's aiming error (the finger's line misses the point meant by up to
//! `aim_error_deg`). Where that line really meets the working plane is the *aim point*: what a
//! perfect pointing detector would report, and what the judge compares the daemon with. The
//! pose follows simulated time only, so runs stay deterministic; the hand has no collider.
//!
//! Frame of the hand's mesh ([`crate::render::cell_scene::pointer_mesh`]): origin at the
//! fingertip, +x back along the finger and forearm (towards the elbow), +y across the hand
//! (horizontal), +z the back of the hand.

use glam::{DAffine3, DMat3, DVec3};
use handeye_vision::rng::{SplitMix64, mix64};
use serde::{Deserialize, Serialize};

use crate::render::camera::Camera;
use crate::scenario::{PointerConfig, Scenario, s_to_ns};

/// How far back along its own axis the hand starts and ends, metres: out of the workspace.
pub const RETRACT_M: f64 = 0.6;
/// Tremor frequencies along the hand's three axes, Hz (physiological tremor is 8-12 Hz;
/// the slower one is the sway of an outstretched arm).
const TREMOR_HZ: [f64; 3] = [1.3, 9.0, 11.0];

/// What the hand is doing at a moment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PointerPhase {
    Away,
    Entering,
    Holding,
    Withdrawing,
}

/// One drawn gesture.
#[derive(Debug, Clone, PartialEq)]
pub struct PointerGesture {
    /// Fingertip while holding (mean pose), robot frame, m.
    pub tip_m: DVec3,
    /// Unit vector from the fingertip back along the finger (up and away from the point).
    pub back: DVec3,
    /// The point meant: the task's point on the working plane, m.
    pub intended_m: DVec3,
    /// Where the finger's line meets the working plane, m.
    pub aim_m: DVec3,
    /// Angle between the finger's line and the line to the point meant, degrees.
    pub aim_error_deg: f64,
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
    times_ns: [u64; 4],
    tremor_m: f64,
    tremor_phase: [f64; 3],
    rotation: DMat3,
}

impl PointerGesture {
    /// The gesture of `scenario`'s `[pointer]`, if it has one.
    pub fn of_scenario(scenario: &Scenario) -> Option<Self> {
        let cfg = scenario.pointer.as_ref()?;
        let p = scenario.indicated_point_m();
        Some(Self::draw(cfg, DVec3::from_array(p), gesture_seed(scenario.seed, 0)))
    }

    /// Draws a gesture pointing at `intended_m` (on the working plane) from `seed`, starting
    /// at `cfg.at_s`.
    pub fn draw(cfg: &PointerConfig, intended_m: DVec3, seed: u64) -> Self {
        Self::draw_at(cfg, intended_m, seed, s_to_ns(cfg.at_s))
    }

    /// When the hand has gone, ns.
    pub fn end_ns(&self) -> u64 {
        self.times_ns[3]
    }

    /// The same, starting at `at_ns`.
    pub fn draw_at(cfg: &PointerConfig, intended_m: DVec3, seed: u64, at_ns: u64) -> Self {
        let mut rng = SplitMix64::new(seed);
        let azimuth_deg = rng.range(cfg.azimuth_deg[0], cfg.azimuth_deg[1]);
        let elevation_deg = rng.range(cfg.elevation_deg[0], cfg.elevation_deg[1]);
        let height_m = rng.range(cfg.tip_height_m[0], cfg.tip_height_m[1]);
        let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        let meant = DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        let tip_m = intended_m + meant * (height_m / el.sin());
        // The person's error: the finger turned about the tip by up to aim_error_deg, in a
        // random direction across the line meant.
        let error_rad = rng.range(0.0, cfg.aim_error_deg).to_radians();
        let roll = rng.range(0.0, std::f64::consts::TAU);
        let across = meant.any_orthonormal_pair();
        let axis = across.0 * roll.cos() + across.1 * roll.sin();
        let mut back = DMat3::from_axis_angle(axis, error_rad) * meant;
        if back.z < 0.05 {
            back = meant; // never pointing upwards: a person points down at the table
        }
        let aim_m = tip_m - back * ((tip_m.z - intended_m.z) / back.z);
        let y = DVec3::Z.cross(back).normalize_or(DVec3::Y);
        let rotation = DMat3::from_cols(back, y, back.cross(y));
        let t0 = at_ns;
        let t1 = t0 + s_to_ns(cfg.enter_s);
        let t2 = t1 + s_to_ns(cfg.hold_s);
        let t3 = t2 + s_to_ns(cfg.withdraw_s);
        let tremor_phase = [rng.range(0.0, 6.3), rng.range(0.0, 6.3), rng.range(0.0, 6.3)];
        Self {
            tip_m,
            back,
            intended_m,
            aim_m,
            aim_error_deg: back.angle_between(meant).to_degrees(),
            azimuth_deg,
            elevation_deg,
            times_ns: [t0, t1, t2, t3],
            tremor_m: cfg.tremor_mm * 1e-3,
            tremor_phase,
            rotation,
        }
    }

    /// What the hand is doing at `now_ns`.
    pub fn phase(&self, now_ns: u64) -> PointerPhase {
        let [t0, t1, t2, t3] = self.times_ns;
        match now_ns {
            t if t < t0 || t >= t3 => PointerPhase::Away,
            t if t < t1 => PointerPhase::Entering,
            t if t < t2 => PointerPhase::Holding,
            _ => PointerPhase::Withdrawing,
        }
    }

    /// When the hand holds still: from, to (s of simulated time).
    pub fn hold_s(&self) -> [f64; 2] {
        [self.times_ns[1] as f64 * 1e-9, self.times_ns[2] as f64 * 1e-9]
    }

    /// The mesh's pose at `now_ns` (robot from hand), `None` while away.
    pub fn pose(&self, now_ns: u64) -> Option<DAffine3> {
        let [t0, t1, t2, t3] = self.times_ns;
        let smooth = |s: f64| s * s * (3.0 - 2.0 * s);
        let frac = |a: u64, b: u64| (now_ns.saturating_sub(a)) as f64 / (b - a).max(1) as f64;
        let back_m = match self.phase(now_ns) {
            PointerPhase::Away => return None,
            PointerPhase::Entering => RETRACT_M * (1.0 - smooth(frac(t0, t1))),
            PointerPhase::Holding => 0.0,
            PointerPhase::Withdrawing => RETRACT_M * smooth(frac(t2, t3)),
        };
        let t = now_ns as f64 * 1e-9;
        let tremor = DVec3::from_array(std::array::from_fn(|k| (std::f64::consts::TAU * TREMOR_HZ[k] * t + self.tremor_phase[k]).sin()));
        let tip = self.tip_m + self.back * back_m + self.rotation * tremor * self.tremor_m;
        Some(DAffine3::from_mat3_translation(self.rotation, tip))
    }

    /// Ground truth of the gesture as `cameras` see it.
    pub fn truth(&self, cameras: &[Camera; 2], now_ns: u64) -> PointerTruth {
        let elbow = self.tip_m + self.back * 0.3;
        let view = |c: &Camera| PointerView {
            tip_px: c.project(self.tip_m).unwrap_or([f64::NAN; 2]),
            elbow_px: c.project(elbow).unwrap_or([f64::NAN; 2]),
            aim_px: c.project(self.aim_m).unwrap_or([f64::NAN; 2]),
        };
        PointerTruth {
            phase: self.phase(now_ns),
            hold_s: self.hold_s(),
            intended_m: self.intended_m.to_array(),
            aim_m: self.aim_m.to_array(),
            aim_error_deg: self.aim_error_deg,
            tip_m: self.tip_m.to_array(),
            direction: (-self.back).to_array(),
            azimuth_deg: self.azimuth_deg,
            elevation_deg: self.elevation_deg,
            views: [view(&cameras[0]), view(&cameras[1])],
        }
    }
}

/// The seed of a scenario's `k`-th gesture (0: the first).
fn gesture_seed(scenario_seed: u64, k: u64) -> u64 {
    mix64(scenario_seed ^ 0x0050_4f49_4e54_4552 ^ k.wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

/// The person behind the gestures: points again, from a new direction, when the robot did
/// not react to a gesture (`[pointer] repeats`). Watches the arm only (where the tool is),
/// as a person would; never the daemon's telemetry.
///
/// A reaction is the arm *staying* somewhere else than where it stood while the hand held
/// (it went for the block, or back to work): a person waits while the arm moves, and when it
/// has come back to where it waited and stands there (the robot busied itself with
/// something else: a hold for a lost view, the cage visited again) and still does nothing
/// for `repeat_after_s`, points again. Only the tool's distance from that place counts, so
/// the parked arm's settling and a hold's stop (well under a millimetre) never read as a
/// reaction. Where it stood is taken as the hand begins to go, not once it has gone: a daemon
/// that sees the hand leave its views may move the arm while the hand is still withdrawing.
#[derive(Debug, Clone)]
pub struct PointerOperator {
    cfg: PointerConfig,
    intended_m: DVec3,
    scenario_seed: u64,
    /// Gestures made, the current one last.
    made: u64,
    /// Where the tool was when the current gesture's hand had gone.
    tool_at_end: Option<DVec3>,
    /// The last time the tool was away from there (more than [`REACTED_M`]), ns.
    away_ns: Option<u64>,
    /// The earlier gestures' truth, as the judge needs it.
    pub earlier: Vec<PointerGesture>,
}

/// How far the tool must be from where it stood when the hand went for the operator to see
/// that the robot is doing something, m: a person a metre away sees a move of a couple of
/// centimetres; the parked arm's settling and a hold's stop move it well under 1 mm, and the
/// smallest move the daemon makes after an answer (back from the point phase's park to the
/// calibration's) is about 12 cm.
const REACTED_M: f64 = 0.02;

impl PointerOperator {
    pub fn of_scenario(scenario: &Scenario) -> Option<Self> {
        let cfg = scenario.pointer.clone()?;
        Some(Self {
            intended_m: DVec3::from_array(scenario.indicated_point_m()),
            cfg,
            scenario_seed: scenario.seed,
            made: 1,
            tool_at_end: None,
            away_ns: None,
            earlier: Vec::new(),
        })
    }

    /// At `now_ns`, with the tool at `tool_m`: the next gesture when it is time for one
    /// (the caller makes it the current one; the old one goes to [`Self::earlier`]).
    pub fn watch(&mut self, now_ns: u64, current: &PointerGesture, tool_m: DVec3) -> Option<PointerGesture> {
        // Where the arm stood while the hand held: taken as the hand begins to go (the daemon
        // does not move it before the hand goes, but may before it has quite gone).
        if now_ns >= current.times_ns[2] && self.tool_at_end.is_none() {
            tracing::info!(gesture = self.made, t_s = now_ns as f64 * 1e-9, tool_m = ?tool_m.to_array(), "operator: the hand goes; watching the arm");
            self.tool_at_end = Some(tool_m);
        }
        if now_ns < current.end_ns() {
            return None;
        }
        let at_end = *self.tool_at_end.get_or_insert(tool_m);
        let moved_m = (tool_m - at_end).length();
        if moved_m > REACTED_M {
            if self.away_ns.is_none() {
                tracing::info!(gesture = self.made, t_s = now_ns as f64 * 1e-9, tool_m = ?tool_m.to_array(), moved_m, "operator: the robot is moving");
            }
            self.away_ns = Some(now_ns);
            return None;
        }
        // Since the hand went, or since the arm came back to where it waited.
        let quiet_since_ns = self.away_ns.unwrap_or(0).max(current.end_ns());
        if self.made > u64::from(self.cfg.repeats) || now_ns < quiet_since_ns + s_to_ns(self.cfg.repeat_after_s) {
            return None;
        }
        tracing::info!(gesture = self.made + 1, t_s = now_ns as f64 * 1e-9, tool_m = ?tool_m.to_array(), moved_m, "operator: no reaction; pointing again");
        let next = PointerGesture::draw_at(&self.cfg, self.intended_m, gesture_seed(self.scenario_seed, self.made), now_ns);
        self.made += 1;
        self.tool_at_end = None;
        self.away_ns = None;
        Some(next)
    }
}

/// The finger's axis line in one view: the images of the fingertip, of a point 0.3 m back
/// along the axis, and of the aim point (all on the line), pixels (centres at integers).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PointerView {
    pub tip_px: [f64; 2],
    pub elbow_px: [f64; 2],
    pub aim_px: [f64; 2],
}

/// Ground truth of the pointing gesture (`truth.json`, `sim.json`): for the judge only.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointerTruth {
    pub phase: PointerPhase,
    /// When the hand holds still, from and to, s.
    pub hold_s: [f64; 2],
    /// The point meant (the task's), robot frame, m.
    pub intended_m: [f64; 3],
    /// Where the finger's line meets the working plane (the answer a pointing detector
    /// should give), robot frame, m.
    pub aim_m: [f64; 3],
    pub aim_error_deg: f64,
    /// Fingertip while holding, m.
    pub tip_m: [f64; 3],
    /// Unit vector along the finger, from the tip towards the aim point.
    pub direction: [f64; 3],
    /// Where the hand came from: azimuth from +x about the vertical, and elevation, degrees.
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
    /// The axis line in the left and right views.
    pub views: [PointerView; 2],
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> PointerConfig {
        toml::from_str("at_s = 10.0\naim_error_deg = 2.0").unwrap()
    }

    #[test]
    fn the_line_meets_the_plane_at_the_aim_point_within_the_aiming_error() {
        let meant = DVec3::new(0.4, 0.02, 0.06);
        let mut misses = Vec::new();
        for seed in 0..200 {
            let g = PointerGesture::draw(&cfg(), meant, seed);
            // The aim point is on the plane and on the finger's line.
            assert!((g.aim_m.z - meant.z).abs() < 1e-12);
            assert!((g.aim_m - g.tip_m).normalize().dot(-g.back) > 1.0 - 1e-12);
            assert!(g.aim_error_deg <= 2.0 + 1e-9 && g.tip_m.z > meant.z + 0.079 && g.back.z > 0.0);
            misses.push((g.aim_m - meant).length());
        }
        // Up to 2° over a fingertip ~0.1-0.3 m from the plane along the line: mm to ~1 cm.
        let worst = misses.iter().copied().fold(0.0, f64::max);
        assert!(worst > 0.002 && worst < 0.02, "worst miss {worst} m");
    }

    #[test]
    fn the_operator_points_again_only_while_the_robot_does_not_react() {
        let text = include_str!("../../scenarios/point_clutter3.toml").replace("at_s = 80.0", "at_s = 1.0");
        let scenario = Scenario::parse(&text, std::path::Path::new("p.toml")).unwrap();
        let first = PointerGesture::of_scenario(&scenario).unwrap();
        let mut op = PointerOperator::of_scenario(&scenario).unwrap();
        let still = DVec3::new(0.18, 0.0, 0.14);
        let s = |t: f64| s_to_ns(t);
        let end = first.end_ns();
        assert_eq!(op.watch(end - 1, &first, still), None, "the hand is still there");
        assert_eq!(op.watch(end, &first, still), None, "a pause first");
        let second = op.watch(end + s(4.0), &first, still).expect("the robot did not move: point again");
        assert!(second.azimuth_deg != first.azimuth_deg, "from a new direction");
        assert_eq!(second.hold_s()[0], (end + s(4.0)) as f64 * 1e-9 + 1.0);
        // The robot moves after the second gesture and stays where it went: no third.
        let went = still + DVec3::new(0.12, 0.0, 0.04);
        assert_eq!(op.watch(second.end_ns(), &second, still), None);
        assert_eq!(op.watch(second.end_ns() + s(1.0), &second, still + DVec3::new(0.05, 0.0, 0.0)), None);
        for t in [2.0, 5.0, 20.0, 60.0] {
            assert_eq!(op.watch(second.end_ns() + s(t), &second, went), None, "the robot reacted ({t} s)");
        }
        // Without repeats, never.
        let mut once = PointerOperator::of_scenario(&Scenario::parse(&text.replace("repeats = 2 ", "repeats = 0 "), std::path::Path::new("p.toml")).unwrap()).unwrap();
        assert_eq!(once.watch(end + s(10.0), &first, still), None);
    }

    #[test]
    fn an_arm_that_settles_or_goes_away_and_comes_back_is_not_a_reaction() {
        let text = include_str!("../../scenarios/point_clutter3.toml").replace("at_s = 80.0", "at_s = 1.0");
        let scenario = Scenario::parse(&text, std::path::Path::new("p.toml")).unwrap();
        let first = PointerGesture::of_scenario(&scenario).unwrap();
        let s = |t: f64| s_to_ns(t);
        let end = first.end_ns();
        let parked = DVec3::new(0.18, 0.0, 0.14);
        // A hold's stop and the parked arm's settling: a fraction of a millimetre.
        let mut op = PointerOperator::of_scenario(&scenario).unwrap();
        assert_eq!(op.watch(end, &first, parked), None);
        assert_eq!(op.watch(end + s(1.0), &first, parked + DVec3::new(0.0004, 0.0, -0.0003)), None);
        assert!(op.watch(end + s(4.0), &first, parked + DVec3::new(0.0002, 0.0, 0.0)).is_some(), "a settling arm did not react");
        // The robot busies itself elsewhere (the cage visited again after a lost view) and
        // comes back to where it waited: the operator waits while it moves, then, the arm
        // standing still there, points again `repeat_after_s` after it came back.
        let mut op = PointerOperator::of_scenario(&scenario).unwrap();
        assert_eq!(op.watch(end, &first, parked), None);
        assert_eq!(op.watch(end + s(1.0), &first, DVec3::new(0.27, -0.10, 0.06)), None);
        assert_eq!(op.watch(end + s(6.0), &first, DVec3::new(0.45, 0.10, 0.20)), None, "still moving");
        assert_eq!(op.watch(end + s(9.0), &first, parked), None, "just back");
        let again = op.watch(end + s(13.0), &first, parked).expect("back where it waited and still: no reaction after all");
        assert!(again.azimuth_deg != first.azimuth_deg);
        // The daemon sees the hand leave its views and moves the arm while the hand is still
        // withdrawing; the arm comes back to where it stood while the hand held: no reaction.
        let mut op = PointerOperator::of_scenario(&scenario).unwrap();
        let withdrawing = first.times_ns[2];
        assert_eq!(op.watch(withdrawing, &first, parked), None);
        assert_eq!(op.watch(end - s(0.2), &first, parked + DVec3::new(0.03, 0.0, 0.01)), None);
        assert_eq!(op.watch(end, &first, parked + DVec3::new(0.05, 0.0, 0.02)), None, "moving");
        assert_eq!(op.watch(end + s(3.0), &first, parked + DVec3::new(0.05, 0.0, 0.02)), None, "away");
        assert_eq!(op.watch(end + s(5.0), &first, parked), None, "just back");
        assert!(op.watch(end + s(9.5), &first, parked).is_some(), "back where it stood while the hand held: point again");
    }

    #[test]
    fn the_hand_enters_holds_still_and_goes() {
        let mut c = cfg();
        c.tremor_mm = 0.0;
        let g = PointerGesture::draw(&c, DVec3::new(0.4, 0.0, 0.06), 7);
        let s = |t: f64| s_to_ns(t);
        assert_eq!(g.pose(s(9.9)), None);
        let entering = g.pose(s(10.5)).unwrap();
        assert_eq!(g.phase(s(10.5)), PointerPhase::Entering);
        assert!(entering.translation.z > g.tip_m.z + 0.1, "comes in from above");
        for t in [11.0, 11.7, 12.9] {
            assert!((g.pose(s(t)).unwrap().translation - g.tip_m).length() < 1e-12, "still at {t} s");
        }
        assert_eq!(g.phase(s(13.5)), PointerPhase::Withdrawing);
        assert_eq!(g.pose(s(14.01)), None);
        // The mesh's +x is the finger's back direction.
        assert!((entering.matrix3 * DVec3::X - g.back).length() < 1e-12);
    }
}

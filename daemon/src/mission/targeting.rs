//! What to grasp: the target facet (from the operator hint or the plan), the plan's other
//! grasp sites to fall back on, the operator's indicated point, and how many targets were
//! tried.

use serde::{Deserialize, Serialize};

use handeye_wire::hint::OperatorHint;

/// Where the target came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetSource {
    /// The operator clicked the facet in both views (`hint.json`).
    Hint,
    /// The grasp planner chose it.
    Plan,
}

/// The target facet and how to grasp it: from the operator hint or from the plan.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetSpec {
    pub source: TargetSource,
    /// The facet's outline in both views, tracker pixels, vertex for vertex.
    pub left_px: Vec<[f64; 2]>,
    pub right_px: Vec<[f64; 2]>,
    /// Extent of the object behind the facet along its normal: the grasp width, m.
    pub depth_m: f64,
    /// The grasp site in both views when the target was chosen, tracker pixels (`None`:
    /// the facet's centre).
    pub site_px: Option<[[f64; 2]; 2]>,
    /// The site in each target tracker's template coordinates, set once they are on the
    /// facet: the site then moves with the tracked facet.
    pub site_template: Option<[[f64; 2]; 2]>,
    /// Tool height at the grasp, robot frame, m (`None`: `servo.grasp_height_m` above the
    /// table).
    pub grasp_tool_z_m: Option<f64>,
}

impl TargetSpec {
    pub fn from_hint(h: &OperatorHint) -> Self {
        Self {
            source: TargetSource::Hint,
            left_px: h.left_px.clone(),
            right_px: h.right_px.clone(),
            depth_m: h.depth_mm * 1e-3,
            site_px: None,
            site_template: None,
            grasp_tool_z_m: None,
        }
    }
}

/// The target and its fall-backs; owned by the mission, set by the plan phase (or the hint
/// at start-up), used by acquire target, servo and grasp.
#[derive(Debug, Default)]
pub struct Targeting {
    /// What to grasp: set from the hint at start-up, or by the plan phase.
    target: Option<TargetSpec>,
    /// The operator's indicated point on the working plane, robot frame, m.
    indicated_m: Option<[f64; 3]>,
    /// The indicated point's one-sigma radius, m: 0 for a point given as a coordinate, the
    /// gesture's for a pointed one (the plan checks that it picks one block).
    indicated_sigma_m: f64,
    /// Times the operator was asked to point again because the point did not pick one block.
    repoints: u32,
    /// The last pointed point turned down for lying on no block the plan saw (x, y, m) and its
    /// sigma, m: a second point there is a block the plan does not see, not a missed aim.
    off_blocks_m: Option<([f64; 2], f64)>,
    /// The plan's other grasp sites near the indicated point, next best first: tried in turn
    /// when the target trackers cannot hold the chosen facet or it turns out not vertical.
    alternatives: Vec<TargetSpec>,
    /// Targets tried (1 when the first one served).
    attempts: u32,
    /// The target's image position (its trackers' frame origins, left u, v, right u, v) when
    /// it was acquired: how far it moved since is measured from there.
    acquired_px: Option<[f64; 4]>,
    /// Times the scene was planned again because the target moved or could not be held.
    replans: u32,
}

impl Targeting {
    /// The hint's facet is the target from the start; without one the plan chooses it.
    pub fn new(hint: Option<&OperatorHint>) -> Self {
        Self { target: hint.map(TargetSpec::from_hint), ..Self::default() }
    }

    pub fn target(&self) -> Option<&TargetSpec> {
        self.target.as_ref()
    }

    pub fn target_mut(&mut self) -> Option<&mut TargetSpec> {
        self.target.as_mut()
    }

    pub fn source(&self) -> Option<TargetSource> {
        self.target.as_ref().map(|t| t.source)
    }

    pub fn set_target(&mut self, target: TargetSpec) {
        self.target = Some(target);
    }

    /// A camera moved and is being calibrated again: a planned target and its alternatives
    /// are forgotten (planned again with the new calibration); a hint's outline in `view` is
    /// shifted by `shift_px` with the image.
    pub fn camera_moved(&mut self, view: handeye_vision::tracker::View, shift_px: [f64; 2]) {
        self.alternatives.clear();
        match &mut self.target {
            Some(t) if t.source == TargetSource::Hint => {
                let px = if view == handeye_vision::tracker::View::Left { &mut t.left_px } else { &mut t.right_px };
                for p in px.iter_mut() {
                    p[0] += shift_px[0];
                    p[1] += shift_px[1];
                }
                t.site_template = None;
            }
            _ => self.target = None,
        }
    }

    /// The plan's other grasp sites, next best first.
    pub fn set_alternatives(&mut self, alternatives: Vec<TargetSpec>) {
        self.alternatives = alternatives;
    }

    /// Makes the next alternative the target; `false` when none is left.
    pub fn advance(&mut self) -> bool {
        if self.alternatives.is_empty() {
            return false;
        }
        self.target = Some(self.alternatives.remove(0));
        true
    }

    pub fn alternatives_left(&self) -> usize {
        self.alternatives.len()
    }

    pub fn indicated_m(&self) -> Option<[f64; 3]> {
        self.indicated_m
    }

    /// A point given as a coordinate (`--point`, a re-plan's moved point keeps its sigma).
    pub fn set_indicated_m(&mut self, point_m: Option<[f64; 3]>) {
        self.indicated_m = point_m;
        if point_m.is_none() {
            self.indicated_sigma_m = 0.0;
        }
    }

    /// A point the operator pointed at, with its one-sigma radius, m.
    pub fn set_pointed_m(&mut self, point_m: [f64; 3], sigma_m: f64) {
        self.indicated_m = Some(point_m);
        self.indicated_sigma_m = sigma_m.max(0.0);
    }

    pub fn indicated_sigma_m(&self) -> f64 {
        self.indicated_sigma_m
    }

    /// Forgets a pointed point that did not pick one block, so that the operator is asked
    /// again; `false` (nothing forgotten) after `max` such times, or for a point that was not
    /// pointed.
    pub fn point_again(&mut self, max: u32) -> bool {
        if self.indicated_sigma_m <= 0.0 || self.repoints >= max {
            return false;
        }
        self.repoints += 1;
        self.indicated_m = None;
        self.indicated_sigma_m = 0.0;
        self.target = None;
        self.alternatives.clear();
        true
    }

    /// Records the indicated point as lying on no block the plan saw (before asking again);
    /// returns how far it lies from the one recorded before, m, when that is within the two
    /// points' error (3 sigma of both, at least 20 mm): the operator points at the same place
    /// again, so the plan does not see the block there.
    pub fn off_blocks_again(&mut self) -> Option<f64> {
        let point = self.indicated_m?;
        let (p, sigma) = ([point[0], point[1]], self.indicated_sigma_m);
        let before = self.off_blocks_m.replace((p, sigma));
        before.and_then(|(q, s)| {
            let apart_m = (p[0] - q[0]).hypot(p[1] - q[1]);
            (apart_m <= (3.0 * sigma.hypot(s)).max(0.02)).then_some(apart_m)
        })
    }

    pub fn repoints(&self) -> u32 {
        self.repoints
    }

    /// The target's trackers converged on it here (frame origins, left u, v, right u, v).
    pub fn set_acquired_px(&mut self, px: [f64; 4]) {
        self.acquired_px = Some(px);
    }

    pub fn acquired_px(&self) -> Option<[f64; 4]> {
        self.acquired_px
    }

    /// Whether the scene may be planned again for a lost or unusable target: the target was
    /// planned (a hint names one facet; there is nothing to choose again), there is an
    /// indicated point to choose by, and fewer than `max` re-plans were made.
    pub fn can_replan(&self, max: u32) -> bool {
        self.source() == Some(TargetSource::Plan) && self.indicated_m.is_some() && self.replans < max
    }

    /// The scene is planned again: the target and its alternatives are forgotten and the
    /// indicated point moves by `moved_m` (x, y: how far the target was last seen to have
    /// moved), so that it stays on the block.
    pub fn forget_for_replan(&mut self, moved_m: [f64; 2]) {
        self.target = None;
        self.alternatives.clear();
        self.acquired_px = None;
        self.replans += 1;
        if let Some(p) = &mut self.indicated_m {
            p[0] += moved_m[0];
            p[1] += moved_m[1];
        }
    }

    pub fn replans(&self) -> u32 {
        self.replans
    }

    /// One more target is being acquired.
    pub fn begin_attempt(&mut self) {
        self.attempts += 1;
    }

    pub fn attempts(&self) -> u32 {
        self.attempts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_pointed_point_is_forgotten_to_point_again_and_only_so_often() {
        let mut t = Targeting::default();
        // A point given as a coordinate is the operator's word: never asked again.
        t.set_indicated_m(Some([0.3, 0.0, 0.06]));
        assert!(!t.point_again(2) && t.indicated_m().is_some());
        t.set_pointed_m([0.3, 0.01, 0.06], 0.012);
        assert_eq!(t.indicated_sigma_m(), 0.012);
        t.set_alternatives(vec![TargetSpec {
            source: TargetSource::Plan,
            left_px: vec![],
            right_px: vec![],
            depth_m: 0.03,
            site_px: None,
            site_template: None,
            grasp_tool_z_m: None,
        }]);
        assert!(t.point_again(2));
        assert!(t.indicated_m().is_none() && t.target().is_none() && t.alternatives_left() == 0 && t.indicated_sigma_m() == 0.0);
        t.set_pointed_m([0.3, 0.01, 0.06], 0.012);
        assert!(t.point_again(2) && t.repoints() == 2);
        t.set_pointed_m([0.3, 0.01, 0.06], 0.012);
        assert!(!t.point_again(2), "the third ambiguous point ends the run");
        assert_eq!(t.indicated_m(), Some([0.3, 0.01, 0.06]));
    }

    #[test]
    fn a_second_point_on_no_block_at_the_same_place_is_told_from_a_missed_aim() {
        let mut t = Targeting::default();
        t.set_pointed_m([0.30, 0.10, 0.06], 0.005);
        assert_eq!(t.off_blocks_again(), None, "the first is a missed aim: ask again");
        assert!(t.point_again(2));
        // Pointed again 40 mm away (sigmas 5 and 4 mm: 3 sigma of both is 19 mm, the floor 20):
        // another missed aim.
        t.set_pointed_m([0.34, 0.10, 0.06], 0.004);
        assert_eq!(t.off_blocks_again(), None);
        assert!(t.point_again(2));
        // Then 12 mm from that one: the same place twice, a block the plan does not see.
        t.set_pointed_m([0.34, 0.112, 0.06], 0.004);
        let apart = t.off_blocks_again().expect("the same place");
        assert!((apart - 0.012).abs() < 1e-9, "{apart}");
    }

}

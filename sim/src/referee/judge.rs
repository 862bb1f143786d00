//! The success rule, judged from ground truth: the target block lifted at least `lift_mm`
//! above where it rested, and kept there for `hold_s` seconds without a break.

use serde::{Deserialize, Serialize};

use crate::scenario::SuccessRule;

/// How the run stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Not (yet) lifted long enough.
    Pending,
    /// Lifted and held; `at_ns` is when the hold time was completed.
    Success { at_ns: u64 },
    /// The scenario's time-out passed first.
    TimedOut,
}

/// Tracks the target's height over time.
#[derive(Debug, Clone)]
pub struct SuccessJudge {
    rest_z_m: f64,
    lift_m: f64,
    hold_ns: u64,
    timeout_ns: u64,
    lifted_since_ns: Option<u64>,
    /// Highest lift seen so far, metres.
    pub max_lift_m: f64,
    verdict: Verdict,
}

impl SuccessJudge {
    pub fn new(rule: &SuccessRule, rest_z_m: f64) -> Self {
        Self {
            rest_z_m,
            lift_m: rule.lift_mm * 1e-3,
            hold_ns: crate::scenario::s_to_ns(rule.hold_s),
            timeout_ns: crate::scenario::s_to_ns(rule.timeout_s),
            lifted_since_ns: None,
            max_lift_m: 0.0,
            verdict: Verdict::Pending,
        }
    }

    /// Feeds the target's current height (of its body origin) at `now_ns`.
    pub fn observe(&mut self, now_ns: u64, target_z_m: f64) -> Verdict {
        if self.verdict != Verdict::Pending {
            return self.verdict;
        }
        let lift = target_z_m - self.rest_z_m;
        self.max_lift_m = self.max_lift_m.max(lift);
        if lift >= self.lift_m {
            let since = *self.lifted_since_ns.get_or_insert(now_ns);
            if now_ns - since >= self.hold_ns {
                self.verdict = Verdict::Success { at_ns: now_ns };
            }
        } else {
            self.lifted_since_ns = None;
        }
        if self.verdict == Verdict::Pending && now_ns >= self.timeout_ns {
            self.verdict = Verdict::TimedOut;
        }
        self.verdict
    }

    pub fn verdict(&self) -> Verdict {
        self.verdict
    }

    /// How long the target has been held lifted so far, seconds.
    pub fn held_s(&self, now_ns: u64) -> f64 {
        self.lifted_since_ns.map_or(0.0, |t| (now_ns - t) as f64 * 1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn needs_an_unbroken_hold_above_the_lift_height() {
        let rule = SuccessRule { lift_mm: 50.0, hold_s: 2.0, timeout_s: 10.0 };
        let mut j = SuccessJudge::new(&rule, 0.02);
        let ms = 1_000_000u64;
        assert_eq!(j.observe(0, 0.02), Verdict::Pending);
        assert_eq!(j.observe(100 * ms, 0.075), Verdict::Pending);
        // Dips below the line: the hold starts again.
        assert_eq!(j.observe(1500 * ms, 0.06), Verdict::Pending);
        assert_eq!(j.observe(1600 * ms, 0.075), Verdict::Pending);
        assert_eq!(j.observe(3500 * ms, 0.075), Verdict::Pending);
        assert_eq!(j.observe(3600 * ms, 0.075), Verdict::Success { at_ns: 3600 * ms });
        // Latched.
        assert_eq!(j.observe(3700 * ms, 0.0), Verdict::Success { at_ns: 3600 * ms });

        let mut j = SuccessJudge::new(&rule, 0.02);
        assert_eq!(j.observe(10_000 * ms, 0.02), Verdict::TimedOut);
    }
}

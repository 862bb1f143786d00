//! What a batch's runs gave and how they add up: the runs (`Job`, `Outcome`), their grouping
//! by phase and failure kind into the batch result, and the table printed for it. Pure: no
//! processes, no files.

use std::collections::BTreeMap;
use std::path::PathBuf;

use handeye_wire::report::{Failure, FailureKind};

use crate::cli::report::{holds_brief, loss_text, BatchGroup, BatchResult, FailedRun, FailureGroup, GroupRun, JudgedTallies, RunDetail, RunSummary};

/// One run to make.
#[derive(Debug, Clone)]
pub(super) struct Job {
    pub(super) scenario: PathBuf,
    pub(super) name: String,
    pub(super) seed: u64,
    pub(super) out: Option<PathBuf>,
}

/// What one run gave.
#[derive(Debug, Clone)]
pub(super) struct Outcome {
    pub(super) job: Job,
    pub(super) success: bool,
    /// The working phase the run got to (`run` when `handeye run` itself failed).
    pub(super) phase: String,
    /// Why it failed (`None` when it lifted).
    pub(super) failure: Option<Failure>,
    pub(super) servo_steps: Option<f64>,
    pub(super) wall_s: f64,
    /// What `handeye run --json` printed (`None`: nothing usable).
    pub(super) summary: Option<RunSummary>,
}

impl Outcome {
    pub(super) fn reason(&self) -> Option<&str> {
        self.failure.as_ref().map(|f| f.detail.as_str())
    }

    /// The daemon refused the task (its plan found no grasp on the pointed block).
    pub(super) fn refused(&self) -> bool {
        self.failure.as_ref().is_some_and(|f| f.kind == FailureKind::Refused)
    }

    /// The daemon went for a target: it lifted, or got past planning.
    pub(super) fn attempted(&self) -> bool {
        self.success || ["acquire_target", "servo", "grasp", "lift", "done"].contains(&self.phase.as_str())
    }

    /// The simulator's judge: the target has a grasp the rules allow (`None`: not judged).
    pub(super) fn graspable(&self) -> Option<bool> {
        self.summary.as_ref().and_then(|s| s.target_graspable)
    }
}

/// Successes over graspable targets, right and wrong refusals, attempts on ungraspable ones.
pub(super) fn judge_tallies(outcomes: &[&Outcome]) -> JudgedTallies {
    let mut t = JudgedTallies::default();
    for o in outcomes {
        match o.graspable() {
            Some(true) => {
                t.graspable_runs += 1;
                t.graspable_successes += usize::from(o.success);
                t.wrong_refusals += usize::from(o.refused());
            }
            Some(false) => {
                t.ungraspable_runs += 1;
                t.correct_refusals += usize::from(o.refused());
                t.attempts_on_ungraspable += usize::from(o.attempted());
            }
            None => t.unjudged_runs += 1,
        }
    }
    let rate = |k: usize, n: usize| (n > 0).then(|| k as f64 / n as f64);
    t.graspable_success_rate = rate(t.graspable_successes, t.graspable_runs);
    t.correct_refusal_rate = rate(t.correct_refusals, t.ungraspable_runs);
    t
}

pub(super) fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// Counts and medians over `outcomes`; failures grouped by the phase they happened in and
/// their kind.
pub(super) fn group(outcomes: &[&Outcome], wall_s: Option<f64>) -> BatchGroup {
    let runs = outcomes.len();
    let successes = outcomes.iter().filter(|o| o.success).count();
    let mut groups: BTreeMap<(String, FailureKind), Vec<GroupRun>> = BTreeMap::new();
    for o in outcomes {
        if let Some(f) = &o.failure {
            groups.entry((f.phase.clone(), f.kind)).or_default().push(GroupRun { run: format!("{}#{}", o.job.name, o.job.seed), reason: f.detail.clone() });
        }
    }
    let mut failures: BTreeMap<String, BTreeMap<FailureKind, usize>> = BTreeMap::new();
    for ((phase, kind), runs) in &groups {
        failures.entry(phase.clone()).or_default().insert(*kind, runs.len());
    }
    BatchGroup {
        runs,
        successes,
        success_rate: if runs > 0 { successes as f64 / runs as f64 } else { 0.0 },
        failures,
        failure_list: groups.into_iter().map(|((phase, kind), runs)| FailureGroup { phase, kind, count: runs.len(), runs }).collect(),
        median_servo_steps: median(outcomes.iter().filter(|o| o.success).filter_map(|o| o.servo_steps).collect()),
        median_run_wall_s: median(outcomes.iter().map(|o| o.wall_s).collect()),
        wall_s,
        judged: judge_tallies(outcomes),
    }
}

pub(super) fn summarise(outcomes: &[Outcome], wall_s: f64, daemon_config: Option<String>) -> BatchResult {
    let all: Vec<&Outcome> = outcomes.iter().collect();
    let mut names: Vec<&str> = outcomes.iter().map(|o| o.job.name.as_str()).collect();
    names.dedup();
    BatchResult {
        all: group(&all, Some(wall_s)),
        scenarios: names.iter().map(|n| (n.to_string(), group(&outcomes.iter().filter(|o| o.job.name == *n).collect::<Vec<_>>(), None))).collect(),
        failed_runs: outcomes
            .iter()
            .filter_map(|o| {
                let failure = o.failure.clone()?;
                Some(FailedRun { scenario: o.job.name.clone(), seed: o.job.seed, phase: o.phase.clone(), reason: failure.detail.clone(), failure })
            })
            .collect(),
        runs_detail: outcomes.iter().map(|o| RunDetail { scenario: o.job.name.clone(), seed: o.job.seed, summary: o.summary.clone(), wall_s: o.wall_s }).collect(),
        daemon_config,
    }
}

pub(super) fn table(report: &BatchResult) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let f = |v: Option<f64>, unit: &str| v.map_or("-".to_string(), |x| format!("{x:.1}{unit}"));
    let _ = writeln!(s, "{:<24} {:>5} {:>9} {:>8} {:>12} {:>10}", "scenario", "runs", "lifted", "rate", "servo steps", "run wall");
    let row = |s: &mut String, name: &str, g: &BatchGroup| {
        let _ = writeln!(
            s,
            "{:<24} {:>5} {:>9} {:>7.0}% {:>12} {:>10}",
            name,
            g.runs,
            g.successes,
            100.0 * g.success_rate,
            f(g.median_servo_steps, ""),
            f(g.median_run_wall_s, " s")
        );
    };
    for (name, g) in &report.scenarios {
        row(&mut s, name, g);
    }
    row(&mut s, "all", &report.all);
    let j = &report.all.judged;
    if j.graspable_runs + j.ungraspable_runs > 0 {
        let pct = |r: Option<f64>| r.map_or("-".to_string(), |r| format!("{:.0}%", 100.0 * r));
        let _ = writeln!(
            s,
            "\ngraspable targets:   {:>3} runs, {} lifted ({}), {} wrong refusals",
            j.graspable_runs,
            j.graspable_successes,
            pct(j.graspable_success_rate),
            j.wrong_refusals
        );
        let _ = writeln!(
            s,
            "ungraspable targets: {:>3} runs, {} correct refusals ({}), {} attempts",
            j.ungraspable_runs,
            j.correct_refusals,
            pct(j.correct_refusal_rate),
            j.attempts_on_ungraspable
        );
        if j.unjudged_runs > 0 {
            let _ = writeln!(s, "not judged (no simulator report): {} runs", j.unjudged_runs);
        }
    }
    pointing_lines(&mut s, report);
    if !report.all.failure_list.is_empty() {
        let _ = writeln!(s, "\nfailures by phase and kind:");
        for g in &report.all.failure_list {
            let runs: Vec<&str> = g.runs.iter().map(|r| r.run.as_str()).collect();
            let _ = writeln!(s, "  {:>3} x {}: {} ({})", g.count, g.phase, g.kind, runs.join(", "));
            for r in &g.runs {
                let _ = writeln!(s, "          {}: {}", r.run, r.reason);
            }
        }
    }
    s.push_str(&holds_table(report));
    let _ = writeln!(s, "\nwall time: {:.1} s in all; median servo steps over the runs that lifted; run wall: median per run", report.all.wall_s.unwrap_or(0.0));
    s
}

/// The runs in which the daemon watched the operator's hand (issue 19): how many gestures it
/// answered, whether it went for the block pointed at, how far its point was from where the
/// hand really aimed, and per run what happened.
fn pointing_lines(s: &mut String, report: &BatchResult) {
    use std::fmt::Write;
    let runs: Vec<(&RunDetail, &crate::cli::report::RunPointing)> =
        report.runs_detail.iter().filter_map(|r| Some((r, r.summary.as_ref()?.pointing.as_ref()?))).collect();
    if runs.is_empty() {
        return;
    }
    let answered: Vec<_> = runs.iter().filter(|(_, p)| p.indicated_m.is_some()).collect();
    let chose = |want: bool| runs.iter().filter(|(_, p)| p.chose_pointed == Some(want)).count();
    let mut errors: Vec<f64> = answered.iter().filter_map(|(_, p)| p.error_mm).collect();
    errors.sort_by(f64::total_cmp);
    let rank = |q: f64| (!errors.is_empty()).then(|| errors[((q * errors.len() as f64).ceil() as usize).clamp(1, errors.len()) - 1]);
    let mm = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1} mm"));
    let _ = writeln!(
        s,
        "\npointing: {} runs watched the hand, {} answered ({} gestures refused before); went for the pointed block in {}, another block in {}; point off the hand's aim: median {}, p90 {}, max {}",
        runs.len(),
        answered.len(),
        runs.iter().map(|(_, p)| p.refusals.len()).sum::<usize>(),
        chose(true),
        chose(false),
        mm(rank(0.5)),
        mm(rank(0.9)),
        mm(errors.last().copied())
    );
    for (r, p) in &runs {
        let what = match (p.indicated_m, p.chose_pointed) {
            (Some(_), Some(true)) => format!("answered {} off, went for the pointed block '{}'", mm(p.error_mm), p.pointed_block.as_deref().unwrap_or("?")),
            (Some(_), Some(false)) => format!("answered {} off, went for ANOTHER block than '{}'", mm(p.error_mm), p.pointed_block.as_deref().unwrap_or("?")),
            (Some(_), None) => format!("answered {} off, no block targeted", mm(p.error_mm)),
            (None, _) => "not answered".to_string(),
        };
        let refused = if p.refusals.is_empty() { String::new() } else { format!("; refused first: {}", p.refusals.join("; ")) };
        let _ = writeln!(s, "  {}#{}: {what}{refused}", r.scenario, r.seed);
    }
}

/// The runs in which the arm held for lost trackers: each loss, its search and how it ended
/// (issue 18); empty when no arm held.
fn holds_table(report: &BatchResult) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    for r in &report.runs_detail {
        let Some(h) = r.summary.as_ref().and_then(|s| s.recovery.as_ref()) else { continue };
        let Some(brief) = holds_brief(h) else { continue };
        if s.is_empty() {
            let _ = writeln!(s, "\nholds for lost trackers:");
        }
        let _ = writeln!(s, "  {}#{}: {brief}", r.scenario, r.seed);
        for l in &h.losses {
            let _ = writeln!(s, "          {}", loss_text(l));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(seed: u64, failure: Option<(&str, FailureKind, &str)>, steps: Option<f64>) -> Outcome {
        Outcome {
            job: Job { scenario: PathBuf::from("c.toml"), name: "c".into(), seed, out: None },
            success: failure.is_none(),
            phase: failure.map_or("done", |f| f.0).into(),
            failure: failure.map(|(phase, kind, detail)| Failure::new(phase, kind, detail)),
            servo_steps: steps,
            wall_s: 40.0 + seed as f64,
            summary: None,
        }
    }

    #[test]
    fn the_summary_counts_failures_by_phase_and_kind() {
        let not_converged = |steps| format!("servo: not converged after 90 s ({steps} steps)");
        let (c2, c4) = (not_converged(60), not_converged(61));
        let runs = [
            outcome(1, None, Some(3.0)),
            outcome(2, Some(("servo", FailureKind::NotConverged, &c2)), Some(60.0)),
            outcome(3, None, Some(5.0)),
            outcome(4, Some(("servo", FailureKind::NotConverged, &c4)), None),
            outcome(5, Some(("plan", FailureKind::NoGraspSite, "plan: no grasp site within 60 mm of the indicated point (the nearest is 75 mm away)")), None),
            // Same phase, another kind: a group of its own, whatever the words.
            outcome(6, Some(("servo", FailureKind::TrackerLost, "servo: not converged: the target tracker was lost")), None),
        ];
        let r = summarise(&runs, 210.0, None);
        assert_eq!((r.all.runs, r.all.successes), (6, 2));
        assert!((r.all.success_rate - 2.0 / 6.0).abs() < 1e-12);
        assert_eq!(r.all.failures["servo"][&FailureKind::NotConverged], 2);
        assert_eq!(r.all.failures["servo"][&FailureKind::TrackerLost], 1);
        assert_eq!(r.all.failures["plan"].len(), 1);
        // One group per (phase, kind), with each run's reason in full.
        assert_eq!(r.all.failure_list.len(), 3);
        let servo = r.all.failure_list.iter().find(|g| g.phase == "servo" && g.kind == FailureKind::NotConverged).unwrap();
        assert_eq!(servo.count, 2);
        assert_eq!(servo.runs, vec![GroupRun { run: "c#2".into(), reason: c2.clone() }, GroupRun { run: "c#4".into(), reason: c4.clone() }]);
        // Median servo steps over the runs that lifted only; wall times over all.
        assert_eq!(r.all.median_servo_steps, Some(4.0));
        assert_eq!(r.all.median_run_wall_s, Some(43.5));
        assert_eq!(r.all.wall_s, Some(210.0));
        assert_eq!(r.failed_runs.len(), 4);
        assert_eq!(r.failed_runs[0].reason, c2);
        assert_eq!(r.scenarios["c"].runs, 6);
        assert_eq!(r.scenarios["c"].wall_s, None);
        assert_eq!(r.runs_detail.len(), 6);
        let t = table(&r);
        assert!(t.contains("  2 x servo: not_converged (c#2, c#4)"), "{t}");
        assert!(t.contains(&format!("c#4: {c4}")), "{t}");
        assert!(t.contains("  1 x servo: tracker_lost (c#6)"), "{t}");
        assert!(t.contains("33%"), "{t}");
    }

    /// A run whose target the simulator judged graspable or not, and how it ended.
    fn judged(seed: u64, graspable: bool, end: &str) -> Outcome {
        let failure = match end {
            "lifted" => None,
            "refused" => Some(("plan", FailureKind::Refused, "plan: refused: the pointed block has no graspable facet pair: its top edges slope 34°, more than 30°")),
            "no_site" => Some(("plan", FailureKind::NoGraspSite, "plan: no grasp site (0 facets; rejected: none found)")),
            "servo" => Some(("servo", FailureKind::NotConverged, "servo: not converged")),
            "grasp" => Some(("grasp", FailureKind::GraspLost, "grasp: the jaws closed on nothing")),
            other => panic!("{other}"),
        };
        let mut o = outcome(seed, failure, None);
        let mut summary = crate::cli::report::tests::summary();
        summary.target_graspable = Some(graspable);
        o.summary = Some(summary);
        o
    }

    #[test]
    fn refusals_are_tallied_apart_from_failures_by_what_the_judge_says() {
        let runs = [
            judged(1, true, "lifted"),
            judged(2, true, "lifted"),
            judged(3, true, "refused"), // a wrong refusal
            judged(4, true, "servo"),   // an ordinary failure
            judged(5, false, "refused"), // a correct refusal
            judged(6, false, "refused"),
            judged(7, false, "grasp"),   // an attempt on an ungraspable target
            judged(8, false, "no_site"), // not seen: neither a refusal nor an attempt
            outcome(9, Some(("run", FailureKind::Process, "handeye run gave no result")), None),
        ];
        let r = summarise(&runs, 100.0, None);
        let j = &r.all.judged;
        assert_eq!((j.graspable_runs, j.graspable_successes, j.wrong_refusals), (4, 2, 1));
        assert_eq!(j.graspable_success_rate, Some(0.5));
        assert_eq!((j.ungraspable_runs, j.correct_refusals, j.attempts_on_ungraspable), (4, 2, 1));
        assert_eq!(j.correct_refusal_rate, Some(0.5));
        assert_eq!(j.unjudged_runs, 1);
        // The old keys stay as they were: successes over every run.
        assert_eq!((r.all.runs, r.all.successes), (9, 2));
        let json = serde_json::to_value(&r).unwrap();
        for key in ["graspable_success_rate", "correct_refusals", "wrong_refusals", "attempts_on_ungraspable", "success_rate"] {
            assert!(json.get(key).is_some(), "{key} missing from the batch JSON");
        }
        assert_eq!(json["scenarios"]["c"]["correct_refusals"], 2);
        let t = table(&r);
        assert!(t.contains("graspable targets:     4 runs, 2 lifted (50%), 1 wrong refusals"), "{t}");
        assert!(t.contains("ungraspable targets:   4 runs, 2 correct refusals (50%), 1 attempts"), "{t}");
        assert!(t.contains("3 x plan: refused (c#3, c#5, c#6)"), "{t}");
    }

    #[test]
    fn the_table_names_each_loss_its_search_and_how_it_ended() {
        let mut held = outcome(7, None, Some(4.0));
        held.summary = Some(crate::cli::report::tests::summary());
        let mut calm = outcome(8, None, Some(4.0));
        calm.summary = Some(crate::cli::report::RunSummary { recovery: Some(Default::default()), ..crate::cli::report::tests::summary() });
        let t = table(&summarise(&[held, calm], 10.0, None));
        assert!(t.contains("holds for lost trackers:\n  c#7: 1 loss, 1 recovered, held 1.25 s\n"), "{t}");
        assert!(t.contains("servo, frame 812: target tracker (left view) lost: support 0.21 below 0.35; held 1.25 s, 3 search passes, 1 relapse; recovered"), "{t}");
        assert!(!t.contains("c#8"), "a run that never held is not listed\n{t}");
    }

    #[test]
    fn medians() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(vec![f64::NAN]), None);
    }
}

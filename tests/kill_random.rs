//! Processes killed at random (issue 21, item 2): a seed picks one of the closed loop's
//! processes (simulator, daemon) or the camera chain's (camera, record, monitor) and a moment,
//! the case SIGKILLs it, and checks that every survivor noticed within its bound (500 ms for a
//! publisher gone, the daemon's 100 ms stale-frame stop, the arm's 200 ms watchdog), that the
//! arm never moved after it had stopped, and that the killed process starts again in the
//! same domain (no stale shared memory in the way). The harness is `tests/kill_support/`.
//!
//! `make test` runs one seed per kind of process; `make kill` runs the 50-seed long run and
//! prints the table BENCHMARKS.md keeps ("Random kills").

mod e2e_support;
mod kill_support;
mod wire_support;

use e2e_support::one_at_a_time;
use kill_support::{run_case, table, CaseResult, Plan};

/// Runs the plans one after another (each loop wants the machine to itself) and fails with
/// every case that broke a rule.
fn run_all(plans: &[Plan]) -> Vec<CaseResult> {
    let _one = one_at_a_time();
    let mut results = Vec::new();
    for (i, plan) in plans.iter().enumerate() {
        let r = run_case(*plan);
        eprintln!("[{}/{}] {}", i + 1, plans.len(), r.describe());
        results.push(r);
    }
    results
}

fn assert_all_passed(results: &[CaseResult]) {
    let failed: Vec<String> =
        results.iter().filter(|r| !r.violations().is_empty()).map(|r| format!("{}\n  -> {}", r.describe(), r.violations().join("; "))).collect();
    assert!(failed.is_empty(), "{} of {} case(s) broke a rule:\n{}\n\n{}", failed.len(), results.len(), failed.join("\n"), table(results));
}

#[test]
fn killing_each_kind_of_process_once_leaves_the_arm_stopped_and_the_domain_usable() {
    let plans = Plan::one_per_victim(0);
    let results = run_all(&plans);
    eprintln!("{}", table(&results));
    assert_all_passed(&results);
}

/// The long run: 50 seeds (`make kill`; about half an hour on a loaded 2-core machine).
#[test]
#[ignore = "long run (50 seeds): make kill"]
fn fifty_random_kills() {
    // HANDEYE_KILL_SEEDS: a count (seeds 0..N) or one range A-B (inclusive), to rerun a case.
    let seeds = std::env::var("HANDEYE_KILL_SEEDS").unwrap_or_else(|_| "50".into());
    let range = match seeds.split_once('-') {
        Some((a, b)) => a.parse().expect("HANDEYE_KILL_SEEDS: A-B")..=b.parse().expect("HANDEYE_KILL_SEEDS: A-B"),
        None => 0..=seeds.parse::<u64>().expect("HANDEYE_KILL_SEEDS: a count or A-B").saturating_sub(1),
    };
    let plans: Vec<Plan> = range.map(Plan::from_seed).collect();
    let results = run_all(&plans);
    println!("{}", table(&results));
    assert_all_passed(&results);
}

#[test]
fn a_seed_always_makes_the_same_plan_and_the_short_run_kills_every_kind() {
    let a = Plan::from_seed(7);
    let b = Plan::from_seed(7);
    assert_eq!((a.victim, a.moment), (b.victim, b.moment));
    let short = Plan::one_per_victim(0);
    for v in kill_support::Victim::available() {
        assert_eq!(short.iter().filter(|p| p.victim == v).count(), 1, "{v:?} in {short:?}");
    }
}

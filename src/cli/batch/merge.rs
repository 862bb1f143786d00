//! `handeye batch merge DIR...`: the shards of one batch (`handeye batch --shard K/N --out
//! DIR`) combined into the table, batch.json and index.html that the unsharded batch would
//! have written. The runs are put back in the batch's order (scenario, then seed) and summed
//! up by the same code as a batch's, so medians, failure groups and their order agree.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;

use super::shard::{BatchFile, BatchSpec};
use super::summary::{summarise, Job, Outcome};
use crate::cli::report::read_report;

/// Combine the shards of a batch into one report.
///
/// Each DIR is the --out folder of one `handeye batch ... --shard K/N` (an unsharded batch's
/// folder counts as the one shard 1/1). Their batch.json files must describe the same batch:
/// the same scenarios (by name and file content), the same seed list and the same `handeye
/// run` flags (daemon config, hint, time-out); no shard may come twice, and together they
/// must hold every run of the batch (else an error that names the missing shards; with
/// --allow-partial the runs there are are reported, and the missing ones listed on stderr).
///
/// Prints the table (or with --json the object) that `handeye batch` prints, and with --out
/// writes batch.json and index.html as the unsharded batch would, with each run's folder
/// (its report and page) copied from its shard (hard links where the file system allows).
/// The merged wall time (`wall_s`) is the longest shard's: shards run side by side.
///
/// Examples:
///   handeye batch merge shared/shard-1 shared/shard-2 shared/shard-3
///   handeye batch merge shared/shard-* --out shared/batch
///   handeye batch merge shared/shard-* --allow-partial --json
#[derive(Args)]
#[command(verbatim_doc_comment)]
pub struct MergeArgs {
    /// The shards' report folders (each with a batch.json).
    #[arg(required = true, value_name = "DIR")]
    dirs: Vec<PathBuf>,
    /// Write the merged batch.json, index.html and run folders here.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print one JSON object instead of the table (as `handeye batch --json`).
    #[arg(long)]
    json: bool,
    /// Report the runs there are when shards are missing, instead of refusing.
    #[arg(long)]
    allow_partial: bool,
}

/// One shard as read from its folder.
pub(super) struct ShardDir {
    pub(super) dir: PathBuf,
    pub(super) file: BatchFile,
}

/// What differs between two shards' specs, in words (`None`: the same batch).
fn spec_difference(a: &BatchSpec, b: &BatchSpec) -> Option<String> {
    let names = |s: &BatchSpec| s.scenarios.iter().map(|c| c.name.clone()).collect::<Vec<_>>();
    if names(a) != names(b) {
        return Some(format!("scenarios {:?}, not {:?}", names(b), names(a)));
    }
    if let Some((x, y)) = a.scenarios.iter().zip(&b.scenarios).find(|(x, y)| x.content_fnv1a64 != y.content_fnv1a64) {
        return Some(format!("scenario {} from another file ({} hashes to {}, not {} as {})", x.name, y.file, y.content_fnv1a64, x.content_fnv1a64, x.file));
    }
    if a.seeds != b.seeds {
        let range = |s: &BatchSpec| format!("{} seeds from {}", s.seeds.len(), s.seeds.first().map_or("-".into(), |x| x.to_string()));
        return Some(format!("seed list {}, not {}", range(b), range(a)));
    }
    if a.run_flags != b.run_flags {
        return Some(format!("run flags {:?}, not {:?}", b.run_flags.join(" "), a.run_flags.join(" ")));
    }
    let count = |s: &BatchSpec| s.shard.map_or(1, |s| s.count);
    if count(a) != count(b) {
        return Some(format!("one of {} shards, not of {}", count(b), count(a)));
    }
    None
}

/// Checks that `shards` are shares of one batch and puts their runs back in the batch's
/// order; returns the runs and the batch's spec as the
/// unsharded batch would have written it.
pub(super) fn combine(shards: &[ShardDir], allow_partial: bool, out: Option<&Path>) -> Result<(Vec<Outcome>, BatchSpec)> {
    let Some(first) = shards.first() else { bail!("no shard folders given") };
    let spec = &first.file.batch;
    let mut by_index: BTreeMap<u64, &Path> = BTreeMap::new();
    for s in shards {
        if let Some(why) = spec_difference(spec, &s.file.batch) {
            bail!("{}: not a shard of the same batch as {}: {why}", s.dir.display(), first.dir.display());
        }
        let index = s.file.batch.shard.map_or(1, |s| s.index);
        if let Some(other) = by_index.insert(index, &s.dir) {
            bail!("{} and {} are both shard {index} of {}", other.display(), s.dir.display(), spec.shard.map_or(1, |s| s.count));
        }
    }
    // Each run, from the shard that should have run it.
    let mut runs: BTreeMap<(String, u64), (&ShardDir, usize)> = BTreeMap::new();
    for s in shards {
        let own = s.file.batch.own_seeds();
        for (i, d) in s.file.result.runs_detail.iter().enumerate() {
            if !own.contains(&d.seed) {
                bail!("{}: run {}#{} is not one of this shard's seeds", s.dir.display(), d.scenario, d.seed);
            }
            if runs.insert((d.scenario.clone(), d.seed), (s, i)).is_some() {
                bail!("{}: run {}#{} comes twice", s.dir.display(), d.scenario, d.seed);
            }
        }
    }
    let mut outcomes = Vec::new();
    let mut missing = Vec::new();
    for scenario in &spec.scenarios {
        for &seed in &spec.seeds {
            let Some(&(s, i)) = runs.get(&(scenario.name.clone(), seed)) else {
                missing.push(format!("{}#{seed}", scenario.name));
                continue;
            };
            outcomes.push(outcome(s, i, Path::new(&scenario.file), out)?);
        }
    }
    if !missing.is_empty() {
        let count = spec.shard.map_or(1, |s| s.count);
        let absent: Vec<String> = (1..=count).filter(|k| !by_index.contains_key(k)).map(|k| format!("{k}/{count}")).collect();
        let what = format!(
            "{} of {} runs missing ({}{}); shards absent: {}",
            missing.len(),
            missing.len() + outcomes.len(),
            missing.iter().take(10).cloned().collect::<Vec<_>>().join(", "),
            if missing.len() > 10 { ", ..." } else { "" },
            if absent.is_empty() { "none (a shard was interrupted)".to_string() } else { absent.join(", ") }
        );
        if !allow_partial {
            bail!("incomplete batch: {what}; merge the rest too, or pass --allow-partial");
        }
        eprintln!("batch merge: partial: {what}");
    }
    Ok((outcomes, BatchSpec { shard: None, ..spec.clone() }))
}

/// Run `i` of shard `s` as the batch that ran it saw it.
fn outcome(s: &ShardDir, i: usize, scenario: &Path, out: Option<&Path>) -> Result<Outcome> {
    let d = &s.file.result.runs_detail[i];
    let failed = s.file.result.failed_runs.iter().find(|f| f.scenario == d.scenario && f.seed == d.seed);
    let success = failed.is_none();
    if d.summary.as_ref().is_some_and(|sum| sum.success != success) {
        bail!("{}: run {}#{} is {} in failed_runs but its summary says success={}", s.dir.display(), d.scenario, d.seed, if success { "absent" } else { "present" }, !success);
    }
    Ok(Outcome {
        job: Job { scenario: scenario.to_path_buf(), name: d.scenario.clone(), seed: d.seed, out: out.map(|o| o.join(&d.scenario).join(format!("seed-{}", d.seed))) },
        success,
        phase: failed.map_or_else(|| "done".to_string(), |f| f.phase.clone()),
        failure: failed.map(|f| f.failure.clone()),
        servo_steps: d.summary.as_ref().and_then(|s| s.servo_steps).map(f64::from),
        wall_s: d.wall_s,
        summary: d.summary.clone(),
    })
}

/// Copies `from` into `to` (hard links where possible), folders recursively.
fn copy_tree(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for entry in std::fs::read_dir(from).with_context(|| format!("listing {}", from.display()))? {
        let entry = entry?;
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        if entry.file_type()?.is_dir() {
            copy_tree(&src, &dst)?;
        } else {
            let _ = std::fs::remove_file(&dst);
            if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst).with_context(|| format!("copying {} to {}", src.display(), dst.display()))?;
            }
        }
    }
    Ok(())
}

pub fn run(args: MergeArgs) -> Result<()> {
    let mut shards = Vec::new();
    for dir in &args.dirs {
        let path = dir.join("batch.json");
        if !path.is_file() {
            bail!("{}: no batch.json here (give the --out folder of a `handeye batch --shard K/N` run)", dir.display());
        }
        let file: BatchFile = read_report(&path).with_context(|| format!("{}: not a batch.json of a batch that can be merged (written by an older handeye?)", dir.display()))?;
        shards.push(ShardDir { dir: dir.clone(), file });
    }
    let (outcomes, spec) = combine(&shards, args.allow_partial, args.out.as_deref())?;
    if args.out.is_some() {
        for o in &outcomes {
            let shard = shards.iter().find(|s| s.file.result.runs_detail.iter().any(|d| d.scenario == o.job.name && d.seed == o.job.seed));
            let from = shard.map(|s| s.dir.join(&o.job.name).join(format!("seed-{}", o.job.seed)));
            if let (Some(from), Some(to)) = (from, &o.job.out)
                && from.is_dir()
                && from.canonicalize().ok() != to.canonicalize().ok()
            {
                copy_tree(&from, to)?;
            }
        }
    }
    let wall_s = shards.iter().filter_map(|s| s.file.result.all.wall_s).fold(0.0, f64::max);
    let daemon_config = shards[0].file.result.daemon_config.clone();
    let result = summarise(&outcomes, wall_s, daemon_config);
    super::pages::write_report(&BatchFile { batch: spec, result }, &outcomes, args.out.as_deref(), args.json)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::batch::shard::{ScenarioSpec, Shard};
    use handeye_wire::report::{Failure, FailureKind};

    /// Shard `k` of `n` of a batch of seeds 1..=7 of scenario "c", run by the batch's own
    /// summing-up; seed 4 fails. (The runs have no summaries: the end-to-end test in
    /// tests/batch_shard.rs merges real ones.)
    fn shard(k: u64, n: u64) -> ShardDir {
        let spec = BatchSpec {
            scenarios: vec![ScenarioSpec { name: "c".into(), file: "c.toml".into(), content_fnv1a64: "00".into() }],
            seeds: (1..=7).collect(),
            shard: Some(Shard { index: k, count: n }),
            run_flags: vec!["--random-layout".into()],
        };
        let outcomes: Vec<Outcome> = spec
            .own_seeds()
            .into_iter()
            .map(|seed| Outcome {
                job: Job { scenario: "c.toml".into(), name: "c".into(), seed, out: None },
                success: seed != 4,
                phase: if seed == 4 { "servo".into() } else { "done".into() },
                failure: (seed == 4).then(|| Failure::new("servo", FailureKind::NotConverged, "servo: not converged")),
                // As `run_one` makes it: the steps come from the summary, none without one.
                servo_steps: None,
                wall_s: 10.0 + seed as f64,
                summary: None,
            })
            .collect();
        ShardDir { dir: format!("shard-{k}").into(), file: BatchFile { batch: spec, result: summarise(&outcomes, 50.0, None) } }
    }

    #[test]
    fn three_shards_merge_into_the_unsharded_batch() {
        let whole = shard(1, 1);
        // Given in any order.
        let (outcomes, spec) = combine(&[shard(3, 3), shard(1, 3), shard(2, 3)], false, None).unwrap();
        assert_eq!(spec, BatchSpec { shard: None, ..whole.file.batch.clone() });
        assert_eq!(outcomes.iter().map(|o| o.job.seed).collect::<Vec<_>>(), (1..=7).collect::<Vec<_>>());
        let merged = summarise(&outcomes, 50.0, None);
        assert_eq!(merged, whole.file.result);
        assert_eq!(merged.all.median_run_wall_s, Some(14.0));
    }

    #[test]
    fn shards_that_do_not_belong_together_are_refused_naming_the_folder() {
        let err = |shards: &[ShardDir], partial: bool| combine(shards, partial, None).unwrap_err().to_string();
        // Missing shard 2: an error unless partial.
        let e = err(&[shard(1, 3), shard(3, 3)], false);
        assert!(e.contains("incomplete") && e.contains("2/3") && e.contains("c#2, c#5"), "{e}");
        let (partial, _) = combine(&[shard(1, 3), shard(3, 3)], true, None).unwrap();
        assert_eq!(partial.iter().map(|o| o.job.seed).collect::<Vec<_>>(), vec![1, 3, 4, 6, 7]);
        // The same shard twice.
        let e = err(&[shard(1, 3), shard(1, 3), shard(2, 3)], true);
        assert!(e.contains("both shard 1"), "{e}");
        // Another split, another seed list, other flags, another scenario text.
        let e = err(&[shard(1, 3), shard(2, 2)], true);
        assert!(e.contains("shard-2") && e.contains("one of 2 shards"), "{e}");
        let mut other = shard(2, 3);
        other.file.batch.seeds.push(8);
        assert!(err(&[shard(1, 3), other], true).contains("seed list"));
        let mut other = shard(2, 3);
        other.file.batch.run_flags.push("--hint".into());
        assert!(err(&[shard(1, 3), other], true).contains("run flags"));
        let mut other = shard(2, 3);
        other.file.batch.scenarios[0].content_fnv1a64 = "01".into();
        let e = err(&[shard(1, 3), other], true);
        assert!(e.starts_with("shard-2") && e.contains("another file"), "{e}");
        // A run the shard should not have run.
        let mut other = shard(2, 3);
        other.file.result.runs_detail[0].seed = 3;
        assert!(err(&[shard(1, 3), other], true).contains("not one of this shard's seeds"));
    }
}

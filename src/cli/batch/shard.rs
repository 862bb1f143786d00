//! Splitting a batch across machines: `--shard K/N` picks the K-th share of the seeds, and
//! every shard's batch.json says which batch it is a share of (the [`BatchSpec`]), so that
//! `handeye batch merge` can check that its inputs belong together and add up to the whole.
//!
//! The split is by seed position, not by contiguous ranges: shard K of N takes the seeds at
//! positions K-1, K-1+N, K-1+2N, ... of the list (--first-seed, --first-seed + 1, ...), every
//! scenario's runs of those seeds. Neighbouring seeds cost about the same, so the shards are
//! balanced to within one seed, and any N gives disjoint shards whose union is the list.

use std::fmt;
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::cli::report::BatchResult;

/// The K-th of N shares of a batch (K counts from 1, as Slurm's array ids and `K/N` read).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shard {
    /// K, 1..=count.
    pub index: u64,
    /// N.
    pub count: u64,
}

impl Shard {
    /// Whether this shard runs the seed at `position` in the batch's seed list (0-based).
    pub fn takes(&self, position: u64) -> bool {
        position % self.count == self.index - 1
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// `--shard K/N`: 1 <= K <= N.
pub fn parse_shard(text: &str) -> Result<Shard, String> {
    let bad = |why: &str| format!("'{text}': {why} (write K/N, e.g. 2/8 for the second of eight shards, K from 1 to N)");
    let (k, n) = text.trim().split_once('/').ok_or_else(|| bad("no '/'"))?;
    let k: u64 = k.trim().parse().map_err(|_| bad("K is not a whole number"))?;
    let n: u64 = n.trim().parse().map_err(|_| bad("N is not a whole number"))?;
    if n == 0 {
        return Err(bad("N must be at least 1"));
    }
    if k == 0 || k > n {
        return Err(bad(&format!("K must be between 1 and {n}")));
    }
    Ok(Shard { index: k, count: n })
}

/// One scenario of a batch, as its shards must agree on it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioSpec {
    pub name: String,
    /// The file as given on the command line (informative: shards may run in other folders).
    pub file: String,
    /// FNV-1a 64 of the file's bytes, hex: shards of one batch ran the same scenario text.
    pub content_fnv1a64: String,
}

impl ScenarioSpec {
    pub fn read(file: &Path, name: String) -> Result<Self> {
        let bytes = std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
        Ok(Self { name, file: file.display().to_string(), content_fnv1a64: format!("{:016x}", fnv1a64(&bytes)) })
    }
}

/// A stable hash of a file's bytes (the same on every machine and Rust version, unlike std's
/// `DefaultHasher`).
fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3))
}

/// Which batch a batch.json belongs to: what every run of it shares, the whole seed list and
/// the share this process ran (`null`: all of it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BatchSpec {
    /// In the order the batch runs and reports them.
    pub scenarios: Vec<ScenarioSpec>,
    /// Every seed of the batch, in order (not only this shard's).
    pub seeds: Vec<u64>,
    #[serde(deserialize_with = "handeye_wire::report::required")]
    pub shard: Option<Shard>,
    /// The `handeye run` flags every run got (layout, hint, daemon config, time-out).
    pub run_flags: Vec<String>,
}

impl BatchSpec {
    /// The seeds this batch.json's process ran.
    pub fn own_seeds(&self) -> Vec<u64> {
        self.seeds.iter().enumerate().filter(|(i, _)| self.shard.is_none_or(|s| s.takes(*i as u64))).map(|(_, &s)| s).collect()
    }
}

/// batch.json: the result (as `--json` prints it) with the [`BatchSpec`] under `batch`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchFile {
    pub batch: BatchSpec,
    #[serde(flatten)]
    pub result: BatchResult,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_are_disjoint_balanced_and_cover_every_seed() {
        for n in 1..=7u64 {
            let mut seen = vec![0u32; 30];
            let mut sizes = Vec::new();
            for k in 1..=n {
                let shard = parse_shard(&format!("{k}/{n}")).unwrap();
                let mine: Vec<u64> = (0..30).filter(|&p| shard.takes(p)).collect();
                for &p in &mine {
                    seen[p as usize] += 1;
                }
                sizes.push(mine.len());
            }
            assert!(seen.iter().all(|&c| c == 1), "{n} shards: {seen:?}");
            assert!(sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1, "{n} shards: {sizes:?}");
        }
        // Shard 2 of 3 over seeds 1..=7: positions 1 and 4, i.e. seeds 2 and 5.
        let spec = BatchSpec { scenarios: vec![], seeds: (1..=7).collect(), shard: Some(Shard { index: 2, count: 3 }), run_flags: vec![] };
        assert_eq!(spec.own_seeds(), vec![2, 5]);
        assert_eq!(BatchSpec { shard: None, ..spec }.own_seeds(), (1..=7).collect::<Vec<_>>());
    }

    #[test]
    fn a_bad_shard_says_what_is_wrong() {
        assert_eq!(parse_shard("3/8"), Ok(Shard { index: 3, count: 8 }));
        assert_eq!(parse_shard("1/1"), Ok(Shard { index: 1, count: 1 }));
        for (text, why) in [("0/4", "between 1 and 4"), ("5/4", "between 1 and 4"), ("1/0", "at least 1"), ("3", "no '/'"), ("a/4", "K is not"), ("2/x", "N is not")] {
            let e = parse_shard(text).unwrap_err();
            assert!(e.contains(why) && e.contains(text), "{text}: {e}");
        }
    }

    #[test]
    fn the_scenario_hash_is_fnv1a() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}

//! Where the real-frame test data lives, and how a test that lacks it says so.
//!
//! One setting for the whole workspace: `HANDEYE_DATA`, the folder that holds `visp-cube/`
//! (the ViSP `mbt/cube` image sequence; see README.md, "Test data"). Unset, it is
//! `../shared/data`; a relative value is taken relative to the workspace root, so the root
//! crate's tests and `handeye-vision`'s (which include this file by `#[path]`) agree.
//!
//! A test whose data is missing passes without checking anything, so it must not do so
//! quietly: it prints `SKIPPED` with the path it looked for and the setting to change, and
//! appends the same line to the file named by `HANDEYE_SKIPPED_LOG` when that is set. Cargo
//! hides the output of passing tests; `make test` sets the log and lists it at the end.
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};

/// The folder that holds the data sets (`visp-cube/`).
pub const DATA_ENV: &str = "HANDEYE_DATA";
/// A file each skipped data-dependent test appends one line to.
pub const SKIPPED_LOG_ENV: &str = "HANDEYE_SKIPPED_LOG";
/// `HANDEYE_DATA` when unset, relative to the workspace root.
const DEFAULT_DATA: &str = "../shared/data";

/// The workspace root: the nearest folder at or above this crate's manifest whose
/// `Cargo.toml` declares the workspace.
fn workspace_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest
        .ancestors()
        .find(|d| std::fs::read_to_string(d.join("Cargo.toml")).is_ok_and(|t| t.contains("[workspace]")))
        .unwrap_or(manifest)
        .to_path_buf()
}

/// The data folder: `HANDEYE_DATA`, or `../shared/data` next to the workspace.
pub fn data_dir() -> PathBuf {
    let root = workspace_root();
    match std::env::var_os(DATA_ENV) {
        // `join` keeps an absolute value as it is.
        Some(dir) if !dir.is_empty() => root.join(dir),
        _ => root.join(DEFAULT_DATA),
    }
}

/// The `visp-cube` folder if every file in `needed` is in it; otherwise reports this test
/// as skipped (see the module docs) and gives `None`.
pub fn visp_cube(needed: &[&str]) -> Option<PathBuf> {
    let dir = data_dir().join("visp-cube");
    match needed.iter().map(|f| dir.join(f)).find(|p| !p.is_file()) {
        None => Some(dir),
        Some(missing) => {
            skipped(&format!("{} not found", missing.display()));
            None
        }
    }
}

/// Says loudly that the running test was skipped, and why.
pub fn skipped(why: &str) {
    let line = format!(
        "{}: {why}; set {DATA_ENV} to the folder that holds visp-cube/ (README.md, \"Test data\")",
        current_test()
    );
    eprintln!("SKIPPED {line}");
    if let Some(log) = std::env::var_os(SKIPPED_LOG_ENV).filter(|l| !l.is_empty()) {
        // One write per line, in append mode: tests running in parallel do not interleave.
        let appended = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log)
            .and_then(|mut f| f.write_all(format!("{line}\n").as_bytes()));
        if let Err(e) = appended {
            eprintln!("could not append to {SKIPPED_LOG_ENV}={}: {e}", Path::new(&log).display());
        }
    }
}

/// `binary::test`: the test binary's name without cargo's hash, and the test's name, which
/// the test harness gives the thread it runs the test on.
fn current_test() -> String {
    let binary = std::env::current_exe()
        .ok()
        .and_then(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .map(|s| match s.rsplit_once('-') {
            Some((name, hash)) if hash.len() == 16 && hash.chars().all(|c| c.is_ascii_hexdigit()) => name.to_owned(),
            _ => s,
        })
        .unwrap_or_else(|| "?".into());
    match std::thread::current().name() {
        Some(test) if test != "main" => format!("{binary}::{test}"),
        _ => binary,
    }
}

//! Helpers for the end-to-end tests: `handeye run` as a user runs it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Mutex, MutexGuard};

use handeye_sim::referee::report::SimReport;
use serde_json::Value;

pub fn scenario(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios").join(name)
}

/// Holds the machine for one closed loop at a time. Each loop is a lockstep simulator
/// rendering on the CPU plus a daemon with frame deadlines; several at once on a 2-core
/// machine starve each other until a daemon rightly calls its camera dead.
pub fn one_at_a_time() -> MutexGuard<'static, ()> {
    static LOOP: Mutex<()> = Mutex::new(());
    // A test that failed while holding it leaves nothing behind that matters here.
    LOOP.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// A copy of a shipped scenario in `dir` with 4x multisampling off: a third of the render
/// time, for tests whose point is timing (a daemon with a 100 ms stale-frame guard) rather
/// than sub-pixel accuracy.
pub fn scenario_without_antialias(name: &str, dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(scenario(name)).unwrap();
    let out = dir.join(name);
    std::fs::write(&out, text.replace("antialias = true", "antialias = false")).unwrap();
    out
}

/// A fresh temporary folder, removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(stem: &str) -> Self {
        let d = std::env::temp_dir().join(format!("handeye-{stem}-{}-{}", std::process::id(), handeye_wire::monotonic_ns()));
        std::fs::create_dir_all(&d).unwrap();
        Self(d)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// `handeye run SCENARIO --json --out DIR [extra]`: the summary, the sim's report (typed: a
/// missing or renamed field fails here, naming it), the daemon's JSON, and the exit status.
pub struct RunResult {
    pub summary: Value,
    pub sim: SimReport,
    pub daemon: Value,
    pub status: i32,
    pub out: TempDir,
}

pub fn run(scenario_file: &str, extra: &[&str]) -> RunResult {
    let _one = one_at_a_time();
    let out = TempDir::new(scenario_file.trim_end_matches(".toml"));
    let o = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .arg("run")
        .arg(scenario(scenario_file))
        .arg("--json")
        .arg("--out")
        .arg(&out.0)
        .args(extra)
        .env("HANDEYE_LOG", "warn")
        .output()
        .expect("handeye run");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let line = stdout.lines().rev().find(|l| l.starts_with('{')).unwrap_or_else(|| {
        panic!("no JSON from handeye run {scenario_file}:\nstdout: {stdout}\nstderr: {}", String::from_utf8_lossy(&o.stderr))
    });
    let summary: Value = serde_json::from_str(line).unwrap();
    let read = |name: &str| -> Value {
        std::fs::read_to_string(out.0.join(name)).ok().and_then(|t| serde_json::from_str(&t).ok()).unwrap_or(Value::Null)
    };
    let sim_path = out.0.join("sim.json");
    let sim = std::fs::read_to_string(&sim_path)
        .map_err(|e| e.to_string())
        .and_then(|t| serde_json::from_str(&t).map_err(|e| e.to_string()))
        .unwrap_or_else(|e| panic!("{}: {e}\nstdout: {stdout}\nstderr: {}", sim_path.display(), String::from_utf8_lossy(&o.stderr)));
    let daemon = read("daemon.json");
    RunResult { summary, sim, daemon, status: o.status.code().unwrap_or(-1), out }
}

impl RunResult {
    /// The summary, the sim's phases and the tail of both logs, for assertion messages.
    pub fn explain(&self) -> String {
        let tail = |name: &str| {
            let t = std::fs::read_to_string(self.out.0.join(name)).unwrap_or_default();
            let lines: Vec<&str> = t.lines().collect();
            lines[lines.len().saturating_sub(4)..].join("\n")
        };
        format!(
            "summary: {}\nsim saw: {}\nsim stderr: {}\ndaemon stderr: {}",
            self.summary,
            serde_json::to_string(&self.sim.daemon).unwrap_or_default(),
            tail("sim.stderr.log"),
            tail("daemon.stderr.log")
        )
    }

    pub fn f(&self, key: &str) -> f64 {
        self.summary[key].as_f64().unwrap_or(f64::NAN)
    }
}

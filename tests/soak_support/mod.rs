//! What the stress and soak harnesses (`tests/stress_cpu.rs`, `tests/soak_observe.rs`) read
//! from the operating system: a process's memory, descriptors and threads from `/proc`, the
//! shared-memory files of a domain in `/dev/shm` and iceoryx2's root directory, and a
//! `stress-ng` load that ends with the test.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Child, Command, Stdio};

/// iceoryx2's root directory for management files (`handeye_wire::Domain` keeps the default).
pub const ICEORYX2_ROOT: &str = "/tmp/iceoryx2";

/// One look at a process in `/proc`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProcSample {
    /// Resident set size now (`VmRSS`), KiB.
    pub rss_kib: u64,
    /// Peak resident set size so far (`VmHWM`), KiB.
    pub hwm_kib: u64,
    /// Open file descriptors (entries of `/proc/PID/fd`).
    pub fds: usize,
    pub threads: u64,
}

/// Reads `/proc/PID/status` and `/proc/PID/fd`; `None` once the process is gone.
pub fn sample_proc(pid: u32) -> Option<ProcSample> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| -> Option<u64> {
        let line = status.lines().find(|l| l.starts_with(name))?;
        line[name.len()..].split_whitespace().next()?.parse().ok()
    };
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).ok()?.count();
    Some(ProcSample { rss_kib: field("VmRSS:")?, hwm_kib: field("VmHWM:")?, fds, threads: field("Threads:")? })
}

/// Names of the files and folders whose name starts with `prefix` (an iceoryx2 domain prefix,
/// `iox2_<domain>_`, or the start of one) in `/dev/shm` and anywhere under iceoryx2's root.
pub fn domain_files(prefix: &str) -> Vec<String> {
    let mut found = Vec::new();
    collect(Path::new("/dev/shm"), prefix, false, &mut found);
    collect(Path::new(ICEORYX2_ROOT), prefix, true, &mut found);
    found.sort();
    found
}

fn collect(dir: &Path, prefix: &str, recurse: bool, found: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with(prefix) {
            found.push(entry.path().display().to_string());
        } else if recurse && entry.file_type().is_ok_and(|t| t.is_dir()) {
            collect(&entry.path(), prefix, true, found);
        }
    }
}

/// The `p`-th percentile (0-100) of `values` by nearest rank; NaN for none.
pub fn percentile(values: &[f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * v.len() as f64).ceil() as usize;
    v[rank.clamp(1, v.len()) - 1]
}

/// `stress-ng --cpu N` running until dropped (then SIGTERMed, which ends its workers too).
pub struct CpuStress {
    child: Child,
    pub workers: usize,
}

impl CpuStress {
    /// Starts `workers` CPU hogs (0 = one per online CPU, as stress-ng counts them). The
    /// `--timeout` is only a backstop should the test process die without dropping this.
    pub fn start(workers: usize, backstop_s: u64) -> Self {
        let which = Command::new("stress-ng").arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status();
        assert!(which.is_ok_and(|s| s.success()), "stress-ng is not installed: run `make setup` (scripts/setup.sh installs it) or apt-get install stress-ng");
        let child = Command::new("stress-ng")
            .args(["--cpu", &workers.to_string(), "--cpu-method", "matrixprod", "--timeout", &format!("{backstop_s}s"), "--quiet"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("starting stress-ng");
        let workers = if workers == 0 { std::thread::available_parallelism().map_or(1, |n| n.get()) } else { workers };
        // Let the workers start before the first measurement.
        std::thread::sleep(std::time::Duration::from_millis(500));
        Self { child, workers }
    }
}

impl Drop for CpuStress {
    fn drop(&mut self) {
        let _ = Command::new("kill").args(["-TERM", &self.child.id().to_string()]).status();
        let _ = self.child.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!((percentile(&v, 50.0), percentile(&v, 99.0), percentile(&v, 100.0)), (50.0, 99.0, 100.0));
        assert!(percentile(&[], 50.0).is_nan());
    }

    #[test]
    fn this_process_can_be_sampled() {
        let s = sample_proc(std::process::id()).unwrap();
        assert!(s.rss_kib > 0 && s.hwm_kib >= s.rss_kib && s.fds >= 3 && s.threads >= 1, "{s:?}");
    }
}

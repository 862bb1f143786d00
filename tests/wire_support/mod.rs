//! Helpers shared by the cross-process wire tests (`tests/wire_*.rs`).
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use handeye_wire::checksum::PixelChecksum;
use handeye_wire::domain::remove_domain_files;
use handeye_wire::Domain;

/// A unique domain whose shared-memory files are removed when the test ends.
pub struct TestDomain(pub Domain);

impl TestDomain {
    pub fn new(stem: &str) -> Self {
        Self(Domain::unique(stem))
    }

    pub fn name(&self) -> &str {
        self.0.name()
    }
}

impl Drop for TestDomain {
    fn drop(&mut self) {
        let _ = remove_domain_files(&self.0);
    }
}

/// A `handeye` command in `domain`, quiet logging.
pub fn handeye(domain: &TestDomain) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_handeye"));
    c.env("HANDEYE_DOMAIN", domain.name()).env("HANDEYE_LOG", "warn").env_remove("IOX2_LOG_LEVEL");
    c
}

/// A child process that is SIGKILLed if the test ends (or panics) while it still runs, and
/// whose stderr lines arrive on a channel.
pub struct Proc {
    pub child: Child,
    pub name: &'static str,
    stderr: Receiver<String>,
    stderr_log: Vec<String>,
}

impl Proc {
    pub fn spawn(name: &'static str, mut cmd: Command) -> Self {
        cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
        let mut child = cmd.spawn().unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        let err = child.stderr.take().expect("piped stderr");
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self { child, name, stderr: rx, stderr_log: Vec::new() }
    }

    /// Waits for a stderr line containing `needle`; panics with everything seen on time-out.
    pub fn wait_line(&mut self, needle: &str, timeout: Duration) -> String {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.stderr.recv_timeout(left) {
                Ok(line) => {
                    self.stderr_log.push(line.clone());
                    if line.contains(needle) {
                        return line;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    panic!("{}: no line with {needle:?} within {timeout:?}; stderr so far:\n{}", self.name, self.stderr_log.join("\n"))
                }
                Err(RecvTimeoutError::Disconnected) => {
                    panic!("{}: exited without a line with {needle:?}; stderr:\n{}", self.name, self.stderr_log.join("\n"))
                }
            }
        }
    }

    /// Sends SIGINT (Ctrl-C).
    pub fn interrupt(&self) {
        // SAFETY: plain kill(2) on our own child's pid.
        let rc = unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGINT) };
        assert_eq!(rc, 0, "kill -INT {}", self.name);
    }

    /// Waits for the exit (at most `timeout`) and returns (success, stdout, all stderr).
    pub fn finish(mut self, timeout: Duration) -> (bool, String, String) {
        let deadline = Instant::now() + timeout;
        let status = loop {
            if let Some(s) = self.child.try_wait().expect("try_wait") {
                break s;
            }
            if Instant::now() >= deadline {
                let _ = self.child.kill();
                let err = self.drain_stderr();
                panic!("{} did not exit within {timeout:?}; stderr:\n{err}", self.name);
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut out = String::new();
        if let Some(mut o) = self.child.stdout.take() {
            let _ = o.read_to_string(&mut out);
        }
        let err = self.drain_stderr();
        (status.success(), out, err)
    }

    fn drain_stderr(&mut self) -> String {
        while let Ok(line) = self.stderr.recv_timeout(Duration::from_millis(200)) {
            self.stderr_log.push(line);
        }
        self.stderr_log.join("\n")
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// PNG files of `dir` in file-name order.
pub fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        .collect();
    v.sort();
    v
}

/// The checksum a subscriber must report for frames made of these images (each frame is a
/// (left, right) pair), decoded independently of `handeye feed`.
pub fn checksum_of_pairs(pairs: &[(PathBuf, PathBuf)]) -> String {
    let mut c = PixelChecksum::new();
    for (l, r) in pairs {
        for p in [l, r] {
            let img = image::open(p).unwrap().to_luma8();
            c.add_bytes(img.as_raw());
        }
    }
    format!("{:016x}", c.value())
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

/// Writes `n` gray PNGs of `w` x `h` into `dir`, each with different content.
pub fn write_pngs(dir: &Path, n: usize, w: u32, h: u32, seed: u8) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).unwrap();
    (0..n)
        .map(|i| {
            let p = dir.join(format!("frame{i:04}.png"));
            let img = image::GrayImage::from_fn(w, h, |x, y| image::Luma([(x * 7 + y * 13 + i as u32 * 29) as u8 ^ seed]));
            img.save(&p).unwrap();
            p
        })
        .collect()
}

/// Parses the monitor's JSON summary.
pub fn parse_json(stdout: &str) -> serde_json::Value {
    let line = stdout.lines().rev().find(|l| l.starts_with('{')).unwrap_or_else(|| panic!("no JSON in stdout:\n{stdout}"));
    serde_json::from_str(line).unwrap_or_else(|e| panic!("bad JSON ({e}): {line}"))
}

/// A child process SIGKILLed and reaped when dropped, so a test that fails (or panics) leaves
/// no simulator, daemon or feeder running. For one whose stderr the test reads, see [`Proc`].
pub struct Kid(pub Child);

impl Drop for Kid {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The JSON objects of a log with one per line (`monitor --telemetry`, the gesture log);
/// other lines (a header, a progress message) are skipped.
pub fn json_lines(path: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    text.lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{}: a line is not JSON ({e}): {l}", path.display())))
        .collect()
}

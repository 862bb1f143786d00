//! Who may command the arm (issue 21, item 5): a domain's shared memory belongs to the user
//! who runs it, and another local user can neither publish a command into it nor read its
//! frames. README.md, "Safety and security", describes the model this test proves.
//!
//! As root (CI runs as root), the test runs a domain: `handeye feed` publishing frames and the
//! test itself subscribed to robot commands, as an arm's driver would be. Then, as `nobody`
//! (through util-linux's `setpriv`), it runs (1) this test binary in probe mode, which tries
//! what an attacker's own program would: join the domain through the wire library, publish
//! commands, read frames, and open, write and delete every file the domain created in
//! `/dev/shm` and iceoryx2's root folder directly; and (2) `handeye monitor` and
//! `handeye daemon` in that domain. All of it must fail, no command may reach the subscriber,
//! and the one file iceoryx2 makes world-writable must be the one that holds no data.
//!
//! Run as another user than root, the test cannot switch users: it says SKIPPED (and logs it
//! for `make test`'s list).

mod wire_support;

use std::io::Write as _;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use handeye_wire::message::{MessagePublisher, MessageSubscriber};
use handeye_wire::stereo::{StereoEvent, StereoSubscriber};
use handeye_wire::{monotonic_ns, CommandKind, Domain, RobotCommand, WireNode, WIRE_VERSION};
use serde_json::{json, Value};
use wire_support::{handeye, write_pngs, Proc, TestDomain};

/// Set for the probe run: the file that lists the domain and its files.
const PROBE_ENV: &str = "HANDEYE_PERMISSION_PROBE";
/// The one file of a domain iceoryx2 0.10 creates readable and writable by everyone: the
/// node counter every user's nodes draw their ids from (`..._node.0_10_0.global_mgmt`).
const GLOBAL_MGMT_SUFFIX: &str = ".global_mgmt";

/// Says SKIPPED (on stderr, and in `HANDEYE_SKIPPED_LOG` for `make test`'s list).
fn skipped(why: &str) {
    let line = format!("permissions: {why}");
    eprintln!("SKIPPED {line}");
    if let Some(log) = std::env::var_os("HANDEYE_SKIPPED_LOG").filter(|l| !l.is_empty())
        && let Ok(mut f) = std::fs::OpenOptions::new().create(true).append(true).open(log)
    {
        let _ = writeln!(f, "{line}");
    }
}

/// `setpriv` as `nobody`/`nogroup` with no supplementary groups: an unprivileged user
/// that shares nothing with root.
fn as_nobody(program: &Path) -> Command {
    let mut c = Command::new("setpriv");
    c.args(["--reuid=nobody", "--regid=nogroup", "--clear-groups", "--"]).arg(program);
    c
}

/// `program` itself if `nobody` may run it, else a copy in a folder everyone may enter (the
/// checkout may sit under a home folder closed to other users).
fn runnable_by_nobody(program: &Path, scratch: &Path) -> PathBuf {
    let ok = Command::new("setpriv")
        .args(["--reuid=nobody", "--regid=nogroup", "--clear-groups", "--", "test", "-x"])
        .arg(program)
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        return program.to_path_buf();
    }
    let copy = scratch.join(program.file_name().unwrap());
    std::fs::copy(program, &copy).unwrap();
    std::fs::set_permissions(&copy, std::fs::Permissions::from_mode(0o755)).unwrap();
    copy
}

/// Every file and folder of `domain` in `/dev/shm` and in iceoryx2's root folder (recursive).
fn domain_files(domain: &Domain) -> Vec<PathBuf> {
    fn walk(dir: &Path, prefix: &str, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for e in entries.flatten() {
            let p = e.path();
            if e.file_name().to_string_lossy().starts_with(prefix) {
                out.push(p.clone());
            }
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                walk(&p, prefix, out);
            }
        }
    }
    let prefix = domain.prefix();
    let mut out = Vec::new();
    walk(Path::new("/dev/shm"), &prefix, &mut out);
    walk(Path::new(domain.iceoryx2_config().global.root_path().to_string().as_str()), &prefix, &mut out);
    out
}

fn text(o: &Output) -> String {
    format!("status {:?}\nstdout: {}\nstderr: {}", o.status.code(), String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn another_user_can_neither_command_the_arm_nor_read_frames() {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        skipped("not root: switching to another user needs root (CI runs as root; run `sudo make test` to include it)");
        return;
    }
    assert!(
        Command::new("setpriv").arg("--version").output().is_ok_and(|o| o.status.success()),
        "setpriv (util-linux) is missing: scripts/setup.sh installs it"
    );
    let scratch = wire_support::TempDir::new("perm");
    std::fs::set_permissions(&scratch.0, std::fs::Permissions::from_mode(0o755)).unwrap();
    let domain = TestDomain::new("perm");

    // The owner's side: a frame publisher and a command subscriber (the arm's driver).
    let images = scratch.0.join("images");
    write_pngs(&images, 3, 64, 48, 0);
    let mut feed = handeye(&domain);
    feed.args(["feed", "--mono", "--loop", "--rate-hz", "30", "--wait-subscriber-s", "0", "--dir"]).arg(&images);
    let _feed = Proc::spawn("feed", feed);
    let node = WireNode::create(&domain.0, "perm-owner").unwrap();
    let mut commands = MessageSubscriber::<RobotCommand>::create(&node).unwrap();
    let mut frames = StereoSubscriber::create(&node, 1).unwrap();
    let t0 = Instant::now();
    loop {
        assert!(t0.elapsed() < Duration::from_secs(20), "the owner got no frame from the feed");
        if let StereoEvent::Frame(_) = frames.wait(Duration::from_millis(100)).unwrap() {
            break;
        }
    }
    // And the owner may command: its own command reaches the subscriber.
    let mut owner_cmds = MessagePublisher::<RobotCommand>::create(&node).unwrap();
    owner_cmds.send(&RobotCommand { version: WIRE_VERSION, kind: CommandKind::Hold as u32, time_ns: monotonic_ns(), ..Default::default() }).unwrap();
    let t0 = Instant::now();
    while commands.try_receive().is_none() {
        assert!(t0.elapsed() < Duration::from_secs(5), "the owner's own command did not arrive");
        std::thread::sleep(Duration::from_millis(10));
    }
    drop(owner_cmds);

    let files = domain_files(&domain.0);
    assert!(files.iter().any(|f| f.starts_with("/dev/shm")), "no /dev/shm file for the domain: {files:?}");
    let list = scratch.0.join("files.json");
    let listed: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    std::fs::write(&list, json!({ "domain": domain.name(), "files": listed }).to_string()).unwrap();
    std::fs::set_permissions(&list, std::fs::Permissions::from_mode(0o644)).unwrap();

    // (1) The probe, as nobody.
    let exe = runnable_by_nobody(&std::env::current_exe().unwrap(), &scratch.0);
    let out = as_nobody(&exe)
        .args(["--exact", "probe_as_another_user", "--ignored", "--nocapture", "--test-threads", "1"])
        .env(PROBE_ENV, &list)
        .current_dir(&scratch.0)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let report: Value = stdout
        .lines()
        .find_map(|l| l.find("PROBE ").map(|i| &l[i + "PROBE ".len()..]))
        .map(|l| serde_json::from_str(l).unwrap())
        .unwrap_or_else(|| panic!("the probe reported nothing:\n{}", text(&out)));
    eprintln!("probe as nobody: {report}");
    assert_eq!(report["uid"], 65534, "the probe did not run as nobody: {report}");
    assert!(report["node"].as_str().unwrap().starts_with("refused"), "nobody joined the domain: {report}");
    assert_eq!(report["commands_sent"], 0, "{report}");
    assert_eq!(report["frames_read"], 0, "{report}");
    for f in report["files"].as_array().unwrap() {
        let path = f["path"].as_str().unwrap();
        let open_by_all = path.ends_with(GLOBAL_MGMT_SUFFIX);
        for access in ["read", "write", "unlink"] {
            let r = f[access].as_str().unwrap();
            let allowed = open_by_all && access != "unlink";
            assert_eq!(r == "ok", allowed, "nobody's {access} of {path}: {r} ({report})");
        }
    }
    // The world-writable one holds one 32-bit counter and no service data.
    for f in files.iter().filter(|f| f.to_string_lossy().ends_with(GLOBAL_MGMT_SUFFIX)) {
        assert!(std::fs::metadata(f).unwrap().len() <= 64, "{} is larger than a node counter", f.display());
    }

    // (2) The user-facing commands, as nobody, in that domain.
    let bin = runnable_by_nobody(Path::new(env!("CARGO_BIN_EXE_handeye")), &scratch.0);
    let monitor = as_nobody(&bin).args(["monitor", "--count", "1", "--timeout-s", "3", "--domain", domain.name()]).current_dir(&scratch.0).output().unwrap();
    assert!(!monitor.status.success(), "nobody's monitor read the domain: {}", text(&monitor));
    let daemon = as_nobody(&bin).args(["daemon", "--domain", domain.name()]).current_dir(&scratch.0).output().unwrap();
    assert!(!daemon.status.success(), "nobody's daemon ran in the domain: {}", text(&daemon));
    for o in [&monitor, &daemon] {
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(domain.name()), "the refusal should name the domain: {err}");
    }

    // Nothing nobody did reached the arm's command subscriber.
    std::thread::sleep(Duration::from_millis(200));
    assert!(commands.try_receive().is_none(), "a command from nobody reached the arm");
}

/// The probe (run by the test above as `nobody`; does nothing otherwise).
#[test]
#[ignore = "run as another user by another_user_can_neither_command_the_arm_nor_read_frames"]
fn probe_as_another_user() {
    let Some(list) = std::env::var_os(PROBE_ENV) else { return };
    let spec: Value = serde_json::from_str(&std::fs::read_to_string(list).unwrap()).unwrap();
    let domain = Domain::new(spec["domain"].as_str().unwrap()).unwrap();
    // SAFETY: getuid has no preconditions.
    let uid = unsafe { libc::getuid() };
    let (mut commands_sent, mut frames_read) = (0, 0);
    let node = match WireNode::create(&domain, "intruder") {
        Err(e) => format!("refused: {e}"),
        Ok(node) => {
            // Joined after all: try to command the arm and read the cameras.
            if let Ok(mut p) = MessagePublisher::<RobotCommand>::create(&node) {
                let stop = RobotCommand { version: WIRE_VERSION, kind: CommandKind::Stop as u32, time_ns: monotonic_ns(), ..Default::default() };
                commands_sent += p.send(&stop).unwrap_or(0);
            }
            if let Ok(mut s) = StereoSubscriber::create(&node, 1) {
                let t0 = Instant::now();
                while t0.elapsed() < Duration::from_secs(1) {
                    if let Ok(StereoEvent::Frame(_)) = s.wait(Duration::from_millis(50)) {
                        frames_read += 1;
                    }
                }
            }
            "joined".to_owned()
        }
    };
    let outcome = |r: std::io::Result<()>| match r {
        Ok(()) => "ok".to_owned(),
        Err(e) => e.kind().to_string(),
    };
    let files: Vec<Value> = spec["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let path = Path::new(p.as_str().unwrap());
            // A folder is read by listing it and written by creating a file in it.
            let is_dir = path.is_dir();
            let read = outcome(if is_dir { std::fs::read_dir(path).map(drop) } else { std::fs::File::open(path).map(drop) });
            let write = outcome(if is_dir {
                std::fs::File::create(path.join("intruder")).map(drop)
            } else {
                std::fs::OpenOptions::new().write(true).open(path).map(drop)
            });
            let unlink = outcome(if is_dir { std::fs::remove_dir(path) } else { std::fs::remove_file(path) });
            json!({ "path": p, "read": read, "write": write, "unlink": unlink })
        })
        .collect();
    let report = json!({ "uid": uid, "node": node, "commands_sent": commands_sent, "frames_read": frames_read, "files": files });
    println!("PROBE {report}");
}

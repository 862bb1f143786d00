//! Runs the `camera_publisher` example as its own process and checks what a subscriber gets:
//! the example is documentation, so it must keep working.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

use handeye_wire::domain::remove_domain_files;
use handeye_wire::stereo::{StereoEvent, StereoSubscriber};
use handeye_wire::{Domain, WireNode};

/// The example binary, built by `cargo test` next to the test binaries.
fn example_binary() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    // target/<profile>/deps/<test> -> target/<profile>/examples/camera_publisher
    let profile_dir = exe.parent().and_then(|d| d.parent()).unwrap();
    let bin = profile_dir.join("examples").join("camera_publisher");
    assert!(
        bin.is_file(),
        "{} is missing: run `cargo test -p handeye-wire` (it builds the examples) or \
         `cargo build -p handeye-wire --examples` first",
        bin.display()
    );
    bin
}

fn pattern(x: usize, y: usize, camera: usize, frame: u64) -> u8 {
    ((x as u64 + 4 * frame + 8 * camera as u64) as u8) ^ (y as u8)
}

#[test]
fn example_camera_publisher_sends_its_documented_pattern() {
    let domain = Domain::unique("example");
    let node = WireNode::create(&domain, "example-test").unwrap();
    let mut sub = StereoSubscriber::create(&node, 2).unwrap();
    let mut child = Command::new(example_binary())
        .args(["--frames", "12", "--size", "64x40", "--lossless"])
        .env("HANDEYE_DOMAIN", domain.name())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut ids = Vec::new();
    while ids.len() < 12 {
        match sub.wait(Duration::from_secs(20)).unwrap() {
            StereoEvent::Frame(f) => {
                let l = *f.layout();
                assert_eq!((l.width, l.height, l.camera_count), (64, 40, 2));
                for c in 0..2 {
                    for y in [0, 17, 39] {
                        let row = f.row(c, y).unwrap();
                        for (x, &p) in row.iter().enumerate() {
                            assert_eq!(p, pattern(x, y, c, f.frame_id()), "frame {} camera {c} ({x}, {y})", f.frame_id());
                        }
                    }
                }
                ids.push(f.frame_id());
            }
            StereoEvent::Timeout => {
                let _ = child.kill();
                panic!("example sent only {ids:?}");
            }
            _ => {}
        }
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(ids, (0..12).collect::<Vec<u64>>());
    assert_eq!(sub.stats().rejected_total(), 0);
    drop(sub);
    drop(node);
    let _ = remove_domain_files(&domain);
}

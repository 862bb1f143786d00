//! The daemon's hard loop driven in-process by the simulator (no shared memory).

mod daemon_support;

use daemon_support::{scenario, InProcess};
use handeye_daemon::DaemonConfig;
use handeye_wire::Phase;

#[test]
#[ignore]
fn debug_target_tracking() {
    let mut sc = scenario(&std::env::var("SCEN").unwrap_or("pick_cube.toml".into()));
    if let Ok(shade) = std::env::var("TABLE") {
        sc.table.shade = shade.parse().unwrap();
    }
    if let Ok(seed) = std::env::var("SEED") {
        sc.randomise_target(seed.parse().unwrap());
    }
    let mut run = InProcess::new(sc, DaemonConfig::default());
    for _ in 0..2000 {
        run.step();
        let p = run.daemon.phase();
        if matches!(p, Phase::Servo) && run.frame % 10 == 0 {
            let t = run.daemon.telemetry();
            let c = t.tracker_corners_px[2];
            eprintln!("frame {} {:?} conf {:?} corners {:?} err {:?} steps {}", run.frame, p, t.tracker_confidence, &c[..2], t.servo_error, t.servo_steps);
        }
        if matches!(p, Phase::Failed | Phase::Stopped | Phase::Done) {
            eprintln!("{:?}: {:?} {:?}", p, run.daemon.failure(), run.runner.watch);
            break;
        }
    }
}

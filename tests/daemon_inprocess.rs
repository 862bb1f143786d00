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
    let mut cfg = DaemonConfig::default();
    if std::env::var("AFFINE").is_ok() {
        cfg.tracker.projective = false;
    }
    if let Ok(v) = std::env::var("LOCAL") {
        cfg.servo.local_cage_m = v.parse().unwrap();
    }
    if let Ok(v) = std::env::var("STANDOFF") {
        cfg.servo.standoff_above_m = v.parse().unwrap();
    }
    let mut run = InProcess::new(sc, cfg);
    for _ in 0..2000 {
        run.step();
        let p = run.daemon.phase();
        if matches!(p, Phase::Servo) && run.frame % 10 == 0 {
            let t = run.daemon.telemetry();
            let c = t.tracker_corners_px[2];
            eprintln!("frame {} {:?} conf {:?} corners {:?} err {:?} steps {}", run.frame, p, t.tracker_confidence, &c[..2], t.servo_error, t.servo_steps);
        }
        if p == Phase::Grasp && run.runner.watch.converged.is_some() && run.runner.watch.converged.unwrap().frame + 1 == run.frame {
            let sim = &run.runner.sim;
            let (pos, rot) = sim.world.body_pose(sim.world.arm.links[4]);
            let pc: handeye_sim::glam::DVec3 = handeye_sim::scene::plate_corners_in_palm().iter().map(|c| pos + rot * *c).sum::<handeye_sim::glam::DVec3>() / 4.0;
            let b = &sim.world.blocks[run.facet.block];
            let (_, pose) = sim.block_pose(run.facet.block);
            let f = &b.shape.faces[run.facet.face];
            let fc = f.corners.iter().map(|&c| pose.transform_point3(b.shape.corners[c])).sum::<handeye_sim::glam::DVec3>() / f.corners.len() as f64;
            let n = run.facet.normal;
            let d = pc - fc;
            let cam = &sim.events.cameras[0];
            let m = run.daemon.mission.calibration.as_ref().unwrap().model.m;
            for (k, at) in [("facet", fc), ("plate", pc), ("cage centre", handeye_sim::glam::DVec3::new(0.36 + 0.056, 0.0, 0.23))] {
                let j: Vec<[f64; 2]> = (0..3).map(|a| { let mut e = handeye_sim::glam::DVec3::ZERO; e[a] = 0.001; let p1 = cam.project(at + e).unwrap(); let p0 = cam.project(at - e).unwrap(); [(p1[0]-p0[0]) / 0.002, (p1[1]-p0[1]) / 0.002] }).collect();
                eprintln!("true J left at {k}: {:?}", j);
            }
            eprintln!("model M left: [{:.0}, {:.0}], [{:.0}, {:.0}], [{:.0}, {:.0}]", m[(0,0)], m[(1,0)], m[(0,1)], m[(1,1)], m[(0,2)], m[(1,2)]);
            let pn = sim.arm_reading().palm_rot * handeye_sim::glam::DVec3::Y;
            eprintln!("AZIMUTH facet {:.1}° plate {:.1}° yaw {:.1}°", n.y.atan2(n.x).to_degrees(), pn.y.atan2(pn.x).to_degrees(), sim.arm_reading().yaw_rad().to_degrees());
            eprintln!("TRUTH ref-facet: along n {:.1} mm (want 0), up {:.1} mm (want 150), lateral {:.1} mm; tool {:?}", d.dot(n) * 1e3, d.z * 1e3, (d - n * d.dot(n)).truncate().length() * 1e3, sim.arm_reading().tool_m);
        }
        if matches!(p, Phase::Failed | Phase::Stopped | Phase::Done) {
            eprintln!("{:?}: {:?} {:?}", p, run.daemon.failure(), run.runner.watch);
            break;
        }
    }
}

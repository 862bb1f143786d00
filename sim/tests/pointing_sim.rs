//! Pointing accuracy on rendered frames (issue 19): 30 seeded pointing gestures on
//! `clutter3` layouts (`scenarios/point_clutter3.toml`, `--random-layout` seeds 1..=30), the
//! simulator rendering the stereo pair as `handeye sim` publishes it, and the pure pointing
//! module of `handeye-vision` (`PointingTracker`) reading only those frames. The judge's
//! ground truth (where the finger's line really meets the working plane) is used to score,
//! never given to the tracker.
//!
//! The plane maps are fitted from the calibration cage's four lower points and their pixels.
//! Here those pixels come from the simulator's camera projection of the cage points: that
//! stands in for the cage positions the daemon measures during calibration (the tracked
//! plate at each lower cage point), which is where the daemon will take them from.
//!
//! The arm stands where the daemon's point phase parks it (`daemon.toml` `[point] park_m`,
//! default `[0.18, 0, 0.14]`: towards its base, where no hand comes from), not at home in
//! front of the hand: the daemon moves it there before it watches for a gesture.
//!
//! Acceptance: the indicated point within 10 mm of the aim point at the median and within
//! 20 mm at the 90th percentile; degenerate gestures reported, never answered; the block
//! nearest the indicated point is the one pointed at. Run with
//! `cargo test -p handeye-sim --test pointing_sim -- --nocapture` to see every gesture;
//! with `HANDEYE_POINTING_DEBUG=DIR` it also writes each gesture's last stereo frame and its
//! background (`seedN.pgm`, `seedN-bg.pgm`) and says what each view's silhouette gave.
//! Needs a Vulkan adapter (lavapipe on GPU-less machines).

use std::path::Path;
use std::time::Instant;

use handeye_sim::render::Renderer;
use handeye_sim::{Scenario, Simulator};
use handeye_vision::pointing::{GestureConfig, GestureState, PointingTracker};

mod pointing_support;
use pointing_support::{ensure_runtime_dir, plane_maps, views, POINT_PARK_M, SCENARIO};

const GESTURES: u64 = 30;

struct Outcome {
    seed: u64,
    state: GestureState,
    error_m: Option<f64>,
    picks_target: Option<bool>,
}

#[test]
fn thirty_rendered_gestures_indicate_where_the_hand_aimed() {
    ensure_runtime_dir();
    let base = Scenario::parse(SCENARIO, Path::new("point_clutter3.toml")).unwrap();
    let mut renderer: Option<Renderer> = None;
    let mut outcomes = Vec::new();
    let mut update_us = Vec::new();
    for seed in 1..=GESTURES {
        let mut scenario = base.clone();
        assert!(scenario.randomise_layout(seed), "seed {seed}: layout");
        // The gesture early in the run (the arm stands parked throughout): only its
        // timing changes, not where it points from or at.
        scenario.pointer.as_mut().unwrap().at_s = 1.0;
        // The arm parked out of the hand's way, as the daemon parks it before watching.
        scenario.arm.home_m = POINT_PARK_M;
        let mut sim = Simulator::new(scenario).unwrap();
        let r = renderer.get_or_insert_with(|| {
            Renderer::for_scene_with(&sim.scene, &sim.events.cameras, sim.scenario.render.antialias).expect("a Vulkan adapter (lavapipe)")
        });
        let (w, h) = (r.width() as usize, r.height() as usize);
        let mut gray = vec![0u8; r.frame_bytes()];
        let mut poses = Vec::new();
        let mut render = |sim: &Simulator, gray: &mut Vec<u8>| {
            sim.object_poses(&mut poses);
            r.render(&sim.frame_input(&poses), gray).unwrap();
        };
        let mut tracker = PointingTracker::new(plane_maps(&sim), GestureConfig::default());
        let gesture = sim.pointer.clone().unwrap();
        let [hold_from, hold_to] = gesture.hold_s();
        let t = |sim: &Simulator| sim.now_ns() as f64 * 1e-9;
        // The scene before the hand, then the last part of its way in and the hold.
        while t(&sim) < 0.9 {
            sim.step_frame();
        }
        render(&sim, &mut gray);
        let [l, r] = views(&gray, w, h);
        tracker.set_background(&l, &r);
        let tracker_background = gray.clone();
        while t(&sim) < hold_from - 0.2 {
            sim.step_frame();
        }
        // As the daemon's point phase watches: a refusal does not end the watch while the
        // hand holds (its window may settle into an answer); a hand unanswered by the end of
        // the hold is refused with its newest refusal (one from a steady window first).
        let mut state = GestureState::Absent;
        let mut refusal = None;
        while t(&sim) < hold_to {
            sim.step_frame();
            render(&sim, &mut gray);
            let [l, r] = views(&gray, w, h);
            let start = Instant::now();
            state = tracker.update(&l, &r);
            update_us.push(start.elapsed().as_secs_f64() * 1e6);
            match state {
                GestureState::Indicated(_) => break,
                // One from a steady window stands over a later unsteady or no line.
                GestureState::Degenerate { .. } | GestureState::Uncertain { .. } | GestureState::Disagree { .. } => refusal = Some(state),
                GestureState::Unsteady { .. } | GestureState::NoLine { .. } => {
                    if !matches!(refusal, Some(GestureState::Degenerate { .. } | GestureState::Uncertain { .. } | GestureState::Disagree { .. })) {
                        refusal = Some(state);
                    }
                }
                GestureState::Absent | GestureState::Moving { .. } => {}
            }
        }
        if let (false, Some(r)) = (matches!(state, GestureState::Indicated(_)), refusal) {
            state = r;
        }
        if let Some(dir) = std::env::var_os("HANDEYE_POINTING_DEBUG") {
            // The last frame and the background as PGM, and why each view found no arm.
            let dir = Path::new(&dir);
            std::fs::create_dir_all(dir).unwrap();
            let mut pgm = format!("P5 {w} {} 255\n", 2 * h).into_bytes();
            pgm.extend_from_slice(&gray);
            std::fs::write(dir.join(format!("seed{seed}.pgm")), pgm).unwrap();
            let mut finder = handeye_vision::pointing::SilhouetteFinder::new(Default::default());
            let bg = tracker_background.clone();
            let mut pgm = format!("P5 {w} {} 255\n", 2 * h).into_bytes();
            pgm.extend_from_slice(&bg);
            std::fs::write(dir.join(format!("seed{seed}-bg.pgm")), pgm).unwrap();
            let [l, r] = views(&gray, w, h);
            let [bl, br] = views(&bg, w, h);
            let t = gesture.truth(&sim.events.cameras, sim.now_ns());
            eprintln!("seed {seed}: truth {:?}, tip {:?} / {:?} px", t.phase, t.views[0].tip_px, t.views[1].tip_px);
            eprintln!("seed {seed}: left {:?}", finder.find(&bl, &l).map(|a| (a.tip_px, a.tail_px, a.sections)));
            eprintln!("seed {seed}: right {:?} ({} px)", finder.find(&br, &r).map(|a| (a.tip_px, a.tail_px, a.sections)), finder.changed_pixels());
        }
        if let GestureState::Indicated(p) = &state {
            // How far the found finger lines pass from the true images of the tip and the aim.
            let t = gesture.truth(&sim.events.cameras, sim.now_ns());
            let off = |v: usize, q: [f64; 2]| {
                let l = p.axes[v].line.0;
                l[0] * q[0] + l[1] * q[1] + l[2]
            };
            eprintln!(
                "seed {seed}: lines off the truth at tip / aim: left {:.1} / {:.1} px, right {:.1} / {:.1} px",
                off(0, t.views[0].tip_px),
                off(0, t.views[0].aim_px),
                off(1, t.views[1].tip_px),
                off(1, t.views[1].aim_px)
            );
        }
        let truth = gesture.aim_m;
        let (error_m, picks_target) = match state {
            GestureState::Indicated(p) => {
                let d2 = |b: &handeye_sim::scenario::BlockConfig| (b.position_m[0] - p.point_m[0]).powi(2) + (b.position_m[1] - p.point_m[1]).powi(2);
                let nearest = (0..sim.scenario.blocks.len()).min_by(|&a, &b| d2(&sim.scenario.blocks[a]).total_cmp(&d2(&sim.scenario.blocks[b]))).unwrap();
                (Some((p.point_m[0] - truth.x).hypot(p.point_m[1] - truth.y)), Some(nearest == sim.target_index()))
            }
            _ => (None, None),
        };
        eprintln!(
            "seed {seed:2}: az {:6.1}° el {:4.1}° aim error {:.1}° -> {}",
            gesture.azimuth_deg,
            gesture.elevation_deg,
            gesture.aim_error_deg,
            match state {
                GestureState::Indicated(p) => format!(
                    "{:5.1} mm off (sigma {:.1} mm, lines cross at {:.0}°){}",
                    error_m.unwrap() * 1e3,
                    p.sigma_m * 1e3,
                    p.crossing_rad.to_degrees(),
                    if picks_target == Some(true) { "" } else { ", NOT the target block" }
                ),
                other => format!("{other:?}"),
            }
        );
        outcomes.push(Outcome { seed, state, error_m, picks_target });
    }

    let mut errors: Vec<f64> = outcomes.iter().filter_map(|o| o.error_m).collect();
    errors.sort_by(f64::total_cmp);
    let rank = |q: f64| errors[((q * errors.len() as f64).ceil() as usize).clamp(1, errors.len()) - 1];
    let refused = |f: fn(&GestureState) -> bool| -> Vec<u64> { outcomes.iter().filter(|o| f(&o.state)).map(|o| o.seed).collect() };
    let degenerate = refused(|s| matches!(s, GestureState::Degenerate { .. }));
    let uncertain = refused(|s| matches!(s, GestureState::Uncertain { .. }));
    let no_line = refused(|s| matches!(s, GestureState::NoLine { .. }));
    let unsteady = refused(|s| matches!(s, GestureState::Unsteady { .. }));
    let disagree = refused(|s| matches!(s, GestureState::Disagree { .. }));
    let unanswered = refused(|s| matches!(s, GestureState::Absent | GestureState::Moving { .. }));
    update_us.sort_by(f64::total_cmp);
    eprintln!(
        "{} of {GESTURES} indicated: median {:.1} mm, p90 {:.1} mm, max {:.1} mm; reported instead: degenerate {degenerate:?}, uncertain {uncertain:?}, no line in a view {no_line:?}, unsteady {unsteady:?}, disagree {disagree:?}; nothing by the end of the hold {unanswered:?}; update p50 {:.0} µs, max {:.0} µs",
        errors.len(),
        rank(0.5) * 1e3,
        rank(0.9) * 1e3,
        errors.last().unwrap() * 1e3,
        update_us[update_us.len() / 2],
        update_us.last().unwrap()
    );
    // Every gesture ends in an answer or a stated refusal before the hand goes, but for a hand
    // that never came into view.
    for seed in &unanswered {
        let o = &outcomes[(*seed - 1) as usize];
        assert!(matches!(o.state, GestureState::Absent), "seed {seed}: still {:?} at the end of the hold", o.state);
    }
    // 21 of 30 answered with the finger found as a part of its own in a blob-shaped
    // silhouette (seed 14: a hand seen from the front), 20 before, with the arm parked out of
    // the hand's way and the watch going on after a refusal while the hand holds (18 when the
    // first refusal ended it, 17 with the arm at home in front of the hand; BENCHMARKS.md,
    // Pointing): the refusals are the point of the design (never a guess; the operator points
    // again), but fewer answers than this is a regression.
    assert!(errors.len() >= 20, "only {} of {GESTURES} gestures gave a point", errors.len());
    assert!(rank(0.5) <= 0.010, "median error {:.1} mm", rank(0.5) * 1e3);
    assert!(rank(0.9) <= 0.020, "90th percentile error {:.1} mm", rank(0.9) * 1e3);
    let wrong: Vec<u64> = outcomes.iter().filter(|o| o.picks_target == Some(false)).map(|o| o.seed).collect();
    assert!(wrong.is_empty(), "the block nearest the indicated point is not the one pointed at for seeds {wrong:?}");
}

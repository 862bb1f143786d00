//! Every gesture of a batch run's operator, repeats included, on rendered frames (issue 19):
//! `point_clutter3.toml` laid out by each seed of `HANDEYE_POINTING_SEEDS` (default `14,15`,
//! the batch's gestures from the cameras' side), the arm parked, the operator pointing again
//! 4 s after each gesture (the arm never reacts), and `PointingTracker` reading the frames as
//! `pointing_sim` does. Says what each gesture gave and writes, under
//! `HANDEYE_POINTING_DEBUG` (default `/tmp/handeye-pointing`), each gesture's frame mid-hold,
//! its background and the frame with the finger part marked (`sSgK*.pgm`). A diagnosis tool,
//! not an acceptance test (that is `pointing_sim`): run with
//! `cargo test -p handeye-sim --test pointing_repeats -- --ignored --nocapture`. With
//! `HANDEYE_POINTING_TRACE` set, it also prints each frame's axis in both views (tip, the
//! silhouette's end, centroid, pixels, sections, finger part) and the gesture's state.
use std::path::Path;

use handeye_sim::render::Renderer;
use handeye_sim::{Scenario, Simulator};
use handeye_vision::pointing::{GestureConfig, GestureState, PointingTracker, SilhouetteFinder};

mod pointing_support;
use pointing_support::{ensure_runtime_dir, plane_maps, views, POINT_PARK_M, SCENARIO};

#[test]
#[ignore = "diagnosis: renders three gestures per seed"]
fn every_gesture_of_the_seeds() {
    let seeds: Vec<u64> = std::env::var("HANDEYE_POINTING_SEEDS")
        .unwrap_or("14,15".into())
        .split(',')
        .map(|s| {
            s.trim()
                .parse()
                .expect("HANDEYE_POINTING_SEEDS: comma-separated seeds")
        })
        .collect();
    ensure_runtime_dir();
    let dir = std::env::var("HANDEYE_POINTING_DEBUG").unwrap_or("/tmp/handeye-pointing".into());
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir).unwrap();
    let base = Scenario::parse(SCENARIO, Path::new("point_clutter3.toml")).unwrap();
    let mut renderer: Option<Renderer> = None;
    let mut tally = (0, 0);
    let trace = std::env::var("HANDEYE_POINTING_TRACE").is_ok();
    let mut trace_finder = SilhouetteFinder::new(Default::default());
    for seed in seeds {
        let mut scenario = base.clone();
        assert!(scenario.randomise_layout(seed));
        scenario.pointer.as_mut().unwrap().at_s = 1.0;
        scenario.arm.home_m = POINT_PARK_M;
        let mut sim = Simulator::new(scenario).unwrap();
        let r = renderer.get_or_insert_with(|| {
            Renderer::for_scene_with(
                &sim.scene,
                &sim.events.cameras,
                sim.scenario.render.antialias,
            )
            .unwrap()
        });
        let (w, h) = (r.width() as usize, r.height() as usize);
        let mut gray = vec![0u8; r.frame_bytes()];
        let mut poses = Vec::new();
        let mut render = |sim: &Simulator, gray: &mut Vec<u8>| {
            sim.object_poses(&mut poses);
            r.render(&sim.frame_input(&poses), gray).unwrap();
        };
        let t = |sim: &Simulator| sim.now_ns() as f64 * 1e-9;
        let mut bg = Vec::new();
        for k in 0..3 {
            if k == 0 {
                while t(&sim) < 0.9 {
                    sim.step_frame();
                }
                render(&sim, &mut gray);
                bg = gray.clone();
            }
            let gesture = sim.pointer.clone().unwrap();
            let [hold_from, hold_to] = gesture.hold_s();
            let mut tracker = PointingTracker::new(plane_maps(&sim), GestureConfig::default());
            {
                let [l, r] = views(&bg, w, h);
                tracker.set_background(&l, &r);
            }
            while t(&sim) < hold_from - 0.2 {
                sim.step_frame();
            }
            let mut state = GestureState::Absent;
            let mut refusal = None;
            let mut mid = None;
            while t(&sim) < hold_to {
                sim.step_frame();
                render(&sim, &mut gray);
                if mid.is_none() && t(&sim) > hold_from + 0.5 {
                    mid = Some(gray.clone());
                }
                let [l, r] = views(&gray, w, h);
                state = tracker.update(&l, &r);
                if trace {
                    let [bl, br] = views(&bg, w, h);
                    let f = |a: Result<handeye_vision::pointing::ArmAxis, _>, finder: &SilhouetteFinder| match a {
                        Ok(a) => format!(
                            "tip ({:.0},{:.0}) end ({:.0},{:.0}) cen ({:.1},{:.1}) n{} s{} part{}",
                            a.tip_px[0], a.tip_px[1], a.end_px[0], a.end_px[1], a.centroid_px[0], a.centroid_px[1], a.pixels, a.sections,
                            finder.finger_part_pixels().len()
                        ),
                        Err(e) => format!("{e:?}"),
                    };
                    let al = trace_finder.find(&bl, &l);
                    let sl = f(al, &trace_finder);
                    let ar = trace_finder.find(&br, &r);
                    let sr = f(ar, &trace_finder);
                    eprintln!("   t {:.2} L {sl} | R {sr} -> {}", t(&sim), match state { GestureState::Moving { .. } => "moving".to_string(), s => format!("{s:?}").chars().take(40).collect() });
                }
                match state {
                    GestureState::Indicated(_) => break,
                    GestureState::Degenerate { .. } | GestureState::Uncertain { .. } | GestureState::Disagree { .. } => {
                        refusal = Some(state)
                    }
                    GestureState::Unsteady { .. } | GestureState::NoLine { .. } => {
                        if !matches!(
                            refusal,
                            Some(GestureState::Degenerate { .. } | GestureState::Uncertain { .. } | GestureState::Disagree { .. })
                        ) {
                            refusal = Some(state);
                        }
                    }
                    _ => {}
                }
            }
            if let (false, Some(r)) = (matches!(state, GestureState::Indicated(_)), refusal) {
                state = r;
            }
            let frame = mid.unwrap_or(gray.clone());
            let write = |name: String, data: &[u8]| {
                let mut pgm = format!("P5 {w} {} 255\n", 2 * h).into_bytes();
                pgm.extend_from_slice(data);
                std::fs::write(dir.join(name), pgm).unwrap();
            };
            write(format!("s{seed}g{k}.pgm"), &frame);
            write(format!("s{seed}g{k}-bg.pgm"), &bg);
            let tr = gesture.truth(&sim.events.cameras, sim.now_ns());
            let mut finder = SilhouetteFinder::new(Default::default());
            let [l, r] = views(&frame, w, h);
            let [bl, br] = views(&bg, w, h);
            eprintln!(
                "seed {seed} g{k}: az {:.1} el {:.1} h {:.3}; truth tip {:?}/{:?} elbow {:?}/{:?}",
                gesture.azimuth_deg,
                gesture.elevation_deg,
                gesture.tip_m.z,
                tr.views[0].tip_px,
                tr.views[1].tip_px,
                tr.views[0].elbow_px,
                tr.views[1].elbow_px
            );
            let mut marked: Vec<u8> = frame.iter().map(|g| g / 2).collect();
            eprintln!(
                "  left {:?}",
                finder
                    .find(&bl, &l)
                    .map(|a| (a.tip_px, a.tail_px, a.sections, a.angle_sigma_rad))
            );
            for &(x, y) in finder.finger_part_pixels() {
                marked[usize::from(y) * w + usize::from(x)] = 255;
            }
            eprintln!(
                "  right {:?}",
                finder
                    .find(&br, &r)
                    .map(|a| (a.tip_px, a.tail_px, a.sections, a.angle_sigma_rad))
            );
            for &(x, y) in finder.finger_part_pixels() {
                marked[(usize::from(y) + h) * w + usize::from(x)] = 255;
            }
            write(format!("s{seed}g{k}-finger.pgm"), &marked);
            let aim = gesture.aim_m;
            // The mid-hold frame alone: how far each view's line passes from the truth's tip
            // and aim (a line through the tip that misses the aim is turned: a direction bias),
            // and how far the point the two lines give is from the aim.
            let single = [finder.find(&bl, &l), finder.find(&br, &r)];
            for (v, a) in single.iter().enumerate() {
                if let Ok(a) = a {
                    let d = |q: [f64; 2]| a.line.0[0] * q[0] + a.line.0[1] * q[1] + a.line.0[2];
                    eprintln!(
                        "  mid-hold {}: aim {:.1} px, tip {:.1} px off the line ({} sections)",
                        ["left", "right"][v],
                        d(tr.views[v].aim_px),
                        d(tr.views[v].tip_px),
                        a.sections
                    );
                }
            }
            if let [Ok(a), Ok(b)] = &single {
                if let Ok(hit) = tracker.pointing.indicate(&a.line, &b.line) {
                    eprintln!(
                        "  mid-hold point {:.1} mm off the aim",
                        (hit.point_m[0] - aim.x).hypot(hit.point_m[1] - aim.y) * 1e3
                    );
                }
            }
            match state {
                GestureState::Indicated(p) => {
                    tally.0 += 1;
                    let off = |v: usize, q: [f64; 2]| {
                        let l = p.axes[v].line.0;
                        l[0] * q[0] + l[1] * q[1] + l[2]
                    };
                    let end_off = |v: usize| off(v, p.axes[v].end_px);
                    eprintln!("  end off the line L {:.1} R {:.1} px; sections L {} R {}", end_off(0), end_off(1), p.axes[0].sections, p.axes[1].sections);
                    eprintln!(
                        "  -> {:.1} mm off, sigma {:.1} mm, crossing {:.0}°; lines off tip/aim L {:.1}/{:.1} R {:.1}/{:.1}",
                        (p.point_m[0] - aim.x).hypot(p.point_m[1] - aim.y) * 1e3,
                        p.sigma_m * 1e3,
                        p.crossing_rad.to_degrees(),
                        off(0, tr.views[0].tip_px),
                        off(0, tr.views[0].aim_px),
                        off(1, tr.views[1].tip_px),
                        off(1, tr.views[1].aim_px)
                    );
                }
                other => {
                    tally.1 += 1;
                    eprintln!("  -> {other:?}")
                }
            }
            // On to the next gesture (the scene without the hand once it has gone).
            while t(&sim) < hold_to + 1.2 {
                sim.step_frame();
            }
            render(&sim, &mut gray);
            bg = gray.clone();
            while sim.pointer.as_ref().unwrap().hold_s() == gesture.hold_s()
                && t(&sim) < hold_to + 12.0
            {
                sim.step_frame();
            }
            if sim.pointer.as_ref().unwrap().hold_s() == gesture.hold_s() {
                break;
            }
        }
    }
    eprintln!("answered {} refused {}", tally.0, tally.1);
}

//! Timing of the geometry parts of `handeye-vision`: one coplanarity-servo step (runs in the
//! hard loop), one pointing intersection, one per-frame pointing-gesture update, grasp planning on a 10-block scene, and gripper
//! location by differencing on a 640x480 pair. Run: `cargo bench -p handeye-vision --bench geometry`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use handeye_vision::affine::AffineStereo;
use handeye_vision::grasp::{plan_grasps, GraspConfig, GraspScene, SceneFacet, Segment3};
use handeye_vision::image::ImageBuf;
use handeye_vision::locate::{locate_moving, LocateConfig};
use handeye_vision::pointing::{GestureConfig, ImageLine, PlaneHomography, Pointing, PointingTracker};
use handeye_vision::servo::{ViewFrame, CoplanarityServo, GripperView, ServoConfig, ServoGoal, ServoModel, StepOutcome, StereoFrame, StereoPoint};
use nalgebra::{Matrix4x3, Vector3, Vector4};
use std::hint::black_box;

fn servo_step(c: &mut Criterion) {
    let m = Matrix4x3::new(700.0, -350.0, 0.0, -90.0, -190.0, -690.0, 650.0, 420.0, 0.0, -110.0, 180.0, -690.0);
    let cv = Vector4::new(320.0, 300.0, 310.0, 290.0);
    let model = ServoModel::new(&AffineStereo { m, c: cv, residual_rms_px: 0.0, disparity_range_px: [0.0; 2] }).unwrap();
    let project = |x: Vector3<f64>| {
        let w = m * x + cv;
        StereoPoint { left: [w[0], w[1]], right: [w[2], w[3]] }
    };
    let frame = |o: Vector3<f64>, a: Vector3<f64>, b: Vector3<f64>| {
        let (po, pa, pb) = (project(o), project(o + a), project(o + b));
        let d = |p: [f64; 2], q: [f64; 2]| [q[0] - p[0], q[1] - p[1]];
        StereoFrame {
            left: ViewFrame { o: po.left, e1: d(po.left, pa.left), e2: d(po.left, pb.left) },
            right: ViewFrame { o: po.right, e1: d(po.right, pa.right), e2: d(po.right, pb.right) },
        }
    };
    let target = frame(Vector3::new(0.5, 0.0, 0.04), Vector3::new(0.0, 0.04, 0.0), Vector3::new(0.0, 0.0, -0.04));
    let view = |tool: Vector3<f64>, yaw: f64| {
        let (s, c) = yaw.sin_cos();
        let at = |y: f64, z: f64| tool + Vector3::new(-s * y, c * y, z);
        let (a, b) = (project(at(-0.035, 0.03)), project(at(0.035, 0.03)));
        GripperView {
            marks: [a, b, project(at(0.0, 0.08))],
            reference: project(at(0.0, 0.05)),
            axis: StereoPoint { left: [b.left[0] - a.left[0], b.left[1] - a.left[1]], right: [b.right[0] - a.right[0], b.right[1] - a.right[1]] },
        }
    };
    let goal_tool = Vector3::new(0.5, 0.02, 0.06);
    let goal = ServoGoal::teach(&model, &target, &view(goal_tool, 0.0)).unwrap();
    // One whole closed loop per iteration: start 60 mm and 0.2 rad off, step until converged.
    let run = |servo: &mut CoplanarityServo| {
        servo.reset();
        let (mut tool, mut yaw) = (Vector3::new(0.56, -0.03, 0.1), 0.2);
        loop {
            let s = servo.step(&target, &view(tool, yaw), &goal);
            tool += s.motion.translation_m;
            yaw += s.motion.yaw_rad;
            if s.outcome != StepOutcome::Move {
                assert_eq!(s.outcome, StepOutcome::Converged);
                return servo.steps();
            }
        }
    };
    for broyden in [false, true] {
        let mut servo = CoplanarityServo::new(model, ServoConfig { broyden, ..Default::default() }).unwrap();
        let steps = run(&mut servo);
        let mut group = c.benchmark_group(if broyden { "servo loop, Broyden on" } else { "servo loop" });
        // Reported per step (the loop converges in `steps` steps).
        group.throughput(Throughput::Elements(steps as u64));
        group.bench_function(format!("{steps} steps to convergence"), |b| b.iter(|| black_box(run(&mut servo))));
        group.finish();
    }
}

fn pointing(c: &mut Criterion) {
    let plane = [[0.4, -0.1], [0.6, -0.1], [0.6, 0.1], [0.4, 0.1]];
    let see = |h: [[f64; 3]; 3], p: [f64; 2]| {
        let w = h[2][0] * p[0] + h[2][1] * p[1] + h[2][2];
        [(h[0][0] * p[0] + h[0][1] * p[1] + h[0][2]) / w, (h[1][0] * p[0] + h[1][1] * p[1] + h[1][2]) / w]
    };
    let hl = [[900.0, 150.0, -150.0], [60.0, -800.0, 420.0], [0.2, 0.1, 1.0]];
    let hr = [[850.0, -200.0, -60.0], [-40.0, -780.0, 400.0], [-0.1, 0.2, 1.0]];
    let fit = |h| PlaneHomography::fit(&plane, &plane.map(|p| see(h, p))).unwrap();
    c.bench_function("pointing: fit one plane map (4 points)", |b| b.iter(|| black_box(fit(black_box(hl)))));
    let p = Pointing::new(fit(hl), fit(hr));
    let l = ImageLine::through(&see(hl, [0.45, -0.05]), &see(hl, [0.5, 0.02])).unwrap();
    let r = ImageLine::through(&see(hr, [0.58, 0.0]), &see(hr, [0.5, 0.02])).unwrap();
    c.bench_function("pointing: indicated point", |b| b.iter(|| black_box(p.indicate(black_box(&l), black_box(&r)))));

    // The per-frame update of a held pointing gesture: differencing and the finger's line in
    // both 640x480 views, steadiness, the plane lines' intersection and its uncertainty.
    let scene = |seed: usize| {
        let mut img = ImageBuf::filled(640, 480, 40);
        for k in 0..6 {
            let (x0, y0, g) = ((seed * 97 + k * 131) % 560, (seed * 53 + k * 71) % 400, (80 + k * 25) as u8);
            for y in y0..y0 + 50 {
                for x in x0..x0 + 50 {
                    img.set(x, y, g);
                }
            }
        }
        img
    };
    let with_arm = |base: &ImageBuf, tip: [f64; 2], elbow: [f64; 2]| {
        let mut img = base.clone();
        let (dx, dy) = (elbow[0] - tip[0], elbow[1] - tip[1]);
        let len = dx.hypot(dy);
        for y in 0..480 {
            for x in 0..640 {
                let (px, py) = (x as f64 - tip[0], y as f64 - tip[1]);
                let (s, t) = ((px * dx + py * dy) / len, ((-px * dy + py * dx) / len).abs());
                if (0.0..=len).contains(&s) && t <= if s < 0.2 * len { 5.0 } else { 14.0 } {
                    img.set(x, y, 190);
                }
            }
        }
        img
    };
    let (bl, br) = (scene(1), scene(2));
    let (fl, fr) = (with_arm(&bl, [300.0, 300.0], [520.0, 60.0]), with_arm(&br, [280.0, 310.0], [80.0, 80.0]));
    let mut tracker = PointingTracker::new(p, GestureConfig::default());
    tracker.set_background(&bl.view(), &br.view());
    for _ in 0..12 {
        tracker.update(&fl.view(), &fr.view());
    }
    c.bench_function("pointing: gesture update, 640x480 pair (arm held still)", |b| b.iter(|| black_box(tracker.update(&fl.view(), &fr.view()))));
}

fn grasp(c: &mut Criterion) {
    let p = Vector3::new;
    let face = |poly: Vec<Vector3<f64>>, component| {
        let edges = (0..poly.len()).map(|i| Segment3::new(poly[i], poly[(i + 1) % poly.len()])).collect();
        SceneFacet { polygon_m: poly, edges, component }
    };
    // Ten 40 mm blocks in two rows: front and top faces of each.
    let mut facets = Vec::new();
    for k in 0..10 {
        let (x0, y0) = (0.35 + 0.1 * (k / 5) as f64, -0.2 + 0.08 * (k % 5) as f64);
        let (x1, y1, h) = (x0 + 0.04, y0 + 0.04, 0.04);
        facets.push(face(vec![p(x1, y0, 0.0), p(x1, y1, 0.0), p(x1, y1, h), p(x1, y0, h)], k));
        facets.push(face(vec![p(x0, y0, h), p(x1, y0, h), p(x1, y1, h), p(x0, y1, h)], k));
    }
    let scene = GraspScene { facets, edges: vec![], toward_viewer: p(1.0, 0.2, 0.7) };
    let indicated = p(0.5, 0.0, 0.05);
    let plan = plan_grasps(&scene, Some(&indicated), &GraspConfig::default()).unwrap();
    assert_eq!(plan.candidates.len(), 10);
    c.bench_function("grasp planning: 10 blocks, 20 facets", |b| b.iter(|| black_box(plan_grasps(black_box(&scene), Some(&indicated), &GraspConfig::default()))));
}

fn locate(c: &mut Criterion) {
    let (w, h) = (640, 480);
    let mut open = ImageBuf::new(w, h);
    let mut seed = 1u64;
    for v in open.data.iter_mut() {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        *v = 100 + ((seed >> 60) as u8);
    }
    let mut closed = open.clone();
    let finger = |img: &mut ImageBuf, x0: usize| {
        for y in 200..230 {
            for x in x0..x0 + 12 {
                img.set(x, y, 230);
            }
        }
    };
    finger(&mut open, 280);
    finger(&mut open, 350);
    finger(&mut closed, 300);
    finger(&mut closed, 330);
    let m = locate_moving(&open.view(), &closed.view(), &LocateConfig::default()).unwrap();
    assert_eq!(m.blobs.len(), 4);
    c.bench_function("locate by differencing: 640x480", |b| b.iter(|| black_box(locate_moving(&open.view(), &closed.view(), &LocateConfig::default()))));
}

criterion_group! {
    name = geometry;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(2)).warm_up_time(std::time::Duration::from_millis(500));
    targets = servo_step, pointing, grasp, locate
}
criterion_main!(geometry);

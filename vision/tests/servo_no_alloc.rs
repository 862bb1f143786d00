//! The servo step runs in the daemon's hard loop: it must not touch the heap. A counting
//! global allocator (this test binary only) checks that a whole servo run allocates nothing.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use handeye_vision::affine::AffineStereo;
use handeye_vision::servo::{ViewFrame, CoplanarityServo, GripperView, ServoConfig, ServoGoal, ServoModel, StepOutcome, StereoFrame, StereoPoint};
use nalgebra::{Matrix4x3, Vector3, Vector4};

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(|c| c.get())
}

#[test]
fn a_servo_run_does_not_allocate() {
    // Exact affine cameras, a vertical target facet, a gripper plate 60 mm off it and turned.
    let m = Matrix4x3::new(700.0, -350.0, 0.0, -90.0, -190.0, -690.0, 650.0, 420.0, 0.0, -110.0, 180.0, -690.0);
    let c = Vector4::new(320.0, 300.0, 310.0, 290.0);
    let model = ServoModel::new(&AffineStereo { m, c, residual_rms_px: 0.0, disparity_range_px: [0.0, 0.0] }).unwrap();
    let project = |x: Vector3<f64>| {
        let w = m * x + c;
        StereoPoint { left: [w[0], w[1]], right: [w[2], w[3]] }
    };
    let frame_of = |o: Vector3<f64>, a: Vector3<f64>, b: Vector3<f64>| {
        let (po, pa, pb) = (project(o), project(o + a), project(o + b));
        let d = |p: [f64; 2], q: [f64; 2]| [q[0] - p[0], q[1] - p[1]];
        StereoFrame {
            left: ViewFrame { o: po.left, e1: d(po.left, pa.left), e2: d(po.left, pb.left) },
            right: ViewFrame { o: po.right, e1: d(po.right, pa.right), e2: d(po.right, pb.right) },
        }
    };
    // Facet in the plane x = 0.5, normal +x.
    let target = frame_of(Vector3::new(0.5, 0.0, 0.04), Vector3::new(0.0, 0.04, 0.0), Vector3::new(0.0, 0.0, -0.04));
    // The gripper: tool point and yaw; its plate is the plane through the marks below.
    let view = |tool: Vector3<f64>, yaw: f64| {
        let (s, c) = yaw.sin_cos();
        let at = |y: f64, z: f64| tool + Vector3::new(-s * y, c * y, z);
        let d = |p: StereoPoint, q: StereoPoint| StereoPoint { left: [q.left[0] - p.left[0], q.left[1] - p.left[1]], right: [q.right[0] - p.right[0], q.right[1] - p.right[1]] };
        GripperView {
            marks: [project(at(-0.035, 0.03)), project(at(0.035, 0.03)), project(at(0.0, 0.08))],
            reference: project(at(0.0, 0.05)),
            axis: d(project(at(-0.035, 0.03)), project(at(0.035, 0.03))),
        }
    };
    let goal = ServoGoal::teach(&model, &target, &view(Vector3::new(0.5, 0.02, 0.06), 0.0)).unwrap();
    let (mut tool, mut yaw) = (Vector3::new(0.56, -0.03, 0.1), 0.2);
    let mut servo = CoplanarityServo::new(model, ServoConfig { broyden: true, ..Default::default() }).unwrap();
    let mut steps = 0;
    let before = allocations();
    loop {
        let s = servo.step(&target, &view(tool, yaw), &goal);
        tool += s.motion.translation_m;
        yaw += s.motion.yaw_rad;
        steps += 1;
        if s.outcome != StepOutcome::Move || steps > 60 {
            assert_eq!(s.outcome, StepOutcome::Converged);
            break;
        }
    }
    let allocated = allocations() - before;
    assert_eq!(allocated, 0, "{allocated} heap allocations in {steps} servo steps");
    assert!((tool - Vector3::new(0.5, 0.02, 0.06)).norm() < 1e-3 && yaw.abs() < 0.01, "{tool:?} {yaw}");
    assert!(steps > 5, "the run should take several steps, took {steps}");
    // The counter does count.
    let mark = allocations();
    let v = std::hint::black_box(vec![1u8; 64]);
    assert_eq!(allocations(), mark + 1, "{}", v.len());
}

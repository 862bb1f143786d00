//! The daemon's hard loop driven in-process by the simulator (no shared memory): the same
//! code as `handeye run`, with the loop's inside visible. Proves the steady-state servo
//! cycle allocates nothing and that every frame is answered, also while the worker computes.

mod daemon_support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

use daemon_support::{scenario, InProcess};
use handeye_daemon::DaemonConfig;
use handeye_wire::{CommandKind, Phase};

/// Counts allocations made on the current thread while `COUNTING` is set.
struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(|c| c.get()) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Runs `f` counting this thread's allocations.
fn counted(f: &mut dyn FnMut()) -> u64 {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.load(Ordering::Relaxed) - before
}

#[test]
fn the_servo_cycles_allocate_nothing_and_every_frame_is_answered() {
    let mut run = InProcess::new(scenario("pick_cube.toml"), DaemonConfig::default());
    let (mut servo_cycles, mut servo_moves, mut servo_allocs) = (0u64, 0u64, 0u64);
    let mut busy_frames = 0;
    let mut entry_allocs = 0;
    let mut phases = Vec::new();
    for _ in 0..3000 {
        let before = run.daemon.phase();
        let mut allocs = 0;
        let frame = run.frame;
        let cmd = run.step_with(&mut |cycle| allocs = counted(cycle));
        let after = run.daemon.phase();
        // Exactly one command per frame, answering it.
        assert_eq!(cmd.frame_id, frame);
        assert_eq!(cmd.seq, frame + 1);
        if run.daemon.telemetry().planning == 1 {
            // The worker is computing: the loop still tracks and answers, and even moves the
            // arm (back from the cage while the calibration is fitted).
            busy_frames += 1;
        }
        if phases.last() != Some(&after) {
            phases.push(after);
        }
        // Steady state: a cycle that starts and ends in the servo (entering a phase builds
        // its state once).
        if before == Phase::AcquireTarget && after == Phase::Servo {
            entry_allocs = allocs;
        }
        if before == Phase::Servo && after == Phase::Servo {
            servo_cycles += 1;
            servo_allocs += allocs;
            servo_moves += u64::from(cmd.kind == CommandKind::MoveBy as u32);
        }
        if matches!(after, Phase::Done | Phase::Failed | Phase::Stopped) {
            break;
        }
    }
    assert_eq!(run.daemon.phase(), Phase::Done, "{:?}: {:?}", phases, run.daemon.failure());
    assert_eq!(
        phases,
        [Phase::AcquireGripper, Phase::Calibrate, Phase::AcquireTarget, Phase::Servo, Phase::Grasp, Phase::Lift, Phase::Done]
    );
    assert!(servo_cycles > 30 && servo_moves >= 3, "{servo_cycles} servo cycles, {servo_moves} moves");
    assert_eq!(servo_allocs, 0, "{servo_allocs} allocations in {servo_cycles} servo cycles");
    // The counter works: building the servo's state on entry does allocate.
    assert!(entry_allocs > 0);
    assert!(busy_frames >= 2, "the worker was never seen busy ({busy_frames} frames)");
    // The simulator judged the convergence from ground truth.
    let c = run.runner.watch.converged.expect("converged placement");
    assert!(c.final_plane_error_mm < 5.0 && c.final_angle_error_deg < 5.0, "{c:?}");
}

#[test]
fn a_robot_fault_stops_the_arm_with_the_reason() {
    let mut run = InProcess::new(scenario("pick_cube.toml"), DaemonConfig::default());
    // Run into the calibration, then make the robot report a fault.
    while run.daemon.phase() != Phase::Calibrate {
        run.step();
        assert!(run.frame < 1000, "no calibration: {:?}", run.daemon.failure());
    }
    for _ in 0..5 {
        run.step();
    }
    let mut state = run.runner.sim.robot_state();
    state.flags |= handeye_wire::robot_flags::FAULT;
    state.fault = 9;
    run.daemon.robot_state(&state);
    let cmd = run.step();
    assert_eq!(cmd.kind, CommandKind::Stop as u32);
    assert_eq!(run.daemon.phase(), Phase::Stopped);
    assert!(run.daemon.telemetry().reason_text().contains("robot fault (code 9)"), "{}", run.daemon.telemetry().reason_text());
    // Afterwards it holds; the stop is not repeated.
    assert_eq!(run.step().kind, CommandKind::Hold as u32);
    let o = run.daemon.outcome(0.0);
    assert!(!o.end.success);
    assert_eq!(o.end.phase_reached, "calibrate");
    assert_eq!(o.end.final_phase, "stopped");
}


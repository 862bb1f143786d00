//! Proves that tracker updates allocate nothing after construction: a counting global
//! allocator wraps the system one, and the count must not move across many stereo updates
//! (and re-initialisations with the same polygon size).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use handeye_vision::image::ImageBuf;
use handeye_vision::rng::SplitMix64;
use handeye_vision::tracker::synth::Scene;
use handeye_vision::tracker::{ContourTracker, Role, StereoTrackerSet, TrackerConfig, View};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards every call unchanged to the system allocator; only counts them.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn scene(dx: f64, polygon: [[f64; 2]; 4]) -> Scene {
    Scene {
        width: 200,
        height: 160,
        background: 170.0,
        background_slope: [0.1, 0.0],
        polygon: polygon.iter().map(|p| [p[0] + dx, p[1]]).collect(),
        foreground: 70.0,
        background_lines: vec![],
        texture_lines: vec![],
        blur_px: 0.8,
        noise: 3.0,
    }
}

#[test]
fn stereo_updates_and_reinit_allocate_nothing() {
    let square = [[60.0, 50.0], [130.0, 45.0], [135.0, 110.0], [55.0, 105.0]];
    let other = [[70.0, 60.0], [120.0, 58.0], [124.0, 100.0], [66.0, 98.0]];
    // Pre-render the frames so image making is outside the counted region.
    let mut rng = SplitMix64::new(3);
    let lefts: Vec<ImageBuf> = (0..40).map(|k| scene(0.4 * k as f64, square).render(&mut rng)).collect();
    let rights: Vec<ImageBuf> = (0..40).map(|k| scene(0.4 * k as f64 - 3.0, square).render(&mut rng)).collect();
    let config = TrackerConfig::default();
    let shifted: Vec<[f64; 2]> = square.iter().map(|p| [p[0] - 3.0, p[1]]).collect();
    let mut set = StereoTrackerSet::new();
    set.insert(Role::Gripper, View::Left, ContourTracker::new(config, &square).unwrap());
    set.insert(Role::Gripper, View::Right, ContourTracker::new(config, &shifted).unwrap());
    set.insert(Role::Target, View::Left, ContourTracker::new(config, &square).unwrap());
    set.insert(Role::Target, View::Right, ContourTracker::new(config, &shifted).unwrap());
    // One warm-up update, then count.
    set.update(&lefts[0].view(), &rights[0].view(), 0.0);
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut tracking = 0;
    for k in 1..40 {
        let states = set.update(&lefts[k].view(), &rights[k].view(), 1.0 / 30.0);
        tracking += states.all_active_tracking() as usize;
    }
    // Re-initialising with a polygon of the same size reuses the buffers too.
    set.get_mut(Role::Target, View::Left).unwrap().reinit(&other).unwrap();
    set.update(&lefts[39].view(), &rights[39].view(), 1.0 / 30.0);
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(after - before, 0, "updates allocated {} times", after - before);
    // The updates did real work: every contour kept tracking the moving square.
    assert_eq!(tracking, 39);
    let c = set.get(Role::Gripper, View::Left).unwrap().corners().next().unwrap();
    assert!((c.x - (60.0 + 0.4 * 39.0)).abs() < 1.0 && (c.y - 50.0).abs() < 1.0, "{c:?}");
    // And the counter does count: building a tracker allocates.
    let _extra = ContourTracker::new(config, &square).unwrap();
    assert!(ALLOCATIONS.load(Ordering::SeqCst) > after);
}

//! What the pointing tests on rendered frames share (`pointing_sim`, `pointing_repeats`):
//! the scenario, where the daemon parks the arm, the plane maps from the cage, the two views
//! of a stereo buffer and a runtime dir for the renderer.

use handeye_sim::Simulator;
use handeye_vision::image::ImageView;
use handeye_vision::pointing::{PlaneHomography, Pointing};

pub const SCENARIO: &str = include_str!("../../../scenarios/point_clutter3.toml");
/// The daemon's default `[point] park_m` (`handeye_daemon::config::PointSettings`).
pub const POINT_PARK_M: [f64; 3] = [0.18, 0.0, 0.14];

/// The two views of a stereo buffer (left rows, then right rows).
pub fn views(g: &[u8], w: usize, h: usize) -> [ImageView<'_>; 2] {
    [ImageView::new(&g[..w * h], w, h, w).unwrap(), ImageView::new(&g[w * h..], w, h, w).unwrap()]
}

/// The tracker's plane maps from the lower cage points and their projections: they stand in
/// for the cage positions the daemon measures during calibration.
pub fn plane_maps(sim: &Simulator) -> Pointing {
    let z = sim.scenario.cage.points_m.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min);
    let lower: Vec<[f64; 3]> = sim.scenario.cage.points_m.iter().copied().filter(|p| p[2] < z + 1e-9).collect();
    let plane: Vec<[f64; 2]> = lower.iter().map(|p| [p[0], p[1]]).collect();
    let fit = |v: usize| {
        let px: Vec<[f64; 2]> = lower.iter().map(|p| sim.events.cameras[v].project(glam::DVec3::from_array(*p)).expect("cage in view")).collect();
        PlaneHomography::fit(&plane, &px).expect("four lower cage points in general position")
    };
    Pointing::new(fit(0), fit(1))
}

/// A runtime dir for the renderer when the environment has none.
pub fn ensure_runtime_dir() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        let dir = std::env::temp_dir().join(format!("handeye-xdg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // SAFETY: set before any thread of this test binary's renderer exists.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
    }
}

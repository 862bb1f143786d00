//! Scenario files: the work cell, the cameras, the task and the scripted disturbances.
//!
//! A scenario is a TOML file (see `scenarios/*.toml` and `sim/README.md`). Every table rejects
//! unknown keys and every required key must be present; errors name the file, the line and
//! column, and the field path (`blocks[1].size_mm`), e.g.
//!
//! ```text
//! scenarios/bad.toml:14:1: blocks[0]: unknown field `colour`, expected one of `name`, `kind`, ...
//! ```
//!
//! All positions are in the robot frame: metres, z up, origin at the arm's base on the table
//! top (the table top is the plane z = 0). The arm's base therefore sits at the origin by
//! definition; the table, blocks and cameras are placed relative to it.

mod locate;
mod validate;

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::de::DeTable;

use crate::geometry::BlockKind;
use locate::{error_at, path_at, path_string, span_of};

/// A whole scenario, as read from its file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name, used in reports.
    pub name: String,
    /// One or two sentences on what the scenario exercises.
    #[serde(default)]
    pub description: String,
    /// Seed of every random choice (shades, sensor noise).
    pub seed: u64,
    pub physics: Physics,
    pub render: Render,
    pub table: Table,
    pub light: Light,
    pub arm: ArmConfig,
    /// Exactly two: `[[cameras]]` left then right.
    pub cameras: Vec<CameraConfig>,
    pub blocks: Vec<BlockConfig>,
    pub cage: Cage,
    pub task: Task,
    pub success: SuccessRule,
    #[serde(default)]
    pub events: Vec<Event>,
}

/// `[physics]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Physics {
    /// Physics steps per simulated second (the controller ticks at this rate too).
    pub rate_hz: u32,
    /// Gravity along -z, m/s².
    #[serde(default = "default_gravity")]
    pub gravity_mps2: f64,
}

fn default_gravity() -> f64 {
    9.81
}

/// `[render]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Render {
    /// Stereo frames per simulated second; must divide `physics.rate_hz`.
    pub frame_rate_hz: u32,
    /// Grey level of the background behind the table, 0..1.
    pub background: f64,
    /// Anti-alias the grey views (4x multisampling): edges get the sub-pixel grey a camera
    /// gives them, so trackers can place them to a fraction of a pixel (the servo's angle
    /// accuracy needs that); ~12 ms more per stereo frame on lavapipe. Default off.
    #[serde(default)]
    pub antialias: bool,
}

/// `[table]`: a box whose top face is the plane z = 0.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Table {
    /// Centre of the table top, x and y, metres.
    pub center_m: [f64; 2],
    /// Length (x) and width (y) of the table top, metres.
    pub size_m: [f64; 2],
    /// Albedo of the table top, 0..1.
    pub shade: f64,
    /// Coulomb friction coefficient.
    #[serde(default = "default_table_friction")]
    pub friction: f64,
}

fn default_table_friction() -> f64 {
    0.8
}

/// `[light]`: one directional light plus ambient light.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Light {
    /// Direction from the scene towards the light (any length but zero).
    pub direction: [f64; 3],
    /// Brightness of the directional light, 0..2.
    pub intensity: f64,
    /// Ambient light, 0..1.
    pub ambient: f64,
}

/// `[arm]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArmConfig {
    /// Tool point at start, metres (robot frame).
    pub home_m: [f64; 3],
    /// Tool yaw at start, degrees.
    #[serde(default)]
    pub home_yaw_deg: f64,
    /// Default tool speed limit when a command gives none, m/s.
    #[serde(default = "default_speed")]
    pub default_speed_mps: f64,
}

fn default_speed() -> f64 {
    0.15
}

/// `[[cameras]]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    /// `left` or `right` (the left camera is the first image of a stereo sample).
    pub name: String,
    /// Optical centre, metres.
    pub position_m: [f64; 3],
    /// The point the optical axis passes through, metres.
    pub look_at_m: [f64; 3],
    /// World direction that appears up in the image; default +z.
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    /// Focal length in pixels. Give this or `vfov_deg`.
    pub focal_px: Option<f64>,
    /// Vertical field of view, degrees. Give this or `focal_px`.
    pub vfov_deg: Option<f64>,
    /// Width and height in pixels (both cameras must agree).
    pub resolution: [u32; 2],
    /// Standard deviation of additive Gaussian sensor noise, grey levels (0..255 scale).
    #[serde(default)]
    pub noise_sigma: f64,
    /// Standard deviation of the Gaussian optical blur, pixels (0 = sharp, at most 2).
    #[serde(default)]
    pub blur_sigma_px: f64,
}

fn default_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// `[[blocks]]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockConfig {
    /// Unique name; tasks and events refer to blocks by it.
    pub name: String,
    pub kind: BlockKind,
    /// Bounding box in the block frame (x, y, z), millimetres, each 20..60.
    pub size_mm: [f64; 3],
    /// Centre of the block's footprint on the table, metres; the block rests on the table.
    pub position_m: [f64; 2],
    /// Rotation about z, degrees.
    #[serde(default)]
    pub yaw_deg: f64,
    /// Albedo per face (see `sim/README.md` for the face order of each kind), 0..1.
    /// Leave out for seeded random shades.
    pub shades: Option<Vec<f64>>,
    /// Seed of the random shades (when `shades` is absent); default derives from the
    /// scenario seed and the block's index.
    pub shade_seed: Option<u64>,
    /// kg/m³.
    #[serde(default = "default_density")]
    pub density_kg_m3: f64,
    #[serde(default = "default_block_friction")]
    pub friction: f64,
}

fn default_density() -> f64 {
    600.0
}

fn default_block_friction() -> f64 {
    0.9
}

/// `[cage]`: the eight points the gripper visits to calibrate the cameras.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cage {
    /// Exactly eight tool positions, metres (robot frame).
    pub points_m: Vec<[f64; 3]>,
}

/// `[task]`: what to pick. Give `target` or `point_m`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Task {
    /// Name of the block to pick.
    pub target: Option<String>,
    /// A point on the working plane (x, y, metres) indicated by the operator; the block
    /// nearest to it is the target.
    pub point_m: Option<[f64; 2]>,
}

/// `[success]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SuccessRule {
    /// The target must rise at least this far above its resting height, millimetres.
    pub lift_mm: f64,
    /// ... and stay there this long, seconds.
    pub hold_s: f64,
    /// The run fails if not done by then, seconds of simulated time.
    #[serde(default = "default_timeout")]
    pub timeout_s: f64,
}

fn default_timeout() -> f64 {
    120.0
}

/// `[[events]]`: a scripted disturbance (`kind = "..."`), starting at `at_s` seconds of
/// simulated time.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Event {
    /// A camera is knocked: it turns about its own axes (x right, y down, z forward) by
    /// `rotate_deg` (a rotation vector) and moves by `translate_mm` (camera axes).
    CameraBump {
        at_s: f64,
        camera: String,
        #[serde(default)]
        rotate_deg: [f64; 3],
        #[serde(default)]
        translate_mm: [f64; 3],
    },
    /// A block is pushed: moved by `translate_mm` (x, y) and turned by `rotate_deg` about z.
    TargetNudge {
        at_s: f64,
        block: String,
        #[serde(default)]
        translate_mm: [f64; 2],
        #[serde(default)]
        rotate_deg: f64,
    },
    /// A box (visible only, it touches nothing) crosses the scene from `from_m` to `to_m`
    /// in `duration_s` seconds.
    Occluder {
        at_s: f64,
        duration_s: f64,
        from_m: [f64; 3],
        to_m: [f64; 3],
        size_mm: [f64; 3],
        shade: f64,
    },
    /// The lighting changes to new values over `ramp_s` seconds (0 = at once).
    LightChange {
        at_s: f64,
        #[serde(default)]
        ramp_s: f64,
        intensity: f64,
        ambient: f64,
        direction: Option<[f64; 3]>,
    },
}

impl Event {
    /// When the event starts, seconds of simulated time.
    pub fn at_s(&self) -> f64 {
        match self {
            Self::CameraBump { at_s, .. }
            | Self::TargetNudge { at_s, .. }
            | Self::Occluder { at_s, .. }
            | Self::LightChange { at_s, .. } => *at_s,
        }
    }
}

/// A scenario that could not be read. Displays as `file:line:column: field: message`.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}:{line}:{column}: {field}: {message}", file.display())]
pub struct ScenarioError {
    pub file: PathBuf,
    /// 1-based; 0 when unknown.
    pub line: usize,
    /// 1-based; 0 when unknown.
    pub column: usize,
    /// Dotted path of the offending field, e.g. `blocks[1].size_mm`; `(file)` for the file.
    pub field: String,
    pub message: String,
}

impl Scenario {
    /// Reads and validates a scenario file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ScenarioError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
            file: path.to_path_buf(),
            line: 0,
            column: 0,
            field: "(file)".into(),
            message: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates scenario text; `file` is used in error messages only.
    ///
    /// ```
    /// let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/pick_cube.toml")).unwrap();
    /// let bad = text.replace("seed =", "sead =");
    /// let err = handeye_sim::scenario::Scenario::parse(&bad, "pick_cube.toml".as_ref()).unwrap_err();
    /// assert!(err.to_string().contains("sead"), "{err}");
    /// ```
    pub fn parse(text: &str, file: &Path) -> Result<Self, ScenarioError> {
        let doc = DeTable::parse(text).map_err(|e| error_at(file, text, None, e.span(), e.message()))?;
        let scenario: Scenario = toml::from_str(text).map_err(|e| {
            let field = e.span().map(|s| path_at(&doc, s.start)).unwrap_or_default();
            error_at(file, text, Some(field), e.span(), e.message())
        })?;
        scenario.validate().map_err(|(path, message)| {
            let span = span_of(&doc, &path);
            error_at(file, text, Some(path_string(&path)), span, &message)
        })?;
        Ok(scenario)
    }

    /// Seconds of simulated time per physics step.
    pub fn physics_dt_s(&self) -> f64 {
        1.0 / f64::from(self.physics.rate_hz)
    }

    /// Physics steps per stereo frame.
    pub fn substeps_per_frame(&self) -> u32 {
        self.physics.rate_hz / self.render.frame_rate_hz
    }

    /// Largest random shift of the target block (each of x and y), metres, and turn,
    /// degrees, of [`Self::randomise_target`].
    pub const RANDOM_SHIFT_M: f64 = 0.02;
    pub const RANDOM_TURN_DEG: f64 = 15.0;

    /// Uses `seed` for every random choice and moves the target block by a seeded random
    /// shift (uniform, ±[`Self::RANDOM_SHIFT_M`] in x and y) and turn (±[`Self::RANDOM_TURN_DEG`]),
    /// so that seeds give different block poses around the scenario's.
    pub fn randomise_target(&mut self, seed: u64) {
        self.seed = seed;
        let mut rng = handeye_vision::rng::SplitMix64::new(handeye_vision::rng::mix64(seed ^ 0x504f_5345));
        let mut u = || 2.0 * rng.next_f64() - 1.0;
        let t = self.target_index();
        let b = &mut self.blocks[t];
        b.position_m[0] += u() * Self::RANDOM_SHIFT_M;
        b.position_m[1] += u() * Self::RANDOM_SHIFT_M;
        b.yaw_deg += u() * Self::RANDOM_TURN_DEG;
    }

    /// Where [`Self::randomise_layout`] puts blocks: x and y ranges of their centres, metres
    /// (the calibration cage's footprint widened in y: in view of both cameras and in reach
    /// with the gripper's plate facing the cameras). Towards the cameras the whole block
    /// stays inside the x range (its bounding circle): the bottom rows of the images end
    /// ~0.47 m out, and a face cut by the image border cannot be tracked.
    pub const LAYOUT_X_M: [f64; 2] = [0.27, 0.45];
    pub const LAYOUT_Y_M: [f64; 2] = [-0.15, 0.15];
    /// Smallest gap between two blocks' bounding circles, metres: room for a finger of the
    /// fully opened jaws (40 mm from the grasp centre, 12 mm thick) beside a block.
    pub const LAYOUT_GAP_M: f64 = 0.06;
    /// Largest distance of the indicated point from the target block's centre, metres.
    pub const LAYOUT_POINT_OFFSET_M: f64 = 0.015;
    /// Least difference in rendered grey (0..1) between the two faces at each of a block's
    /// edges, and between a face and the table where it stands, that a random yaw must give:
    /// 12 grey levels of 255 (the sensor noise is 1.5), so that every edge shows.
    pub const LAYOUT_MIN_EDGE_CONTRAST: f64 = 12.0 / 255.0;
    /// Yaws drawn per block at most in search of one that shows every edge.
    pub const LAYOUT_YAW_DRAWS: usize = 32;

    /// A seeded random layout of the scenario's blocks (batch runs): uses `seed` for every
    /// random choice, then places every block (kind, size and shades as written) at a random
    /// position in [`Self::LAYOUT_X_M`] x [`Self::LAYOUT_Y_M`] (wholly inside the x range on
    /// the cameras' side) with a random yaw (any angle), at least [`Self::LAYOUT_GAP_M`]
    /// between any two blocks' bounding circles. A yaw at which an edge of the block that
    /// the cameras see would not show — its two faces, or a face and the table, rendered
    /// within [`Self::LAYOUT_MIN_EDGE_CONTRAST`] under the scenario's light — is drawn again
    /// (the design's "distinct face brightness so edges show": no camera, and no tracker,
    /// finds an edge of 4 grey levels).
    /// The task stays meaningful: with a named target, that block; with an indicated point,
    /// a random block becomes the target and the point is put within
    /// [`Self::LAYOUT_POINT_OFFSET_M`] of its centre (so it is the nearest block by far).
    /// Returns `false` (layout unchanged but for the seed) when the blocks do not fit.
    pub fn randomise_layout(&mut self, seed: u64) -> bool {
        self.randomise_layout_drawing(seed, Self::LAYOUT_YAW_DRAWS)
    }

    /// [`Self::randomise_layout`] with at most `yaw_draws` yaws per block (1: the first
    /// draw, whatever it hides).
    fn randomise_layout_drawing(&mut self, seed: u64, yaw_draws: usize) -> bool {
        self.seed = seed;
        let mut rng = handeye_vision::rng::SplitMix64::new(handeye_vision::rng::mix64(seed ^ 0x4c41_594f_5554));
        let radius = |b: &BlockConfig| 0.5e-3 * b.size_mm[0].hypot(b.size_mm[1]);
        // Up to 200 attempts at the whole layout, each placing the blocks in turn.
        for _ in 0..200 {
            let mut placed: Vec<([f64; 2], f64)> = Vec::with_capacity(self.blocks.len());
            for b in &self.blocks {
                let r = radius(b);
                let mut ok = None;
                for _ in 0..200 {
                    let x_max = (Self::LAYOUT_X_M[1] - r).max(Self::LAYOUT_X_M[0]);
                    let p = [
                        Self::LAYOUT_X_M[0] + rng.next_f64() * (x_max - Self::LAYOUT_X_M[0]),
                        Self::LAYOUT_Y_M[0] + rng.next_f64() * (Self::LAYOUT_Y_M[1] - Self::LAYOUT_Y_M[0]),
                    ];
                    if placed.iter().all(|(q, rq)| (p[0] - q[0]).hypot(p[1] - q[1]) >= r + rq + Self::LAYOUT_GAP_M) {
                        ok = Some(p);
                        break;
                    }
                }
                match ok {
                    Some(p) => placed.push((p, r)),
                    None => break,
                }
            }
            if placed.len() < self.blocks.len() {
                continue;
            }
            let (light, table_shade, seed) = (self.light.clone(), self.table.shade, self.seed);
            let cameras_m: Vec<[f64; 3]> = self.cameras.iter().map(|c| c.position_m).collect();
            for (index, (b, (p, _))) in self.blocks.iter_mut().zip(&placed).enumerate() {
                b.position_m = *p;
                // A yaw at which two neighbouring faces (or a face and the table) render
                // alike hides the edge between them from every camera: draw again (the
                // first draw stands whenever it shows every edge, so such layouts are as
                // before), keeping the clearest of a few draws.
                let mut best = (f64::NEG_INFINITY, 0.0);
                for _ in 0..yaw_draws.max(1) {
                    let yaw_deg = rng.next_f64() * 360.0 - 180.0;
                    let contrast = least_edge_contrast(b, index, seed, &light, table_shade, &cameras_m, yaw_deg);
                    if contrast > best.0 {
                        best = (contrast, yaw_deg);
                    }
                    if contrast >= Self::LAYOUT_MIN_EDGE_CONTRAST {
                        break;
                    }
                }
                b.yaw_deg = best.1;
            }
            if self.task.point_m.is_some() {
                let t = ((rng.next_f64() * self.blocks.len() as f64) as usize).min(self.blocks.len() - 1);
                let (angle, dist) = (rng.next_f64() * std::f64::consts::TAU, rng.next_f64() * Self::LAYOUT_POINT_OFFSET_M);
                let c = self.blocks[t].position_m;
                self.task.point_m = Some([c[0] + dist * angle.cos(), c[1] + dist * angle.sin()]);
            }
            return true;
        }
        false
    }

    /// The operator's indicated point on the working plane (robot frame, metres): the task's
    /// `point_m`, or, with a named target, that block's centre (where an operator would
    /// point). Its height is the working plane's, the lowest cage point's (thesis §6.3.1:
    /// the lower cage points define the plane the operator points at).
    pub fn indicated_point_m(&self) -> [f64; 3] {
        let z = self.cage.points_m.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min);
        let z = if z.is_finite() { z } else { 0.0 };
        match self.task.point_m {
            Some(p) => [p[0], p[1], z],
            None => {
                let b = &self.blocks[self.target_index()];
                [b.position_m[0], b.position_m[1], z]
            }
        }
    }

    /// Index of the target block: the named one, or the one nearest the indicated point.
    pub fn target_index(&self) -> usize {
        if let Some(name) = &self.task.target {
            return self.blocks.iter().position(|b| &b.name == name).unwrap_or(0);
        }
        let p = self.task.point_m.unwrap_or([0.0, 0.0]);
        let d2 = |b: &BlockConfig| (b.position_m[0] - p[0]).powi(2) + (b.position_m[1] - p[1]).powi(2);
        (0..self.blocks.len())
            .min_by(|&a, &b| d2(&self.blocks[a]).total_cmp(&d2(&self.blocks[b])))
            .unwrap_or(0)
    }
}

/// The least rendered contrast (grey 0..1, as `shaders/scene.wgsl` shades a face:
/// `albedo · (ambient + intensity · max(0, n·l))`) across the edges of block `b` (the
/// `index`-th of a scenario seeded `seed`) standing at `yaw_deg` that a camera at one of
/// `cameras_m` sees: between the two faces at an edge where it sees both, and between a
/// face and the table behind or below it where it sees only that face.
fn least_edge_contrast(b: &BlockConfig, index: usize, seed: u64, light: &Light, table_shade: f64, cameras_m: &[[f64; 3]], yaw_deg: f64) -> f64 {
    use glam::DVec3;
    let shape = crate::geometry::BlockShape::new(b.kind, DVec3::from_array(b.size_mm) * 1e-3);
    let shades = match &b.shades {
        Some(s) => s.clone(),
        None => crate::world::random_shades(b.shade_seed.unwrap_or_else(|| handeye_vision::rng::mix64(seed ^ (index as u64 + 1))), shape.faces.len()),
    };
    let towards = DVec3::from_array(light.direction).normalize_or_zero();
    let grey = |albedo: f64, n: DVec3| (albedo * (light.ambient + light.intensity * n.dot(towards).max(0.0))).clamp(0.0, 1.0);
    let (sin, cos) = yaw_deg.to_radians().sin_cos();
    let centre = DVec3::new(b.position_m[0], b.position_m[1], 0.5e-3 * b.size_mm[2]);
    // Seen: facing a camera by more than ~3° (a face turned edge-on shows no area).
    let face = |f: usize| {
        let n = shape.faces[f].normal;
        let world = DVec3::new(cos * n.x - sin * n.y, sin * n.x + cos * n.y, n.z);
        let seen = cameras_m.iter().any(|c| world.dot((DVec3::from_array(*c) - centre).normalize_or_zero()) > 0.05);
        (seen, grey(shades.get(f).copied().unwrap_or(0.0), world))
    };
    let table = grey(table_shade, DVec3::Z);
    let mut least = f64::INFINITY;
    for e in &shape.edges {
        let ((seen_a, a), (seen_b, b)) = (face(e.faces[0]), face(e.faces[1]));
        let contrast = match (seen_a, seen_b) {
            (true, true) => (a - b).abs(),
            (true, false) => (a - table).abs(),
            (false, true) => (b - table).abs(),
            (false, false) => continue,
        };
        least = least.min(contrast);
    }
    least
}

#[cfg(test)]
mod tests {
    use super::*;

    const PICK_CUBE: &str = include_str!("../../../scenarios/pick_cube.toml");

    fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        Scenario::parse(text, Path::new("test.toml"))
    }

    fn line_of(text: &str, needle: &str) -> usize {
        text.lines().position(|l| l.contains(needle)).expect("needle in text") + 1
    }

    #[test]
    fn shipped_scenario_parses() {
        let s = parse(PICK_CUBE).unwrap();
        assert_eq!(s.cameras.len(), 2);
        assert_eq!(s.substeps_per_frame(), 8);
        assert_eq!(s.blocks[s.target_index()].name, "cube");
    }

    #[test]
    fn random_layouts_show_every_edge_of_every_block() {
        let clutter = parse(include_str!("../../../scenarios/clutter3.toml")).unwrap();
        let cameras_m: Vec<[f64; 3]> = clutter.cameras.iter().map(|c| c.position_m).collect();
        let contrast = |s: &Scenario, i: usize, yaw_deg: f64| least_edge_contrast(&s.blocks[i], i, s.seed, &s.light, s.table.shade, &cameras_m, yaw_deg);
        // The check has something to catch: under clutter3's light each block has yaws at
        // which two of its neighbouring faces render within the threshold (clutter3 seed 28's
        // cube showed its front and side faces 4 grey levels apart before the check).
        for i in 0..clutter.blocks.len() {
            let hidden = (0..360).filter(|d| contrast(&clutter, i, *d as f64) < Scenario::LAYOUT_MIN_EDGE_CONTRAST).count();
            assert!(hidden > 0 && hidden < 180, "{}: {hidden} of 360 yaws hide an edge", clutter.blocks[i].name);
        }
        let mut redrawn = Vec::new();
        for seed in 1..=60 {
            let mut s = clutter.clone();
            assert!(s.randomise_layout(seed), "seed {seed}");
            for i in 0..s.blocks.len() {
                let c = contrast(&s, i, s.blocks[i].yaw_deg);
                assert!(c >= Scenario::LAYOUT_MIN_EDGE_CONTRAST, "seed {seed}: {} at {:.0}° has an edge of {:.1} grey levels", s.blocks[i].name, s.blocks[i].yaw_deg, c * 255.0);
            }
            // A layout whose first draws show every edge is the one drawn without the check.
            let mut plain = clutter.clone();
            assert!(plain.randomise_layout_drawing(seed, 1));
            let shows = (0..plain.blocks.len()).all(|i| contrast(&plain, i, plain.blocks[i].yaw_deg) >= Scenario::LAYOUT_MIN_EDGE_CONTRAST);
            if shows {
                assert_eq!(format!("{:?}", plain.blocks), format!("{:?}", s.blocks), "seed {seed}");
            } else {
                redrawn.push(seed);
            }
        }
        eprintln!("clutter3 layouts redrawn for a hidden edge: {redrawn:?}");
        assert!(!redrawn.is_empty(), "the check changed no layout of 60");
    }

    #[test]
    fn random_layouts_keep_blocks_apart_in_the_region_and_the_point_on_one() {
        let clutter = parse(include_str!("../../../scenarios/clutter3.toml")).unwrap();
        let mut targets = std::collections::BTreeSet::new();
        for seed in 1..=40 {
            let mut s = clutter.clone();
            assert!(s.randomise_layout(seed), "seed {seed}");
            assert_eq!(s.seed, seed);
            for (i, a) in s.blocks.iter().enumerate() {
                assert_eq!((a.kind, a.size_mm), (clutter.blocks[i].kind, clutter.blocks[i].size_mm), "blocks keep their kind and size");
                let r = 0.5e-3 * a.size_mm[0].hypot(a.size_mm[1]);
                assert!((Scenario::LAYOUT_X_M[0]..=Scenario::LAYOUT_X_M[1] - r).contains(&a.position_m[0]), "seed {seed}: {} wholly inside x", a.name);
                assert!((Scenario::LAYOUT_Y_M[0]..=Scenario::LAYOUT_Y_M[1]).contains(&a.position_m[1]));
                for b in &s.blocks[i + 1..] {
                    let d = (a.position_m[0] - b.position_m[0]).hypot(a.position_m[1] - b.position_m[1]);
                    let r = |x: &BlockConfig| 0.5e-3 * x.size_mm[0].hypot(x.size_mm[1]);
                    assert!(d >= r(a) + r(b) + Scenario::LAYOUT_GAP_M - 1e-12, "seed {seed}: {} and {} {d:.3} m apart", a.name, b.name);
                }
            }
            // The indicated point is within 15 mm of the target, which is the nearest block.
            let t = &s.blocks[s.target_index()];
            let p = s.task.point_m.unwrap();
            assert!((t.position_m[0] - p[0]).hypot(t.position_m[1] - p[1]) <= Scenario::LAYOUT_POINT_OFFSET_M + 1e-12);
            targets.insert(t.name.clone());
            // Seeded: the same seed, the same layout.
            let mut again = clutter.clone();
            again.randomise_layout(seed);
            assert_eq!(format!("{:?}", again.blocks), format!("{:?}", s.blocks));
        }
        assert_eq!(targets.len(), 3, "every block is the target for some seed: {targets:?}");
        // A named target stays the target.
        let mut cube = parse(PICK_CUBE).unwrap();
        assert!(cube.randomise_layout(9));
        assert_eq!(cube.blocks[cube.target_index()].name, "cube");
        let p = cube.indicated_point_m();
        assert_eq!([p[0], p[1]], cube.blocks[0].position_m);
        assert_eq!(p[2], 0.06, "the working plane: the lower cage points");
    }

    #[test]
    fn unknown_field_names_field_and_line() {
        let text = PICK_CUBE.replace("yaw_deg = 25.0", "yaw_deg = 25.0\ncolour = 3");
        let e = parse(&text).unwrap_err();
        assert!(e.message.contains("colour"), "{e}");
        assert_eq!(e.line, line_of(&text, "colour"), "{e}");
        assert!(e.field.starts_with("blocks[0]"), "{e}");
    }

    #[test]
    fn missing_field_is_named() {
        let text = PICK_CUBE.replace("rate_hz = 240", "");
        let e = parse(&text).unwrap_err();
        assert!(e.message.contains("rate_hz"), "{e}");
        assert!(e.to_string().starts_with("test.toml:"), "{e}");
    }

    #[test]
    fn wrong_type_names_field_path_and_line() {
        let text = PICK_CUBE.replace("focal_px = 1800.0\nresolution = [640, 480]\nnoise_sigma = 1.5\nblur_sigma_px = 0.0\n\n[[blocks]]",
            "focal_px = 1800.0\nresolution = [640, \"480\"]\nnoise_sigma = 1.5\nblur_sigma_px = 0.0\n\n[[blocks]]");
        assert_ne!(text, PICK_CUBE);
        let e = parse(&text).unwrap_err();
        assert_eq!(e.line, line_of(&text, "\"480\""), "{e}");
        assert!(e.field.contains("cameras[1].resolution"), "{e}");
    }

    #[test]
    fn out_of_range_value_points_at_its_key() {
        let text = PICK_CUBE.replace("size_mm = [40.0, 40.0, 40.0]", "size_mm = [40.0, 40.0, 80.0]");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.field, "blocks[0].size_mm", "{e}");
        assert_eq!(e.line, line_of(&text, "size_mm"), "{e}");
        assert!(e.message.contains("20..60"), "{e}");
    }

    #[test]
    fn dangling_reference_and_bad_event_are_reported() {
        let text = PICK_CUBE.replace("target = \"cube\"", "target = \"sphere\"");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.field, "task.target");
        assert!(e.message.contains("sphere"));

        let ev = format!("{PICK_CUBE}\n[[events]]\nat_s = 3.0\nkind = \"camera_bump\"\ncamera = \"middle\"\n");
        let e = parse(&ev).unwrap_err();
        assert_eq!(e.field, "events[0].camera", "{e}");
        assert_eq!(e.line, line_of(&ev, "\"middle\""), "{e}");

        let ev = format!("{PICK_CUBE}\n[[events]]\nat_s = 3.0\nkind = \"camera_bump\"\ncamera = \"left\"\nrotation = [1, 2, 3]\n");
        let e = parse(&ev).unwrap_err();
        assert!(e.message.contains("rotation"), "{e}");
        assert_eq!(e.line, line_of(&ev, "at_s = 3.0") - 1, "{e}");

        let ev = format!("{PICK_CUBE}\n[[events]]\nat_s = 3.0\nkind = \"earthquake\"\n");
        let e = parse(&ev).unwrap_err();
        assert!(e.message.contains("earthquake"), "{e}");
    }

    #[test]
    fn syntax_error_has_a_line() {
        let text = PICK_CUBE.replace("seed = 1", "seed = = 1");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.line, line_of(&text, "seed = = 1"), "{e}");
    }

    #[test]
    fn camera_count_and_focal_rules() {
        let one_cam = PICK_CUBE.split("[[cameras]]\nname = \"right\"").next().unwrap().to_string()
            + &PICK_CUBE[PICK_CUBE.find("[[blocks]]").unwrap()..];
        let e = parse(&one_cam).unwrap_err();
        assert_eq!(e.field, "cameras");
        let both = PICK_CUBE.replacen("focal_px = 1800.0", "focal_px = 1800.0\nvfov_deg = 20.0", 1);
        let e = parse(&both).unwrap_err();
        assert_eq!(e.field, "cameras[0]", "{e}");
    }
}

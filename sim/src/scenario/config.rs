//! The scenario file's format: one serde type per table of `scenarios/*.toml` (see
//! `sim/README.md`), and what follows from the file alone (the target block, the indicated
//! point, the step and frame periods).
//!
//! All positions are in the robot frame: metres, z up, origin at the arm's base on the table
//! top (the table top is the plane z = 0). The arm's base therefore sits at the origin by
//! definition; the table, blocks and cameras are placed relative to it.
//!
//! Plain data: this module depends on nothing else of the crate, so every other domain (the
//! work cell, the renderer, the referee) may build on it.

use serde::{Deserialize, Serialize};

pub use super::pointer_config::PointerConfig;

/// The kinds of block a scenario may place.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BlockKind {
    /// All three sides equal.
    Cube,
    /// A cuboid with sides of any length.
    Bar,
    /// A right triangular prism: the triangle lies in the x-z plane (bottom along x, vertical
    /// back side at +x, slope rising from -x to +x), extruded along y.
    Wedge,
    /// An L-shaped prism: the L lies in the x-z plane (a low leg of half height over the whole
    /// length, a tall leg over the +x half), extruded along y.
    LBlock,
}

impl BlockKind {
    pub fn name(self) -> &'static str {
        match self {
            Self::Cube => "cube",
            Self::Bar => "bar",
            Self::Wedge => "wedge",
            Self::LBlock => "l_block",
        }
    }

    /// Number of faces of this kind (length of a scenario's `shades` list).
    pub fn face_count(self) -> usize {
        match self {
            Self::Cube | Self::Bar => 6,
            Self::Wedge => 5,
            Self::LBlock => 8,
        }
    }
}

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
    pub physics: PhysicsConfig,
    pub render: RenderConfig,
    pub table: TableConfig,
    pub light: LightConfig,
    pub arm: ArmConfig,
    /// Exactly two: `[[cameras]]` left then right.
    pub cameras: Vec<CameraConfig>,
    pub blocks: Vec<BlockConfig>,
    pub cage: Cage,
    pub task: Task,
    pub success: SuccessRule,
    #[serde(default)]
    pub events: Vec<Event>,
    /// The ranges `--randomize` draws a whole work cell from (see [`RandomizeConfig`]);
    /// without the section, the default ranges.
    pub randomize: Option<RandomizeConfig>,
    /// An operator's hand that points at what `[task]` names (see [`PointerConfig`]);
    /// without the section, nobody points.
    pub pointer: Option<PointerConfig>,
}

/// `[physics]`
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhysicsConfig {
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
pub struct RenderConfig {
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
pub struct TableConfig {
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
pub struct LightConfig {
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

/// `[randomize]`
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomizeConfig {
    /// Distance of each camera from the point both look at, metres.
    pub camera_distance_m: [f64; 2],
    /// Angle between the two optical axes (the pair's vergence), degrees.
    pub vergence_deg: [f64; 2],
    /// Elevation of the pair above the table plane, as seen from the point they look at,
    /// degrees.
    pub elevation_deg: [f64; 2],
    /// Azimuth of the pair's bisector about the vertical, degrees (0: looking back from +x
    /// towards the arm, as in the shipped scenarios).
    pub azimuth_deg: [f64; 2],
    /// Horizontal field of view of both cameras (one lens for the pair), degrees: sets the
    /// focal length in pixels for the scenario's resolution.
    pub hfov_deg: [f64; 2],
    /// Roll of each camera about its optical axis, degrees.
    pub roll_deg: [f64; 2],
    /// How far the point the cameras look at lies from the workspace centre, each of x, y and
    /// z, metres (nobody aims a camera pair at the exact centre).
    pub aim_offset_m: f64,
    /// Elevation of the light's direction above the table, degrees (its azimuth is any).
    pub light_elevation_deg: [f64; 2],
    /// Brightness of the directional light.
    pub light_intensity: [f64; 2],
    /// Ambient light.
    pub ambient: [f64; 2],
    /// Albedo of the table top.
    pub table_shade: [f64; 2],
    /// Albedo of a block (one paint per block).
    pub block_shade: [f64; 2],
    /// Largest difference of one face's albedo from its block's (paint and wear), ±.
    pub face_shade_spread: f64,
    /// Number of blocks, inclusive.
    pub blocks: [usize; 2],
    /// Block kinds in play, each equally likely: `cube`, `bar`, `wedge`, `l_block`.
    pub kinds: Vec<BlockKind>,
    /// Each side of a block, millimetres: within what the gripper opens (50 mm), so that a
    /// block's graspability is up to its shape and pose, not its bulk.
    pub size_mm: [f64; 2],
    /// Block centres: x range, metres (the whole block inside it).
    pub region_x_m: [f64; 2],
    /// Block centres: y range, metres.
    pub region_y_m: [f64; 2],
    /// Sensor noise, grey levels (standard deviation).
    pub noise_sigma: [f64; 2],
    /// Optical blur, pixels (standard deviation).
    pub blur_sigma_px: [f64; 2],
}

impl Default for RandomizeConfig {
    fn default() -> Self {
        use BlockKind::{Bar, Cube, LBlock, Wedge};
        Self {
            camera_distance_m: [1.2, 1.9],
            vergence_deg: [14.0, 30.0],
            elevation_deg: [25.0, 45.0],
            azimuth_deg: [-15.0, 15.0],
            hfov_deg: [30.0, 50.0],
            roll_deg: [-3.0, 3.0],
            aim_offset_m: 0.03,
            light_elevation_deg: [15.0, 90.0],
            light_intensity: [0.4, 0.9],
            ambient: [0.2, 0.5],
            table_shade: [0.05, 0.5],
            block_shade: [0.35, 0.95],
            face_shade_spread: 0.1,
            blocks: [2, 5],
            kinds: vec![Cube, Bar, Wedge, LBlock],
            size_mm: [20.0, 45.0],
            region_x_m: [0.27, 0.47],
            region_y_m: [-0.18, 0.18],
            noise_sigma: [0.5, 2.5],
            blur_sigma_px: [0.0, 1.0],
        }
    }
}

impl RandomizeConfig {
    /// Ranges out of order or out of what a scenario allows: the key and the problem.
    pub(super) fn check(&self) -> Result<(), (&'static str, String)> {
        let ranges: [(&'static str, [f64; 2], f64, f64); 17] = [
            ("camera_distance_m", self.camera_distance_m, 0.3, 5.0),
            ("vergence_deg", self.vergence_deg, 1.0, 90.0),
            ("elevation_deg", self.elevation_deg, 5.0, 85.0),
            ("azimuth_deg", self.azimuth_deg, -60.0, 60.0),
            ("hfov_deg", self.hfov_deg, 5.0, 120.0),
            ("roll_deg", self.roll_deg, -30.0, 30.0),
            ("light_elevation_deg", self.light_elevation_deg, 1.0, 90.0),
            ("light_intensity", self.light_intensity, 0.0, 2.0),
            ("ambient", self.ambient, 0.0, 1.0),
            ("table_shade", self.table_shade, 0.0, 1.0),
            ("block_shade", self.block_shade, 0.0, 1.0),
            ("size_mm", self.size_mm, 20.0, 60.0),
            ("region_x_m", self.region_x_m, -2.0, 2.0),
            ("region_y_m", self.region_y_m, -2.0, 2.0),
            ("noise_sigma", self.noise_sigma, 0.0, 50.0),
            ("blur_sigma_px", self.blur_sigma_px, 0.0, 2.0),
            ("blocks", [self.blocks[0] as f64, self.blocks[1] as f64], 1.0, 16.0),
        ];
        for (key, [lo, hi], min, max) in ranges {
            if !(lo.is_finite() && hi.is_finite() && min <= lo && lo <= hi && hi <= max) {
                return Err((key, format!("must be [low, high] with {min} <= low <= high <= {max}")));
            }
        }
        if !(self.aim_offset_m.is_finite() && (0.0..=0.2).contains(&self.aim_offset_m)) {
            return Err(("aim_offset_m", "must be 0..0.2 m".into()));
        }
        if !(self.face_shade_spread.is_finite() && (0.0..=0.5).contains(&self.face_shade_spread)) {
            return Err(("face_shade_spread", "must be 0..0.5".into()));
        }
        if self.kinds.is_empty() {
            return Err(("kinds", "name at least one block kind".into()));
        }
        Ok(())
    }
}

/// Seconds (the scenario's unit of time) to integer nanoseconds (the simulator's clock).
pub fn s_to_ns(s: f64) -> u64 {
    (s * 1e9).round().max(0.0) as u64
}

impl Scenario {
    /// Seconds of simulated time per physics step.
    pub fn physics_dt_s(&self) -> f64 {
        1.0 / f64::from(self.physics.rate_hz)
    }

    /// Physics steps per stereo frame.
    pub fn substeps_per_frame(&self) -> u32 {
        self.physics.rate_hz / self.render.frame_rate_hz
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

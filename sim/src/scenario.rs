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

use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::geometry::BlockKind;

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

    /// Semantic checks after deserialisation; the error carries the field path.
    fn validate(&self) -> Result<(), (Vec<Seg>, String)> {
        use Seg::{I, K};
        let p = |segs: &[Seg]| segs.to_vec();
        let finite_in = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;

        if !(10..=10_000).contains(&self.physics.rate_hz) {
            return Err((p(&[K("physics"), K("rate_hz")]), "must be 10..10000 steps per second".into()));
        }
        if !finite_in(self.physics.gravity_mps2, 0.0, 30.0) {
            return Err((p(&[K("physics"), K("gravity_mps2")]), "must be 0..30 m/s²".into()));
        }
        let fr = self.render.frame_rate_hz;
        if fr == 0 || !self.physics.rate_hz.is_multiple_of(fr) {
            return Err((
                p(&[K("render"), K("frame_rate_hz")]),
                format!("must divide physics.rate_hz = {} (whole physics steps per frame)", self.physics.rate_hz),
            ));
        }
        if !finite_in(self.render.background, 0.0, 1.0) {
            return Err((p(&[K("render"), K("background")]), "must be a grey level 0..1".into()));
        }
        if !self.table.size_m.iter().all(|&s| finite_in(s, 0.2, 5.0)) {
            return Err((p(&[K("table"), K("size_m")]), "sides must be 0.2..5 m".into()));
        }
        if !self.table.center_m.iter().all(|&c| finite_in(c, -5.0, 5.0)) {
            return Err((p(&[K("table"), K("center_m")]), "must be within 5 m of the arm base".into()));
        }
        if !finite_in(self.table.shade, 0.0, 1.0) {
            return Err((p(&[K("table"), K("shade")]), "must be 0..1".into()));
        }
        if !finite_in(self.table.friction, 0.0, 3.0) {
            return Err((p(&[K("table"), K("friction")]), "must be 0..3".into()));
        }
        check_light(&self.light.direction, self.light.intensity, self.light.ambient)
            .map_err(|(f, m)| (p(&[K("light"), K(f)]), m))?;
        if !self.arm.home_m.iter().all(|v| v.is_finite()) || !self.arm.home_yaw_deg.is_finite() {
            return Err((p(&[K("arm"), K("home_m")]), "must be finite".into()));
        }
        if !finite_in(self.arm.default_speed_mps, 0.01, 1.0) {
            return Err((p(&[K("arm"), K("default_speed_mps")]), "must be 0.01..1 m/s".into()));
        }

        if self.cameras.len() != 2 {
            return Err((p(&[K("cameras")]), format!("need exactly 2 cameras (left, right), found {}", self.cameras.len())));
        }
        for (i, c) in self.cameras.iter().enumerate() {
            let at = |f: &'static str| p(&[K("cameras"), I(i), K(f)]);
            let want = ["left", "right"][i];
            if c.name != want {
                return Err((at("name"), format!("camera {i} must be named {want:?} (left first), found {:?}", c.name)));
            }
            let [w, h] = c.resolution;
            if !(64..=4096).contains(&w) || !(64..=4096).contains(&h) {
                return Err((at("resolution"), "width and height must be 64..4096 px".into()));
            }
            if c.resolution != self.cameras[0].resolution {
                return Err((at("resolution"), "both cameras must have the same resolution".into()));
            }
            match (c.focal_px, c.vfov_deg) {
                (Some(f), None) if finite_in(f, 10.0, 100_000.0) => {}
                (None, Some(v)) if finite_in(v, 1.0, 150.0) => {}
                (Some(_), None) => return Err((at("focal_px"), "must be 10..100000 px".into())),
                (None, Some(_)) => return Err((at("vfov_deg"), "must be 1..150 degrees".into())),
                _ => return Err((p(&[K("cameras"), I(i)]), "give exactly one of `focal_px` and `vfov_deg`".into())),
            }
            if !c.position_m.iter().chain(&c.look_at_m).chain(&c.up).all(|v| v.is_finite()) {
                return Err((at("position_m"), "position, look_at and up must be finite".into()));
            }
            let fwd = sub(c.look_at_m, c.position_m);
            if norm(fwd) < 0.05 {
                return Err((at("look_at_m"), "must be at least 5 cm from position_m".into()));
            }
            if norm(cross(fwd, c.up)) < 1e-3 * norm(fwd) * norm(c.up).max(1e-12) {
                return Err((at("up"), "must not be parallel to the viewing direction".into()));
            }
            if !finite_in(c.noise_sigma, 0.0, 50.0) {
                return Err((at("noise_sigma"), "must be 0..50 grey levels".into()));
            }
            if !finite_in(c.blur_sigma_px, 0.0, 2.0) {
                return Err((at("blur_sigma_px"), "must be 0..2 px".into()));
            }
        }

        if self.blocks.is_empty() || self.blocks.len() > 16 {
            return Err((p(&[K("blocks")]), "need 1..16 blocks".into()));
        }
        for (i, b) in self.blocks.iter().enumerate() {
            let at = |f: &'static str| p(&[K("blocks"), I(i), K(f)]);
            if b.name.is_empty() || self.blocks[..i].iter().any(|o| o.name == b.name) {
                return Err((at("name"), format!("block names must be unique and not empty ({:?})", b.name)));
            }
            if !b.size_mm.iter().all(|&s| finite_in(s, 20.0, 60.0)) {
                return Err((at("size_mm"), "each side must be 20..60 mm".into()));
            }
            if b.kind == BlockKind::Cube && (b.size_mm[1] != b.size_mm[0] || b.size_mm[2] != b.size_mm[0]) {
                return Err((at("size_mm"), "a cube has three equal sides".into()));
            }
            if !b.position_m.iter().all(|v| v.is_finite()) || !b.yaw_deg.is_finite() {
                return Err((at("position_m"), "must be finite".into()));
            }
            let (tx, ty) = (self.table.size_m[0] / 2.0, self.table.size_m[1] / 2.0);
            let (dx, dy) = (b.position_m[0] - self.table.center_m[0], b.position_m[1] - self.table.center_m[1]);
            if dx.abs() > tx - 0.05 || dy.abs() > ty - 0.05 {
                return Err((at("position_m"), "must be on the table, at least 5 cm from its edge".into()));
            }
            if let Some(shades) = &b.shades {
                if shades.len() != b.kind.face_count() {
                    return Err((
                        at("shades"),
                        format!("a {} has {} faces, found {} shades", b.kind.name(), b.kind.face_count(), shades.len()),
                    ));
                }
                if let Some(j) = shades.iter().position(|&s| !finite_in(s, 0.0, 1.0)) {
                    return Err((p(&[K("blocks"), I(i), K("shades"), I(j)]), "must be 0..1".into()));
                }
                if b.shade_seed.is_some() {
                    return Err((at("shade_seed"), "give `shades` or `shade_seed`, not both".into()));
                }
            }
            if !finite_in(b.density_kg_m3, 50.0, 20_000.0) {
                return Err((at("density_kg_m3"), "must be 50..20000 kg/m³".into()));
            }
            if !finite_in(b.friction, 0.05, 3.0) {
                return Err((at("friction"), "must be 0.05..3".into()));
            }
        }

        if self.cage.points_m.len() != 8 {
            return Err((p(&[K("cage"), K("points_m")]), format!("need exactly 8 points, found {}", self.cage.points_m.len())));
        }
        if let Some(j) = self.cage.points_m.iter().position(|q| !q.iter().all(|v| v.is_finite())) {
            return Err((p(&[K("cage"), K("points_m"), I(j)]), "must be finite".into()));
        }

        match (&self.task.target, &self.task.point_m) {
            (Some(name), None) => {
                if !self.blocks.iter().any(|b| &b.name == name) {
                    return Err((p(&[K("task"), K("target")]), format!("no block named {name:?}")));
                }
            }
            (None, Some(pt)) if pt.iter().all(|v| v.is_finite()) => {}
            (None, Some(_)) => return Err((p(&[K("task"), K("point_m")]), "must be finite".into())),
            _ => return Err((p(&[K("task")]), "give exactly one of `target` and `point_m`".into())),
        }
        if !finite_in(self.success.lift_mm, 1.0, 1000.0) {
            return Err((p(&[K("success"), K("lift_mm")]), "must be 1..1000 mm".into()));
        }
        if !finite_in(self.success.hold_s, 0.0, 60.0) {
            return Err((p(&[K("success"), K("hold_s")]), "must be 0..60 s".into()));
        }
        if !finite_in(self.success.timeout_s, 1.0, 3600.0) {
            return Err((p(&[K("success"), K("timeout_s")]), "must be 1..3600 s".into()));
        }

        for (i, e) in self.events.iter().enumerate() {
            let at = |f: &'static str| p(&[K("events"), I(i), K(f)]);
            if !finite_in(e.at_s(), 0.0, 3600.0) {
                return Err((at("at_s"), "must be 0..3600 s".into()));
            }
            match e {
                Event::CameraBump { camera, rotate_deg, translate_mm, .. } => {
                    if !self.cameras.iter().any(|c| &c.name == camera) {
                        return Err((at("camera"), format!("no camera named {camera:?}")));
                    }
                    if !rotate_deg.iter().all(|&v| finite_in(v, -45.0, 45.0)) {
                        return Err((at("rotate_deg"), "must be -45..45 degrees".into()));
                    }
                    if !translate_mm.iter().all(|&v| finite_in(v, -500.0, 500.0)) {
                        return Err((at("translate_mm"), "must be -500..500 mm".into()));
                    }
                }
                Event::TargetNudge { block, translate_mm, rotate_deg, .. } => {
                    if !self.blocks.iter().any(|b| &b.name == block) {
                        return Err((at("block"), format!("no block named {block:?}")));
                    }
                    if !translate_mm.iter().all(|&v| finite_in(v, -200.0, 200.0)) {
                        return Err((at("translate_mm"), "must be -200..200 mm".into()));
                    }
                    if !finite_in(*rotate_deg, -180.0, 180.0) {
                        return Err((at("rotate_deg"), "must be -180..180 degrees".into()));
                    }
                }
                Event::Occluder { duration_s, from_m, to_m, size_mm, shade, .. } => {
                    if !finite_in(*duration_s, 0.01, 600.0) {
                        return Err((at("duration_s"), "must be 0.01..600 s".into()));
                    }
                    if !from_m.iter().chain(to_m).all(|v| v.is_finite()) {
                        return Err((at("from_m"), "from_m and to_m must be finite".into()));
                    }
                    if !size_mm.iter().all(|&v| finite_in(v, 1.0, 2000.0)) {
                        return Err((at("size_mm"), "must be 1..2000 mm".into()));
                    }
                    if !finite_in(*shade, 0.0, 1.0) {
                        return Err((at("shade"), "must be 0..1".into()));
                    }
                }
                Event::LightChange { ramp_s, intensity, ambient, direction, .. } => {
                    if !finite_in(*ramp_s, 0.0, 600.0) {
                        return Err((at("ramp_s"), "must be 0..600 s".into()));
                    }
                    let dir = direction.unwrap_or(self.light.direction);
                    check_light(&dir, *intensity, *ambient).map_err(|(f, m)| (at(f), m))?;
                }
            }
        }
        Ok(())
    }
}

fn check_light(direction: &[f64; 3], intensity: f64, ambient: f64) -> Result<(), (&'static str, String)> {
    if !direction.iter().all(|v| v.is_finite()) || norm(*direction) < 1e-6 {
        return Err(("direction", "must be a finite, non-zero vector".into()));
    }
    if !(intensity.is_finite() && (0.0..=2.0).contains(&intensity)) {
        return Err(("intensity", "must be 0..2".into()));
    }
    if !(ambient.is_finite() && (0.0..=1.0).contains(&ambient)) {
        return Err(("ambient", "must be 0..1".into()));
    }
    Ok(())
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// One step of a field path: a table key or an array index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seg {
    K(&'static str),
    I(usize),
}

fn path_string(path: &[Seg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::K(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::I(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// Span of the value at `path` (or of the deepest part of it that exists).
fn span_of(doc: &Spanned<DeTable<'_>>, path: &[Seg]) -> Option<Range<usize>> {
    let mut span = doc.span();
    let mut table: Option<&DeTable<'_>> = Some(doc.get_ref());
    let mut value: Option<&Spanned<DeValue<'_>>> = None;
    for seg in path {
        let next = match (*seg, table, value) {
            (Seg::K(k), Some(t), _) => t.iter().find(|(key, _)| key.get_ref() == k).map(|(key, v)| {
                // Point at the key itself: the line a user looks for.
                span = key.span();
                v
            }),
            (Seg::I(i), _, Some(v)) => v.get_ref().as_array().and_then(|a| a.get(i)).inspect(|v| span = v.span()),
            _ => None,
        };
        let Some(v) = next else { break };
        value = Some(v);
        table = v.get_ref().as_table();
    }
    Some(span)
}

/// Dotted path of the field at byte offset `pos`: the key, value or table header that starts
/// last at or before `pos` (toml spans of tables cover only their header line).
fn path_at(doc: &Spanned<DeTable<'_>>, pos: usize) -> String {
    fn collect_table(t: &DeTable<'_>, prefix: &str, out: &mut Vec<(usize, String)>) {
        for (k, v) in t.iter() {
            let path = if prefix.is_empty() { k.get_ref().to_string() } else { format!("{prefix}.{}", k.get_ref()) };
            out.push((k.span().start, path.clone()));
            collect_value(v, &path, out);
        }
    }
    fn collect_value(v: &Spanned<DeValue<'_>>, path: &str, out: &mut Vec<(usize, String)>) {
        out.push((v.span().start, path.to_string()));
        if let Some(t) = v.get_ref().as_table() {
            collect_table(t, path, out);
        } else if let Some(a) = v.get_ref().as_array() {
            for (i, item) in a.iter().enumerate() {
                collect_value(item, &format!("{path}[{i}]"), out);
            }
        }
    }
    let mut entries = Vec::new();
    collect_table(doc.get_ref(), "", &mut entries);
    entries
        .into_iter()
        .filter(|(start, _)| *start <= pos)
        .max_by(|a, b| a.0.cmp(&b.0).then(a.1.len().cmp(&b.1.len())))
        .map_or_else(|| "(top level)".to_string(), |(_, p)| p)
}

fn error_at(file: &Path, text: &str, field: Option<String>, span: Option<Range<usize>>, message: &str) -> ScenarioError {
    let (line, column) = match span {
        Some(s) => line_col(text, s.start),
        None => (0, 0),
    };
    ScenarioError {
        file: file.to_path_buf(),
        line,
        column,
        field: field.unwrap_or_else(|| "(syntax)".into()),
        message: message.trim().replace('\n', "; "),
    }
}

/// 1-based line and column (in characters) of byte offset `pos`.
fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let mut pos = pos.min(text.len());
    while !text.is_char_boundary(pos) {
        pos -= 1;
    }
    let before = &text[..pos];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PICK_CUBE: &str = include_str!("../../scenarios/pick_cube.toml");

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

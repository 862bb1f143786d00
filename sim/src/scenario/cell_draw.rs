//! Randomised work cells (`--randomize`, `handeye batch --randomize`): one seed draws the
//! camera pair, the light, the shades, the blocks (kinds, sizes, poses), the sensor's noise
//! and blur and the task from the ranges of the scenario's `[randomize]` section
//! ([`RandomizeConfig`], or its defaults).
//!
//! A cell is drawn once from its seed. Only what is physically impossible is drawn again:
//! blocks that overlap (or leave no room for a finger between them), a block the arm cannot
//! reach, and a camera pair that does not see the calibration cage and every block whole.
//! Nothing is drawn again because an edge would render faintly: that is the world the
//! software has to handle.

use glam::DVec3;

use super::config::{BlockConfig, BlockKind, RandomizeConfig, Scenario};
use crate::cell::geometry::BlockShape;
use crate::cell::kinematics::{ik, IkError, ToolPose};
use crate::render::camera::Camera;
use handeye_vision::rng::{mix64, SplitMix64};

/// Why no cell could be drawn for a seed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CellDrawError {
    #[error("no camera pair of {attempts} drawn sees the whole calibration cage and workspace (last: {last})")]
    Cameras { attempts: usize, last: String },
    #[error("no layout of {attempts} drawn puts the blocks apart, in reach and in both views (last: {last})")]
    Layout { attempts: usize, last: String },
}

/// Attempts at a camera pair, and at a layout, before the seed is given up.
const DRAWS: usize = 400;
/// Least distance of a cage point or a block corner from the image border, pixels: a face
/// cut by the border cannot be tracked, and the gripper's plate stands out around the cage
/// point.
const VIEW_MARGIN_PX: f64 = 24.0;
/// Height of the tool point when it grasps a block, metres, for the reach check.
const GRASP_HEIGHT_M: f64 = 0.012;

impl Scenario {
    /// Draws a whole work cell from `seed` (see the module docs) and uses `seed` for every
    /// other random choice (sensor noise, hint errors). Keeps the scenario's physics, render
    /// settings, table size, arm speed, cage, success rule and events. The task becomes an
    /// indicated point within [`Self::LAYOUT_POINT_OFFSET_M`] of a random block. The arm's
    /// home yaw turns with the cameras' azimuth so that its plate faces them.
    ///
    /// A pure function of the seed and the `[randomize]` ranges.
    pub fn randomise_cell(&mut self, seed: u64) -> Result<(), CellDrawError> {
        let ranges = self.randomize.clone().unwrap_or_default();
        self.seed = seed;
        let mut rng = SplitMix64::new(mix64(seed ^ 0x4345_4c4c));
        let mut draw = |r: [f64; 2]| r[0] + rng.next_f64() * (r[1] - r[0]);

        // Light: a direction over the upper hemisphere above the lowest elevation (uniform
        // over that band's area), intensity and ambient.
        let azimuth = draw([0.0, std::f64::consts::TAU]);
        let [s_lo, s_hi] = ranges.light_elevation_deg.map(|d| d.to_radians().sin());
        let sin_el = draw([s_lo, s_hi]);
        let cos_el = (1.0 - sin_el * sin_el).max(0.0).sqrt();
        self.light.direction = [cos_el * azimuth.cos(), cos_el * azimuth.sin(), sin_el];
        self.light.intensity = draw(ranges.light_intensity);
        self.light.ambient = draw(ranges.ambient);
        self.table.shade = draw(ranges.table_shade);
        drop(draw);

        self.draw_cameras(&ranges, &mut rng)?;
        self.draw_blocks(&ranges, &mut rng)?;
        Ok(())
    }

    /// The camera pair (and the arm's home yaw facing it), drawn until both cameras see
    /// every cage point and the whole block region.
    fn draw_cameras(&mut self, ranges: &RandomizeConfig, rng: &mut SplitMix64) -> Result<(), CellDrawError> {
        let n = self.cage.points_m.len().max(1) as f64;
        let centre = self.cage.points_m.iter().fold(DVec3::ZERO, |a, p| a + DVec3::from_array(*p)) / n;
        let region_corners: Vec<DVec3> = [0, 1, 2, 3]
            .iter()
            .map(|i| DVec3::new(ranges.region_x_m[i & 1], ranges.region_y_m[i >> 1], 0.0))
            .collect();
        let must_see: Vec<DVec3> = self.cage.points_m.iter().map(|p| DVec3::from_array(*p)).chain(region_corners).collect();
        let mut last = String::new();
        for _ in 0..DRAWS {
            let mut draw = |r: [f64; 2]| r[0] + rng.next_f64() * (r[1] - r[0]);
            let distance_m = draw(ranges.camera_distance_m);
            let vergence = draw(ranges.vergence_deg).to_radians();
            let elevation = draw(ranges.elevation_deg).to_radians();
            let bisector = draw(ranges.azimuth_deg).to_radians();
            let hfov = draw(ranges.hfov_deg).to_radians();
            let rolls = [draw(ranges.roll_deg).to_radians(), draw(ranges.roll_deg).to_radians()];
            let aim = centre + ranges.aim_offset_m * DVec3::new(draw([-1.0, 1.0]), draw([-1.0, 1.0]), draw([-1.0, 1.0]));
            let noise = draw(ranges.noise_sigma);
            let blur = draw(ranges.blur_sigma_px);
            // Both cameras at the same elevation, their azimuths `half` either side of the
            // bisector, so that the angle between the optical axes is the vergence:
            // cos v = cos² e cos 2h + sin² e.
            let (se, ce) = elevation.sin_cos();
            let half = 0.5 * ((vergence.cos() - se * se) / (ce * ce)).clamp(-1.0, 1.0).acos();
            let width_px = f64::from(self.cameras[0].resolution[0]);
            let focal_px = 0.5 * width_px / (0.5 * hfov).tan();
            for (i, camera) in self.cameras.iter_mut().enumerate() {
                // The left camera (first) on the -y side of the bisector, as in the shipped
                // scenarios.
                let a = bisector + if i == 0 { -half } else { half };
                let position = aim + distance_m * DVec3::new(ce * a.cos(), ce * a.sin(), se);
                let forward = (aim - position).normalize();
                let up = rotate_about(DVec3::Z, forward, rolls[i]);
                camera.position_m = position.to_array();
                camera.look_at_m = aim.to_array();
                camera.up = up.to_array();
                camera.focal_px = Some(focal_px);
                camera.vfov_deg = None;
                camera.noise_sigma = noise;
                camera.blur_sigma_px = blur;
            }
            match self.cameras.iter().find_map(|c| {
                let cam = Camera::from_config(c);
                must_see.iter().find(|p| !in_view(&cam, **p)).map(|p| format!("{} misses ({:.2}, {:.2}, {:.2}) m", c.name, p.x, p.y, p.z))
            }) {
                None => {
                    // The plate faces the cameras: home yaw −90° faces +x (the shipped cells).
                    self.arm.home_yaw_deg = -90.0 + bisector.to_degrees();
                    return Ok(());
                }
                Some(why) => last = why,
            }
        }
        Err(CellDrawError::Cameras { attempts: DRAWS, last })
    }

    /// The blocks (count, kinds, sizes, shades, poses) and the task, drawn until they are
    /// apart, in reach and whole in both views.
    fn draw_blocks(&mut self, ranges: &RandomizeConfig, rng: &mut SplitMix64) -> Result<(), CellDrawError> {
        let cameras: Vec<Camera> = self.cameras.iter().map(Camera::from_config).collect();
        let template = self.blocks.first().cloned();
        let mut last = String::new();
        for _ in 0..DRAWS {
            let count = ranges.blocks[0] + rng.below(ranges.blocks[1] - ranges.blocks[0] + 1);
            let mut blocks: Vec<BlockConfig> = Vec::with_capacity(count);
            let mut why = None;
            for i in 0..count {
                let kind = ranges.kinds[rng.below(ranges.kinds.len())];
                let mut size_mm = [rng.range(ranges.size_mm[0], ranges.size_mm[1]), rng.range(ranges.size_mm[0], ranges.size_mm[1]), rng.range(ranges.size_mm[0], ranges.size_mm[1])];
                if kind == BlockKind::Cube {
                    size_mm = [size_mm[0]; 3];
                }
                let paint = rng.range(ranges.block_shade[0], ranges.block_shade[1]);
                let shades: Vec<f64> = (0..kind.face_count()).map(|_| (paint + rng.range(-ranges.face_shade_spread, ranges.face_shade_spread)).clamp(0.0, 1.0)).collect();
                let r = 0.5e-3 * size_mm[0].hypot(size_mm[1]);
                let x_max = (ranges.region_x_m[1] - r).max(ranges.region_x_m[0]);
                let position_m = [rng.range(ranges.region_x_m[0], x_max), rng.range(ranges.region_y_m[0], ranges.region_y_m[1])];
                let yaw_deg = rng.range(-180.0, 180.0);
                let block = BlockConfig {
                    name: format!("{}{}", kind.name(), i + 1),
                    kind,
                    size_mm,
                    position_m,
                    yaw_deg,
                    shades: Some(shades),
                    shade_seed: None,
                    density_kg_m3: template.as_ref().map_or(600.0, |t| t.density_kg_m3),
                    friction: template.as_ref().map_or(0.9, |t| t.friction),
                };
                why = why.or_else(|| physically_invalid(&block, &blocks, &cameras, self.arm.home_yaw_deg));
                blocks.push(block);
            }
            if let Some(w) = why {
                last = w;
                continue;
            }
            let t = rng.below(blocks.len());
            let (angle, dist) = (rng.range(0.0, std::f64::consts::TAU), rng.range(0.0, Self::LAYOUT_POINT_OFFSET_M));
            let c = blocks[t].position_m;
            self.blocks = blocks;
            self.task.target = None;
            self.task.point_m = Some([c[0] + dist * angle.cos(), c[1] + dist * angle.sin()]);
            return Ok(());
        }
        Err(CellDrawError::Layout { attempts: DRAWS, last })
    }
}

/// Why `block` cannot stand where it was drawn beside `placed`: too close to one of them
/// (bounding circles [`Scenario::LAYOUT_GAP_M`] apart), out of the arm's reach, or not whole
/// in a camera's view. `None` when it can.
fn physically_invalid(block: &BlockConfig, placed: &[BlockConfig], cameras: &[Camera], home_yaw_deg: f64) -> Option<String> {
    let radius = |b: &BlockConfig| 0.5e-3 * b.size_mm[0].hypot(b.size_mm[1]);
    if let Some(o) = placed.iter().find(|o| (block.position_m[0] - o.position_m[0]).hypot(block.position_m[1] - o.position_m[1]) < radius(block) + radius(o) + Scenario::LAYOUT_GAP_M) {
        return Some(format!("{} too close to {}", block.name, o.name));
    }
    let pose = ToolPose { pos_m: DVec3::new(block.position_m[0], block.position_m[1], GRASP_HEIGHT_M), yaw_rad: home_yaw_deg.to_radians() };
    if let Err(e @ IkError::OutOfReach(_)) = ik(pose) {
        return Some(format!("{}: {e}", block.name));
    }
    let corners = block_corners_m(block);
    for cam in cameras {
        if let Some(p) = corners.iter().find(|p| !in_view(cam, **p)) {
            return Some(format!("{} corner ({:.2}, {:.2}, {:.2}) m out of a view", block.name, p.x, p.y, p.z));
        }
    }
    None
}

/// The block's corners in the robot frame, as the work cell stands it on the table.
pub(super) fn block_corners_m(b: &BlockConfig) -> Vec<DVec3> {
    let shape = BlockShape::new(b.kind, DVec3::from_array(b.size_mm) * 1e-3);
    let (sin, cos) = b.yaw_deg.to_radians().sin_cos();
    let centre = DVec3::new(b.position_m[0], b.position_m[1], 0.5e-3 * b.size_mm[2]);
    shape.corners.iter().map(|c| centre + DVec3::new(cos * c.x - sin * c.y, sin * c.x + cos * c.y, c.z)).collect()
}

/// In front of the camera and at least [`VIEW_MARGIN_PX`] inside its image.
fn in_view(cam: &Camera, p: DVec3) -> bool {
    cam.project(p).is_some_and(|[u, v]| {
        (VIEW_MARGIN_PX..=f64::from(cam.width_px) - 1.0 - VIEW_MARGIN_PX).contains(&u) && (VIEW_MARGIN_PX..=f64::from(cam.height_px) - 1.0 - VIEW_MARGIN_PX).contains(&v)
    })
}

/// `v` turned by `angle_rad` about the unit `axis` (Rodrigues).
fn rotate_about(v: DVec3, axis: DVec3, angle_rad: f64) -> DVec3 {
    let (s, c) = angle_rad.sin_cos();
    v * c + axis.cross(v) * s + axis * axis.dot(v) * (1.0 - c)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    const RANDOM: &str = include_str!("../../../scenarios/random.toml");

    fn random() -> Scenario {
        Scenario::parse(RANDOM, Path::new("random.toml")).unwrap()
    }

    fn within(v: f64, [lo, hi]: [f64; 2], what: &str, seed: u64) {
        assert!(v >= lo - 1e-9 && v <= hi + 1e-9, "seed {seed}: {what} = {v} outside [{lo}, {hi}]");
    }

    #[test]
    fn drawn_cells_keep_to_their_ranges_for_many_seeds() {
        let base = random();
        let r = base.randomize.clone().unwrap_or_default();
        let mut kinds = std::collections::HashSet::new();
        let mut counts = std::collections::BTreeSet::new();
        for seed in 1..=200 {
            let mut s = base.clone();
            s.randomise_cell(seed).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            assert_eq!(s.seed, seed);
            // The drawn cell is a valid scenario.
            s.validate().unwrap_or_else(|(path, m)| panic!("seed {seed}: {path:?}: {m}"));
            let [l, rt] = [&s.cameras[0], &s.cameras[1]];
            let aim = DVec3::from_array(l.look_at_m);
            assert_eq!(l.look_at_m, rt.look_at_m, "both cameras look at one point");
            let (dl, dr) = (DVec3::from_array(l.position_m) - aim, DVec3::from_array(rt.position_m) - aim);
            within(dl.length(), r.camera_distance_m, "left distance", seed);
            within(dr.length(), r.camera_distance_m, "right distance", seed);
            within(dl.angle_between(dr).to_degrees(), r.vergence_deg, "vergence", seed);
            within((dl.z / dl.length()).asin().to_degrees(), r.elevation_deg, "elevation", seed);
            assert!(dl.y < dr.y, "seed {seed}: the left camera on the -y side");
            let hfov = 2.0 * (0.5 * f64::from(l.resolution[0]) / l.focal_px.unwrap()).atan().to_degrees();
            within(hfov, r.hfov_deg, "hfov", seed);
            for c in [l, rt] {
                let fwd = -DVec3::from_array(c.position_m) + aim;
                let up = DVec3::from_array(c.up);
                let level = fwd.cross(DVec3::Z).normalize();
                within((up.dot(level)).asin().to_degrees().abs(), [0.0, r.roll_deg[1].abs().max(r.roll_deg[0].abs())], "roll", seed);
                within(c.noise_sigma, r.noise_sigma, "noise", seed);
                within(c.blur_sigma_px, r.blur_sigma_px, "blur", seed);
            }
            let d = DVec3::from_array(s.light.direction);
            within((d.z / d.length()).asin().to_degrees(), r.light_elevation_deg, "light elevation", seed);
            within(s.light.intensity, r.light_intensity, "intensity", seed);
            within(s.light.ambient, r.ambient, "ambient", seed);
            within(s.table.shade, r.table_shade, "table shade", seed);
            within(s.blocks.len() as f64, [r.blocks[0] as f64, r.blocks[1] as f64], "block count", seed);
            counts.insert(s.blocks.len());
            for b in &s.blocks {
                kinds.insert(b.kind);
                for v in b.size_mm {
                    within(v, r.size_mm, "size", seed);
                }
                let shades = b.shades.as_ref().unwrap();
                let mean = shades.iter().sum::<f64>() / shades.len() as f64;
                within(mean, [r.block_shade[0] - r.face_shade_spread, r.block_shade[1] + r.face_shade_spread], "block shade", seed);
                within(b.position_m[1], r.region_y_m, "y", seed);
                within(b.position_m[0] + 0.5e-3 * b.size_mm[0].hypot(b.size_mm[1]), [r.region_x_m[0], r.region_x_m[1]], "x (whole block)", seed);
            }
            // The point is next to its target, the nearest block by far.
            let t = &s.blocks[s.target_index()];
            let p = s.task.point_m.unwrap();
            assert!((t.position_m[0] - p[0]).hypot(t.position_m[1] - p[1]) <= Scenario::LAYOUT_POINT_OFFSET_M + 1e-12);
        }
        assert_eq!(kinds.len(), 4, "every block kind in play: {kinds:?}");
        assert_eq!(counts, (r.blocks[0]..=r.blocks[1]).collect(), "every block count drawn");
    }

    #[test]
    fn a_draw_is_a_pure_function_of_the_seed() {
        let base = random();
        for seed in [1, 2, 77, 1_000_003] {
            let (mut a, mut b) = (base.clone(), base.clone());
            a.randomise_cell(seed).unwrap();
            // Whatever the scenario held before (another seed's cell) does not matter.
            b.randomise_cell(seed + 1).unwrap();
            b.randomise_cell(seed).unwrap();
            assert_eq!(format!("{:?}", (&a.cameras, &a.blocks, &a.light, a.table.shade, &a.task.point_m, a.arm.home_yaw_deg)),
                format!("{:?}", (&b.cameras, &b.blocks, &b.light, b.table.shade, &b.task.point_m, b.arm.home_yaw_deg)), "seed {seed}");
        }
        let (mut a, mut b) = (base.clone(), base);
        a.randomise_cell(5).unwrap();
        b.randomise_cell(6).unwrap();
        assert_ne!(format!("{:?}", a.blocks), format!("{:?}", b.blocks));
    }

    #[test]
    fn drawn_cells_are_physically_valid_and_see_the_cage() {
        let base = random();
        for seed in 1..=100 {
            let mut s = base.clone();
            s.randomise_cell(seed).unwrap();
            let cams: Vec<Camera> = s.cameras.iter().map(Camera::from_config).collect();
            for p in &s.cage.points_m {
                assert!(cams.iter().all(|c| in_view(c, DVec3::from_array(*p))), "seed {seed}: cage point {p:?} out of a view");
            }
            for (i, b) in s.blocks.iter().enumerate() {
                assert_eq!(physically_invalid(b, &s.blocks[..i], &cams, s.arm.home_yaw_deg), None, "seed {seed}");
            }
        }
    }

    #[test]
    fn physically_invalid_layouts_are_rejected_and_faint_ones_are_not() {
        let mut s = random();
        s.randomise_cell(3).unwrap();
        let cams: Vec<Camera> = s.cameras.iter().map(Camera::from_config).collect();
        let a = s.blocks[0].clone();
        // Overlapping.
        let mut b = a.clone();
        b.name = "b".into();
        b.position_m[1] += 0.02;
        assert!(physically_invalid(&b, std::slice::from_ref(&a), &cams, s.arm.home_yaw_deg).unwrap().contains("too close"));
        // Out of reach (and of view).
        let mut far = a.clone();
        far.position_m = [0.9, 0.0];
        assert!(physically_invalid(&far, &[], &cams, s.arm.home_yaw_deg).unwrap().contains("reach"));
        // In reach but not whole in a view: somewhere to the side of the arm.
        let mut hidden = a.clone();
        let spot = (0..40)
            .flat_map(|i| (0..40).map(move |j| [-0.5 + 0.025 * f64::from(i), -0.5 + 0.025 * f64::from(j)]))
            .find(|p| {
                hidden.position_m = *p;
                let reach = ik(ToolPose { pos_m: DVec3::new(p[0], p[1], GRASP_HEIGHT_M), yaw_rad: s.arm.home_yaw_deg.to_radians() });
                !matches!(reach, Err(IkError::OutOfReach(_))) && block_corners_m(&hidden).iter().any(|c| !in_view(&cams[0], *c))
            })
            .expect("a spot in reach that the left camera does not see");
        hidden.position_m = spot;
        assert!(physically_invalid(&hidden, &[], &cams, s.arm.home_yaw_deg).unwrap().contains("out of a view"), "{spot:?}");
        // A block whose faces all have one shade on a table of that shade renders with no
        // edge at all; it is still a valid cell (the world, not an error).
        let mut faint = a.clone();
        faint.shades = Some(vec![s.table.shade; faint.kind.face_count()]);
        assert_eq!(physically_invalid(&faint, &[], &cams, s.arm.home_yaw_deg), None);
    }
}

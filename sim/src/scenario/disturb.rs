//! One seeded random disturbance per run, for `handeye batch --disturb` (issue 18): a camera
//! knocked, the target nudged, the light changed, or a box crossing between the cameras and
//! the target, at a random moment. Drawn after the layout, from the scenario's own cameras,
//! target and light, so it fits whatever cell the seed made.

use super::config::{Event, Scenario};
use handeye_vision::rng::{SplitMix64, mix64};

impl Scenario {
    /// When a [`Self::add_random_disturbance`] event starts, seconds of simulated time: from
    /// calibration (the gripper is found in the first seconds) to the end of a typical servo.
    pub const DISTURB_AT_S: [f64; 2] = [6.0, 30.0];

    /// Appends one random disturbance drawn from `seed` (the kind, its moment in
    /// [`Self::DISTURB_AT_S`] and its size) and returns it:
    /// - `camera_bump`: the left or right camera turned 1.5-3° about an axis across its view;
    /// - `target_nudge`: the target block pushed 20-30 mm in any direction and turned 10-20°;
    /// - `light_change`: intensity and ambient each scaled by 0.7-1.3 over 0-1.5 s;
    /// - `occluder`: a 80 x 120 x 200 mm box crossing the line from the cameras to the target
    ///   at 40-60 % of the way, sideways, in 1.2-2.0 s.
    pub fn add_random_disturbance(&mut self, seed: u64) -> &Event {
        let mut rng = SplitMix64::new(mix64(seed ^ 0x4449_5354_5552_42));
        let at_s = rng.range(Self::DISTURB_AT_S[0], Self::DISTURB_AT_S[1]);
        let sign = |rng: &mut SplitMix64| if rng.next_f64() < 0.5 { -1.0 } else { 1.0 };
        let target = &self.blocks[self.target_index()];
        let event = match rng.below(4) {
            0 => {
                let camera = self.cameras[rng.below(self.cameras.len())].name.clone();
                let angle_deg = rng.range(1.5, 3.0);
                let axis_rad = rng.range(0.0, std::f64::consts::TAU);
                Event::CameraBump { at_s, camera, rotate_deg: [angle_deg * axis_rad.cos(), angle_deg * axis_rad.sin(), 0.0], translate_mm: [0.0; 3] }
            }
            1 => {
                let (dist_mm, dir_rad) = (rng.range(20.0, 30.0), rng.range(0.0, std::f64::consts::TAU));
                let rotate_deg = sign(&mut rng) * rng.range(10.0, 20.0);
                Event::TargetNudge { at_s, block: target.name.clone(), translate_mm: [dist_mm * dir_rad.cos(), dist_mm * dir_rad.sin()], rotate_deg }
            }
            2 => Event::LightChange {
                at_s,
                ramp_s: rng.range(0.0, 1.5),
                intensity: self.light.intensity * rng.range(0.7, 1.3),
                ambient: self.light.ambient * rng.range(0.7, 1.3),
                direction: None,
            },
            _ => {
                // Across the line from the cameras' midpoint to the target, 40-60 % of the way
                // to the cameras, from one side to the other (horizontal, perpendicular).
                let n = self.cameras.len().max(1) as f64;
                let eye = self.cameras.iter().fold([0.0; 3], |a, c| [a[0] + c.position_m[0] / n, a[1] + c.position_m[1] / n, a[2] + c.position_m[2] / n]);
                let goal = [target.position_m[0], target.position_m[1], 0.5e-3 * target.size_mm[2]];
                let f = rng.range(0.4, 0.6);
                let centre: [f64; 3] = std::array::from_fn(|i| goal[i] + f * (eye[i] - goal[i]));
                let (dx, dy) = (eye[0] - goal[0], eye[1] - goal[1]);
                let len = dx.hypot(dy).max(1e-9);
                let s = sign(&mut rng);
                let side = [-dy / len * s, dx / len * s, 0.0];
                let half_m = 0.3;
                Event::Occluder {
                    at_s,
                    duration_s: rng.range(1.2, 2.0),
                    from_m: std::array::from_fn(|i| centre[i] - half_m * side[i]),
                    to_m: std::array::from_fn(|i| centre[i] + half_m * side[i]),
                    size_mm: [80.0, 120.0, 200.0],
                    shade: rng.range(0.3, 0.8),
                }
            }
        };
        self.events.push(event);
        self.events.last().expect("just pushed")
    }
}

impl Event {
    /// The event in words, for reports: `target_nudge at 12.3 s: cube 24 mm, 13°`.
    pub fn summary(&self) -> String {
        match self {
            Self::CameraBump { at_s, camera, rotate_deg, translate_mm } => {
                let deg = rotate_deg.iter().map(|a| a * a).sum::<f64>().sqrt();
                let mm = translate_mm.iter().map(|a| a * a).sum::<f64>().sqrt();
                format!("camera_bump at {at_s:.1} s: {camera} camera turned {deg:.1}°, moved {mm:.0} mm")
            }
            Self::TargetNudge { at_s, block, translate_mm, rotate_deg } => {
                format!("target_nudge at {at_s:.1} s: {block} pushed {:.0} mm, turned {rotate_deg:.0}°", translate_mm[0].hypot(translate_mm[1]))
            }
            Self::Occluder { at_s, duration_s, .. } => format!("occluder at {at_s:.1} s: crossing the view for {duration_s:.1} s"),
            Self::LightChange { at_s, ramp_s, intensity, ambient, .. } => {
                format!("light_change at {at_s:.1} s: intensity {intensity:.2}, ambient {ambient:.2} over {ramp_s:.1} s")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario() -> Scenario {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/clutter3.toml");
        Scenario::load(&path).unwrap()
    }

    #[test]
    fn a_seed_adds_one_event_of_every_kind_over_seeds_within_its_ranges_and_the_same_each_time() {
        let mut kinds = std::collections::BTreeSet::new();
        for seed in 0..40 {
            let mut s = scenario();
            let before = s.events.len();
            let e = s.add_random_disturbance(seed).clone();
            assert_eq!(s.events.len(), before + 1);
            let at = e.at_s();
            assert!((Scenario::DISTURB_AT_S[0]..=Scenario::DISTURB_AT_S[1]).contains(&at), "{e:?}");
            let target = s.blocks[s.target_index()].clone();
            match &e {
                Event::CameraBump { camera, rotate_deg, .. } => {
                    assert!(s.cameras.iter().any(|c| &c.name == camera));
                    let a = rotate_deg[0].hypot(rotate_deg[1]);
                    assert!((1.5..=3.0).contains(&a) && rotate_deg[2] == 0.0, "{e:?}");
                    kinds.insert("camera_bump");
                }
                Event::TargetNudge { block, translate_mm, rotate_deg, .. } => {
                    assert_eq!(block, &target.name);
                    assert!((20.0..=30.0).contains(&translate_mm[0].hypot(translate_mm[1])) && (10.0..=20.0).contains(&rotate_deg.abs()), "{e:?}");
                    kinds.insert("target_nudge");
                }
                Event::LightChange { intensity, ambient, .. } => {
                    let (i, a) = (intensity / s.light.intensity, ambient / s.light.ambient);
                    assert!((0.7..=1.3).contains(&i) && (0.7..=1.3).contains(&a), "{e:?}");
                    kinds.insert("light_change");
                }
                Event::Occluder { from_m, to_m, .. } => {
                    // Its path's midpoint lies on the line from the target to the cameras.
                    let mid: [f64; 3] = std::array::from_fn(|i| 0.5 * (from_m[i] + to_m[i]));
                    let n = s.cameras.len() as f64;
                    let eye: [f64; 3] = std::array::from_fn(|i| s.cameras.iter().map(|c| c.position_m[i]).sum::<f64>() / n);
                    let goal = [target.position_m[0], target.position_m[1], 0.5e-3 * target.size_mm[2]];
                    let f = (mid[2] - goal[2]) / (eye[2] - goal[2]);
                    assert!((0.4..=0.6).contains(&f), "{e:?}");
                    for i in 0..2 {
                        assert!((mid[i] - (goal[i] + f * (eye[i] - goal[i]))).abs() < 1e-9, "{e:?}");
                    }
                    kinds.insert("occluder");
                }
            }
            let mut again = scenario();
            assert_eq!(format!("{:?}", again.add_random_disturbance(seed)), format!("{e:?}"), "seed {seed} draws the same event");
        }
        assert_eq!(kinds.len(), 4, "{kinds:?}");
    }
}

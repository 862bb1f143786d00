//! Scripted disturbances: camera bumps, target nudges, occluders crossing the view, and
//! lighting changes, fired at their times in simulated nanoseconds (never wall-clock time, so
//! runs stay deterministic).

use glam::DVec3;

use crate::cell::world::World;
use crate::render::camera::Camera;
use crate::render::shading::Lighting;
use crate::scenario::{Event, Scenario, s_to_ns};

/// The state the events change, and which of them have fired.
#[derive(Debug, Clone)]
pub struct EventState {
    events: Vec<Event>,
    fired: Vec<bool>,
    pub cameras: [Camera; 2],
    pub lighting: Lighting,
    /// A lighting ramp under way: (start ns, end ns, from, to).
    ramp: Option<(u64, u64, Lighting, Lighting)>,
}

impl EventState {
    pub fn new(scenario: &Scenario) -> Self {
        Self {
            events: scenario.events.clone(),
            fired: vec![false; scenario.events.len()],
            cameras: [Camera::from_config(&scenario.cameras[0]), Camera::from_config(&scenario.cameras[1])],
            lighting: Lighting::from_config(&scenario.light),
            ramp: None,
        }
    }

    /// Fires every event due at `now_ns` (called at each physics step boundary).
    pub fn update(&mut self, now_ns: u64, world: &mut World) {
        for i in 0..self.events.len() {
            if self.fired[i] || s_to_ns(self.events[i].at_s()) > now_ns {
                continue;
            }
            self.fired[i] = true;
            match &self.events[i] {
                Event::CameraBump { camera, rotate_deg, translate_mm, .. } => {
                    let k = usize::from(camera != "left");
                    let rot = DVec3::from_array(*rotate_deg) * (std::f64::consts::PI / 180.0);
                    self.cameras[k] = self.cameras[k].bumped(rot, DVec3::from_array(*translate_mm) * 1e-3);
                    tracing::info!(camera, ?rotate_deg, ?translate_mm, "event: camera bump");
                }
                Event::TargetNudge { block, translate_mm, rotate_deg, .. } => {
                    if let Some(b) = world.blocks.iter().position(|b| &b.name == block) {
                        world.nudge_block(b, [translate_mm[0] * 1e-3, translate_mm[1] * 1e-3], rotate_deg.to_radians());
                    }
                    tracing::info!(block, "event: target nudge");
                }
                Event::Occluder { .. } => {} // drawn by `occluder_position` while active
                Event::LightChange { ramp_s, intensity, ambient, direction, .. } => {
                    let to = Lighting {
                        direction: direction.map_or(self.lighting.direction, |d| DVec3::from_array(d).normalize()),
                        intensity: *intensity,
                        ambient: *ambient,
                    };
                    let start = now_ns;
                    self.ramp = Some((start, start + s_to_ns(*ramp_s), self.lighting, to));
                    tracing::info!(intensity, ambient, "event: light change");
                }
            }
        }
        if let Some((t0, t1, from, to)) = self.ramp {
            if now_ns >= t1 {
                self.lighting = to;
                self.ramp = None;
            } else {
                self.lighting = from.lerp(&to, (now_ns - t0) as f64 / (t1 - t0) as f64);
            }
        }
    }

    /// Where occluder event `index` is at `now_ns`, if it is crossing the scene now.
    pub fn occluder_position(&self, index: usize, now_ns: u64) -> Option<DVec3> {
        let Event::Occluder { at_s, duration_s, from_m, to_m, .. } = self.events.get(index)? else { return None };
        let (t0, t1) = (s_to_ns(*at_s), s_to_ns(*at_s + *duration_s));
        if now_ns < t0 || now_ns > t1 {
            return None;
        }
        let s = (now_ns - t0) as f64 / (t1 - t0).max(1) as f64;
        Some(DVec3::from_array(*from_m).lerp(DVec3::from_array(*to_m), s))
    }
}

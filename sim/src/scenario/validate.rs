//! Semantic checks of a deserialised scenario (ranges, references between sections, counts);
//! each failure carries the path of the offending field.

use super::config::{BlockKind, Event, Scenario};
use super::locate::Seg;

impl Scenario {
    /// Semantic checks after deserialisation; the error carries the field path.
    pub(super) fn validate(&self) -> Result<(), (Vec<Seg>, String)> {
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

        if let Some(r) = &self.randomize {
            r.check().map_err(|(f, m)| (p(&[K("randomize"), K(f)]), m))?;
        }

        if let Some(pt) = &self.pointer {
            pt.check().map_err(|(f, m)| (p(&[K("pointer"), K(f)]), m))?;
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

//! The controller's motion profile: an online trapezoidal profile (speed limit, acceleration
//! limit, braking curve) that a new goal may replace at any tick without a jerk. Pure math.

use glam::DVec3;

/// One step of an online trapezoidal profile in 3-D: accelerate towards the goal, cruise at
/// `vmax`, brake along `sqrt(2 a d)`, never overshoot.
pub fn profile_3d(p: DVec3, v: DVec3, goal: DVec3, vmax: f64, a: f64, dt: f64) -> (DVec3, DVec3) {
    let e = goal - p;
    let d = e.length();
    if d < 1e-9 && v.length() < a * dt {
        return (goal, DVec3::ZERO);
    }
    let dir = if d > 0.0 { e / d } else { DVec3::ZERO };
    let speed = vmax.min((2.0 * a * d).sqrt()).min(d / dt);
    let dv = dir * speed - v;
    let max_dv = a * dt;
    let v_new = if dv.length() > max_dv { v + dv * (max_dv / dv.length()) } else { dir * speed };
    let p_new = p + v_new * dt;
    // Arriving within this step (the braking curve makes the landing speed tiny): land exactly.
    if (goal - p_new).dot(e) <= 0.0 || (goal - p_new).length() < 1e-9 {
        return (goal, DVec3::ZERO);
    }
    (p_new, v_new)
}

/// [`profile_3d`] along one axis (the tool yaw).
pub fn profile_1d(x: f64, v: f64, goal: f64, vmax: f64, a: f64, dt: f64) -> (f64, f64) {
    let (p, vv) = profile_3d(DVec3::new(x, 0.0, 0.0), DVec3::new(v, 0.0, 0.0), DVec3::new(goal, 0.0, 0.0), vmax, a, dt);
    (p.x, vv.x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_respects_speed_and_acceleration_and_lands_exactly() {
        let (vmax, a, dt) = (0.15, 1.0, 1.0 / 240.0);
        let goal = DVec3::new(0.2, -0.1, 0.05);
        let (mut p, mut v) = (DVec3::ZERO, DVec3::ZERO);
        let mut steps = 0;
        while (p != goal || v != DVec3::ZERO) && steps < 10_000 {
            let (np, nv) = profile_3d(p, v, goal, vmax, a, dt);
            assert!(nv.length() <= vmax + 1e-9, "speed {}", nv.length());
            // Acceleration bounded (the last landing step may brake a little harder).
            if np != goal {
                assert!((nv - v).length() <= a * dt * 1.0001, "accel {}", (nv - v).length() / dt);
            }
            assert!((goal - np).length() <= (goal - p).length() + 1e-12, "moves towards the goal");
            p = np;
            v = nv;
            steps += 1;
        }
        assert_eq!(p, goal);
        // Distance 0.229 m at 0.15 m/s with 1 m/s² ramps: about 1.68 s.
        let t = steps as f64 * dt;
        assert!((1.6..1.8).contains(&t), "took {t} s");
    }
}

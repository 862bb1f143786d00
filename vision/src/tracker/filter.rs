//! The first-order predictive filter of Appendix A: the contour's velocity is estimated from
//! frame to frame and, scaled by the real time between frames, places the next search.

use super::frame::Placement;

/// An alpha-beta filter on the placement's parameters (origin, basis vectors, perspective)
/// with alpha = 1: the measured placement is taken as it is (as the thesis does), and the
/// velocity follows the prediction error with gain `beta` (origin) or `beta_deformation`
/// (basis vectors and perspective).
#[derive(Debug, Clone)]
pub(crate) struct PredictiveFilter {
    /// Parameter velocities, per second: `[o.x, o.y, e1.x, e1.y, e2.x, e2.y, w.x, w.y]`.
    velocity: [f64; 8],
    pub beta: f64,
    pub beta_deformation: f64,
    /// Largest predicted move of the origin in one step, px (keeps a bad velocity from
    /// throwing the search off the object).
    pub max_step_px: f64,
}

impl PredictiveFilter {
    pub fn new(beta: f64, beta_deformation: f64, max_step_px: f64) -> Self {
        Self { velocity: [0.0; 8], beta, beta_deformation, max_step_px }
    }

    pub fn reset(&mut self) {
        self.velocity = [0.0; 8];
    }

    /// The placement expected `dt_s` seconds after `placement`.
    pub fn predict(&self, placement: &Placement, dt_s: f64) -> Placement {
        let mut p = placement.to_params();
        let mut scale = dt_s;
        // Limit the origin's step; scale the whole velocity down with it so shape and
        // position stay consistent.
        let step = (self.velocity[0].hypot(self.velocity[1])) * dt_s;
        if step > self.max_step_px && step > 0.0 {
            scale *= self.max_step_px / step;
        }
        for (p, v) in p.iter_mut().zip(self.velocity) {
            *p += v * scale;
        }
        Placement::from_params(p)
    }

    /// Updates the velocity from how far the measurement landed from the prediction.
    pub fn correct(&mut self, predicted: &Placement, measured: &Placement, dt_s: f64) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return;
        }
        let (p, m) = (predicted.to_params(), measured.to_params());
        for k in 0..8 {
            let gain = if k < 2 { self.beta } else { self.beta_deformation };
            self.velocity[k] += gain * (m[k] - p[k]) / dt_s;
        }
    }

    /// Current velocity of the origin, px/s.
    pub fn origin_velocity(&self) -> [f64; 2] {
        [self.velocity[0], self.velocity[1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracker::TemplateFrame;
    use nalgebra::Vector2;

    #[test]
    fn learns_a_constant_velocity_and_scales_prediction_by_real_time() {
        let mut f = PredictiveFilter::new(0.5, 0.5, 100.0);
        let v = Vector2::new(30.0, -12.0); // px/s
        let mut frame = TemplateFrame::new(Vector2::new(100.0, 100.0), Vector2::new(10.0, 0.0), Vector2::new(0.0, 10.0));
        let mut time = 0.0;
        // Irregular frame intervals.
        for k in 0..60 {
            let dt = [0.02, 0.033, 0.05][k % 3];
            time += dt;
            let predicted = f.predict(&Placement::affine(frame), dt);
            let truth = TemplateFrame { origin: Vector2::new(100.0, 100.0) + v * time, ..frame };
            f.correct(&predicted, &Placement::affine(truth), dt);
            frame = truth;
        }
        let got = f.origin_velocity();
        assert!((got[0] - 30.0).abs() < 0.1 && (got[1] + 12.0).abs() < 0.1, "{got:?}");
        let p = f.predict(&Placement::affine(frame), 0.1).frame;
        assert!((p.origin - (frame.origin + v * 0.1)).norm() < 0.02);
    }

    #[test]
    fn prediction_step_is_limited() {
        let mut f = PredictiveFilter::new(1.0, 1.0, 5.0);
        let a = Placement::affine(TemplateFrame::new(Vector2::zeros(), Vector2::new(1.0, 0.0), Vector2::new(0.0, 1.0)));
        let b = Placement::affine(TemplateFrame { origin: Vector2::new(100.0, 0.0), ..a.frame });
        f.correct(&a, &b, 0.1); // 1000 px/s
        let p = f.predict(&b, 0.1);
        assert!(((p.frame.origin - b.frame.origin).norm() - 5.0).abs() < 1e-9);
        // A non-positive time step teaches nothing.
        let mut g = PredictiveFilter::new(1.0, 1.0, 5.0);
        g.correct(&a, &b, 0.0);
        assert_eq!(g.origin_velocity(), [0.0, 0.0]);
    }
}

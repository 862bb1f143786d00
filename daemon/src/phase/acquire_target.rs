//! Acquire the target from the operator hint: one tracker per view on the hinted facet
//! polygon, checked against the epipolar constraint (corners that break it mean the two
//! clicks are not the same facet), left to converge with the arm still, then verified.

use handeye_vision::tracker::{ContourTracker, Role, View};

use super::{timed_out, Cmd, Cycle, Mission, Step};

pub struct AcquireTarget {
    start_frame: u64,
    started: bool,
    frames: u32,
}

impl AcquireTarget {
    pub fn new(frame_index: u64) -> Self {
        Self { start_frame: frame_index, started: false, frames: 0 }
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(&m.cfg, self.start_frame, c.frame_index, m.cfg.target.timeout_s) {
            return Step::Fail(format!("acquire_target: timed out after {} s", m.cfg.target.timeout_s));
        }
        if !self.started {
            self.started = true;
            let Some(hint) = m.hint.as_ref() else {
                return Step::Fail("acquire_target: no operator hint (start the daemon with --hint FILE)".into());
            };
            let Some(cal) = m.calibration.as_ref() else { return Step::Fail("acquire_target: not calibrated".into()) };
            let n = hint.left_px.len();
            let rms = (hint
                .left_px
                .iter()
                .zip(&hint.right_px)
                .map(|(l, r)| cal.model.epipolar().residual_px(&[l[0], l[1], r[0], r[1]]).powi(2))
                .sum::<f64>()
                / n as f64)
                .sqrt();
            if rms > m.cfg.target.max_epipolar_px {
                return Step::Fail(format!(
                    "acquire_target: the hint's corners break the epipolar constraint ({rms:.1} px RMS > {} px): not the same facet in both views?",
                    m.cfg.target.max_epipolar_px
                ));
            }
            let max_depth = m.cfg.gripper.max_opening_m * 1e3;
            if hint.depth_mm >= max_depth {
                return Step::Fail(format!("acquire_target: the target is {:.0} mm deep, wider than the jaws open ({max_depth:.0} mm)", hint.depth_mm));
            }
            for (view, poly) in [(View::Left, &hint.left_px), (View::Right, &hint.right_px)] {
                match ContourTracker::new(m.cfg.tracker.target_tracker_config(), poly) {
                    Ok(t) => {
                        m.trackers.insert(Role::Target, view, t);
                    }
                    Err(e) => return Step::Fail(format!("acquire_target: hint polygon ({view:?}): {e}")),
                }
            }
            m.set_status("acquire target: trackers on the hinted facet converging");
            return Step::Stay(Cmd::HOLD);
        }
        self.frames += 1;
        // Twice while converging: refine the hinted corners from the image's edges and restart
        // the trackers on them (the hint's corner errors would otherwise stay in the template).
        let half = m.cfg.target.converge_frames / 3;
        if half > 0 && (self.frames == half || self.frames == 2 * half) {
            for view in View::ALL {
                let Some(t) = m.trackers.get_mut(Role::Target, view) else { continue };
                if let Some(corners) = crate::gripper::refine_polygon(t) {
                    let _ = t.reinit(&corners);
                }
            }
        }
        if self.frames < m.cfg.target.converge_frames {
            return Step::Stay(Cmd::HOLD);
        }
        for view in View::ALL {
            let Some(t) = m.trackers.get(Role::Target, view) else { return Step::Fail("acquire_target: tracker missing".into()) };
            let score = t.confidence().score;
            if score < m.cfg.target.min_score {
                return Step::Fail(format!("acquire_target: target tracker ({view:?}) confidence {score:.2} < {}", m.cfg.target.min_score));
            }
        }
        m.snapshot = Some("target_acquired");
        m.set_status("target acquired");
        Step::Next(Cmd::HOLD)
    }
}

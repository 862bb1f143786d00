//! What a search candidate must satisfy to count as a contour re-found (`crate::recovery`):
//! not another contour tracked in its view, not the wrong lock its tracker was refused on, and
//! on the calibration's epipolar constraint with the other view (issues 18, 19).

use handeye_vision::affine::EpipolarConstraint;
use handeye_vision::tracker::{ContourTracker, Role, StereoTrackerSet, View};
use nalgebra::Vector2;

/// A candidate whose every corner is within this of the shape a tracker was declared wrongly
/// locked on, px, is that lock again, not a recovery (issue 18: the search's base, the last
/// steady shape, can itself be the wrong lock; seed 22 of point_clutter3 re-found a strip of
/// the robot's base 0.7 px from where it was refused). The tracker's own search reaches
/// ±12 px, so a candidate this close would converge onto the refused lock anyway.
pub const REFUSED_LOCK_TOL_PX: f64 = 4.0;

/// The calibration's epipolar constraint, to verify a re-found target against the other
/// view (the same check the acquisition makes of a hint).
#[derive(Debug, Clone, Copy)]
pub struct EpipolarCheck {
    pub constraint: EpipolarConstraint,
    /// Largest residual accepted, px, beyond the plate's own (a moved camera offsets both).
    pub tol_px: f64,
    /// Largest residual a re-found plate may have with the other view's plate, px: from the
    /// calibration's own residual ([`plate_tol_px`]).
    pub plate_tol_px: f64,
}

/// Standard deviations of the calibration's residual a re-found plate pair may be off the
/// epipolar constraint. Seed 22 of point_clutter3: the pair before the loss 0.2 px off, the
/// look-alike on the robot's base 69 px off, against a fit residual of 5.35 px RMS.
pub const PLATE_EPIPOLAR_SIGMAS: f64 = 3.0;
/// Least tolerance of the plate check, px (a near-perfect fit still sees tracker noise).
pub const MIN_PLATE_EPIPOLAR_TOL_PX: f64 = 4.0;

/// The plate check's tolerance from the calibration's residuals (the affine fit's over the cage
/// and the image-only epipolar fit's, RMS px).
pub fn plate_tol_px(fit_rms_px: f64, epipolar_rms_px: f64) -> f64 {
    (PLATE_EPIPOLAR_SIGMAS * fit_rms_px.max(epipolar_rms_px)).max(MIN_PLATE_EPIPOLAR_TOL_PX)
}

/// The other camera's view.
pub(crate) fn other(view: View) -> View {
    if view == View::Left { View::Right } else { View::Left }
}

/// The tracker of `role` in `view` if it is active and tracking.
pub(crate) fn tracked(trackers: &StereoTrackerSet, role: Role, view: View) -> Option<&ContourTracker> {
    trackers.is_active(role, view).then(|| trackers.get(role, view)).flatten().filter(|t| t.state().is_tracking())
}

fn centroid(t: &ContourTracker) -> Vector2<f64> {
    let n = t.corners().len().max(1) as f64;
    t.corners().sum::<Vector2<f64>>() / n
}

/// Whether `p` lies inside the closed polygon `poly` (even-odd rule).
fn inside(poly: &[Vector2<f64>], p: Vector2<f64>) -> bool {
    let mut odd = false;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y) {
            odd = !odd;
        }
    }
    odd
}

/// A search candidate for `role` in `view` is not another contour that is being tracked
/// there (a square lost off a block face locks happily onto part of the plate), and, for
/// a target the other view still tracks, satisfies the epipolar constraint with it. A plate
/// candidate must satisfy it with the other view's tracked plate too (issue 19, seed 22: the
/// right plate re-found on a look-alike strip of the robot's base passed the area check but
/// sat 69 px off the constraint): `mate_plate`, the other view's plate origin to check
/// against (`Recovery::mate_plate`; `None`: no check).
pub(crate) fn plausible(cand: &ContourTracker, role: Role, view: View, trackers: &StereoTrackerSet, epipolar: Option<&EpipolarCheck>, mate_plate: Option<Vector2<f64>>) -> bool {
    let tracked = |r: Role, v: View| tracked(trackers, r, v);
    let other_role = if role == Role::Gripper { Role::Target } else { Role::Gripper };
    if let Some(o) = tracked(other_role, view) {
        let poly: Vec<Vector2<f64>> = o.corners().collect();
        let cpoly: Vec<Vector2<f64>> = cand.corners().collect();
        if inside(&poly, centroid(cand)) || inside(&cpoly, centroid(o)) {
            return false;
        }
    }
    if role == Role::Target
        && let Some(e) = epipolar
        && let Some(mate) = tracked(Role::Target, other(view))
    {
        let (l, r) = if view == View::Left { (centroid(cand), centroid(mate)) } else { (centroid(mate), centroid(cand)) };
        let residual = |l: Vector2<f64>, r: Vector2<f64>| e.constraint.residual_px(&[l.x, l.y, r.x, r.y]);
        // The plate's residual in the same pair: what a moved camera adds to every point.
        let offset = match (tracked(Role::Gripper, View::Left), tracked(Role::Gripper, View::Right)) {
            (Some(gl), Some(gr)) => residual(centroid(gl), centroid(gr)),
            _ => 0.0,
        };
        if (residual(l, r) - offset).abs() > e.tol_px {
            return false;
        }
    }
    if role == Role::Gripper
        && let Some(e) = epipolar
        && let Some(mate) = mate_plate
    {
        // Frame origins (the template's centre): plate points all lie on the constraint
        // under the affine model; a point extrapolated from the frame would not.
        let c = cand.frame().origin;
        let (l, r) = if view == View::Left { (c, mate) } else { (mate, c) };
        let residual = e.constraint.residual_px(&[l.x, l.y, r.x, r.y]);
        if !(residual.abs() <= e.plate_tol_px) {
            tracing::debug!(?role, ?view, residual, tol = e.plate_tol_px, "plate candidate off the other view's plate's epipolar line: refused");
            return false;
        }
    }
    true
}

/// Whether `cand` sits on the `refused` corners (the lock its tracker was declared wrong on):
/// every corner within [`REFUSED_LOCK_TOL_PX`].
pub(crate) fn same_lock(cand: &ContourTracker, refused: &[Vector2<f64>]) -> bool {
    let corners: Vec<Vector2<f64>> = cand.corners().collect();
    corners.len() == refused.len() && corners.iter().zip(refused).all(|(c, r)| (c - r).norm() <= REFUSED_LOCK_TOL_PX)
}

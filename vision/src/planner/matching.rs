//! Candidate stereo matches under the weak linear epipolar constraint, and their mutual
//! support ("FRIENDS").
//!
//! With a linear epipolar constraint `n·(u, v, u', v') + n0 = 0` all epipolar lines in a view
//! are parallel, so each view has one *epipolar coordinate* across them: for a right point
//! `x'`, `η(x') = n_r·x' / |n_r|` (right pixels); for a left point `x`, the value its match
//! must have, `η̂(x) = −(n_l·x + n0) / |n_r|`. A left segment covers an interval of `η̂`, a
//! right segment an interval of `η`; a candidate match needs the two intervals to overlap
//! (each widened by the tolerance `epipolar_tol_px` of the weak calibration), the implied
//! horizontal disparities `u' − u` to fall within the workspace limits, the same contrast
//! polarity and similar contrast, and a bounded change of orientation. Right segments are
//! sorted by interval start, so each left segment scans only those that can overlap.
//!
//! Two candidates are *friends* when their left segments form a junction and their right
//! segments form the corresponding junction (same ends), with the two junction points
//! themselves obeying the epipolar constraint: the figural continuity that seeds coplanarity
//! grouping.

use super::geom::{self, P2};
use super::relations::{End, Relations};
use nalgebra::Vector3;

use super::projective::ProjectiveStereo;
use super::segments::Segment;
use crate::affine::{AffineStereo, EpipolarConstraint, FitError};

/// The stereo geometry the matcher works with: the epipolar constraint (known up to a small
/// error) and the workspace's disparity limits; the full affine model when calibrated.
#[derive(Debug, Clone, PartialEq)]
pub struct EpipolarGeometry {
    pub epipolar: EpipolarConstraint,
    /// A smooth correction of the linear constraint, fitted by the planner's bootstrap when
    /// the cameras are not quite affine (`None` from a calibration).
    pub correction: Option<EpipolarCorrection>,
    /// Allowed horizontal disparity `u' − u`, pixels (margins included).
    pub disparity_px: [f64; 2],
    /// The affine stereo model, when the robot coordinates of the calibration are known.
    pub model: Option<AffineStereo>,
    /// Pinhole cameras fitted to the same calibration points (>= 6, not coplanar), when
    /// known: robot coordinates come from these rather than from the affine model, whose
    /// weak-perspective error is several millimetres at the simulator's distances (see
    /// [`ProjectiveStereo`]).
    pub projective: Option<ProjectiveStereo>,
}

impl EpipolarGeometry {
    /// From a calibrated model: its epipolar constraint, and its calibration disparity range
    /// widened by `margin_frac` of the range plus `margin_px` on each side (objects on the
    /// table lie a little outside a cage held above it).
    pub fn from_model(model: AffineStereo, margin_frac: f64, margin_px: f64) -> Self {
        let [lo, hi] = model.disparity_range_px;
        let m = margin_frac * (hi - lo) + margin_px;
        Self { epipolar: model.epipolar(), correction: None, disparity_px: [lo - m, hi + m], model: Some(model), projective: None }
    }

    /// From calibration points with robot coordinates (such as the simulator's cage): the
    /// affine model as [`from_model`](Self::from_model), and the pinhole cameras for metric
    /// reconstruction when the points allow them (>= 6, not coplanar); an error when not even
    /// the affine model can be fitted.
    pub fn from_calibration_points(robot_m: &[Vector3<f64>], image_px: &[[f64; 4]], margin_frac: f64, margin_px: f64) -> Result<Self, FitError> {
        let model = AffineStereo::fit(robot_m, image_px)?;
        Ok(Self { projective: ProjectiveStereo::fit(robot_m, image_px).ok(), ..Self::from_model(model, margin_frac, margin_px) })
    }

    /// Robot coordinates of the point seen at `w = (u, v, u', v')`: through the pinhole
    /// cameras when known, else the affine model; `None` when uncalibrated.
    pub fn robot_point(&self, w: &[f64; 4]) -> Option<[f64; 3]> {
        match (&self.projective, &self.model) {
            (Some(p), _) => Some(p.reconstruct(w).into()),
            (None, Some(m)) => Some(m.reconstruct(w).into()),
            (None, None) => None,
        }
    }

    /// From `>= 4` correspondences `(u, v, u', v')` without robot coordinates: the epipolar
    /// constraint by orthogonal regression, disparity limits from their range plus margins.
    pub fn from_correspondences(points: &[[f64; 4]], margin_frac: f64, margin_px: f64) -> Result<Self, FitError> {
        let epipolar = EpipolarConstraint::fit(points)?;
        let (lo, hi) = points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), w| (lo.min(w[2] - w[0]), hi.max(w[2] - w[0])));
        let m = margin_frac * (hi - lo) + margin_px;
        Ok(Self { epipolar, correction: None, disparity_px: [lo - m, hi + m], model: None, projective: None })
    }

    /// Sets the correction of the linear constraint that the pinhole cameras imply, so that
    /// matching follows the cameras' true epipolar geometry where the linear constraint of a
    /// cage held above the table is off (near the image edges, blocks close to the cameras:
    /// 9 px at the bottom of a 640 x 480 view at 1.6 m, three times the tolerance, where the
    /// bootstrap's junctions, taken from the middle of the scene, do not reach). A grid of
    /// left pixels (every 16 px of a `width` x `height` view) is followed down to each of
    /// `heights_m` (robot z: where the objects are), seen by the right camera, and the
    /// residuals of the linear constraint there are fitted ([`EpipolarCorrection::fit`]).
    /// Returns the RMS of what the correction leaves of them, pixels; `None` (and no change)
    /// without pinhole cameras or points in both views.
    pub fn correct_from_cameras(&mut self, width: usize, height: usize, heights_m: &[f64]) -> Option<f64> {
        let cams = self.projective.as_ref()?;
        let linear = EpipolarFrame::new(&self.epipolar);
        let (w, h) = (width as f64, height as f64);
        // The bottom middle of the view looks down at the table: its depth's sign is "in
        // front" (a DLT fixes each camera only up to sign).
        let &z0 = heights_m.first()?;
        let (_, front) = cams.left_ray_at_height(0.5 * w, h - 1.0, z0)?;
        let mut points: Vec<(P2, f64)> = Vec::new();
        for &z in heights_m {
            for v in (8..height).step_by(16) {
                for u in (8..width).step_by(16) {
                    let (uf, vf) = (u as f64, v as f64);
                    let Some((x, depth)) = cams.left_ray_at_height(uf, vf, z) else { continue };
                    if depth[0] * front[0] <= 0.0 || depth[1] * front[1] <= 0.0 {
                        continue;
                    }
                    let q = cams.project(&x);
                    if !(0.0..w).contains(&q[2]) || !(0.0..h).contains(&q[3]) {
                        continue;
                    }
                    points.push(([uf, vf], linear.residual([uf, vf], [q[2], q[3]])));
                }
            }
        }
        let (correction, _) = EpipolarCorrection::fit(&points)?;
        let rms = (points.iter().map(|(x, r)| (r - correction.eval(*x)).powi(2)).sum::<f64>() / points.len() as f64).sqrt();
        self.correction = Some(correction);
        Some(rms)
    }

    /// The epipolar coordinates of this geometry (constraint and correction).
    pub fn frame(&self) -> EpipolarFrame {
        EpipolarFrame::with_correction(&self.epipolar, self.correction)
    }
}

/// A smooth correction `g` of the linear epipolar constraint, right pixels across the
/// epipolar lines: a left point `x`'s match lies at `η = η̂(x) + g(x)` (see [`EpipolarFrame`]).
///
/// Perspective cameras are affine only to first order: over a workspace seen from ~1.6 m with
/// a 20° vergence, true correspondences stray up to ~6 px from the best linear constraint of a
/// calibration cage held above the table, and by different amounts in different parts of the
/// image (the arm high up, the blocks on the table). A quadratic in the left image position
/// absorbs most of that; it is fitted to matched junctions by the bootstrap. Outside the box
/// of the points it was fitted to it is not extrapolated: `g` is evaluated at the nearest
/// point of that box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpipolarCorrection {
    /// Coefficients of `1, s, t, s², s·t, t²`, with `(s, t) = (x − centre) / scale`.
    pub coef: [f64; 6],
    pub centre: P2,
    pub scale: f64,
    /// The box of the fitted points (left pixels).
    pub lo: P2,
    pub hi: P2,
}

impl EpipolarCorrection {
    /// `g(x)`, right pixels.
    #[inline]
    pub fn eval(&self, x: P2) -> f64 {
        let x = [x[0].clamp(self.lo[0], self.hi[0]), x[1].clamp(self.lo[1], self.hi[1])];
        let (s, t) = ((x[0] - self.centre[0]) / self.scale, (x[1] - self.centre[1]) / self.scale);
        let c = &self.coef;
        c[0] + c[1] * s + c[2] * t + c[3] * s * s + c[4] * s * t + c[5] * t * t
    }

    /// Least-squares fit of `g` to `(left point, residual)` pairs, with outliers (beyond 2.5
    /// robust standard deviations, at least 0.5 px) dropped twice. The model grows with the
    /// data: a constant from 2 points, a plane from 6 spread in two directions, the full
    /// quadratic from 15 spread over at least 60 px each way. `None` with fewer than 2.
    pub fn fit(points: &[(P2, f64)]) -> Option<(Self, usize)> {
        if points.len() < 2 {
            return None;
        }
        let mut keep: Vec<bool> = vec![true; points.len()];
        let mut out = None;
        for _ in 0..3 {
            let kept: Vec<(P2, f64)> = points.iter().zip(&keep).filter(|(_, k)| **k).map(|(p, _)| *p).collect();
            let Some(corr) = Self::fit_once(&kept) else { break };
            let res: Vec<f64> = points.iter().map(|(x, r)| (r - corr.eval(*x)).abs()).collect();
            let mut sorted: Vec<f64> = res.iter().zip(&keep).filter(|(_, k)| **k).map(|(r, _)| *r).collect();
            sorted.sort_by(f64::total_cmp);
            let cut = (2.5 * 1.4826 * sorted[sorted.len() / 2]).max(0.5);
            let next: Vec<bool> = res.iter().map(|&r| r <= cut).collect();
            let n = next.iter().filter(|k| **k).count();
            out = Some((corr, kept.len()));
            if next == keep || n < 2 {
                break;
            }
            keep = next;
        }
        out
    }

    fn fit_once(points: &[(P2, f64)]) -> Option<Self> {
        let n = points.len();
        if n < 2 {
            return None;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (x, _) in points {
            lo = [lo[0].min(x[0]), lo[1].min(x[1])];
            hi = [hi[0].max(x[0]), hi[1].max(x[1])];
        }
        let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        let scale = (0.5 * (hi[0] - lo[0]).max(hi[1] - lo[1])).max(1.0);
        let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
        // Spread across the points' main direction decides whether a plane is determined.
        let mean = points.iter().fold([0.0; 2], |a, (x, _)| [a[0] + x[0] / n as f64, a[1] + x[1] / n as f64]);
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for (x, _) in points {
            let (dx, dy) = (x[0] - mean[0], x[1] - mean[1]);
            sxx += dx * dx / n as f64;
            sxy += dx * dy / n as f64;
            syy += dy * dy / n as f64;
        }
        let minor = (0.5 * (sxx + syy) - (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt()).max(0.0).sqrt();
        let terms = if n >= 15 && w >= 60.0 && h >= 60.0 && minor >= 15.0 {
            6
        } else if n >= 6 && minor >= 10.0 {
            3
        } else {
            1
        };
        let mut ata = nalgebra::DMatrix::<f64>::zeros(terms, terms);
        let mut atb = nalgebra::DVector::<f64>::zeros(terms);
        for (x, r) in points {
            let (s, t) = ((x[0] - centre[0]) / scale, (x[1] - centre[1]) / scale);
            let basis = [1.0, s, t, s * s, s * t, t * t];
            for i in 0..terms {
                atb[i] += basis[i] * r;
                for j in 0..terms {
                    ata[(i, j)] += basis[i] * basis[j];
                }
            }
        }
        // A little ridge on the non-constant terms keeps a thin spread of points from tilting
        // the correction wildly.
        for i in 1..terms {
            ata[(i, i)] += 1e-3 * n as f64;
        }
        let sol = ata.cholesky()?.solve(&atb);
        let mut coef = [0.0; 6];
        for i in 0..terms {
            coef[i] = sol[i];
        }
        coef.iter().all(|c| c.is_finite()).then_some(Self { coef, centre, scale, lo, hi })
    }
}

/// Epipolar coordinates of both views (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct EpipolarFrame {
    nl: P2,
    nr: P2,
    n0: f64,
    inv_nr: f64,
    correction: Option<EpipolarCorrection>,
}

impl EpipolarFrame {
    pub fn new(e: &EpipolarConstraint) -> Self {
        Self::with_correction(e, None)
    }

    /// With a smooth correction of the constraint (see [`EpipolarCorrection`]).
    pub fn with_correction(e: &EpipolarConstraint, correction: Option<EpipolarCorrection>) -> Self {
        let nl = [e.n[0], e.n[1]];
        let nr = [e.n[2], e.n[3]];
        let len = geom::norm(nr).max(1e-9);
        Self { nl, nr, n0: e.n0, inv_nr: 1.0 / len, correction }
    }

    /// `(n_r, 1/|n_r|)`: `η` of a right point is `n_r·x' / |n_r|`.
    pub fn right_normal(&self) -> (P2, f64) {
        (self.nr, self.inv_nr)
    }

    /// `η` of a right point, right pixels across the epipolar lines.
    #[inline]
    pub fn eta_right(&self, x: P2) -> f64 {
        geom::dot(self.nr, x) * self.inv_nr
    }

    /// The `η` a left point's match must have.
    #[inline]
    pub fn eta_left(&self, x: P2) -> f64 {
        let linear = -(geom::dot(self.nl, x) + self.n0) * self.inv_nr;
        match &self.correction {
            Some(c) => linear + c.eval(x),
            None => linear,
        }
    }

    /// Signed distance of right point `xr` from the epipolar line of left point `xl`, right
    /// pixels.
    #[inline]
    pub fn residual(&self, xl: P2, xr: P2) -> f64 {
        self.eta_right(xr) - self.eta_left(xl)
    }

    /// Unit direction of the epipolar lines in the right view.
    pub fn right_dir(&self) -> P2 {
        [-self.nr[1] * self.inv_nr, self.nr[0] * self.inv_nr]
    }

    /// Unit direction of the epipolar lines in the left view.
    pub fn left_dir(&self) -> P2 {
        let l = geom::norm(self.nl).max(1e-12);
        [-self.nl[1] / l, self.nl[0] / l]
    }

    /// The point on the line `p + t·d` (right view) whose `η` is `eta`; `None` when the line
    /// runs along the epipolar lines.
    pub fn right_point_at(&self, p: P2, d: P2, eta: f64) -> Option<P2> {
        let rate = geom::dot(self.nr, d) * self.inv_nr;
        (rate.abs() > 1e-9).then(|| geom::add(p, geom::scale(d, (eta - self.eta_right(p)) / rate)))
    }

    /// The point on the line `p + t·d` (left view) whose `η̂` is `eta` (with a correction,
    /// by a few Newton steps on the linear rate: the correction bends `η̂` only slightly).
    pub fn left_point_at(&self, p: P2, d: P2, eta: f64) -> Option<P2> {
        let rate = -geom::dot(self.nl, d) * self.inv_nr;
        if rate.abs() <= 1e-9 {
            return None;
        }
        let mut x = geom::add(p, geom::scale(d, (eta - self.eta_left(p)) / rate));
        if self.correction.is_some() {
            for _ in 0..3 {
                x = geom::add(x, geom::scale(d, (eta - self.eta_left(x)) / rate));
            }
        }
        Some(x)
    }
}

/// Tolerances of candidate matching.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchConfig {
    /// How far a match may sit off its epipolar line (weak calibration), right pixels.
    pub epipolar_tol_px: f64,
    /// Smallest overlap of the epipolar intervals, as a fraction of the shorter one.
    pub min_overlap: f64,
    /// Largest change of a segment's orientation between views, degrees.
    pub max_turn_deg: f64,
    /// Largest ratio of the two segments' contrasts. Kept loose: an occluding edge's contrast
    /// changes between views when the surface behind it differs (a side face seen in one view
    /// only).
    pub max_contrast_ratio: f64,
    /// Segments within this angle of the epipolar lines are matched by band only, degrees.
    pub epipolar_parallel_deg: f64,
    /// Also match segments of opposite contrast polarity. An occluding edge borders a
    /// different surface behind it in each view (a side face seen in one view only, the table
    /// in the other), so its polarity can flip between views.
    pub allow_flipped: bool,
}

impl Default for MatchConfig {
    fn default() -> Self {
        Self { epipolar_tol_px: 3.0, min_overlap: 0.3, max_turn_deg: 45.0, max_contrast_ratio: 8.0, epipolar_parallel_deg: 10.0, allow_flipped: true }
    }
}

/// A candidate match between left segment `left` and right segment `right`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub left: u32,
    pub right: u32,
    /// Overlap of the epipolar intervals, right pixels (for segments along the epipolar
    /// lines: of their extents along them).
    pub overlap_px: f64,
    /// Whether either segment runs within `epipolar_parallel_deg` of the epipolar lines, so
    /// that the epipolar constraint does not fix its correspondence along its length.
    pub along_epipolar: bool,
    /// The two segments have opposite contrast polarity (their directions are opposed: the
    /// left segment's `p0` corresponds to the right segment's `p1`).
    pub flipped: bool,
}

/// All candidates, grouped by left segment (sorted by `(left, right)`).
#[derive(Debug, Clone, Default)]
pub struct Candidates {
    pub list: Vec<Candidate>,
    offsets: Vec<u32>,
}

impl Candidates {
    /// Indices into `list` of the candidates of left segment `l`.
    pub fn of_left(&self, l: u32) -> std::ops::Range<usize> {
        let l = l as usize;
        if l + 1 >= self.offsets.len() {
            return 0..0;
        }
        self.offsets[l] as usize..self.offsets[l + 1] as usize
    }

    /// Index of the candidate `(l, r)`, if there is one.
    pub fn find(&self, l: u32, r: u32) -> Option<usize> {
        let range = self.of_left(l);
        let start = range.start;
        self.list[range].binary_search_by_key(&r, |c| c.right).ok().map(|i| start + i)
    }
}

/// Whether a segment runs within `deg` of the epipolar direction `e`.
fn along(s: &Segment, e: P2, deg: f64) -> bool {
    geom::cross(s.dir(), e).abs() < deg.to_radians().sin()
}

/// Enumerates candidate matches (see the module docs).
pub fn candidates(left: &[Segment], right: &[Segment], geo: &EpipolarGeometry, cfg: &MatchConfig) -> Candidates {
    let ef = geo.frame();
    let tol = cfg.epipolar_tol_px;
    let (el, er) = (ef.left_dir(), ef.right_dir());
    // Right intervals, sorted by start.
    let mut rint: Vec<(f64, f64, u32)> = right
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let (a, b) = (ef.eta_right(s.p0), ef.eta_right(s.p1));
            (a.min(b), a.max(b), i as u32)
        })
        .collect();
    rint.sort_by(|x, y| x.0.total_cmp(&y.0));
    let max_ext = rint.iter().map(|r| r.1 - r.0).fold(0.0, f64::max);
    let starts: Vec<f64> = rint.iter().map(|r| r.0).collect();
    let cos_turn = cfg.max_turn_deg.to_radians().cos();
    let [dmin, dmax] = geo.disparity_px;

    let mut out = Candidates { list: Vec::new(), offsets: Vec::with_capacity(left.len() + 1) };
    out.offsets.push(0);
    for (il, l) in left.iter().enumerate() {
        let (a, b) = (ef.eta_left(l.p0), ef.eta_left(l.p1));
        let (lo_l, hi_l) = (a.min(b), a.max(b));
        let l_along = along(l, el, cfg.epipolar_parallel_deg);
        let from = starts.partition_point(|&s| s < lo_l - tol - max_ext);
        let to = starts.partition_point(|&s| s <= hi_l + tol);
        let first = out.list.len();
        for &(lo_r, hi_r, ir) in &rint[from..to] {
            if hi_r < lo_l - tol {
                continue;
            }
            let r = &right[ir as usize];
            // A bounded turn; directions are polarity-oriented, so opposed directions are a
            // flipped polarity.
            let cos = geom::dot(l.dir(), r.dir());
            let flipped = cos < 0.0;
            if cos.abs() < cos_turn || (flipped && !cfg.allow_flipped) {
                continue;
            }
            let ratio = l.contrast.max(r.contrast) / l.contrast.min(r.contrast).max(1e-9);
            if ratio > cfg.max_contrast_ratio {
                continue;
            }
            let r_along = along(r, er, cfg.epipolar_parallel_deg);
            let is_along = l_along || r_along;
            let overlap = (hi_l.min(hi_r) - lo_l.max(lo_r)).max(0.0);
            let disp = if is_along {
                // Correspondence along the segment is not fixed: any pairing may hold.
                let ul = (l.p0[0].min(l.p1[0]), l.p0[0].max(l.p1[0]));
                let ur = (r.p0[0].min(r.p1[0]), r.p0[0].max(r.p1[0]));
                (ur.0 - ul.1, ur.1 - ul.0)
            } else {
                let ext = (hi_l - lo_l).min(hi_r - lo_r);
                if overlap + 2.0 * tol < cfg.min_overlap * ext || overlap + 2.0 * tol <= 0.0 {
                    continue;
                }
                // Disparity at both ends of the overlap (linear in between).
                let (e0, e1) = (lo_l.max(lo_r) - tol, hi_l.min(hi_r) + tol);
                let mut dl = (f64::INFINITY, f64::NEG_INFINITY);
                for e in [e0.max(lo_l.min(lo_r)), e1.min(hi_l.max(hi_r))] {
                    let (Some(xl), Some(xr)) = (ef.left_point_at(l.p0, l.dir(), e), ef.right_point_at(r.p0, r.dir(), e)) else { continue };
                    let d = xr[0] - xl[0];
                    dl = (dl.0.min(d), dl.1.max(d));
                }
                dl
            };
            if disp.1 < dmin || disp.0 > dmax {
                continue;
            }
            out.list.push(Candidate { left: il as u32, right: ir, overlap_px: overlap, along_epipolar: is_along, flipped });
        }
        out.list[first..].sort_by_key(|c| c.right);
        out.offsets.push(out.list.len() as u32);
    }
    out
}

/// A pair of friendly candidates with the corresponding junction points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Friendship {
    /// Candidate indices, `a < b`.
    pub a: u32,
    pub b: u32,
    /// Junction point in the left and in the right view.
    pub left_point: P2,
    pub right_point: P2,
}

/// Finds the friends among `cands` (see the module docs).
pub fn friends(cands: &Candidates, rel_l: &Relations, rel_r: &Relations, geo: &EpipolarGeometry, cfg: &MatchConfig) -> Vec<Friendship> {
    let ef = geo.frame();
    let mut out = Vec::new();
    for jl in &rel_l.junctions {
        for ca in cands.of_left(jl.a) {
            let ra = cands.list[ca].right;
            for &jri in rel_r.junctions_of(ra) {
                let jr = &rel_r.junctions[jri as usize];
                let (rb, end_rb) = jr.other(ra);
                let Some(cb) = cands.find(jl.b, rb) else { continue };
                // The right ends, seen as the left segments' ends.
                if as_left(jr.end_of(ra), cands.list[ca].flipped) != jl.end_a || as_left(end_rb, cands.list[cb].flipped) != jl.end_b {
                    continue;
                }
                if ef.residual(jl.point, jr.point).abs() > cfg.epipolar_tol_px {
                    continue;
                }
                let d = jr.point[0] - jl.point[0];
                if d < geo.disparity_px[0] || d > geo.disparity_px[1] {
                    continue;
                }
                let (a, b) = if ca < cb { (ca as u32, cb as u32) } else { (cb as u32, ca as u32) };
                out.push(Friendship { a, b, left_point: jl.point, right_point: jr.point });
            }
        }
    }
    out.sort_by_key(|f| (f.a, f.b));
    out.dedup_by_key(|f| (f.a, f.b));
    out
}

/// The end of a left segment that end `e` of its matched right segment corresponds to.
fn as_left(e: End, flipped: bool) -> End {
    match (e, flipped) {
        (End::P0, true) => End::P1,
        (End::P1, true) => End::P0,
        (e, _) => e,
    }
}

/// Whether a junction end is a true end (L/Y) rather than the interior of a T.
pub fn is_end(e: End) -> bool {
    e != End::Interior
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::relations::{find_relations, RelationConfig};
    use nalgebra::Vector4;

    fn seg(p0: P2, p1: P2) -> Segment {
        Segment { p0, p1, contrast: 10.0, rms_px: 0.1, n_points: 20 }
    }

    /// Horizontal epipolar lines: v' = v (n = (0, −1, 0, 1)/√2), disparity in [−40, 0].
    fn rectified() -> EpipolarGeometry {
        EpipolarGeometry { epipolar: EpipolarConstraint::from_normal(Vector4::new(0.0, -1.0, 0.0, 1.0), 0.0), correction: None, disparity_px: [-40.0, 0.0], model: None, projective: None }
    }

    #[test]
    fn candidates_respect_band_disparity_and_polarity() {
        let left = vec![seg([100.0, 50.0], [100.0, 100.0])];
        let right = vec![
            seg([80.0, 52.0], [80.0, 103.0]),   // good: disparity −20, overlapping band
            seg([30.0, 50.0], [30.0, 100.0]),   // disparity −70: outside the limits
            seg([90.0, 100.0], [90.0, 50.0]),   // opposite polarity
            seg([85.0, 140.0], [85.0, 190.0]),  // another band
            seg([95.0, 40.0], [96.0, 60.0]),    // overlaps 10 of 20 px: enough
        ];
        let strict = MatchConfig { allow_flipped: false, ..MatchConfig::default() };
        let c = candidates(&left, &right, &rectified(), &strict);
        let rs: Vec<u32> = c.list.iter().map(|c| c.right).collect();
        assert_eq!(rs, vec![0, 4]);
        assert!(c.find(0, 0).is_some() && c.find(0, 1).is_none());
        assert!(c.list.iter().all(|c| !c.flipped));
        // Allowing flips (occluding edges) admits the opposite polarity, marked as such.
        let c = candidates(&left, &right, &rectified(), &MatchConfig::default());
        let got: Vec<(u32, bool)> = c.list.iter().map(|c| (c.right, c.flipped)).collect();
        assert_eq!(got, vec![(0, false), (2, true), (4, false)]);
    }

    #[test]
    fn epipolar_frame_residual_matches_the_constraint() {
        let e = EpipolarConstraint::from_normal(Vector4::new(0.1, -0.9, 0.05, 0.95), 3.0);
        let f = EpipolarFrame::new(&e);
        let (xl, xr) = ([120.0, 80.0], [100.0, 90.0]);
        let w = [xl[0], xl[1], xr[0], xr[1]];
        let nr = (e.n[2] * e.n[2] + e.n[3] * e.n[3]).sqrt();
        assert!((f.residual(xl, xr) - e.residual_px(&w) / nr).abs() < 1e-12);
        // Moving along the right epipolar direction keeps the residual.
        let moved = geom::add(xr, geom::scale(f.right_dir(), 7.0));
        assert!((f.residual(xl, moved) - f.residual(xl, xr)).abs() < 1e-12);
        // right_point_at lands on the requested η.
        let p = f.right_point_at([0.0, 0.0], [0.6, 0.8], 42.0).unwrap();
        assert!((f.eta_right(p) - 42.0).abs() < 1e-9);
    }

    #[test]
    fn friends_need_corresponding_junctions_on_the_epipolar_line() {
        // An L corner in both views, shifted by −20 px; plus a decoy L in the right view at
        // the wrong height for the second segment.
        let left = vec![seg([100.0, 50.0], [160.0, 50.0]), seg([100.0, 110.0], [100.0, 50.0])];
        let right = vec![seg([80.0, 50.0], [140.0, 50.0]), seg([80.0, 110.0], [80.0, 50.0])];
        let geo = rectified();
        let cfg = MatchConfig::default();
        let c = candidates(&left, &right, &geo, &cfg);
        let rl = find_relations(&left, 320, 240, &RelationConfig::default());
        let rr = find_relations(&right, 320, 240, &RelationConfig::default());
        let f = friends(&c, &rl, &rr, &geo, &cfg);
        assert_eq!(f.len(), 1, "{f:?}");
        assert_eq!((c.list[f[0].a as usize].left, c.list[f[0].b as usize].left), (0, 1));
        assert!(geom::dist(f[0].right_point, [80.0, 50.0]) < 1e-9);
        // Break the right corner's epipolar consistency (move it 10 px down): no friends.
        let right2 = vec![seg([80.0, 60.0], [140.0, 60.0]), seg([80.0, 120.0], [80.0, 60.0])];
        let c2 = candidates(&left, &right2, &geo, &cfg);
        let rr2 = find_relations(&right2, 320, 240, &RelationConfig::default());
        assert!(friends(&c2, &rl, &rr2, &geo, &cfg).is_empty());
    }

    /// A pinhole camera at `centre` looking at `target` (z up), focal `f` px, 640 x 480.
    fn pinhole(centre: Vector3<f64>, target: Vector3<f64>, f: f64) -> nalgebra::Matrix3x4<f64> {
        let fwd = (target - centre).normalize();
        let right = fwd.cross(&Vector3::z()).normalize();
        let down = fwd.cross(&right);
        let r = nalgebra::Matrix3::from_rows(&[right.transpose(), down.transpose(), fwd.transpose()]);
        let k = nalgebra::Matrix3::new(f, 0.0, 320.0, 0.0, f, 240.0, 0.0, 0.0, 1.0);
        let mut rt = nalgebra::Matrix3x4::zeros();
        rt.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
        rt.set_column(3, &(-r * centre));
        k * rt
    }

    #[test]
    fn the_cameras_correction_matches_blocks_near_the_image_edge_that_the_cage_line_misses() {
        // The simulator's rig: cameras 1.7 m off at ±0.24 m, 0.9 m up, 1800 px focal; the
        // cage of reference points 15-25 cm above the table.
        let target = Vector3::new(0.35, 0.0, 0.16);
        let (pl, pr) = (pinhole(Vector3::new(1.695, -0.241, 0.9), target, 1800.0), pinhole(Vector3::new(1.695, 0.241, 0.9), target, 1800.0));
        let see = |p: &nalgebra::Matrix3x4<f64>, x: &Vector3<f64>| {
            let h = p * x.push(1.0);
            [h.x / h.z, h.y / h.z]
        };
        let w = |x: &Vector3<f64>| {
            let (a, b) = (see(&pl, x), see(&pr, x));
            [a[0], a[1], b[0], b[1]]
        };
        let mut cage = Vec::new();
        for (i, j, k) in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)] {
            cage.push(Vector3::new(0.3 + 0.1 * f64::from(i), -0.05 + 0.1 * f64::from(j), 0.15 + 0.1 * f64::from(k)));
        }
        let images: Vec<[f64; 4]> = cage.iter().map(w).collect();
        let mut geo = EpipolarGeometry::from_calibration_points(&cage, &images, 0.5, 10.0).unwrap();
        assert!(geo.projective.is_some());
        // Blocks on the table, as far out as the views reach.
        let mut table = Vec::new();
        for i in 0..=10 {
            for j in 0..=10 {
                for z in [0.0, 0.02, 0.05] {
                    let x = Vector3::new(0.22 + 0.026 * f64::from(i), -0.17 + 0.034 * f64::from(j), z);
                    let q = w(&x);
                    if q.iter().all(|v| (0.0..480.0).contains(v)) && (0.0..640.0).contains(&q[0]) && (0.0..640.0).contains(&q[2]) {
                        table.push(q);
                    }
                }
            }
        }
        assert!(table.len() > 100, "{}", table.len());
        let worst = |g: &EpipolarGeometry| {
            let ef = g.frame();
            table.iter().map(|q| ef.residual([q[0], q[1]], [q[2], q[3]]).abs()).fold(0.0, f64::max)
        };
        let before = worst(&geo);
        assert!(before > 3.0, "the cage's line alone is off by more than the 3 px tolerance: {before}");
        let rms = geo.correct_from_cameras(640, 480, &[0.0, 0.05]).expect("corrected");
        let after = worst(&geo);
        assert!(after < 1.0 && rms < 0.5, "true matches within a pixel of the corrected line: {after} (fit rms {rms})");
    }
}

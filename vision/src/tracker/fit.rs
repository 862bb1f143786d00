//! The least-squares fit of Appendix A, made robust: translation (A.1), then deformation
//! (A.2 or A.3), inside an iteratively reweighted loop that also re-chooses, for every point,
//! which of its candidate edges the current fit explains best.

use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

use super::search::PointEdges;

/// Which least-squares problem estimates the 2x2 deformation `A` (Appendix A).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DeformationModel {
    /// A.2: `h_i − n_i·t = n_i·(A p_i)`: only the normal component of each offset is used,
    /// which is what the edge search measures (the aperture problem). Unbiased; the fit is
    /// regularised so a long thin contour cannot blow up.
    #[default]
    NormalOnly,
    /// A.3: `(h_i − n_i·t) n_i = A p_i`: the thesis's simplification that treats the normal
    /// offset as the whole displacement. More stable under occlusion, but sluggish to deform.
    FullVector,
    /// Translation only (`A = 0`): for contours whose shape is known not to change.
    None,
}

/// The robust weight function of the iteratively reweighted fit.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum RobustLoss {
    /// Plain least squares (the thesis): every point weighs the same.
    LeastSquares,
    /// Huber: quadratic within `k·σ`, linear beyond (k = 1.345).
    Huber,
    /// Tukey's biweight: points beyond `c·σ` (c = 4.685) get no weight at all.
    #[default]
    Tukey,
}

impl RobustLoss {
    #[inline]
    fn weight(self, r: f64, sigma: f64) -> f64 {
        match self {
            RobustLoss::LeastSquares => 1.0,
            RobustLoss::Huber => {
                let k = 1.345 * sigma;
                if r.abs() <= k { 1.0 } else { k / r.abs() }
            }
            RobustLoss::Tukey => {
                let u = r / (4.685 * sigma);
                if u.abs() >= 1.0 {
                    0.0
                } else {
                    let v = 1.0 - u * u;
                    v * v
                }
            }
        }
    }
}

/// Settings of one fit.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FitSettings {
    pub model: DeformationModel,
    pub loss: RobustLoss,
    pub iterations: usize,
    /// Bounds of the robust scale `σ` (px).
    pub sigma_min_px: f64,
    pub sigma_max_px: f64,
    /// Ridge on the deformation, relative to the data's own scale.
    pub deformation_ridge: f64,
}

/// The fit's result: the motion `x ↦ x + t + A (x − centre)`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FitResult {
    pub t: Vector2<f64>,
    pub a: Matrix2<f64>,
    /// Final robust scale (px).
    pub sigma_px: f64,
}

/// Per-point data the fit reads and writes; all vectors are sized at construction.
#[derive(Debug, Clone, Default)]
pub(crate) struct FitBuffers {
    /// Chosen candidate index per point, -1 for none.
    pub chosen: Vec<i8>,
    /// Residual of the chosen candidate after the fit, px (0 for none).
    pub residual: Vec<f64>,
    /// Final robust weight (0 for none).
    pub weight: Vec<f64>,
    /// Scratch for the median.
    scratch: Vec<f64>,
}

impl FitBuffers {
    pub fn with_capacity(n: usize) -> Self {
        Self {
            chosen: Vec::with_capacity(n),
            residual: Vec::with_capacity(n),
            weight: Vec::with_capacity(n),
            scratch: Vec::with_capacity(n),
        }
    }

    /// Sets the length to `n` (no allocation within capacity).
    pub fn resize(&mut self, n: usize) {
        self.chosen.resize(n, -1);
        self.residual.resize(n, 0.0);
        self.weight.resize(n, 0.0);
    }
}

/// Point geometry of one pass: predicted positions relative to the centre, and unit normals.
pub(crate) struct FitPoints<'a> {
    pub px: &'a [f64],
    pub py: &'a [f64],
    pub nx: &'a [f64],
    pub ny: &'a [f64],
    pub edges: &'a [PointEdges],
}

/// The candidate of point `i` closest to the offset the motion `(t, A)` predicts there, and
/// its residual; `None` when the point has no candidate.
#[inline]
fn closest_candidate(points: &FitPoints<'_>, i: usize, t: &Vector2<f64>, a: &Matrix2<f64>) -> Option<(usize, f64)> {
    let cands = points.edges[i].as_slice();
    if cands.is_empty() {
        return None;
    }
    let pred = predicted_offset(points, i, t, a);
    let (mut best, mut best_r) = (0usize, f64::INFINITY);
    for (k, c) in cands.iter().enumerate() {
        let r = c.h_px as f64 - pred;
        if r.abs() < best_r.abs() {
            best = k;
            best_r = r;
        }
    }
    Some((best, best_r))
}

/// Fits translation then deformation to the candidate edges by iteratively reweighted least
/// squares. Each iteration every point takes the candidate closest to the current fit's
/// prediction (so a nearer texture edge cannot hold a point once the others agree elsewhere),
/// the robust scale is re-estimated from the median absolute residual, and the weights follow.
pub(crate) fn fit_motion(points: &FitPoints<'_>, settings: &FitSettings, buf: &mut FitBuffers) -> FitResult {
    let n = points.px.len();
    buf.resize(n);
    let mut t = Vector2::zeros();
    let mut a = Matrix2::zeros();
    // Scale of the template for the ridge: mean |p|².
    let mut p2 = 0.0;
    for i in 0..n {
        p2 += points.px[i] * points.px[i] + points.py[i] * points.py[i];
    }
    let p2 = (p2 / n.max(1) as f64).max(1.0);
    let mut sigma = settings.sigma_max_px;
    let iterations = settings.iterations.max(1);
    for iter in 0..iterations {
        // 1. Association and residuals under the current motion.
        buf.scratch.clear();
        for i in 0..n {
            match closest_candidate(points, i, &t, &a) {
                Some((k, r)) => {
                    buf.chosen[i] = k as i8;
                    buf.residual[i] = r;
                    buf.scratch.push(r.abs());
                }
                None => {
                    buf.chosen[i] = -1;
                    buf.residual[i] = 0.0;
                }
            }
        }
        if buf.scratch.is_empty() {
            buf.weight.iter_mut().for_each(|w| *w = 0.0);
            return FitResult { t, a, sigma_px: sigma };
        }
        // 2. Robust scale: 1.4826·MAD within bounds; the first iteration starts at the top so
        // that points far from the prediction still get a say.
        let mid = buf.scratch.len() / 2;
        let (_, median, _) = buf.scratch.select_nth_unstable_by(mid, |x, y| x.total_cmp(y));
        let mad_sigma = 1.4826 * *median;
        sigma = if iter == 0 { mad_sigma.max(settings.sigma_max_px) } else { mad_sigma };
        sigma = sigma.clamp(settings.sigma_min_px, settings.sigma_max_px.max(settings.sigma_min_px));
        for i in 0..n {
            buf.weight[i] = if buf.chosen[i] < 0 { 0.0 } else { settings.loss.weight(buf.residual[i], sigma) };
        }
        // 3. Translation (A.1) with the deformation's share removed.
        let mut nn = Matrix2::zeros();
        let mut nb = Vector2::zeros();
        let mut wsum = 0.0;
        for i in 0..n {
            let w = buf.weight[i];
            if w == 0.0 {
                continue;
            }
            let (nx, ny) = (points.nx[i], points.ny[i]);
            let h = chosen_h(points, buf, i) - normal_dot_ap(points, i, &a);
            nn[(0, 0)] += w * nx * nx;
            nn[(0, 1)] += w * nx * ny;
            nn[(1, 1)] += w * ny * ny;
            nb.x += w * nx * h;
            nb.y += w * ny * h;
            wsum += w;
        }
        if wsum == 0.0 {
            break;
        }
        nn[(1, 0)] = nn[(0, 1)];
        // A tiny ridge keeps the motion along a lone straight side (unobservable) at zero.
        let ridge_t = 1e-6 * wsum;
        nn[(0, 0)] += ridge_t;
        nn[(1, 1)] += ridge_t;
        let t_new = nn.try_inverse().map(|inv| inv * nb).unwrap_or(t);
        // 4. Deformation given the translation.
        let a_new = match settings.model {
            DeformationModel::None => Matrix2::zeros(),
            DeformationModel::NormalOnly => fit_normal_only(points, buf, &t_new, p2, settings.deformation_ridge, wsum),
            DeformationModel::FullVector => fit_full_vector(points, buf, &t_new, p2, settings.deformation_ridge, wsum),
        };
        let change = (t_new - t).norm() + (a_new - a).norm() * p2.sqrt();
        t = t_new;
        a = a_new;
        if change < 1e-3 && iter > 0 {
            break;
        }
    }
    // Final association and residuals against the final motion (for confidence).
    for i in 0..n {
        if let Some((k, r)) = closest_candidate(points, i, &t, &a) {
            buf.chosen[i] = k as i8;
            buf.residual[i] = r;
            buf.weight[i] = settings.loss.weight(r, sigma);
        }
    }
    FitResult { t, a, sigma_px: sigma }
}

#[inline]
fn chosen_h(points: &FitPoints<'_>, buf: &FitBuffers, i: usize) -> f64 {
    points.edges[i].candidates[buf.chosen[i] as usize].h_px as f64
}

#[inline]
fn normal_dot_ap(points: &FitPoints<'_>, i: usize, a: &Matrix2<f64>) -> f64 {
    let (px, py) = (points.px[i], points.py[i]);
    let apx = a[(0, 0)] * px + a[(0, 1)] * py;
    let apy = a[(1, 0)] * px + a[(1, 1)] * py;
    points.nx[i] * apx + points.ny[i] * apy
}

/// Normal offset the motion `(t, A)` predicts at point `i`.
#[inline]
fn predicted_offset(points: &FitPoints<'_>, i: usize, t: &Vector2<f64>, a: &Matrix2<f64>) -> f64 {
    points.nx[i] * t.x + points.ny[i] * t.y + normal_dot_ap(points, i, a)
}

/// A.2: `r_i = n_i·(A p_i)` with `r_i = h_i − n_i·t`; unknowns `(a11, a12, a21, a22)`.
fn fit_normal_only(points: &FitPoints<'_>, buf: &FitBuffers, t: &Vector2<f64>, p2: f64, ridge: f64, wsum: f64) -> Matrix2<f64> {
    let mut m = Matrix4::zeros();
    let mut b = Vector4::zeros();
    for i in 0..points.px.len() {
        let w = buf.weight[i];
        if w == 0.0 {
            continue;
        }
        let (nx, ny, px, py) = (points.nx[i], points.ny[i], points.px[i], points.py[i]);
        let r = chosen_h(points, buf, i) - (nx * t.x + ny * t.y);
        let j = Vector4::new(nx * px, nx * py, ny * px, ny * py);
        m += j * j.transpose() * w;
        b += j * (w * r);
    }
    // Ridge in units of the data: pulls A towards 0 (no deformation) where the points do not
    // constrain it, e.g. along the long axis of a thin contour.
    let lambda = ridge * wsum * p2;
    for k in 0..4 {
        m[(k, k)] += lambda;
    }
    match m.cholesky() {
        Some(ch) => {
            let x = ch.solve(&b);
            Matrix2::new(x[0], x[1], x[2], x[3])
        }
        None => Matrix2::zeros(),
    }
}

/// A.3: `r_i n_i = A p_i`; each row of `A` is an independent 2-parameter fit.
fn fit_full_vector(points: &FitPoints<'_>, buf: &FitBuffers, t: &Vector2<f64>, p2: f64, ridge: f64, wsum: f64) -> Matrix2<f64> {
    let mut pp = Matrix2::zeros();
    let mut bx = Vector2::zeros();
    let mut by = Vector2::zeros();
    for i in 0..points.px.len() {
        let w = buf.weight[i];
        if w == 0.0 {
            continue;
        }
        let (nx, ny, px, py) = (points.nx[i], points.ny[i], points.px[i], points.py[i]);
        let r = chosen_h(points, buf, i) - (nx * t.x + ny * t.y);
        pp[(0, 0)] += w * px * px;
        pp[(0, 1)] += w * px * py;
        pp[(1, 1)] += w * py * py;
        bx += Vector2::new(px, py) * (w * r * nx);
        by += Vector2::new(px, py) * (w * r * ny);
    }
    pp[(1, 0)] = pp[(0, 1)];
    let lambda = ridge * wsum * p2;
    pp[(0, 0)] += lambda;
    pp[(1, 1)] += lambda;
    match pp.try_inverse() {
        Some(inv) => {
            let r1 = inv * bx;
            let r2 = inv * by;
            Matrix2::new(r1.x, r1.y, r2.x, r2.y)
        }
        None => Matrix2::zeros(),
    }
}

#[cfg(test)]
mod tests {
    use super::super::search::Candidate;
    use super::*;

    /// Points around a 100x60 rectangle centred on the origin, with outward normals.
    fn rectangle() -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let (mut px, mut py, mut nx, mut ny) = (vec![], vec![], vec![], vec![]);
        for k in 0..25 {
            let f = -0.48 + 0.04 * k as f64;
            for (x, y, a, b) in [(f * 100.0, -30.0, 0.0, -1.0), (50.0, f * 60.0, 1.0, 0.0), (-f * 100.0, 30.0, 0.0, 1.0), (-50.0, -f * 60.0, -1.0, 0.0)] {
                px.push(x);
                py.push(y);
                nx.push(a);
                ny.push(b);
            }
        }
        (px, py, nx, ny)
    }

    fn settings(model: DeformationModel, loss: RobustLoss) -> FitSettings {
        FitSettings { model, loss, iterations: 10, sigma_min_px: 0.3, sigma_max_px: 3.0, deformation_ridge: 1e-6 }
    }

    /// One exact candidate per point for the motion `(t, A)`.
    fn exact_edges(pts: &(Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>), t: Vector2<f64>, a: Matrix2<f64>) -> Vec<PointEdges> {
        let (px, py, nx, ny) = pts;
        (0..px.len())
            .map(|i| {
                let d = t + a * Vector2::new(px[i], py[i]);
                let mut e = PointEdges::default();
                e.candidates[0] = Candidate { h_px: (nx[i] * d.x + ny[i] * d.y) as f32, contrast: 50.0 };
                e.count = 1;
                e
            })
            .collect()
    }

    #[test]
    fn recovers_an_exact_motion_with_the_normal_only_model() {
        let r = rectangle();
        let t = Vector2::new(1.5, -2.0);
        let a = Matrix2::new(0.02, -0.03, 0.025, -0.01);
        let edges = exact_edges(&r, t, a);
        let pts = FitPoints { px: &r.0, py: &r.1, nx: &r.2, ny: &r.3, edges: &edges };
        let mut buf = FitBuffers::with_capacity(r.0.len());
        let fit = fit_motion(&pts, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
        assert!((fit.t - t).norm() < 1e-3, "{:?}", fit.t);
        assert!((fit.a - a).norm() < 1e-4, "{:?}", fit.a);
    }

    #[test]
    fn full_vector_model_is_exact_for_translation_and_sluggish_for_rotation() {
        let r = rectangle();
        let s = settings(DeformationModel::FullVector, RobustLoss::LeastSquares);
        let mut buf = FitBuffers::with_capacity(r.0.len());
        let edges = exact_edges(&r, Vector2::new(3.0, 1.0), Matrix2::zeros());
        let fit = fit_motion(&FitPoints { px: &r.0, py: &r.1, nx: &r.2, ny: &r.3, edges: &edges }, &s, &mut buf);
        assert!((fit.t - Vector2::new(3.0, 1.0)).norm() < 1e-4);
        // A small rotation: A.3 recovers only part of it (the aperture problem it ignores).
        let rot = Matrix2::new(0.0, -0.02, 0.02, 0.0);
        let edges = exact_edges(&r, Vector2::zeros(), rot);
        let fit = fit_motion(&FitPoints { px: &r.0, py: &r.1, nx: &r.2, ny: &r.3, edges: &edges }, &s, &mut buf);
        let got = fit.a[(1, 0)] - fit.a[(0, 1)];
        assert!(got > 0.0 && got < 0.04 * 0.9, "rotation part {got}");
    }

    #[test]
    fn robust_fit_ignores_outliers_and_picks_the_consistent_candidate() {
        let (px, py, nx, ny) = rectangle();
        let t = Vector2::new(2.0, 1.0);
        let edges: Vec<PointEdges> = (0..px.len())
            .map(|i| {
                let h = nx[i] * t.x + ny[i] * t.y;
                let mut e = PointEdges::default();
                // One point in five sees only a wild outlier; every third point also sees a
                // stronger clutter edge 3-6 px away, on either side (the patterns cycle
                // through all four sides).
                let clutter = [3.0, -4.5, 6.0, -3.5, 5.0][i % 5];
                if i % 5 == 2 {
                    e.candidates[0] = Candidate { h_px: (h + 7.0 * if i % 10 == 2 { 1.0 } else { -1.0 }) as f32, contrast: 80.0 };
                    e.count = 1;
                } else if i % 3 == 0 {
                    e.candidates[0] = Candidate { h_px: (h + clutter) as f32, contrast: 90.0 };
                    e.candidates[1] = Candidate { h_px: h as f32, contrast: 50.0 };
                    e.count = 2;
                } else {
                    e.candidates[0] = Candidate { h_px: h as f32, contrast: 50.0 };
                    e.count = 1;
                }
                e
            })
            .collect();
        let pts = FitPoints { px: &px, py: &py, nx: &nx, ny: &ny, edges: &edges };
        let mut buf = FitBuffers::with_capacity(px.len());
        let fit = fit_motion(&pts, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
        assert!((fit.t - t).norm() < 0.05 && fit.a.norm() < 1e-3, "{:?} {:?}", fit.t, fit.a);
        let wrong_choice = (0..px.len()).filter(|i| i % 5 != 2 && buf.chosen[*i] != (i % 3 == 0) as i8).count();
        assert_eq!(wrong_choice, 0);
        let outliers_weighted = (0..px.len()).filter(|i| i % 5 == 2 && buf.weight[*i] > 0.0).count();
        assert_eq!(outliers_weighted, 0);
        // Plain least squares is dragged off by the same data.
        let ls = fit_motion(&pts, &settings(DeformationModel::NormalOnly, RobustLoss::LeastSquares), &mut buf);
        assert!((ls.t - t).norm() > 0.1 || ls.a.norm() > 1e-2, "{:?} {:?}", ls.t, ls.a);
    }
}

//! One affine template active contour: predict, search, fit, check, learn.

use nalgebra::{Matrix2, Vector2};

use super::config::{TrackerConfigError, EdgeSign, TrackerConfig};
use super::contour::{Template, TemplateError};
use super::filter::PredictiveFilter;
use super::fit::{fit_motion, DeformationModel, FitBuffers, FitPoints, FitSettings, FitSide};
use super::frame::{TemplateFrame, Placement};
use super::batch::{ContourSearch, SearchSettings};
use super::search::{Appearance, Candidate, PointEdges, SideGeometry, SignRule};
use super::state::{Confidence, LostReason, TrackState};
use crate::image::ImageView;

/// Why a tracker could not be built or re-initialised.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackerError {
    #[error(transparent)]
    Config(#[from] TrackerConfigError),
    #[error(transparent)]
    Template(#[from] TemplateError),
}

/// One point's search in the last pass.
#[derive(Debug, Clone, Copy)]
pub struct SearchLine<'a> {
    /// Where the point was placed, image px.
    pub point: Vector2<f64>,
    /// Outward unit normal searched along.
    pub normal: Vector2<f64>,
    /// Edges found, strongest first (offsets along `normal`).
    pub candidates: &'a [Candidate],
    /// Index of the candidate the fit used.
    pub chosen: Option<usize>,
    /// Distance of the chosen candidate from the fitted contour, px.
    pub residual_px: f64,
    /// The search line left the image.
    pub outside: bool,
}

/// An affine template active contour (Appendix A of the thesis, made robust).
///
/// All buffers are sized at construction; [`update`](Self::update) allocates nothing.
///
/// ```
/// use handeye_vision::image::ImageBuf;
/// use handeye_vision::tracker::{ContourTracker, TrackerConfig};
/// // A dark square on a bright background, and a tracker started 2 px off.
/// let mut img = ImageBuf::filled(160, 120, 200);
/// for y in 40..80 { for x in 60..100 { img.set(x, y, 50); } }
/// let mut tracker = ContourTracker::new(TrackerConfig::default(),
///     &[[62.0, 41.0], [101.5, 41.0], [101.5, 81.0], [62.0, 81.0]]).unwrap();
/// let state = tracker.update(&img.view(), 1.0 / 30.0);
/// assert!(state.is_tracking());
/// // Pixel (x, y) covers x-0.5..x+0.5, so the square's boundary runs at 39.5 and 79.5.
/// let c = tracker.corners().next().unwrap();
/// assert!((c.x - 59.5).abs() < 0.3 && (c.y - 39.5).abs() < 0.3, "{c:?}");
/// ```
#[derive(Debug, Clone)]
pub struct ContourTracker {
    config: TrackerConfig,
    template: Template,
    placement: Placement,
    /// Basis at initialisation, inverted: `[e1 e2] · initial⁻¹` is the deformation so far.
    initial_basis_inv: Matrix2<f64>,
    initial_det: f64,
    filter: PredictiveFilter,
    state: TrackState,
    confidence: Confidence,
    /// Running average of the inlier share over recent good updates.
    recent_inliers: f64,
    updates: u64,
    // Per-side search geometry of the current pass, and the same sides for the fit.
    sides: Vec<SideGeometry>,
    fit_sides: Vec<FitSide>,
    // Per-point data of the current pass (structure of arrays, sized at construction).
    pos_x: Vec<f64>,
    pos_y: Vec<f64>,
    rel_x: Vec<f64>,
    rel_y: Vec<f64>,
    nrm_x: Vec<f64>,
    nrm_y: Vec<f64>,
    edges: Vec<PointEdges>,
    /// Learnt signed outward contrast per point (0 = not learnt yet).
    ref_contrast: Vec<f32>,
    /// Learnt grey level just inside each point's edge (negative = not learnt yet).
    ref_inside: Vec<f32>,
    /// Scratch for [`Self::follow_light`]: each inlier's seen / learnt inside grey level.
    light_ratios: Vec<f32>,
    fit: FitBuffers,
    /// `ref_contrast`, `ref_inside` and `side_of` of a subset pass's points, in its order.
    subset_contrast: Vec<f32>,
    subset_inside: Vec<f32>,
    subset_side: Vec<u16>,
    /// Side index of each point.
    side_of: Vec<u16>,
    /// The search of all the points' normals.
    lines: ContourSearch,
    /// Scratch: the first pass's fitted contour's offset along each point's search line, px.
    fitted_px: Vec<f64>,
    /// Per side, where the template's shape under the similarity nearest the contour's
    /// placement puts it, px from the fitted side at its first and last point (the wrong-lock
    /// check's `template_px`).
    template_pull_px: Vec<[f64; 2]>,
    /// The strongest rival edge the first pass of the last update saw.
    rival: super::wrong_lock::Rival,
    /// Updates whose wide pass saw a rival edge outnumber its side's, less those that did not
    /// (never below 0; see `TrackerConfig::max_rival_updates`).
    rival_updates: usize,
    /// Bit `j` set: side `j` is not searched (its edge is not where this view can see it,
    /// e.g. a crease between two faces of one shade); see [`Self::set_side_measured`].
    unmeasured_sides: u64,
    /// Appearance across each stretch of each side (`TrackerConfig::max_crossed_side_updates`).
    bands: super::side_bands::SideBands,
    /// Scratch: the fitted contour's corners in the image, for [`Self::bands`].
    corner_px: Vec<Vector2<f64>>,
}

/// What one search and fit found.
struct PassResult {
    /// The fitted placement.
    moved: Placement,
    /// How far it moved the farthest corner, px.
    moved_px: f64,
    /// The same edges fitted with the predicted shape held, where that puts more of the points
    /// on an edge (see [`ContourTracker::pass`]).
    held: Option<Placement>,
}

/// Every `stride`-th of a side's `count` points, centred on the side: the first one's index
/// and how many.
fn subset(count: usize, stride: usize) -> (usize, usize) {
    if count == 0 {
        return (0, 0);
    }
    let offset = (count - 1) % stride / 2;
    (offset, (count - 1 - offset) / stride + 1)
}

impl ContourTracker {
    /// A tracker for the polygon `corners_px` (image pixels, in order around it, >= 3).
    pub fn new(config: TrackerConfig, corners_px: &[[f64; 2]]) -> Result<Self, TrackerError> {
        config.validate()?;
        let (template, frame) = Template::from_polygon_px(corners_px, config.points, config.corner_margin)?;
        Ok(Self::with_template(config, template, frame))
    }

    /// A tracker for a template built in its own coordinates (e.g. the gripper's face with its
    /// marks), placed at `frame`.
    pub fn from_template(config: TrackerConfig, template: Template, frame: TemplateFrame) -> Result<Self, TrackerError> {
        config.validate()?;
        if template.points().len() < super::contour::MIN_POINTS {
            return Err(TemplateError::TooFewPoints { min: super::contour::MIN_POINTS, got: template.points().len() }.into());
        }
        if !frame.is_finite() || frame.det() == 0.0 {
            return Err(TemplateError::Degenerate("the initial frame is singular").into());
        }
        Ok(Self::with_template(config, template, frame))
    }

    fn with_template(config: TrackerConfig, template: Template, frame: TemplateFrame) -> Self {
        let n = template.points().len().max(config.points);
        let sides = template.sides();
        let mut tracker = Self {
            filter: PredictiveFilter::new(
                config.velocity_gain,
                config.deformation_velocity_gain,
                config.max_predicted_step_px,
            ),
            config,
            template,
            placement: Placement::affine(frame),
            initial_basis_inv: Matrix2::identity(),
            initial_det: 1.0,
            state: TrackState::Tracking,
            confidence: Confidence::default(),
            recent_inliers: 0.0,
            updates: 0,
            sides: Vec::with_capacity(sides.max(8)),
            fit_sides: Vec::with_capacity(sides.max(8)),
            pos_x: Vec::with_capacity(n),
            pos_y: Vec::with_capacity(n),
            rel_x: Vec::with_capacity(n),
            rel_y: Vec::with_capacity(n),
            nrm_x: Vec::with_capacity(n),
            nrm_y: Vec::with_capacity(n),
            edges: Vec::with_capacity(n),
            ref_contrast: Vec::with_capacity(n),
            ref_inside: Vec::with_capacity(n),
            light_ratios: Vec::with_capacity(n),
            fit: FitBuffers::with_capacity(n),
            side_of: Vec::with_capacity(n),
            subset_contrast: vec![0.0; n],
            subset_inside: vec![-1.0; n],
            subset_side: vec![0; n],
            lines: ContourSearch::new(),
            fitted_px: Vec::with_capacity(n),
            template_pull_px: Vec::with_capacity(sides.max(8)),
            rival: super::wrong_lock::Rival::default(),
            rival_updates: 0,
            unmeasured_sides: 0,
            bands: super::side_bands::SideBands::new(sides),
            corner_px: Vec::with_capacity(sides.max(8)),
        };
        tracker.restart(frame);
        tracker
    }

    /// Resets state, learning and velocity and places the template at `frame`.
    fn restart(&mut self, frame: TemplateFrame) {
        let n = self.template.points().len();
        self.placement = Placement::affine(frame);
        self.initial_basis_inv = frame.basis().try_inverse().unwrap_or_else(Matrix2::identity);
        self.initial_det = frame.det();
        self.filter.reset();
        self.state = TrackState::Tracking;
        self.confidence = Confidence::default();
        self.recent_inliers = 0.0;
        self.updates = 0;
        self.rival = super::wrong_lock::Rival::default();
        self.rival_updates = 0;
        if self.bands.sides() == self.template.sides() {
            self.bands.reset();
        } else {
            self.bands = super::side_bands::SideBands::new(self.template.sides());
        }
        for v in [&mut self.pos_x, &mut self.pos_y, &mut self.rel_x, &mut self.rel_y, &mut self.nrm_x, &mut self.nrm_y] {
            v.clear();
            v.resize(n, 0.0);
        }
        self.edges.clear();
        self.edges.resize(n, PointEdges::default());
        self.ref_contrast.clear();
        self.ref_contrast.resize(n, 0.0);
        self.ref_inside.clear();
        self.ref_inside.resize(n, -1.0);
        self.fit.resize(n);
        self.side_of.clear();
        self.side_of.resize(n, 0);
        for (s, edge) in self.template.edges.iter().enumerate() {
            self.side_of[edge.first..edge.first + edge.count].fill(s as u16);
        }
    }

    /// Re-initialises from a new polygon (image pixels): a new template, fresh state. Does not
    /// allocate when the polygon has no more corners than the first one.
    pub fn reinit(&mut self, corners_px: &[[f64; 2]]) -> Result<(), TemplateError> {
        let frame = self.template.rebuild_from_polygon_px(corners_px, self.config.points, self.config.corner_margin)?;
        self.restart(frame);
        Ok(())
    }

    /// Re-initialises the same template at another frame (e.g. handed over from the planner).
    pub fn reinit_at(&mut self, frame: TemplateFrame) -> Result<(), TemplateError> {
        if !frame.is_finite() || frame.det() == 0.0 {
            return Err(TemplateError::Degenerate("the frame is singular"));
        }
        self.restart(frame);
        Ok(())
    }

    /// One tracking step on `image`, `dt_s` seconds after the previous one (the real time
    /// between the frames; non-finite or negative counts as 0). A lost tracker stays lost and
    /// this returns at once.
    pub fn update(&mut self, image: &ImageView<'_>, dt_s: f64) -> TrackState {
        if !self.state.is_tracking() {
            return self.state;
        }
        let dt_s = if dt_s.is_finite() && dt_s > 0.0 { dt_s } else { 0.0 };
        let predicted = self.filter.predict(&self.placement, dt_s);


        let mut current = predicted;
        // Optionally a short search around the prediction first, kept when it barely moves
        // the contour (see `TrackerConfig::short_first_px`).
        let mut settled = false;
        if self.config.short_first_px > 0.0 && self.updates > 0 {
            let (search_px, iterations) = (self.config.refine_search_px, self.config.refine_iterations);
            if let Some(out) = self.pass(image, &current, search_px, 1, iterations, false)
                && out.moved_px < self.config.short_first_px
            {
                (current, settled) = (out.moved, true);
            }
        }
        let passes = if settled { 0 } else { self.config.passes };
        for pass in 0..passes {
            let (search_px, iterations) = if pass == 0 {
                (self.config.search_px, self.config.iterations)
            } else {
                (self.config.refine_search_px, self.config.refine_iterations)
            };
            // The first of several passes only has to find where the contour went within the
            // wide range: with `coarse_stride` > 1 a subset of the points does that (the last
            // pass always searches them all).
            let stride = if pass == 0 && passes > 1 { self.config.coarse_stride } else { 1 };
            // A wide pass followed by another also tries the predicted shape (see
            // `TrackerConfig::min_shape_support_points`).
            let try_held = pass + 1 < passes && self.config.min_shape_support_points > 0;
            let Some(out) = self.pass(image, &current, search_px, stride, iterations, try_held) else {
                self.state = TrackState::Lost(LostReason::NotFinite);
                self.updates += 1;
                return self.state;
            };
            if pass == 0 && stride == 1 && self.config.max_rival_updates > 0 {
                self.find_rival(out.held.as_ref().unwrap_or(&out.moved));
            }
            if let Some(held) = out.held {
                let Some(chosen) = self.better_refined(image, held, out.moved, pass + 1, passes) else {
                    self.state = TrackState::Lost(LostReason::NotFinite);
                    self.updates += 1;
                    return self.state;
                };
                current = chosen;
                break;
            }
            current = out.moved;
            // A pass that barely moved any corner would be searched again at the same places:
            // skip the remaining passes (not after a subset: the checks need every point).
            if stride == 1 && out.moved_px < self.config.refine_skip_px {
                break;
            }
        }
        // Per-point choices and residuals of the last pass, for the checks and the learning.
        self.fit.finish();
        if self.config.max_crossed_side_updates > 0 {
            self.corner_px.clear();
            self.corner_px.extend(self.template.corners().iter().map(|c| current.image_from_template(*c)));
            self.bands.measure(image, &self.corner_px, self.config.min_contrast as f32);
        }
        let verdict = self.judge(&current);
        self.state = match verdict {
            Some(reason) => TrackState::Lost(reason),
            None => {
                if self.updates > 0 {
                    self.filter.correct(&predicted, &current, dt_s);
                }
                self.placement = current;
                self.learn();
                if self.config.max_crossed_side_updates > 0 {
                    self.bands.learn();
                }
                let f = self.confidence.inlier_fraction;
                self.recent_inliers = if self.updates == 0 { f } else { self.recent_inliers + 0.2 * (f - self.recent_inliers) };
                TrackState::Tracking
            }
        };
        self.updates += 1;
        self.state
    }

    /// One search and fit from `placement` (`None` when the fit is not finite). With
    /// `try_held`, the same edges are also fitted with the shape `placement` predicts held
    /// (translation only): [`PassResult::held`] when that puts at least
    /// `min_shape_support_points` more of the points on an edge than the full fit.
    fn pass(
        &mut self,
        image: &ImageView<'_>,
        placement: &Placement,
        search_px: f64,
        stride: usize,
        iterations: usize,
        try_held: bool,
    ) -> Option<PassResult> {
        let searched = self.search(image, placement, search_px, stride);
        let settings = FitSettings {
            model: self.config.model,
            loss: self.config.loss,
            iterations,
            sigma_min_px: self.config.sigma_min_px,
            sigma_max_px: self.config.sigma_max_px.min(search_px),
            deformation_ridge: self.config.deformation_ridge,
            perspective_ridge: self.config.perspective_ridge,
        };
        let points = FitPoints { px: &self.rel_x[..searched], py: &self.rel_y[..searched], sides: &self.fit_sides };
        let fit = fit_motion(&points, &settings, &mut self.fit);
        let moved = placement.moved(fit.t, fit.a, fit.g, placement.frame.origin)?;
        let mut held = None;
        if try_held {
            let rigid = FitSettings { model: DeformationModel::None, ..settings };
            let points = FitPoints { px: &self.rel_x[..searched], py: &self.rel_y[..searched], sides: &self.fit_sides };
            let fit = fit_motion(&points, &rigid, &mut self.fit);
            if let Some(kept) = placement.moved(fit.t, fit.a, fit.g, placement.frame.origin) {
                let band_px = 0.5 * self.config.inlier_px;
                let deformed_support = self.support(&moved, searched, band_px);
                let kept_support = self.support(&kept, searched, band_px);
                if kept_support >= deformed_support + self.config.min_shape_support_points {
                    held = Some(kept);
                }
            }
        }
        let moved_px = self
            .template
            .corners()
            .iter()
            .map(|c| (moved.image_from_template(*c) - placement.image_from_template(*c)).norm())
            .fold(0.0, f64::max);
        Some(PassResult { moved, moved_px, held })
    }

    /// Passes `from..passes` (the refinement passes) from `start`: where they put the contour.
    fn refine(&mut self, image: &ImageView<'_>, start: Placement, from: usize, passes: usize) -> Option<Placement> {
        let mut current = start;
        for _ in from..passes {
            let (search_px, iterations) = (self.config.refine_search_px, self.config.refine_iterations);
            let out = self.pass(image, &current, search_px, 1, iterations, false)?;
            current = out.moved;
            if out.moved_px < self.config.refine_skip_px {
                break;
            }
        }
        Some(current)
    }

    /// A wide pass whose change of shape explained fewer edges than the predicted shape: the
    /// refinement passes from both, and the held one only where it ends with
    /// `min_shape_support_points` more of the points on an edge (else the full fit's: the
    /// plain tracker's choice). The wide pass's count alone held the shape through the real
    /// sequence's fast turn at its end in 6 of the wide grid's 495 top-face starts (a contour
    /// then wrong keeps its wrong shape, 24-28 px off); compared after the refinement, in 4:
    /// why the setting is off. The buffers are left with the chosen one's last pass.
    fn better_refined(
        &mut self,
        image: &ImageView<'_>,
        held: Placement,
        moved: Placement,
        from: usize,
        passes: usize,
    ) -> Option<Placement> {
        let n = self.template.points().len();
        let band_px = 0.5 * self.config.inlier_px;
        let from_held = self.refine(image, held, from, passes).map(|p| self.support(&p, n, band_px));
        let from_moved = self.refine(image, moved, from, passes)?;
        let moved_support = self.support(&from_moved, n, band_px);
        let margin = self.config.min_shape_support_points;
        match from_held {
            // Again, to leave its search and fit in the buffers for the checks and learning.
            Some(held_support) if held_support >= moved_support + margin => self.refine(image, held, from, passes),
            _ => Some(from_moved),
        }
    }

    /// Where each searched point's search line meets its side under `placement`, into
    /// `fitted_px` (the same axis as its candidates' `h_px`; a side stays straight under the
    /// placement: `p + d n` on the line through `a` along `t`).
    fn fitted_offsets(&mut self, placement: &Placement, searched: usize) {
        self.fitted_px.clear();
        self.fitted_px.resize(searched, f64::INFINITY);
        let cross = |u: Vector2<f64>, v: Vector2<f64>| u.x * v.y - u.y * v.x;
        for (edge, side) in self.template.edges.iter().zip(&self.fit_sides).filter(|(_, s)| s.count > 0) {
            let a = placement.image_from_template(edge.start);
            let t = placement.image_from_template(edge.start + edge.tangent) - a;
            for i in side.first..side.first + side.count {
                let (p, normal) = (Vector2::new(self.pos_x[i], self.pos_y[i]), Vector2::new(self.nrm_x[i], self.nrm_y[i]));
                let along = cross(t, normal);
                // A side turned edge-on to its old normal has no offset: far outside any band.
                self.fitted_px[i] = if along.abs() > 1e-9 * t.norm() { cross(t, a - p) / along } else { f64::INFINITY };
            }
        }
    }

    /// How many of the searched points found an edge within `band_px` of the contour placed
    /// at `placement`.
    fn support(&mut self, placement: &Placement, searched: usize, band_px: f64) -> usize {
        self.fitted_offsets(placement, searched);
        self.edges[..searched]
            .iter()
            .zip(&self.fitted_px)
            .filter(|(e, f)| e.as_slice().iter().any(|c| (f64::from(c.h_px) - **f).abs() <= band_px))
            .count()
    }

    /// After a wide pass: the strongest rival edge of any side (see
    /// [`strongest_rival`](super::wrong_lock::strongest_rival)).
    fn find_rival(&mut self, moved: &Placement) {
        let n = self.template.points().len();
        self.fitted_offsets(moved, n);
        self.template_pull_px.clear();
        if self.config.shape_is_fixed {
            self.template_pull(moved);
        }
        let band_px = 0.5 * self.config.inlier_px;
        self.rival = super::wrong_lock::strongest_rival(
            &self.template.edges,
            &self.edges[..n],
            &self.fitted_px,
            band_px,
            self.config.min_rival_offset_px,
            self.config.rival_margin_points,
            // Turned lines cost ~8 more histograms a side: on a track with no rival in its
            // count, every other update is enough to see one appear (a wrong lock lasts);
            // once counting, every update.
            self.rival_updates > 0 || self.updates.is_multiple_of(2),
            &self.template_pull_px,
        );
        let outnumbered = self.rival.outnumbers_its_side(self.config.rival_margin_points);
        self.rival_updates = if outnumbered { self.rival_updates + 1 } else { self.rival_updates.saturating_sub(1) };
    }

    /// Into `template_pull_px` (after `fitted_offsets` for `moved` over every point): per side,
    /// the offsets from the fitted side, at its first and last point along their search lines,
    /// of the side of the template's own shape placed by the similarity nearest to `moved`'s
    /// change of shape since the start (the same origin; rotation and scale the mean of the
    /// deformation's, no perspective). A contour that keeps its template's shape has them near
    /// 0; one with a side slid off its edge has its shape bent by the slide, and these point
    /// back towards the edge it left.
    fn template_pull(&mut self, moved: &Placement) {
        self.template_pull_px.clear();
        let d = moved.frame.basis() * self.initial_basis_inv;
        let (p, q) = (0.5 * (d[(0, 0)] + d[(1, 1)]), 0.5 * (d[(1, 0)] - d[(0, 1)]));
        let similar = Matrix2::new(p, -q, q, p) * self.initial_basis_inv.try_inverse().unwrap_or_else(Matrix2::identity);
        let shape = Placement::affine(TemplateFrame::new(moved.frame.origin, similar.column(0).into(), similar.column(1).into()));
        let cross = |u: Vector2<f64>, v: Vector2<f64>| u.x * v.y - u.y * v.x;
        for edge in &self.template.edges {
            if edge.count == 0 {
                self.template_pull_px.push([0.0; 2]);
                continue;
            }
            let a = shape.image_from_template(edge.start);
            let t = shape.image_from_template(edge.start + edge.tangent) - a;
            let pull = |i: usize| {
                let (p, normal) = (Vector2::new(self.pos_x[i], self.pos_y[i]), Vector2::new(self.nrm_x[i], self.nrm_y[i]));
                let along = cross(t, normal);
                let at = if along.abs() > 1e-9 * t.norm() { cross(t, a - p) / along } else { f64::INFINITY };
                // Not finite (a side edge-on to its normal): no pull either way.
                let d = at - self.fitted_px[i];
                if d.is_finite() { d } else { 0.0 }
            };
            self.template_pull_px.push([pull(edge.first), pull(edge.first + edge.count - 1)]);
        }
    }

    /// Places the points for `placement` and searches their normals: every point, or with
    /// `stride` > 1 every `stride`-th point of each side (centred on the side). The searched
    /// points are stored in order from index 0 (with `stride` 1, point `i` at `i`); returns
    /// their number.
    fn search(&mut self, image: &ImageView<'_>, placement: &Placement, search_px: f64, stride: usize) -> usize {
        let frame = &placement.frame;
        let orient = self.template.orientation * frame.det().signum();
        let stride = stride.max(1);
        self.sides.clear();
        self.fit_sides.clear();
        let searched: usize = self.template.edges.iter().map(|e| subset(e.count, stride).1).sum();
        if searched != self.fit.len() {
            self.fit.resize(searched);
        }
        let mut dst = 0;
        for (side_index, edge) in self.template.edges.iter().enumerate() {
            // A side stays straight under the placement; its image direction is that of its
            // end points (the tangent pushed through the map's derivative in the affine case).
            let tau = if placement.perspective == Vector2::zeros() {
                frame.e1 * edge.tangent.x + frame.e2 * edge.tangent.y
            } else {
                placement.image_from_template(edge.start + edge.tangent)
                    - placement.image_from_template(edge.start)
            };
            let len = tau.norm();
            // Outward normal: right of the tangent for a positively oriented polygon.
            let normal = if len > 0.0 { [orient * tau.y / len, -orient * tau.x / len] } else { [1.0, 0.0] };
            let side = SideGeometry::new(normal, search_px);
            self.sides.push(side);
            let start = placement.image_from_template(edge.start) - frame.origin;
            let np = normal[0] * start.x + normal[1] * start.y;
            // This side's searched points: template points `edge.first + offset + stride · j`,
            // stored at `dst + j`.
            let (offset, count) = subset(edge.count, stride);
            debug_assert!(stride > 1 || dst == edge.first, "a template's sides hold consecutive points");
            self.fit_sides.push(FitSide { first: dst, count, normal: Vector2::new(normal[0], normal[1]), np });
            let affine = placement.perspective == Vector2::zeros();
            let (t_start, t_step) = (edge.start + edge.step * offset as f64, edge.step * stride as f64);
            let first = frame.image_from_template(t_start);
            let step = frame.e1 * t_step.x + frame.e2 * t_step.y;
            let range = dst..dst + count;
            // The side's points...
            let points = self.pos_x[range.clone()]
                .iter_mut()
                .zip(&mut self.pos_y[range.clone()])
                .zip(self.rel_x[range.clone()].iter_mut().zip(&mut self.rel_y[range.clone()]));
            for (k, ((pos_x, pos_y), (rel_x, rel_y))) in points.enumerate() {
                let p = if affine {
                    first + step * k as f64
                } else {
                    placement.image_from_template(t_start + t_step * k as f64)
                };
                (*pos_x, *pos_y) = (p.x, p.y);
                (*rel_x, *rel_y) = (p.x - frame.origin.x, p.y - frame.origin.y);
            }
            // ...what they have learnt, next to each other for a subset...
            if stride > 1 {
                for j in 0..count {
                    let i = edge.first + offset + stride * j;
                    self.subset_contrast[dst + j] = self.ref_contrast[i];
                    self.subset_inside[dst + j] = self.ref_inside[i];
                    self.subset_side[dst + j] = side_index as u16;
                }
            }
            // ...and the fit's copy.
            self.nrm_x[range.clone()].fill(normal[0]);
            self.nrm_y[range.clone()].fill(normal[1]);
            let geometry = (normal[0] as f32, normal[1] as f32, np as f32);
            self.fit.set_side(dst, &self.rel_x[range.clone()], &self.rel_y[range], geometry);
            dst += count;
        }
        // The searches of all of them (with the appearance cue).
        let (ref_contrast, ref_inside, side_of) = if stride == 1 {
            (&self.ref_contrast[..searched], &self.ref_inside[..searched], &self.side_of[..searched])
        } else {
            (&self.subset_contrast[..searched], &self.subset_inside[..searched], &self.subset_side[..searched])
        };
        let min_contrast = self.config.min_contrast;
        let settings = SearchSettings {
            search_px,
            signs: match self.config.edge_sign {
                EdgeSign::Either => SignRule::Fixed(0),
                EdgeSign::Fixed(p) => SignRule::Fixed(p.outward_sign()),
                EdgeSign::Learned => SignRule::Learned { reference: ref_contrast, min_contrast: min_contrast as f32 },
            },
            appearance: Appearance {
                reference: ref_inside,
                gain: self.config.appearance_px_per_grey as f32,
                tolerance: self.config.appearance_tolerance as f32,
            },
            min_contrast,
        };
        let (xs, ys) = (&self.pos_x[..searched], &self.pos_y[..searched]);
        let fit = self.fit.candidate_slots();
        self.lines.search(image, &self.sides, side_of, xs, ys, &settings, &mut self.edges[..searched], Some(fit));
        // A side this view cannot see measures nothing: whatever edge lies within its search
        // range (the neighbouring face's outer edge) is not its edge.
        if self.unmeasured_sides != 0 {
            for (s, side) in self.fit_sides.iter().enumerate() {
                if !self.side_measured(s) {
                    for i in side.first..side.first + side.count {
                        self.edges[i].count = 0;
                        self.fit.set_candidates(i, &[]);
                    }
                }
            }
        }
        searched
    }

    /// Whether side `side` (corner `side` to `side + 1`) is searched for its edge.
    pub fn side_measured(&self, side: usize) -> bool {
        side >= 64 || self.unmeasured_sides & (1 << side) == 0
    }

    /// Stops (or resumes) searching side `side` for its edge: the contour is then placed by
    /// its other sides, and its confidence counts only the sides it measures. For a side
    /// whose edge the caller knows this view cannot see (two faces of one shade meet there),
    /// where the nearest edge in reach would pull the side off its face. Kept through
    /// [`reinit`](Self::reinit) and [`reinit_at`](Self::reinit_at); sides past the 64th are
    /// always measured.
    pub fn set_side_measured(&mut self, side: usize, measured: bool) {
        if side < 64 {
            if measured {
                self.unmeasured_sides &= !(1 << side);
            } else {
                self.unmeasured_sides |= 1 << side;
            }
        }
    }

    /// Quality and geometry checks of the fitted placement; `Some(reason)` means lost.
    fn judge(&mut self, placement: &Placement) -> Option<LostReason> {
        let frame = &placement.frame;
        let n = self.template.points().len();
        let (mut outside, mut with_edge, mut inliers, mut sq) = (0usize, 0usize, 0usize, 0.0);
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        let (mut axx, mut axy, mut ayy) = (0.0, 0.0, 0.0);
        let mut measured = 0usize;
        for i in 0..n {
            if !self.side_measured(usize::from(self.side_of[i])) {
                continue;
            }
            measured += 1;
            let (nx, ny) = (self.nrm_x[i], self.nrm_y[i]);
            axx += nx * nx;
            axy += nx * ny;
            ayy += ny * ny;
            if self.edges[i].outside {
                outside += 1;
            }
            if self.fit.chosen[i] >= 0 {
                with_edge += 1;
                let r = self.fit.residual[i];
                if r.abs() <= self.config.inlier_px {
                    inliers += 1;
                    sq += r * r;
                    sxx += nx * nx;
                    sxy += nx * ny;
                    syy += ny * ny;
                }
            }
        }
        let nf = measured.max(1) as f64;
        let residual_px = if inliers > 0 { (sq / inliers as f64).sqrt() } else { 0.0 };
        let inlier_fraction = inliers as f64 / nf;
        // How well the inliers pin the contour down in its worst direction, relative to what
        // all its points would: the smallest eigenvalue of Σ n nᵀ over the inliers over that
        // of all points. A contour whose left and right sides found nothing cannot tell where
        // it is along x, however many inliers remain on the others.
        let lambda_min = |xx: f64, xy: f64, yy: f64| 0.5 * (xx + yy - ((xx - yy).powi(2) + 4.0 * xy * xy).sqrt());
        let full = lambda_min(axx, axy, ayy);
        let direction_support = if full > 0.0 { lambda_min(sxx, sxy, syy) / full } else { 0.0 };
        self.confidence = Confidence {
            edge_fraction: with_edge as f64 / nf,
            inlier_fraction,
            residual_px,
            outside_fraction: outside as f64 / nf,
            direction_support,
            score: inlier_fraction * (-(residual_px / self.config.inlier_px).powi(2)).exp(),
        };
        let c = &self.confidence;
        if !frame.is_finite() || !placement.perspective.iter().all(|v| v.is_finite()) {
            return Some(LostReason::NotFinite);
        }
        if c.outside_fraction > self.config.max_outside_fraction {
            return Some(LostReason::LeftImage { outside_fraction: c.outside_fraction });
        }
        if c.edge_fraction < self.config.min_edge_fraction {
            return Some(LostReason::TooFewEdges { edge_fraction: c.edge_fraction });
        }
        if c.inlier_fraction < self.config.min_inlier_fraction {
            return Some(LostReason::TooFewInliers { inlier_fraction: c.inlier_fraction });
        }
        if c.direction_support < self.config.min_direction_support {
            return Some(LostReason::Unconstrained { direction_support: c.direction_support });
        }
        if self.updates >= 3 && c.inlier_fraction < self.config.min_inlier_ratio_to_recent * self.recent_inliers {
            return Some(LostReason::SuddenDrop { inlier_fraction: c.inlier_fraction, recent: self.recent_inliers });
        }
        if c.residual_px > self.config.max_residual_px {
            return Some(LostReason::ResidualTooLarge { rms_px: c.residual_px });
        }
        if self.config.max_rival_updates > 0 && self.rival_updates >= self.config.max_rival_updates {
            let r = self.rival;
            return Some(LostReason::WrongLock {
                side: r.side,
                offset_px: r.offset_px,
                turn_px: r.turn_px,
                support: r.support,
                rival: r.rival,
                updates: self.rival_updates,
            });
        }
        if self.config.max_crossed_side_updates > 0 && self.bands.streak >= self.config.max_crossed_side_updates {
            let w = self.bands.worst;
            return Some(LostReason::CrossedSide {
                side: w.side,
                stretch: w.stretch,
                share: w.share,
                inside: w.inside,
                outside: w.outside,
                updates: self.bands.streak,
            });
        }
        let det = frame.det();
        if det.signum() != self.initial_det.signum() || det == 0.0 {
            return Some(LostReason::FlippedBasis);
        }
        let area_ratio = det / self.initial_det;
        let deformation = TemplateFrame::new(
            Vector2::zeros(),
            (frame.basis() * self.initial_basis_inv).column(0).into(),
            (frame.basis() * self.initial_basis_inv).column(1).into(),
        );
        let squash = deformation.anisotropy();
        if squash > self.config.max_squash
            || area_ratio > self.config.max_area_change
            || area_ratio < 1.0 / self.config.max_area_change
        {
            return Some(LostReason::DegenerateBasis { squash, area_ratio });
        }
        // Perspective must not bend the template through the horizon: across the polygon the
        // scale `1 / (1 + w·q)` stays within a factor of 3 of the origin's.
        let horizon_ok = self.template.corners().iter().all(|c| {
            let d = placement.denominator(*c);
            d > 1.0 / 3.0 && d < 3.0
        });
        if !horizon_ok {
            return Some(LostReason::DegenerateBasis { squash, area_ratio });
        }
        None
    }

    /// A change of light (intensity, ambient) scales the grey level inside every edge of the
    /// contour alike, faster than the per-point appearance learning follows (it learns only
    /// from edges within the tolerance, so a ramp of a few grey levels per frame would lock
    /// the contour out). The median, over the inliers, of seen / learnt inside level is that
    /// common factor: every learnt level is scaled by it (at most ±25 % per update). A
    /// neighbouring face creeping in beside a few edges moves a minority of the ratios and
    /// not the median.
    fn follow_light(&mut self) {
        self.light_ratios.clear();
        let n = self.template.points().len();
        for i in 0..n {
            let k = self.fit.chosen[i];
            let r = self.ref_inside[i];
            if k < 0 || self.fit.residual[i].abs() > self.config.inlier_px || r < 8.0 {
                continue;
            }
            self.light_ratios.push(self.edges[i].candidates[k as usize].inside as f32 / r);
        }
        if self.light_ratios.len() < 4 || 2 * self.light_ratios.len() < n {
            return;
        }
        self.light_ratios.sort_unstable_by(f32::total_cmp);
        let g = self.light_ratios[self.light_ratios.len() / 2].clamp(0.8, 1.25);
        if (g - 1.0).abs() < 0.01 {
            return;
        }
        for r in self.ref_inside.iter_mut().filter(|r| **r >= 0.0) {
            *r = (*r * g).min(255.0);
        }
    }

    /// Each inlier point's reference contrast follows the edge it locked on to; with
    /// [`EdgeSign::Learned`] its sign is the point's polarity from then on.
    fn learn(&mut self) {
        if self.updates > 0 {
            self.follow_light();
        }
        let rate = if self.updates == 0 { 1.0 } else { self.config.contrast_learning_rate as f32 };
        let appearance_rate = self.config.appearance_learning_rate as f32;
        for i in 0..self.template.points().len() {
            let k = self.fit.chosen[i];
            if k < 0 || self.fit.residual[i].abs() > self.config.inlier_px {
                continue;
            }
            let cand = self.edges[i].candidates[k as usize];
            let inside = &mut self.ref_inside[i];
            if *inside < 0.0 {
                *inside = cand.inside as f32;
            } else if cand.penalty_px <= 0.0 {
                // Only an edge that already looks right teaches: an appearance that creeps away
                // (a neighbouring face widening beside the edge) must not drag the reference.
                *inside += appearance_rate * (cand.inside as f32 - *inside);
            }
            let c = cand.contrast;
            let r = &mut self.ref_contrast[i];
            // A point that has learnt a sign keeps it: only same-sign edges update it.
            if *r == 0.0 || r.signum() == c.signum() || self.config.edge_sign != EdgeSign::Learned {
                *r += rate * (c - *r);
            }
        }
    }

    /// The most crossed side stretch of the last update and the updates in a row with one
    /// (`TrackerConfig::max_crossed_side_updates`; share 0 when off or none measurable).
    pub fn crossed_side(&self) -> (super::side_bands::Crossing, usize) {
        (self.bands.worst, self.bands.streak)
    }

    /// Current state.
    pub fn state(&self) -> TrackState {
        self.state
    }

    /// Quality of the last update.
    pub fn confidence(&self) -> Confidence {
        self.confidence
    }

    /// Updates run since (re-)initialisation, including the one that lost the contour.
    pub fn update_count(&self) -> u64 {
        self.updates
    }

    /// Wide passes (less those without; see `TrackerConfig::max_rival_updates`) whose
    /// wrong-lock check saw a side outnumbered by a rival edge
    /// (`tracker::wrong_lock`; lost at `max_rival_updates`), and that rival's side, offset at
    /// the side's middle and turn, px: how close a tracker is to reporting a wrong lock.
    pub fn rival_streak(&self) -> (usize, usize, f64, f64) {
        (self.rival_updates, self.rival.side, self.rival.offset_px, self.rival.turn_px)
    }

    /// The current affine frame (the last good one once lost). With the projective model it
    /// is the contour's local affine frame at the template origin.
    pub fn frame(&self) -> TemplateFrame {
        self.placement.frame
    }

    /// The full placement: affine frame plus perspective term.
    pub fn placement(&self) -> Placement {
        self.placement
    }

    /// The template (corners and points in affine coordinates).
    pub fn template(&self) -> &Template {
        &self.template
    }

    /// Settings in use.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// Current corners in image pixels, in the order given at initialisation.
    pub fn corners(&self) -> impl ExactSizeIterator<Item = Vector2<f64>> + '_ {
        self.template.corners().iter().map(|c| self.placement.image_from_template(*c))
    }

    /// Image position of template coordinates `(s, t)`.
    pub fn image_from_template(&self, st: Vector2<f64>) -> Vector2<f64> {
        self.placement.image_from_template(st)
    }

    /// Template coordinates of an image point (`None` if the frame were singular).
    pub fn template_from_image(&self, x: Vector2<f64>) -> Option<Vector2<f64>> {
        self.placement.template_from_image(x)
    }

    /// Estimated velocity of the origin, px/s.
    pub fn velocity_px_per_s(&self) -> [f64; 2] {
        self.filter.origin_velocity()
    }

    /// The sampling points of the last search pass, image px (for overlays and debugging).
    pub fn sample_points(&self) -> impl ExactSizeIterator<Item = Vector2<f64>> + '_ {
        self.pos_x.iter().zip(&self.pos_y).map(|(x, y)| Vector2::new(*x, *y))
    }

    /// What each point's search found in the last pass (for overlays and diagnosis).
    pub fn search_lines(&self) -> impl ExactSizeIterator<Item = SearchLine<'_>> + '_ {
        (0..self.pos_x.len()).map(move |i| SearchLine {
            point: Vector2::new(self.pos_x[i], self.pos_y[i]),
            normal: Vector2::new(self.nrm_x[i], self.nrm_y[i]),
            candidates: self.edges[i].as_slice(),
            chosen: usize::try_from(self.fit.chosen[i]).ok(),
            residual_px: self.fit.residual[i],
            outside: self.edges[i].outside,
        })
    }

    /// Per point of the last pass: the accepted edge's image position, if it was an inlier.
    pub fn inlier_edges(&self) -> impl Iterator<Item = Vector2<f64>> + '_ {
        (0..self.pos_x.len()).filter_map(move |i| {
            let k = self.fit.chosen[i];
            if k < 0 || self.fit.residual[i].abs() > self.config.inlier_px {
                return None;
            }
            let h = self.edges[i].candidates[k as usize].h_px as f64;
            Some(Vector2::new(self.pos_x[i] + h * self.nrm_x[i], self.pos_y[i] + h * self.nrm_y[i]))
        })
    }
}

#[cfg(test)]
mod light_tests {
    use super::*;
    use crate::image::ImageBuf;
    use crate::tracker::EdgeSign;

    /// A face at grey 190 beside a darker face (120) on a dark table (60), every level scaled
    /// by `gain` (the light).
    fn scene(gain: f64) -> ImageBuf {
        let g = |v: f64| (v * gain).round().clamp(0.0, 255.0) as u8;
        let mut img = ImageBuf::filled(260, 220, g(60.0));
        for y in 81..141 {
            for x in 60..101 {
                img.set(x, y, g(120.0));
            }
            for x in 101..161 {
                img.set(x, y, g(190.0));
            }
        }
        img
    }

    /// The learnt inside grey levels follow a 30 % dimming over a second (the per-point
    /// learning alone lags it by more than the appearance tolerance and then stops learning:
    /// the face's own edges would look wrong from then on).
    #[test]
    fn learnt_inside_levels_follow_a_thirty_percent_dimming() {
        let face = [[100.5, 80.5], [160.5, 80.5], [160.5, 140.5], [100.5, 140.5]];
        let config = TrackerConfig { edge_sign: EdgeSign::Learned, ..TrackerConfig::default() };
        let mut t = ContourTracker::new(config, &face).unwrap();
        let gains = (0..10).map(|_| 1.0).chain((1..=30).map(|k| 1.0 - 0.3 * f64::from(k) / 30.0)).chain((0..5).map(|_| 0.7));
        for gain in gains {
            assert!(t.update(&scene(gain).view(), 1.0 / 30.0).is_tracking());
        }
        let mut learnt: Vec<f32> = t.ref_inside.iter().copied().filter(|&r| r >= 0.0).collect();
        learnt.sort_unstable_by(f32::total_cmp);
        let median = learnt[learnt.len() / 2];
        // The face is at 133 now (190 × 0.7); the tolerance is 10 grey levels.
        assert!((median - 133.0).abs() < 8.0, "learnt inside level {median} for a face at 133");
    }
}

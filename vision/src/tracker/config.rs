//! Tracker settings.

use thiserror::Error;

use super::fit::{DeformationModel, RobustLoss};
use super::search::{Polarity, MAX_SEARCH_PX};

/// How each sampling point decides which edge sign it accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EdgeSign {
    /// Two-sided: any sign.
    #[default]
    Either,
    /// One-sided with one given polarity for the whole contour.
    Fixed(Polarity),
    /// One-sided with a polarity per point, learnt from the edges the point locks on to
    /// during the first updates (two-sided until then). A face boundary often changes sign
    /// along its length (printed texture, shading, background), which a single polarity
    /// cannot express. Beware: where a side stops being a silhouette (a neighbouring face
    /// comes into view, an occluder passes) its true polarity flips, and a learnt one-sided
    /// point then prefers the wrong edge; the default two-sided search with the appearance
    /// cue ([`TrackerConfig::appearance_px_per_grey`]) handles that case better.
    Learned,
}

/// Everything that tunes a [`ContourTracker`](super::ContourTracker). `Default` is the
/// setting that tracks the real `visp-cube` sequence; each field says what it trades.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    /// Sampling points around the contour (the thesis uses about 100).
    pub points: usize,
    /// Fraction of each side kept free of points at both ends: near a corner the normal
    /// search would find the neighbouring side.
    pub corner_margin: f64,
    /// Half-length of the normal search of the first pass, pixels along the normal (<= 40).
    pub search_px: f64,
    /// Search passes per update: after the first pass the contour is moved and searched again
    /// with `refine_search_px`, which recovers the deformation a single step leaves behind.
    /// One pass costs about 65 % of two, but on the real `visp-cube` sequence, from 495
    /// perturbed starts (see `short_first_px`), it lost or misplaced (>= 4 px) the top face in
    /// 244 of them (28 lost) against 11 (none lost) with two passes; reusing the first pass's
    /// edges, re-measured at the moved points, instead of a second search failed on some of
    /// those starts too. Two is the default.
    pub passes: usize,
    /// The first of several passes searches only every `coarse_stride`-th point of each side
    /// (1: all of them, the default): it only has to find where the contour went within the
    /// wide range, and the last pass searches every point over the short range. 2 saves about
    /// a fifth of the time, but on the real `visp-cube` sequence (the 495 runs described at
    /// `short_first_px`) the top face strayed >= 4 px or was lost in 51 runs (27 of them lost
    /// or >= 6 px, a lock on a wrong edge) against 11 (5) with every point.
    pub coarse_stride: usize,
    /// Try the short search first: search `refine_search_px` around the prediction, fit with
    /// `refine_iterations`, and keep that result, skipping the wide pass, when it moves no
    /// corner by this much, px (0: never, the default). When the prediction is good that is a
    /// third of the work; but on the real `visp-cube` sequence, from 55 perturbed starts under
    /// 9 neutral variations of the settings (495 runs), 1 px let the top face stray >= 4 px
    /// (or be lost) in 173 runs against 11 without it; 0.5 px in 17 (13 of them >= 6 px, a
    /// lock on a wrong edge, against 5) at about 0.7x the default's median time; 0.3 px lost
    /// a contour in every pass of the stereo benchmark.
    pub short_first_px: f64,
    /// Half-length of the refinement passes' search, pixels. The first pass has already put
    /// the contour within about a pixel, so a short search sees fewer of the texture's and the
    /// neighbouring faces' edges: on the 495 perturbed starts 2.5 px let the top face stray
    /// or be lost in 11 runs, against 16 with 2 px, 17 with 3 px and 24 with 4 px (and the
    /// left face be lost in 7 against 3, 12 and 18), at the same cost.
    pub refine_search_px: f64,
    /// Skip the remaining passes once a pass moves no corner by this much, px (0: never).
    /// 1 px saves about a quarter of the time but, on the same 55 starts, misplaced the top
    /// face in 24 (once by 35 px, a wrong lock): the default never skips.
    pub refine_skip_px: f64,
    /// Edge polarity rule.
    pub edge_sign: EdgeSign,
    /// Weakest gradient accepted as an edge: central difference `I(k+1) − I(k−1)` in grey
    /// levels (a clean step of 10 grey levels scores 10).
    pub min_contrast: i32,
    /// Deformation estimator (A.2 or A.3).
    pub model: DeformationModel,
    /// Robust weight function of the fit.
    pub loss: RobustLoss,
    /// Reweighting iterations of the first pass.
    pub iterations: usize,
    /// Reweighting iterations of each refinement pass (it starts close to the answer).
    pub refine_iterations: usize,
    /// Bounds of the robust scale, px.
    pub sigma_min_px: f64,
    pub sigma_max_px: f64,
    /// Ridge on the deformation (relative): damps deformation the edges do not constrain.
    pub deformation_ridge: f64,
    /// Ridge on the perspective term of the projective model (relative): perspective changes
    /// slowly on real objects, and unchecked it lets one side swing away on its own.
    pub perspective_ridge: f64,
    /// A point is an inlier when its chosen edge is within this distance of the fit, px.
    pub inlier_px: f64,
    /// Lost when more than this share of the search lines leave the image.
    pub max_outside_fraction: f64,
    /// Lost when fewer than this share of the points find any edge.
    pub min_edge_fraction: f64,
    /// Lost when fewer than this share of the points are inliers.
    pub min_inlier_fraction: f64,
    /// Lost when the inliers pin the contour down this little in some direction (see
    /// [`Confidence::direction_support`](super::Confidence::direction_support); 1 at best).
    pub min_direction_support: f64,
    /// Lost when the inlier share falls below this fraction of its recent average in one
    /// update (the real `visp-cube` faces never drop below 0.9 of it).
    pub min_inlier_ratio_to_recent: f64,
    /// Lost when the inliers' RMS residual exceeds this, px.
    pub max_residual_px: f64,
    /// Wrong-lock check (`tracker::wrong_lock`, after each wide pass): a *rival* is a line
    /// parallel to a side or turned up to 20 px over its length, reaching at least
    /// `min_rival_offset_px` from it at one end, on which at least this many
    /// more of the side's points found an edge (within `inlier_px / 2`) than on the side as
    /// fitted, and more than half of them. With ~25 points a side, 3 is more than the one or
    /// two points a side's count moves by from update to update on a steady track.
    pub rival_margin_points: usize,
    /// Nearest a rival may lie to its side, px: beyond the fit's inlier band on both sides
    /// (2 `inlier_px`) by a pixel. Nearer edges are the same physical edge's other flank (a
    /// cube's edge shows as a thin line or bevel 2-3 px wide: the real left face's front edge
    /// is such a pair, 3 px apart), which the inlier band already covers. The wrong locks on
    /// the real sequence sit 6-11 px from the face's edge.
    pub min_rival_offset_px: f64,
    /// Lost (`wrong_lock`) when the updates with a rival outnumber those without by this many
    /// since the last time they did not (a count that rises by one on an update with a rival
    /// and falls by one, not below 0, on one without; 0: never check). On the face's true
    /// outline the wide pass pulls a side onto the edge most of its points see within a few
    /// updates (a start 3-5 px off snaps in 1-4); a third of a second at 30 frames/s is past
    /// that, and short of what a servo step acts on. Not "in a row": a wrong lock's rival
    /// drops out of the wide pass for 1-3 updates now and then (the left face sheared 13 px off
    /// its far bottom corner on the real sequence: rival on 47 of the first 58 updates, never
    /// 10 in a row), and a reset each time let such locks run the whole sequence. The check needs the
    /// wide pass over every point: with `coarse_stride` > 1, or when `short_first_px` skips
    /// the wide pass, the count does not advance.
    pub max_rival_updates: usize,
    /// Lost (`wrong_lock`, [`LostReason::CrossedSide`](super::LostReason::CrossedSide)) when
    /// on this many updates in a row the band just inside a stretch of a side looks like what
    /// that stretch has learnt lies outside it (`tracker::side_bands`; 0: never check). A
    /// side that turned or slid across the face's outline onto a neighbouring surface keeps
    /// an edge, and none of the edge-based checks see it. Two: on the real sequence's wide
    /// grid (495 starts) the top face's three frame-150 slides have a crossed stretch from
    /// frame 149 and are 6 px off on 150, so 3 is too late; with 1, two starts whose side
    /// crossed for one update on 149 and came back (tracked to the end without it) are lost.
    pub max_crossed_side_updates: usize,
    /// The contour's start shape is the face's shape for the whole track (a still object seen
    /// by still cameras: the daemon's target, placed by the plan): a rival then counts only
    /// where that shape, placed by the similarity nearest the contour's placement, pulls the
    /// side towards it (`tracker::wrong_lock`). A side that slid bent the contour out of the
    /// shape; one beside an edge of a contour that keeps its shape slid off nothing
    /// (clutter3 seed 127: the block's outline 7 px beyond a faint crease the side holds).
    /// Off by default: under a moving camera the face's shape changes with the view (on the
    /// real sequence it would keep 249 of the left face's wrong locks; BENCHMARKS.md).
    pub shape_is_fixed: bool,
    /// Experimental, off (0) by default: the wide pass of several also fits its edges with
    /// the predicted shape held (translation only); where that puts at least this many more of
    /// the points on an edge (within `inlier_px / 2`) than the full fit, the refinement passes
    /// run from both and the held one is kept if it ends with this many more too. Against a
    /// shear no edge opposes (issue 18 item 5: on the real sequence the top face's side 2
    /// turned onto the right face's silhouette 7 px out while side 0 turned onto a texture
    /// line 6 px in and side 3 slid along itself, 2.4 px at a corner in one wide pass that
    /// explained 9 fewer points than the shape it left; the filter then learnt the shear as a
    /// deformation velocity and predicted more, 12 px in three frames). With 3 it removes all
    /// three of the wide grid's frame-150 slides (`tracker_profile`, `TRACKER_GRID=wide`) and
    /// loses no run, but pushes four others into a lock the default only brushes at the
    /// sequence's end (frames 184-217: a bottom corner sliding along the same crease onto the
    /// cube's outline, 24-28 px off at 217; where the face turns fast the shape the edges
    /// support best is not always the right one, and holding it locks the wrong one in):
    /// 4 wrong locks against 3, hence off (BENCHMARKS.md, issue 18 item 5).
    pub min_shape_support_points: usize,
    /// Lost when the contour is squashed (ratio of the singular values of the deformation
    /// since initialisation) beyond this.
    pub max_squash: f64,
    /// Lost when the area changes by more than this factor since initialisation.
    pub max_area_change: f64,
    /// Velocity gain of the predictive filter for the origin (0 = no prediction).
    pub velocity_gain: f64,
    /// Velocity gain for the basis vectors.
    pub deformation_velocity_gain: f64,
    /// Largest predicted step of the origin per update, px.
    pub max_predicted_step_px: f64,
    /// Rate at which a point's reference contrast follows what it sees (0..1).
    pub contrast_learning_rate: f64,
    /// Appearance cue: each point learns the grey level just inside its edge (the tracked
    /// surface, which moves with the contour). A candidate whose inside differs from it by
    /// more than `appearance_tolerance` grey levels costs this many px per extra grey level
    /// when the fit chooses among a point's candidates. It tells a face's own edge from the
    /// silhouette of a neighbouring face appearing beside it. 0 disables.
    pub appearance_px_per_grey: f64,
    /// Grey-level difference the appearance cue tolerates for free.
    pub appearance_tolerance: f64,
    /// Rate at which a point's inside grey level follows what it sees (0..1), from edges
    /// within the tolerance only: slow, so lighting can drift but a neighbouring face creeping
    /// in beside the edge cannot.
    pub appearance_learning_rate: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            points: 100,
            corner_margin: 0.06,
            search_px: 10.0,
            passes: 2,
            coarse_stride: 1,
            short_first_px: 0.0,
            refine_search_px: 2.5,
            refine_skip_px: 0.0,
            edge_sign: EdgeSign::Either,
            min_contrast: 12,
            model: DeformationModel::Projective,
            loss: RobustLoss::Tukey,
            iterations: 4,
            refine_iterations: 2,
            sigma_min_px: 0.4,
            sigma_max_px: 3.0,
            deformation_ridge: 1e-3,
            perspective_ridge: 4.0,
            inlier_px: 2.0,
            max_outside_fraction: 0.5,
            min_edge_fraction: 0.3,
            min_inlier_fraction: 0.3,
            max_residual_px: 1.2,
            rival_margin_points: 3,
            min_rival_offset_px: 5.0,
            max_rival_updates: 10,
            max_crossed_side_updates: 2,
            shape_is_fixed: false,
            min_shape_support_points: 0,
            min_direction_support: 0.35,
            min_inlier_ratio_to_recent: 0.65,
            max_squash: 8.0,
            max_area_change: 25.0,
            velocity_gain: 0.5,
            deformation_velocity_gain: 0.3,
            max_predicted_step_px: 20.0,
            contrast_learning_rate: 0.2,
            appearance_px_per_grey: 0.6,
            appearance_tolerance: 10.0,
            appearance_learning_rate: 0.05,
        }
    }
}

/// A setting outside its valid range.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("tracker setting `{field}` = {value} is invalid: {expected}")]
pub struct TrackerConfigError {
    pub field: &'static str,
    pub value: f64,
    pub expected: &'static str,
}

impl TrackerConfig {
    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), TrackerConfigError> {
        let check = |ok: bool, field: &'static str, value: f64, expected: &'static str| {
            if ok { Ok(()) } else { Err(TrackerConfigError { field, value, expected }) }
        };
        let unit = |v: f64| (0.0..=1.0).contains(&v);
        check(self.points >= super::contour::MIN_POINTS && self.points <= 4096, "points", self.points as f64, "12..=4096")?;
        check((0.0..0.45).contains(&self.corner_margin), "corner_margin", self.corner_margin, "0 <= x < 0.45")?;
        check(self.search_px >= 1.0 && self.search_px <= MAX_SEARCH_PX, "search_px", self.search_px, "1..=40 px")?;
        check((1..=8).contains(&self.passes), "passes", self.passes as f64, "1..=8")?;
        check((1..=8).contains(&self.coarse_stride), "coarse_stride", self.coarse_stride as f64, "1..=8")?;
        check(self.short_first_px >= 0.0 && self.short_first_px.is_finite(), "short_first_px", self.short_first_px, ">= 0 px")?;
        check(
            self.refine_search_px >= 1.0 && self.refine_search_px <= MAX_SEARCH_PX,
            "refine_search_px",
            self.refine_search_px,
            "1..=40 px",
        )?;
        check((1..=255).contains(&self.min_contrast), "min_contrast", self.min_contrast as f64, "1..=255")?;
        check((1..=50).contains(&self.iterations), "iterations", self.iterations as f64, "1..=50")?;
        check((1..=50).contains(&self.refine_iterations), "refine_iterations", self.refine_iterations as f64, "1..=50")?;
        check(self.sigma_min_px > 0.0 && self.sigma_min_px <= self.sigma_max_px, "sigma_min_px", self.sigma_min_px, "0 < x <= sigma_max_px")?;
        check(self.sigma_max_px.is_finite(), "sigma_max_px", self.sigma_max_px, "finite")?;
        check(self.deformation_ridge >= 0.0 && self.deformation_ridge.is_finite(), "deformation_ridge", self.deformation_ridge, ">= 0")?;
        check(self.perspective_ridge >= 0.0 && self.perspective_ridge.is_finite(), "perspective_ridge", self.perspective_ridge, ">= 0")?;
        check(self.inlier_px > 0.0 && self.inlier_px.is_finite(), "inlier_px", self.inlier_px, "> 0 px")?;
        check(unit(self.max_outside_fraction), "max_outside_fraction", self.max_outside_fraction, "0..=1")?;
        check(unit(self.min_edge_fraction), "min_edge_fraction", self.min_edge_fraction, "0..=1")?;
        check(unit(self.min_inlier_fraction), "min_inlier_fraction", self.min_inlier_fraction, "0..=1")?;
        check(self.max_residual_px > 0.0, "max_residual_px", self.max_residual_px, "> 0 px")?;
        check((1..=1000).contains(&self.rival_margin_points), "rival_margin_points", self.rival_margin_points as f64, "1..=1000")?;
        check(
            self.min_rival_offset_px >= 0.0 && self.min_rival_offset_px <= MAX_SEARCH_PX,
            "min_rival_offset_px",
            self.min_rival_offset_px,
            "0..=40 px",
        )?;
        check(self.max_rival_updates <= 100_000, "max_rival_updates", self.max_rival_updates as f64, "0..=100000")?;
        check(
            self.max_crossed_side_updates <= 100_000,
            "max_crossed_side_updates",
            self.max_crossed_side_updates as f64,
            "0..=100000",
        )?;
        check(
            self.min_shape_support_points <= 4096,
            "min_shape_support_points",
            self.min_shape_support_points as f64,
            "0..=4096",
        )?;
        check(unit(self.min_direction_support), "min_direction_support", self.min_direction_support, "0..=1")?;
        check(unit(self.min_inlier_ratio_to_recent), "min_inlier_ratio_to_recent", self.min_inlier_ratio_to_recent, "0..=1")?;
        check(self.max_squash >= 1.0, "max_squash", self.max_squash, ">= 1")?;
        check(self.max_area_change >= 1.0, "max_area_change", self.max_area_change, ">= 1")?;
        check(self.refine_skip_px >= 0.0 && self.refine_skip_px.is_finite(), "refine_skip_px", self.refine_skip_px, ">= 0 px")?;
        check(unit(self.velocity_gain), "velocity_gain", self.velocity_gain, "0..=1")?;
        check(unit(self.deformation_velocity_gain), "deformation_velocity_gain", self.deformation_velocity_gain, "0..=1")?;
        check(self.max_predicted_step_px >= 0.0, "max_predicted_step_px", self.max_predicted_step_px, ">= 0 px")?;
        check(unit(self.contrast_learning_rate), "contrast_learning_rate", self.contrast_learning_rate, "0..=1")?;
        check(
            self.appearance_px_per_grey >= 0.0 && self.appearance_px_per_grey.is_finite(),
            "appearance_px_per_grey",
            self.appearance_px_per_grey,
            ">= 0",
        )?;
        check(unit(self.appearance_learning_rate), "appearance_learning_rate", self.appearance_learning_rate, "0..=1")?;
        check(
            self.appearance_tolerance >= 0.0 && self.appearance_tolerance.is_finite(),
            "appearance_tolerance",
            self.appearance_tolerance,
            ">= 0 grey levels",
        )?;
        Ok(())
    }
}

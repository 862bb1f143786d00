//! The planner (thesis chapter 5, METHOD.md §5): from one stereo pair and a weakly known
//! epipolar constraint to planar facets and reconstructed edges.
//!
//! Stages: [`edges`] → [`segments`] → [`relations`] (junctions, collinears, parallels) →
//! [`matching`] (candidates under the epipolar constraint and disparity limits, friends) →
//! [`planes`] (coplanarity grouping, hypothesis selection) → bootstrap of the epipolar
//! constraint (a linear refit and a smooth correction for cameras that are not quite affine,
//! from junctions matched on accepted planes; then matching again) → [`facets`] →
//! [`reconstruct`].
//!
//! Coordinates: continuous image coordinates in which pixel `(i, j)` covers
//! `[i, i+1) x [j, j+1)`, u right, v down (the simulator's ground-truth convention).
//!
//! Pure: the caller times stages through the callback of [`Planner::plan_with`].
//!
//! ```
//! use handeye_vision::planner::{synth::{BoxSpec, SynthScene}, Planner, PlannerConfig, EpipolarGeometry};
//! use handeye_vision::affine::AffineStereo;
//! use nalgebra::Vector3;
//! let scene = SynthScene::new(vec![BoxSpec { center_m: [0.0, 0.0, 0.025], size_m: [0.06, 0.05, 0.05], yaw_rad: 0.4 }]);
//! let pair = scene.render(3);
//! let robot: Vec<Vector3<f64>> = pair.cage.iter().map(|c| Vector3::from(c.0)).collect();
//! let image: Vec<[f64; 4]> = pair.cage.iter().map(|c| c.1).collect();
//! let geo = EpipolarGeometry::from_model(AffineStereo::fit(&robot, &image).unwrap(), 0.5, 10.0);
//! let mut planner = Planner::new(PlannerConfig::default());
//! let plan = planner.plan(&pair.left.view(), &pair.right.view(), &geo);
//! assert_eq!(plan.facets.len(), 3); // top and two sides
//! ```


// Index loops over parallel arrays (points, links, flags) read more plainly than zips here.
#![allow(clippy::needless_range_loop)]
pub mod edges;
pub mod facets;
pub mod geom;
pub mod matching;
pub mod planes;
pub mod projective;
pub mod reconstruct;
pub mod relations;
pub mod score;
pub mod segments;
pub mod synth;
pub mod transfer;

use nalgebra::{Matrix4, Vector4};

use crate::affine::EpipolarConstraint;
use crate::image::ImageView;
use edges::{EdgeConfig, EdgeDetector};
use facets::{Facet, FacetConfig, FacetInput};
use geom::P2;
use matching::{Candidates, EpipolarFrame, Friendship, MatchConfig};
use planes::{Plane, PlaneConfig, PlaneInput};
use reconstruct::Match;
use relations::{RelationConfig, Relations};
use segments::{Segment, SegmentConfig, SegmentDetector};

pub use matching::{EpipolarCorrection, EpipolarGeometry};

/// All tuning of the planner; the defaults suit 640x480 views of blocks 1-2 m away.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerConfig {
    pub edges: EdgeConfig,
    pub segments: SegmentConfig,
    pub relations: RelationConfig,
    pub matching: MatchConfig,
    pub planes: PlaneConfig,
    pub facets: FacetConfig,
    /// Rounds of re-fitting the epipolar constraint from matched junctions and matching
    /// again (0 disables the bootstrap).
    pub bootstrap_rounds: usize,
    /// The bootstrap's first round collects its junctions from a matching with the epipolar
    /// tolerance widened by this factor (1: from the first matching), so that they cover the
    /// scene even where the given constraint is off by more than the tolerance.
    pub bootstrap_widen: f64,
    /// Segments closer than this to the epipolar lines (in either view) cannot be
    /// reconstructed from the epipolar constraint alone, degrees.
    pub epipolar_min_angle_deg: f64,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        Self {
            edges: EdgeConfig::default(),
            segments: SegmentConfig::default(),
            relations: RelationConfig::default(),
            matching: MatchConfig::default(),
            planes: PlaneConfig::default(),
            facets: FacetConfig::default(),
            bootstrap_rounds: 1,
            bootstrap_widen: 2.0,
            epipolar_min_angle_deg: 10.0,
        }
    }
}

/// The stages reported to [`Planner::plan_with`]'s callback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    Edges,
    Segments,
    Relations,
    Matching,
    Planes,
    Bootstrap,
    Facets,
    Reconstruction,
}

impl Stage {
    pub const ALL: [Stage; 8] = [Stage::Edges, Stage::Segments, Stage::Relations, Stage::Matching, Stage::Planes, Stage::Bootstrap, Stage::Facets, Stage::Reconstruction];

    /// A short snake_case name (JSON keys, bench output).
    pub fn name(&self) -> &'static str {
        match self {
            Stage::Edges => "edges",
            Stage::Segments => "segments",
            Stage::Relations => "relations",
            Stage::Matching => "matching",
            Stage::Planes => "planes",
            Stage::Bootstrap => "bootstrap",
            Stage::Facets => "facets",
            Stage::Reconstruction => "reconstruction",
        }
    }
}

/// A facet with its reconstructed corners.
#[derive(Debug, Clone, PartialEq)]
pub struct FacetResult {
    pub facet: Facet,
    /// `(cyclopean u, cyclopean v, disparity)` of each polygon vertex, pixels.
    pub corners_cyclopean_disparity: Vec<[f64; 3]>,
    /// Robot coordinates of each polygon vertex, metres (when calibrated).
    pub corners_robot_m: Option<Vec<[f64; 3]>>,
}

/// How the epipolar bootstrap went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BootstrapReport {
    /// Junction correspondences used.
    pub points: usize,
    /// RMS residual of those correspondences under the initial and the refitted constraint,
    /// right pixels.
    pub rms_before_px: f64,
    pub rms_after_px: f64,
    /// Whether matching was re-run with the refitted constraint.
    pub rematched: bool,
}

/// Everything the planner found in one stereo pair.
#[derive(Debug, Clone)]
pub struct Plan {
    pub left_segments: Vec<Segment>,
    pub right_segments: Vec<Segment>,
    pub left_relations: Relations,
    pub right_relations: Relations,
    pub candidates: Candidates,
    pub friends: Vec<Friendship>,
    pub planes: Vec<Plane>,
    pub matches: Vec<Match>,
    pub facets: Vec<FacetResult>,
    /// The epipolar constraint finally used (after the bootstrap) ...
    pub epipolar: EpipolarConstraint,
    /// ... and its smooth correction, if the bootstrap fitted one.
    pub epipolar_correction: Option<EpipolarCorrection>,
    pub bootstrap: Option<BootstrapReport>,
}

/// The planner, owning reusable scratch buffers for the image stages.
#[derive(Debug, Clone)]
pub struct Planner {
    pub config: PlannerConfig,
    edges: EdgeDetector,
    segments: SegmentDetector,
}

impl Planner {
    pub fn new(config: PlannerConfig) -> Self {
        Self { config, edges: EdgeDetector::new(config.edges), segments: SegmentDetector::new(config.segments) }
    }

    /// Runs the whole pipeline.
    pub fn plan(&mut self, left: &ImageView, right: &ImageView, geo: &EpipolarGeometry) -> Plan {
        self.plan_with(left, right, geo, &mut |_| {})
    }

    /// Edges and segments of one view.
    pub fn segments_of(&mut self, img: &ImageView, on_stage: &mut dyn FnMut(Stage)) -> Vec<Segment> {
        self.edges.config = self.config.edges;
        self.segments.config = self.config.segments;
        let map = self.edges.detect(img);
        on_stage(Stage::Edges);
        let segs = self.segments.detect(map).to_vec();
        on_stage(Stage::Segments);
        segs
    }

    /// Runs the whole pipeline, calling `on_stage(s)` when stage `s` ends (edges and segments
    /// once per view): the time since the previous call is that stage's.
    pub fn plan_with(&mut self, left: &ImageView, right: &ImageView, geo: &EpipolarGeometry, on_stage: &mut dyn FnMut(Stage)) -> Plan {
        let cfg = self.config;
        let ls = self.segments_of(left, on_stage);
        let rs = self.segments_of(right, on_stage);
        let rl = relations::find_relations(&ls, left.width(), left.height(), &cfg.relations);
        let rr = relations::find_relations(&rs, right.width(), right.height(), &cfg.relations);
        on_stage(Stage::Relations);

        let mut geo_used = geo.clone();
        let (mut cands, mut friends) = match_views(&ls, &rs, &rl, &rr, &geo_used, &cfg);
        on_stage(Stage::Matching);
        let mut planes = group_planes(&ls, &rs, &cands, &friends, &geo_used, left, &cfg);
        on_stage(Stage::Planes);

        let mut bootstrap = None;
        for round in 0..cfg.bootstrap_rounds {
            // The first round takes its junctions from a pass at a widened tolerance, so that
            // they cover the scene even where the constraint is off by more than the
            // tolerance (a linear constraint of perspective cameras is off by different
            // amounts in different parts of the image).
            let pts = if round == 0 && cfg.bootstrap_widen > 1.0 {
                let mut wide = cfg;
                wide.matching.epipolar_tol_px *= cfg.bootstrap_widen;
                let (c, f) = match_views(&ls, &rs, &rl, &rr, &geo_used, &wide);
                let p = group_planes(&ls, &rs, &c, &f, &geo_used, left, &wide);
                confident_junctions(&f, &p)
            } else {
                confident_junctions(&friends, &planes)
            };
            let Some((refined, mut report)) = refine_epipolar(&geo_used, &pts) else { break };
            // Re-match only when the constraint was noticeably off: more than half a pixel, and
            // the refit explains the junctions by a fifth better (the visp-cube pair's eye-
            // annotated constraint, 1.26 px, refits to 0.94 px).
            if report.rms_before_px > 0.5 && report.rms_after_px < report.rms_before_px * 0.8 {
                geo_used = refined;
                let (c, f) = match_views(&ls, &rs, &rl, &rr, &geo_used, &cfg);
                cands = c;
                friends = f;
                planes = group_planes(&ls, &rs, &cands, &friends, &geo_used, left, &cfg);
                report.rematched = true;
            }
            bootstrap = Some(report);
            if !report.rematched {
                break;
            }
        }
        on_stage(Stage::Bootstrap);

        let ef = geo_used.frame();
        let mut matches = reconstruct::select_matches(&cands, &friends, &planes, &ls, &rs);
        let facets = facets::find_facets(
            &FacetInput { left: &ls, right: &rs, cands: &cands, planes: &planes, rel_left: &rl, friends: &friends, epipolar: &ef },
            &cfg.facets,
        );
        on_stage(Stage::Facets);

        reconstruct::reconstruct(&mut matches, &facets, &friends, &ls, &rs, &geo_used, cfg.epipolar_min_angle_deg, cfg.relations.junction_gap_px);
        let facets = facets
            .into_iter()
            .map(|f| {
                let cd = f.left.iter().zip(&f.right).map(|(l, r)| reconstruct::cyclopean_disparity(*l, *r)).collect();
                let robot = f.left.iter().zip(&f.right).map(|(l, r)| geo_used.robot_point(&[l[0], l[1], r[0], r[1]])).collect();
                FacetResult { facet: f, corners_cyclopean_disparity: cd, corners_robot_m: robot }
            })
            .collect();
        on_stage(Stage::Reconstruction);
        Plan {
            left_segments: ls,
            right_segments: rs,
            left_relations: rl,
            right_relations: rr,
            candidates: cands,
            friends,
            planes,
            matches,
            facets,
            epipolar: geo_used.epipolar,
            epipolar_correction: geo_used.correction,
            bootstrap,
        }
    }
}

fn match_views(ls: &[Segment], rs: &[Segment], rl: &Relations, rr: &Relations, geo: &EpipolarGeometry, cfg: &PlannerConfig) -> (Candidates, Vec<Friendship>) {
    let cands = matching::candidates(ls, rs, geo, &cfg.matching);
    let friends = matching::friends(&cands, rl, rr, geo, &cfg.matching);
    (cands, friends)
}

fn group_planes(ls: &[Segment], rs: &[Segment], cands: &Candidates, friends: &[Friendship], geo: &EpipolarGeometry, left: &ImageView, cfg: &PlannerConfig) -> Vec<Plane> {
    let ef = geo.frame();
    planes::find_planes(
        &PlaneInput { left: ls, right: rs, cands, friends, epipolar: &ef, epipolar_tol_px: cfg.matching.epipolar_tol_px, width: left.width(), height: left.height() },
        &cfg.planes,
    )
}

/// Junction correspondences `(u, v, u', v')` of friends that both lie on one accepted plane
/// (confident matches), with the number of planes they come from; duplicates merged.
fn confident_junctions(friends: &[Friendship], planes: &[Plane]) -> (Vec<[f64; 4]>, usize) {
    let mut plane_of = std::collections::HashMap::new();
    for (pi, p) in planes.iter().enumerate() {
        for &m in &p.members {
            plane_of.entry(m).or_insert(pi);
        }
    }
    let mut pts: Vec<[f64; 4]> = Vec::new();
    let mut seen_planes = std::collections::HashSet::new();
    for f in friends {
        if let (Some(pa), Some(pb)) = (plane_of.get(&f.a), plane_of.get(&f.b))
            && pa == pb
        {
            seen_planes.insert(*pa);
            pts.push([f.left_point[0], f.left_point[1], f.right_point[0], f.right_point[1]]);
        }
    }
    pts.sort_by(|a, b| a.iter().zip(b).map(|(x, y)| x.total_cmp(y)).find(|o| o.is_ne()).unwrap_or(std::cmp::Ordering::Equal));
    pts.dedup_by(|a, b| a.iter().zip(b.iter()).all(|(x, y)| (x - y).abs() < 0.5));
    (pts, seen_planes.len())
}

/// Refines the stereo geometry's epipolar constraint from confident junction
/// correspondences: a linear refit by orthogonal regression (outliers beyond 3x the median
/// residual dropped once) when they come from two or more planes and span three dimensions
/// of `(u, v, u', v')` space, then a smooth correction of what the linear constraint leaves
/// (perspective; see [`EpipolarCorrection`]). `None` with fewer than 6 points.
fn refine_epipolar(geo: &EpipolarGeometry, junctions: &(Vec<[f64; 4]>, usize)) -> Option<(EpipolarGeometry, BootstrapReport)> {
    let (pts, planes) = junctions;
    if pts.len() < 6 {
        return None;
    }
    let mut epipolar = geo.epipolar;
    if *planes >= 2 && spans_depth(pts)
        && let Ok(first) = EpipolarConstraint::fit(pts)
    {
        let ef = EpipolarFrame::new(&first);
        let res: Vec<f64> = pts.iter().map(|w| ef.residual([w[0], w[1]], [w[2], w[3]]).abs()).collect();
        let mut sorted = res.clone();
        sorted.sort_by(f64::total_cmp);
        let cut = (3.0 * sorted[sorted.len() / 2]).max(0.3);
        let kept: Vec<[f64; 4]> = pts.iter().zip(&res).filter(|(_, r)| **r <= cut).map(|(p, _)| *p).collect();
        if kept.len() >= 6
            && spans_depth(&kept)
            && let Ok(refit) = EpipolarConstraint::fit(&kept)
        {
            epipolar = refit;
        }
    }
    let linear = EpipolarFrame::new(&epipolar);
    let residuals: Vec<(P2, f64)> = pts.iter().map(|w| ([w[0], w[1]], linear.residual([w[0], w[1]], [w[2], w[3]]))).collect();
    let mut correction = EpipolarCorrection::fit(&residuals).map(|(c, _)| c);
    let with = |correction| EpipolarGeometry { epipolar, correction, ..geo.clone() };
    // Judge on the points the refined geometry explains (within 2 px): the matches that are
    // right under it.
    let explained = |g: &EpipolarGeometry| -> Vec<[f64; 4]> {
        let ef = g.frame();
        pts.iter().filter(|w| ef.residual([w[0], w[1]], [w[2], w[3]]).abs() <= 2.0).copied().collect()
    };
    let rms = |ef: &EpipolarFrame, pts: &[[f64; 4]]| (pts.iter().map(|w| ef.residual([w[0], w[1]], [w[2], w[3]]).powi(2)).sum::<f64>() / pts.len().max(1) as f64).sqrt();
    // The correction must earn its keep: a third less residual than the linear refit alone
    // (with cameras close to affine it would only fit the noise of the junctions).
    if correction.is_some() {
        let inliers = explained(&with(correction));
        if rms(&with(correction).frame(), &inliers) > 0.7 * rms(&linear, &inliers) {
            correction = None;
        }
    }
    let refined = with(correction);
    let inliers = explained(&refined);
    if inliers.len() < 6 {
        return None;
    }
    let (before, after) = (geo.frame(), refined.frame());
    Some((refined, BootstrapReport { points: inliers.len(), rms_before_px: rms(&before, &inliers), rms_after_px: rms(&after, &inliers), rematched: false }))
}

/// Whether correspondences spread over three dimensions of `w`-space by at least a few pixels
/// (the third principal spread is the depth variation the constraint is fitted across).
fn spans_depth(pts: &[[f64; 4]]) -> bool {
    let n = pts.len() as f64;
    let mean = pts.iter().fold(Vector4::zeros(), |a, p| a + Vector4::from(*p)) / n;
    let mut s = Matrix4::zeros();
    for p in pts {
        let d = Vector4::from(*p) - mean;
        s += d * d.transpose();
    }
    let mut ev: Vec<f64> = s.symmetric_eigenvalues().iter().copied().collect();
    ev.sort_by(f64::total_cmp);
    (ev[1] / n).sqrt() >= 1.0
}

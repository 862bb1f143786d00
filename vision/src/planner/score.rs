//! Scoring planner output against ground truth: polygon IoU per view, facets matched to
//! truth faces, spurious facets, and corner errors in robot coordinates.
//!
//! Definitions (used by the simulator acceptance tests):
//! - a truth face is *considered* when its visible area exceeds `min_area_px` in both views;
//! - it is *found* when some facet overlaps it with IoU >= `min_iou` in each view;
//! - a facet is *spurious* when its left-view IoU with every truth face (of any size) is below
//!   `spurious_iou`;
//! - the corner error of a found face is, per truth corner, the distance to the nearest
//!   reconstructed corner of its facet (robot coordinates, metres).

use super::geom::{self, P2};

/// One ground-truth face.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthFace {
    /// Visible polygon per view, pixels.
    pub left: Vec<P2>,
    pub right: Vec<P2>,
    /// Visible area per view, pixels.
    pub visible_left_px: f64,
    pub visible_right_px: f64,
    /// Corners in robot coordinates, metres, if known.
    pub corners_m: Option<Vec<[f64; 3]>>,
}

/// One facet to score.
#[derive(Debug, Clone, PartialEq)]
pub struct FacetPolygons {
    pub left: Vec<P2>,
    pub right: Vec<P2>,
    pub corners_m: Option<Vec<[f64; 3]>>,
}

/// Thresholds of the score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoreConfig {
    pub min_area_px: f64,
    pub min_iou: f64,
    pub spurious_iou: f64,
}

impl Default for ScoreConfig {
    fn default() -> Self {
        Self { min_area_px: 400.0, min_iou: 0.7, spurious_iou: 0.3 }
    }
}

/// The best facet for one considered truth face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceMatch {
    pub face: usize,
    pub facet: Option<usize>,
    pub iou_left: f64,
    pub iou_right: f64,
    pub found: bool,
}

/// The score of one scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneScore {
    pub faces: Vec<FaceMatch>,
    pub considered: usize,
    pub found: usize,
    pub spurious: usize,
    /// Corner errors of found faces, metres.
    pub corner_errors_m: Vec<f64>,
}

/// Scores `facets` against `truth` (see the module docs).
pub fn score_scene(facets: &[FacetPolygons], truth: &[TruthFace], cfg: &ScoreConfig) -> SceneScore {
    let iou = |a: &[P2], b: &[P2]| geom::polygon_iou(a, b, 4);
    let mut faces = Vec::new();
    let mut corner_errors_m = Vec::new();
    for (fi, t) in truth.iter().enumerate() {
        if t.visible_left_px <= cfg.min_area_px || t.visible_right_px <= cfg.min_area_px {
            continue;
        }
        let mut best = FaceMatch { face: fi, facet: None, iou_left: 0.0, iou_right: 0.0, found: false };
        for (k, f) in facets.iter().enumerate() {
            let (il, ir) = (iou(&f.left, &t.left), iou(&f.right, &t.right));
            let key = (il.min(ir), il + ir);
            let best_key = (best.iou_left.min(best.iou_right), best.iou_left + best.iou_right);
            if key > best_key {
                best = FaceMatch { face: fi, facet: Some(k), iou_left: il, iou_right: ir, found: il >= cfg.min_iou && ir >= cfg.min_iou };
            }
        }
        if let (true, Some(k)) = (best.found, best.facet)
            && let (Some(tc), Some(fc)) = (&t.corners_m, &facets[k].corners_m) {
                for c in tc {
                    let d = fc.iter().map(|p| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt()).fold(f64::INFINITY, f64::min);
                    if d.is_finite() {
                        corner_errors_m.push(d);
                    }
                }
            }
        faces.push(best);
    }
    let spurious = facets.iter().filter(|f| truth.iter().all(|t| iou(&f.left, &t.left) < cfg.spurious_iou)).count();
    let found = faces.iter().filter(|f| f.found).count();
    SceneScore { considered: faces.len(), found, spurious, faces, corner_errors_m }
}

/// Median of a list (NaN-free); `None` when empty.
pub fn median(v: &[f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    Some(if n % 2 == 1 { s[n / 2] } else { 0.5 * (s[n / 2 - 1] + s[n / 2]) })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sq(x: f64, y: f64, s: f64) -> Vec<P2> {
        vec![[x, y], [x + s, y], [x + s, y + s], [x, y + s]]
    }

    #[test]
    fn found_missed_spurious_and_corner_errors() {
        let truth = vec![
            TruthFace { left: sq(0.0, 0.0, 30.0), right: sq(-10.0, 0.0, 30.0), visible_left_px: 900.0, visible_right_px: 900.0, corners_m: Some(vec![[0.0, 0.0, 0.0], [0.03, 0.0, 0.0]]) },
            TruthFace { left: sq(100.0, 0.0, 30.0), right: sq(90.0, 0.0, 30.0), visible_left_px: 900.0, visible_right_px: 900.0, corners_m: None },
            // Too small to be considered.
            TruthFace { left: sq(200.0, 0.0, 10.0), right: sq(190.0, 0.0, 10.0), visible_left_px: 100.0, visible_right_px: 100.0, corners_m: None },
        ];
        let facets = vec![
            // Face 0, off by 1 px: IoU ~0.94 in each view; corners 1 mm and 2 mm off.
            FacetPolygons { left: sq(1.0, 0.0, 30.0), right: sq(-9.0, 0.0, 30.0), corners_m: Some(vec![[0.001, 0.0, 0.0], [0.03, 0.002, 0.0]]) },
            // Face 1 found in the left view only: not found.
            FacetPolygons { left: sq(100.0, 0.0, 30.0), right: sq(60.0, 0.0, 30.0), corners_m: None },
            // Nothing there: spurious.
            FacetPolygons { left: sq(300.0, 300.0, 30.0), right: sq(290.0, 300.0, 30.0), corners_m: None },
        ];
        let s = score_scene(&facets, &truth, &ScoreConfig::default());
        assert_eq!((s.considered, s.found, s.spurious), (2, 1, 1));
        assert_eq!(s.faces[0].facet, Some(0));
        assert!(!s.faces[1].found && s.faces[1].iou_left > 0.99);
        let mut e = s.corner_errors_m.clone();
        e.sort_by(f64::total_cmp);
        assert!((e[0] - 0.001).abs() < 1e-12 && (e[1] - 0.002).abs() < 1e-12);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
    }
}

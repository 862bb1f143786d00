//! `handeye hint`: the operator hint (`hint.json`) for the planar facet at one pixel of the
//! left view, from the planner's facets on a stereo pair, so nobody has to type corners.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_vision::planner::geom::{self, P2};
use handeye_vision::planner::{EpipolarGeometry, FacetResult, Plan, Planner, PlannerConfig};
use handeye_wire::hint::{OperatorHint, HINT_VERSION};
use nalgebra::Vector3;

use super::plan::{geometry_from_points, load_calib, load_gray, load_points, SIMULATOR_TO_PLANNER_PX};

const HINT_HELP: &str = "\
Runs the planner (as `handeye plan` does) on one stereo pair, takes the planar facet whose
left-view polygon contains the pixel --at U,V, and writes the operator hint the daemon
reads (`handeye daemon --hint hint.json`): the facet's corners in both views, vertex for
vertex, and the depth of the object behind the facet along its normal (the grasp width).

Pixels: U,V as an image viewer shows them (column, row; pixel centres at integers, the
convention of hint.json).

The stereo model is needed to match the two views (and, with robot coordinates, for the
depth). Give one of:
  --points cage.json   point correspondences: the simulator snapshot's cage.json
                       (`handeye snapshot SCENARIO --out DIR` writes DIR/cage.json), or a
                       list of >= 4 points clicked in both views, each {\"left\": [u, v],
                       \"right\": [u, v], \"robot_m\": [x, y, z]} (robot_m optional; see
                       `handeye plan --help`)
  --calib plan.json    an affine stereo model: the `plan.json` a daemon run writes into its
                       report folder (--out) has one, or {\"m\", \"c\", \"disparity_range_px\"}
Depth: with robot coordinates it is measured from the other reconstructed faces of the same
object (how far they reach behind the facet's plane); without them, or when the planner saw
no other face of that object, give --depth-mm (measure the object).

When no facet contains the pixel, it exits with status 1 and lists the nearest facets and
their centres; `handeye plan ... --overlay plan.png` shows them all.

Examples:
  handeye snapshot scenarios/pick_cube.toml --out snap
  handeye hint --left snap/left.png --right snap/right.png --points snap/cage.json --at 356,390
  handeye hint --left l.png --right r.png --calib report/plan.json --at 412,230 --out target.json
  handeye hint --left l.png --right r.png --points clicks.json --at 412,230 --depth-mm 40";

/// Write hint.json for the planar facet at a left-view pixel, from the planner's facets.
#[derive(Args, Debug)]
#[command(after_long_help = HINT_HELP)]
pub struct HintArgs {
    /// Left view, PNG (converted to 8-bit grey).
    #[arg(long, value_name = "PNG")]
    pub left: PathBuf,
    /// Right view, PNG, same size as the left.
    #[arg(long, value_name = "PNG")]
    pub right: PathBuf,
    /// The facet's pixel in the left view: `U,V` (column, row; pixel centres at integers).
    #[arg(long, value_name = "U,V", value_parser = parse_pixel, allow_hyphen_values = true)]
    pub at: [f64; 2],
    /// Where to write the hint.
    #[arg(long, value_name = "JSON", default_value = "hint.json")]
    pub out: PathBuf,
    /// Point correspondences (as `handeye plan --points`): the snapshot's cage.json, or a
    /// list of {left, right, robot_m?} points.
    #[arg(long, value_name = "JSON", conflicts_with = "calib")]
    pub points: Option<PathBuf>,
    /// Affine stereo model (as `handeye plan --calib`): a daemon report's plan.json, or
    /// {m, c, disparity_range_px}.
    #[arg(long, value_name = "JSON")]
    pub calib: Option<PathBuf>,
    /// Depth of the object behind the facet, mm (overrides the measured one).
    #[arg(long, value_name = "MM")]
    pub depth_mm: Option<f64>,
    /// Tolerance of the weak epipolar constraint, pixels (as `handeye plan`).
    #[arg(long, default_value_t = 3.0, value_name = "PX")]
    pub epipolar_tol_px: f64,
}

fn parse_pixel(s: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [u, v] = parts.as_slice() else { return Err(format!("'{s}': expected U,V (two numbers, pixels)")) };
    let num = |t: &str| t.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| format!("'{t}' in '{s}' is not a finite number"));
    Ok([num(u)?, num(v)?])
}

/// Smallest depth taken as measured: less means no other face reaches behind the facet.
const MIN_MEASURED_DEPTH_MM: f64 = 5.0;
/// Largest number of corners a hint may have ([`OperatorHint`]).
const MAX_CORNERS: usize = 8;
/// Douglas-Peucker tolerance the daemon's plan phase simplifies facet outlines with, px.
const SIMPLIFY_TOL_PX: f64 = 1.5;

pub fn run(args: HintArgs) -> Result<()> {
    if let Some(d) = args.depth_mm
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--depth-mm {d}: a positive number of millimetres expected");
    }
    let geo = stereo_model(&args)?;
    let left = load_gray(&args.left)?;
    let right = load_gray(&args.right)?;
    if (left.width, left.height) != (right.width, right.height) {
        bail!("{} is {}x{} but {} is {}x{}: the views must be the same size", args.left.display(), left.width, left.height, args.right.display(), right.width, right.height);
    }
    let [u, v] = args.at;
    if u < -0.5 || v < -0.5 || u >= left.width as f64 - 0.5 || v >= left.height as f64 - 0.5 {
        bail!("--at {u},{v} is outside the {}x{} left view {}", left.width, left.height, args.left.display());
    }
    let mut config = PlannerConfig::default();
    config.matching.epipolar_tol_px = args.epipolar_tol_px;
    let plan = Planner::new(config).plan(&left.view(), &right.view(), &geo);
    let at_planner = [u + SIMULATOR_TO_PLANNER_PX, v + SIMULATOR_TO_PLANNER_PX];
    let index = facet_at(&plan, at_planner).map_err(|nearest| anyhow::anyhow!(no_facet_message(&args, &nearest, plan.facets.len())))?;
    let facet = &plan.facets[index];
    let depth = match args.depth_mm {
        Some(d) => Depth { mm: d, how: "given with --depth-mm".into() },
        None => measured_depth(&plan, index).with_context(|| {
            format!("facet {index} at {u},{v}: its depth (the grasp width) cannot be measured; give --depth-mm (the object's extent behind the facet, mm)")
        })?,
    };
    let hint = hint_from_facet(facet, depth.mm, format!(
        "handeye hint: planner facet {index} (object {}) at left pixel ({u}, {v}) of {} / {}; depth {:.1} mm {}",
        facet.facet.component,
        args.left.display(),
        args.right.display(),
        depth.mm,
        depth.how
    ))?;
    let text = serde_json::to_string_pretty(&hint)? + "\n";
    // What the daemon will read must pass its own checks.
    OperatorHint::parse(&text, &args.out).context("the hint does not pass the daemon's checks")?;
    std::fs::write(&args.out, text).with_context(|| format!("cannot write {}", args.out.display()))?;
    println!(
        "wrote {}: facet {index}, {} corners, depth {:.1} mm ({})",
        args.out.display(),
        hint.left_px.len(),
        hint.depth_mm,
        depth.how
    );
    Ok(())
}

/// The stereo geometry from --points or --calib, or an error saying what to supply.
fn stereo_model(args: &HintArgs) -> Result<EpipolarGeometry> {
    // The margins `handeye plan` defaults to: objects lie outside the calibration cage.
    let (margin, margin_px) = (0.5, 10.0);
    match (&args.points, &args.calib) {
        (Some(p), _) => Ok(geometry_from_points(&load_points(p)?, margin, margin_px, p)?.0),
        (None, Some(c)) => Ok(EpipolarGeometry::from_model(load_calib(c)?, margin, margin_px)),
        (None, None) => bail!(
            "no stereo model: the planner must know how the two views relate to match them. Give \
             --points FILE (point correspondences: the cage.json that `handeye snapshot SCENARIO --out DIR` \
             writes, or >= 4 points clicked in both views as [{{\"left\": [u, v], \"right\": [u, v], \"robot_m\": [x, y, z]}}, ...]) \
             or --calib FILE (the plan.json in the report folder of a `handeye daemon --out DIR` run that calibrated); \
             see `handeye hint --help`"
        ),
    }
}

/// How far `p` is from a facet's left polygon (0 inside) and the polygon's centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearFacet {
    pub index: usize,
    pub distance_px: f64,
    pub centre: P2,
}

/// The facet whose left polygon contains `p` (planner pixels); of several, the smallest. Else
/// the facets by distance, nearest first.
pub fn facet_at(plan: &Plan, p: P2) -> Result<usize, Vec<NearFacet>> {
    let inside = plan.facets.iter().enumerate().filter(|(_, f)| geom::contains(&f.facet.left, p, 0.0));
    if let Some((i, _)) = inside.min_by(|a, b| geom::area(&a.1.facet.left).total_cmp(&geom::area(&b.1.facet.left))) {
        return Ok(i);
    }
    let mut near: Vec<NearFacet> = plan
        .facets
        .iter()
        .enumerate()
        .map(|(index, f)| {
            let poly = &f.facet.left;
            let n = poly.len();
            let distance_px = (0..n).map(|k| geom::point_segment_distance(p, poly[k], poly[(k + 1) % n])).fold(f64::INFINITY, f64::min);
            let centre = poly.iter().fold([0.0, 0.0], |s, q| [s[0] + q[0] / n as f64, s[1] + q[1] / n as f64]);
            NearFacet { index, distance_px, centre }
        })
        .collect();
    near.sort_by(|a, b| a.distance_px.total_cmp(&b.distance_px));
    Err(near)
}

fn no_facet_message(args: &HintArgs, near: &[NearFacet], total: usize) -> String {
    let [u, v] = args.at;
    if total == 0 {
        return format!(
            "no facet at {u},{v}: the planner found no planar facet on {} / {} (too little contrast at the object's edges, or a stereo model that does not fit these views)",
            args.left.display(),
            args.right.display()
        );
    }
    let s = SIMULATOR_TO_PLANNER_PX;
    let list: Vec<String> = near
        .iter()
        .take(3)
        .map(|f| format!("facet {} ({:.0} px away, centre {:.0},{:.0})", f.index, f.distance_px, f.centre[0] - s, f.centre[1] - s))
        .collect();
    format!(
        "no facet at {u},{v} in {}: the pixel is inside none of the planner's {total} facets (the table or the background is not a facet). Nearest: {}. `handeye plan --left {} --right {} ... --overlay plan.png` draws them",
        args.left.display(),
        list.join("; "),
        args.left.display(),
        args.right.display()
    )
}

/// A depth and how it was found.
struct Depth {
    mm: f64,
    how: String,
}

/// The object's extent behind facet `index` along its normal: the farthest any corner of
/// another facet of the same object lies from the facet's plane (a block's faces all lie on
/// one side of each face). Needs robot coordinates.
fn measured_depth(plan: &Plan, index: usize) -> Result<Depth> {
    let facet = &plan.facets[index];
    let corners = facet.corners_robot_m.as_ref().context("the stereo model has no robot coordinates (give --points with robot_m, or --calib)")?;
    let pts: Vec<Vector3<f64>> = corners.iter().map(|c| Vector3::from(*c)).collect();
    let centre = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    // Newell's normal: robust for any simple polygon.
    let mut normal = Vector3::zeros();
    for k in 0..pts.len() {
        normal += (pts[k] - centre).cross(&(pts[(k + 1) % pts.len()] - centre));
    }
    let normal = normal.try_normalize(1e-12).context("the facet's 3-D corners are degenerate (no plane)")?;
    let others: Vec<&FacetResult> = plan.facets.iter().enumerate().filter(|(i, f)| *i != index && f.facet.component == facet.facet.component).map(|(_, f)| f).collect();
    let depth_m = others
        .iter()
        .filter_map(|f| f.corners_robot_m.as_ref())
        .flatten()
        .map(|q| normal.dot(&(Vector3::from(*q) - centre)).abs())
        .fold(0.0, f64::max);
    let depth_mm = depth_m * 1e3;
    if depth_mm < MIN_MEASURED_DEPTH_MM {
        bail!("the planner reconstructed no other face of its object (object {}) reaching behind it", facet.facet.component);
    }
    Ok(Depth { mm: depth_mm, how: format!("measured from {} other face(s) of the object", others.len()) })
}

/// The hint for one planner facet: its outline simplified as the daemon's plan phase does
/// (at most [`MAX_CORNERS`] corners), converted to hint pixels (centres at integers).
pub fn hint_from_facet(f: &FacetResult, depth_mm: f64, note: String) -> Result<OperatorHint> {
    let (l, r) = (&f.facet.left, &f.facet.right);
    if l.len() != r.len() || l.len() < 3 {
        bail!("the facet's outline has {} left and {} right vertices (3 or more each, equal counts needed)", l.len(), r.len());
    }
    let cyclopean: Vec<P2> = l.iter().zip(r).map(|(a, b)| [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]).collect();
    let mut tol = SIMPLIFY_TOL_PX;
    let mut keep = geom::simplify_closed(&cyclopean, tol);
    while keep.len() > MAX_CORNERS {
        tol *= 1.5;
        keep = geom::simplify_closed(&cyclopean, tol);
    }
    let keep = geom::tracker_order(&cyclopean, &keep);
    let s = SIMULATOR_TO_PLANNER_PX;
    // Thousandths of a pixel are far below what the trackers resolve.
    let r3 = |x: f64| (x * 1e3).round() / 1e3;
    let pick = |poly: &[P2]| -> Vec<[f64; 2]> { keep.iter().map(|&i| [r3(poly[i][0] - s), r3(poly[i][1] - s)]).collect() };
    Ok(OperatorHint { version: HINT_VERSION, left_px: pick(l), right_px: pick(r), depth_mm: r3(depth_mm), note })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_parse_and_bad_ones_are_named() {
        assert_eq!(parse_pixel("356, 390.5").unwrap(), [356.0, 390.5]);
        assert!(parse_pixel("356").unwrap_err().contains("U,V"));
        assert!(parse_pixel("356,x").unwrap_err().contains("'x'"));
        assert!(parse_pixel("1,2,3").is_err());
        assert!(parse_pixel("nan,2").is_err());
    }

    #[test]
    fn many_vertex_outlines_are_simplified_to_at_most_eight_corners() {
        use handeye_vision::planner::facets::Facet;
        // A 24-gon (a circle of radius 40 px): more vertices than a hint may carry.
        let circle: Vec<P2> = (0..24).map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 24.0;
            [100.0 + 40.0 * a.cos(), 100.0 + 40.0 * a.sin()]
        }).collect();
        let right: Vec<P2> = circle.iter().map(|p| [p[0] - 12.0, p[1]]).collect();
        let f = FacetResult {
            facet: Facet { plane: 0, transfer: handeye_vision::planner::transfer::Transfer::IDENTITY, members: vec![], left: circle.clone(), right, component: 0 },
            corners_cyclopean_disparity: vec![],
            corners_robot_m: None,
        };
        let hint = hint_from_facet(&f, 40.0, String::new()).unwrap();
        assert!((3..=MAX_CORNERS).contains(&hint.left_px.len()), "{} corners", hint.left_px.len());
        // Vertex for vertex: each right corner is its left corner moved by the disparity, and
        // every corner is on the circle (shifted to pixel centres at integers).
        for (a, b) in hint.left_px.iter().zip(&hint.right_px) {
            assert!((a[0] - b[0] - 12.0).abs() < 2e-3 && (a[1] - b[1]).abs() < 2e-3);
            assert!(((a[0] + 0.5 - 100.0).hypot(a[1] + 0.5 - 100.0) - 40.0).abs() < 2e-3);
        }
    }
}

//! The working plane of observe mode's pointing (`handeye daemon --observe --plane FILE`):
//! four or more points of the table, each with its plane coordinates and its pixel in the
//! left and the right view. Each view's plane homography is fitted from them (a least-squares
//! DLT for more than four, [`PlaneHomography::fit`]), and the finger's line in each view is
//! carried onto the plane with it (METHOD.md §4): no camera calibration, no robot.
//!
//! The file is TOML:
//!
//! ```toml
//! plane_z_m = 0.06          # optional: the plane's height, reported with the point (default 0)
//! [[points]]
//! plane_m = [0.27, -0.10]   # x, y on the plane, metres (e.g. robot frame)
//! left_px = [383.4, 305.2]  # its pixel in the left view (column, row)
//! right_px = [254.6, 305.1] # and in the right view
//! # ... three or more further [[points]]
//! ```
//!
//! Errors name the file and the field: too few points, a coordinate that is not finite,
//! points in line (in the plane or in a view: the map is then undetermined), pixels that do
//! not belong to their plane points (the fitted map folds the plane, or one point lies far
//! from where the others put it), and, once the first frame's size is known, a pixel outside
//! the image.

use std::path::{Path, PathBuf};

use handeye_vision::pointing::{PlaneHomography, Pointing, PointingError};
use serde::Deserialize;

/// Points fewer than this do not determine a plane homography.
pub const MIN_POINTS: usize = 4;

/// A point farther than this from the line through two others, as a fraction of the
/// points' extent, is not "in line" with them: 1 % (2 mm over a 20 cm square, 3 px over
/// 300 px). Closer than that, four points give a map that the smallest click error tips.
const IN_LINE_FRACTION: f64 = 0.01;

/// With more than four points the fit is over-determined: a point whose pixel lies farther
/// than this from where the others' map puts it is a mistyped or misclicked pixel, px.
pub const MAX_POINT_RESIDUAL_PX: f64 = 4.0;

/// Why a plane file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PlaneFileError {
    #[error("{}: cannot read it: {source}", file.display())]
    Read { file: PathBuf, source: std::io::Error },
    #[error("{}: {message}", file.display())]
    Syntax { file: PathBuf, message: String },
    #[error("{}: {field}: {detail}", file.display())]
    Field { file: PathBuf, field: String, detail: String },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlaneToml {
    #[serde(default)]
    plane_z_m: f64,
    #[serde(default)]
    points: Vec<PointToml>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct PointToml {
    plane_m: [f64; 2],
    left_px: [f64; 2],
    right_px: [f64; 2],
}

/// One point of the working plane and its pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanePoint {
    pub plane_m: [f64; 2],
    /// Left and right view, pixels.
    pub view_px: [[f64; 2]; 2],
}

/// A checked plane file and the two views' homographies fitted from it.
#[derive(Debug, Clone)]
pub struct WorkingPlane {
    /// The file it came from (named in errors found later, e.g. a pixel outside the image).
    pub file: PathBuf,
    pub plane_z_m: f64,
    pub points: Vec<PlanePoint>,
    /// The plane maps of both views.
    pub pointing: Pointing,
}

const VIEW_FIELDS: [&str; 2] = ["left_px", "right_px"];

impl WorkingPlane {
    pub fn load(file: &Path) -> Result<Self, PlaneFileError> {
        let text = std::fs::read_to_string(file).map_err(|source| PlaneFileError::Read { file: file.to_path_buf(), source })?;
        Self::parse(&text, file)
    }

    /// Parses and checks TOML text (see the module docs); `file` names it in errors.
    pub fn parse(text: &str, file: &Path) -> Result<Self, PlaneFileError> {
        let raw: PlaneToml = toml::from_str(text).map_err(|e| PlaneFileError::Syntax { file: file.to_path_buf(), message: e.to_string().trim_end().to_string() })?;
        let field = |field: String, detail: String| PlaneFileError::Field { file: file.to_path_buf(), field, detail };
        if !raw.plane_z_m.is_finite() {
            return Err(field("plane_z_m".into(), format!("{} is not a finite height in metres", raw.plane_z_m)));
        }
        if raw.points.len() < MIN_POINTS {
            return Err(field(
                "points".into(),
                format!("{} point(s) given: the plane's map needs {MIN_POINTS} or more [[points]], each with plane_m, left_px and right_px", raw.points.len()),
            ));
        }
        for (i, p) in raw.points.iter().enumerate() {
            for (name, v) in [("plane_m", p.plane_m), ("left_px", p.left_px), ("right_px", p.right_px)] {
                if !v.iter().all(|x| x.is_finite()) {
                    return Err(field(format!("points[{i}].{name}"), format!("{v:?} is not finite")));
                }
            }
        }
        let points: Vec<PlanePoint> = raw.points.iter().map(|p| PlanePoint { plane_m: p.plane_m, view_px: [p.left_px, p.right_px] }).collect();
        let plane: Vec<[f64; 2]> = points.iter().map(|p| p.plane_m).collect();
        if let Some(why) = in_line(&plane) {
            return Err(field(why.field("plane_m"), why.detail("the plane points", "m")));
        }
        let mut fits = Vec::with_capacity(2);
        for (v, name) in VIEW_FIELDS.iter().enumerate() {
            let px: Vec<[f64; 2]> = points.iter().map(|p| p.view_px[v]).collect();
            if let Some(why) = in_line(&px) {
                return Err(field(why.field(name), why.detail(&format!("their pixels in the {} view", &name[..name.len() - 3]), "px")));
            }
            let h = PlaneHomography::fit(&plane, &px).map_err(|e| match e {
                PointingError::DegeneratePoints => field(format!("points[*].{name}"), "no four of the points are in general position: the map is undetermined".into()),
                other => field(format!("points[*].{name}"), other.to_string()),
            })?;
            check_fit(&h, &plane, &px).map_err(|(i, detail)| field(format!("points[{i}].{name}"), detail))?;
            fits.push(h);
        }
        let right = fits.pop().expect("two fits");
        let left = fits.pop().expect("two fits");
        Ok(Self { file: file.to_path_buf(), plane_z_m: raw.plane_z_m, points, pointing: Pointing::new(left, right) })
    }

    /// Checks every pixel against the camera's image size (known at the first frame):
    /// inside `[-0.5, width - 0.5] x [-0.5, height - 0.5]` (pixel centres at integers).
    pub fn check_image_size(&self, width: usize, height: usize) -> Result<(), PlaneFileError> {
        let (w, h) = (width as f64 - 0.5, height as f64 - 0.5);
        for (i, p) in self.points.iter().enumerate() {
            for (v, name) in VIEW_FIELDS.iter().enumerate() {
                let [u, r] = p.view_px[v];
                if !(-0.5..=w).contains(&u) || !(-0.5..=h).contains(&r) {
                    return Err(PlaneFileError::Field {
                        file: self.file.clone(),
                        field: format!("points[{i}].{name}"),
                        detail: format!("({u}, {r}) is outside the camera's {width}x{height} image: were the pixels taken at another resolution?"),
                    });
                }
            }
        }
        Ok(())
    }

    /// Each view's fit residual (RMS over the points, px; 0 for exactly four points).
    pub fn fit_rms_px(&self) -> [f64; 2] {
        [self.pointing.left.residual_rms_px, self.pointing.right.residual_rms_px]
    }

    /// Where a plane point shows in each view, px (`None` on a view's vanishing line).
    pub fn project(&self, plane_m: &[f64; 2]) -> [Option<[f64; 2]>; 2] {
        [self.pointing.left.project(plane_m), self.pointing.right.project(plane_m)]
    }
}

/// Points found in line: all of them, or three of exactly four.
enum InLine {
    All { n: usize },
    Three { which: [usize; 3], off: f64 },
}

impl InLine {
    fn field(&self, name: &str) -> String {
        match self {
            InLine::All { .. } => format!("points[*].{name}"),
            InLine::Three { which: [a, b, c], .. } => format!("points[{a}], points[{b}], points[{c}] .{name}"),
        }
    }

    fn detail(&self, what: &str, unit: &str) -> String {
        match self {
            InLine::All { n } => format!("all {n} of {what} lie on one line: the plane's map is undetermined (take points that span an area)"),
            InLine::Three { off, .. } => format!(
                "three of {what} lie on one line (the third {off:.3} {unit} from the line through the other two): with four points, no three may be in line"
            ),
        }
    }
}

/// Distance of `p` from the line through `a` and `b` (from `a` when they coincide).
fn off_line(a: &[f64; 2], b: &[f64; 2], p: &[f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    if len == 0.0 {
        return (p[0] - a[0]).hypot(p[1] - a[1]);
    }
    ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx).abs() / len
}

/// Whether the points are in line (see [`IN_LINE_FRACTION`]): all of them (any count), or,
/// for exactly four, any three.
fn in_line(points: &[[f64; 2]]) -> Option<InLine> {
    let extent = points
        .iter()
        .flat_map(|p| points.iter().map(move |q| (p[0] - q[0]).hypot(p[1] - q[1])))
        .fold(0.0, f64::max);
    let tol = IN_LINE_FRACTION * extent;
    // The two points farthest apart span the line all of them would lie on.
    let (mut a, mut b, mut far) = (0, 0, -1.0);
    for i in 0..points.len() {
        for j in i + 1..points.len() {
            let d = (points[i][0] - points[j][0]).hypot(points[i][1] - points[j][1]);
            if d > far {
                (a, b, far) = (i, j, d);
            }
        }
    }
    if extent == 0.0 || points.iter().all(|p| off_line(&points[a], &points[b], p) <= tol) {
        return Some(InLine::All { n: points.len() });
    }
    if points.len() == MIN_POINTS {
        for skip in 0..MIN_POINTS {
            let three: Vec<usize> = (0..MIN_POINTS).filter(|&k| k != skip).collect();
            let [i, j, k] = [three[0], three[1], three[2]];
            // The distance of each from the line through the other two; the largest decides.
            let off = [off_line(&points[j], &points[k], &points[i]), off_line(&points[i], &points[k], &points[j]), off_line(&points[i], &points[j], &points[k])]
                .into_iter()
                .fold(f64::INFINITY, f64::min);
            if off <= tol {
                return Some(InLine::Three { which: [i, j, k], off });
            }
        }
    }
    None
}

/// The fitted map against its points: the same side of the camera for all (a map that
/// sends some behind it folds the plane: pixels swapped between points), and every pixel
/// within [`MAX_POINT_RESIDUAL_PX`] of its plane point's image. `Err((point, detail))`.
fn check_fit(h: &PlaneHomography, plane: &[[f64; 2]], px: &[[f64; 2]]) -> Result<(), (usize, String)> {
    let w: Vec<f64> = plane.iter().map(|p| (h.h * nalgebra::Vector3::new(p[0], p[1], 1.0))[2]).collect();
    if let Some(i) = w.iter().position(|&x| x.signum() != w[0].signum()) {
        return Err((i, "the pixels do not keep the plane points' arrangement (the map would fold the plane): is a pixel given for the wrong point?".into()));
    }
    let mut worst = (0, 0.0);
    for (i, (p, q)) in plane.iter().zip(px).enumerate() {
        let d = h.project(p).map_or(f64::INFINITY, |m| (m[0] - q[0]).hypot(m[1] - q[1]));
        if d > worst.1 {
            worst = (i, d);
        }
    }
    if worst.1 > MAX_POINT_RESIDUAL_PX {
        return Err((worst.0, format!("{:.1} px from where the other points' map puts it (at most {MAX_POINT_RESIDUAL_PX} px): a mistyped or misclicked pixel?", worst.1)));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A projective view of the plane: `(x, y)` m to pixels.
    fn see(h: [[f64; 3]; 3], p: [f64; 2]) -> [f64; 2] {
        let w = h[2][0] * p[0] + h[2][1] * p[1] + h[2][2];
        [(h[0][0] * p[0] + h[0][1] * p[1] + h[0][2]) / w, (h[1][0] * p[0] + h[1][1] * p[1] + h[1][2]) / w]
    }
    const HL: [[f64; 3]; 3] = [[900.0, 150.0, -150.0], [60.0, -800.0, 420.0], [0.2, 0.1, 1.0]];
    const HR: [[f64; 3]; 3] = [[850.0, -200.0, -60.0], [-40.0, -780.0, 400.0], [-0.1, 0.2, 1.0]];

    fn file(points: &[[f64; 2]]) -> String {
        let mut s = String::from("plane_z_m = 0.06\n");
        for p in points {
            let (l, r) = (see(HL, *p), see(HR, *p));
            s.push_str(&format!("[[points]]\nplane_m = [{}, {}]\nleft_px = [{}, {}]\nright_px = [{}, {}]\n", p[0], p[1], l[0], l[1], r[0], r[1]));
        }
        s
    }

    fn err(text: &str) -> String {
        WorkingPlane::parse(text, Path::new("plane.toml")).unwrap_err().to_string()
    }

    const SQUARE: [[f64; 2]; 4] = [[0.3, -0.1], [0.5, -0.1], [0.5, 0.1], [0.3, 0.1]];

    #[test]
    fn four_or_more_points_give_both_views_maps_and_the_point_the_lines_meet_at() {
        let five = [SQUARE[0], SQUARE[1], SQUARE[2], SQUARE[3], [0.42, 0.03]];
        for points in [&SQUARE[..], &five[..]] {
            let plane = WorkingPlane::parse(&file(points), Path::new("plane.toml")).unwrap();
            assert_eq!((plane.points.len(), plane.plane_z_m), (points.len(), 0.06));
            assert!(plane.fit_rms_px().iter().all(|&r| r < 1e-6), "{:?}", plane.fit_rms_px());
            let [l, r] = plane.project(&[0.41, 0.02]).map(Option::unwrap);
            let (tl, tr) = (see(HL, [0.41, 0.02]), see(HR, [0.41, 0.02]));
            assert!((l[0] - tl[0]).hypot(l[1] - tl[1]) < 1e-6 && (r[0] - tr[0]).hypot(r[1] - tr[1]) < 1e-6);
        }
        // Five points with a pixel 1 px off: least squares, a residual, still accepted.
        let mut text = file(&five);
        let l4 = see(HL, five[4]);
        text = text.replace(&format!("left_px = [{}, {}]", l4[0], l4[1]), &format!("left_px = [{}, {}]", l4[0] + 1.0, l4[1]));
        let plane = WorkingPlane::parse(&text, Path::new("plane.toml")).unwrap();
        assert!(plane.fit_rms_px()[0] > 0.05 && plane.fit_rms_px()[1] < 1e-6, "{:?}", plane.fit_rms_px());
    }

    #[test]
    fn bad_files_are_refused_naming_the_file_and_the_field() {
        let e = err(&file(&SQUARE[..3]));
        assert!(e.starts_with("plane.toml: points: 3 point(s) given") && e.contains("4 or more"), "{e}");
        let e = err(&file(&SQUARE).replacen("plane_m = [0.5, -0.1]", "plane_m = [nan, -0.1]", 1));
        assert!(e.starts_with("plane.toml: points[1].plane_m:") && e.contains("not finite"), "{e}");
        let e = err(&file(&[[0.3, 0.0], [0.4, 0.0], [0.5, 0.0], [0.6, 0.0001]]));
        assert!(e.contains("points[*].plane_m") && e.contains("all 4 of the plane points lie on one line"), "{e}");
        let e = err(&file(&[[0.3, -0.1], [0.4, -0.1], [0.5, -0.1], [0.4, 0.1]]));
        assert!(e.contains("points[0], points[1], points[2] .plane_m") && e.contains("three of the plane points"), "{e}");
        let e = err(&file(&SQUARE).replace("left_px", "left_pix"));
        assert!(e.starts_with("plane.toml: ") && e.contains("left_pix"), "{e}");
        let e = err("plane_z_m = 0.0\n[[points]]\nplane_m = [0.3, 0.1]\n");
        assert!(e.contains("right_px") || e.contains("left_px"), "{e}");
        // Two neighbouring corners' pixels swapped in the right view: the map folds the
        // plane (a bow tie; swapping opposite corners would only mirror it).
        let (r0, r2) = (see(HR, SQUARE[0]), see(HR, SQUARE[1]));
        let swapped = file(&SQUARE)
            .replace(&format!("right_px = [{}, {}]", r0[0], r0[1]), "right_px = [X]")
            .replace(&format!("right_px = [{}, {}]", r2[0], r2[1]), &format!("right_px = [{}, {}]", r0[0], r0[1]))
            .replace("right_px = [X]", &format!("right_px = [{}, {}]", r2[0], r2[1]));
        let e = err(&swapped);
        assert!(e.contains(".right_px") && (e.contains("fold") || e.contains("in line")), "{e}");
        // A fifth point 20 px off in the left view: named.
        let five = [SQUARE[0], SQUARE[1], SQUARE[2], SQUARE[3], [0.42, 0.03]];
        let l4 = see(HL, five[4]);
        let e = err(&file(&five).replace(&format!("left_px = [{}, {}]", l4[0], l4[1]), &format!("left_px = [{}, {}]", l4[0] + 20.0, l4[1])));
        assert!(e.contains("points[4].left_px") && e.contains("misclicked"), "{e}");
        assert!(err("[[points]]\nplane_m = 3").starts_with("plane.toml: "));
    }

    #[test]
    fn a_pixel_outside_the_first_frame_is_named() {
        let plane = WorkingPlane::parse(&file(&SQUARE), Path::new("plane.toml")).unwrap();
        let px = plane.points.iter().flat_map(|p| p.view_px).fold([0.0f64; 2], |m, p| [m[0].max(p[0]), m[1].max(p[1])]);
        let (w, h) = (px[0].ceil() as usize + 1, px[1].ceil() as usize + 1);
        plane.check_image_size(w, h).unwrap();
        let e = plane.check_image_size(w / 2, h).unwrap_err().to_string();
        assert!(e.starts_with("plane.toml: points[") && e.contains("outside the camera's"), "{e}");
    }
}

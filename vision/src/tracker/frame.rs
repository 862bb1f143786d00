//! The affine frame of a contour: a local origin `o` and two basis vectors `e1, e2` in the
//! image. A template point with affine coordinates `(s, t)` sits at `o + s·e1 + t·e2`.

use nalgebra::{Matrix2, Matrix3, Vector2};

/// Origin and basis of a tracker's affine frame, in image pixels (`u` right, `v` down): where
/// its template's coordinates `(s, t)` lie in the image.
///
/// The servo uses it both ways: gripper marks are placed in the gripper tracker's frame
/// ([`image_from_template`](Self::image_from_template)), and the gripper point is expressed in
/// the target tracker's frame ([`template_from_image`](Self::template_from_image)).
///
/// ```
/// use handeye_vision::tracker::TemplateFrame;
/// use nalgebra::Vector2;
/// let frame = TemplateFrame::new(Vector2::new(100.0, 50.0), Vector2::new(20.0, 0.0), Vector2::new(5.0, 10.0));
/// let x = frame.image_from_template(Vector2::new(0.5, -1.0));
/// assert_eq!(x, Vector2::new(105.0, 40.0));
/// let st = frame.template_from_image(x).unwrap();
/// assert!((st - Vector2::new(0.5, -1.0)).norm() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemplateFrame {
    /// Local origin `o`, pixels.
    pub origin: Vector2<f64>,
    /// First basis vector `e1`, pixels per unit of `s`.
    pub e1: Vector2<f64>,
    /// Second basis vector `e2`, pixels per unit of `t`.
    pub e2: Vector2<f64>,
}

impl TemplateFrame {
    pub fn new(origin: Vector2<f64>, e1: Vector2<f64>, e2: Vector2<f64>) -> Self {
        Self { origin, e1, e2 }
    }

    /// The basis as the columns of a 2x2 matrix `[e1 e2]`.
    #[inline]
    pub fn basis(&self) -> Matrix2<f64> {
        Matrix2::from_columns(&[self.e1, self.e2])
    }

    /// `det [e1 e2]`: the signed area (px²) of the unit square of template coordinates. Its
    /// sign is the frame's handedness; it changes only if the frame flips through degeneracy.
    #[inline]
    pub fn det(&self) -> f64 {
        self.e1.x * self.e2.y - self.e1.y * self.e2.x
    }

    /// Image position (px) of template coordinates `(s, t)`.
    #[inline]
    pub fn image_from_template(&self, st: Vector2<f64>) -> Vector2<f64> {
        self.origin + self.e1 * st.x + self.e2 * st.y
    }

    /// Template coordinates `(s, t)` of an image point: `[e1 e2]⁻¹ (x − o)`. `None` when the
    /// basis is singular.
    pub fn template_from_image(&self, x: Vector2<f64>) -> Option<Vector2<f64>> {
        let det = self.det();
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let d = x - self.origin;
        Some(Vector2::new((self.e2.y * d.x - self.e2.x * d.y) / det, (self.e1.x * d.y - self.e1.y * d.x) / det))
    }

    /// Ratio of the larger to the smaller singular value of `[e1 e2]` (1 for a similarity,
    /// infinite for a collapsed basis). Large values mean the contour has been squashed flat.
    pub fn anisotropy(&self) -> f64 {
        let b = self.basis();
        // Singular values of a 2x2 matrix from its Frobenius norm and determinant.
        let f2 = b.norm_squared();
        let det = self.det().abs();
        let disc = (f2 * f2 - 4.0 * det * det).max(0.0).sqrt();
        let s_max = ((f2 + disc) / 2.0).sqrt();
        let s_min_sq = (f2 - disc) / 2.0;
        if s_min_sq <= 0.0 {
            return f64::INFINITY;
        }
        s_max / s_min_sq.sqrt()
    }

    /// All six numbers are finite.
    pub fn is_finite(&self) -> bool {
        self.origin.iter().chain(self.e1.iter()).chain(self.e2.iter()).all(|v| v.is_finite())
    }

    /// The frame after an image-plane motion `x ↦ x + t + A (x − centre)`: a translation `t`
    /// and a deformation `A` about `centre`.
    pub fn moved(&self, t: Vector2<f64>, a: Matrix2<f64>, centre: Vector2<f64>) -> Self {
        Self { origin: self.origin + t + a * (self.origin - centre), e1: self.e1 + a * self.e1, e2: self.e2 + a * self.e2 }
    }
}

/// Where a template sits in the image: an affine frame plus an optional perspective term
/// `w`, mapping template coordinates `q = (s, t)` to `x(q) = o + [e1 e2] q / (1 + w·q)`.
///
/// `w = 0` is the thesis's affine contour. With `w ≠ 0` (the
/// [`Projective`](super::DeformationModel::Projective) model) the frame `o, e1, e2` is still
/// the contour's local affine frame at the origin: `x(0) = o` and the derivative there is
/// `[e1 e2]`, so the servo's affine reasoning applies unchanged near the origin.
///
/// ```
/// use handeye_vision::tracker::{TemplateFrame, Placement};
/// use nalgebra::Vector2;
/// let frame = TemplateFrame::new(Vector2::new(100.0, 50.0), Vector2::new(20.0, 0.0), Vector2::new(0.0, 20.0));
/// let p = Placement { frame, perspective: Vector2::new(0.1, 0.0) };
/// let x = p.image_from_template(Vector2::new(1.0, 1.0));
/// assert!((x - Vector2::new(100.0 + 20.0 / 1.1, 50.0 + 20.0 / 1.1)).norm() < 1e-12);
/// assert!((p.template_from_image(x).unwrap() - Vector2::new(1.0, 1.0)).norm() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// The local affine frame at the template origin.
    pub frame: TemplateFrame,
    /// Perspective term `w`, per unit of template coordinates (0 for an affine contour).
    pub perspective: Vector2<f64>,
}

impl Placement {
    /// An affine placement (no perspective).
    pub fn affine(frame: TemplateFrame) -> Self {
        Self { frame, perspective: Vector2::zeros() }
    }

    /// `1 + w·q`: positive wherever the template is in front of the camera's horizon.
    #[inline]
    pub fn denominator(&self, q: Vector2<f64>) -> f64 {
        1.0 + self.perspective.dot(&q)
    }

    /// Image position (px) of template coordinates `q`.
    #[inline]
    pub fn image_from_template(&self, q: Vector2<f64>) -> Vector2<f64> {
        let f = &self.frame;
        f.origin + (f.e1 * q.x + f.e2 * q.y) / self.denominator(q)
    }

    /// Template coordinates of an image point; `None` when the map is singular there.
    pub fn template_from_image(&self, x: Vector2<f64>) -> Option<Vector2<f64>> {
        // (x − o)(1 + w·q) = E q  ⇔  (E − d wᵀ) q = d.
        let d = x - self.frame.origin;
        let m = self.frame.basis() - d * self.perspective.transpose();
        let q = m.try_inverse()? * d;
        q.iter().all(|v| v.is_finite()).then_some(q)
    }

    /// The 3x3 homography from homogeneous template to image coordinates.
    pub fn homography(&self) -> Matrix3<f64> {
        let (o, e, w) = (self.frame.origin, self.frame.basis(), self.perspective);
        let top = e + o * w.transpose();
        Matrix3::new(top[(0, 0)], top[(0, 1)], o.x, top[(1, 0)], top[(1, 1)], o.y, w.x, w.y, 1.0)
    }

    /// The placement of a homography (normalised so its last entry is 1).
    pub fn from_homography(h: &Matrix3<f64>) -> Option<Self> {
        let s = h[(2, 2)];
        if s == 0.0 || !s.is_finite() {
            return None;
        }
        let h = h / s;
        let o = Vector2::new(h[(0, 2)], h[(1, 2)]);
        let w = Vector2::new(h[(2, 0)], h[(2, 1)]);
        let e = Matrix2::new(h[(0, 0)], h[(0, 1)], h[(1, 0)], h[(1, 1)]) - o * w.transpose();
        let p = Self { frame: TemplateFrame::new(o, e.column(0).into(), e.column(1).into()), perspective: w };
        (p.frame.is_finite() && w.iter().all(|v| v.is_finite())).then_some(p)
    }

    /// The placement after an image-plane motion about `centre`: translation `t`, deformation
    /// `A` and perspective `g`, i.e. `x ↦ centre + t + (I + A)(x − c) / (1 + g·(x − c))`. With
    /// `g = 0` this is exactly the affine update of Appendix A.
    pub fn moved(&self, t: Vector2<f64>, a: Matrix2<f64>, g: Vector2<f64>, centre: Vector2<f64>) -> Option<Self> {
        if g == Vector2::zeros() && self.perspective == Vector2::zeros() {
            return Some(Self::affine(self.frame.moved(t, a, centre)));
        }
        let ia = Matrix2::identity() + a;
        let m = Matrix3::new(ia[(0, 0)], ia[(0, 1)], 0.0, ia[(1, 0)], ia[(1, 1)], 0.0, g.x, g.y, 1.0);
        let to = Matrix3::new(1.0, 0.0, centre.x + t.x, 0.0, 1.0, centre.y + t.y, 0.0, 0.0, 1.0);
        let from = Matrix3::new(1.0, 0.0, -centre.x, 0.0, 1.0, -centre.y, 0.0, 0.0, 1.0);
        Self::from_homography(&(to * m * from * self.homography()))
    }

    /// The eight parameters `[o, e1, e2, w]` (for the filter).
    pub(crate) fn to_params(self) -> [f64; 8] {
        let (f, w) = (self.frame, self.perspective);
        [f.origin.x, f.origin.y, f.e1.x, f.e1.y, f.e2.x, f.e2.y, w.x, w.y]
    }

    pub(crate) fn from_params(p: [f64; 8]) -> Self {
        Self {
            frame: TemplateFrame::new(Vector2::new(p[0], p[1]), Vector2::new(p[2], p[3]), Vector2::new(p[4], p[5])),
            perspective: Vector2::new(p[6], p[7]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moved_applies_the_motion_to_every_template_point() {
        let f = TemplateFrame::new(Vector2::new(10.0, 20.0), Vector2::new(3.0, 1.0), Vector2::new(-1.0, 4.0));
        let t = Vector2::new(1.5, -2.0);
        let a = Matrix2::new(0.1, -0.2, 0.05, 0.03);
        let c = Vector2::new(12.0, 18.0);
        let g = f.moved(t, a, c);
        for st in [Vector2::new(0.0, 0.0), Vector2::new(1.0, -2.0), Vector2::new(-0.3, 0.7)] {
            let x = f.image_from_template(st);
            let want = x + t + a * (x - c);
            assert!((g.image_from_template(st) - want).norm() < 1e-12);
        }
    }

    #[test]
    fn projective_motion_composes_exactly_and_reduces_to_affine() {
        let frame = TemplateFrame::new(Vector2::new(200.0, 150.0), Vector2::new(40.0, 5.0), Vector2::new(-8.0, 30.0));
        let p = Placement { frame, perspective: Vector2::new(0.05, -0.08) };
        let (t, a, g, c) = (Vector2::new(2.0, -1.0), Matrix2::new(0.03, 0.01, -0.02, 0.04), Vector2::new(1e-3, 5e-4), Vector2::new(190.0, 160.0));
        let moved = p.moved(t, a, g, c).unwrap();
        for q in [Vector2::new(0.0, 0.0), Vector2::new(0.5, -0.5), Vector2::new(-0.7, 0.3)] {
            let x = p.image_from_template(q);
            let d = x - c;
            let want = c + t + (Matrix2::identity() + a) * d / (1.0 + g.dot(&d));
            assert!((moved.image_from_template(q) - want).norm() < 1e-9);
            assert!((moved.template_from_image(want).unwrap() - q).norm() < 1e-9);
        }
        // The frame is the local affine frame at the origin: derivative there is [e1 e2].
        let eps = 1e-6;
        let de1 = (moved.image_from_template(Vector2::new(eps, 0.0)) - moved.image_from_template(Vector2::new(-eps, 0.0))) / (2.0 * eps);
        assert!((de1 - moved.frame.e1).norm() < 1e-5);
        // Without perspective the projective update is the affine one.
        let affine = Placement::affine(frame);
        let h = Placement::from_homography(&affine.homography()).unwrap();
        assert!((h.frame.e2 - frame.e2).norm() < 1e-12 && h.perspective.norm() == 0.0);
        let m = affine.moved(t, a, Vector2::zeros(), c).unwrap();
        assert_eq!(m.frame, frame.moved(t, a, c));
    }

    #[test]
    fn anisotropy_of_similarity_is_one_and_of_collapsed_basis_infinite() {
        let rot = TemplateFrame::new(Vector2::zeros(), Vector2::new(3.0, 4.0), Vector2::new(-4.0, 3.0));
        assert!((rot.anisotropy() - 1.0).abs() < 1e-9);
        let stretched = TemplateFrame::new(Vector2::zeros(), Vector2::new(10.0, 0.0), Vector2::new(0.0, 2.0));
        assert!((stretched.anisotropy() - 5.0).abs() < 1e-9);
        let flat = TemplateFrame::new(Vector2::zeros(), Vector2::new(1.0, 1.0), Vector2::new(2.0, 2.0));
        assert!(flat.anisotropy().is_infinite());
        assert!(flat.template_from_image(Vector2::new(1.0, 0.0)).is_none());
    }
}

//! The affine frame of a contour: a local origin `o` and two basis vectors `e1, e2` in the
//! image. A template point with affine coordinates `(s, t)` sits at `o + s·e1 + t·e2`.

use nalgebra::{Matrix2, Vector2};

/// Origin and basis of a tracker's affine frame, in image pixels (`u` right, `v` down).
///
/// The servo uses it both ways: gripper marks are placed in the gripper tracker's frame
/// ([`image_from_template`](Self::image_from_template)), and the gripper point is expressed in
/// the target tracker's frame ([`template_from_image`](Self::template_from_image)).
///
/// ```
/// use handeye_vision::tracker::AffineFrame;
/// use nalgebra::Vector2;
/// let frame = AffineFrame::new(Vector2::new(100.0, 50.0), Vector2::new(20.0, 0.0), Vector2::new(5.0, 10.0));
/// let x = frame.image_from_template(Vector2::new(0.5, -1.0));
/// assert_eq!(x, Vector2::new(105.0, 40.0));
/// let st = frame.template_from_image(x).unwrap();
/// assert!((st - Vector2::new(0.5, -1.0)).norm() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineFrame {
    /// Local origin `o`, pixels.
    pub origin: Vector2<f64>,
    /// First basis vector `e1`, pixels per unit of `s`.
    pub e1: Vector2<f64>,
    /// Second basis vector `e2`, pixels per unit of `t`.
    pub e2: Vector2<f64>,
}

impl AffineFrame {
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

    /// The six parameters as an array `[o.x, o.y, e1.x, e1.y, e2.x, e2.y]` (for the filter).
    pub(crate) fn to_params(self) -> [f64; 6] {
        [self.origin.x, self.origin.y, self.e1.x, self.e1.y, self.e2.x, self.e2.y]
    }

    pub(crate) fn from_params(p: [f64; 6]) -> Self {
        Self { origin: Vector2::new(p[0], p[1]), e1: Vector2::new(p[2], p[3]), e2: Vector2::new(p[4], p[5]) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moved_applies_the_motion_to_every_template_point() {
        let f = AffineFrame::new(Vector2::new(10.0, 20.0), Vector2::new(3.0, 1.0), Vector2::new(-1.0, 4.0));
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
    fn anisotropy_of_similarity_is_one_and_of_collapsed_basis_infinite() {
        let rot = AffineFrame::new(Vector2::zeros(), Vector2::new(3.0, 4.0), Vector2::new(-4.0, 3.0));
        assert!((rot.anisotropy() - 1.0).abs() < 1e-9);
        let stretched = AffineFrame::new(Vector2::zeros(), Vector2::new(10.0, 0.0), Vector2::new(0.0, 2.0));
        assert!((stretched.anisotropy() - 5.0).abs() < 1e-9);
        let flat = AffineFrame::new(Vector2::zeros(), Vector2::new(1.0, 1.0), Vector2::new(2.0, 2.0));
        assert!(flat.anisotropy().is_infinite());
        assert!(flat.template_from_image(Vector2::new(1.0, 0.0)).is_none());
    }
}

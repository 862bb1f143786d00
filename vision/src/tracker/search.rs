//! The local edge finder: a 1-D search along the contour normal for maxima of the intensity
//! gradient, with sub-pixel location.
//!
//! Speed comes from sampling on the pixel grid. A point whose normal is closer to horizontal
//! is searched along its image row, otherwise along its column, so every sample is one byte
//! load (contiguous for rows, one stride apart for columns) and no interpolation is needed.
//! This is exact for a straight edge: moving `d` pixels along the row from the predicted point
//! `x` reaches the edge line `n·p = c` where `n·(x + d·u) = c`, so the normal offset is
//! `h = n·(p_edge − x)`, computed from the row sample's true position. The search covers
//! `±search_px` along the normal, i.e. `±search_px / |n_axis|` samples along the axis (at most
//! 1.42x more for a 45° edge).
//!
//! What a line finds: the strongest [`MAX_CANDIDATES`] local maxima of the gradient along it
//! (central difference, of either sign or of the wanted one) of at least `min_contrast`, each
//! moved to the vertex of the parabola through it and its neighbours, with the grey levels
//! 2-3 samples inside and outside it. The tracker searches all of a contour's lines at once,
//! sixteen side by side (`tracker::batch`); `reference` (test builds) does the same one
//! line at a time, and the tests hold the two to the same results bit for bit.

/// Most candidate edges kept per point.
pub const MAX_CANDIDATES: usize = 4;
/// Longest search half-length accepted, pixels along the normal.
pub const MAX_SEARCH_PX: f64 = 40.0;
/// Extra samples read beyond the search window at each end, for the gradient's neighbours
/// and the intensities just inside and outside a peak.
pub(crate) const PAD: usize = 4;
/// Most samples each side of the base pixel inside the window: `(40 + 0.71) · √2`.
pub(crate) const MAX_HALF: usize = 58;

/// Which intensity change across the contour an edge must have.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Polarity {
    /// Two-sided: either sign ("two-sided" snake of the thesis).
    #[default]
    Either,
    /// One-sided: darker inside the contour than outside.
    DarkInside,
    /// One-sided: brighter inside the contour than outside.
    BrightInside,
}

impl Polarity {
    /// Sign of the intensity derivative along the outward normal: +1, -1, or 0 for either.
    #[inline]
    pub(crate) fn outward_sign(self) -> i32 {
        match self {
            Polarity::Either => 0,
            Polarity::DarkInside => 1,
            Polarity::BrightInside => -1,
        }
    }
}

/// Search geometry shared by all points of one polygon side in one update.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SideGeometry {
    /// Outward unit normal in the image.
    pub normal: [f64; 2],
    /// Search along the row (`true`) or the column.
    pub horizontal: bool,
    /// Normal component along the search axis (`n.x` or `n.y`), |.| >= 0.707.
    pub n_axis: f64,
    /// `1 / n_axis`.
    pub inv_n_axis: f64,
    /// Samples each side of the base pixel.
    pub half: usize,
}

impl SideGeometry {
    pub fn new(normal: [f64; 2], search_px: f64) -> Self {
        let horizontal = normal[0].abs() >= normal[1].abs();
        let n_axis = if horizontal { normal[0] } else { normal[1] };
        // Rounding the base pixel moves the search line up to 0.71 px along the normal.
        let half = ((search_px + 0.71) / n_axis.abs()).ceil() as usize;
        Self { normal, horizontal, n_axis, inv_n_axis: 1.0 / n_axis, half: half.min(MAX_HALF) }
    }
}

/// One candidate edge on a search line.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Candidate {
    /// Offset along the outward normal from the predicted point, pixels.
    pub h_px: f32,
    /// Gradient along the outward normal at the peak, signed (central difference, grey levels
    /// per two samples: -255..255). Positive: brighter outside.
    pub contrast: f32,
    /// Mean grey level 2-3 samples inside the peak (towards the contour's interior).
    pub inside: u8,
    /// Mean grey level 2-3 samples outside the peak.
    pub outside: u8,
    /// Extra cost (px) the fit adds to this candidate's distance when choosing among a
    /// point's candidates (set by the tracker from its appearance; 0 from the search).
    pub penalty_px: f32,
}

/// What a search line found.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct PointEdges {
    pub candidates: [Candidate; MAX_CANDIDATES],
    pub count: u8,
    /// The search line left the image: no measurement.
    pub outside: bool,
}

impl PointEdges {
    #[inline]
    pub fn as_slice(&self) -> &[Candidate] {
        &self.candidates[..self.count as usize]
    }
}


/// How each point of a side chooses the edge sign it accepts.
#[derive(Debug, Clone, Copy)]
pub(crate) enum SignRule<'a> {
    /// The same outward sign for every point (`0` = either).
    Fixed(i32),
    /// Each point's learnt reference contrast: its sign once at least `min_contrast` strong,
    /// either sign before.
    Learned { reference: &'a [f32], min_contrast: f32 },
}

impl SignRule<'_> {
    #[inline]
    pub(crate) fn sign(&self, i: usize) -> i32 {
        match *self {
            SignRule::Fixed(s) => s,
            SignRule::Learned { reference, min_contrast } => {
                let r = reference[i];
                if r.abs() >= min_contrast { r.signum() as i32 } else { 0 }
            }
        }
    }
}

/// The appearance cue of a side's points: each candidate costs `gain` px per grey level by
/// which the grey level inside it differs from the point's `reference` by more than
/// `tolerance` (points with a negative reference have learnt none yet; gain 0 disables).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Appearance<'a> {
    pub reference: &'a [f32],
    pub gain: f32,
    pub tolerance: f32,
}

#[cfg(test)]
impl Appearance<'_> {
    /// No cue: every penalty 0.
    pub const NONE: Appearance<'static> = Appearance { reference: &[], gain: 0.0, tolerance: 0.0 };
}

/// The search one line at a time that `tracker::batch` replaces, kept as the reference
/// its tests compare against.
#[cfg(test)]
#[path = "search_reference.rs"]
pub(crate) mod reference;

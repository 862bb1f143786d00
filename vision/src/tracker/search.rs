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

use crate::image::ImageView;

/// Most candidate edges kept per point.
pub const MAX_CANDIDATES: usize = 4;
/// Longest search half-length accepted, pixels along the normal.
pub const MAX_SEARCH_PX: f64 = 40.0;
/// Samples along the axis for the longest search: `40 · √2 + 2` each side plus two ends.
const BUF: usize = 2 * 60 + 3;

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

    /// The polarity whose outward sign is `sign` (0 = either).
    pub(crate) fn from_outward_sign(sign: i32) -> Self {
        match sign.signum() {
            1 => Polarity::DarkInside,
            -1 => Polarity::BrightInside,
            _ => Polarity::Either,
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
    /// Samples each side of the base pixel.
    pub half: usize,
}

impl SideGeometry {
    pub fn new(normal: [f64; 2], search_px: f64) -> Self {
        let horizontal = normal[0].abs() >= normal[1].abs();
        let n_axis = if horizontal { normal[0] } else { normal[1] };
        // Rounding the base pixel moves the search line up to 0.71 px along the normal.
        let half = ((search_px + 0.71) / n_axis.abs()).ceil() as usize;
        Self { normal, horizontal, n_axis, half: half.min((BUF - 3) / 2) }
    }
}

/// One candidate edge on a search line.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Candidate {
    /// Offset along the outward normal from the predicted point, pixels.
    pub h_px: f32,
    /// Gradient along the outward normal at the peak, signed (central difference, grey levels
    /// per two samples: -510..510). Positive: brighter outside.
    pub contrast: f32,
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

/// Searches one point's normal for up to [`MAX_CANDIDATES`] gradient maxima of at least
/// `min_contrast` with the wanted outward sign (`0` = either), keeping the strongest, and
/// writes them into `out`. `(x, y)` is the predicted point in pixels.
#[inline]
pub(crate) fn search_point(
    image: &ImageView<'_>,
    side: &SideGeometry,
    x: f64,
    y: f64,
    search_px: f64,
    outward_sign: i32,
    min_contrast: i32,
    out: &mut PointEdges,
) {
    out.count = 0;
    out.outside = false;
    let (w, h, stride) = (image.width() as isize, image.height() as isize, image.stride());
    let bx = x.round();
    let by = y.round();
    if !(bx.is_finite() && by.is_finite()) {
        out.outside = true;
        return;
    }
    let (bxi, byi) = (bx as isize, by as isize);
    let half = side.half as isize;
    let reach = half + 1;
    let len = 2 * side.half + 3;
    let mut buf = [0i16; BUF];
    let data = image.data();
    if side.horizontal {
        if byi < 0 || byi >= h || bxi - reach < 0 || bxi + reach >= w {
            out.outside = true;
            return;
        }
        let start = byi as usize * stride + (bxi - reach) as usize;
        for (b, &p) in buf[..len].iter_mut().zip(&data[start..start + len]) {
            *b = p as i16;
        }
    } else {
        if bxi < 0 || bxi >= w || byi - reach < 0 || byi + reach >= h {
            out.outside = true;
            return;
        }
        let start = (byi - reach) as usize * stride + bxi as usize;
        let column = data[start..start + (len - 1) * stride + 1].iter().step_by(stride);
        for (b, &p) in buf[..len].iter_mut().zip(column) {
            *b = p as i16;
        }
    }

    // Derivative along the outward normal (sign of the axis step folded in), then the score
    // that the wanted polarity maximises.
    let axis_sign: i32 = if side.n_axis >= 0.0 { 1 } else { -1 };
    let mut score = [0i32; BUF];
    let mut grad = [0i32; BUF];
    for k in 1..len - 1 {
        let g = axis_sign * (buf[k + 1] as i32 - buf[k - 1] as i32);
        grad[k] = g;
        score[k] = match outward_sign {
            0 => g.abs(),
            s => s * g,
        };
    }

    // Normal offset of the base pixel relative to the predicted point.
    let h0 = side.normal[0] * (bx - x) + side.normal[1] * (by - y);
    let step_h = side.n_axis; // normal offset per axis step
    let mut count = 0usize;
    for k in 2..len - 2 {
        let s = score[k];
        if s < min_contrast || s <= score[k - 1] || s < score[k + 1] {
            continue;
        }
        // Parabola through the peak and its neighbours.
        let (a, c) = (score[k - 1] as f64, score[k + 1] as f64);
        let denom = a - 2.0 * s as f64 + c;
        let delta = if denom < 0.0 { (0.5 * (a - c) / denom).clamp(-0.5, 0.5) } else { 0.0 };
        let d = (k as isize - reach) as f64 + delta;
        let h_px = h0 + d * step_h;
        if h_px.abs() > search_px {
            continue;
        }
        let peak = s as f64 - 0.25 * (a - c) * delta;
        let sign = if grad[k] >= 0 { 1.0 } else { -1.0 };
        let cand = Candidate { h_px: h_px as f32, contrast: (sign * peak) as f32 };
        // Keep the strongest MAX_CANDIDATES (insertion into a tiny sorted array).
        let mut pos = count;
        while pos > 0 && out.candidates[pos - 1].contrast.abs() < cand.contrast.abs() {
            if pos < MAX_CANDIDATES {
                out.candidates[pos] = out.candidates[pos - 1];
            }
            pos -= 1;
        }
        if pos < MAX_CANDIDATES {
            out.candidates[pos] = cand;
            count = (count + 1).min(MAX_CANDIDATES);
        }
    }
    out.count = count as u8;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::ImageBuf;

    /// An image with a straight step edge `n·p = c` (value `lo` on the side where `n·p < c`)
    /// blurred over about one pixel, rendered by supersampling.
    fn edge_image(n: [f64; 2], c: f64, lo: u8, hi: u8) -> ImageBuf {
        let mut img = ImageBuf::new(64, 64);
        for y in 0..64 {
            for x in 0..64 {
                let mut acc = 0.0;
                for sy in 0..8 {
                    for sx in 0..8 {
                        let (px, py) = (x as f64 + (sx as f64 + 0.5) / 8.0 - 0.5, y as f64 + (sy as f64 + 0.5) / 8.0 - 0.5);
                        let dist = n[0] * px + n[1] * py - c;
                        acc += 1.0 / (1.0 + (-2.0 * dist).exp());
                    }
                }
                let f = acc / 64.0;
                img.set(x, y, (lo as f64 + f * (hi as f64 - lo as f64)).round() as u8);
            }
        }
        img
    }

    #[test]
    fn finds_a_straight_edge_with_subpixel_accuracy_at_any_angle() {
        for deg in [0.0f64, 17.0, 44.0, 46.0, 90.0, 133.0, 200.0, 301.0] {
            let a = deg.to_radians();
            let n = [a.cos(), a.sin()];
            let centre = [32.3, 31.6];
            for true_h in [-4.3, -0.5, 0.0, 2.7, 6.1] {
                let c = n[0] * centre[0] + n[1] * centre[1] + true_h;
                let img = edge_image(n, c, 40, 200);
                let side = SideGeometry::new(n, 10.0);
                let mut out = PointEdges::default();
                search_point(&img.view(), &side, centre[0], centre[1], 10.0, 1, 10, &mut out);
                assert_eq!(out.count, 1, "angle {deg} h {true_h}");
                let got = out.candidates[0];
                assert!((got.h_px as f64 - true_h).abs() < 0.1, "angle {deg}: want {true_h}, got {}", got.h_px);
                assert!(got.contrast > 0.0);
                // The opposite polarity sees nothing.
                search_point(&img.view(), &side, centre[0], centre[1], 10.0, -1, 10, &mut out);
                assert_eq!(out.count, 0);
            }
        }
    }

    #[test]
    fn edges_beyond_the_search_range_or_too_weak_are_not_found() {
        let n = [1.0, 0.0];
        let img = edge_image(n, 32.0 + 8.0, 100, 200);
        let side = SideGeometry::new(n, 5.0);
        let mut out = PointEdges::default();
        search_point(&img.view(), &side, 32.0, 32.0, 5.0, 0, 10, &mut out);
        assert_eq!(out.count, 0);
        let side = SideGeometry::new(n, 10.0);
        search_point(&img.view(), &side, 32.0, 32.0, 10.0, 0, 10, &mut out);
        assert_eq!(out.count, 1);
        search_point(&img.view(), &side, 32.0, 32.0, 10.0, 0, 250, &mut out);
        assert_eq!(out.count, 0);
    }

    #[test]
    fn keeps_the_strongest_candidates_and_reports_leaving_the_image() {
        // Three vertical bars of different contrast to the right of x = 32.
        let mut img = ImageBuf::filled(64, 64, 100);
        for y in 0..64 {
            for x in 0..64 {
                let v = match x {
                    34..=35 => 130,
                    38..=39 => 190,
                    42..=43 => 110,
                    _ => 100,
                };
                img.set(x, y, v);
            }
        }
        let side = SideGeometry::new([1.0, 0.0], 12.0);
        let mut out = PointEdges::default();
        search_point(&img.view(), &side, 32.0, 20.0, 12.0, 1, 5, &mut out);
        let c = out.as_slice();
        assert_eq!(c.len(), 3);
        // Strongest first: the 190 bar's rising edge, then the 130, then the 110.
        assert!((c[0].h_px - 5.5).abs() < 0.6 && c[0].contrast > c[1].contrast);
        assert!((c[1].h_px - 1.5).abs() < 0.6 && c[1].contrast > c[2].contrast);
        assert!((c[2].h_px - 9.5).abs() < 0.6);
        search_point(&img.view(), &side, 60.0, 20.0, 12.0, 1, 5, &mut out);
        assert!(out.outside && out.count == 0);
    }
}

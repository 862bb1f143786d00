//! Pixel work of the plan phase: the gripper masked out of the images by a harmonic fill, and
//! the image support of a projected edge. The polygon geometry it needs (and the outline
//! that initialises the target trackers) is vision's (`handeye_vision::planner::geom`).

use handeye_vision::image::ImageBuf;
use handeye_vision::planner::geom::{contains, point_segment_distance};

/// Replaces the pixels inside `poly` (or within `margin_px` of it; tracker pixels) with a
/// smooth fill from the unmasked pixels around (module docs). Returns how many were masked.
pub fn mask_and_fill(img: &mut ImageBuf, poly: &[[f64; 2]], margin_px: f64) -> usize {
    let (w, h) = (img.width, img.height);
    if poly.len() < 3 || w == 0 || h == 0 || poly.iter().flatten().any(|v| !v.is_finite()) {
        return 0;
    }
    let lo = |k: usize| poly.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min) - margin_px;
    let hi = |k: usize| poly.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max) + margin_px;
    let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64 - 1.0) as usize;
    let (x0, x1, y0, y1) = (clamp(lo(0).floor(), w), clamp(hi(0).ceil(), w), clamp(lo(1).floor(), h), clamp(hi(1).ceil(), h));
    let mut masked = vec![false; w * h];
    let mut count = 0;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let p = [x as f64, y as f64];
            let near = contains(poly, p, 0.0) || (0..poly.len()).any(|i| point_segment_distance(p, poly[i], poly[(i + 1) % poly.len()]) <= margin_px);
            if near {
                masked[y * w + x] = true;
                count += 1;
            }
        }
    }
    if count == 0 || count == w * h {
        return count;
    }
    // Harmonic fill: the masked pixels solve Laplace's equation with the unmasked pixels
    // around as boundary values (over-relaxed Gauss-Seidel, from the row/column
    // interpolation as a start). Smooth inside, no step at the border: a step in the
    // background that crosses the mask (the arm's silhouette) is spread into a gentle ramp
    // that no edge detector takes for an edge.
    let src = img.data.clone();
    let (bw, bh) = (x1 - x0 + 1, y1 - y0 + 1);
    let mut v = vec![0f32; bw * bh];
    for y in y0..=y1 {
        for x in x0..=x1 {
            let i = (y - y0) * bw + (x - x0);
            if !masked[y * w + x] {
                v[i] = f32::from(src[y * w + x]);
                continue;
            }
            let (mut sum, mut wsum) = (0.0, 0.0);
            let mut take = |xx: usize, yy: usize, d: usize| {
                let wt = 1.0 / d as f32;
                sum += wt * f32::from(src[yy * w + xx]);
                wsum += wt;
            };
            if let Some(d) = (1..=x).find(|&d| !masked[y * w + x - d]) {
                take(x - d, y, d);
            }
            if let Some(d) = (1..w - x).find(|&d| !masked[y * w + x + d]) {
                take(x + d, y, d);
            }
            if let Some(d) = (1..=y).find(|&d| !masked[(y - d) * w + x]) {
                take(x, y - d, d);
            }
            if let Some(d) = (1..h - y).find(|&d| !masked[(y + d) * w + x]) {
                take(x, y + d, d);
            }
            v[i] = if wsum > 0.0 { sum / wsum } else { 128.0 };
        }
    }
    // Neighbours outside the box are outside the mask too (the box holds the whole mask),
    // so the box's own border rows and columns are fixed values.
    let cells: Vec<(usize, usize)> = (y0..=y1).flat_map(|y| (x0..=x1).map(move |x| (x, y))).filter(|&(x, y)| masked[y * w + x]).collect();
    let omega = 1.9f32;
    for _ in 0..400 {
        let mut change = 0f32;
        for &(x, y) in &cells {
            let i = (y - y0) * bw + (x - x0);
            let (mut sum, mut n) = (0f32, 0f32);
            if x > x0 {
                sum += v[i - 1];
                n += 1.0;
            } else if x > 0 {
                sum += f32::from(src[y * w + x - 1]);
                n += 1.0;
            }
            if x < x1 {
                sum += v[i + 1];
                n += 1.0;
            } else if x + 1 < w {
                sum += f32::from(src[y * w + x + 1]);
                n += 1.0;
            }
            if y > y0 {
                sum += v[i - bw];
                n += 1.0;
            } else if y > 0 {
                sum += f32::from(src[(y - 1) * w + x]);
                n += 1.0;
            }
            if y < y1 {
                sum += v[i + bw];
                n += 1.0;
            } else if y + 1 < h {
                sum += f32::from(src[(y + 1) * w + x]);
                n += 1.0;
            }
            if n > 0.0 {
                let d = omega * (sum / n - v[i]);
                v[i] += d;
                change = change.max(d.abs());
            }
        }
        if change < 0.05 {
            break;
        }
    }
    for &(x, y) in &cells {
        img.data[y * w + x] = v[(y - y0) * bw + (x - x0)].round().clamp(0.0, 255.0) as u8;
    }
    count
}

/// Share of the segment `a`-`b` (tracker pixels) along which the image steps by at least
/// 12 grey levels across it, within 3 px of the line (a projected edge is off by a pixel or
/// two): at each pixel along it, the largest difference of the grey levels 2 px either side
/// of points up to 3 px off the line. 0 for a segment off the image or under 4 px.
pub fn edge_support(img: &ImageBuf, a: [f64; 2], b: [f64; 2]) -> f64 {
    let (mut hits, mut n) = (0usize, 0usize);
    let walked = walk_segment(img, a, b, |across| {
        // The step at `d` px off the line: the pixels 2 px either side of it, along the normal.
        let step = |d: f64| Some((across(d + 2.0)? - across(d - 2.0)?).abs());
        n += 1;
        if (-3..=3).filter_map(|d| step(f64::from(d))).any(|s| s >= 12.0) {
            hits += 1;
        }
    });
    if walked { hits as f64 / n as f64 } else { 0.0 }
}

/// How strongly the image steps across the segment `a`-`b` exactly on it (tracker pixels):
/// the mean absolute difference of the pixels 2 px either side along its normal, grey levels.
/// Unlike [`edge_support`] it has no slack across the segment, so it peaks where the edge is.
pub fn edge_strength(img: &ImageBuf, a: [f64; 2], b: [f64; 2]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    walk_segment(img, a, b, |across| {
        if let (Some(p), Some(q)) = (across(2.0), across(-2.0)) {
            sum += (p - q).abs();
            n += 1;
        }
    });
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// Walks the segment `a`-`b` one pixel at a time (both ends included) and hands `visit`, at
/// each point, the grey level `d` px off it along its normal (`None` off the image). Returns
/// false, visiting nothing, for a segment under 4 px or with NaN ends: too short to say
/// anything about an edge.
fn walk_segment(img: &ImageBuf, a: [f64; 2], b: [f64; 2], mut visit: impl FnMut(&dyn Fn(f64) -> Option<f64>)) -> bool {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    if len.is_nan() || len < 4.0 {
        return false;
    }
    let (nx, ny) = (-dy / len, dx / len);
    let steps = len.floor() as usize;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = (a[0] + t * dx, a[1] + t * dy);
        let across = |d: f64| -> Option<f64> {
            let (xi, yi) = ((x + d * nx).round(), (y + d * ny).round());
            (xi >= 0.0 && yi >= 0.0 && (xi as usize) < img.width && (yi as usize) < img.height).then(|| f64::from(img.get(xi as usize, yi as usize)))
        };
        visit(&across);
    }
    true
}

/// The segment `a`-`b` moved along `dir` (a unit image direction) by the shift, within
/// `max_shift_px` either way in 1 px steps, at which the image steps most strongly across it
/// ([`edge_strength`]): the middle of the run of shifts within 5 % of the strongest (a sharp
/// step is as strong over the few pixels the 2 px sampling straddles), the run nearest no
/// shift. For an edge whose image place comes from a model that may be a few pixels off (the
/// bottom edge of a face hung from a top edge down to the table): where the edge is.
pub fn strongest_shift(img: &ImageBuf, a: [f64; 2], b: [f64; 2], dir: [f64; 2], max_shift_px: f64) -> f64 {
    let reach = max_shift_px.max(0.0).floor() as i32;
    let strength: Vec<f64> = (-reach..=reach)
        .map(|k| {
            let s = f64::from(k);
            let m = |p: [f64; 2]| [p[0] + s * dir[0], p[1] + s * dir[1]];
            edge_strength(img, m(a), m(b))
        })
        .collect();
    let max = strength.iter().copied().fold(0.0, f64::max);
    if max <= 0.0 {
        return 0.0;
    }
    let strong = |i: usize| strength[i] >= 0.95 * max;
    let centre = reach as usize;
    let Some(seed) = (0..strength.len()).filter(|&i| strong(i)).min_by_key(|&i| i.abs_diff(centre)) else { return 0.0 };
    let (mut lo, mut hi) = (seed, seed);
    while lo > 0 && strong(lo - 1) {
        lo -= 1;
    }
    while hi + 1 < strength.len() && strong(hi + 1) {
        hi += 1;
    }
    (lo + hi) as f64 / 2.0 - f64::from(reach)
}

/// How near the image border an edge cannot be seen, px: [`edge_support`] samples 2 px
/// either side of points up to 3 px off the line.
pub const BORDER_PX: f64 = 5.0;

/// Where the bottom edge of a face hung from a top edge down to the table shows in one view:
/// `quad` is its outline (tracker pixels) bottom corners first, `[a0, b0, b, a]`, its bottom
/// placed by a model that may be a few pixels off at table height (the cage of reference
/// points is 10-15 cm above it). The bottom edge is looked for within 30 % of the face's
/// image height of where the model put it ([`strongest_shift`]) and must have image support
/// there ([`edge_support`] at least `min_support`), and the face between it and the top edge
/// must be one face: no edge along it inside, more than 6 px from both (the tall leg of an
/// L-block over its low leg shows the step there). Returns the image offset to add to the
/// bottom corners; `None` when the face is not seen.
///
/// A face whose bottom corners the model puts past the image border (within
/// [`BORDER_PX`] of it, or outside) cannot show its bottom edge: the border is not an edge.
/// Such a face is seen when its top edge is inside the image and it is one face down to
/// where the image ends; its bottom stays where the model put it (offset zero).
pub fn bottom_edge_offset(img: &ImageBuf, quad: &[[f64; 2]], min_support: f64) -> Option<[f64; 2]> {
    let [a0, b0, b, a] = <[[f64; 2]; 4]>::try_from(quad).ok()?;
    let inside = |p: [f64; 2]| {
        let (w, h) = (img.width as f64, img.height as f64);
        p[0] >= BORDER_PX && p[1] >= BORDER_PX && p[0] <= w - 1.0 - BORDER_PX && p[1] <= h - 1.0 - BORDER_PX
    };
    let cut_by_border = !(inside(a0) && inside(b0));
    if cut_by_border && !(inside(a) && inside(b)) {
        return None;
    }
    let (ua, ub) = ([a[0] - a0[0], a[1] - a0[1]], [b[0] - b0[0], b[1] - b0[1]]);
    let height_px = 0.5 * (ua[0].hypot(ua[1]) + ub[0].hypot(ub[1]));
    let up = [ua[0] + ub[0], ua[1] + ub[1]];
    let norm = up[0].hypot(up[1]);
    if !(height_px.is_finite() && norm > 1e-9) {
        return None;
    }
    let up = [up[0] / norm, up[1] / norm];
    let moved = |p: [f64; 2], d: f64| [p[0] + d * up[0], p[1] + d * up[1]];
    let s = if cut_by_border { 0.0 } else { strongest_shift(img, a0, b0, up, 0.3 * height_px) };
    if !cut_by_border && edge_support(img, moved(a0, s), moved(b0, s)) < min_support {
        return None;
    }
    const MARGIN_PX: f64 = 6.0;
    let mut d = s + MARGIN_PX;
    while d <= height_px - MARGIN_PX {
        let t = d / height_px;
        let on_face = |lo: [f64; 2], hi: [f64; 2]| [lo[0] + t * (hi[0] - lo[0]), lo[1] + t * (hi[1] - lo[1])];
        if edge_support(img, on_face(a0, a), on_face(b0, b)) >= min_support {
            return None;
        }
        d += 1.0;
    }
    Some([s * up[0], s * up[1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fill_leaves_no_step_at_the_mask_border() {
        // A left-to-right ramp with a bright square on it; masking the square gives back the
        // ramp (to rounding), so no edge is left at the mask's border.
        let (w, h) = (60, 40);
        let mut img = ImageBuf::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let inside = (20..35).contains(&x) && (10..25).contains(&y);
                img.set(x, y, if inside { 250 } else { (50 + 2 * x) as u8 });
            }
        }
        let sq = [[20.0, 10.0], [34.0, 10.0], [34.0, 24.0], [20.0, 24.0]];
        let n = mask_and_fill(&mut img, &sq, 1.0);
        assert_eq!(n, 17 * 17 - 4, "the square and 1 px around it, less the far corners");
        for y in 0..h {
            for x in 0..w {
                let want = (50 + 2 * x) as i32;
                assert!((i32::from(img.get(x, y)) - want).abs() <= 1, "({x}, {y}): {} vs {want}", img.get(x, y));
            }
        }
        // Nothing to mask, or a bad polygon: the image is untouched.
        let before = img.clone();
        assert_eq!(mask_and_fill(&mut img, &[[1.0, 1.0], [2.0, 2.0]], 1.0), 0);
        assert_eq!(mask_and_fill(&mut img, &[[f64::NAN, 1.0], [2.0, 2.0], [3.0, 1.0]], 1.0), 0);
        assert_eq!(img, before);
    }

    #[test]
    fn edge_support_sees_a_step_and_not_a_flat_face() {
        // Left half 40, right half 120: a vertical edge at x = 29.5.
        let mut img = ImageBuf::new(60, 40);
        for y in 0..40 {
            for x in 0..60 {
                img.set(x, y, if x < 30 { 40 } else { 120 });
            }
        }
        assert!(edge_support(&img, [29.5, 5.0], [29.5, 35.0]) > 0.95);
        assert!(edge_support(&img, [27.0, 5.0], [27.0, 35.0]) > 0.95, "2.5 px off the edge still finds it");
        assert!(edge_support(&img, [10.0, 5.0], [10.0, 35.0]) < 0.05, "inside a flat region");
        assert!(edge_support(&img, [5.0, 20.0], [55.0, 20.0]) < 0.05, "along the edge's normal");
        assert_eq!(edge_support(&img, [10.0, 5.0], [10.0, 6.0]), 0.0, "too short");
        assert_eq!(edge_support(&img, [-100.0, 5.0], [-100.0, 35.0]), 0.0, "off the image");
    }

    #[test]
    fn the_strongest_shift_finds_an_edge_a_model_put_a_few_pixels_off() {
        // A face (120) above a table (30) with the step at y = 27.5: the model's line at
        // y = 20 is found 7-8 px down; a flat image gives no shift.
        let mut img = ImageBuf::new(60, 50);
        for y in 0..50 {
            for x in 0..60 {
                img.set(x, y, if y < 28 { 120 } else { 30 });
            }
        }
        let s = strongest_shift(&img, [10.0, 20.0], [50.0, 20.0], [0.0, 1.0], 10.0);
        assert!((7.0..=8.0).contains(&s), "{s}");
        assert!(edge_strength(&img, [10.0, 20.0 + s], [50.0, 20.0 + s]) > 80.0);
        assert!(edge_strength(&img, [10.0, 10.0], [50.0, 10.0]) < 1.0, "inside the face");
        let flat = ImageBuf::new(60, 50);
        assert_eq!(strongest_shift(&flat, [10.0, 20.0], [50.0, 20.0], [0.0, 1.0], 10.0), 0.0);
    }

    #[test]
    fn a_hung_face_is_seen_down_to_its_bottom_edge_and_not_over_a_step() {
        // A face from y = 10 (top) to y = 37.5 (its bottom, against a dark table), 20..50 px
        // wide; the model put its bottom at y = 33.
        let mut img = ImageBuf::new(70, 60);
        for y in 0..60 {
            for x in 0..70 {
                img.set(x, y, if (20..50).contains(&x) && (10..38).contains(&y) { 120 } else { 30 });
            }
        }
        let quad = [[20.0, 33.0], [50.0, 33.0], [50.0, 10.0], [20.0, 10.0]];
        let off = bottom_edge_offset(&img, &quad, 0.6).expect("seen");
        assert!(off[0].abs() < 1e-9 && (4.0..=5.0).contains(&off[1]), "{off:?}");
        // A step across the face halfway down (an L-block's tall leg over its low leg): not
        // one face.
        for y in 22..38 {
            for x in 20..50 {
                img.set(x, y, 190);
            }
        }
        assert_eq!(bottom_edge_offset(&img, &quad, 0.6), None);
        // No bottom edge near where the model put it: not seen.
        let flat = ImageBuf::new(70, 60);
        assert_eq!(bottom_edge_offset(&flat, &quad, 0.6), None);
    }

    #[test]
    fn a_hung_face_cut_by_the_image_border_is_seen_without_its_bottom_edge() {
        // --disturb seed 4: the pointed cube across the right view's bottom border. Its face
        // runs from y = 40 (top edge) off the image (60 rows); the model puts its bottom at
        // y = 66, past the border.
        let mut img = ImageBuf::new(70, 60);
        for y in 0..60 {
            for x in 0..70 {
                img.set(x, y, if (20..50).contains(&x) && y >= 40 { 120 } else { 30 });
            }
        }
        let quad = [[20.0, 66.0], [50.0, 66.0], [50.0, 40.0], [20.0, 40.0]];
        assert_eq!(bottom_edge_offset(&img, &quad, 0.6), Some([0.0, 0.0]), "the border is not an edge");
        // Still one face only: a step across it inside the image is not.
        for y in 50..60 {
            for x in 20..50 {
                img.set(x, y, 200);
            }
        }
        assert_eq!(bottom_edge_offset(&img, &quad, 0.6), None);
        // Its top edge must be inside the image.
        let above = [[20.0, 66.0], [50.0, 66.0], [50.0, 57.0], [20.0, 57.0]];
        assert_eq!(bottom_edge_offset(&img, &above, 0.6), None);
    }
}

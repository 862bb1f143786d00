//! Pixel work of the plan phase: the gripper masked out of the images by a harmonic fill,
//! the image support of a projected edge, and the simplified outline that initialises the
//! target trackers.

use handeye_vision::image::ImageBuf;

pub(crate) fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0) } else { 0.0 };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

fn inside(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut odd = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            odd = !odd;
        }
    }
    odd
}

/// Share of polygon `a`'s area (pixel centres inside it) that lies inside polygon `b`; 0
/// when `a` covers no pixel centre.
pub fn covered_share(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    if a.len() < 3 || b.len() < 3 || a.iter().chain(b).flatten().any(|v| !v.is_finite()) {
        return 0.0;
    }
    let lo = |k: usize| a.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min).floor() as i64;
    let hi = |k: usize| a.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max).ceil() as i64;
    let (mut total, mut shared) = (0u64, 0u64);
    for y in lo(1)..=hi(1) {
        for x in lo(0)..=hi(0) {
            let p = [x as f64, y as f64];
            if inside(a, p) {
                total += 1;
                shared += u64::from(inside(b, p));
            }
        }
    }
    if total == 0 { 0.0 } else { shared as f64 / total as f64 }
}

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
            let near = inside(poly, p) || (0..poly.len()).any(|i| point_segment_distance(p, poly[i], poly[(i + 1) % poly.len()]) <= margin_px);
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
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    if len.is_nan() || len < 4.0 {
        return 0.0;
    }
    let (nx, ny) = (-dy / len, dx / len);
    let at = |x: f64, y: f64| -> Option<f64> {
        let (xi, yi) = (x.round(), y.round());
        (xi >= 0.0 && yi >= 0.0 && (xi as usize) < img.width && (yi as usize) < img.height).then(|| f64::from(img.get(xi as usize, yi as usize)))
    };
    let steps = len.floor() as usize;
    let mut hits = 0;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = (a[0] + t * dx, a[1] + t * dy);
        let step = |d: f64| -> Option<f64> { Some((at(x + (d + 2.0) * nx, y + (d + 2.0) * ny)? - at(x + (d - 2.0) * nx, y + (d - 2.0) * ny)?).abs()) };
        if (-3..=3).filter_map(|d| step(f64::from(d))).any(|s| s >= 12.0) {
            hits += 1;
        }
    }
    hits as f64 / (steps + 1) as f64
}

/// Indices of the vertices kept by Douglas-Peucker on a closed polygon (tolerance `tol`),
/// at least three, in order.
pub fn simplify_closed(poly: &[[f64; 2]], tol: f64) -> Vec<usize> {
    let n = poly.len();
    if n <= 3 {
        return (0..n).collect();
    }
    // Split at vertex 0 and the vertex farthest from it.
    let far = (1..n).max_by(|&a, &b| {
        let d = |i: usize| (poly[i][0] - poly[0][0]).hypot(poly[i][1] - poly[0][1]);
        d(a).total_cmp(&d(b))
    });
    let Some(far) = far else { return (0..n).collect() };
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[far] = true;
    fn dp(poly: &[[f64; 2]], a: usize, b: usize, tol: f64, keep: &mut [bool]) {
        // Vertices strictly between a and b, going forward (cyclically).
        let n = poly.len();
        let mut best = (0.0, None);
        let mut i = (a + 1) % n;
        while i != b {
            let d = point_segment_distance(poly[i], poly[a], poly[b]);
            if d > best.0 {
                best = (d, Some(i));
            }
            i = (i + 1) % n;
        }
        if let (d, Some(i)) = best
            && d > tol
        {
            keep[i] = true;
            dp(poly, a, i, tol, keep);
            dp(poly, i, b, tol, keep);
        }
    }
    dp(poly, 0, far, tol, &mut keep);
    dp(poly, far, 0, tol, &mut keep);
    let mut out: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
    // Fewer than three: add the vertex farthest from the chord.
    while out.len() < 3 {
        let extra = (0..n).filter(|i| !out.contains(i)).max_by(|&a, &b| {
            let d = |i: usize| point_segment_distance(poly[i], poly[out[0]], poly[out[out.len() - 1]]);
            d(a).total_cmp(&d(b))
        });
        match extra {
            Some(e) => {
                out.push(e);
                out.sort_unstable();
            }
            None => break,
        }
    }
    out
}

/// `keep` (indices into `poly`, in order) rotated to start at the corner whose two sides
/// span the largest parallelogram: a tracker's template frame is `e1 = c1 − c0`,
/// `e2 = c_{n−1} − c0`, and the servo's view of the facet (its `s, t` rows and plane
/// transfer) is only as well conditioned as that frame; a short side at a notch of an L
/// would make it lopsided.
pub fn tracker_order(poly: &[[f64; 2]], keep: &[usize]) -> Vec<usize> {
    let n = keep.len();
    if n < 3 {
        return keep.to_vec();
    }
    let area = |k: usize| {
        let (o, a, b) = (poly[keep[k]], poly[keep[(k + 1) % n]], poly[keep[(k + n - 1) % n]]);
        ((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])).abs()
    };
    let best = (0..n).max_by(|&a, &b| area(a).total_cmp(&area(b)).then(b.cmp(&a))).unwrap_or(0);
    (0..n).map(|k| keep[(best + k) % n]).collect()
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
    fn covered_share_is_the_share_of_the_first_polygon_inside_the_second() {
        let square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let left_half = [[-1.0, -1.0], [4.9, -1.0], [4.9, 11.0], [-1.0, 11.0]];
        assert_eq!(covered_share(&square, &square), 1.0);
        // Pixel centres 0..=4 of the ten columns inside the square (0..10).
        let half = covered_share(&square, &left_half);
        assert!((half - 0.5).abs() < 0.01, "{half}");
        assert_eq!(covered_share(&left_half, &[[20.0, 0.0], [30.0, 0.0], [30.0, 10.0]]), 0.0);
        assert_eq!(covered_share(&square, &[[0.0, 0.0], [1.0, 1.0]]), 0.0, "not a polygon");
        assert_eq!(covered_share(&[[f64::NAN, 0.0], [1.0, 0.0], [1.0, 1.0]], &square), 0.0);
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
    fn simplification_drops_slivers_and_keeps_corners() {
        // A square whose corner (10, 0) is split into two vertices 1 px apart, plus a point
        // in the middle of a side.
        let poly = [[0.0, 0.0], [9.0, 0.0], [10.0, 1.0], [10.0, 10.0], [5.0, 10.2], [0.0, 10.0]];
        let keep = simplify_closed(&poly, 1.5);
        assert_eq!(keep.len(), 4, "{keep:?}");
        assert!(keep.contains(&0) && keep.contains(&5));
        // A triangle stays a triangle.
        assert_eq!(simplify_closed(&[[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]], 1.5), vec![0, 1, 2]);
        // An L (tall leg on the right): the frame starts at the corner with the longest
        // sides, the bottom-right one (40 across, 40 up).
        let l = [[0.0, 0.0], [0.0, -20.0], [20.0, -20.0], [20.0, -40.0], [40.0, -40.0], [40.0, 0.0]];
        assert_eq!(tracker_order(&l, &[0, 1, 2, 3, 4, 5]), vec![5, 0, 1, 2, 3, 4]);
    }
}

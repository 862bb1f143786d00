//! Tests of `batch`: the search of a whole contour must find exactly what the line-by-line
//! reference search finds.

use super::super::search::reference::{search_side, SideScratch};
use super::*;
use crate::image::ImageView;
use crate::rng::SplitMix64;

/// A textured image: bands, blobs and noise, with plateaus (ties are where an off-by-one
/// would show), in a buffer whose stride exceeds its width.
fn image(rng: &mut SplitMix64, width: usize, height: usize, stride: usize) -> Vec<u8> {
    let mut data = vec![0u8; stride * (height - 1) + width];
    let (fx, fy, phase) = (rng.next_f64() * 0.7, rng.next_f64() * 0.7, rng.next_f64() * 6.0);
    for y in 0..height {
        for x in 0..width {
            let wave = ((x as f64 * fx + y as f64 * fy + phase).sin() * 90.0) as i32;
            let step = if (x / 7 + y / 5) % 3 == 0 { 60 } else { 0 };
            let noise = (rng.next_u64() % 9) as i32 - 4;
            let v = (128 + wave + step + if rng.below(4) == 0 { 0 } else { noise }).clamp(0, 255);
            data[y * stride + x] = v as u8;
        }
    }
    data
}

#[test]
fn matches_the_line_by_line_search_bit_for_bit() {
    let mut rng = SplitMix64::new(0x1234_5678_9abc_def1);
    let mut search = ContourSearch::new();
    let mut checked = (0usize, 0usize, 0usize);
    for round in 0..160 {
        let (width, height) = (60 + rng.below(200), 60 + rng.below(160));
        let stride = width + rng.below(9);
        let data = image(&mut rng, width, height, stride);
        let view = ImageView::new(&data, width, height, stride).unwrap();
        let search_px = [1.0, 2.5, 4.0, 4.0, 7.3, 10.0, 10.0, 14.0, 25.0, 40.0][rng.below(10)];
        // Up to five sides at any angle, with a few points each (some near or past the
        // image's edges, one not finite).
        let sides: Vec<SideGeometry> = (0..1 + rng.below(5))
            .map(|_| {
                let a = rng.next_f64() * std::f64::consts::TAU;
                SideGeometry::new([a.cos(), a.sin()], search_px)
            })
            .collect();
        let n = 1 + rng.below(60);
        let mut side_of: Vec<u16> = (0..n).map(|_| rng.below(sides.len()) as u16).collect();
        side_of.sort_unstable();
        // Most points well inside, some anywhere near the image.
        let place = |size: usize, rng: &mut SplitMix64| {
            if rng.below(6) == 0 { rng.next_f64() * (size as f64 + 20.0) - 10.0 } else { size as f64 * (0.25 + 0.5 * rng.next_f64()) }
        };
        let xs: Vec<f64> = (0..n).map(|_| place(width, &mut rng)).collect();
        let mut ys: Vec<f64> = (0..n).map(|_| place(height, &mut rng)).collect();
        if round % 17 == 3 {
            ys[0] = f64::NAN;
        }
        let reference: Vec<f32> = (0..n).map(|_| if rng.below(5) == 0 { -1.0 } else { rng.next_f64() as f32 * 255.0 }).collect();
        let contrast: Vec<f32> = (0..n).map(|_| (rng.next_f64() as f32 - 0.5) * 80.0).collect();
        let signs = match round % 4 {
            0 => SignRule::Fixed(0),
            1 => SignRule::Fixed(1),
            2 => SignRule::Fixed(-1),
            _ => SignRule::Learned { reference: &contrast, min_contrast: 12.0 },
        };
        let gain = if round % 3 == 0 { 0.0 } else { 0.6 };
        let appearance = Appearance { reference: &reference, gain, tolerance: 10.0 };
        let min_contrast = [1, 5, 12, 30, 255, 300][rng.below(6)];
        let settings = SearchSettings { search_px, signs, appearance, min_contrast };
        // The fit's slots, with room for the widest padding.
        // Both vector paths (AVX2 where the processor has it, and the baseline one).
        let stride_fit = n.div_ceil(8) * 8;
        let (mut h, mut pen) = (vec![7.0f32; 4 * stride_fit], vec![7.0f32; 4 * stride_fit]);
        let mut got = vec![PointEdges::default(); n];
        search.avx2 = round % 2 == 0 && has_avx2();
        let fit = FitSlots { h: &mut h, penalty: &mut pen, stride: stride_fit };
        search.search(&view, &sides, &side_of, &xs, &ys, &settings, &mut got, Some(fit));
        // The reference: each side's points through `search_side`.
        let mut want = vec![PointEdges::default(); n];
        let mut scratch = SideScratch::with_capacity(n);
        let mut first = 0;
        while first < n {
            let s = side_of[first];
            let end = first + side_of[first..].iter().take_while(|v| **v == s).count();
            let r = first..end;
            let side_signs = match signs {
                SignRule::Learned { min_contrast, .. } => SignRule::Learned { reference: &contrast[r.clone()], min_contrast },
                fixed => fixed,
            };
            let side_appearance = Appearance { reference: &reference[r.clone()], ..appearance };
            search_side(&view, &sides[s as usize], &xs[r.clone()], &ys[r.clone()], search_px, side_signs, side_appearance, min_contrast, &mut scratch, &mut want[r]);
            first = end;
        }
        for i in 0..n {
            let (g, w) = (&got[i], &want[i]);
            assert_eq!((g.outside, g.count), (w.outside, w.count), "round {round} point {i}");
            for (k, (a, b)) in g.as_slice().iter().zip(w.as_slice()).enumerate() {
                let bits = |c: &Candidate| (c.h_px.to_bits(), c.contrast.to_bits(), c.inside, c.outside, c.penalty_px.to_bits());
                assert_eq!(bits(a), bits(b), "round {round} point {i} candidate {k}");
            }
            for k in 0..MAX_CANDIDATES {
                let at = k * stride_fit + i;
                let expect = w.as_slice().get(k).map_or((0.0, f32::INFINITY), |c| (c.h_px, c.penalty_px));
                assert_eq!((h[at].to_bits(), pen[at].to_bits()), (expect.0.to_bits(), expect.1.to_bits()), "round {round} point {i} slot {k}");
            }
            checked.0 += 1;
            checked.1 += w.count as usize;
            checked.2 += w.outside as usize;
        }
    }
    // The random cases must exercise what they are for.
    assert!(checked.1 > checked.0 * 3 / 4 && checked.2 > 50 && checked.2 < checked.0 / 2, "{checked:?}");
}

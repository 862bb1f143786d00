//! Tests of the fit: exact motions, the models' behaviour, robustness, and the association
//! paths agreeing bit for bit.

use nalgebra::{Matrix2, Vector2};

use super::associate::{associate, associate_scalar};
use super::*;
use crate::tracker::search::{Candidate, PointEdges};

/// Points around a 100x60 rectangle centred on the origin, grouped by side.
fn rectangle() -> (Vec<f64>, Vec<f64>, Vec<FitSide>) {
    let (mut px, mut py, mut sides) = (vec![], vec![], vec![]);
    let corners: [(f64, f64); 4] = [(-50.0, -30.0), (50.0, -30.0), (50.0, 30.0), (-50.0, 30.0)];
    for j in 0..4 {
        let (a, b) = (corners[j], corners[(j + 1) % 4]);
        let d = (b.0 - a.0, b.1 - a.1);
        let len = f64::hypot(d.0, d.1);
        // (d.y, −d.x) points away from the centre for this corner order.
        let normal = Vector2::new(d.1 / len, -d.0 / len);
        let first = px.len();
        for k in 0..25 {
            let f = (k as f64 + 0.5) / 25.0;
            px.push(a.0 + f * d.0);
            py.push(a.1 + f * d.1);
        }
        let np = normal.x * px[first] + normal.y * py[first];
        sides.push(FitSide { first, count: 25, normal, np });
    }
    assert!(sides.iter().all(|s| s.np > 0.0), "normals must point outward");
    (px, py, sides)
}

/// A whole fit as the tracker runs it: candidates in, fit, per-point results out.
fn run_fit(pts: &FitPoints<'_>, edges: &[PointEdges], settings: &FitSettings, buf: &mut FitBuffers) -> FitResult {
    buf.load(pts, edges);
    let fit = fit_motion(pts, settings, buf);
    buf.finish();
    fit
}

fn settings(model: DeformationModel, loss: RobustLoss) -> FitSettings {
    FitSettings {
        model,
        loss,
        iterations: 10,
        sigma_min_px: 0.3,
        sigma_max_px: 3.0,
        deformation_ridge: 1e-6,
        perspective_ridge: 1e-6,
    }
}

fn normal_of(sides: &[FitSide], i: usize) -> Vector2<f64> {
    sides.iter().find(|s| (s.first..s.first + s.count).contains(&i)).unwrap().normal
}

/// One exact candidate per point for the motion `(t, A, g)`.
fn exact_edges(px: &[f64], py: &[f64], sides: &[FitSide], t: Vector2<f64>, a: Matrix2<f64>, g: Vector2<f64>) -> Vec<PointEdges> {
    (0..px.len())
        .map(|i| {
            let p = Vector2::new(px[i], py[i]);
            let d = t + a * p - p * g.dot(&p);
            let mut e = PointEdges::default();
            e.candidates[0] = Candidate { h_px: normal_of(sides, i).dot(&d) as f32, contrast: 50.0, ..Default::default() };
            e.count = 1;
            e
        })
        .collect()
}

#[test]
fn recovers_an_exact_motion_with_the_normal_only_and_projective_models() {
    let (px, py, sides) = rectangle();
    let t = Vector2::new(1.5, -2.0);
    let a = Matrix2::new(0.02, -0.03, 0.025, -0.01);
    let mut buf = FitBuffers::with_capacity(px.len());
    let edges = exact_edges(&px, &py, &sides, t, a, Vector2::zeros());
    let pts = FitPoints { px: &px, py: &py, sides: &sides };
    let fit = run_fit(&pts, &edges, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
    assert!((fit.t - t).norm() < 1e-3, "{:?}", fit.t);
    assert!((fit.a - a).norm() < 1e-4, "{:?}", fit.a);
    // Perspective too (first-order model: exact for exact first-order data).
    let g = Vector2::new(4e-4, -3e-4);
    let edges = exact_edges(&px, &py, &sides, t, a, g);
    let pts = FitPoints { px: &px, py: &py, sides: &sides };
    // On this symmetric rectangle translation and perspective are strongly coupled, so the
    // alternating stages need many iterations to converge (a tracker gets them over frames).
    let many = FitSettings { iterations: 400, ..settings(DeformationModel::Projective, RobustLoss::Tukey) };
    let fit = run_fit(&pts, &edges, &many, &mut buf);
    assert!((fit.t - t).norm() < 1e-3 && (fit.a - a).norm() < 1e-4, "{:?} {:?}", fit.t, fit.a);
    assert!((fit.g - g).norm() < 1e-6, "{:?}", fit.g);
}

#[test]
fn full_vector_model_is_exact_for_translation_and_sluggish_for_rotation() {
    let (px, py, sides) = rectangle();
    let s = settings(DeformationModel::FullVector, RobustLoss::LeastSquares);
    let mut buf = FitBuffers::with_capacity(px.len());
    let edges = exact_edges(&px, &py, &sides, Vector2::new(3.0, 1.0), Matrix2::zeros(), Vector2::zeros());
    let fit = run_fit(&FitPoints { px: &px, py: &py, sides: &sides }, &edges, &s, &mut buf);
    assert!((fit.t - Vector2::new(3.0, 1.0)).norm() < 1e-4);
    assert!(fit.a.norm() < 1e-6);
    // A scaling and a rotation are recovered only in part: A.3 takes each normal offset
    // for the whole displacement and so misses the part along the side (aperture problem).
    let scale = Matrix2::new(0.02, 0.0, 0.0, 0.02);
    let edges = exact_edges(&px, &py, &sides, Vector2::zeros(), scale, Vector2::zeros());
    let fit = run_fit(&FitPoints { px: &px, py: &py, sides: &sides }, &edges, &s, &mut buf);
    assert!(fit.a[(0, 0)] > 0.005 && fit.a[(0, 0)] < 0.019, "{:?}", fit.a);
    let rot = Matrix2::new(0.0, -0.02, 0.02, 0.0);
    let edges = exact_edges(&px, &py, &sides, Vector2::zeros(), rot, Vector2::zeros());
    let fit = run_fit(&FitPoints { px: &px, py: &py, sides: &sides }, &edges, &s, &mut buf);
    let got = fit.a[(1, 0)] - fit.a[(0, 1)];
    assert!(got > 0.0 && got < 0.04 * 0.9, "rotation part {got}");
}

#[test]
fn robust_fit_ignores_outliers_and_picks_the_consistent_candidate() {
    let (px, py, sides) = rectangle();
    let t = Vector2::new(2.0, 1.0);
    let edges: Vec<PointEdges> = (0..px.len())
        .map(|i| {
            let h = normal_of(&sides, i).dot(&t);
            let mut e = PointEdges::default();
            // One point in five sees only a wild outlier; every third point also sees a
            // stronger clutter edge 3-6 px away, on either side.
            let clutter = [3.0, -4.5, 6.0, -3.5, 5.0][i % 5];
            let cand = |h: f64, contrast: f32| Candidate { h_px: h as f32, contrast, ..Default::default() };
            if i % 5 == 2 {
                e.candidates[0] = cand(h + 7.0 * if i % 10 == 2 { 1.0 } else { -1.0 }, 80.0);
                e.count = 1;
            } else if i % 3 == 0 {
                e.candidates[0] = cand(h + clutter, 90.0);
                e.candidates[1] = cand(h, 50.0);
                e.count = 2;
            } else {
                e.candidates[0] = cand(h, 50.0);
                e.count = 1;
            }
            e
        })
        .collect();
    let pts = FitPoints { px: &px, py: &py, sides: &sides };
    let mut buf = FitBuffers::with_capacity(px.len());
    let fit = run_fit(&pts, &edges, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
    assert!((fit.t - t).norm() < 0.05 && fit.a.norm() < 1e-3, "{:?} {:?}", fit.t, fit.a);
    let wrong_choice = (0..px.len()).filter(|i| i % 5 != 2 && buf.chosen[*i] != (i % 3 == 0) as i8).count();
    assert_eq!(wrong_choice, 0);
    let outliers_weighted = (0..px.len()).filter(|i| i % 5 == 2 && buf.weight[*i] > 0.0).count();
    assert_eq!(outliers_weighted, 0);
    // Plain least squares is dragged off by the same data.
    let ls = run_fit(&pts, &edges, &settings(DeformationModel::NormalOnly, RobustLoss::LeastSquares), &mut buf);
    assert!((ls.t - t).norm() > 0.1 || ls.a.norm() > 1e-2, "{:?} {:?}", ls.t, ls.a);
}

#[test]
fn appearance_penalty_steers_the_choice_between_equally_near_candidates() {
    let mut e = PointEdges::default();
    e.candidates[0] = Candidate { h_px: -1.0, contrast: 60.0, penalty_px: 3.0, ..Default::default() };
    e.candidates[1] = Candidate { h_px: 1.2, contrast: 40.0, penalty_px: 0.0, ..Default::default() };
    e.count = 2;
    let side = FitSide { first: 0, count: 1, normal: Vector2::new(1.0, 0.0), np: 10.0 };
    let mut buf = FitBuffers::with_capacity(1);
    buf.resize(1);
    let mut edges = vec![e];
    let run = |edges: &[PointEdges], buf: &mut FitBuffers| {
        let pts = FitPoints { px: &[10.0], py: &[0.0], sides: &[side] };
        buf.load(&pts, edges);
        // The four-lane association and the final one agree.
        let found = associate::<true, false>(&Vec8::zeros(), buf);
        let (h, r) = (buf.h[0], buf.r[0]);
        associate_scalar(&Vec8::zeros(), buf);
        assert_eq!((h, r), (buf.h[0], buf.r[0]));
        found
    };
    assert_eq!(run(&edges, &mut buf), 1);
    assert_eq!((buf.chosen[0], buf.r[0]), (1, 1.2));
    edges[0].candidates[0].penalty_px = 0.0;
    run(&edges, &mut buf);
    assert_eq!((buf.chosen[0], buf.r[0]), (0, -1.0));
}

#[test]
fn every_association_path_gives_the_same_choices_residuals_and_histogram() {
    // Random points and candidates (some slots empty, some tied), a random motion: the
    // four-lane, the eight-lane (where the processor has it) and the one-at-a-time
    // association must agree bit for bit.
    let mut rng = crate::rng::SplitMix64::new(0x9e37_79b9_7f4a_7c15);
    let mut next = || rng.next_f64();
    let n = 61;
    let (px, py): (Vec<f64>, Vec<f64>) = (0..n).map(|_| (next() * 200.0 - 100.0, next() * 120.0 - 60.0)).unzip();
    let sides = [
        FitSide { first: 0, count: 30, normal: Vector2::new(0.6, 0.8), np: 12.0 },
        FitSide { first: 30, count: 31, normal: Vector2::new(-1.0, 0.0), np: -40.0 },
    ];
    let edges: Vec<PointEdges> = (0..n)
        .map(|_| {
            let mut e = PointEdges { count: (next() * 5.0) as u8, ..Default::default() };
            for c in &mut e.candidates[..e.count as usize] {
                c.h_px = ((next() * 20.0 - 10.0) * 4.0).round() as f32 / 4.0;
                c.penalty_px = if next() < 0.3 { (next() * 3.0) as f32 } else { 0.0 };
            }
            e
        })
        .collect();
    let theta = Vec8::from_fn(|k, _| [1.3, -0.7, 0.02, -0.01, 0.015, 0.03, 2e-4, -1e-4][k]);
    let pts = FitPoints { px: &px, py: &py, sides: &sides };
    let run = |avx2: bool| {
        let mut buf = FitBuffers::with_capacity(n);
        buf.avx2 = avx2 && buf.avx2;
        buf.load(&pts, &edges);
        buf.bins.clear(40);
        let found = associate::<true, false>(&theta, &mut buf);
        (found, buf.h.clone(), buf.r.clone(), buf.valid.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), buf)
    };
    let (found4, h4, r4, valid4, mut buf4) = run(false);
    let (found8, h8, r8, valid8, buf8) = run(true);
    assert_eq!((found4, &h4, &r4, &valid4), (found8, &h8, &r8, &valid8));
    let total = |b: &FitBuffers| -> Vec<usize> { b.bins.counts[..=40].iter().map(|c| c.iter().map(|v| *v as usize).sum()).collect() };
    assert_eq!(total(&buf4), total(&buf8));
    assert!(found4 > 30 && found4 < n, "the data must mix points with and without candidates");
    associate_scalar(&theta, &mut buf4);
    assert_eq!((&buf4.h, &buf4.r), (&h4, &r4));
    assert_eq!(buf4.valid.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), valid4);
    // The final association's choices too, on both vector paths.
    let scalar_chosen = buf4.chosen.clone();
    for avx2 in [false, true] {
        let mut buf = FitBuffers::with_capacity(n);
        buf.avx2 = avx2 && buf.avx2;
        buf.load(&pts, &edges);
        associate::<false, true>(&theta, &mut buf);
        let chosen: Vec<i8> = buf.chosen_lane[..n].iter().map(|k| *k as i8).collect();
        assert_eq!(chosen, scalar_chosen, "avx2 {avx2}");
        assert_eq!((&buf.h, &buf.r), (&h4, &r4));
    }
    assert!(scalar_chosen.iter().any(|k| *k > 0) && scalar_chosen.contains(&-1));
}

//! Coplanarity grouping: planes as left-to-right affine transfers, grown from seed groups,
//! and hypothesis selection.
//!
//! Under weak perspective the images of a plane in the two views are related by an affine
//! map `x' = A x + b` (6 parameters). A matched segment pair constrains it linearly: both
//! ends of the left segment, transferred, must lie on the right segment's line (2 equations;
//! this holds however the segment ends are truncated in either view). The epipolar
//! constraint adds `n_l + Aᵀ n_r = 0`, `n_r·b + n0 = 0` for any true plane; since it is only
//! weakly known it enters as down-weighted rows (at the left end points), which pins the
//! directions the line equations leave free — two junction-connected segments then suffice
//! for a seed.
//!
//! Chains of two friendships (three segments meeting at two junctions), then single
//! friendships, seed hypotheses; each grows by alternating support (candidates whose
//! transferred left segment lies on the right segment within `line_tol_px` and overlaps it)
//! and least-squares refits, within a region that starts around the seed and follows the
//! members (a plane is grown locally: a global model also collects far-away edges that run
//! along the epipolar lines and fit any plane). A seed whose candidates are all members of
//! one grown hypothesis is skipped (it would grow the same plane again), which keeps the work
//! near-linear in practice.
//! A hypothesis whose disparity is pinned only along one line (its junctions and the ends of
//! its segments that cross the epipolar lines are collinear: a face whose other edges run with
//! the epipolar lines) may tilt about that line; while growing it tries the candidates that
//! meet its members at junctions and takes the one that fits and explains most.
//! Hypothesis selection is greedy: the plane with the most newly explained segment length is
//! accepted, its matches fix their left segments' correspondences (a segment on a crease may
//! still belong to several planes, with the same match), and the remaining hypotheses are
//! re-scored lazily. A member with no junction partner inside its hypothesis (no friend) may
//! be an accidental coplanarity: it counts half, and its claim does not exclude another
//! plane's junction-connected match of the same segment. Last, hypotheses that explain nothing new are accepted when no single
//! accepted plane holds most of their segments (a face all of whose edges are shared).

use std::collections::BinaryHeap;

use super::geom::{self, P2};
use super::matching::{Candidates, EpipolarFrame, Friendship};
use super::relations::SegmentGrid;
use super::segments::Segment;
pub use super::transfer::{coverage, line_residuals, stretches_overlap, Transfer, TransferFit};

/// Tolerances of plane grouping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneConfig {
    /// Largest distance of a transferred left end from the right segment's line, pixels.
    /// The true transfer of a face puts its edges' segments within ~0.7 px (sub-pixel edges,
    /// and a face's perspective bending of the affine transfer at ~1.6 m); much more lets a
    /// transfer straddle two faces where their parallax differs little (the visp-cube pair).
    pub line_tol_px: f64,
    /// Weight of the (weak) epipolar rows relative to the line rows.
    pub epipolar_weight: f64,
    /// Radius around a seed's junction within which it first grows (then around its
    /// members' bounding box, by half this), pixels.
    pub seed_radius_px: f64,
    /// Fewest member segments of an accepted plane.
    pub min_members: usize,
    /// Least newly explained segment length of an accepted plane, pixels. (15 px, three of the
    /// shortest segments, finds twice the randomised cells' small faces but let a hypothesised
    /// zero-width facet into clutter3 seed 14's plan: BENCHMARKS, s7-random, reverted.)
    pub min_support_px: f64,
    /// Most seeds tried (best first).
    pub max_seeds: usize,
    /// Segments within this angle of the epipolar lines (in either view) support a plane only
    /// through a junction point it transfers correctly, degrees.
    pub weak_angle_deg: f64,
    /// Largest singular value ratio of `A` accepted (a plane seen at grazing angle in one view
    /// has a very anisotropic transfer; beyond this it is a bad fit).
    pub max_anisotropy: f64,
    /// A hypothesis's disparity is pinned when the points where it is known (junctions, ends
    /// of segments that cross the epipolar lines) spread at least this far across their main
    /// direction, pixels (and a tenth of their extent along it). Otherwise the transfer may
    /// tilt freely about their line, and the growing hypothesis tries to take in a
    /// junction-connected candidate that pins it (see `extend_by_friend`).
    pub min_anchor_spread_px: f64,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        Self { line_tol_px: 0.9, epipolar_weight: 0.1, seed_radius_px: 120.0, min_members: 3, min_support_px: 40.0, max_seeds: 3000, weak_angle_deg: 20.0, max_anisotropy: 4.0, min_anchor_spread_px: 3.0 }
    }
}

/// An accepted plane.
#[derive(Debug, Clone, PartialEq)]
pub struct Plane {
    pub transfer: Transfer,
    /// Member candidate indices (one per left segment, or several covering disjoint
    /// stretches of it).
    pub members: Vec<u32>,
    /// Sum over members of the matched (covered) length, pixels.
    pub support_px: f64,
    /// RMS line residual of the members, pixels.
    pub rms_px: f64,
}

/// The inputs of plane grouping.
pub struct PlaneInput<'a> {
    pub left: &'a [Segment],
    pub right: &'a [Segment],
    pub cands: &'a Candidates,
    pub friends: &'a [Friendship],
    pub epipolar: &'a EpipolarFrame,
    /// The epipolar tolerance of the matcher: a plane's transfer must keep the points it is
    /// fitted to within this of their epipolar lines (an affine map through a chain of three
    /// lines always exists; only a real plane's also honours the epipolar geometry).
    pub epipolar_tol_px: f64,
    pub width: usize,
    pub height: usize,
}

/// Per-candidate context of plane grouping.
struct Ctx {
    /// Friendships of each candidate.
    adj: Vec<Vec<u32>>,
    /// Whether a candidate runs near the epipolar lines in either view.
    weak: Vec<bool>,
}

struct Hypothesis {
    transfer: Transfer,
    /// Candidate indices, one per left segment.
    members: Vec<u32>,
    /// The candidates of the region it was grown in.
    pool: Vec<u32>,
}

/// Grows hypotheses from the friends and selects planes (see the module docs).
pub fn find_planes(inp: &PlaneInput, cfg: &PlaneConfig) -> Vec<Plane> {
    let weight = |c: u32| {
        let c = &inp.cands.list[c as usize];
        inp.left[c.left as usize].length().min(inp.right[c.right as usize].length())
    };
    let n = inp.cands.list.len();
    // Friendships of each candidate.
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (k, f) in inp.friends.iter().enumerate() {
        adj[f.a as usize].push(k as u32);
        adj[f.b as usize].push(k as u32);
    }
    let sin_weak = cfg.weak_angle_deg.to_radians().sin();
    let (el, er) = (inp.epipolar.left_dir(), inp.epipolar.right_dir());
    let weak = inp
        .cands
        .list
        .iter()
        .map(|c| geom::cross(inp.left[c.left as usize].dir(), el).abs() < sin_weak || geom::cross(inp.right[c.right as usize].dir(), er).abs() < sin_weak)
        .collect();
    let ctx = Ctx { adj, weak };
    let adj = &ctx.adj;
    // Seeds: chains of two friendships (three segments, two junctions: the transfer is fully
    // determined even when the middle segment runs along the epipolar lines), then single
    // friendships; heaviest first within each kind.
    let mut seeds: Vec<(Vec<u32>, Vec<u32>, f64)> = Vec::new();
    for b in 0..n {
        for (x, &f1) in adj[b].iter().enumerate() {
            for &f2 in &adj[b][x + 1..] {
                let (p, q) = (&inp.friends[f1 as usize], &inp.friends[f2 as usize]);
                let a = if p.a as usize == b { p.b } else { p.a };
                let c = if q.a as usize == b { q.b } else { q.a };
                let lefts = [inp.cands.list[a as usize].left, inp.cands.list[b].left, inp.cands.list[c as usize].left];
                if a == c || lefts[0] == lefts[2] || geom::dist(p.left_point, q.left_point) < 3.0 {
                    continue;
                }
                seeds.push((vec![a, b as u32, c], vec![f1, f2], weight(a) + weight(b as u32) + weight(c)));
            }
        }
    }
    seeds.sort_by(|x, y| y.2.total_cmp(&x.2));
    let mut pairs: Vec<(Vec<u32>, Vec<u32>, f64)> = inp.friends.iter().enumerate().map(|(k, f)| (vec![f.a, f.b], vec![k as u32], weight(f.a) + weight(f.b))).collect();
    pairs.sort_by(|x, y| y.2.total_cmp(&x.2));
    seeds.extend(pairs);
    seeds.truncate(cfg.max_seeds);

    let mut grid = SegmentGrid::build(inp.left, inp.width, inp.height, 32.0);
    let mut near = Vec::new();
    let mut local = Vec::new();
    let mut scratch = vec![false; n];
    // The grown hypotheses each candidate belongs to: a seed whose candidates already all
    // share one would only grow that hypothesis again.
    let mut member_of: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut hyps: Vec<Hypothesis> = Vec::new();
    for (cs, fs, _) in seeds {
        if member_of[cs[0] as usize].iter().any(|h| cs[1..].iter().all(|&c| member_of[c as usize].contains(h))) {
            continue;
        }
        let p = inp.friends[fs[0] as usize].left_point;
        let mut fit = TransferFit::new(p);
        for &c in &cs {
            let c = &inp.cands.list[c as usize];
            let (l, r) = (&inp.left[c.left as usize], &inp.right[c.right as usize]);
            fit.add_line(l, r, 1.0);
            for q in [l.p0, l.p1] {
                fit.add_epipolar(inp.epipolar, q, cfg.epipolar_weight);
            }
        }
        for &f in &fs {
            let f = &inp.friends[f as usize];
            fit.add_point(f.left_point, f.right_point, 1.0);
        }
        let Some(mut t) = fit.solve() else { continue };
        if !plausible(&t, cfg) || !cs.iter().all(|&c| supports(&t, inp, c, cfg)) || !epipolar_consistent(&t, inp, &cs) {
            continue;
        }
        // Growth: support within a region that starts around the seed and then follows the
        // members (planes are grown locally: a global plane model would also collect the
        // accidental coplanarities of far-away edges).
        let r = cfg.seed_radius_px;
        let (mut lo, mut hi) = ([p[0] - r, p[1] - r], [p[0] + r, p[1] + r]);
        let mut members = Vec::new();
        for round in 0..4 {
            grid.query(lo, hi, &mut near);
            local.clear();
            for &l in &near {
                local.extend(inp.cands.of_left(l).map(|c| c as u32));
            }
            members = support(&t, inp, &ctx, &local, cfg);
            if members.len() < 2 || round == 3 {
                break;
            }
            if !determined(inp, &ctx, &members, cfg)
                && let Some((t2, m2)) = extend_by_friend(inp, &ctx, &members, &local, &mut scratch, cfg, p)
            {
                t = t2;
                members = m2;
            }
            match refit(inp, &members, adj, &mut scratch, cfg, p) {
                Some(t2) if plausible(&t2, cfg) && epipolar_consistent(&t2, inp, &members) => t = t2,
                _ => break,
            }
            if round >= 1 {
                // Follow the members: their bounding box plus half the radius.
                let (mut a, mut b) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for &m in &members {
                    let l = &inp.left[inp.cands.list[m as usize].left as usize];
                    for q in [l.p0, l.p1] {
                        a = [a[0].min(q[0]), a[1].min(q[1])];
                        b = [b[0].max(q[0]), b[1].max(q[1])];
                    }
                }
                lo = [a[0] - 0.5 * r, a[1] - 0.5 * r];
                hi = [b[0] + 0.5 * r, b[1] + 0.5 * r];
            }
        }
        if members.len() < cfg.min_members {
            continue;
        }
        for &m in &members {
            member_of[m as usize].push(hyps.len() as u32);
        }
        hyps.push(Hypothesis { transfer: t, members, pool: local.clone() });
    }
    select(inp, hyps, &ctx, cfg)
}

/// Whether the disparity of a plane with these members is pinned: the points where it is
/// known (junctions between members, ends of members that cross the epipolar lines) spread
/// in two directions (see [`PlaneConfig::min_anchor_spread_px`]).
fn determined(inp: &PlaneInput, ctx: &Ctx, members: &[u32], cfg: &PlaneConfig) -> bool {
    let mut pts: Vec<P2> = Vec::new();
    for &m in members {
        if !ctx.weak[m as usize] {
            let l = &inp.left[inp.cands.list[m as usize].left as usize];
            pts.extend([l.p0, l.p1]);
        }
        for &f in &ctx.adj[m as usize] {
            let f = &inp.friends[f as usize];
            if f.a == m && members.contains(&f.b) {
                pts.push(f.left_point);
            }
        }
    }
    if pts.len() < 3 {
        return false;
    }
    let n = pts.len() as f64;
    let c = pts.iter().fold([0.0; 2], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n]);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in &pts {
        let (x, y) = (p[0] - c[0], p[1] - c[1]);
        sxx += x * x / n;
        sxy += x * y / n;
        syy += y * y / n;
    }
    let tr = 0.5 * (sxx + syy);
    let d = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
    let (major, minor) = ((tr + d).sqrt(), (tr - d).max(0.0).sqrt());
    minor >= cfg.min_anchor_spread_px.max(0.1 * major)
}

/// An under-determined hypothesis (see [`determined`]) tries each candidate that meets one of
/// its members at a junction seen in both views: refitted with it (and that junction point),
/// does it still fit every member, and how much does it then explain? The best such
/// extension is returned, preferring one that pins the disparity.
fn extend_by_friend(inp: &PlaneInput, ctx: &Ctx, members: &[u32], pool: &[u32], scratch: &mut [bool], cfg: &PlaneConfig, origin: P2) -> Option<(Transfer, Vec<u32>)> {
    let mut tried: Vec<u32> = Vec::new();
    for &m in members {
        for &f in &ctx.adj[m as usize] {
            let f = &inp.friends[f as usize];
            let o = if f.a == m { f.b } else { f.a };
            let left = inp.cands.list[o as usize].left;
            if !tried.contains(&o) && !members.iter().any(|&x| inp.cands.list[x as usize].left == left) {
                tried.push(o);
            }
        }
    }
    tried.truncate(16);
    let mut best: Option<((bool, usize), Transfer, Vec<u32>)> = None;
    let mut trial: Vec<u32> = Vec::with_capacity(members.len() + 1);
    for c in tried {
        trial.clear();
        trial.extend_from_slice(members);
        trial.push(c);
        let Some(t) = refit(inp, &trial, &ctx.adj, scratch, cfg, origin) else { continue };
        if !plausible(&t, cfg) || !epipolar_consistent(&t, inp, &trial) || !trial.iter().all(|&x| supports(&t, inp, x, cfg)) {
            continue;
        }
        let grown = support(&t, inp, ctx, pool, cfg);
        if !grown.contains(&c) {
            continue;
        }
        let key = (determined(inp, ctx, &grown, cfg), grown.len());
        if best.as_ref().is_none_or(|b| key > b.0) {
            best = Some((key, t, grown));
        }
    }
    best.map(|(_, t, m)| (t, m))
}

fn plausible(t: &Transfer, cfg: &PlaneConfig) -> bool {
    let (s1, s2) = t.singular_values();
    t.det() > 0.0 && s2 > 1e-6 && s1 / s2 <= cfg.max_anisotropy && s1 < 4.0 && s2 > 0.25
}

/// Whether `t` keeps the end points of the left segments of `members` within the epipolar
/// tolerance of their epipolar lines.
fn epipolar_consistent(t: &Transfer, inp: &PlaneInput, members: &[u32]) -> bool {
    members.iter().all(|&m| {
        let l = &inp.left[inp.cands.list[m as usize].left as usize];
        [l.p0, l.p1].iter().all(|&x| inp.epipolar.residual(x, t.apply(x)).abs() <= inp.epipolar_tol_px)
    })
}

fn supports(t: &Transfer, inp: &PlaneInput, c: u32, cfg: &PlaneConfig) -> bool {
    let c = &inp.cands.list[c as usize];
    let (res, overlap) = line_residuals(t, &inp.left[c.left as usize], &inp.right[c.right as usize]);
    overlap && res[0].abs() <= cfg.line_tol_px && res[1].abs() <= cfg.line_tol_px
}

/// Candidates among `pool` supporting `t`. A left segment normally has one; it has several
/// only when they cover disjoint stretches of it (its right image is broken, or it is two
/// edges that line up in the left view only).
///
/// A segment running within `weak_angle_deg` of the epipolar lines fits nearly any plane
/// through the right line (parallax moves it along itself), so it supports `t` only through a
/// junction with a friend whose point correspondence `t` also transfers correctly.
fn support(t: &Transfer, inp: &PlaneInput, ctx: &Ctx, pool: &[u32], cfg: &PlaneConfig) -> Vec<u32> {
    let mut out: Vec<(u32, u32, f64)> = Vec::new();
    for &ci in pool {
        let c = &inp.cands.list[ci as usize];
        let (res, overlap) = line_residuals(t, &inp.left[c.left as usize], &inp.right[c.right as usize]);
        let worst = res[0].abs().max(res[1].abs());
        if !overlap || worst > cfg.line_tol_px {
            continue;
        }
        if ctx.weak[ci as usize] {
            let anchored = ctx.adj[ci as usize].iter().any(|&f| {
                let f = &inp.friends[f as usize];
                geom::dist(t.apply(f.left_point), f.right_point) <= 2.0 * cfg.line_tol_px
            });
            if !anchored {
                continue;
            }
        }
        out.push((c.left, ci, worst));
    }
    out.sort_by(|x, y| x.0.cmp(&y.0).then(x.2.total_cmp(&y.2)));
    let mut kept: Vec<u32> = Vec::with_capacity(out.len());
    let mut group: Vec<(f64, f64)> = Vec::new();
    let mut current = u32::MAX;
    for (l, ci, _) in out {
        if l != current {
            current = l;
            group.clear();
        }
        let c = &inp.cands.list[ci as usize];
        let cov = coverage(t, &inp.left[l as usize], &inp.right[c.right as usize]);
        if group.iter().all(|g| !stretches_overlap(*g, cov)) {
            group.push(cov);
            kept.push(ci);
        }
    }
    kept
}

/// Least-squares transfer of `members`: their line equations, the junction points of
/// friendships between them (point correspondences, which also fix the transfer along
/// segments that run with the epipolar lines), and weak epipolar rows.
fn refit(inp: &PlaneInput, members: &[u32], adj: &[Vec<u32>], scratch: &mut [bool], cfg: &PlaneConfig, origin: P2) -> Option<Transfer> {
    let mut fit = TransferFit::new(origin);
    for &m in members {
        scratch[m as usize] = true;
    }
    for &m in members {
        let c = &inp.cands.list[m as usize];
        let (l, r) = (&inp.left[c.left as usize], &inp.right[c.right as usize]);
        fit.add_line(l, r, 1.0);
        for p in [l.p0, l.p1] {
            fit.add_epipolar(inp.epipolar, p, cfg.epipolar_weight);
        }
        for &f in &adj[m as usize] {
            let f = &inp.friends[f as usize];
            // Each friendship once, from its first candidate.
            if f.a == m && scratch[f.b as usize] {
                fit.add_point(f.left_point, f.right_point, 1.0);
            }
        }
    }
    for &m in members {
        scratch[m as usize] = false;
    }
    fit.solve()
}

/// A left segment's stretch claimed by an accepted plane for one right segment.
#[derive(Debug, Clone, Copy)]
struct Claim {
    right: u32,
    stretch: (f64, f64),
    /// Claimed by a member that meets a fellow member at a junction seen in both views (a
    /// friend). A member without one may be an accidental coplanarity (an edge far away that
    /// happens to fit the transfer, typical of edges running with the epipolar lines or of
    /// the vertical edges of another object), so its claim does not exclude another plane's
    /// anchored match of the same stretch.
    hard: bool,
}

/// Greedy hypothesis selection with lazy re-scoring.
fn select(inp: &PlaneInput, hyps: Vec<Hypothesis>, ctx: &Ctx, cfg: &PlaneConfig) -> Vec<Plane> {
    let adj = &ctx.adj;
    let mut scratch = vec![false; inp.cands.list.len()];
    let mut claims: Vec<Vec<Claim>> = vec![Vec::new(); inp.left.len()];
    // Per hypothesis and member: whether it has a friend among the hypothesis's members.
    let anchored: Vec<Vec<bool>> = hyps
        .iter()
        .map(|h| {
            h.members
                .iter()
                .map(|&m| {
                    adj[m as usize].iter().any(|&f| {
                        let f = &inp.friends[f as usize];
                        let other = if f.a == m { f.b } else { f.a };
                        h.members.contains(&other)
                    })
                })
                .collect()
        })
        .collect();
    // Per member: (left, right, stretch covered, matched length).
    let info = |h: &Hypothesis, m: u32| {
        let c = &inp.cands.list[m as usize];
        let cov = coverage(&h.transfer, &inp.left[c.left as usize], &inp.right[c.right as usize]);
        (c.left as usize, c.right, cov, cov.1 - cov.0)
    };
    // 0: new, 1: already claimed with this right segment, 2: conflicts with a claim (an
    // anchored member conflicts only with hard claims).
    let status = |claims: &[Vec<Claim>], l: usize, r: u32, cov: (f64, f64), anchored: bool| -> u8 {
        if claims[l].iter().any(|c| c.right == r) {
            1
        } else if claims[l].iter().any(|c| (c.hard || !anchored) && stretches_overlap(c.stretch, cov)) {
            2
        } else {
            0
        }
    };
    // Newly explained length (unanchored members count half), new and acceptable members.
    let score = |hi: usize, claims: &[Vec<Claim>]| -> (f64, usize, usize) {
        let h = &hyps[hi];
        let (mut s, mut new, mut ok) = (0.0, 0, 0);
        for (k, &m) in h.members.iter().enumerate() {
            let (l, r, cov, w) = info(h, m);
            match status(claims, l, r, cov, anchored[hi][k]) {
                0 => {
                    s += if anchored[hi][k] { w } else { 0.5 * w };
                    new += 1;
                    ok += 1;
                }
                1 => ok += 1,
                _ => {}
            }
        }
        (s, new, ok)
    };
    #[derive(PartialEq)]
    struct Item(f64, usize);
    impl Eq for Item {}
    impl PartialOrd for Item {
        fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
            Some(self.cmp(o))
        }
    }
    impl Ord for Item {
        fn cmp(&self, o: &Self) -> std::cmp::Ordering {
            self.0.total_cmp(&o.0).then(o.1.cmp(&self.1))
        }
    }
    let mut heap: BinaryHeap<Item> = (0..hyps.len()).map(|i| Item(score(i, &claims).0, i)).collect();
    let mut accepted: Vec<usize> = Vec::new();
    let mut deferred: Vec<usize> = Vec::new();
    let accept = |i: usize, claims: &mut Vec<Vec<Claim>>, accepted: &mut Vec<usize>| {
        for (k, &m) in hyps[i].members.iter().enumerate() {
            let (l, r, cov, _) = info(&hyps[i], m);
            if status(claims, l, r, cov, anchored[i][k]) == 0 {
                claims[l].push(Claim { right: r, stretch: cov, hard: anchored[i][k] });
            }
        }
        accepted.push(i);
    };
    while let Some(Item(s, i)) = heap.pop() {
        let (now, new, ok) = score(i, &claims);
        if now < s - 1e-9 {
            // Stale: re-queue with the current score.
            if now > 0.0 {
                heap.push(Item(now, i));
            } else {
                deferred.push(i);
            }
            continue;
        }
        if new == 0 || now < cfg.min_support_px || ok < cfg.min_members {
            deferred.push(i);
            continue;
        }
        accept(i, &mut claims, &mut accepted);
    }
    // A hypothesis whose segments all belong to other planes already is still a plane of its
    // own when no single accepted plane holds most of them: a face whose every edge is shared
    // (two creases, and silhouette edges that also lie on the table plane).
    let mut rest: Vec<(f64, usize)> = deferred
        .into_iter()
        .map(|i| {
            let total: f64 = hyps[i].members.iter().enumerate().map(|(k, &m)| (k, info(&hyps[i], m))).filter(|(k, x)| status(&claims, x.0, x.1, x.2, anchored[i][*k]) != 2).map(|(_, x)| x.3).sum();
            (total, i)
        })
        .collect();
    rest.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (_, i) in rest {
        let ok: Vec<u32> = hyps[i].members.iter().enumerate().filter(|&(k, &m)| {
            let (l, r, cov, _) = info(&hyps[i], m);
            status(&claims, l, r, cov, anchored[i][k]) != 2
        }).map(|(_, &m)| m).collect();
        let total: f64 = ok.iter().map(|&m| info(&hyps[i], m).3).sum();
        if ok.len() < cfg.min_members || total < cfg.min_support_px {
            continue;
        }
        let most_in_one = accepted.iter().map(|&a| ok.iter().filter(|m| hyps[a].members.contains(m)).count()).max().unwrap_or(0);
        if (most_in_one as f64) < 0.6 * ok.len() as f64 {
            accept(i, &mut claims, &mut accepted);
        }
    }
    // Final membership: every accepted plane takes the claimed supporters of its region,
    // then refits.
    let claimed = |ci: &u32| {
        let c = &inp.cands.list[*ci as usize];
        claims[c.left as usize].iter().any(|k| k.right == c.right)
    };
    let mut planes = Vec::new();
    for i in accepted {
        let all: Vec<u32> = hyps[i].pool.iter().copied().filter(claimed).collect();
        let mut t = hyps[i].transfer;
        let mut members = support(&t, inp, ctx, &all, cfg);
        if let Some(origin) = members.first().map(|&m| inp.left[inp.cands.list[m as usize].left as usize].midpoint())
            && let Some(t2) = refit(inp, &members, adj, &mut scratch, cfg, origin).filter(|t2| plausible(t2, cfg)) {
                t = t2;
                members = support(&t, inp, ctx, &all, cfg);
            }
        if members.len() < cfg.min_members {
            continue;
        }
        let mut sq = 0.0;
        let mut support_px = 0.0;
        for &m in &members {
            let c = &inp.cands.list[m as usize];
            let (l, r) = (&inp.left[c.left as usize], &inp.right[c.right as usize]);
            let (res, _) = line_residuals(&t, l, r);
            sq += res[0] * res[0] + res[1] * res[1];
            let cov = coverage(&t, l, r);
            support_px += cov.1 - cov.0;
        }
        let rms_px = (sq / (2 * members.len()) as f64).sqrt();
        planes.push(Plane { transfer: t, members, support_px, rms_px });
    }
    merge_duplicates(inp, planes, cfg)
}

/// Merges planes that are the same plane grown twice (from seeds far apart): their transfers
/// agree, within the line tolerance, at the end points of both planes' segments.
fn merge_duplicates(inp: &PlaneInput, mut planes: Vec<Plane>, cfg: &PlaneConfig) -> Vec<Plane> {
    let ends = |p: &Plane| -> Vec<P2> {
        p.members.iter().flat_map(|&m| {
            let l = &inp.left[inp.cands.list[m as usize].left as usize];
            [l.p0, l.p1]
        }).collect()
    };
    let mut i = 0;
    while i < planes.len() {
        let mut j = i + 1;
        while j < planes.len() {
            let pts: Vec<P2> = ends(&planes[i]).into_iter().chain(ends(&planes[j])).collect();
            let (ti, tj) = (planes[i].transfer, planes[j].transfer);
            let same = pts.iter().all(|&x| geom::dist(ti.apply(x), tj.apply(x)) <= cfg.line_tol_px);
            if same {
                let pj = planes.remove(j);
                let pi = &mut planes[i];
                for m in pj.members {
                    if !pi.members.contains(&m) {
                        pi.members.push(m);
                    }
                }
                pi.support_px += pj.support_px;
                pi.rms_px = pi.rms_px.max(pj.rms_px);
            } else {
                j += 1;
            }
        }
        i += 1;
    }
    planes
}

//! The small solves: translation (A.1), shape (A.2, with perspective), both together, and
//! A.3's per-row fit; written out rather than left to nalgebra's general routines.

use nalgebra::{Matrix2, Vector2};

use super::buffers::FitBuffers;
use super::types::{FitPoints, Mat8, Vec8};

/// A.1: `M_tt t = b_t − M_ts s` with the shape `s` of `theta` held.
///
/// The small solves here are written out rather than left to nalgebra's general routines
/// (views, copies and loops sized at run time cost more than the arithmetic); the order of
/// operations is nalgebra's, so the results are the same.
pub(super) fn solve_translation(m: &Mat8, b: &Vec8, theta: &Vec8, wsum: f64) -> Vector2<f64> {
    // rhs = b_t − M_ts s, the product column by column.
    let rhs: [f64; 2] = std::array::from_fn(|i| {
        let mut p = m[(i, 2)] * theta[2];
        for j in 3..8 {
            p += m[(i, j)] * theta[j];
        }
        b[i] - p
    });
    // A tiny ridge keeps the motion along a lone straight side (unobservable) at zero.
    let (m11, m12, m21, m22) = (m[(0, 0)] + 1e-6 * wsum, m[(0, 1)], m[(1, 0)], m[(1, 1)] + 1e-6 * wsum);
    let det = m11 * m22 - m21 * m12;
    if det == 0.0 {
        return Vector2::new(theta[0], theta[1]);
    }
    let inv = [[m22 / det, -m12 / det], [-m21 / det, m11 / det]];
    Vector2::new(inv[0][0] * rhs[0] + inv[0][1] * rhs[1], inv[1][0] * rhs[0] + inv[1][1] * rhs[1])
}

/// Solves `a x = rhs` for a symmetric positive definite `a` (only its lower triangle is read)
/// by Cholesky factorisation in place; `rhs` becomes `x`. False, with `rhs` left part-way,
/// when `a` is not positive definite.
// Two indices into one matrix read more plainly than iterator chains here.
#[allow(clippy::needless_range_loop)]
fn cholesky_solve<const K: usize>(a: &mut [[f64; K]; K], rhs: &mut [f64; K]) -> bool {
    for j in 0..K {
        for k in 0..j {
            let f = a[j][k];
            for i in j..K {
                a[i][j] += -f * a[i][k];
            }
        }
        let d = a[j][j];
        if d <= 0.0 || d.is_nan() {
            return false;
        }
        let d = d.sqrt();
        a[j][j] = d;
        for i in j + 1..K {
            a[i][j] /= d;
        }
    }
    // L y = rhs, then Lᵀ x = y.
    for i in 0..K {
        let y = rhs[i] / a[i][i];
        rhs[i] = y;
        for r in i + 1..K {
            rhs[r] += -y * a[r][i];
        }
    }
    for i in (0..K).rev() {
        let mut dot = 0.0;
        for r in i + 1..K {
            dot += a[r][i] * rhs[r];
        }
        rhs[i] = (rhs[i] - dot) / a[i][i];
    }
    true
}

/// Translation with A.2 (`K = 6`) or with A.2 and perspective (`K = 8`) solved together:
/// the fixed point the two stages converge to, reached in one step once the association has
/// settled; same ridges and prior as the staged solve.
pub(super) fn solve_joint<const K: usize>(m: &Mat8, b: &Vec8, theta: &mut Vec8, wsum: f64, ridge_a: f64, ridge_g: f64) {
    let mut mk: [[f64; K]; K] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
    let mut rhs: [f64; K] = std::array::from_fn(|i| b[i]);
    for (k, row) in mk.iter_mut().enumerate() {
        row[k] += match k {
            0 | 1 => 1e-6 * wsum,
            2..=5 => ridge_a,
            _ => ridge_g,
        };
    }
    if cholesky_solve(&mut mk, &mut rhs) {
        for (k, v) in rhs.iter().enumerate() {
            theta[k] = *v;
        }
    }
}

/// A.2 (`K = 4`: `A`) or A.2 with perspective (`K = 6`: `A, g`) given the translation in
/// `theta`, ridge-regularised towards no change of shape.
pub(super) fn solve_shape<const K: usize>(m: &Mat8, b: &Vec8, theta: &mut Vec8, ridge_a: f64, ridge_g: f64) {
    let mut mss: [[f64; K]; K] = std::array::from_fn(|i| std::array::from_fn(|j| m[(2 + i, 2 + j)]));
    // rhs = b_s − M_st t, the product column by column.
    let mut rhs: [f64; K] = std::array::from_fn(|i| b[2 + i] - (m[(2 + i, 0)] * theta[0] + m[(2 + i, 1)] * theta[1]));
    for (k, row) in mss.iter_mut().enumerate() {
        row[k] += if k < 4 { ridge_a } else { ridge_g };
    }
    if cholesky_solve(&mut mss, &mut rhs) {
        for (k, v) in rhs.iter().enumerate() {
            theta[2 + k] = *v;
        }
    }
}

/// A.3: `(h_i − n_i·t) n_i = A p_i`: each row of `A` is a 2-parameter fit with the normal
/// matrix `Σ w p pᵀ`.
pub(super) fn solve_full_vector(
    points: &FitPoints<'_>,
    buf: &FitBuffers,
    mut pp: Matrix2<f64>,
    h_rhs: Matrix2<f64>,
    t: &Vector2<f64>,
    ridge: f64,
) -> Matrix2<f64> {
    // The n·t part of the right-hand side, per side: (n·t) n (Σ w p)ᵀ.
    let mut t_rhs = Matrix2::zeros();
    for side in points.sides {
        let nt = side.normal.dot(t);
        let mut sp = Vector2::zeros();
        for i in side.first..side.first + side.count {
            sp += Vector2::new(points.px[i], points.py[i]) * buf.w[i] as f64;
        }
        t_rhs += side.normal * sp.transpose() * nt;
    }
    pp[(0, 0)] += ridge;
    pp[(1, 1)] += ridge;
    match pp.try_inverse() {
        // Row k of A solves pp a_k = Σ w (h − n·t) n_k p, i.e. A = R pp⁻¹ (pp symmetric).
        Some(inv) => (h_rhs - t_rhs) * inv,
        None => Matrix2::zeros(),
    }
}

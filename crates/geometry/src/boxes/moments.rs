//! Moments of the surface point `V(v₀, Y)` of a Gaussian box `Y ~ N(ȳ, Σ)` (Appendix A,
//! eq. A.4–A.6).
//!
//! Appendix A writes `v = Φ(y)ᵀ w` with the homogeneous `w = [v₀; 1]` and needs `E[Φ(Y)]ᵀ w` and
//! `E[Φ(Y)ᵀ w wᵀ Φ(Y)]` (A.6). `Φ` is linear in `(c, l, w)` but trigonometric in `r_y`, so the
//! expectation is taken exactly over the linear part and by Gauss–Hermite quadrature over
//! `r_y`: conditioned on `r_y = r`, `z = (c₁, c₂, l, w)` is Gaussian with mean
//! `m(r) = μ_z + Σ_zr/σ_r²·(r − μ_r)` and covariance `C = Σ_zz − Σ_zr Σ_rz/σ_r²`, and
//! `V | r = A(r)·z` with `A(r) = [I₂, R(r)·diag(v₀)]`. Hence
//!
//! ```text
//! E[V]   = Σ_q ω_q A(r_q) m(r_q),
//! E[VVᵀ] = Σ_q ω_q A(r_q) (C + m(r_q) m(r_q)ᵀ) A(r_q)ᵀ,
//! ```
//!
//! with the `Q`-node probabilists' Gauss–Hermite rule `(r_q, ω_q)` (exact for polynomials in
//! `r` of degree `2Q − 1`; `Q = 16` leaves errors far below 1e−12 for `σ_r < 0.5` rad).

// Loops over the 2 and 4 coordinates index several arrays at once; ranges read clearest.
#![allow(clippy::needless_range_loop)]

use std::sync::OnceLock;

use super::{BEV_PARAMS, Box2, Cov5};

/// Gauss–Hermite nodes used over the heading.
pub const HERMITE_NODES: usize = 16;

/// Probabilists' Gauss–Hermite nodes and weights (weights sum to 1) by Golub–Welsch.
fn hermite() -> &'static ([f64; HERMITE_NODES], [f64; HERMITE_NODES]) {
    static RULE: OnceLock<([f64; HERMITE_NODES], [f64; HERMITE_NODES])> = OnceLock::new();
    RULE.get_or_init(|| {
        let n = HERMITE_NODES;
        // Jacobi matrix of He_n: zero diagonal, off-diagonal √k.
        let j = nalgebra::DMatrix::<f64>::from_fn(n, n, |a, b| {
            if a + 1 == b || b + 1 == a {
                ((a.max(b)) as f64).sqrt()
            } else {
                0.0
            }
        });
        let eig = j.symmetric_eigen();
        let mut idx: Vec<usize> = (0..n).collect();
        idx.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let mut x = [0.0; HERMITE_NODES];
        let mut w = [0.0; HERMITE_NODES];
        for (k, &i) in idx.iter().enumerate() {
            x[k] = eig.eigenvalues[i];
            w[k] = eig.eigenvectors[(0, i)].powi(2);
        }
        (x, w)
    })
}

/// Precomputed conditional moments of a Gaussian box, evaluated at any `v₀`.
#[derive(Debug, Clone)]
pub struct BoxMoments {
    /// Per node: weight, cos r, sin r, conditional mean `m(r)` of `(c₁, c₂, l, w)`.
    nodes: Vec<(f64, f64, f64, [f64; 4])>,
    /// `C + m mᵀ` per node.
    second: Vec<[[f64; 4]; 4]>,
}

impl BoxMoments {
    /// Moments of `Y ~ N(mean, cov)` (the covariance must be valid, see
    /// [`super::check_covariance`]).
    pub fn new(mean: &Box2, cov: &Cov5) -> Self {
        let mu = mean.params();
        let srr = cov[4][4];
        let mut nodes = Vec::new();
        let mut second = Vec::new();
        let mut c = [[0.0; 4]; 4];
        let mut k = [0.0; 4];
        if srr > 1e-18 {
            for i in 0..4 {
                k[i] = cov[i][4] / srr;
            }
        }
        for i in 0..4 {
            for j in 0..4 {
                c[i][j] = cov[i][j] - k[i] * cov[4][j];
            }
        }
        let single = [(0.0, 1.0)];
        let rule: Vec<(f64, f64)> = if srr > 1e-18 {
            let (x, w) = hermite();
            x.iter().zip(w.iter()).map(|(a, b)| (*a, *b)).collect()
        } else {
            single.to_vec()
        };
        let sr = srr.max(0.0).sqrt();
        for (x, w) in rule {
            let dr = sr * x;
            let r = mu[4] + dr;
            let mut m = [0.0; 4];
            for i in 0..4 {
                m[i] = mu[i] + k[i] * dr;
            }
            let mut s2 = [[0.0; 4]; 4];
            for i in 0..4 {
                for j in 0..4 {
                    s2[i][j] = c[i][j] + m[i] * m[j];
                }
            }
            let (s, co) = r.sin_cos();
            nodes.push((w, co, s, m));
            second.push(s2);
        }
        Self { nodes, second }
    }

    /// `(E[V], Cov[V])` of the surface point `V(v₀, Y)` (eq. A.6).
    pub fn point(&self, v0: [f64; 2]) -> ([f64; 2], [[f64; 2]; 2]) {
        let mut mean = [0.0; 2];
        let mut sec = [[0.0; 2]; 2];
        for ((w, co, s, m), s2) in self.nodes.iter().zip(&self.second) {
            // A = [[1, 0, co·v0x, −s·v0y], [0, 1, s·v0x, co·v0y]].
            let a = [
                [1.0, 0.0, co * v0[0], -s * v0[1]],
                [0.0, 1.0, s * v0[0], co * v0[1]],
            ];
            for (p, ap) in a.iter().enumerate() {
                mean[p] += w * (0..4).map(|i| ap[i] * m[i]).sum::<f64>();
                for (q, aq) in a.iter().enumerate() {
                    let mut acc = 0.0;
                    for i in 0..4 {
                        let mut t = 0.0;
                        for j in 0..4 {
                            t += s2[i][j] * aq[j];
                        }
                        acc += ap[i] * t;
                    }
                    sec[p][q] += w * acc;
                }
            }
        }
        let cov = [
            [sec[0][0] - mean[0] * mean[0], sec[0][1] - mean[0] * mean[1]],
            [sec[1][0] - mean[1] * mean[0], sec[1][1] - mean[1] * mean[1]],
        ];
        (mean, cov)
    }

    /// Total variance `tr Cov[V(v₀, Y)]` (the quantity of Fig. 8.9).
    pub fn total_variance(&self, v0: [f64; 2]) -> f64 {
        let (_, c) = self.point(v0);
        c[0][0] + c[1][1]
    }
}

/// First-order (linearised) covariance `J Σ Jᵀ` of `V(v₀, Y)`: a cross-check of
/// [`BoxMoments::point`] for small heading variance.
pub fn linearised_point_cov(mean: &Box2, cov: &Cov5, v0: [f64; 2]) -> [[f64; 2]; 2] {
    let j = mean.point_jacobian(v0);
    let mut out = [[0.0; 2]; 2];
    for p in 0..2 {
        for q in 0..2 {
            let mut acc = 0.0;
            for a in 0..BEV_PARAMS {
                for b in 0..BEV_PARAMS {
                    acc += j[p][a] * cov[a][b] * j[q][b];
                }
            }
            out[p][q] = acc;
        }
    }
    out
}

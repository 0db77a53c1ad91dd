//! The full-rank non-rigid M-step (000_3b1454b2b2194811.txt eq. (3.18); Myronenko & Song 2010,
//! Fig. 4) by preconditioned conjugate gradients instead of a dense factorisation per
//! iteration.
//!
//! The update `(d(P1) G + λσ² I) W = PX − d(P1) Y` is solved in its symmetric positive definite
//! form: with `S = d(P1)^{½}`,
//!
//! ```text
//! A V = b,   A = S G S + λσ² I,   b = S⁻¹ (PX − d(P1) Y),   W = S V,
//! ```
//!
//! which stays SPD (eigenvalues ≥ λσ²) however many `P1_m` vanish (rows with `P1_m = 0` have
//! `PX_m = 0` as well, so `b_m = 0` there and `W_m = 0`, as in the direct solve). Each CG step
//! is one product `G (S p)` for the `D` columns together: by the fast Gauss transform of the
//! `fgt` module (`G ≈ Bᵀ K B`, every entry within ~`D·10⁻¹¹`, symmetric positive
//! semi-definite, `G` never formed) when its estimated cost is below the `M² D` multiply–adds
//! of the dense product — e.g. β = 2 over a 10 × 10 square at M = 2000 — else with `G` formed
//! once per registration and streamed per product (the only choice with `EStep::Dense`).
//!
//! Preconditioner: the top eigenpairs `G ≈ Q Λ Qᵀ` (Nyström from the landmark columns of the
//! stored `G`, see the `lowrank` module), applied by the Woodbury identity,
//! `(S Q Λ Qᵀ S + λσ² I)⁻¹ r = (λσ²)⁻¹ [r − S Q (λσ² Λ⁻¹ + Qᵀ S² Q)⁻¹ Qᵀ S r]`,
//! with only the eigenpairs that matter at this σ² (`λ_k · max P1 > 10⁻³ λσ²`). The Gaussian
//! kernel's spectrum decays fast, so the preconditioned system is close to the identity and
//! CG needs a handful of products. It is warm-started from the previous iteration's `W`
//! (`V₀ = S⁻¹ W_prev`), so the starting residual needs `G S V₀ = G W_prev`, which the previous
//! solve already has: `G W` for the moved points is updated along with `V` and costs no extra
//! product (rows with a tiny `S_m` start at 0 instead; then one product). It stops at a
//! relative residual `‖b − A V‖ ≤ 10⁻¹⁰ ‖b‖` per column; if it has not by [`CG_MAX`] steps
//! (or lost positive curvature to rounding first), the M-step falls back to the dense Cholesky
//! factorisation, so the result is never worse than the direct solve.

use nalgebra::{DMatrix, DVector};

use super::fgt::KernelTransform;
use super::lowrank;
use crate::{DetectError, Result};

/// Relative residual at which CG stops.
const CG_TOL: f64 = 1e-10;

/// CG steps before the dense fallback.
const CG_MAX: usize = 100;

/// Eigenpairs computed for the preconditioner (at most; fewer for small `M`).
const PRECOND_RANK: usize = 160;

/// Rows whose `S_m` is below this fraction of the largest are not warm-started from the
/// previous `W` (`V_m = W_m / S_m` would be huge).
const WARM_MIN_SCALE: f64 = 1e-3;

/// How `G` is applied.
enum Product<const D: usize> {
    /// The stored `M × M` matrix (one streaming pass per product).
    Dense(DMatrix<f64>),
    /// The fast Gauss transform of the `fgt` module (`G` not formed).
    Fast(KernelTransform<D>),
}

/// The full-rank kernel with its preconditioner and the warm start.
pub(crate) struct FullSystem<const D: usize> {
    /// The source points `Y` and the kernel width.
    y: Vec<[f64; D]>,
    beta: f64,
    product: Product<D>,
    /// `G` formed for the dense fallback when the product is the transform.
    dense: Option<DMatrix<f64>>,
    /// Top eigenvectors of `G` (M × K) and eigenvalues (decreasing).
    q: DMatrix<f64>,
    lambda: DVector<f64>,
    /// `W` of the last solve and `G W` (as applied by the product).
    w: Option<DMatrix<f64>>,
    gw: Option<DMatrix<f64>>,
    /// CG steps taken over all solves.
    pub cg_steps: usize,
    /// Products with `G` over all solves (CG steps plus starting residuals).
    pub products: usize,
    /// Solves that fell back to the dense factorisation.
    pub fallbacks: usize,
}

impl<const D: usize> FullSystem<D> {
    /// The kernel of the source points `y`: applied by the fast Gauss transform when
    /// `exact` is false and its estimated cost per product is below the `M² D` multiply–adds
    /// of the dense product, else formed densely; and the preconditioner eigenpairs.
    pub fn new(y: &[[f64; D]], beta: f64, exact: bool) -> Self {
        let m = y.len();
        let k = PRECOND_RANK.min(m / 4).max(1);
        let fast = if exact {
            None
        } else {
            KernelTransform::new(y, beta, m.saturating_mul(m).saturating_mul(D))
        };
        let (product, (q, lambda)) = match fast {
            Some(t) => (Product::Fast(t), lowrank::low_rank_kernel(y, beta, k, 0)),
            None => {
                let g = lowrank::kernel_matrix(y, beta);
                let eig = lowrank::low_rank_of_dense(y, beta, &g, k, 0);
                (Product::Dense(g), eig)
            }
        };
        Self {
            y: y.to_vec(),
            beta,
            product,
            dense: None,
            q,
            lambda,
            w: None,
            gw: None,
            cg_steps: 0,
            products: 0,
            fallbacks: 0,
        }
    }

    /// Whether `G` is applied by the fast Gauss transform.
    #[cfg(test)]
    pub fn is_fast(&self) -> bool {
        matches!(self.product, Product::Fast(_))
    }

    /// `G w`.
    pub fn times(&self, w: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.product {
            Product::Dense(g) => lowrank::sym_times(g, w),
            Product::Fast(t) => t.apply(&self.y, w),
        }
    }

    /// `G W` of the last [`FullSystem::solve`] (`None` before the first).
    pub fn last_gw(&self) -> Option<&DMatrix<f64>> {
        self.gw.as_ref()
    }

    /// Solves the M-step for `W` (see the module docs); `f = PX − d(P1) Y`.
    pub fn solve(&mut self, p1: &[f64], f: &DMatrix<f64>, lam_s2: f64) -> Result<DMatrix<f64>> {
        let (m, dc) = f.shape();
        let s: Vec<f64> = p1.iter().map(|p| p.max(0.0).sqrt()).collect();
        let b = DMatrix::from_fn(
            m,
            dc,
            |i, d| {
                if s[i] > 0.0 { f[(i, d)] / s[i] } else { 0.0 }
            },
        );
        let scale_rows = |v: &DMatrix<f64>| {
            let mut o = v.clone();
            for (mut row, si) in o.row_iter_mut().zip(&s) {
                row *= *si;
            }
            o
        };
        // Preconditioner on the eigenpairs that matter at this λσ².
        let pmax = p1.iter().fold(0.0f64, |a, &p| a.max(p));
        let kk = self
            .lambda
            .iter()
            .take_while(|&&l| l * pmax > 1e-3 * lam_s2)
            .count();
        let qk = self.q.columns(0, kk).into_owned();
        // Qᵀ S² Q + λσ² Λ⁻¹ (lower triangle products only).
        let mut h = lowrank::weighted_gram(&qk, p1);
        for i in 0..kk {
            h[(i, i)] += lam_s2 / self.lambda[i];
        }
        let sq = scale_rows(&qk);
        let chol = h.cholesky();
        let precond = |r: &DMatrix<f64>| -> DMatrix<f64> {
            match &chol {
                Some(c) if kk > 0 => {
                    let z = c.solve(&lowrank::mul(&sq, true, r));
                    (r - lowrank::mul(&sq, false, &z)) / lam_s2
                }
                _ => r / lam_s2,
            }
        };
        // Warm start from the previous W: V₀ = S⁻¹ W_prev, whose G S V₀ = G W_prev is known
        // (no product) when every row is well scaled; else rows with a small S start at 0 and
        // G S V₀ is one product.
        let smax = s.iter().fold(0.0f64, |a, &v| a.max(v));
        let (mut x, mut gsx) = match (&self.w, &self.gw) {
            (Some(wp), Some(gwp)) if wp.shape() == (m, dc) && wp.iter().all(|a| a.is_finite()) => {
                let mut all = true;
                let x = DMatrix::from_fn(m, dc, |i, d| {
                    if s[i] > WARM_MIN_SCALE * smax {
                        wp[(i, d)] / s[i]
                    } else {
                        all &= wp[(i, d)] == 0.0;
                        0.0
                    }
                });
                if all {
                    (x, gwp.clone())
                } else {
                    self.products += 1;
                    let gsx = self.times(&scale_rows(&x));
                    (x, gsx)
                }
            }
            _ => (DMatrix::zeros(m, dc), DMatrix::zeros(m, dc)),
        };
        // r = b − (S G S x + λσ² x).
        let mut r = &b - (scale_rows(&gsx) + &x * lam_s2);
        let bnorm: Vec<f64> = (0..dc).map(|d| b.column(d).norm()).collect();
        let done = |r: &DMatrix<f64>, d: usize| r.column(d).norm() <= CG_TOL * bnorm[d];
        let mut active: Vec<bool> = (0..dc).map(|d| !done(&r, d)).collect();
        let mut z = precond(&r);
        let mut p = z.clone();
        let mut rz: Vec<f64> = (0..dc).map(|d| r.column(d).dot(&z.column(d))).collect();
        let mut steps = 0;
        while active.iter().any(|&a| a) && steps < CG_MAX {
            // A p = S G S p + λσ² p; also G S p.
            let gsp = self.times(&scale_rows(&p));
            let ap = scale_rows(&gsp) + &p * lam_s2;
            steps += 1;
            for d in 0..dc {
                if !active[d] {
                    continue;
                }
                let pap = p.column(d).dot(&ap.column(d));
                if !(pap > 0.0) {
                    // Lost positive curvature to rounding: stop this column.
                    active[d] = false;
                    continue;
                }
                let alpha = rz[d] / pap;
                x.column_mut(d).axpy(alpha, &p.column(d), 1.0);
                gsx.column_mut(d).axpy(alpha, &gsp.column(d), 1.0);
                r.column_mut(d).axpy(-alpha, &ap.column(d), 1.0);
                if done(&r, d) {
                    active[d] = false;
                }
            }
            if !active.iter().any(|&a| a) {
                break;
            }
            z = precond(&r);
            for d in 0..dc {
                if !active[d] {
                    continue;
                }
                let rz_new = r.column(d).dot(&z.column(d));
                let beta = rz_new / rz[d];
                rz[d] = rz_new;
                let zc = z.column(d).into_owned();
                p.column_mut(d).axpy(1.0, &zc, beta);
            }
        }
        self.cg_steps += steps;
        self.products += steps;
        // Converged (every column met the tolerance on its residual) or the dense fallback.
        let ok = !active.iter().any(|&a| a)
            && (0..dc).all(|d| r.column(d).norm() <= CG_TOL * bnorm[d])
            && x.iter().all(|a| a.is_finite());
        let (w, gw) = if ok {
            (scale_rows(&x), gsx)
        } else {
            self.fallbacks += 1;
            let g = match &self.product {
                Product::Dense(g) => g,
                Product::Fast(_) => self
                    .dense
                    .get_or_insert_with(|| lowrank::kernel_matrix(&self.y, self.beta)),
            };
            let w = super::solve_full(g, p1, f, lam_s2)?;
            let gw = lowrank::sym_times(g, &w);
            (w, gw)
        };
        if w.iter().all(|a| a.is_finite()) {
            self.w = Some(w.clone());
            self.gw = Some(gw);
            Ok(w)
        } else {
            self.w = None;
            self.gw = None;
            Err(DetectError::Degenerate {
                reason: format!("the non-rigid CPD update is not finite at λσ² = {lam_s2:e}"),
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// The CG update equals the dense Cholesky solve of the same system (exact `G`), for
    /// weights with zeros and near-zeros, over four orders of λσ², warm-started across
    /// changing weights: with the stored `G` and with `G` applied by the fast Gauss transform.
    #[test]
    fn cg_matches_direct_solve() {
        for (m, beta, exact, tol) in [(600, 1.0, true, 1e-7), (1500, 2.0, false, 1e-6)] {
            let mut rng = Pcg64::seed_from_u64(11);
            let y: Vec<[f64; 2]> = (0..m)
                .map(|_| [rng.random::<f64>() * 6.0, rng.random::<f64>() * 4.0])
                .collect();
            let g = lowrank::kernel_matrix(&y, beta);
            let mut sys = FullSystem::new(&y, beta, exact);
            assert_eq!(sys.is_fast(), !exact);
            for (it, lam_s2) in [30.0, 1.0, 1e-2, 1e-4, 3e-5].into_iter().enumerate() {
                let p1: Vec<f64> = (0..m)
                    .map(|i| match i % 17 {
                        0 => 0.0,
                        1 => 1e-13,
                        _ => rng.random::<f64>() * 2.0,
                    })
                    .collect();
                let f = DMatrix::from_fn(m, 2, |i, _| {
                    if p1[i] > 0.0 {
                        p1[i] * (rng.random::<f64>() - 0.5)
                    } else {
                        0.0
                    }
                });
                let w = sys.solve(&p1, &f, lam_s2).unwrap();
                let direct = crate::cpd::solve_full(&g, &p1, &f, lam_s2).unwrap();
                let err = (&w - &direct).amax() / direct.amax();
                assert!(
                    err < tol,
                    "M {m}, λσ² {lam_s2:e}: relative difference {err:e}"
                );
                // G W returned with the solve is G times the solution.
                let gw = &g * &w;
                let gerr = (sys.last_gw().unwrap() - &gw).amax() / gw.amax();
                assert!(gerr < tol, "M {m}, λσ² {lam_s2:e}: G W off by {gerr:e}");
                assert_eq!(sys.fallbacks, 0, "iteration {it}");
            }
            assert!(sys.cg_steps < 5 * 40, "{} CG steps", sys.cg_steps);
        }
    }
}

//! Numeric differentiation of residuals on the tangent space (central differences), for
//! prototyping residuals without analytic Jacobians.

use nalgebra::DMatrix;

use super::manifold::Manifold;
use super::problem::Residual;
use crate::{EstimateError, Result};

/// Wraps a residual function `f(params, residual)` into a [`Residual`] whose Jacobians are
/// central differences along the tangent of each block: column i of ∂r/∂δ_k is
/// (r(x_k ⊕ h eᵢ) − r(x_k ⊕ −h eᵢ)) / 2h, with h = `step`·max(1, |xᵢ|) on Euclidean
/// components and translations, `step` on rotations (truncation error O(h²)).
pub struct NumericDiff<F> {
    dim: usize,
    manifolds: Vec<Manifold>,
    f: F,
    step: f64,
}

impl<F> NumericDiff<F>
where
    F: Fn(&[&[f64]], &mut [f64]) -> Result<()> + Send + Sync,
{
    /// A residual of dimension `dim` over blocks on `manifolds` (in `evaluate` order), with
    /// the default relative step ∛ε ≈ 6e-6.
    pub fn new(dim: usize, manifolds: Vec<Manifold>, f: F) -> Self {
        Self {
            dim,
            manifolds,
            f,
            step: f64::EPSILON.cbrt(),
        }
    }

    /// Sets the relative step (finite and positive; invalid values keep the default).
    pub fn with_step(mut self, step: f64) -> Self {
        if step.is_finite() && step > 0.0 {
            self.step = step;
        }
        self
    }

    fn step_for(&self, m: Manifold, x: &[f64], i: usize) -> f64 {
        let scale = match m {
            Manifold::Euclidean(_) => x.get(i).map_or(1.0, |v| v.abs().max(1.0)),
            Manifold::Se3 if i >= 3 => {
                let t = x
                    .get(4..7)
                    .map_or(0.0, |t| t.iter().map(|v| v * v).sum::<f64>().sqrt());
                t.max(1.0)
            }
            _ => 1.0,
        };
        self.step * scale
    }
}

impl<F> Residual for NumericDiff<F>
where
    F: Fn(&[&[f64]], &mut [f64]) -> Result<()> + Send + Sync,
{
    fn dim(&self) -> usize {
        self.dim
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        if params.len() != self.manifolds.len() {
            return Err(EstimateError::DimensionMismatch {
                what: "NumericDiff parameter blocks".into(),
                expected: vec![self.manifolds.len()],
                got: vec![params.len()],
            });
        }
        (self.f)(params, residual)?;
        let Some(jac) = jacobians else { return Ok(()) };
        let mut owned: Vec<Vec<f64>> = params.iter().map(|p| p.to_vec()).collect();
        let mut rp = vec![0.0; self.dim];
        let mut rm = vec![0.0; self.dim];
        for (k, &m) in self.manifolds.iter().enumerate() {
            let x0 = params[k].to_vec();
            let nt = m.tangent_dim();
            let mut d = vec![0.0; nt];
            for i in 0..nt {
                let h = self.step_for(m, &x0, i);
                for (sign, out) in [(1.0, &mut rp), (-1.0, &mut rm)] {
                    d[i] = sign * h;
                    m.plus(&x0, &d, &mut owned[k]);
                    let views: Vec<&[f64]> = owned.iter().map(|v| v.as_slice()).collect();
                    (self.f)(&views, out)?;
                }
                d[i] = 0.0;
                if let Some(j) = jac.get_mut(k) {
                    for r in 0..self.dim.min(j.nrows()) {
                        if i < j.ncols() {
                            j[(r, i)] = (rp[r] - rm[r]) / (2.0 * h);
                        }
                    }
                }
            }
            owned[k].copy_from_slice(&x0);
        }
        Ok(())
    }
}

//! Built-in models: the fast path of the filters (no callbacks).

use nalgebra::{DMatrix, DVector, DVectorView};

use super::kernels;
use super::linalg;
use super::model::UkfModel;
use crate::{EstimateError, Result};

/// The whole-matrix overrides of [`UkfModel`] for models whose state and measurement are
/// plain vectors: `out[:, i] = sigmas[:, i] − mean` for both residuals and
/// `out[:, i] = x + offsets[:, i]` for the sigma points.
macro_rules! vector_space_methods {
    () => {
        fn x_residuals(
            &self,
            sigmas: &DMatrix<f64>,
            mean: &DVector<f64>,
            out: &mut DMatrix<f64>,
        ) -> Result<()> {
            vector_residuals(sigmas, mean, out)
        }

        fn z_residuals(
            &self,
            sigmas: &DMatrix<f64>,
            mean: &DVector<f64>,
            out: &mut DMatrix<f64>,
        ) -> Result<()> {
            vector_residuals(sigmas, mean, out)
        }

        fn sigma_points(
            &self,
            x: &DVector<f64>,
            offsets: &DMatrix<f64>,
            out: &mut DMatrix<f64>,
        ) -> Result<()> {
            kernels::add_columns(
                x.len(),
                x.as_slice(),
                offsets.as_slice(),
                out.as_mut_slice(),
            );
            Ok(())
        }
    };
}

/// `out[:, i] = sigmas[:, i] − mean`.
fn vector_residuals(
    sigmas: &DMatrix<f64>,
    mean: &DVector<f64>,
    out: &mut DMatrix<f64>,
) -> Result<()> {
    kernels::sub_columns(
        mean.len(),
        sigmas.as_slice(),
        mean.as_slice(),
        out.as_mut_slice(),
    );
    Ok(())
}

/// The linear model `x' = F x + B u`, `z = H x` (noise additive). With it the UKF reproduces
/// the Kalman filter exactly (the unscented transform is exact for linear maps), which is the
/// closed-form truth the filters are tested against. `dt` is ignored: F is fixed.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearModel {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    /// Hᵀ, for the sigma-point products (contiguous rows of H).
    ht: DMatrix<f64>,
    b: Option<DMatrix<f64>>,
}

impl LinearModel {
    /// `F` is `n × n`, `H` is `m × n`, `B` (optional) is `n × k`; all finite.
    pub fn new(f: DMatrix<f64>, h: DMatrix<f64>, b: Option<DMatrix<f64>>) -> Result<Self> {
        let n = f.nrows();
        if n == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "F",
                value: 0.0,
                reason: "the state dimension must be at least 1",
            });
        }
        linalg::check_shape(&f, n, n, "transition matrix F")?;
        linalg::check_finite_input(f.as_slice(), "transition matrix F")?;
        if h.ncols() != n || h.nrows() == 0 {
            return Err(EstimateError::DimensionMismatch {
                what: "measurement matrix H".to_string(),
                expected: vec![h.nrows().max(1), n],
                got: vec![h.nrows(), h.ncols()],
            });
        }
        linalg::check_finite_input(h.as_slice(), "measurement matrix H")?;
        if let Some(b) = &b {
            if b.nrows() != n || b.ncols() == 0 {
                return Err(EstimateError::DimensionMismatch {
                    what: "input matrix B".to_string(),
                    expected: vec![n, b.ncols().max(1)],
                    got: vec![b.nrows(), b.ncols()],
                });
            }
            linalg::check_finite_input(b.as_slice(), "input matrix B")?;
        }
        let ht = h.transpose();
        Ok(Self { f, h, ht, b })
    }

    /// F.
    pub fn f(&self) -> &DMatrix<f64> {
        &self.f
    }

    /// H.
    pub fn h(&self) -> &DMatrix<f64> {
        &self.h
    }

    /// B, if any.
    pub fn b(&self) -> Option<&DMatrix<f64>> {
        self.b.as_ref()
    }
}

impl UkfModel for LinearModel {
    fn dim_x(&self) -> usize {
        self.f.nrows()
    }

    fn dim_z(&self) -> usize {
        self.h.nrows()
    }

    fn dim_u(&self) -> usize {
        self.b.as_ref().map_or(0, |b| b.ncols())
    }

    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        _dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out.gemv(1.0, &self.f, &x, 0.0);
        if let (Some(b), Some(u)) = (&self.b, u) {
            out.gemv(1.0, b, u, 1.0);
        }
        Ok(())
    }

    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        out.gemv(1.0, &self.h, &x, 0.0);
        Ok(())
    }

    fn fx_sigmas(
        &self,
        sigmas: &DMatrix<f64>,
        _dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let n = self.f.nrows();
        let ns = sigmas.ncols();
        kernels::product(
            n,
            n,
            ns,
            self.f.as_slice(),
            sigmas.as_slice(),
            out.as_mut_slice(),
        );
        if let (Some(b), Some(u)) = (&self.b, u) {
            let bu = b * u;
            for c in out.as_mut_slice().chunks_exact_mut(n) {
                for (ci, bi) in c.iter_mut().zip(bu.as_slice()) {
                    *ci += bi;
                }
            }
        }
        Ok(())
    }

    fn hx_sigmas(&self, sigmas: &DMatrix<f64>, out: &mut DMatrix<f64>) -> Result<()> {
        let (m, n) = self.h.shape();
        kernels::gemm_tn(
            m,
            n,
            sigmas.ncols(),
            self.ht.as_slice(),
            sigmas.as_slice(),
            out.as_mut_slice(),
        );
        Ok(())
    }

    vector_space_methods!();
}

/// The constant-velocity model in `dim` dimensions: state `[p; v]` (positions first, `2·dim`
/// entries), `p' = p + v·dt + a·dt²/2`, `v' = v + a·dt` with the optional input `u = a` (an
/// acceleration, `dim` entries), and the positions measured, `z = p`. Unlike
/// [`LinearModel`] it uses the `dt` of each prediction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConstantVelocityModel {
    dim: usize,
}

impl ConstantVelocityModel {
    /// A model for `dim ≥ 1` spatial dimensions.
    pub fn new(dim: usize) -> Result<Self> {
        if dim == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "dim",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        Ok(Self { dim })
    }

    /// The number of spatial dimensions.
    pub fn dim(&self) -> usize {
        self.dim
    }
}

impl UkfModel for ConstantVelocityModel {
    fn dim_x(&self) -> usize {
        2 * self.dim
    }

    fn dim_z(&self) -> usize {
        self.dim
    }

    fn dim_u(&self) -> usize {
        self.dim
    }

    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        let d = self.dim;
        for i in 0..d {
            let (p, v) = (x[i], x[d + i]);
            let a = u.map_or(0.0, |u| u[i]);
            out[i] = p + v * dt + 0.5 * a * dt * dt;
            out[d + i] = v + a * dt;
        }
        Ok(())
    }

    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
        for i in 0..self.dim {
            out[i] = x[i];
        }
        Ok(())
    }

    fn fx_sigmas(
        &self,
        sigmas: &DMatrix<f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let d = self.dim;
        for (o, x) in out
            .as_mut_slice()
            .chunks_exact_mut(2 * d)
            .zip(sigmas.as_slice().chunks_exact(2 * d))
        {
            for i in 0..d {
                let a = u.map_or(0.0, |u| u[i]);
                o[i] = x[i] + x[d + i] * dt + 0.5 * a * dt * dt;
                o[d + i] = x[d + i] + a * dt;
            }
        }
        Ok(())
    }

    fn hx_sigmas(&self, sigmas: &DMatrix<f64>, out: &mut DMatrix<f64>) -> Result<()> {
        let d = self.dim;
        for (o, x) in out
            .as_mut_slice()
            .chunks_exact_mut(d)
            .zip(sigmas.as_slice().chunks_exact(2 * d))
        {
            o.copy_from_slice(&x[..d]);
        }
        Ok(())
    }

    vector_space_methods!();
}

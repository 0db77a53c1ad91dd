//! The process/measurement model interface of the UKF.

use nalgebra::{DMatrix, DVector, DVectorView};

use super::kernels;
use crate::Result;

/// A state-space model for the unscented Kalman filter: the process function `f`, the
/// measurement function `h`, and the hooks that make the filter work on states and
/// measurements that are not plain vectors.
///
/// This is the structure of seed 000_3b1454b2b2194811.txt eq. (5.1),
/// `X(k+1) = f(X(k), u(k)) + w` and `y(k+1) = h(X(k+1)) + v`, where the seed's input `u` is
/// the SLAM increment and its state mixes a translation, Euler angles and joint zero offsets.
///
/// # Manifold states
///
/// The state is stored as a vector of `dim_x()` numbers whose covariance is `dim_x × dim_x`.
/// Parts that live on a manifold (an angle, a rotation stored as its rotation vector) are
/// handled by overriding the hooks, after Solà's "micro Lie theory" (the ⊕/⊖ of seed
/// eq. (5.11)):
/// * [`x_add`](Self::x_add) is `x ⊕ δ` (used for the sigma points and for `x + K y`),
/// * [`x_residual`](Self::x_residual) is `a ⊖ b` (deviations of sigma points from the mean),
/// * [`x_mean`](Self::x_mean) is the weighted mean on the manifold (e.g. an iterative Karcher
///   mean of the sigma rotations),
/// * [`z_mean`](Self::z_mean) / [`z_residual`](Self::z_residual) do the same for measurements
///   (e.g. a bearing angle that wraps at ±π).
///
/// The defaults are the vector-space operations (weighted sum, `a − b`, `x + δ`), which is what
/// filterpy does when no `x_mean_fn`/`residual_x`/`state_add` is given.
///
/// # Noise
///
/// With additive noise (the default form of the filters) only [`fx`](Self::fx) and
/// [`hx`](Self::hx) are called and Q, R are added to the transformed covariances. With the
/// augmented form the state is augmented by process noise `w` (`dim_w()` entries, covariance
/// Q) for the prediction and by measurement noise `v` (`dim_v()`, covariance R) for the
/// update, and [`fx_noise`](Self::fx_noise)/[`hx_noise`](Self::hx_noise) receive the noise
/// values of each sigma point. Their defaults inject the noise additively (`f(x) ⊕ w`,
/// `h(x) + v`), so an additive model gives the same filter in both forms up to the spread of
/// the sigma points.
///
/// All functions write into `out` (already sized `dim_x()` or `dim_z()`) and return an error
/// only for failures of the model itself (e.g. a Python callback that raised); the filters
/// check every output for NaN/inf.
pub trait UkfModel {
    /// Dimension of the state (and of its tangent space).
    fn dim_x(&self) -> usize;

    /// Dimension of the measurement.
    fn dim_z(&self) -> usize;

    /// Length of the control input `u` accepted by [`fx`](Self::fx) (0: no input).
    fn dim_u(&self) -> usize {
        0
    }

    /// The process function: `out = f(x, dt, u)`. `u` is `None` when no input is given for
    /// this step.
    fn fx(
        &self,
        x: DVectorView<'_, f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()>;

    /// The measurement function: `out = h(x)`.
    fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()>;

    /// Dimension of the process noise `w` in the augmented form (default `dim_x()`).
    fn dim_w(&self) -> usize {
        self.dim_x()
    }

    /// Dimension of the measurement noise `v` in the augmented form (default `dim_z()`).
    fn dim_v(&self) -> usize {
        self.dim_z()
    }

    /// `f` applied to every column of `sigmas` (additive form), into the columns of `out`
    /// (`dim_x × N`). The default calls [`fx`](Self::fx) per column; models override it to
    /// transform all sigma points at once (the built-in linear model does one matrix product).
    fn fx_sigmas(
        &self,
        sigmas: &DMatrix<f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let len = out.nrows();
        columnwise(len, sigmas.ncols(), out, |i, tmp| {
            self.fx(sigmas.column(i), dt, u, tmp)
        })
    }

    /// `h` applied to every column of `sigmas`, into the columns of `out` (`dim_z × N`).
    /// The default calls [`hx`](Self::hx) per column.
    fn hx_sigmas(&self, sigmas: &DMatrix<f64>, out: &mut DMatrix<f64>) -> Result<()> {
        let len = out.nrows();
        columnwise(len, sigmas.ncols(), out, |i, tmp| {
            self.hx(sigmas.column(i), tmp)
        })
    }

    /// `sigmas[:, i] ⊖ mean` for every column, into `out`. The default calls
    /// [`x_residual`](Self::x_residual) per column.
    fn x_residuals(
        &self,
        sigmas: &DMatrix<f64>,
        mean: &DVector<f64>,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let len = out.nrows();
        columnwise(len, sigmas.ncols(), out, |i, tmp| {
            self.x_residual(sigmas.column(i), mean.column(0), tmp)
        })
    }

    /// `sigmas[:, i] ⊖ mean` for measurement sigma points. The default calls
    /// [`z_residual`](Self::z_residual) per column.
    fn z_residuals(
        &self,
        sigmas: &DMatrix<f64>,
        mean: &DVector<f64>,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let len = out.nrows();
        columnwise(len, sigmas.ncols(), out, |i, tmp| {
            self.z_residual(sigmas.column(i), mean.column(0), tmp)
        })
    }

    /// The process function with explicit noise (augmented form): default `f(x, dt, u) ⊕ w`,
    /// which requires `dim_w() == dim_x()`.
    fn fx_noise(
        &self,
        x: DVectorView<'_, f64>,
        w: DVectorView<'_, f64>,
        dt: f64,
        u: Option<&DVector<f64>>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        let mut fx = DVector::zeros(self.dim_x());
        self.fx(x, dt, u, &mut fx)?;
        self.x_add(fx.column(0), w, out)
    }

    /// The measurement function with explicit noise (augmented form): default `h(x) + v`,
    /// which requires `dim_v() == dim_z()`.
    fn hx_noise(
        &self,
        x: DVectorView<'_, f64>,
        v: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        self.hx(x, out)?;
        *out += v;
        Ok(())
    }

    /// Weighted mean of the state sigma points (the columns of `sigmas`) with weights `wm`
    /// (which sum to one, and whose first entry may be negative). Default: `sigmas · wm`.
    fn x_mean(
        &self,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        weighted_mean(sigmas, wm, out)
    }

    /// Weighted mean of the measurement sigma points. Default: `sigmas · wm`.
    fn z_mean(
        &self,
        sigmas: &DMatrix<f64>,
        wm: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        weighted_mean(sigmas, wm, out)
    }

    /// State residual `a ⊖ b`. Default: `a − b`.
    fn x_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        difference(a, b, out)
    }

    /// Measurement residual `a ⊖ b`. Default: `a − b`.
    fn z_residual(
        &self,
        a: DVectorView<'_, f64>,
        b: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        difference(a, b, out)
    }

    /// State update `x ⊕ δ`. Default: `x + δ`.
    fn x_add(
        &self,
        x: DVectorView<'_, f64>,
        dx: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        out.copy_from(&x);
        *out += dx;
        Ok(())
    }

    /// How a sigma point is placed at `offset` (a column of the covariance square root, or
    /// its negative) from the mean. Default: [`x_add`](Self::x_add). (filterpy computes it
    /// with the sigma-point object's `subtract(x, -offset)`, independently of `state_add`.)
    fn sigma_add(
        &self,
        x: DVectorView<'_, f64>,
        offset: DVectorView<'_, f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        self.x_add(x, offset, out)
    }

    /// All sigma points at once: `out[:, i] = x ⊕ offsets[:, i]` (column 0 of `offsets` is
    /// zero). The default calls [`sigma_add`](Self::sigma_add) per column; vector-space models
    /// override it with one addition.
    fn sigma_points(
        &self,
        x: &DVector<f64>,
        offsets: &DMatrix<f64>,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        columnwise(x.len(), offsets.ncols(), out, |i, tmp| {
            self.sigma_add(x.column(0), offsets.column(i), tmp)
        })
    }

    /// An optional custom matrix square root: `Some(A)` with `A Aᵀ = scale · p` whose
    /// COLUMNS are the sigma offsets (filterpy's `sqrt_method` returns a matrix whose rows are
    /// the offsets: pass its transpose). `None` (the default) uses the Cholesky factor. Only
    /// the standard filter with additive noise calls it.
    fn sqrt_cov(&self, p: &DMatrix<f64>, scale: f64) -> Option<Result<DMatrix<f64>>> {
        let _ = (p, scale);
        None
    }

    /// Sigma points of (x, P) drawn by the model itself into the columns of `out` (`n × N`),
    /// for a [`SigmaPoints::Given`](super::SigmaPoints::Given) family (a sigma-point object
    /// defined outside this crate, e.g. filterpy's, whose weights the filter was given).
    /// `None` (the default): the model cannot draw, and such a family is refused.
    fn draw_sigmas(
        &self,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
        out: &mut DMatrix<f64>,
    ) -> Option<Result<()>> {
        let _ = (x, p, out);
        None
    }
}

/// Fills the first `ncols` columns of `out` with `f(i, tmp)` (`tmp` of length `len`): the
/// per-column defaults of [`UkfModel`].
fn columnwise(
    len: usize,
    ncols: usize,
    out: &mut DMatrix<f64>,
    mut f: impl FnMut(usize, &mut DVector<f64>) -> Result<()>,
) -> Result<()> {
    let mut tmp = DVector::zeros(len);
    for i in 0..ncols {
        f(i, &mut tmp)?;
        out.set_column(i, &tmp);
    }
    Ok(())
}

/// `out = sigmas · wm` (the default weighted means).
fn weighted_mean(sigmas: &DMatrix<f64>, wm: &DVector<f64>, out: &mut DVector<f64>) -> Result<()> {
    kernels::weighted_sum(
        sigmas.nrows(),
        sigmas.as_slice(),
        wm.as_slice(),
        out.as_mut_slice(),
    );
    Ok(())
}

/// `out = a − b` (the default residuals).
fn difference(
    a: DVectorView<'_, f64>,
    b: DVectorView<'_, f64>,
    out: &mut DVector<f64>,
) -> Result<()> {
    out.copy_from(&a);
    *out -= b;
    Ok(())
}

macro_rules! forward_model {
    ($($ty:ty),*) => {$(
        impl<M: UkfModel + ?Sized> UkfModel for $ty {
            fn dim_x(&self) -> usize { (**self).dim_x() }
            fn dim_z(&self) -> usize { (**self).dim_z() }
            fn dim_u(&self) -> usize { (**self).dim_u() }
            fn fx(&self, x: DVectorView<'_, f64>, dt: f64, u: Option<&DVector<f64>>, out: &mut DVector<f64>) -> Result<()> {
                (**self).fx(x, dt, u, out)
            }
            fn hx(&self, x: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).hx(x, out)
            }
            fn fx_sigmas(&self, sigmas: &DMatrix<f64>, dt: f64, u: Option<&DVector<f64>>, out: &mut DMatrix<f64>) -> Result<()> {
                (**self).fx_sigmas(sigmas, dt, u, out)
            }
            fn hx_sigmas(&self, sigmas: &DMatrix<f64>, out: &mut DMatrix<f64>) -> Result<()> {
                (**self).hx_sigmas(sigmas, out)
            }
            fn x_residuals(&self, sigmas: &DMatrix<f64>, mean: &DVector<f64>, out: &mut DMatrix<f64>) -> Result<()> {
                (**self).x_residuals(sigmas, mean, out)
            }
            fn z_residuals(&self, sigmas: &DMatrix<f64>, mean: &DVector<f64>, out: &mut DMatrix<f64>) -> Result<()> {
                (**self).z_residuals(sigmas, mean, out)
            }
            fn dim_w(&self) -> usize { (**self).dim_w() }
            fn dim_v(&self) -> usize { (**self).dim_v() }
            fn fx_noise(&self, x: DVectorView<'_, f64>, w: DVectorView<'_, f64>, dt: f64, u: Option<&DVector<f64>>, out: &mut DVector<f64>) -> Result<()> {
                (**self).fx_noise(x, w, dt, u, out)
            }
            fn hx_noise(&self, x: DVectorView<'_, f64>, v: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).hx_noise(x, v, out)
            }
            fn x_mean(&self, sigmas: &DMatrix<f64>, wm: &DVector<f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).x_mean(sigmas, wm, out)
            }
            fn z_mean(&self, sigmas: &DMatrix<f64>, wm: &DVector<f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).z_mean(sigmas, wm, out)
            }
            fn x_residual(&self, a: DVectorView<'_, f64>, b: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).x_residual(a, b, out)
            }
            fn z_residual(&self, a: DVectorView<'_, f64>, b: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).z_residual(a, b, out)
            }
            fn x_add(&self, x: DVectorView<'_, f64>, dx: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).x_add(x, dx, out)
            }
            fn sigma_add(&self, x: DVectorView<'_, f64>, offset: DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
                (**self).sigma_add(x, offset, out)
            }
            fn sigma_points(&self, x: &DVector<f64>, offsets: &DMatrix<f64>, out: &mut DMatrix<f64>) -> Result<()> {
                (**self).sigma_points(x, offsets, out)
            }
            fn sqrt_cov(&self, p: &DMatrix<f64>, scale: f64) -> Option<Result<DMatrix<f64>>> {
                (**self).sqrt_cov(p, scale)
            }
            fn draw_sigmas(&self, x: &DVector<f64>, p: &DMatrix<f64>, out: &mut DMatrix<f64>) -> Option<Result<()>> {
                (**self).draw_sigmas(x, p, out)
            }
        }
    )*};
}

forward_model!(Box<M>, &M, std::sync::Arc<M>);

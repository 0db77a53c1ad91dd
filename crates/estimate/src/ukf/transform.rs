//! The unscented transform shared by the standard and the square-root filter: drawing sigma
//! points (optionally augmented with noise), pushing them through the model, and their
//! weighted mean, deviations and covariance.

use nalgebra::{DMatrix, DVector, DVectorView};

use super::family::{Layout, SigmaPoints};
use super::kernels;
use super::linalg;
use super::model::UkfModel;
use crate::{EstimateError, Result};

/// Stamps the filter step into errors raised by a model.
pub(crate) fn at_step(err: EstimateError, step: usize) -> EstimateError {
    match err {
        EstimateError::Model {
            function, message, ..
        } => EstimateError::Model {
            function,
            step,
            message,
        },
        EstimateError::NonFinite {
            what, index, value, ..
        } => EstimateError::NonFinite {
            what,
            step,
            index,
            value,
        },
        EstimateError::NotPositiveDefinite {
            what,
            min_eigenvalue,
            ..
        } => EstimateError::NotPositiveDefinite {
            what,
            step,
            min_eigenvalue,
        },
        other => other,
    }
}

/// Preallocated matrices of one unscented transform.
#[derive(Debug, Clone)]
pub(crate) struct Workspace {
    /// Sigma points of the state part (`n × N`).
    pub sig: DMatrix<f64>,
    /// Noise part of augmented sigma points (`q × N`, `q` may be 0).
    pub noise: DMatrix<f64>,
    /// Transformed sigma points (`dim_out × N`).
    pub out: DMatrix<f64>,
    /// Deviations of the state sigma points from the state mean (`n × N`).
    pub dev_x: DMatrix<f64>,
    /// Deviations of the transformed sigma points from their mean (`dim_out × N`).
    pub dev_out: DMatrix<f64>,
    /// Scratch vector of the output size.
    pub tmp_out: DVector<f64>,
    /// Sigma offsets from the mean (`n × N`).
    pub off: DMatrix<f64>,
    /// Scratch of the output size (`dim_out × N`).
    pub scratch: DMatrix<f64>,
    /// What `out` holds (`"fx output"` or `"hx output"`), for error messages.
    pub out_label: &'static str,
}

impl Workspace {
    pub(crate) fn new(n: usize, q: usize, dim_out: usize, num_sigmas: usize) -> Self {
        Self {
            sig: DMatrix::zeros(n, num_sigmas),
            noise: DMatrix::zeros(q, num_sigmas),
            out: DMatrix::zeros(dim_out, num_sigmas),
            dev_x: DMatrix::zeros(n, num_sigmas),
            dev_out: DMatrix::zeros(dim_out, num_sigmas),
            tmp_out: DVector::zeros(dim_out),
            off: DMatrix::zeros(n, num_sigmas),
            scratch: DMatrix::zeros(dim_out, num_sigmas),
            out_label: "model output",
        }
    }
}

/// Where the state offsets of the sigma points come from.
pub(crate) enum Offsets<'a> {
    /// `√s · (column k of L)` with `L Lᵀ = P` and `s` the family's spread.
    Factor(&'a DMatrix<f64>),
    /// The columns of a given square root of `s · P` (a custom `sqrt_cov`).
    Scaled(&'a DMatrix<f64>),
    /// The covariance itself, for points the model draws ([`Layout::Given`]).
    Covariance(&'a DMatrix<f64>),
}

/// Draws the sigma points of `[x; ν]`, ν ~ N(0, N Nᵀ) (N = `noise_sqrt`, absent for
/// additive noise), with covariance `blkdiag(P, N Nᵀ)`, into `ws.sig` and `ws.noise`, in
/// filterpy's order. Symmetric families (Merwe, Julier): 0 the mean, k+1 the k-th positive
/// offset, n_a+k+1 the k-th negative. Simplex: column j is `blkdiag(L, N) C[:, j]`. Given
/// points: the model draws them from (x, P).
pub(crate) fn draw<M: UkfModel + ?Sized>(
    model: &M,
    pts: &SigmaPoints,
    x: &DVector<f64>,
    offsets: Offsets<'_>,
    noise_sqrt: Option<&DMatrix<f64>>,
    ws: &mut Workspace,
    step: usize,
) -> Result<()> {
    let n = x.len();
    let q = noise_sqrt.map_or(0, |m| m.nrows());
    let na = pts.n();
    debug_assert_eq!(na, n + q);
    let (src, scale) = match (offsets, pts.layout()) {
        (Offsets::Covariance(p), Layout::Given) => {
            return match model.draw_sigmas(x, p, &mut ws.sig) {
                Some(r) => r.map_err(|e| at_step(e, step)),
                None => Err(EstimateError::InvalidParameter {
                    name: "points",
                    value: n as f64,
                    reason: "this model cannot draw sigma points of a given (external) family",
                }),
            };
        }
        (_, Layout::Given) | (Offsets::Covariance(_), _) => {
            return Err(EstimateError::InvalidParameter {
                name: "points",
                value: n as f64,
                reason: "given (external) sigma points need the standard filter with additive noise",
            });
        }
        (Offsets::Factor(l), Layout::Symmetric(s)) => (l, s.sqrt()),
        (Offsets::Factor(l), Layout::Simplex(_)) => (l, 1.0),
        (Offsets::Scaled(a), _) => (a, 1.0),
    };
    match pts.layout() {
        Layout::Simplex(c) => {
            // All columns are offsets: off = src C[:n], noise = N C[n:].
            ws.off.gemm(scale, src, &c.rows(0, n), 0.0);
            if let Some(ns) = noise_sqrt {
                ws.noise.gemm(1.0, ns, &c.rows(n, q), 0.0);
            }
        }
        _ => {
            // State offsets: column k+1 is +γLₖ, column na+k+1 is −γLₖ, all others zero.
            // Only the state-offset columns are written: the others (the mean, and the noise
            // columns of an augmented state) stay zero from the workspace's creation.
            {
                let off = ws.off.as_mut_slice();
                let src = &src.as_slice()[..n * n];
                let (_, tail) = off.split_at_mut(n);
                let (plus, rest) = tail.split_at_mut(n * n);
                let minus = &mut rest[(na - n) * n..(na - n) * n + n * n];
                for ((p, m), &v) in plus.iter_mut().zip(minus.iter_mut()).zip(src) {
                    *p = scale * v;
                    *m = -scale * v;
                }
            }
            // Likewise only the noise-offset columns of `ws.noise` are written.
            if let Some(ns) = noise_sqrt {
                let gamma = pts.spread().sqrt();
                for k in 0..q {
                    for (sign, col) in [(1.0, n + k + 1), (-1.0, na + n + k + 1)] {
                        let mut c = ws.noise.column_mut(col);
                        c.copy_from(&ns.column(k));
                        c *= sign * gamma;
                    }
                }
            }
        }
    }
    // Sigma points and model outputs are checked for NaN/inf where they end up (the
    // deviations, see `diagnose`), which is one pass instead of three.
    model
        .sigma_points(x, &ws.off, &mut ws.sig)
        .map_err(|e| at_step(e, step))
}

/// [`draw`] from a covariance `p` (additive noise): the model's own draw for given points,
/// its custom square root of `s·p` if it has one, else the Cholesky factor of `p`. A `p`
/// that is not positive definite fails with [`EstimateError::NotPositiveDefinite`] at
/// `step`.
pub(crate) fn draw_cov<M: UkfModel + ?Sized>(
    model: &M,
    pts: &SigmaPoints,
    x: &DVector<f64>,
    p: &DMatrix<f64>,
    ws: &mut Workspace,
    step: usize,
) -> Result<()> {
    let n = x.len();
    if let SigmaPoints::Given(_) = pts {
        return draw(model, pts, x, Offsets::Covariance(p), None, ws, step);
    }
    if let Some(a) = model.sqrt_cov(p, pts.spread()) {
        let a = a.map_err(|e| at_step(e, step))?;
        linalg::check_shape(&a, n, n, "custom matrix square root")?;
        linalg::check_finite_at(a.as_slice(), || "custom matrix square root".into(), step)?;
        return draw(model, pts, x, Offsets::Scaled(&a), None, ws, step);
    }
    let l = linalg::cholesky(p).ok_or_else(|| EstimateError::NotPositiveDefinite {
        what: "covariance P of the sigma points".to_string(),
        step,
        min_eigenvalue: linalg::min_eigenvalue(p),
    })?;
    draw(model, pts, x, Offsets::Factor(&l), None, ws, step)
}

/// Fails with [`EstimateError::NonFinite`] naming the sigma point (column) of the first
/// non-finite entry of `m`.
fn check_columns(m: &DMatrix<f64>, what: &str, step: usize) -> Result<()> {
    let rows = m.nrows().max(1);
    linalg::check_finite_at(
        m.as_slice(),
        || {
            let col = linalg::first_non_finite(m.as_slice()).map_or(0, |(i, _)| i / rows);
            format!("{what} at sigma point {col}")
        },
        step,
    )
}

/// `ws.out[:, i] = g(ws.sig[:, i], ws.noise[:, i])` for every sigma point (the augmented
/// form of [`propagate_f`] and [`propagate_h`]); a model error is tagged with `step`.
fn noisy_columns(
    ws: &mut Workspace,
    step: usize,
    mut g: impl FnMut(DVectorView<'_, f64>, DVectorView<'_, f64>, &mut DVector<f64>) -> Result<()>,
) -> Result<()> {
    for i in 0..ws.sig.ncols() {
        g(ws.sig.column(i), ws.noise.column(i), &mut ws.tmp_out).map_err(|e| at_step(e, step))?;
        ws.out.set_column(i, &ws.tmp_out);
    }
    Ok(())
}

/// `ws.out[:, i] = f(ws.sig[:, i], dt, u)` (or `f(sig, noise, dt, u)` when augmented).
pub(crate) fn propagate_f<M: UkfModel + ?Sized>(
    model: &M,
    augmented: bool,
    dt: f64,
    u: Option<&DVector<f64>>,
    ws: &mut Workspace,
    step: usize,
) -> Result<()> {
    if augmented {
        noisy_columns(ws, step, |x, w, out| model.fx_noise(x, w, dt, u, out))?;
    } else {
        model
            .fx_sigmas(&ws.sig, dt, u, &mut ws.out)
            .map_err(|e| at_step(e, step))?;
    }
    ws.out_label = "fx output";
    Ok(())
}

/// `ws.out[:, i] = h(ws.sig[:, i])` (or `h(sig, noise)` when augmented).
pub(crate) fn propagate_h<M: UkfModel + ?Sized>(
    model: &M,
    augmented: bool,
    ws: &mut Workspace,
    step: usize,
) -> Result<()> {
    if augmented {
        noisy_columns(ws, step, |x, v, out| model.hx_noise(x, v, out))?;
    } else {
        model
            .hx_sigmas(&ws.sig, &mut ws.out)
            .map_err(|e| at_step(e, step))?;
    }
    ws.out_label = "hx output";
    Ok(())
}

/// Names the first non-finite value upstream of a failed check: the sigma points, then (with
/// `with_out`) the model outputs, then `last` (the matrix that failed, labelled `what`).
fn diagnose(
    ws: &Workspace,
    with_out: bool,
    last: &DMatrix<f64>,
    what: &str,
    step: usize,
) -> Result<()> {
    check_columns(&ws.sig, "sigma point", step)?;
    if with_out {
        check_columns(&ws.out, ws.out_label, step)?;
    }
    check_columns(last, what, step)
}

/// Which space a set of sigma points lives in (selects the mean/residual hooks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Space {
    /// The state: `x_mean`, `x_residual`.
    State,
    /// The measurement: `z_mean`, `z_residual`.
    Measurement,
}

/// Weighted mean of `ws.out` into `mean`, and the deviations `out_i ⊖ mean` into
/// `ws.dev_out`.
pub(crate) fn mean_and_devs<M: UkfModel + ?Sized>(
    model: &M,
    space: Space,
    wm: &DVector<f64>,
    mean: &mut DVector<f64>,
    ws: &mut Workspace,
    step: usize,
) -> Result<()> {
    let r = match space {
        Space::State => model.x_mean(&ws.out, wm, mean),
        Space::Measurement => model.z_mean(&ws.out, wm, mean),
    };
    r.map_err(|e| at_step(e, step))?;
    let label = match space {
        Space::State => "x_mean output",
        Space::Measurement => "z_mean output",
    };
    if !kernels::all_finite(mean.as_slice()) {
        diagnose(ws, true, &ws.out, ws.out_label, step)?;
        linalg::check_finite_at(mean.as_slice(), || label.to_string(), step)?;
    }
    let r = match space {
        Space::State => model.x_residuals(&ws.out, mean, &mut ws.dev_out),
        Space::Measurement => model.z_residuals(&ws.out, mean, &mut ws.dev_out),
    };
    r.map_err(|e| at_step(e, step))?;
    if !kernels::all_finite(ws.dev_out.as_slice()) {
        diagnose(ws, true, &ws.dev_out, "residual", step)?;
    }
    Ok(())
}

/// Deviations `sig_i ⊖ x` of the drawn state sigma points into `ws.dev_x`.
pub(crate) fn state_devs<M: UkfModel + ?Sized>(
    model: &M,
    x: &DVector<f64>,
    ws: &mut Workspace,
    step: usize,
) -> Result<()> {
    model
        .x_residuals(&ws.sig, x, &mut ws.dev_x)
        .map_err(|e| at_step(e, step))?;
    if !kernels::all_finite(ws.dev_x.as_slice()) {
        diagnose(ws, false, &ws.dev_x, "state residual", step)?;
    }
    Ok(())
}

/// `out = Σᵢ wᵢ aᵢ bᵢᵀ` over the columns of `a` and `b`.
pub(crate) fn weighted_outer(
    a: &DMatrix<f64>,
    w: &DVector<f64>,
    b: &DMatrix<f64>,
    out: &mut DMatrix<f64>,
) {
    kernels::weighted_outer(
        a.nrows(),
        b.nrows(),
        a.as_slice(),
        w.as_slice(),
        b.as_slice(),
        out.as_mut_slice(),
    );
}

/// `out = Σᵢ wᵢ aᵢ aᵢᵀ` (exactly symmetric); `scratch` is `a`-sized.
pub(crate) fn weighted_gram(
    a: &DMatrix<f64>,
    w: &DVector<f64>,
    scratch: &mut DMatrix<f64>,
    out: &mut DMatrix<f64>,
) {
    kernels::weighted_gram_auto(
        a.nrows(),
        a.ncols(),
        a.as_slice(),
        w.as_slice(),
        scratch.as_mut_slice(),
        out.as_mut_slice(),
    );
}

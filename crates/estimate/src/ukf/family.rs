//! The sigma-point families a filter can use, behind one type.

use nalgebra::{DMatrix, DVector};

use super::julier::JulierSigmaPoints;
use super::linalg;
use super::model::UkfModel;
use super::points::MerweScaledSigmaPoints;
use super::simplex::SimplexSigmaPoints;
use super::transform::{self, Workspace};
use crate::{EstimateError, Result};

/// `count` weights equal to `value`, where `count` (a multiple of the state dimension given by
/// the caller) may overflow or exceed memory: an `OutOfMemory` error, never an abort.
pub(crate) fn filled_weights(count: Option<usize>, value: f64) -> Result<DVector<f64>> {
    let n = count.unwrap_or(usize::MAX);
    Ok(DVector::from_vec(autoteach_geometry::alloc::try_filled(
        "the sigma-point weights (2n + 1 for n state dimensions)",
        n,
        value,
    )?))
}

/// A sigma-point family with its weights: van der Merwe's scaled points, Julier's symmetric
/// points, the spherical simplex, or points drawn by the model itself with given weights
/// ([`SigmaPoints::Given`], for sigma-point objects defined outside this crate).
#[derive(Debug, Clone, PartialEq)]
pub enum SigmaPoints {
    /// [`MerweScaledSigmaPoints`] (2n + 1 points).
    Merwe(MerweScaledSigmaPoints),
    /// [`JulierSigmaPoints`] (2n + 1 points).
    Julier(JulierSigmaPoints),
    /// [`SimplexSigmaPoints`] (n + 1 points).
    Simplex(SimplexSigmaPoints),
    /// Weights only: the model draws the points ([`UkfModel::draw_sigmas`](super::UkfModel::draw_sigmas)).
    Given(GivenWeights),
}

/// The weights of sigma points that the model draws itself.
#[derive(Debug, Clone, PartialEq)]
pub struct GivenWeights {
    n: usize,
    wm: DVector<f64>,
    wc: DVector<f64>,
}

impl GivenWeights {
    /// Weights `wm`, `wc` (equal lengths ≥ 1, finite) of points in dimension `n ≥ 1`.
    pub fn new(n: usize, wm: DVector<f64>, wc: DVector<f64>) -> Result<Self> {
        if n == 0 {
            return Err(EstimateError::InvalidParameter {
                name: "n",
                value: 0.0,
                reason: "the state dimension must be at least 1",
            });
        }
        if wm.is_empty() || wm.len() != wc.len() {
            return Err(EstimateError::DimensionMismatch {
                what: "sigma-point weights (Wm, Wc)".to_string(),
                expected: vec![wm.len().max(1), wm.len().max(1)],
                got: vec![wm.len(), wc.len()],
            });
        }
        linalg::check_finite_input(wm.as_slice(), "weights Wm")?;
        linalg::check_finite_input(wc.as_slice(), "weights Wc")?;
        Ok(Self { n, wm, wc })
    }
}

/// Where the offsets of a family come from (see [`SigmaPoints::layout`]).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Layout<'a> {
    /// `x`, `x ⊕ √s Lₖ`, `x ⊕ −√s Lₖ` with `L Lᵀ = P`: `s` is the spread.
    Symmetric(f64),
    /// `x ⊕ L C[:, j]` for the unit simplex `C`.
    Simplex(&'a DMatrix<f64>),
    /// Drawn by the model.
    Given,
}

impl SigmaPoints {
    /// The dimension n.
    pub fn n(&self) -> usize {
        match self {
            Self::Merwe(p) => p.n(),
            Self::Julier(p) => p.n(),
            Self::Simplex(p) => p.n(),
            Self::Given(g) => g.n,
        }
    }

    /// The number of sigma points.
    pub fn num_sigmas(&self) -> usize {
        match self {
            Self::Merwe(p) => p.num_sigmas(),
            Self::Julier(p) => p.num_sigmas(),
            Self::Simplex(p) => p.num_sigmas(),
            Self::Given(g) => g.wm.len(),
        }
    }

    /// The mean weights.
    pub fn wm(&self) -> &DVector<f64> {
        match self {
            Self::Merwe(p) => p.wm(),
            Self::Julier(p) => p.wm(),
            Self::Simplex(p) => p.wm(),
            Self::Given(g) => &g.wm,
        }
    }

    /// The covariance weights.
    pub fn wc(&self) -> &DVector<f64> {
        match self {
            Self::Merwe(p) => p.wc(),
            Self::Julier(p) => p.wc(),
            Self::Simplex(p) => p.wc(),
            Self::Given(g) => &g.wc,
        }
    }

    /// The factor by which P is scaled before its square root: n + λ (Merwe), n + κ
    /// (Julier), 1 (simplex and given points).
    pub fn spread(&self) -> f64 {
        match self {
            Self::Merwe(p) => p.n() as f64 + p.lambda(),
            Self::Julier(p) => p.spread(),
            Self::Simplex(_) | Self::Given(_) => 1.0,
        }
    }

    /// The same family for another dimension (the augmented state). Given points have no
    /// other dimension.
    pub fn with_dim(&self, n: usize) -> Result<Self> {
        Ok(match self {
            Self::Merwe(p) => Self::Merwe(p.with_dim(n)?),
            Self::Julier(p) => Self::Julier(JulierSigmaPoints::new(n, p.kappa())?),
            Self::Simplex(_) => Self::Simplex(SimplexSigmaPoints::new(n)?),
            Self::Given(_) => {
                return Err(EstimateError::InvalidParameter {
                    name: "points",
                    value: n as f64,
                    reason: "sigma points drawn by the model cannot be augmented with the noise",
                });
            }
        })
    }

    pub(crate) fn layout(&self) -> Layout<'_> {
        match self {
            Self::Simplex(p) => Layout::Simplex(p.unit()),
            Self::Given(_) => Layout::Given,
            _ => Layout::Symmetric(self.spread()),
        }
    }

    /// Sigma points of (x, P) as the columns of an `n × N` matrix, with plain vector
    /// addition and the lower Cholesky factor (filterpy's order). Fails for wrong sizes,
    /// NaN, a P that is not symmetric positive definite, or given points.
    pub fn sigma_points(&self, x: &DVector<f64>, p: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let n = self.n();
        linalg::check_len(x, n, "state x")?;
        linalg::check_finite_input(x.as_slice(), "state x")?;
        let p = linalg::validate_covariance_input(p, n, "covariance P")?;
        let scaled = p * self.spread();
        let l = linalg::cholesky(&scaled).ok_or_else(|| EstimateError::InvalidCovariance {
            what: "covariance P".to_string(),
            asymmetry: 0.0,
            min_eigenvalue: linalg::min_eigenvalue(&scaled) / self.spread(),
        })?;
        let mut out = DMatrix::zeros(n, self.num_sigmas());
        match self.layout() {
            Layout::Symmetric(_) => {
                for k in 0..n {
                    out.set_column(k + 1, &l.column(k));
                    out.set_column(n + k + 1, &(-l.column(k)));
                }
            }
            Layout::Simplex(c) => out.copy_from(&(&l * c)),
            Layout::Given => {
                return Err(EstimateError::InvalidParameter {
                    name: "points",
                    value: n as f64,
                    reason: "given sigma points are drawn by their model",
                });
            }
        }
        for mut col in out.column_iter_mut() {
            col += x;
        }
        Ok(out)
    }
}

impl SigmaPoints {
    /// Sigma points of (x, P) as a filter with `model` draws them (columns, `n × N`): the
    /// model's ⊕ (`sigma_add`), its custom square root, or its own draw for given points.
    pub fn draw_with<M: UkfModel + ?Sized>(
        &self,
        model: &M,
        x: &DVector<f64>,
        p: &DMatrix<f64>,
    ) -> Result<DMatrix<f64>> {
        let n = self.n();
        linalg::check_len(x, n, "state x")?;
        linalg::check_finite_input(x.as_slice(), "state x")?;
        let p = linalg::validate_covariance_input(p, n, "covariance P")?;
        let mut ws = Workspace::new(n, 0, n, self.num_sigmas());
        transform::draw_cov(model, self, x, &p, &mut ws, 0)?;
        Ok(ws.sig)
    }
}

impl From<MerweScaledSigmaPoints> for SigmaPoints {
    fn from(p: MerweScaledSigmaPoints) -> Self {
        Self::Merwe(p)
    }
}

impl From<JulierSigmaPoints> for SigmaPoints {
    fn from(p: JulierSigmaPoints) -> Self {
        Self::Julier(p)
    }
}

impl From<SimplexSigmaPoints> for SigmaPoints {
    fn from(p: SimplexSigmaPoints) -> Self {
        Self::Simplex(p)
    }
}

impl From<GivenWeights> for SigmaPoints {
    fn from(p: GivenWeights) -> Self {
        Self::Given(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(n: usize) -> DMatrix<f64> {
        let a = DMatrix::from_fn(n, n, |i, j| ((i + 2 * j) % 5) as f64 * 0.3 - 0.4);
        &a * a.transpose() + DMatrix::identity(n, n) * 0.7
    }

    /// Every family reproduces the mean and covariance exactly (the unscented transform of a
    /// linear map is exact).
    #[test]
    fn families_reproduce_mean_and_covariance() {
        let n = 4;
        let x = DVector::from_fn(n, |i, _| i as f64 * 0.5 - 1.0);
        let p = spd(n);
        let fams: Vec<SigmaPoints> = vec![
            MerweScaledSigmaPoints::new(n, 0.3, 2.0, 3.0 - n as f64)
                .unwrap()
                .into(),
            JulierSigmaPoints::new(n, 1.0).unwrap().into(),
            SimplexSigmaPoints::new(n).unwrap().into(),
        ];
        for f in fams {
            let s = f.sigma_points(&x, &p).unwrap();
            assert_eq!(s.ncols(), f.num_sigmas());
            let mean = &s * f.wm();
            assert!((&mean - &x).amax() < 1e-12, "{f:?}");
            let mut cov = DMatrix::zeros(n, n);
            for k in 0..s.ncols() {
                let d = s.column(k) - &x;
                cov += f.wc()[k] * &d * d.transpose();
            }
            assert!((&cov - &p).amax() < 1e-12, "{f:?}");
        }
    }

    #[test]
    fn julier_is_merwe_at_alpha_one_beta_zero() {
        let j: SigmaPoints = JulierSigmaPoints::new(3, 2.0).unwrap().into();
        let m: SigmaPoints = MerweScaledSigmaPoints::new(3, 1.0, 0.0, 2.0)
            .unwrap()
            .into();
        assert!((j.wm() - m.wm()).amax() < 1e-15);
        assert!((j.wc() - m.wc()).amax() < 1e-15);
        let x = DVector::from_element(3, 0.25);
        let d = j.sigma_points(&x, &spd(3)).unwrap() - m.sigma_points(&x, &spd(3)).unwrap();
        assert!(d.amax() < 1e-14);
    }

    /// A linear model that draws its own (simplex) sigma points: the filter with
    /// [`SigmaPoints::Given`] weights must equal the filter with the simplex family.
    struct Drawing {
        inner: crate::ukf::LinearModel,
        pts: SigmaPoints,
    }

    impl UkfModel for Drawing {
        fn dim_x(&self) -> usize {
            self.inner.dim_x()
        }
        fn dim_z(&self) -> usize {
            self.inner.dim_z()
        }
        fn fx(
            &self,
            x: nalgebra::DVectorView<'_, f64>,
            dt: f64,
            u: Option<&DVector<f64>>,
            out: &mut DVector<f64>,
        ) -> Result<()> {
            self.inner.fx(x, dt, u, out)
        }
        fn hx(&self, x: nalgebra::DVectorView<'_, f64>, out: &mut DVector<f64>) -> Result<()> {
            self.inner.hx(x, out)
        }
        fn draw_sigmas(
            &self,
            x: &DVector<f64>,
            p: &DMatrix<f64>,
            out: &mut DMatrix<f64>,
        ) -> Option<Result<()>> {
            Some(self.pts.sigma_points(x, p).map(|s| out.copy_from(&s)))
        }
    }

    #[test]
    fn given_points_drawn_by_the_model_equal_the_family() {
        use crate::ukf::{BatchInputs, LinearModel, SigmaPointFilter, UnscentedKalmanFilter};
        let f = DMatrix::from_row_slice(2, 2, &[1.0, 0.1, 0.0, 1.0]);
        let h = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let lin = LinearModel::new(f, h, None).unwrap();
        let simplex: SigmaPoints = SimplexSigmaPoints::new(2).unwrap().into();
        let given: SigmaPoints = GivenWeights::new(2, simplex.wm().clone(), simplex.wc().clone())
            .unwrap()
            .into();
        let zs: Vec<_> = (0..40)
            .map(|k| Some(DVector::from_element(1, (k as f64 * 0.3).sin())))
            .collect();
        let mut a = UnscentedKalmanFilter::new(lin.clone(), simplex.clone()).unwrap();
        let model = Drawing {
            inner: lin.clone(),
            pts: simplex,
        };
        let mut b = UnscentedKalmanFilter::new(model, given.clone()).unwrap();
        let ra = a.batch(&BatchInputs::new(1.0, &zs)).unwrap();
        let rb = b.batch(&BatchInputs::new(1.0, &zs)).unwrap();
        for k in 0..zs.len() {
            assert!((ra.x(k).unwrap() - rb.x(k).unwrap()).amax() < 1e-14);
            assert!((ra.p(k).unwrap() - rb.p(k).unwrap()).amax() < 1e-14);
        }
        // A model that cannot draw refuses given points; so does the square-root filter.
        let mut c = UnscentedKalmanFilter::new(lin.clone(), given.clone()).unwrap();
        assert!(matches!(
            c.predict(1.0, None),
            Err(EstimateError::InvalidParameter { name: "points", .. })
        ));
        assert!(crate::ukf::SquareRootUkf::new(lin, given).is_err());
    }

    #[test]
    fn given_weights_are_validated_and_not_drawn_here() {
        let w = DVector::from_element(3, 1.0 / 3.0);
        assert!(GivenWeights::new(1, w.clone(), DVector::zeros(2)).is_err());
        let g: SigmaPoints = GivenWeights::new(1, w.clone(), w).unwrap().into();
        assert_eq!(g.num_sigmas(), 3);
        assert!(g.with_dim(2).is_err());
        assert!(
            g.sigma_points(&DVector::zeros(1), &DMatrix::identity(1, 1))
                .is_err()
        );
    }
}

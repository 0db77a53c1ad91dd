//! The problem statement: parameter blocks on manifolds, residual blocks with robust losses,
//! fixed blocks and priors (the factor-graph cost of seed 000_3b1454b2b2194811.txt eq. (5.10)
//! and the calibration cost of 004_815695db12a6b16c.txt eq. (5.1)).

use autoteach_geometry::lie::{se3_minus_jacobians, so3_minus_jacobians};
use nalgebra::{DMatrix, Matrix3};

use super::loss::Loss;
use super::manifold::{Manifold, quat_from_params, se3_from_params, so3_from_params};
use crate::{EstimateError, Result};

/// Handle of a parameter block (its index in insertion order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BlockId(pub usize);

/// Handle of a residual block (its index in insertion order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ResidualId(pub usize);

/// A residual block r(x₁, …, x_k) ∈ Rᵐ over parameter blocks, with analytic Jacobians with
/// respect to the TANGENT of each block (right perturbation, `X ⊕ δ = X·Exp(δ)`).
///
/// Residuals are assumed whitened (unit covariance): cost = ½ Σ ρ(‖r‖²).
pub trait Residual: Send + Sync {
    /// Residual dimension m.
    fn dim(&self) -> usize;
    /// r(params) into `residual` (length m); `params[k]` is block k's stored values. If
    /// `jacobians` is Some, also ∂r/∂δ_k w.r.t. the TANGENT of each block k (right
    /// perturbation), `jacobians[k]` pre-sized m × tangent_dim(k) and zeroed.
    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> std::result::Result<(), EstimateError>;

    /// The manifold each block must have, in order, when the residual knows it; checked by
    /// [`Problem::add_residual`] so that a residual never reads blocks of the wrong kind (which
    /// would index past their values during the solve). `None` (the default) accepts any blocks.
    fn block_manifolds(&self) -> Option<Vec<Manifold>> {
        None
    }
}

/// A parameter block.
#[derive(Debug, Clone)]
pub(crate) struct Block {
    /// Offset of its values in `Problem::values`.
    pub offset: usize,
    pub manifold: Manifold,
    pub fixed: bool,
    pub eliminate: Option<bool>,
}

/// A residual block and the blocks it reads.
pub(crate) struct ResidualBlock {
    pub residual: Box<dyn Residual>,
    pub blocks: Vec<BlockId>,
    pub loss: Loss,
}

/// A nonlinear least-squares problem on manifolds: minimise ½ Σᵢ ρᵢ(‖rᵢ(x)‖²) over the free
/// parameter blocks (seed 004_815695db12a6b16c.txt eq. (5.1); solved by
/// [`Problem::solve`], see the `solver` module).
#[derive(Default)]
pub struct Problem {
    pub(crate) values: Vec<f64>,
    pub(crate) blocks: Vec<Block>,
    pub(crate) residuals: Vec<ResidualBlock>,
}

impl std::fmt::Debug for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Problem")
            .field("blocks", &self.blocks.len())
            .field("residuals", &self.residuals.len())
            .finish()
    }
}

impl Problem {
    /// An empty problem.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of parameter blocks.
    pub fn num_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// Number of residual blocks.
    pub fn num_residuals(&self) -> usize {
        self.residuals.len()
    }

    /// Adds a parameter block with initial `values` in the layout of `manifold` (validated:
    /// length, finiteness, unit quaternion / rotation matrix; rotations are renormalised).
    pub fn add_block(&mut self, values: &[f64], manifold: Manifold) -> Result<BlockId> {
        let id = self.blocks.len();
        let v = manifold.validate(values, &format!("values of block {id}"))?;
        self.blocks.push(Block {
            offset: self.values.len(),
            manifold,
            fixed: false,
            eliminate: None,
        });
        self.values.extend_from_slice(&v);
        Ok(BlockId(id))
    }

    pub(crate) fn block(&self, b: BlockId) -> Result<&Block> {
        self.blocks.get(b.0).ok_or_else(|| {
            EstimateError::InvalidProblem(format!(
                "unknown block {}: block must be an id in [0, {}) returned by an add_* call",
                b.0,
                self.blocks.len()
            ))
        })
    }

    /// The manifold of a block.
    pub fn manifold(&self, block: BlockId) -> Result<Manifold> {
        Ok(self.block(block)?.manifold)
    }

    /// Holds a block constant during [`Problem::solve`] (or releases it).
    pub fn set_fixed(&mut self, block: BlockId, fixed: bool) -> Result<()> {
        self.block(block)?;
        self.blocks[block.0].fixed = fixed;
        Ok(())
    }

    /// Whether a block is held constant.
    pub fn is_fixed(&self, block: BlockId) -> Result<bool> {
        Ok(self.block(block)?.fixed)
    }

    /// Marks a block for elimination by the Schur complement (`LinearSolver::SparseSchur`,
    /// and `Auto` when many blocks are marked). `None` restores the automatic rule: a
    /// `Euclidean(3)` block (point-like) whose residuals touch no other eliminated block.
    pub fn set_eliminate(&mut self, block: BlockId, eliminate: Option<bool>) -> Result<()> {
        self.block(block)?;
        self.blocks[block.0].eliminate = eliminate;
        Ok(())
    }

    /// Adds a residual block over `blocks` (in the order `r.evaluate` expects them) with a
    /// robust `loss`. A block may appear only once per residual.
    pub fn add_residual<R: Residual + 'static>(
        &mut self,
        r: R,
        blocks: &[BlockId],
        loss: Loss,
    ) -> Result<ResidualId> {
        self.add_boxed_residual(Box::new(r), blocks, loss)
    }

    /// [`Problem::add_residual`] for an already boxed residual.
    pub fn add_boxed_residual(
        &mut self,
        r: Box<dyn Residual>,
        blocks: &[BlockId],
        loss: Loss,
    ) -> Result<ResidualId> {
        let id = self.residuals.len();
        loss.validate()?;
        if r.dim() == 0 {
            return Err(EstimateError::InvalidProblem(format!(
                "residual {id} has dimension 0"
            )));
        }
        if let Some(expected) = r.block_manifolds()
            && expected.len() != blocks.len()
        {
            return Err(EstimateError::InvalidProblem(format!(
                "residual {id} reads {} blocks, got {}",
                expected.len(),
                blocks.len()
            )));
        }
        let expected = r.block_manifolds();
        for (k, b) in blocks.iter().enumerate() {
            let have = self.block(*b)?.manifold;
            if let Some(want) = expected.as_ref().map(|e| e[k])
                && have != want
            {
                return Err(EstimateError::InvalidProblem(format!(
                    "residual {id}: block {} is {have:?}, but this residual needs {want:?} there",
                    b.0
                )));
            }
            if blocks[..k].contains(b) {
                return Err(EstimateError::InvalidProblem(format!(
                    "residual {id} lists block {} twice",
                    b.0
                )));
            }
        }
        self.residuals.push(ResidualBlock {
            residual: r,
            blocks: blocks.to_vec(),
            loss,
        });
        Ok(ResidualId(id))
    }

    /// Adds a Gaussian prior on a block: the whitened residual L⁻¹ (x ⊖ mean) with
    /// `covariance = L Lᵀ` (tangent space at `mean`; seed 000_3b1454b2b2194811.txt eq. (5.10),
    /// prior factor). `covariance` must be symmetric positive definite.
    pub fn add_prior(
        &mut self,
        block: BlockId,
        mean: &[f64],
        covariance: &DMatrix<f64>,
    ) -> Result<ResidualId> {
        let manifold = self.block(block)?.manifold;
        let prior = PriorResidual::new(manifold, mean, covariance)?;
        self.add_residual(prior, &[block], Loss::Trivial)
    }

    /// The current values of a block (an empty slice for an unknown id).
    pub fn values(&self, block: BlockId) -> &[f64] {
        match self.blocks.get(block.0) {
            Some(b) => &self.values[b.offset..b.offset + b.manifold.ambient_dim()],
            None => &[],
        }
    }

    /// Overwrites the values of a block (validated like [`Problem::add_block`]).
    pub fn set_values(&mut self, block: BlockId, values: &[f64]) -> Result<()> {
        let b = self.block(block)?.clone();
        let v = b
            .manifold
            .validate(values, &format!("values of block {}", block.0))?;
        self.values[b.offset..b.offset + v.len()].copy_from_slice(&v);
        Ok(())
    }

    /// The blocks a residual reads.
    pub fn residual_blocks(&self, residual: ResidualId) -> Result<&[BlockId]> {
        self.residuals
            .get(residual.0)
            .map(|r| r.blocks.as_slice())
            .ok_or_else(|| {
                EstimateError::InvalidProblem(format!(
                    "unknown residual {} (the problem has {})",
                    residual.0,
                    self.residuals.len()
                ))
            })
    }
}

/// The whitened prior residual L⁻¹ (x ⊖ μ) of a block, Σ = L Lᵀ.
#[derive(Debug, Clone)]
pub struct PriorResidual {
    manifold: Manifold,
    mean: Vec<f64>,
    /// L⁻¹.
    sqrt_info: DMatrix<f64>,
}

impl PriorResidual {
    /// A prior with `mean` (stored layout of `manifold`) and tangent `covariance`.
    pub fn new(manifold: Manifold, mean: &[f64], covariance: &DMatrix<f64>) -> Result<Self> {
        let mean = manifold.validate(mean, "prior mean")?;
        let n = manifold.tangent_dim();
        if covariance.shape() != (n, n) {
            return Err(EstimateError::DimensionMismatch {
                what: "prior covariance".into(),
                expected: vec![n, n],
                got: vec![covariance.nrows(), covariance.ncols()],
            });
        }
        if let Some((index, &value)) = covariance.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: "prior covariance".into(),
                index,
                value,
            });
        }
        let scale = covariance.amax().max(f64::MIN_POSITIVE);
        let asym = (covariance - covariance.transpose()).amax() / scale;
        let chol = if asym <= 1e-9 {
            nalgebra::Cholesky::new(covariance.clone())
        } else {
            None
        };
        let Some(chol) = chol else {
            let min_eigenvalue = covariance.clone().symmetric_eigenvalues().min();
            return Err(EstimateError::InvalidCovariance {
                what: "prior covariance".into(),
                asymmetry: asym,
                min_eigenvalue,
            });
        };
        let l = chol.l();
        let sqrt_info = l
            .solve_lower_triangular(&DMatrix::identity(n, n))
            .ok_or_else(|| EstimateError::InvalidCovariance {
                what: "prior covariance".into(),
                asymmetry: asym,
                min_eigenvalue: 0.0,
            })?;
        Ok(Self {
            manifold,
            mean,
            sqrt_info,
        })
    }
}

impl PriorResidual {
    /// L⁻¹ (the square-root information matrix).
    pub fn sqrt_info(&self) -> &DMatrix<f64> {
        &self.sqrt_info
    }
}

impl Residual for PriorResidual {
    fn dim(&self) -> usize {
        self.manifold.tangent_dim()
    }

    fn evaluate(
        &self,
        params: &[&[f64]],
        residual: &mut [f64],
        jacobians: Option<&mut [DMatrix<f64>]>,
    ) -> Result<()> {
        let x = params.first().copied().unwrap_or(&[]);
        let n = self.manifold.tangent_dim();
        let mut d = vec![0.0; n];
        self.manifold.minus(x, &self.mean, &mut d);
        let r = &self.sqrt_info * nalgebra::DVector::from_vec(d.clone());
        residual.copy_from_slice(r.as_slice());
        if let Some(jac) = jacobians {
            // ∂(x ⊖ μ)/∂δx: identity, J_r⁻¹(x ⊖ μ) on SO(3)/S³, its SE(3) analogue (Solà
            // eq. (76), App. B/D).
            let j: DMatrix<f64> = match self.manifold {
                Manifold::Euclidean(_) => DMatrix::identity(n, n),
                Manifold::So3 => {
                    let (jy, _) =
                        so3_minus_jacobians(&so3_from_params(x), &so3_from_params(&self.mean));
                    dm3(&jy)
                }
                Manifold::UnitQuaternion => {
                    let (jy, _) = so3_minus_jacobians(
                        &quat_from_params(x).to_rotation_matrix(),
                        &quat_from_params(&self.mean).to_rotation_matrix(),
                    );
                    dm3(&jy)
                }
                Manifold::Se3 => {
                    let (jy, _) =
                        se3_minus_jacobians(&se3_from_params(x), &se3_from_params(&self.mean));
                    DMatrix::from_column_slice(6, 6, jy.as_slice())
                }
                Manifold::Se2 => {
                    let d = [d[0], d[1], d[2]];
                    let j = super::se2::se2_right_jacobian_inv(&d);
                    DMatrix::from_column_slice(3, 3, j.as_slice())
                }
            };
            if let Some(j0) = jac.first_mut() {
                *j0 = &self.sqrt_info * j;
            }
        }
        Ok(())
    }
}

fn dm3(m: &Matrix3<f64>) -> DMatrix<f64> {
    DMatrix::from_column_slice(3, 3, m.as_slice())
}

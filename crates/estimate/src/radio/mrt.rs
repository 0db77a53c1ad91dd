//! Multi-robot tomography, MRT (seed 004 §3.2.2): one attenuation unknown per cell of a
//! coarse grid (3 m in Table 3.1) plus the two path-loss parameters, measurement rows
//! `[1, log10 d, w…]` with `w` the link's length in each cell (eq. 3.2), Tikhonov smoothness
//! between 4-neighbours (eq. 3.5), solved exactly by [`super::tomo`]'s bordered sparse
//! Cholesky.

use super::grid::GridGeometry;
use super::tomo::{FactorCache, Regularization, TomoRows, TomoSolution, grid_pairs};
use super::{Link, check_links, check_links_inside, check_training};
use crate::{EstimateError, Result};

/// MRT meta-parameters (Table 3.1, evaluation 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MrtOptions {
    /// Cell side of the attenuation grid in metres (Table 3.1: 3.0).
    pub cell: f64,
    /// Smoothness weight λ of eq. 3.5 (Table 3.1, evaluation 1: 0.1375).
    pub lambda: f64,
}

impl Default for MrtOptions {
    fn default() -> Self {
        Self {
            cell: 3.0,
            lambda: 0.1375,
        }
    }
}

/// A multi-robot tomography model over a fixed workspace.
#[derive(Debug, Clone)]
pub struct Mrt {
    /// The attenuation grid.
    pub grid: GridGeometry,
    /// Meta-parameters.
    pub options: MrtOptions,
    rows: TomoRows,
    solution: Option<TomoSolution>,
    cache: FactorCache,
}

impl Mrt {
    /// An empty model whose attenuation grid of `options.cell` metres covers the box
    /// `[x0, x1] × [y0, y1]`. Errors: `InvalidParameter` for a bad cell size, λ or box.
    pub fn new(bounds: [f64; 4], options: MrtOptions) -> Result<Self> {
        if !(options.lambda.is_finite() && options.lambda >= 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "lambda",
                value: options.lambda,
                reason: "must be finite and non-negative",
            });
        }
        let [x0, y0, x1, y1] = bounds;
        if !(x1 > x0 && y1 > y0) {
            return Err(EstimateError::InvalidParameter {
                name: "bounds",
                value: (x1 - x0).min(y1 - y0),
                reason: "the workspace box must have positive width and height",
            });
        }
        let grid = GridGeometry::covering(x0, y0, x1, y1, options.cell)?;
        Ok(Self {
            rows: TomoRows::new(grid.len()),
            grid,
            options,
            solution: None,
            cache: FactorCache::default(),
        })
    }

    /// Appends measurements (their traversals are computed once and kept) without solving.
    /// Errors: those of [`check_training`], `OutsideMap` for an endpoint off the grid.
    pub fn add(&mut self, links: &[Link], rss: &[f64]) -> Result<()> {
        check_training(links, rss)?;
        check_links_inside(&self.grid, "training links", links)?;
        let mut entries = Vec::new();
        for (l, &y) in links.iter().zip(rss) {
            entries.clear();
            self.grid.traverse(l.tx, l.rx, |c, w| entries.push((c, w)));
            self.rows.push(l.log_distance(), &entries, y);
        }
        Ok(())
    }

    /// Solves eq. 3.5 on every measurement added so far, exactly; the symbolic analysis of
    /// the last solve is reused when the couplings have not grown
    /// ([`TomoRows::solve_cached`]).
    pub fn solve(&mut self) -> Result<&TomoSolution> {
        let reg = self.regularization();
        let sol = self.rows.solve_cached(&reg, &mut self.cache)?;
        Ok(self.solution.insert(sol))
    }

    /// Forgets the cached symbolic analysis (the next solve starts cold).
    pub fn clear_factor_cache(&mut self) {
        self.cache.clear();
    }

    /// Number of symbolic analyses done so far (solves that could not reuse the last one).
    pub fn analyses(&self) -> usize {
        self.cache.analyses
    }

    /// Adds measurements and re-solves (the incremental update of §3.3's replay).
    pub fn update(&mut self, links: &[Link], rss: &[f64]) -> Result<&TomoSolution> {
        self.add(links, rss)?;
        self.solve()
    }

    /// Builds and solves a model in one call.
    pub fn fit(bounds: [f64; 4], links: &[Link], rss: &[f64], options: MrtOptions) -> Result<Self> {
        let mut m = Self::new(bounds, options)?;
        m.update(links, rss)?;
        Ok(m)
    }

    /// The last solution (`None` before the first solve).
    pub fn solution(&self) -> Option<&TomoSolution> {
        self.solution.as_ref()
    }

    /// The measurement rows (for peer solvers and checks).
    pub fn rows(&self) -> &TomoRows {
        &self.rows
    }

    /// The regularisation of eq. 3.5 for this grid.
    pub fn regularization(&self) -> Regularization {
        Regularization {
            pairs: grid_pairs(self.grid.rows, self.grid.cols, 0),
            lambda: self.options.lambda,
            phi: 0.0,
            prior: Vec::new(),
        }
    }

    /// Predicted RSS `L0 − a log10 d + Σ wᵢ vᵢ`. Errors: `InvalidProblem` before a solve,
    /// `NonFiniteInput`, `CoincidentLink`, `OutsideMap`.
    pub fn predict(&self, links: &[Link]) -> Result<Vec<f64>> {
        let sol = self
            .solution
            .as_ref()
            .ok_or_else(|| EstimateError::InvalidProblem("MRT predict before fit".into()))?;
        check_links("query links", links)?;
        check_links_inside(&self.grid, "query links", links)?;
        Ok(links
            .iter()
            .map(|l| {
                let mut g = 0.0;
                self.grid
                    .traverse(l.tx, l.rx, |c, w| g += w * sol.values[c]);
                sol.l0 - sol.exponent * l.log_distance() + g
            })
            .collect())
    }
}

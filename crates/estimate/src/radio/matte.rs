//! MATTE, Multi-sensor ATTenuation Estimation (seed 004 §3.2.3, Algorithms 3.1–3.2):
//! attenuation estimated separately for each occupancy class (free, structure, unknown) on a
//! coarse grid (4 m in Table 3.1), and looked up through the fine occupancy grid when
//! integrating along a link (Fig. 3.2). Unknowns `[L0, b, v_free…, v_structure…,
//! v_unknown…]`, `2 + 3·w·h` of them; Tikhonov smoothness λ between 4-neighbours of the same
//! class layer (eq. 3.5) and a prior `φ (v − ρ_class) = 0` on every unknown (§3.2.3: ρ_f,
//! ρ_s = ρ_u), solved exactly by [`super::tomo`].
//!
//! Two slips of the seed, handled here (docs/design/radio.md; tests
//! `algorithm_3_2_as_printed_drops_the_exponent` and
//! `indicator_weights_of_algorithm_3_1_are_biased`):
//! * Algorithm 3.1, line 6 sets the row entry to 1 (an indicator per fine cell), while eq. 3.2
//!   and its note use the segment length. Length weights are the default
//!   ([`MatteWeights::Length`]): their unknowns are in dB per metre, the unit of Table 3.1's
//!   priors, and do not depend on the link's angle to the grid; the indicator is kept as an
//!   option.
//! * Algorithm 3.2, line 4 predicts `x(0) + log10 ‖p‖`, dropping the fitted path-loss
//!   coefficient `x(1)`; the prediction here is `x(0) + x(1)·log10 d + attenuation integral`,
//!   the row model of Algorithm 3.1 line 3.

use super::grid::{CLASSES, ClassGrid, FREE, GridGeometry, STRUCTURE, UNKNOWN};
use super::tomo::{FactorCache, Regularization, TomoRows, TomoSolution, grid_pairs};
use super::{Link, check_links, check_links_inside, check_training};
use crate::{EstimateError, Result};

/// How a fine cell's share of a link enters its row (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MatteWeights {
    /// The length of the link inside the fine cell, metres (eq. 3.2; default).
    Length,
    /// 1 per fine cell crossed (Algorithm 3.1 line 6 as printed).
    Indicator,
}

/// MATTE meta-parameters (Table 3.1, evaluation 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatteOptions {
    /// Cell side of the per-class attenuation grids in metres (Table 3.1: 4.0).
    pub cell: f64,
    /// Smoothness weight λ (Table 3.1, evaluation 1: 2.0).
    pub lambda: f64,
    /// Prior weight φ (0.2).
    pub phi: f64,
    /// Prior attenuation of free space ρ_f, dB per metre (−0.1).
    pub rho_free: f64,
    /// Prior attenuation of structure and unknown space ρ_s = ρ_u, dB per metre (−0.3).
    pub rho_structure: f64,
    /// Row weights.
    pub weights: MatteWeights,
}

impl Default for MatteOptions {
    fn default() -> Self {
        Self {
            cell: 4.0,
            lambda: 2.0,
            phi: 0.2,
            rho_free: -0.1,
            rho_structure: -0.3,
            weights: MatteWeights::Length,
        }
    }
}

/// A MATTE model on a fixed occupancy grid.
#[derive(Debug, Clone)]
pub struct Matte {
    /// The fine occupancy grid.
    pub map: ClassGrid,
    /// The coarse per-class attenuation grid.
    pub coarse: GridGeometry,
    /// Meta-parameters.
    pub options: MatteOptions,
    /// Coarse cell of every fine cell.
    lookup: Vec<u32>,
    rows: TomoRows,
    solution: Option<TomoSolution>,
    cache: FactorCache,
}

impl Matte {
    /// An empty model on `map` (Algorithm 3.1 line 1: the unknowns from the map's bounds).
    /// Errors: `InvalidParameter` for a bad cell size, λ, φ or prior.
    pub fn new(map: ClassGrid, options: MatteOptions) -> Result<Self> {
        for (name, v, nonneg) in [
            ("lambda", options.lambda, true),
            ("phi", options.phi, true),
            ("rho_free", options.rho_free, false),
            ("rho_structure", options.rho_structure, false),
        ] {
            if !v.is_finite() || (nonneg && v < 0.0) {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "must be finite (and non-negative for weights)",
                });
            }
        }
        let g = map.geometry;
        let [x1, y1] = g.far_corner();
        let coarse = GridGeometry::covering(g.origin[0], g.origin[1], x1, y1, options.cell)?;
        let mut lookup = Vec::with_capacity(g.len());
        for i in 0..g.rows {
            for j in 0..g.cols {
                let c = coarse.cell_of(g.center(i, j)).unwrap_or(0);
                lookup.push(c as u32);
            }
        }
        Ok(Self {
            rows: TomoRows::new(CLASSES * coarse.len()),
            map,
            coarse,
            options,
            lookup,
            solution: None,
            cache: FactorCache::default(),
        })
    }

    /// Unknown index of class `class` in coarse cell `cell`.
    fn unknown(&self, class: u8, cell: usize) -> usize {
        class as usize * self.coarse.len() + cell
    }

    /// The row entries of one link (Algorithm 3.1 lines 4–7).
    fn entries(&self, l: &Link, out: &mut Vec<(usize, f64)>) {
        out.clear();
        let indicator = self.options.weights == MatteWeights::Indicator;
        self.map.geometry.traverse(l.tx, l.rx, |c, w| {
            let k = self.unknown(self.map.classes[c], self.lookup[c] as usize);
            out.push((k, if indicator { 1.0 } else { w }));
        });
    }

    /// Appends measurements (Algorithm 3.1 lines 2–10) without solving.
    pub fn add(&mut self, links: &[Link], rss: &[f64]) -> Result<()> {
        check_training(links, rss)?;
        check_links_inside(&self.map.geometry, "training links", links)?;
        let mut entries = Vec::new();
        for (l, &y) in links.iter().zip(rss) {
            self.entries(l, &mut entries);
            self.rows.push(l.log_distance(), &entries, y);
        }
        Ok(())
    }

    /// The regularisation: smoothness within each class layer and the class priors.
    pub fn regularization(&self) -> Regularization {
        let n = self.coarse.len();
        let mut pairs = Vec::new();
        let mut prior = Vec::with_capacity(CLASSES * n);
        for class in [FREE, STRUCTURE, UNKNOWN] {
            pairs.extend(grid_pairs(
                self.coarse.rows,
                self.coarse.cols,
                class as usize * n,
            ));
            let rho = if class == FREE {
                self.options.rho_free
            } else {
                self.options.rho_structure
            };
            prior.extend(std::iter::repeat_n(rho, n));
        }
        Regularization {
            pairs,
            lambda: self.options.lambda,
            phi: self.options.phi,
            prior,
        }
    }

    /// Solves (Algorithm 3.1 lines 11–13) on every measurement added so far, exactly; the
    /// symbolic analysis of the last solve is reused when the couplings have not grown
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

    /// Adds measurements and re-solves.
    pub fn update(&mut self, links: &[Link], rss: &[f64]) -> Result<&TomoSolution> {
        self.add(links, rss)?;
        self.solve()
    }

    /// Builds and solves a model in one call.
    pub fn fit(map: ClassGrid, links: &[Link], rss: &[f64], options: MatteOptions) -> Result<Self> {
        let mut m = Self::new(map, options)?;
        m.update(links, rss)?;
        Ok(m)
    }

    /// The last solution.
    pub fn solution(&self) -> Option<&TomoSolution> {
        self.solution.as_ref()
    }

    /// The measurement rows.
    pub fn rows(&self) -> &TomoRows {
        &self.rows
    }

    /// Predicted RSS (Algorithm 3.2 with the exponent restored):
    /// `L0 − a log10 d + Σ_fine w · v[class, coarse cell]`. Errors: `InvalidProblem` before
    /// a solve, `NonFiniteInput`, `CoincidentLink`, `OutsideMap`.
    pub fn predict(&self, links: &[Link]) -> Result<Vec<f64>> {
        let sol = self
            .solution
            .as_ref()
            .ok_or_else(|| EstimateError::InvalidProblem("MATTE predict before fit".into()))?;
        check_links("query links", links)?;
        check_links_inside(&self.map.geometry, "query links", links)?;
        let mut entries = Vec::new();
        Ok(links
            .iter()
            .map(|l| {
                self.entries(l, &mut entries);
                let g: f64 = entries.iter().map(|&(k, w)| w * sol.values[k]).sum();
                sol.l0 - sol.exponent * l.log_distance() + g
            })
            .collect())
    }

    /// The attenuation map on the fine grid: each fine cell's value `v[class, coarse]` in dB
    /// per metre (Fig. 3.1). Errors: `InvalidProblem` before a solve.
    pub fn attenuation_map(&self) -> Result<Vec<f64>> {
        let sol = self
            .solution
            .as_ref()
            .ok_or_else(|| EstimateError::InvalidProblem("MATTE map before fit".into()))?;
        Ok(self
            .map
            .classes
            .iter()
            .zip(&self.lookup)
            .map(|(&c, &k)| sol.values[self.unknown(c, k as usize)])
            .collect())
    }
}

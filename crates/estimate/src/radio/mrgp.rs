//! The multi-robot Gaussian process, MRGP (seed 004 §3.1 steps 1–4, §3.2.1): the log-distance
//! fit (eq. 3.1) as the mean, a link kernel ([`super::kernel`]) tapered to compact support
//! (eq. 3.4) so the covariance `K_y = K_f + σ_d² I` is sparse, factored by faer's sparse
//! Cholesky (AMD ordering), and hyper-parameters by maximum marginal likelihood (coordinate
//! descent on `l`, σ_f, σ_d with Θ and γ fixed, Table 3.1's values as the start).
//!
//! Unlike the seed, which capped training at min(600, 5 % of m) points for its dense inverse,
//! every training link is used: only pairs within Θ in both endpoints (for one orientation)
//! are stored, found through a hash grid of cell Θ on the transmitters.

use std::collections::HashMap;

use super::kernel::{KernelParams, LinkKernel, PairDistances};
use super::logfit::LogFit;
use super::sparse::{FactorError, LowerCsc, SparseLlt};
use super::{Link, check_links};
use crate::{EstimateError, Result};

/// A fitted MRGP.
#[derive(Debug)]
pub struct Mrgp {
    /// The link kernel.
    pub kernel: LinkKernel,
    /// Hyper-parameters in use.
    pub params: KernelParams,
    /// The log-fit mean.
    pub mean: LogFit,
    links: Vec<Link>,
    residual: Vec<f64>,
    hash: HashMap<(i64, i64), Vec<u32>>,
    pattern: LowerCsc,
    distances: Vec<PairDistances>,
    llt: SparseLlt,
    alpha: Vec<f64>,
    log_ml: f64,
}

fn cell(p: [f64; 2], size: f64) -> (i64, i64) {
    ((p[0] / size).floor() as i64, (p[1] / size).floor() as i64)
}

fn hash_links(links: &[Link], size: f64) -> HashMap<(i64, i64), Vec<u32>> {
    let mut h: HashMap<(i64, i64), Vec<u32>> = HashMap::new();
    for (i, l) in links.iter().enumerate() {
        h.entry(cell(l.tx, size)).or_default().push(i as u32);
    }
    h
}

/// Indices `≥ first` of links (in `hash`) that may couple with `q` (a superset of the
/// kernel's support), in no particular order; `mark`/`stamp` deduplicate. The fit asks for
/// `first = j` (the lower triangle), so the distances of the upper one are never computed.
#[allow(clippy::too_many_arguments)]
fn candidates(
    q: &Link,
    links: &[Link],
    hash: &HashMap<(i64, i64), Vec<u32>>,
    theta: f64,
    first: usize,
    mark: &mut [u32],
    stamp: u32,
    out: &mut Vec<(usize, PairDistances)>,
) {
    out.clear();
    for centre in [q.tx, q.rx] {
        let (ci, cj) = cell(centre, theta);
        for di in -1..=1 {
            for dj in -1..=1 {
                if let Some(list) = hash.get(&(ci + di, cj + dj)) {
                    for &j in list {
                        let j = j as usize;
                        if j < first || mark[j] == stamp {
                            continue;
                        }
                        let d = PairDistances::new(q, &links[j]);
                        if LinkKernel::may_couple(&d, theta) {
                            mark[j] = stamp;
                            out.push((j, d));
                        }
                    }
                }
            }
        }
    }
}

fn check_params(p: &KernelParams) -> Result<()> {
    for (name, v) in [
        ("length_scale", p.length_scale),
        ("sigma_f", p.sigma_f),
        ("sigma_d", p.sigma_d),
        ("theta", p.theta),
        ("gamma", p.gamma),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name,
                value: v,
                reason: "must be positive and finite",
            });
        }
    }
    Ok(())
}

impl Mrgp {
    /// Fits the MRGP to `rss` on `links` (every link is a training point). With `optimize`,
    /// `l`, σ_f and σ_d maximise the marginal likelihood starting from `params`.
    ///
    /// Errors: those of [`LogFit::fit`]; `InvalidParameter` for a non-positive
    /// hyper-parameter; `KernelNotPositiveDefinite` when the covariance cannot be factored
    /// (for [`LinkKernel::Ds4`], checked on `K_f` itself, without the noise that can hide it).
    pub fn fit(
        links: &[Link],
        rss: &[f64],
        kernel: LinkKernel,
        params: KernelParams,
        optimize: bool,
    ) -> Result<Mrgp> {
        check_params(&params)?;
        let mean = LogFit::fit(links, rss)?;
        let residual: Vec<f64> = links
            .iter()
            .zip(rss)
            .map(|(l, y)| y - mean.mean(l))
            .collect();
        let n = links.len();
        let hash = hash_links(links, params.theta);
        // Pattern of the lower triangle: for column j, rows i ≥ j that may couple.
        let mut mark = vec![u32::MAX; n];
        let mut cand = Vec::new();
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut distances = Vec::new();
        col_ptr.push(0);
        for j in 0..n {
            candidates(
                &links[j],
                links,
                &hash,
                params.theta,
                j,
                &mut mark,
                j as u32,
                &mut cand,
            );
            cand.sort_unstable_by_key(|(i, _)| *i);
            for (i, d) in &cand {
                row_idx.push(*i);
                distances.push(*d);
            }
            col_ptr.push(row_idx.len());
        }
        let pattern = LowerCsc {
            n,
            values: vec![0.0; row_idx.len()],
            col_ptr,
            row_idx,
        };
        let llt = SparseLlt::analyse(&pattern)?;
        let mut gp = Mrgp {
            kernel,
            params,
            mean,
            links: links.to_vec(),
            residual,
            hash,
            pattern,
            distances,
            llt,
            alpha: Vec::new(),
            log_ml: f64::NAN,
        };
        if kernel == LinkKernel::Ds4 {
            gp.check_kernel_pd()?;
        }
        if optimize {
            gp.optimize()?;
        }
        gp.refactor(gp.params)?;
        Ok(gp)
    }

    /// Fills the pattern with `K_f + noise·I`.
    fn fill(&mut self, p: &KernelParams, noise: f64) {
        for j in 0..self.pattern.n {
            for q in self.pattern.col_ptr[j]..self.pattern.col_ptr[j + 1] {
                let mut v = self.kernel.eval(&self.distances[q], p);
                if self.pattern.row_idx[q] == j {
                    v += noise;
                }
                self.pattern.values[q] = v;
            }
        }
    }

    /// Factors `K_f + 10⁻⁶σ_f² I`: a kernel matrix that is not positive definite fails here
    /// even when the noise σ_d² would mask it.
    fn check_kernel_pd(&mut self) -> Result<()> {
        let p = self.params;
        self.fill(&p, 1e-6 * p.sigma_f * p.sigma_f);
        self.llt
            .factor(&self.pattern.values)
            .map_err(|FactorError::NotPositiveDefinite(column)| {
                EstimateError::KernelNotPositiveDefinite {
                    kernel: self.kernel.name().into(),
                    links: self.pattern.n,
                    column,
                }
            })
    }

    /// Factors `K_y` for `p`, sets α = K_y⁻¹ r and the log marginal likelihood
    /// `−½ rᵀα − ½ log|K_y| − (n/2) log 2π`.
    fn refactor(&mut self, p: KernelParams) -> Result<f64> {
        self.fill(&p, p.sigma_d * p.sigma_d);
        self.llt.factor(&self.pattern.values).map_err(
            |FactorError::NotPositiveDefinite(column)| EstimateError::KernelNotPositiveDefinite {
                kernel: self.kernel.name().into(),
                links: self.pattern.n,
                column,
            },
        )?;
        let mut alpha = self.residual.clone();
        self.llt.solve_in_place(&mut alpha, 1)?;
        let n = self.pattern.n as f64;
        let fit: f64 = alpha.iter().zip(&self.residual).map(|(a, r)| a * r).sum();
        self.log_ml =
            -0.5 * fit - 0.5 * self.llt.log_det() - 0.5 * n * (2.0 * std::f64::consts::PI).ln();
        self.alpha = alpha;
        self.params = p;
        Ok(self.log_ml)
    }

    /// Coordinate descent on `ln l`, `ln σ_f`, `ln σ_d` (golden-section search on each,
    /// two sweeps), Θ and γ fixed (the seed sweeps them offline for a CPU budget).
    fn optimize(&mut self) -> Result<()> {
        let bounds = [(0.5f64, 200.0f64), (0.05, 50.0), (0.05, 50.0)];
        let mut best = self.params;
        let mut best_ml = self.refactor(best)?;
        let set = |p: &mut KernelParams, k: usize, v: f64| match k {
            0 => p.length_scale = v,
            1 => p.sigma_f = v,
            _ => p.sigma_d = v,
        };
        let phi = (5f64.sqrt() - 1.0) / 2.0;
        for _sweep in 0..2 {
            for (k, &(lo, hi)) in bounds.iter().enumerate() {
                let (mut a, mut b) = (lo.ln(), hi.ln());
                let eval = |x: f64, gp: &mut Mrgp| -> f64 {
                    let mut p = best;
                    set(&mut p, k, x.exp());
                    gp.refactor(p).unwrap_or(f64::NEG_INFINITY)
                };
                let mut c = b - phi * (b - a);
                let mut d = a + phi * (b - a);
                let (mut fc, mut fd) = (eval(c, self), eval(d, self));
                while b - a > 0.02 {
                    if fc > fd {
                        b = d;
                        d = c;
                        fd = fc;
                        c = b - phi * (b - a);
                        fc = eval(c, self);
                    } else {
                        a = c;
                        c = d;
                        fc = fd;
                        d = a + phi * (b - a);
                        fd = eval(d, self);
                    }
                }
                let x = 0.5 * (a + b);
                let fx = eval(x, self);
                if fx > best_ml {
                    best_ml = fx;
                    set(&mut best, k, x.exp());
                }
            }
        }
        // The last trial factorised other parameters: refactor at the best ones, so the
        // factor, `alpha` and the likelihood agree with `params`.
        self.refactor(best)?;
        Ok(())
    }

    /// Log marginal likelihood of the training residuals under the current hyper-parameters.
    pub fn log_marginal_likelihood(&self) -> f64 {
        self.log_ml
    }

    /// Stored entries of the lower triangle of `K_y`.
    pub fn covariance_nnz(&self) -> usize {
        self.pattern.nnz()
    }

    /// Stored entries of its Cholesky factor.
    pub fn factor_nnz(&self) -> usize {
        self.llt.factor_nnz()
    }

    /// Number of training links.
    pub fn len(&self) -> usize {
        self.links.len()
    }

    /// Whether there is no training link (never true for a fitted model).
    pub fn is_empty(&self) -> bool {
        self.links.is_empty()
    }

    /// Adds measurements and refits with the current hyper-parameters (the pattern grows, so
    /// the symbolic analysis is redone).
    pub fn update(&mut self, links: &[Link], rss: &[f64]) -> Result<()> {
        let mut all = self.links.clone();
        all.extend_from_slice(links);
        let mut y: Vec<f64> = self
            .links
            .iter()
            .zip(&self.residual)
            .map(|(l, r)| r + self.mean.mean(l))
            .collect();
        y.extend_from_slice(rss);
        *self = Mrgp::fit(&all, &y, self.kernel, self.params, false)?;
        Ok(())
    }

    /// Predictive means `m(x*) + k*ᵀ α` and, with `variance`, the latent variances
    /// `k(x*, x*) − k*ᵀ K_y⁻¹ k*` (add σ_d² for a new measurement). Errors:
    /// `NonFiniteInput`, `CoincidentLink`.
    pub fn predict(&self, links: &[Link], variance: bool) -> Result<(Vec<f64>, Option<Vec<f64>>)> {
        check_links("query links", links)?;
        let n = self.links.len();
        let theta = self.params.theta;
        let mut mark = vec![u32::MAX; n];
        let mut cand = Vec::new();
        let mut means = Vec::with_capacity(links.len());
        let mut kstar: Vec<Vec<(usize, f64)>> = Vec::new();
        for (qi, q) in links.iter().enumerate() {
            candidates(
                q,
                &self.links,
                &self.hash,
                theta,
                0,
                &mut mark,
                qi as u32,
                &mut cand,
            );
            let mut m = self.mean.mean(q);
            let mut ks = Vec::new();
            for (j, d) in &cand {
                let k = self.kernel.eval(d, &self.params);
                if k != 0.0 {
                    m += k * self.alpha[*j];
                    if variance {
                        ks.push((*j, k));
                    }
                }
            }
            means.push(m);
            if variance {
                kstar.push(ks);
            }
        }
        if !variance {
            return Ok((means, None));
        }
        const BATCH: usize = 32;
        let mut vars = Vec::with_capacity(links.len());
        for (chunk_q, chunk_k) in links.chunks(BATCH).zip(kstar.chunks(BATCH)) {
            let k = chunk_q.len();
            let mut b = vec![0.0; n * k];
            for (c, ks) in chunk_k.iter().enumerate() {
                for &(j, v) in ks {
                    b[c * n + j] = v;
                }
            }
            self.llt.solve_in_place(&mut b, k)?;
            for (c, (q, ks)) in chunk_q.iter().zip(chunk_k).enumerate() {
                let kqq = self.kernel.eval(&PairDistances::new(q, q), &self.params);
                let quad: f64 = ks.iter().map(|&(j, v)| v * b[c * n + j]).sum();
                vars.push((kqq - quad).max(0.0));
            }
        }
        Ok((means, Some(vars)))
    }

    /// The dense kernel matrix `K_f` (no noise) of `links` (tests and peer comparisons).
    pub fn kernel_matrix(links: &[Link], kernel: LinkKernel, params: &KernelParams) -> Vec<f64> {
        let n = links.len();
        let mut k = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                k[i * n + j] = kernel.eval(&PairDistances::new(&links[i], &links[j]), params);
            }
        }
        k
    }
}

//! Global registration with a selection a distractor cannot win (000_3b1454b2b2194811.txt §3.4,
//! eq. (3.19)–(3.22), Algorithm 3, Fig. 3.14; issue 29).
//!
//! The stages, each a quantity of the data rather than a tuned threshold:
//! 1. **Diverse hypotheses.** Global voting ([`global_voting`], Algorithm 3 with the Y-count)
//!    returns its `top_k` cells after non-maximum suppression in transform space (a cell within
//!    1.5 bins, in angle and translation, of a better one is dropped), so the K hypotheses are
//!    K distinct basins, not K neighbours of one peak.
//! 2. **Local refinement.** Each hypothesis starts a rigid CPD (eq. (3.12)–(3.15), no scale, with
//!    the outlier weight `w`) of a subsample of the template onto the scene points inside a
//!    window around the moved template (its bounding sphere grown by `window ×` the shape
//!    size), so clutter far away neither drags the mixture nor inflates its initial σ².
//! 3. **Selection.** Every refined hypothesis is scored on a common scale: the inlier radius
//!    `r = max(3·√(D·σ̂²), h)`, where `σ̂²` is the smallest converged CPD variance over the
//!    hypotheses (the noise of the best explanation) and `h` the template's median point
//!    spacing (a scene sampled at other positions is up to `h/2` away even without noise).
//!    - `explained`: the fraction of template points with a scene point within `r`;
//!    - `log_likelihood`: the CPD mixture (eq. (3.12)) with its uniform outlier term `w/V` (V =
//!      volume of the scene's bounding box) at the common `σ̂²`, as
//!      `Σ_n log(1 + (1−w)V/(wM) Σ_m 𝒩(x_n; T(y_m), σ̂²I))` (the constant `N log(w/V)` dropped);
//!    - `energy` (when asked): the deformation energy `tr(Wᵀ G W)` (eq. (3.17)) of a non-rigid
//!      CPD from the refined pose, the seed's ranking.
//!
//!    The default criterion is `explained`: a partial or rescaled copy cannot place every
//!    template point on the scene, clutter only adds false inliers at the rate of its density
//!    inside a radius-`r` tube, and it does not depend on the unknown amount of clutter the way the
//!    likelihood does (docs/design/global_registration.md compares the three).
//! 4. **Symmetry.** The template is voted onto itself; every self-map (other than the identity)
//!    that, refined by rigid CPD, puts at least `symmetry_fraction` of the template within `r` of
//!    the template is a symmetry. For each, the pose `best ∘ S` is among the candidates (added
//!    if voting missed it), marked `equivalent`, and the result says `ambiguous`.
//! 5. A full-resolution rigid CPD from the chosen pose (and optionally a non-rigid one).

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::{NonrigidOptions, NonrigidResult, RigidOptions, RigidResult, nonrigid, rigid};
use crate::voting::{RigidHypothesis, VotingOptions, global_voting};
use crate::{DetectError, Result};

mod scoring;
mod trim;

use scoring::{Index, median_spacing, subsample_rows};

/// How [`global_register`] chooses among its refined hypotheses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// Largest fraction of template points with a scene point within the inlier radius (ties:
    /// larger likelihood). The default.
    Explained,
    /// Largest CPD likelihood with the outlier term, at the common σ̂².
    Likelihood,
    /// Least deformation energy of the non-rigid CPD from the refined pose (seed Fig. 3.14).
    Energy,
}

/// Options of [`global_register`].
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalRegisterOptions {
    /// Global voting; `top_k` is the number of suppressed hypotheses refined (default 8;
    /// `max_points` default 200).
    pub voting: VotingOptions,
    /// Outlier weight `w` of the CPD runs and of the likelihood (default 0.5).
    pub w: f64,
    /// Maximum iterations of each rigid CPD refinement (default 10; the sharpening finishes).
    pub max_iterations: usize,
    /// Iterations of the trimmed nearest-neighbour sharpening after each CPD (default 10; see
    /// the `trim` module).
    pub sharpen_iterations: usize,
    /// At most this many template points are refined and scored per hypothesis (uniform stride;
    /// default 100); the scene window is capped at four times as many.
    pub max_refine_points: usize,
    /// Scene window around a moved template: its bounding sphere grown by this fraction of the
    /// shape size (default 0.25).
    pub window: f64,
    /// The selection criterion.
    pub criterion: Criterion,
    /// Compute the deformation energy of every hypothesis (always done for [`Criterion::Energy`]).
    pub energy_all: bool,
    /// Non-rigid CPD used for the energy score (and the final non-rigid refinement).
    pub nonrigid: NonrigidOptions,
    /// Run the non-rigid CPD from the chosen pose at full resolution too.
    pub final_nonrigid: bool,
    /// A self-map of the template is a symmetry when it puts at least this fraction of the
    /// template within the inlier radius of the template (default 0.9).
    pub symmetry_fraction: f64,
}

impl Default for GlobalRegisterOptions {
    fn default() -> Self {
        let mut nonrigid = NonrigidOptions::default();
        nonrigid.cpd.w = 0.5;
        Self {
            voting: VotingOptions {
                top_k: 8,
                max_points: 200,
                ..VotingOptions::default()
            },
            w: 0.5,
            max_iterations: 10,
            sharpen_iterations: 10,
            max_refine_points: 100,
            window: 0.25,
            criterion: Criterion::Explained,
            energy_all: false,
            nonrigid,
            final_nonrigid: false,
            symmetry_fraction: 0.9,
        }
    }
}

/// One refined hypothesis of [`global_register`].
#[derive(Debug, Clone, PartialEq)]
pub struct RegistrationCandidate {
    /// The voting hypothesis it started from (for an added symmetric pose: `best ∘ S`, with
    /// zero votes).
    pub initial: RigidHypothesis,
    /// Refined rotation (`x ≈ R y + t`).
    pub rotation: DMatrix<f64>,
    /// Refined translation.
    pub translation: DVector<f64>,
    /// Converged σ² of its rigid CPD.
    pub sigma2: f64,
    /// Fraction of (subsampled) template points with a scene point within the inlier radius.
    pub explained: f64,
    /// `Σ_n log(1 + (1−w)V/(wM) Σ_m 𝒩(x_n; T(y_m), σ̂²I))` over the scene (module docs).
    pub log_likelihood: f64,
    /// Deformation energy `tr(Wᵀ G W)` of a non-rigid CPD from the refined pose, when computed.
    pub energy: Option<f64>,
    /// This pose is the chosen one composed with a symmetry of the template.
    pub equivalent: bool,
}

/// The result of [`global_register`].
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalRegistration {
    /// Candidates, best first by the criterion; symmetric equivalents of the best follow it.
    pub candidates: Vec<RegistrationCandidate>,
    /// Self-maps `(R, t)` of the template found to be symmetries (`y ≈ R y + t` as a set).
    pub symmetries: Vec<(DMatrix<f64>, DVector<f64>)>,
    /// The template has a symmetry: several poses explain the scene equally well.
    pub ambiguous: bool,
    /// Inlier radius `r` used by the scores.
    pub inlier_radius: f64,
    /// Common σ̂² of the scores.
    pub sigma2: f64,
    /// Full-resolution rigid CPD from the chosen pose (`transformed` is the registered template).
    pub rigid: RigidResult,
    /// Full-resolution non-rigid CPD from the rigid result, if asked.
    pub nonrigid: Option<NonrigidResult>,
}

fn validate(o: &GlobalRegisterOptions) -> Result<()> {
    let bad = |what, value: f64, reason| {
        Err(DetectError::InvalidParameter {
            what,
            value,
            reason,
        })
    };
    if !(o.w.is_finite() && (0.0..1.0).contains(&o.w) && o.w > 0.0) {
        return bad(
            "w",
            o.w,
            "must be in (0, 1): the likelihood needs an outlier term",
        );
    }
    if o.max_iterations == 0 {
        return bad("max_iterations", 0.0, "must be at least 1");
    }
    if o.max_refine_points < 4 {
        return bad(
            "max_refine_points",
            o.max_refine_points as f64,
            "must be at least 4",
        );
    }
    if !(o.window.is_finite() && o.window >= 0.0) {
        return bad("window", o.window, "must be non-negative and finite");
    }
    if !(o.symmetry_fraction.is_finite() && o.symmetry_fraction > 0.0 && o.symmetry_fraction <= 1.0)
    {
        return bad(
            "symmetry_fraction",
            o.symmetry_fraction,
            "must be in (0, 1]",
        );
    }
    Ok(())
}

/// `R p + t` for every row.
fn apply(p: &DMatrix<f64>, r: &DMatrix<f64>, t: &DVector<f64>) -> DMatrix<f64> {
    let mut m = p * r.transpose();
    for mut row in m.row_iter_mut() {
        row += t.transpose();
    }
    m
}

/// Diagonal of the bounding box.
fn extent(p: &DMatrix<f64>) -> f64 {
    (0..p.ncols())
        .map(|c| {
            let col = p.column(c);
            (col.max() - col.min()).powi(2)
        })
        .sum::<f64>()
        .sqrt()
}

fn rotation_angle(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    let d = a.nrows() as f64;
    let tr = (a.transpose() * b).trace();
    // 2-D: tr = 2 cos θ; 3-D: tr = 1 + 2 cos θ.
    let c = if d == 2.0 { tr / 2.0 } else { (tr - 1.0) / 2.0 };
    c.clamp(-1.0, 1.0).acos()
}

/// Rows of `x` within `radius` of `centre`, capped at `cap` by a uniform stride.
fn window_rows(x: &DMatrix<f64>, centre: &DVector<f64>, radius: f64, cap: usize) -> DMatrix<f64> {
    let rows: Vec<usize> = (0..x.nrows())
        .filter(|&r| (x.row(r).transpose() - centre).norm() <= radius)
        .collect();
    let keep = subsample_rows(rows.len(), cap);
    DMatrix::from_fn(keep.len(), x.ncols(), |r, c| x[(rows[keep[r]], c)])
}

/// A refined pose `(R, t, σ²)`.
type Pose = (DMatrix<f64>, DVector<f64>, f64);

/// Shared inputs of the per-hypothesis refinement.
struct Refiner<'a> {
    x: &'a DMatrix<f64>,
    index: &'a Index,
    /// Template subsample.
    ys: &'a DMatrix<f64>,
    size: f64,
    /// Template point spacing.
    h: f64,
    /// Initial σ² of the CPD: the voting's own accuracy (module docs).
    sigma2_0: f64,
    o: &'a GlobalRegisterOptions,
}

impl Refiner<'_> {
    /// Rigid CPD (no scale) of the template moved by `(r0, t0)` onto the scene window around it,
    /// then trimmed sharpening ([`trim::sharpen`]); the composed pose and its σ². `None` when
    /// the window holds too few points or the CPD fails on them.
    fn refine(&self, r0: &DMatrix<f64>, t0: &DVector<f64>) -> Result<Option<Pose>> {
        let (y, o) = (self.ys, self.o);
        let d = y.ncols();
        let moved = apply(y, r0, t0);
        let centre = DVector::from_fn(d, |c, _| moved.column(c).mean());
        let reach = (0..moved.nrows())
            .map(|r| (moved.row(r).transpose() - &centre).norm())
            .fold(0.0, f64::max);
        let xw = window_rows(
            self.x,
            &centre,
            reach + o.window * self.size,
            4 * o.max_refine_points,
        );
        if xw.nrows() < d + 1 {
            return Ok(None);
        }
        let mut opts = RigidOptions {
            scale: false,
            ..RigidOptions::default()
        };
        opts.cpd.w = o.w;
        opts.cpd.max_iterations = o.max_iterations;
        opts.cpd.sigma2 = Some(self.sigma2_0);
        let (r, t, s2) = match rigid(&xw, &moved, &opts) {
            Ok(res) => (
                &res.rotation * r0,
                &res.rotation * t0 + &res.translation,
                res.sigma2,
            ),
            Err(DetectError::Degenerate { .. }) => return Ok(None),
            Err(e) => return Err(e),
        };
        Ok(Some(trim::sharpen(
            self.index,
            self.x,
            y,
            &r,
            &t,
            s2,
            self.h,
            o.sharpen_iterations,
        )))
    }
}

/// Global registration of a template `y` (M×D) into a scene `x` (N×D), D ∈ {2, 3}: diverse
/// voting hypotheses refined by rigid CPD and chosen by a criterion a distractor cannot win,
/// with the template's symmetries reported (module docs).
///
/// Errors: those of [`global_voting`] and of the CPD (bad shapes, NaN/∞, too few points, all
/// points identical, invalid options); `Degenerate` when voting finds no cluster or no
/// hypothesis can be refined.
pub fn global_register(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    options: &GlobalRegisterOptions,
) -> Result<GlobalRegistration> {
    validate(options)?;
    let hyps = global_voting(x, y, &options.voting)?;
    if hyps.is_empty() {
        return Err(DetectError::Degenerate {
            reason: format!(
                "global voting found no cluster with at least {} votes",
                options.voting.min_votes
            ),
        });
    }
    let d = y.ncols();
    let size = extent(y);
    let keep = subsample_rows(y.nrows(), options.max_refine_points);
    let ys = DMatrix::from_fn(keep.len(), d, |r, c| y[(keep[r], c)]);
    let h = median_spacing(&ys)?;
    let index = Index::new(x)?;
    let rms_radius = {
        let c = DVector::from_fn(d, |k, _| ys.column(k).mean());
        ((0..ys.nrows())
            .map(|r| (ys.row(r).transpose() - &c).norm_squared())
            .sum::<f64>()
            / ys.nrows() as f64)
            .sqrt()
    };
    // The voting hypothesis is accurate to about one angle bin over the template's radius (the
    // default translation bin): that is the CPD's initial σ (per coordinate).
    let sigma2_0 = ((options.voting.angle_bin * rms_radius).powi(2) / d as f64).max(h * h);
    let refiner = Refiner {
        x,
        index: &index,
        ys: &ys,
        size,
        h,
        sigma2_0,
        o: options,
    };
    #[allow(clippy::type_complexity)]
    let refined: Vec<Result<Option<(RigidHypothesis, DMatrix<f64>, DVector<f64>, f64)>>> = hyps
        .into_par_iter()
        .map(|hy| {
            let r = refiner.refine(&hy.rotation, &hy.translation)?;
            Ok(r.map(|(r, t, s2)| (hy, r, t, s2)))
        })
        .collect();
    let mut poses = Vec::new();
    for r in refined {
        if let Some(p) = r? {
            poses.push(p);
        }
    }
    if poses.is_empty() {
        return Err(DetectError::Degenerate {
            reason: "no voting hypothesis could be refined: every scene window was empty".into(),
        });
    }
    let sigma2 = poses
        .iter()
        .map(|p| p.3)
        .fold(f64::INFINITY, f64::min)
        .max(f64::MIN_POSITIVE);
    let radius = (3.0 * (d as f64 * sigma2).sqrt()).max(h);
    let volume = (0..d)
        .map(|c| {
            let col = x.column(c);
            (col.max() - col.min()).max(radius)
        })
        .product::<f64>();
    let scorer = scoring::Scorer {
        index: &index,
        radius,
        sigma2,
        w: options.w,
        volume,
        n_scene: x.nrows(),
    };
    let want_energy = options.energy_all || options.criterion == Criterion::Energy;
    let score = |initial: RigidHypothesis, r: DMatrix<f64>, t: DVector<f64>, s2: f64, eq: bool| {
        let moved = apply(&ys, &r, &t);
        let energy = if want_energy {
            energy_of(x, &moved, size, options)?
        } else {
            None
        };
        Ok::<_, DetectError>(RegistrationCandidate {
            initial,
            explained: scorer.explained(&moved),
            log_likelihood: scorer.log_likelihood(&moved),
            rotation: r,
            translation: t,
            sigma2: s2,
            energy,
            equivalent: eq,
        })
    };
    let mut candidates = poses
        .into_par_iter()
        .map(|(hy, r, t, s2)| score(hy, r, t, s2, false))
        .collect::<Result<Vec<_>>>()?;
    rank(&mut candidates, options.criterion);

    // Symmetries of the template: vote it onto itself, refine, verify.
    let symmetries = symmetries(&ys, size, radius, sigma2_0, options)?;
    let best = candidates[0].clone();
    let mut equivalents = Vec::new();
    for (rs, ts) in &symmetries {
        let r0 = &best.rotation * rs;
        let t0 = &best.rotation * ts + &best.translation;
        let found = candidates.iter().position(|c| {
            !c.equivalent
                && rotation_angle(&c.rotation, &r0) <= 1.5 * options.voting.angle_bin
                && (&c.translation - &t0).norm() <= 0.05 * size
        });
        let cand = match found {
            Some(i) => {
                let mut c = candidates.remove(i);
                c.equivalent = true;
                c
            }
            None => {
                let initial = RigidHypothesis {
                    rotation: r0.clone(),
                    translation: t0.clone(),
                    votes: 0,
                    pair_votes: 0,
                };
                match refiner.refine(&r0, &t0)? {
                    Some((r, t, s2)) => score(initial, r, t, s2, true)?,
                    None => continue,
                }
            }
        };
        equivalents.push(cand);
    }
    let n_eq = equivalents.len();
    candidates.splice(1..1, equivalents);
    let ambiguous = n_eq > 0;

    // Full resolution from the chosen pose: the trimmed sharpening on every template point (a
    // CPD E-step over all M·N pairs would cost more than the whole search in 3-D).
    let chosen = &candidates[0];
    let (rf, tf, s2f) = trim::sharpen(
        &index,
        x,
        y,
        &chosen.rotation,
        &chosen.translation,
        chosen.sigma2,
        h,
        options.sharpen_iterations,
    );
    let transformed = apply(y, &rf, &tf);
    let rigid_res = RigidResult {
        rotation: rf,
        translation: tf,
        scale: 1.0,
        transformed,
        sigma2: s2f,
        iterations: options.sharpen_iterations,
        converged: true,
        p: None,
    };
    let xw = {
        let centre = DVector::from_fn(d, |c, _| rigid_res.transformed.column(c).mean());
        let reach = (0..y.nrows())
            .map(|r| (rigid_res.transformed.row(r).transpose() - &centre).norm())
            .fold(0.0, f64::max);
        window_rows(x, &centre, reach + options.window * size, usize::MAX)
    };
    let nonrigid_res = if options.final_nonrigid {
        let mut no = options.nonrigid.clone();
        no.cpd.sigma2 = Some(rigid_res.sigma2);
        Some(nonrigid(&xw, &rigid_res.transformed, &no)?)
    } else {
        None
    };
    Ok(GlobalRegistration {
        candidates,
        symmetries,
        ambiguous,
        inlier_radius: radius,
        sigma2,
        rigid: rigid_res,
        nonrigid: nonrigid_res,
    })
}

/// Deformation energy of a non-rigid CPD of `moved` onto its scene window.
fn energy_of(
    x: &DMatrix<f64>,
    moved: &DMatrix<f64>,
    size: f64,
    o: &GlobalRegisterOptions,
) -> Result<Option<f64>> {
    let d = moved.ncols();
    let centre = DVector::from_fn(d, |c, _| moved.column(c).mean());
    let reach = (0..moved.nrows())
        .map(|r| (moved.row(r).transpose() - &centre).norm())
        .fold(0.0, f64::max);
    let xw = window_rows(x, &centre, reach + o.window * size, 4 * o.max_refine_points);
    if xw.nrows() < d + 1 {
        return Ok(None);
    }
    match nonrigid(&xw, moved, &o.nonrigid) {
        Ok(r) => Ok(Some(r.energy)),
        Err(DetectError::Degenerate { .. }) => Ok(None),
        Err(e) => Err(e),
    }
}

/// Sort best first by `criterion`.
fn rank(c: &mut [RegistrationCandidate], criterion: Criterion) {
    match criterion {
        Criterion::Explained => c.sort_by(|a, b| {
            b.explained
                .total_cmp(&a.explained)
                .then(b.log_likelihood.total_cmp(&a.log_likelihood))
        }),
        Criterion::Likelihood => c.sort_by(|a, b| b.log_likelihood.total_cmp(&a.log_likelihood)),
        Criterion::Energy => c.sort_by(|a, b| {
            a.energy
                .unwrap_or(f64::INFINITY)
                .total_cmp(&b.energy.unwrap_or(f64::INFINITY))
        }),
    }
}

/// Non-identity self-maps `(R, t)` of `ys` that put at least `symmetry_fraction` of it within
/// `radius` of itself after a rigid CPD refinement; duplicates (same rotation within 1.5 angle
/// bins) dropped.
fn symmetries(
    ys: &DMatrix<f64>,
    size: f64,
    radius: f64,
    sigma2_0: f64,
    o: &GlobalRegisterOptions,
) -> Result<Vec<(DMatrix<f64>, DVector<f64>)>> {
    let d = ys.ncols();
    let self_votes = global_voting(ys, ys, &o.voting)?;
    // A symmetry maps every template point onto the template, so it collects about as many
    // distinct-point votes as the identity; a self-map with under half of the best count
    // cannot put `symmetry_fraction` ≥ ½ of the template on itself.
    let top = self_votes.iter().map(|s| s.votes).max().unwrap_or(0);
    let self_votes: Vec<RigidHypothesis> = self_votes
        .into_iter()
        .filter(|s| 2 * s.votes >= top)
        .collect();
    let index = Index::new(ys)?;
    let eye = DMatrix::<f64>::identity(d, d);
    let mut out: Vec<(DMatrix<f64>, DVector<f64>)> = Vec::new();
    for s in self_votes {
        let moved = apply(ys, &s.rotation, &s.translation);
        let mut ro = RigidOptions {
            scale: false,
            ..RigidOptions::default()
        };
        ro.cpd.max_iterations = o.max_iterations;
        ro.cpd.w = 0.1;
        ro.cpd.sigma2 = Some(sigma2_0);
        let Ok(res) = rigid(ys, &moved, &ro) else {
            continue;
        };
        let r = &res.rotation * &s.rotation;
        let t = &res.rotation * &s.translation + &res.translation;
        let is_identity =
            rotation_angle(&r, &eye) <= 1.5 * o.voting.angle_bin && t.norm() <= 0.05 * size;
        if is_identity
            || out
                .iter()
                .any(|(rr, _)| rotation_angle(rr, &r) <= 1.5 * o.voting.angle_bin)
        {
            continue;
        }
        let fraction = index.fraction_within(&apply(ys, &r, &t), radius);
        if fraction >= o.symmetry_fraction {
            out.push((r, t));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests;

//! The chain of gates of the detect front end (000_3b1454b2b2194811.txt §5.3): a first estimate
//! from the tracked rims, then every detected edge re-associated with the projected estimate
//! under shrinking gates ([`gate_edges`]), solving again after each gate.

use std::collections::{BTreeMap, BTreeSet};

use super::{SlamMotInputs, SolvePlan, solve};
use crate::handeye::gating::{DetectedEdges, GateConfig, GateStats, gate_edges};
use crate::handeye::slam::{EdgeObservation, SlamMotSolution, SlamMotState};
use crate::{EstimateError, Result};

/// The gating chain's rules.
#[derive(Debug, Clone, PartialEq)]
pub struct GatingPlan {
    /// The gates (pixels) of the re-association rounds, in order (e.g. 3, 1.5, 1).
    pub gates_px: Vec<f64>,
    /// Also run the chain from level wafers (the nominal carrier): the tracks may mix wafers,
    /// so the first estimate can sit in a mirrored-tilt basin.
    pub reset_tilts: bool,
    /// The association rules; `gate_px` is replaced by each gate, and `min_band_px` and
    /// `band_weights` apply to the last gate only (they thin the points, not the association).
    pub gate: GateConfig,
    /// Wafers gated into fewer frames are dropped (reported in [`GatedStart::too_few_views`]).
    pub min_wafer_frames: usize,
    /// The first solve's height search `(low, high, step)` (m), [`SolvePlan::init_heights`].
    pub first_heights: (f64, f64, f64),
    /// Re-fit wafers by the basin search after each solve ([`SolvePlan::basin_search`]).
    pub basin_search: bool,
}

/// The winning chain's observations and the start of the final solve.
#[derive(Debug, Clone, PartialEq)]
pub struct GatedStart {
    /// The kept observations (wafers with too few views removed).
    pub observations: Vec<EdgeObservation>,
    /// The estimate the last gate was taken from (base, offsets, wafers; default mount and links).
    pub start: SlamMotState,
    /// The last gate's counts; `rims_used` and `frames_used` count the kept observations.
    pub stats: GateStats,
    /// The gate of the winning chain's last round (pixels).
    pub last_gate_px: f64,
    /// Wafers gated into fewer than `min_wafer_frames` frames, removed.
    pub too_few_views: Vec<usize>,
}

/// Runs the chain of gates: a first solve of the `tracked` observations (robust loss, height
/// search), then for each gate the association of every detected edge with that estimate's
/// projection and a new solve of the gated edges. With `reset_tilts` a second chain starts its
/// first new solve from level wafers; the chain whose estimate explains more edges in its last
/// gate wins (the first on a tie). A chain whose solve fails on its own associations (a rim
/// behind a camera: its gated edges mixed wafers) or that gates nothing drops out.
///
/// # Errors
/// [`EstimateError::InvalidInput`] when no chain associates any edge; the errors of the first
/// solve and of the gating.
pub fn gate_and_resolve(
    inputs: &SlamMotInputs,
    tracked: Vec<EdgeObservation>,
    start: &SlamMotState,
    detected: &DetectedEdges<'_>,
    plan: &GatingPlan,
) -> Result<GatedStart> {
    if plan.gates_px.is_empty() {
        return Err(EstimateError::InvalidInput(
            "gates_px needs at least one gate (pixels), got none".into(),
        ));
    }
    let first_plan = SolvePlan {
        init_heights: Some(plan.first_heights),
        ..SolvePlan::batch(plan.basin_search)
    };
    let first = solve(&inputs.problem(tracked, start)?, start, &first_plan)?.solution;
    let mut best: Option<(usize, GatedStart)> = None;
    for reset in [false, true]
        .into_iter()
        .take(1 + plan.reset_tilts as usize)
    {
        if let Some((explained, chain)) = chain(inputs, &first, detected, plan, reset)?
            && best.as_ref().is_none_or(|(b, _)| explained > *b)
        {
            best = Some((explained, chain));
        }
    }
    let Some((_, mut won)) = best else {
        return Err(EstimateError::InvalidInput(format!(
            "no detected edge lies within {:?} px of the projected wafer estimates, or every gating \
             chain's estimate put a rim behind a camera: the first estimate from the tracked rims is \
             inconsistent with the detections",
            plan.gates_px
        )));
    };
    drop_sparse_wafers(&mut won, plan.min_wafer_frames);
    Ok(won)
}

/// One chain from `first`; `None` when it dropped out. Returns the edges its last estimate
/// explains (before the band filter, which only thins their points) with its result.
fn chain(
    inputs: &SlamMotInputs,
    first: &SlamMotSolution,
    detected: &DetectedEdges<'_>,
    plan: &GatingPlan,
    reset: bool,
) -> Result<Option<(usize, GatedStart)>> {
    let mut current = first.clone();
    let mut gated = None;
    let mut next_start = None;
    for (gi, &gate_px) in plan.gates_px.iter().enumerate() {
        if let (Some(obs), Some(start)) = (gated.take(), next_start.take()) {
            let solved = inputs
                .problem(obs, &start)
                .and_then(|p| solve(&p, &start, &SolvePlan::batch(plan.basin_search)));
            match solved {
                Ok(out) => current = out.solution,
                Err(e) if rejects_association(&e) => return Ok(None),
                Err(e) => return Err(e),
            }
        }
        let last = gi + 1 == plan.gates_px.len();
        let config = GateConfig {
            gate_px,
            min_band_px: if last { plan.gate.min_band_px } else { 0.0 },
            band_weights: plan.gate.band_weights && last,
            ..plan.gate
        };
        let wafers: Vec<_> = current.state.wafers.iter().copied().map(Some).collect();
        let out = gate_edges(
            &inputs.config.k,
            &current.camera_poses,
            &wafers,
            inputs.config.geometry,
            detected,
            &config,
        )?;
        if out.observations.is_empty() {
            return Ok(None);
        }
        let mut start_wafers = current.state.wafers.clone();
        if gi == 0 && reset {
            for w in &mut start_wafers {
                w[3] = 0.0;
                w[4] = 0.0;
            }
        }
        let start = SlamMotState::new(current.state.base, current.state.offsets, start_wafers);
        if last {
            let explained = out.stats.rims_associated;
            return Ok(Some((
                explained,
                GatedStart {
                    observations: out.observations,
                    start,
                    stats: out.stats,
                    last_gate_px: gate_px,
                    too_few_views: Vec::new(),
                },
            )));
        }
        gated = Some(out.observations);
        next_start = Some(start);
    }
    Ok(None)
}

/// Errors of a chain's solve that come from its own association (the gated edges put a rim
/// behind a camera, or named inconsistent data): the chain drops out instead of failing the run.
fn rejects_association(e: &EstimateError) -> bool {
    matches!(
        e,
        EstimateError::InvalidParameter { .. }
            | EstimateError::DimensionMismatch { .. }
            | EstimateError::InvalidProblem(_)
            | EstimateError::TooFewPoints { .. }
            | EstimateError::InvalidInput(_)
    )
}

/// Removes the observations of wafers seen in fewer than `min_frames` frames and recounts.
fn drop_sparse_wafers(g: &mut GatedStart, min_frames: usize) {
    let mut frames_of: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
    for o in &g.observations {
        frames_of.entry(o.wafer).or_default().insert(o.frame);
    }
    g.too_few_views = frames_of
        .iter()
        .filter(|(_, f)| f.len() < min_frames)
        .map(|(w, _)| *w)
        .collect();
    if g.too_few_views.is_empty() {
        return;
    }
    g.observations
        .retain(|o| !g.too_few_views.contains(&o.wafer));
    g.stats.rims_used = g.observations.len();
    g.stats.frames_used = g
        .observations
        .iter()
        .map(|o| o.frame)
        .collect::<BTreeSet<_>>()
        .len();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::handeye::slam::tests::scene;
    use nalgebra::Vector2;

    /// A synthetic session's edges as detections (each observation one edge) plus a clutter
    /// arc per frame; the tracked observations are the first half of the frames.
    struct Case {
        inputs: SlamMotInputs,
        tracked: Vec<EdgeObservation>,
        truth: SlamMotState,
        points: Vec<Vector2<f64>>,
        start: Vec<usize>,
        frames: Vec<usize>,
        true_keys: BTreeSet<(usize, usize, u8)>,
    }

    fn case(keep: impl Fn(&EdgeObservation) -> bool) -> Case {
        let sc = scene(3, 24, 0.2);
        let n_frames = sc.encoders.len();
        let (mut points, mut start, mut frames) = (Vec::new(), vec![0], Vec::new());
        let mut true_keys = BTreeSet::new();
        for o in sc.observations.iter().filter(|o| keep(o)) {
            points.extend(&o.points);
            start.push(points.len());
            frames.push(o.frame);
            // The gate scores edges of at least `min_points` points.
            if o.points.len() >= GateConfig::default().min_points {
                true_keys.insert((o.frame, o.wafer, o.rim as u8));
            }
        }
        for f in 0..n_frames {
            // A straight clutter edge across the image (a carrier bar), 30 points.
            points.extend((0..30).map(|i| Vector2::new(100.0 + 30.0 * i as f64, 650.0)));
            start.push(points.len());
            frames.push(f);
        }
        let tracked = sc
            .observations
            .iter()
            .filter(|o| o.frame < n_frames / 2 && keep(o))
            .cloned()
            .collect();
        Case {
            inputs: SlamMotInputs {
                config: sc.config,
                encoders: sc.encoders,
                n_wafers: sc.truth.wafers.len(),
            },
            tracked,
            truth: sc.truth,
            points,
            start,
            frames,
            true_keys,
        }
    }

    fn plan(min_wafer_frames: usize) -> GatingPlan {
        GatingPlan {
            gates_px: vec![3.0, 1.5, 1.0],
            reset_tilts: true,
            gate: GateConfig::default(),
            min_wafer_frames,
            first_heights: (-0.02, 0.2, 0.001),
            basin_search: false,
        }
    }

    fn run(c: &Case, plan: &GatingPlan) -> Result<GatedStart> {
        let edges = DetectedEdges {
            points: &c.points,
            start: &c.start,
            frames: &c.frames,
        };
        let mut start = c.truth.clone();
        start.offsets = Default::default();
        for w in start.wafers.iter_mut().skip(1) {
            w[0] += 0.002;
            w[2] += 0.003;
            w[3] = 0.0;
            w[4] = 0.0;
        }
        gate_and_resolve(&c.inputs, c.tracked.clone(), &start, &edges, plan)
    }

    #[test]
    fn the_chain_associates_every_true_edge_and_rejects_clutter() {
        let c = case(|_| true);
        let out = run(&c, &plan(8)).unwrap();
        let got: BTreeSet<_> = out
            .observations
            .iter()
            .map(|o| (o.frame, o.wafer, o.rim as u8))
            .collect();
        // Every association is a true (frame, wafer, rim) and nearly all true ones are found.
        assert!(
            got.is_subset(&c.true_keys),
            "{:?}",
            got.difference(&c.true_keys)
        );
        assert!(
            got.len() as f64 >= 0.95 * c.true_keys.len() as f64,
            "{} of {}",
            got.len(),
            c.true_keys.len()
        );
        assert!(
            out.stats.edges_rejected >= c.inputs.encoders.len(),
            "{:?}",
            out.stats
        );
        assert!(out.too_few_views.is_empty());
        assert_eq!(out.last_gate_px, 1.0);
        // The start of the final solve is the last chain solve's estimate: near the truth.
        for (w, t) in out.start.wafers.iter().zip(&c.truth.wafers).skip(1) {
            assert!(
                (w.fixed_rows::<3>(0) - t.fixed_rows::<3>(0)).norm() < 5e-4,
                "{w} vs {t}"
            );
        }
    }

    #[test]
    fn a_wafer_gated_into_too_few_frames_is_dropped_and_named() {
        // Wafer 2 is detected in frames 0–4 only.
        let c = case(|o| o.wafer != 2 || o.frame < 5);
        let out = run(&c, &plan(8)).unwrap();
        assert_eq!(out.too_few_views, vec![2]);
        assert!(out.observations.iter().all(|o| o.wafer != 2));
        assert_eq!(out.stats.rims_used, out.observations.len());
    }

    #[test]
    fn no_gate_is_a_clear_error() {
        let c = case(|_| true);
        let mut p = plan(8);
        p.gates_px.clear();
        let err = run(&c, &p).unwrap_err().to_string();
        assert!(err.contains("gates_px"), "{err}");
    }
}

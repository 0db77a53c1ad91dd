//! The order of the SLAM-MOT solves of one session (000_3b1454b2b2194811.txt §5.3, Fig. 5.11):
//! the wafer heights from a coarse search, the sliding-window run, then the batch solve (with
//! the per-wafer basin search when asked).
//!
//! The auto-teaching pipeline as a whole spans the detector (`autoteach-detect`) and the
//! estimators of this crate, which does not depend on the detector; its stage order is the
//! Python driver's (`autoteach.pipeline.autoteach`), each stage one compiled call. Within
//! SLAM-MOT, the order is this module's: [`solve`] for one set of observations, and
//! [`gate_and_resolve`] for the detect front end's chain of gates that produces them.

mod resolve;

pub use resolve::{GatedStart, GatingPlan, gate_and_resolve};

use autoteach_geometry::robot::Joints;

use super::slam::{
    BasinSearch, EdgeObservation, PriorSigmas, SlamMot, SlamMotConfig, SlamMotSolution,
    SlamMotState, WindowRecord,
};
use crate::Result;

/// What every SLAM-MOT solve of one session shares: the configuration, the encoder readings
/// and the number of wafers. The observations and the start change from solve to solve.
#[derive(Debug, Clone)]
pub struct SlamMotInputs {
    /// The estimator's configuration.
    pub config: SlamMotConfig,
    /// Encoder readings, one per frame.
    pub encoders: Vec<Joints>,
    /// Number of wafers (estimated or not).
    pub n_wafers: usize,
}

impl SlamMotInputs {
    /// The estimator over `observations`. In the free-camera mode the calibration prior
    /// ([`super::slam::FreeCamera::calibration_prior`]) is centred on `start`'s base and offsets:
    /// each solve is tied to the calibration it starts from.
    pub fn problem(
        &self,
        observations: Vec<EdgeObservation>,
        start: &SlamMotState,
    ) -> Result<SlamMot> {
        let mut config = self.config.clone();
        if let Some(prior) = config
            .free_camera
            .as_mut()
            .and_then(|f| f.calibration_prior.as_mut())
        {
            prior.0 = start.base;
            prior.1 = start.offsets;
        }
        SlamMot::new(config, self.encoders.clone(), observations, self.n_wafers)
    }
}

/// Which solves to run, in order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolvePlan {
    /// `(low, high, step)` (m): start every wafer at the height of a coarse search over this
    /// range ([`SlamMot::initial_wafer_heights`]); `None` keeps the given start.
    pub init_heights: Option<(f64, f64, f64)>,
    /// Frames per sliding window (Fig. 5.11); 0 skips the windowed run.
    pub window: usize,
    /// Priors carried from one window to the next.
    pub window_prior: PriorSigmas,
    /// Re-fit wafers whose residuals stand out from a grid of basins after the batch solve.
    pub basin_search: bool,
}

impl SolvePlan {
    /// The batch solve alone (with the basin search when asked): no height search, no window
    /// (`window_prior` is then unused).
    pub fn batch(basin_search: bool) -> Self {
        let unused = PriorSigmas {
            base_rotation: 0.0,
            base_translation: 0.0,
            offset: 0.0,
        };
        Self {
            init_heights: None,
            window: 0,
            window_prior: unused,
            basin_search,
        }
    }
}

/// What the solves produced.
#[derive(Debug, Clone, PartialEq)]
pub struct SolveOutcome {
    /// The batch solve's estimate and covariances.
    pub solution: SlamMotSolution,
    /// One record per window (empty without the windowed run).
    pub history: Vec<WindowRecord>,
    /// The start of the solves, after the height search.
    pub initial: SlamMotState,
    /// Wafers the basin search moved.
    pub basins_moved: Vec<usize>,
}

/// Runs `plan`'s solves from `start`: height search, sliding window (its last state starts the
/// batch solve), batch solve or batch solve with basin search.
pub fn solve(slam: &SlamMot, start: &SlamMotState, plan: &SolvePlan) -> Result<SolveOutcome> {
    let mut state = start.clone();
    if let Some((lo, hi, step)) = plan.init_heights {
        state.wafers = slam.initial_wafer_heights(&state, (lo, hi), step)?;
    }
    let initial = state.clone();
    let mut history = Vec::new();
    if plan.window > 0 {
        history = slam.solve_sliding_window(&state, plan.window, &plan.window_prior)?;
        if let Some(last) = history.last() {
            state = last.state.clone();
        }
    }
    let (solution, basins_moved) = if plan.basin_search {
        slam.solve_batch_with_basins(&state, &BasinSearch::default())?
    } else {
        (slam.solve_batch(&state)?, Vec::new())
    };
    Ok(SolveOutcome {
        solution,
        history,
        initial,
        basins_moved,
    })
}

//! The error type of this crate.

use autoteach_geometry::error::Num;
use thiserror::Error;

/// Everything that can go wrong in this crate. Messages carry the offending values.
///
/// Exhaustive on purpose: the bindings map every variant to a Python exception in one `match`
/// (`crates/py/src/errors.rs`), so a new variant does not compile until it is given its class.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EstimateError {
    /// An error from the geometry crate.
    #[error(transparent)]
    Geometry(#[from] autoteach_geometry::GeometryError),

    /// A vector or matrix has the wrong size for the filter or model it is given to.
    #[error(
        "{what}: expected shape {}, got {}",
        shape_str(expected),
        shape_str(got)
    )]
    DimensionMismatch {
        /// What was passed (e.g. `"measurement z"`).
        what: String,
        /// The expected shape.
        expected: Vec<usize>,
        /// The shape received.
        got: Vec<usize>,
    },

    /// A parameter is outside its valid range.
    #[error("invalid parameter {name} = {}: {reason}", Num(*.value))]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// Why it is invalid.
        reason: &'static str,
    },

    /// An input contains NaN or ±inf.
    #[error("{what} must be finite, got {value} at index {index}")]
    NonFiniteInput {
        /// What was passed.
        what: String,
        /// The flat (column-major for matrices) index of the first offending element.
        index: usize,
        /// The offending value.
        value: f64,
    },

    /// A covariance given as input (initial P, Q or R) is not symmetric positive
    /// (semi-)definite.
    #[error(
        "{what} is not a valid covariance: asymmetry {asymmetry:.3e}, smallest eigenvalue {min_eigenvalue:.6e}"
    )]
    InvalidCovariance {
        /// Which matrix.
        what: String,
        /// max |Aᵢⱼ − Aⱼᵢ| relative to max |Aᵢⱼ|.
        asymmetry: f64,
        /// Its smallest eigenvalue (of the symmetric part).
        min_eigenvalue: f64,
    },

    /// A covariance computed by the filter lost positive definiteness (and the repair policy
    /// is off): the run stops instead of propagating it.
    #[error(
        "step {step}: {what} is not positive definite (smallest eigenvalue {min_eigenvalue:.6e}); \
         enable the repair policy to clip eigenvalues instead"
    )]
    NotPositiveDefinite {
        /// Which covariance (e.g. `"predicted covariance P_prior"`).
        what: String,
        /// The filter step (number of predictions before this one, 0-based).
        step: usize,
        /// The smallest eigenvalue of its symmetric part (NaN if it could not be computed).
        min_eigenvalue: f64,
    },

    /// A covariance computed by the filter is far from symmetric (and the repair policy is
    /// off); rounding-level asymmetry is always removed silently.
    #[error("step {step}: {what} is not symmetric (relative asymmetry {asymmetry:.3e})")]
    NotSymmetric {
        /// Which covariance.
        what: String,
        /// The filter step (0-based).
        step: usize,
        /// max |Pᵢⱼ − Pⱼᵢ| relative to max |Pᵢⱼ|.
        asymmetry: f64,
    },

    /// A value computed during filtering (a model output, the state, a covariance) is NaN or
    /// infinite.
    #[error("step {step}: {what} is not finite (value {value} at index {index})")]
    NonFinite {
        /// What became non-finite (e.g. `"fx output at sigma point 3"`).
        what: String,
        /// The filter step (0-based).
        step: usize,
        /// The flat index of the first offending element.
        index: usize,
        /// The offending value.
        value: f64,
    },

    /// A user model (e.g. a Python callback) failed; the message is the model's own.
    #[error("step {step}: the model's {function} failed: {message}")]
    Model {
        /// Which model function (`"fx"`, `"hx"`, `"x_mean"`, …).
        function: &'static str,
        /// The filter step (0-based).
        step: usize,
        /// The model's error message.
        message: String,
    },

    /// A least-squares problem is malformed (unknown block id, wrong number of values or
    /// blocks, a residual of dimension zero, …).
    #[error("invalid least-squares problem: {0}")]
    InvalidProblem(String),

    /// A residual evaluated to NaN or ±inf (at the initial values; during the solve a
    /// non-finite trial step is rejected instead).
    #[error("residual {residual} is not finite (value {value} at component {index}){context}")]
    NonFiniteResidual {
        /// The residual id.
        residual: usize,
        /// The offending component.
        index: usize,
        /// The offending value.
        value: f64,
        /// Extra context (e.g. `" in its Jacobian w.r.t. block 3"`), possibly empty.
        context: String,
    },

    /// The information matrix JᵀJ of a least-squares problem is singular (gauge freedom, an
    /// unconstrained block): the directions are named instead of returning wrong numbers.
    #[error("rank-deficient information matrix ({what}): unconstrained directions: {directions}")]
    RankDeficient {
        /// What was being computed (e.g. `"marginal covariance"`).
        what: String,
        /// The unconstrained tangent directions, as `block b (tangent components …)` lists.
        directions: String,
    },

    /// A linear solve failed for a reason other than rank deficiency.
    #[error("linear solver failed: {0}")]
    LinearSolver(String),

    /// A calibration view has too few usable points (after dropping missing NaN rows) to
    /// constrain its target pose.
    #[error("view {view}: {got} usable points, at least {needed} are needed")]
    TooFewPoints {
        /// The view index.
        view: usize,
        /// Usable points in it.
        got: usize,
        /// The minimum.
        needed: usize,
    },

    /// The calibration data cannot determine the camera (e.g. every view fronto-parallel, so
    /// focal length and target distance are inseparable); the message says why and what to
    /// change.
    #[error("degenerate calibration data: {0}")]
    DegenerateCalibration(String),
    /// An information (or covariance) matrix is singular or not positive definite where a
    /// regular one is required (e.g. the log-determinant or inverse of a Fisher information
    /// matrix without a prior).
    #[error(
        "{what} is singular or not positive definite (eigenvalues in [{min_eigenvalue:.6e}, {max_eigenvalue:.6e}])"
    )]
    SingularInformation {
        /// Which matrix.
        what: String,
        /// Its smallest eigenvalue.
        min_eigenvalue: f64,
        /// Its largest eigenvalue.
        max_eigenvalue: f64,
    },

    /// The measurement-pose planner found no pose satisfying the constraints of
    /// 000_3b1454b2b2194811.txt eq. (6.21); `binding` names the constraint that rejected the
    /// most candidates and `counts` lists the rejections per constraint.
    #[error(
        "no feasible measurement pose among {evaluated} candidates; binding constraint: {binding}; rejections: {counts}"
    )]
    NoFeasiblePose {
        /// Number of candidate poses evaluated.
        evaluated: usize,
        /// The constraint rejecting the most candidates.
        binding: String,
        /// Rejections per constraint, e.g. `"visibility (6.17): 120, collision (6.20): 3"`.
        counts: String,
    },
    /// An iterative design or estimation algorithm did not converge.
    #[error("{what} did not converge after {iterations} iterations (residual {residual:.6e})")]
    NoConvergence {
        /// What was iterated.
        what: String,
        /// Iterations run.
        iterations: usize,
        /// The final convergence measure.
        residual: f64,
    },

    /// A radio link kernel matrix is not positive definite (seed 004 eq. 3.3: a kernel of
    /// the symmetric pair distance d_s4 is not positive definite in general).
    #[error(
        "the {kernel} covariance of {links} links is not positive definite (Cholesky pivot \
         {column} is not positive); the d_s4 kernel of eq. 3.3 is not positive definite in \
         general: use the swap-average kernel"
    )]
    KernelNotPositiveDefinite {
        /// The kernel's name.
        kernel: String,
        /// Number of links in the matrix.
        links: usize,
        /// The column (link index) where the factorisation failed.
        column: usize,
    },

    /// A radio link has coincident (or nearly coincident) transmitter and receiver, where the
    /// path loss `log10 ‖r − t‖` of eq. 3.1 is undefined.
    #[error(
        "{what}: link {index} has transmitter and receiver {distance:.3e} m apart; they must be at least {minimum} m apart"
    )]
    CoincidentLink {
        /// What was passed.
        what: String,
        /// The link index.
        index: usize,
        /// Its length.
        distance: f64,
        /// The minimum accepted length.
        minimum: f64,
    },

    /// A point lies outside the map a model was fitted on.
    #[error(
        "{what}: point {index} = ({}, {}) lies outside the map [{x0}, {x1}] × [{y0}, {y1}]: it must lie inside",
        Num(*.x), Num(*.y)
    )]
    OutsideMap {
        /// What was passed.
        what: String,
        /// The row index.
        index: usize,
        /// Its x coordinate.
        x: f64,
        /// Its y coordinate.
        y: f64,
        /// Map's minimum x.
        x0: f64,
        /// Map's maximum x.
        x1: f64,
        /// Map's minimum y.
        y0: f64,
        /// Map's maximum y.
        y1: f64,
    },

    /// An input that is inconsistent in itself (offsets that do not index its points, an index
    /// beyond what it refers to); the message names the input and the offending value.
    #[error("{0}")]
    InvalidInput(String),

    /// An input that must not be empty is empty (e.g. a training set with no measurement).
    #[error("{0} must not be empty")]
    EmptyInput(String),

    /// Mapping input that the rasterizer cannot use (seed 004_815695db12a6b16c.txt ch. 2): a
    /// repeated or vanished node id, a node that changed robot, a new node without a scan,
    /// a negative range, an empty graph.
    #[error("invalid mapping input: {0}")]
    InvalidMapInput(String),
    /// A linear model (transfer function) or frequency-response data set is unusable for the
    /// requested operation: improper, unstable where stability is required, a zero
    /// denominator, unsorted or non-positive frequencies (issue 31, [`crate::control`]).
    #[error("invalid linear model {what}: {reason}")]
    InvalidModel {
        /// Which model or data set.
        what: String,
        /// Why it is rejected, with the offending values.
        reason: String,
    },
}

/// A shape as Python prints it: `(3,)`, `(2, 2)`, `()` (messages reach Python users).
pub fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

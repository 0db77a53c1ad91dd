//! Covariance functions on links (seed 004 §3.2.1, eqs. 3.3–3.4).
//!
//! The seed's base kernel is `k(x, x') = σ_f² exp(−‖x − x'‖ / l²)` (§3.1; the text calls it
//! squared-exponential but the formula is the exponential kernel of the distance, which is
//! what is implemented), tapered to compact support by eq. 3.4:
//! `k_s = max(0, 1 − d/Θ)^γ · k`.
//!
//! * [`LinkKernel::SwapAverage`] (default): with `a = ‖r − r'‖`, `b = ‖t − t'‖`,
//!   `k_dir(x, x') = σ_f² e^{−(a + b)/l²} c(a) c(b)`, `c(s) = max(0, 1 − s/Θ)^γ`, a product of
//!   kernels positive definite on ℝ² (the exponential kernel in any dimension; the truncated
//!   power `c` for γ ≥ 3/2 by Askey's theorem), and its average over the swap of transmitter
//!   and receiver, `k(x, x') = ½ [k_dir(x, x') + k_dir(x, swap x')]`. It is the inner product
//!   of the swap-averaged feature maps, hence positive (semi-)definite by construction, and
//!   symmetric in transmitter/receiver as d_s4 intends. Its exponent `(a + b)/l²` is exactly
//!   the un-swapped branch of eq. 3.3.
//! * [`LinkKernel::Ds4`]: the seed's kernel of the symmetric pair distance d_s4 (eq. 3.3),
//!   `σ_f² e^{−d_s4/l²} max(0, 1 − d_s4/Θ)^γ`. The minimum of two distances is not a
//!   conditionally negative definite metric, and the covariance is not positive definite in
//!   general (test `ds4_kernel_is_not_positive_definite`); the MRGP checks it and reports
//!   `KernelNotPositiveDefinite`.

use super::Link;

/// Which link kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkKernel {
    /// The swap average of a positive-definite product kernel (default).
    SwapAverage,
    /// The seed's kernel of d_s4 (eq. 3.3), not positive definite in general.
    Ds4,
}

impl LinkKernel {
    /// Its name in messages.
    pub fn name(&self) -> &'static str {
        match self {
            LinkKernel::SwapAverage => "swap-average",
            LinkKernel::Ds4 => "d_s4 (eq. 3.3)",
        }
    }
}

/// Hyper-parameters of the link kernel and the noise (Table 3.1's MRGP values as defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KernelParams {
    /// Length-scale `l` (the kernel decays as `e^{−d/l²}`; Table 3.1: 28.75).
    pub length_scale: f64,
    /// Signal standard deviation σ_f, dB (1.0).
    pub sigma_f: f64,
    /// Measurement noise standard deviation σ_d, dB (1.5).
    pub sigma_d: f64,
    /// Support radius Θ of eq. 3.4, metres (20.0).
    pub theta: f64,
    /// Taper exponent γ of eq. 3.4 (3).
    pub gamma: f64,
}

impl Default for KernelParams {
    fn default() -> Self {
        Self {
            length_scale: 28.75,
            sigma_f: 1.0,
            sigma_d: 1.5,
            theta: 20.0,
            gamma: 3.0,
        }
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// The distances a link kernel needs for one pair of links: direct `(‖r−r'‖, ‖t−t'‖)` and
/// swapped `(‖r−t'‖, ‖t−r'‖)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairDistances {
    /// Direct receiver and transmitter distances.
    pub direct: [f64; 2],
    /// Swapped distances.
    pub swapped: [f64; 2],
}

impl PairDistances {
    /// Distances between links `p` and `q`.
    pub fn new(p: &Link, q: &Link) -> Self {
        Self {
            direct: [dist(p.rx, q.rx), dist(p.tx, q.tx)],
            swapped: [dist(p.rx, q.tx), dist(p.tx, q.rx)],
        }
    }

    /// d_s4 of eq. 3.3.
    pub fn ds4(&self) -> f64 {
        (self.direct[0] + self.direct[1]).min(self.swapped[0] + self.swapped[1])
    }
}

/// `max(0, 1 − s/Θ)^γ`, the taper of eq. 3.4 (an integer γ — Table 3.1's 3 — by repeated
/// multiplication, several times cheaper than `powf`).
fn taper(s: f64, p: &KernelParams) -> f64 {
    let u = 1.0 - s / p.theta;
    if u <= 0.0 {
        0.0
    } else if p.gamma == p.gamma.trunc() && (1.0..=16.0).contains(&p.gamma) {
        u.powi(p.gamma as i32)
    } else {
        u.powf(p.gamma)
    }
}

impl LinkKernel {
    /// The kernel value for a pair with distances `d` (without the noise term).
    pub fn eval(&self, d: &PairDistances, p: &KernelParams) -> f64 {
        let l2 = p.length_scale * p.length_scale;
        let sf2 = p.sigma_f * p.sigma_f;
        match self {
            LinkKernel::SwapAverage => {
                let dir = |a: f64, b: f64| (-(a + b) / l2).exp() * taper(a, p) * taper(b, p);
                0.5 * sf2 * (dir(d.direct[0], d.direct[1]) + dir(d.swapped[0], d.swapped[1]))
            }
            LinkKernel::Ds4 => {
                let s = d.ds4();
                sf2 * (-s / l2).exp() * taper(s, p)
            }
        }
    }

    /// Whether a pair can have a non-zero kernel value: both distances of one orientation
    /// below Θ (a superset of the support of both kernels).
    pub fn may_couple(d: &PairDistances, theta: f64) -> bool {
        (d.direct[0] < theta && d.direct[1] < theta)
            || (d.swapped[0] < theta && d.swapped[1] < theta)
    }
}

//! Joint controller tuning for hand stabilisation (000_3b1454b2b2194811.txt ch. 2.5, eqs.
//! 2.18–2.19, Tables 2.3–2.4, Figs. 2.13–2.15; issue 31).
//!
//! The pipeline of Fig. 2.14, one module per stage:
//! * [`tf`], [`poly`]: continuous-time transfer functions; [`sim`]: exact ZOH simulation;
//! * [`plant`]: the simulated joint plants (motor + flexible link whose inertia follows the
//!   pose) and their noisy sine-sweep measurements;
//! * [`fit`]: transfer functions fitted to the sweeps (the `tfest` step);
//! * [`structure`]: the fixed-structure controller (filter sections + PID) and the loop-shaping
//!   initial design toward `G₀` of eq. 2.18;
//! * [`tune`]: the multi-model nonsmooth H∞ tuning of eq. 2.19 with its constraints;
//! * [`analysis`]: margins, bandwidth, sensitivity peak, closed-loop damping; [`hand`]: hand
//!   vibration on an S-curve move (Table 2.4).
//!
//! ```
//! use autoteach_estimate::control::{analysis, tf::TransferFunction};
//! // L(s) = 0.5 / (s (s+1)²): phase crossover at 1 rad/s with |L| = 0.25, so GM = 4.
//! let l = TransferFunction::new(&[0.5], &[1.0, 2.0, 1.0, 0.0])?;
//! let m = analysis::margins(&l);
//! assert!((m.gain_margin - 4.0).abs() < 1e-9);
//! # Ok::<(), autoteach_estimate::EstimateError>(())
//! ```

pub mod analysis;
pub mod baseline;
pub mod demo;
pub mod fit;
pub mod hand;
pub mod plant;
pub mod poly;
pub mod sim;
pub mod structure;
pub mod tf;
pub mod tune;

//! Active auto-teaching (000_3b1454b2b2194811.txt ch. 6): optimal experimental design for the
//! hand-eye calibration of the wafer-handling robot.
//!
//! * [`design`]: Fisher information of a design (eqs. (6.4)–(6.6)), the observability indices
//!   O1–O6 of Table 6.2, the information recursion (6.15), approximate D-optimal designs with
//!   the General Equivalence Theorem (Theorem 6.2.1) and the DETMAX exchange algorithm for a
//!   finite candidate set (6.10).
//! * [`model`]: the linearised observation model of the hand-eye system (eqs. (6.11)–(6.14))
//!   and its Kalman filter (6.15).
//! * [`planner`]: the one-step-horizon measurement-pose planner (6.16)–(6.25) with the
//!   constraints (6.17)–(6.20): reduced search, plain sampling and finite candidate sets.
//! * [`closed_loop`]: the closed loop of Fig. 6.1 on a simulated chamber opening (ch. 6.4).

pub mod closed_loop;
pub mod design;
pub mod model;
pub mod planner;

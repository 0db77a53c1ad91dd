//! `autoteach._core`: the compiled module behind the `autoteach` Python package.
//!
//! Thin bindings only: each function validates its NumPy inputs (see [`convert`]), calls one
//! core function of the Rust crates, and converts the result. Core errors become the Python
//! exceptions defined in [`errors`].

use pyo3::prelude::*;

mod active;
mod calib;
mod control;
pub mod convert;
mod detect;
mod ellipse_detection;
pub mod errors;
mod estimate;
mod geometry;
mod gray;
mod handeye;
mod handeye_gate;
mod handeye_slam;
mod lsq;
mod mapping;
mod plan;
mod polygon;
mod radio;
mod registration;
mod segment;
mod sim;
mod track;
mod wafers;
// issue 35: probabilistic boxes / JIoU and sparse pooling
mod fusion;
mod uncertainty;
mod validate;
// issue 29: global registration with a distractor-proof selection
mod global_register;
// issue 36: ellipse fits of many arcs in one call
mod ellipse_batch;

/// The compiled module `autoteach._core`.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    geometry::register(m)?;
    sim::register(m)?;
    detect::register(m)?;
    estimate::register(m)?;
    wafers::register(m)?;
    registration::register(m)?;
    polygon::register(m)?;
    track::register(m)?;
    lsq::register(m)?;
    calib::register(m)?;
    handeye::register(m)?;
    handeye_gate::register(m)?;
    handeye_slam::register(m)?;
    active::register(m)?;
    radio::register(m)?;
    ellipse_detection::register(m)?;
    mapping::register(m)?;
    segment::register(m)?;
    control::register(m)?;
    uncertainty::register(m)?;
    fusion::register(m)?;
    plan::register(m)?;
    global_register::register(m)?;
    ellipse_batch::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

//! `autoteach._core`: the compiled module behind the `autoteach` Python package.
//!
//! Thin bindings only: each function validates its NumPy inputs (see [`convert`]), calls one
//! core function of the Rust crates, and converts the result. Core errors become the Python
//! exceptions defined in [`errors`].

use pyo3::prelude::*;

pub mod convert;
mod detect;
pub mod errors;
mod estimate;
mod geometry;
mod sim;

/// The compiled module `autoteach._core`.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    geometry::register(m)?;
    sim::register(m)?;
    detect::register(m)?;
    estimate::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

//! Bindings of the polygon functions (see the matching module of the Rust crates).

use pyo3::prelude::*;

/// Adds the polygon functions and classes to the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}

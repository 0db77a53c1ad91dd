//! Bindings of `autoteach_estimate` (being written).

use pyo3::prelude::*;

/// Adds the estimate functions and classes to the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}

//! Bindings of `autoteach_geometry::render` (being written).

use pyo3::prelude::*;

/// Adds the sim functions and classes to the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}

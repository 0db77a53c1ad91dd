//! Bindings of `autoteach_geometry` (being written).

use pyo3::prelude::*;

/// Adds the geometry functions and classes to the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}

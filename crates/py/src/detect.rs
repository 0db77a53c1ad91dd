//! Bindings of `autoteach_detect` (being written).

use pyo3::prelude::*;

/// Adds the detect functions and classes to the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}

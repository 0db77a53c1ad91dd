//! Fallible allocation of buffers whose size comes from user input.
//!
//! A size from the caller (a sample count, a state dimension) can overflow `usize` or exceed
//! what the allocator gives. `Vec::with_capacity` then panics or aborts the process; these
//! helpers return [`GeometryError::OutOfMemory`] instead, which the Python bindings raise as
//! `MemoryError`.

use crate::error::GeometryError;

/// `rows · cols` elements, or `OutOfMemory` when the product overflows.
pub fn checked_count(what: &'static str, rows: usize, cols: usize) -> Result<usize, GeometryError> {
    rows.checked_mul(cols).ok_or(GeometryError::OutOfMemory {
        what,
        elements: usize::MAX,
        bytes_each: 0,
    })
}

/// An empty vector with room for `n` elements, or `OutOfMemory`.
pub fn try_with_capacity<T>(what: &'static str, n: usize) -> Result<Vec<T>, GeometryError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| GeometryError::OutOfMemory {
            what,
            elements: n,
            bytes_each: std::mem::size_of::<T>(),
        })?;
    Ok(v)
}

/// `Ok` when `n` elements of `T` can be reserved now (the probe is released at once): a check
/// before sizes reach code that allocates infallibly.
pub fn ensure_fits<T>(what: &'static str, n: usize) -> Result<(), GeometryError> {
    try_with_capacity::<T>(what, n).map(drop)
}

/// `n` copies of `value`, or `OutOfMemory`.
pub fn try_filled<T: Clone>(
    what: &'static str,
    n: usize,
    value: T,
) -> Result<Vec<T>, GeometryError> {
    let mut v = try_with_capacity(what, n)?;
    v.resize(n, value);
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impossible_sizes_are_errors_not_aborts() {
        let e = try_filled::<f64>("weights", usize::MAX / 2, 0.0).unwrap_err();
        assert!(matches!(
            e,
            GeometryError::OutOfMemory {
                elements,
                bytes_each: 8,
                ..
            } if elements == usize::MAX / 2
        ));
        assert!(checked_count("matrix", usize::MAX, 2).is_err());
        assert_eq!(checked_count("matrix", 3, 4), Ok(12));
        assert_eq!(try_filled("v", 3, 1.5).unwrap(), vec![1.5; 3]);
    }
}

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

/// Bytes of physical memory: `MemTotal` of `/proc/meminfo` on Linux, `None` where the platform
/// does not say.
pub fn physical_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// `Ok` when `n` elements of `bytes_each` bytes fit in physical memory (always, where the
/// platform does not report it). For work that grows to `n` elements one at a time and runs
/// until it has them all, such as a planner's tree: a size that cannot fit is refused up front,
/// instead of running for hours and failing at the end. Unlike [`ensure_fits`] this does not
/// depend on the allocator refusing a reservation (Linux's overcommit may grant one).
pub fn ensure_within_physical_memory(
    what: &'static str,
    n: usize,
    bytes_each: usize,
) -> Result<(), GeometryError> {
    let need = (n as u128) * (bytes_each as u128);
    match physical_memory() {
        Some(total) if need > u128::from(total) => Err(GeometryError::OutOfMemory {
            what,
            elements: n,
            bytes_each,
        }),
        _ => Ok(()),
    }
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

    #[test]
    fn a_size_beyond_physical_memory_is_refused_and_a_small_one_is_not() {
        assert!(ensure_within_physical_memory("tree", 1000, 128).is_ok());
        if let Some(total) = physical_memory() {
            let n = usize::try_from(total / 64).unwrap_or(usize::MAX);
            let e = ensure_within_physical_memory("tree", n, 128).unwrap_err();
            assert!(matches!(
                e,
                GeometryError::OutOfMemory {
                    bytes_each: 128,
                    ..
                }
            ));
        }
        assert!(
            ensure_within_physical_memory("tree", usize::MAX, usize::MAX).is_err()
                || physical_memory().is_none()
        );
    }
}

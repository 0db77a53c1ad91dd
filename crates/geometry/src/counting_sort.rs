//! Stable counting sort by a small integer key, shared by the sparse assemblies and the
//! graph segmentation (seed 004_815695db12a6b16c.txt ch. 4.2, Algorithm 4.1 line 4,
//! `countingSortOnRGB`: "the number of possible distances is constant … a constant time
//! sorting algorithm sorts edge weights in O(n + k)").
//!
//! ```
//! use autoteach_geometry::counting_sort::{bucket_offsets, counting_sort_order};
//! let keys = [2u32, 0, 2, 1];
//! assert_eq!(bucket_offsets(3, keys), vec![0, 1, 2, 4]);
//! assert_eq!(counting_sort_order(&keys, 3), vec![1, 3, 0, 2]);
//! ```

/// Start offsets of `n` buckets for `keys` (each `< n`): bucket `k` holds the positions
/// `[out[k], out[k + 1])` of the sorted sequence, and `out[n]` is the number of keys. O(len + n).
pub fn bucket_offsets(n: usize, keys: impl IntoIterator<Item = u32>) -> Vec<usize> {
    let mut start = vec![0usize; n + 1];
    for k in keys {
        start[k as usize + 1] += 1;
    }
    for b in 0..n {
        start[b + 1] += start[b];
    }
    start
}

/// The permutation that sorts `keys` ascending, stable (equal keys keep their input order, so
/// results are deterministic). Every key must be `< buckets`, and there are fewer than 2³² keys
/// (the callers index points or matrix entries with `u32`). O(n + buckets) time and memory.
pub fn counting_sort_order(keys: &[u32], buckets: usize) -> Vec<u32> {
    let mut next = bucket_offsets(buckets, keys.iter().copied());
    let mut order = vec![0u32; keys.len()];
    for (i, &k) in keys.iter().enumerate() {
        let slot = &mut next[k as usize];
        order[*slot] = i as u32;
        *slot += 1;
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_a_stable_comparison_sort() {
        let keys: Vec<u32> = (0..1000u32).map(|i| (i * 7919 + 13) % 97).collect();
        let order = counting_sort_order(&keys, 97);
        let mut reference: Vec<u32> = (0..keys.len() as u32).collect();
        reference.sort_by_key(|&i| keys[i as usize]); // `sort_by_key` is stable
        assert_eq!(order, reference);
        let offsets = bucket_offsets(97, keys.iter().copied());
        for b in 0..97 {
            let count = keys.iter().filter(|&&k| k == b as u32).count();
            assert_eq!(offsets[b + 1] - offsets[b], count);
        }
        assert_eq!(offsets[97], keys.len());
    }

    #[test]
    fn empty_and_single_bucket() {
        assert!(counting_sort_order(&[], 0).is_empty());
        assert_eq!(bucket_offsets(0, []), vec![0]);
        assert_eq!(counting_sort_order(&[0, 0, 0], 1), vec![0, 1, 2]);
    }
}

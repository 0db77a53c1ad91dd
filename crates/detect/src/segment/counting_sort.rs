//! Stable counting sort of edges by an integer key (seed 004_815695db12a6b16c.txt ch. 4.2:
//! "in the case of the discrete labels (e.g. in RGB), the number of possible distances is
//! constant … a constant time sorting algorithm sorts edge weights in O(n + k)", and
//! Algorithm 4.1 line 4, `countingSortOnRGB`).

/// The permutation that sorts `keys` ascending, stable (equal keys keep their input order, so
/// the segmentation is deterministic). Every key must be `< buckets`. O(n + buckets) time,
/// O(n + buckets) memory.
pub fn counting_sort_order(keys: &[u32], buckets: usize) -> Vec<u32> {
    let mut start = vec![0u32; buckets + 1];
    for &k in keys {
        start[k as usize + 1] += 1;
    }
    for b in 0..buckets {
        start[b + 1] += start[b];
    }
    let mut order = vec![0u32; keys.len()];
    for (i, &k) in keys.iter().enumerate() {
        let slot = &mut start[k as usize];
        order[*slot as usize] = i as u32;
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
    }
}

//! Stable counting sort of edges by an integer key (seed 004_815695db12a6b16c.txt ch. 4.2:
//! "in the case of the discrete labels (e.g. in RGB), the number of possible distances is
//! constant … a constant time sorting algorithm sorts edge weights in O(n + k)", and
//! Algorithm 4.1 line 4, `countingSortOnRGB`).

pub use autoteach_geometry::counting_sort::counting_sort_order;

/// Widest digit of [`counting_sort_by_key`]: 2¹¹ counters (16 KiB) stay in the L1 cache.
const MAX_DIGIT_BITS: u32 = 11;

/// `items` sorted ascending by `key`, stable, for keys in `0..=max_key`: the counting sort of
/// Algorithm 4.1 line 4 applied digit by digit from the least significant (LSD radix sort, each
/// pass a stable counting sort on a digit of at most 11 bits). The result is the order of
/// [`counting_sort_order`] (stability carries each pass's order into the next), but every
/// pass scatters into at most 2¹¹ write streams instead of one per key value: with the colour
/// key's 195 076 values a single pass writes to scattered places (about one cache miss per
/// edge at 10⁶ points), two 9-bit passes to 512 streams each. The records move with their key,
/// so the caller then reads them sequentially. O(passes · (n + 2^digit)) time, 2n records of
/// memory. Keys above `max_key` are a caller bug; they are masked (the order is then
/// unspecified, but nothing panics).
pub fn counting_sort_by_key<T: Copy>(
    items: Vec<T>,
    max_key: u32,
    key: impl Fn(&T) -> u32,
) -> Vec<T> {
    let bits = u32::BITS - max_key.leading_zeros();
    if items.len() < 2 || bits == 0 {
        return items;
    }
    let passes = bits.div_ceil(MAX_DIGIT_BITS);
    let digit = bits.div_ceil(passes);
    let radix = 1usize << digit;
    let mask = (radix - 1) as u32;
    // One read pass counts every digit; each pass then only scatters.
    let mut start = vec![0usize; radix * passes as usize];
    for it in &items {
        let k = key(it);
        for pass in 0..passes {
            start[pass as usize * radix + ((k >> (pass * digit)) & mask) as usize] += 1;
        }
    }
    for counts in start.chunks_exact_mut(radix) {
        let mut sum = 0usize;
        for c in counts.iter_mut() {
            let k = *c;
            *c = sum;
            sum += k;
        }
    }
    let mut src = items;
    let mut dst = src.clone();
    for (pass, slots) in start.chunks_exact_mut(radix).enumerate() {
        let shift = pass as u32 * digit;
        for it in &src {
            let slot = &mut slots[((key(it) >> shift) & mask) as usize];
            dst[*slot] = *it;
            *slot += 1;
        }
        std::mem::swap(&mut src, &mut dst);
    }
    src
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The digit-wise counting sort gives the stable comparison sort's order, for the colour
    /// key's range (two 9-bit passes), the normal key's (two 8-bit passes), one-pass and
    /// degenerate ranges, on pseudo-random keys with many ties.
    #[test]
    fn by_key_matches_a_stable_comparison_sort() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for (max_key, len) in [
            (195_075u32, 20_000usize),
            (31_416, 5_000),
            (1_000, 3_000),
            (1, 50),
            (0, 7),
        ] {
            let items: Vec<(u32, u32)> = (0..len as u32)
                .map(|i| {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1);
                    // Squaring skews the keys towards 0, so small keys tie often.
                    let u = (state >> 33) as f64 / (1u64 << 31) as f64;
                    ((u * u * f64::from(max_key)) as u32, i)
                })
                .collect();
            let mut reference = items.clone();
            reference.sort_by_key(|it| it.0); // stable
            let sorted = counting_sort_by_key(items.clone(), max_key, |it| it.0);
            assert_eq!(sorted, reference, "max_key {max_key}");
            let keys: Vec<u32> = items.iter().map(|it| it.0).collect();
            let order = counting_sort_order(&keys, max_key as usize + 1);
            let via_order: Vec<(u32, u32)> = order.iter().map(|&i| items[i as usize]).collect();
            assert_eq!(sorted, via_order);
        }
    }
}

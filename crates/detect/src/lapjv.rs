//! Dense square linear assignment by Jonker–Volgenant (R. Jonker and A. Volgenant, "A shortest
//! augmenting path algorithm for dense and sparse linear assignment problems", Computing 38,
//! 1987): the LAPJV solver behind `lap.lapjv`, used by [`solve_assignment`] for square matrices
//! of finite costs (the "BipartiteMatch" of 000_3b1454b2b2194811.txt §3.2, Algorithms 1–2).
//!
//! Three phases, all on the row-major matrix (every scan reads one row contiguously):
//! 1. **Column reduction**: `v[j] = min_i c[i][j]` (computed in one row-major pass), each
//!    column given to its minimising row while that row is free.
//! 2. **Reduction transfer** for rows holding exactly one column, then **augmenting row
//!    reduction** (two passes): a free row takes its cheapest column, lowering that column's
//!    price to the second-cheapest reduced cost and evicting the previous owner. Most rows of a
//!    random instance are assigned here, at O(n) per row.
//! 3. **Augmentation**: for each row still free, a Dijkstra search over reduced costs
//!    `c[i][j] − v[j]` to the nearest free column (the columns at the current minimum distance
//!    kept in a "todo" band of `collist`), then the prices of the scanned columns are updated
//!    and the path is flipped.
//!
//! The duals stay feasible throughout, so the result is optimal; the answer equals the
//! shortest-augmenting-path solver's (Crouse 2016) up to ties.
//!
//! Work bound of the augmenting row reduction: an evicted row is re-examined in the same pass
//! only while a price actually decreased (a decrease below one ulp does not count, as in
//! `lap`'s `_carr_dense`) and while the pass has scanned fewer than `n` rows; beyond that the
//! evicted rows are left to the augmentation. Each pass is then O(n²). Without the budget, on
//! structured costs (Euclidean distances between point sets) the reduction keeps evicting rows
//! with tiny price decreases and costs several times the whole augmentation (measured at
//! n = 1 000: 1.5 s against 0.2 s, docs/design/assignment-lapjv.md); on uniform costs the
//! budget is rarely reached.
//!
//! ```
//! use autoteach_detect::lapjv::solve_assignment_row_major;
//! let cost = [4.0, 1.0, 3.0, 2.0, 0.0, 5.0, 3.0, 2.0, 2.0];
//! let a = solve_assignment_row_major(3, 3, &cost).unwrap();
//! assert_eq!(a.row_to_col, vec![Some(1), Some(0), Some(2)]);
//! assert_eq!(a.cost, 5.0);
//! ```
//!
//! [`solve_assignment`]: crate::assignment::solve_assignment

use nalgebra::DMatrix;

use crate::assignment::{Assignment, solve_assignment};
use crate::{DetectError, Result};

const NONE: usize = usize::MAX;

/// Minimum-cost assignment of a `rows × cols` cost matrix given row-major (`cost[i * cols + j]`),
/// with the semantics of [`solve_assignment`]: rectangular matrices and `+∞` (forbidden) entries
/// are allowed. Square matrices of finite costs are solved by [`lapjv`]; the other cases by
/// [`solve_assignment`].
///
/// # Errors
/// [`DetectError::WrongLength`] if `cost.len() != rows * cols`; [`DetectError::InvalidCost`]
/// for a NaN or `−∞` entry; [`DetectError::Infeasible`] if sums of the costs overflow `f64`.
pub fn solve_assignment_row_major(rows: usize, cols: usize, cost: &[f64]) -> Result<Assignment> {
    if cost.len() != rows * cols {
        return Err(DetectError::WrongLength {
            what: "cost",
            got: cost.len(),
            expected: rows * cols,
        });
    }
    // One branch-free pass (it vectorises; the early-exit scan was 11 % of a 200 × 200 solve);
    // the offending entry is looked up only when there is one.
    let (mut max_abs, mut bad, mut any_inf) = (0.0f64, false, false);
    for &value in cost {
        let a = value.abs();
        bad |= value.is_nan() | (value == f64::NEG_INFINITY);
        any_inf |= a == f64::INFINITY;
        max_abs = if a > max_abs { a } else { max_abs };
    }
    if bad {
        let k = cost
            .iter()
            .position(|v| v.is_nan() || *v == f64::NEG_INFINITY)
            .unwrap_or(0);
        return Err(DetectError::InvalidCost {
            what: "cost",
            row: k / cols,
            col: k % cols,
            value: cost[k],
        });
    }
    // Prices and path lengths are sums of at most 2n costs: far from overflow here, the
    // general solver (which detects overflow exactly) otherwise.
    let safe = max_abs < f64::MAX / (4.0 * (rows.max(1) as f64));
    if rows != cols || any_inf || !safe {
        return solve_assignment(&DMatrix::from_row_slice(rows, cols, cost));
    }
    let col_of_row = lapjv(rows, cost).ok_or_else(|| DetectError::Infeasible {
        reason: format!(
            "the costs of the {rows}×{cols} matrix overflow f64 in the shortest-path sums"
        ),
    })?;
    let mut out = Assignment {
        row_to_col: vec![None; rows],
        col_to_row: vec![None; cols],
        cost: 0.0,
    };
    for (i, &j) in col_of_row.iter().enumerate() {
        out.row_to_col[i] = Some(j);
        out.col_to_row[j] = Some(i);
        out.cost += cost[i * cols + j];
    }
    Ok(out)
}

/// Jonker–Volgenant (1987) on a square row-major `n × n` matrix of finite costs: the column of
/// each row in a minimum-cost assignment, or `None` when a distance is not finite (overflow).
pub fn lapjv(n: usize, c: &[f64]) -> Option<Vec<usize>> {
    debug_assert_eq!(c.len(), n * n);
    if n <= 1 {
        return Some(vec![0; n]);
    }
    let mut x = vec![NONE; n]; // column of each row
    let mut y = vec![NONE; n]; // row of each column
    let mut v = c[..n].to_vec(); // column prices
    let free = column_reduction(n, c, &mut x, &mut y, &mut v);
    let mut free = free;
    for _ in 0..2 {
        if free.is_empty() {
            break;
        }
        free = augmenting_row_reduction(n, c, &mut x, &mut y, &mut v, free);
    }
    augment(n, c, &mut x, &mut y, &mut v, &free)?;
    Some(x)
}

/// Column reduction and reduction transfer (JV 1987, procedures COLUMN REDUCTION and
/// REDUCTION TRANSFER); returns the rows left free. `v` holds row 0 on entry.
fn column_reduction(
    n: usize,
    c: &[f64],
    x: &mut [usize],
    y: &mut [usize],
    v: &mut [f64],
) -> Vec<usize> {
    // v[j] = min_i c[i][j] and its first minimising row, in one row-major pass.
    // Branch-free selects, so that the pass vectorises.
    let mut imin = vec![0usize; n];
    for i in 1..n {
        let row = &c[i * n..(i + 1) * n];
        for ((vj, im), &cij) in v.iter_mut().zip(imin.iter_mut()).zip(row) {
            let lower = cij < *vj;
            *vj = if lower { cij } else { *vj };
            *im = if lower { i } else { *im };
        }
    }
    // Columns in reverse order, each to its minimising row if that row is still unassigned.
    let mut matches = vec![0u32; n];
    for j in (0..n).rev() {
        let i = imin[j];
        matches[i] += 1;
        if matches[i] == 1 {
            x[i] = j;
            y[j] = i;
        }
    }
    let mut free = Vec::with_capacity(n);
    for i in 0..n {
        match matches[i] {
            0 => free.push(i),
            1 => {
                // Reduction transfer: u_i = min_{j ≠ j1} (c_ij − v_j), moved onto v_{j1}.
                let j1 = x[i];
                let row = &c[i * n..(i + 1) * n];
                let mut min = f64::INFINITY;
                for (j, (&cij, &vj)) in row.iter().zip(v.iter()).enumerate() {
                    let h = cij - vj;
                    if h < min && j != j1 {
                        min = h;
                    }
                }
                v[j1] -= min;
            }
            _ => {}
        }
    }
    free
}

/// One pass of augmenting row reduction (JV 1987, procedure AUGMENTING ROW REDUCTION) over
/// `todo`; returns the rows still free.
fn augmenting_row_reduction(
    n: usize,
    c: &[f64],
    x: &mut [usize],
    y: &mut [usize],
    v: &mut [f64],
    mut todo: Vec<usize>,
) -> Vec<usize> {
    let mut still_free = Vec::with_capacity(todo.len());
    let mut k = 0usize;
    let mut count = 0usize;
    while k < todo.len() {
        let i = todo[k];
        k += 1;
        count += 1;
        let row = &c[i * n..(i + 1) * n];
        // Lowest and second-lowest reduced cost of row i.
        let (mut u1, mut j1) = (row[0] - v[0], 0usize);
        let (mut u2, mut j2) = (f64::INFINITY, NONE);
        for (j, (&cij, &vj)) in row.iter().zip(v.iter()).enumerate().skip(1) {
            let h = cij - vj;
            if h < u2 {
                if h >= u1 {
                    u2 = h;
                    j2 = j;
                } else {
                    u2 = u1;
                    u1 = h;
                    j2 = j1;
                    j1 = j;
                }
            }
        }
        let mut i0 = y[j1];
        let lowered = v[j1] - (u2 - u1);
        let lowers = lowered < v[j1];
        if count < n {
            if lowers {
                v[j1] = lowered;
            } else if i0 != NONE && j2 != NONE {
                j1 = j2;
                i0 = y[j2];
            }
            if i0 != NONE {
                if lowers {
                    // The evicted row is examined next, in this pass.
                    k -= 1;
                    todo[k] = i0;
                } else {
                    still_free.push(i0);
                }
            }
        } else if i0 != NONE {
            still_free.push(i0);
        }
        x[i] = j1;
        y[j1] = i;
    }
    still_free
}

/// Augmentation (JV 1987, procedure AUGMENT): a shortest path over reduced costs from each
/// free row to a free column, the price update of the scanned columns, and the flip of the
/// path. `None` if a distance is not finite.
// The scans `for k in up..n` move columns into the band by growing `up` while they run: the
// range is fixed when the loop starts, as in JV's `for (k = up; k < dim; k++)`.
#[allow(clippy::mut_range_bound)]
fn augment(
    n: usize,
    c: &[f64],
    x: &mut [usize],
    y: &mut [usize],
    v: &mut [f64],
    free: &[usize],
) -> Option<()> {
    let mut d = vec![0.0f64; n];
    let mut pred = vec![0usize; n];
    let mut collist: Vec<usize> = (0..n).collect();
    // Every array of length exactly `n`: one bounds check per column index covers them all.
    let (v, y, d, pred, collist) = (
        &mut v[..n],
        &mut y[..n],
        &mut d[..n],
        &mut pred[..n],
        &mut collist[..n],
    );
    for &free_row in free {
        let row = &c[free_row * n..(free_row + 1) * n];
        for j in 0..n {
            d[j] = row[j] - v[j];
            pred[j] = free_row;
            collist[j] = j;
        }
        // collist[..low]: scanned; collist[low..up]: at distance `min`, to scan; the rest: later.
        let (mut low, mut up) = (0usize, 0usize);
        let mut scanned = 0usize;
        let mut min = 0.0f64;
        let end = 'search: loop {
            if up == low {
                // A new minimum distance: move every column at it into the todo band.
                scanned = low;
                min = d[collist[up]];
                up += 1;
                for k in up..n {
                    let j = collist[k];
                    let h = d[j];
                    if h <= min {
                        if h < min {
                            up = low;
                            min = h;
                        }
                        collist[k] = collist[up];
                        collist[up] = j;
                        up += 1;
                    }
                }
                if !min.is_finite() {
                    return None;
                }
                if let Some(&j) = collist[low..up].iter().find(|&&j| y[j] == NONE) {
                    break 'search j;
                }
            }
            // Scan one column at the minimum distance: relax through the row assigned to it.
            let j1 = collist[low];
            low += 1;
            let i = y[j1];
            let rowi = &c[i * n..(i + 1) * n];
            let h = rowi[j1] - v[j1] - min;
            for k in up..n {
                let j = collist[k];
                let dist = rowi[j] - v[j] - h;
                if dist < d[j] {
                    pred[j] = i;
                    if dist == min {
                        if y[j] == NONE {
                            break 'search j;
                        }
                        collist[k] = collist[up];
                        collist[up] = j;
                        up += 1;
                    }
                    d[j] = dist;
                }
            }
        };
        // Prices of the columns scanned before the last minimum (the later ones are at `min`).
        for &j in &collist[..scanned] {
            v[j] += d[j] - min;
        }
        // Flip the path.
        let mut j = end;
        loop {
            let i = pred[j];
            y[j] = i;
            std::mem::swap(&mut x[i], &mut j);
            if i == free_row {
                break;
            }
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// The minimum total cost over all n! permutations (Heap's algorithm).
    fn brute_force(n: usize, c: &[f64]) -> f64 {
        let mut perm: Vec<usize> = (0..n).collect();
        let total = |p: &[usize]| {
            p.iter()
                .enumerate()
                .map(|(i, &j)| c[i * n + j])
                .sum::<f64>()
        };
        let mut best = total(&perm);
        let mut counters = vec![0usize; n];
        let mut i = 0;
        while i < n {
            if counters[i] < i {
                if i % 2 == 0 {
                    perm.swap(0, i);
                } else {
                    perm.swap(counters[i], i);
                }
                best = best.min(total(&perm));
                counters[i] += 1;
                i = 0;
            } else {
                counters[i] = 0;
                i += 1;
            }
        }
        best
    }

    fn is_permutation(x: &[usize]) -> bool {
        let mut seen = vec![false; x.len()];
        x.iter()
            .all(|&j| j < x.len() && !std::mem::replace(&mut seen[j], true))
    }

    fn total(n: usize, c: &[f64], x: &[usize]) -> f64 {
        x.iter().enumerate().map(|(i, &j)| c[i * n + j]).sum()
    }

    #[test]
    fn matches_brute_force_on_small_random_instances() {
        let mut rng = Pcg64::seed_from_u64(36);
        for trial in 0..600 {
            let n = 1 + trial % 8;
            // Uniform, small integers (many ties) and geometric distances.
            let c: Vec<f64> = match trial % 3 {
                0 => (0..n * n).map(|_| rng.random::<f64>()).collect(),
                1 => (0..n * n)
                    .map(|_| f64::from(rng.random_range(0..4u8)))
                    .collect(),
                _ => {
                    let a: Vec<(f64, f64)> = (0..n).map(|_| (rng.random(), rng.random())).collect();
                    let b: Vec<(f64, f64)> = (0..n).map(|_| (rng.random(), rng.random())).collect();
                    (0..n * n)
                        .map(|k| {
                            let (p, q) = (a[k / n], b[k % n]);
                            (p.0 - q.0).hypot(p.1 - q.1)
                        })
                        .collect()
                }
            };
            let x = lapjv(n, &c).unwrap();
            assert!(is_permutation(&x), "trial {trial}: {x:?}");
            let best = brute_force(n, &c);
            assert!(
                (total(n, &c, &x) - best).abs() <= 1e-12 * best.abs().max(1.0),
                "trial {trial}"
            );
        }
    }

    #[test]
    fn equals_the_shortest_augmenting_path_solver_on_larger_instances() {
        let mut rng = Pcg64::seed_from_u64(7);
        for (n, ties) in [(50, false), (120, true), (200, false), (64, true)] {
            let c: Vec<f64> = (0..n * n)
                .map(|_| {
                    if ties {
                        f64::from(rng.random_range(0..10u8))
                    } else {
                        rng.random::<f64>() * 100.0 - 50.0
                    }
                })
                .collect();
            let ours = total(n, &c, &lapjv(n, &c).unwrap());
            // The Crouse path of `solve_assignment`, taken for a rectangular matrix: an extra
            // column that no optimum uses.
            let crouse =
                crate::assignment::solve_assignment(&DMatrix::from_fn(n, n + 1, |i, j| {
                    if j < n { c[i * n + j] } else { 1e12 }
                }))
                .unwrap();
            assert!(
                (ours - crouse.cost).abs() <= 1e-9 * crouse.cost.abs().max(1.0),
                "n={n}: {ours} vs {}",
                crouse.cost
            );
        }
    }

    #[test]
    fn row_major_entry_point_handles_rectangular_and_forbidden() {
        // Rectangular: the 2×3 optimum is rows → (2, 0), cost 1 + 2 = 3.
        let a = solve_assignment_row_major(2, 3, &[5.0, 4.0, 1.0, 2.0, 3.0, 9.0]).unwrap();
        assert_eq!(a.row_to_col, vec![Some(2), Some(0)]);
        assert_eq!(a.cost, 3.0);
        // Forbidden pairs: row 1 can only take column 0.
        let inf = f64::INFINITY;
        let a = solve_assignment_row_major(2, 2, &[1.0, 5.0, 2.0, inf]).unwrap();
        assert_eq!(a.row_to_col, vec![Some(1), Some(0)]);
        assert_eq!(a.cost, 7.0);
        assert!(matches!(
            solve_assignment_row_major(2, 2, &[1.0, f64::NAN, 0.0, 0.0]),
            Err(DetectError::InvalidCost { row: 0, col: 1, .. })
        ));
        assert!(matches!(
            solve_assignment_row_major(2, 2, &[1.0, 2.0, 3.0]),
            Err(DetectError::WrongLength {
                got: 3,
                expected: 4,
                ..
            })
        ));
        assert_eq!(solve_assignment_row_major(0, 0, &[]).unwrap().cost, 0.0);
    }

    #[test]
    fn huge_costs_fall_back_to_the_overflow_checked_solver() {
        let big = f64::MAX * 0.9;
        let r = solve_assignment_row_major(2, 2, &[big, big, big, big]);
        assert!(matches!(r, Err(DetectError::Infeasible { .. })), "{r:?}");
    }
}

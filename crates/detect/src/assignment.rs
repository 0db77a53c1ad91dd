//! Linear assignment (the "BipartiteMatch" of 000_3b1454b2b2194811.txt §3.2, Algorithms 1–2,
//! and the arc-to-arc matching with a dummy arc v₀ of eq. (3.4)); shared with track association.
//!
//! The solver is the shortest-augmenting-path form of Jonker–Volgenant for rectangular
//! matrices (D. F. Crouse, "On implementing 2D rectangular assignment algorithms", IEEE TAES
//! 2016, Algorithm 1 — the algorithm behind `scipy.optimize.linear_sum_assignment`): one
//! Dijkstra search over reduced costs per row, O(n²m) in total for n ≤ m.
//!
//! Forbidden pairs are `+∞` costs. When some pairs are forbidden, the solver minimises the
//! lexicographic cost (number of forbidden pairs used, total finite cost) over complete
//! assignments and then drops the forbidden pairs: the result is the minimum-cost matching among
//! those of maximum cardinality that use only allowed pairs. This is exact (no "big M").
//!
//! ```
//! use autoteach_detect::assignment::solve_assignment;
//! use nalgebra::DMatrix;
//! let cost = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 3.0, 2.0, 0.0, 5.0, 3.0, 2.0, 2.0]);
//! let a = solve_assignment(&cost).unwrap();
//! assert_eq!(a.row_to_col, vec![Some(1), Some(0), Some(2)]);
//! assert_eq!(a.cost, 5.0);
//! ```

// `!(x < y)` is deliberate: it is also true for NaN (an overflowed sum).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::ops::{Add, Sub};

use nalgebra::DMatrix;

use crate::{DetectError, Result};

/// The solution of an assignment problem.
#[derive(Debug, Clone, PartialEq)]
pub struct Assignment {
    /// For each row, the column assigned to it (`None`: unassigned).
    pub row_to_col: Vec<Option<usize>>,
    /// For each column, the row assigned to it (`None`: unassigned).
    pub col_to_row: Vec<Option<usize>>,
    /// Total cost: the sum of the costs of the assigned pairs (plus, for
    /// [`solve_assignment_with_unassigned`], the non-assignment costs of the unassigned rows and
    /// columns).
    pub cost: f64,
}

impl Assignment {
    /// The assigned pairs `(row, col)`, sorted by row.
    pub fn pairs(&self) -> Vec<(usize, usize)> {
        self.row_to_col
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.map(|j| (i, j)))
            .collect()
    }
}

/// Minimum-cost assignment of the rows of `cost` (rows × cols, rectangular allowed) to its
/// columns, each row and column used at most once (Crouse 2016 shortest augmenting path,
/// used for 000_3b1454b2b2194811.txt §3.2 Algorithms 1–2).
///
/// Every row (if rows ≤ cols) or every column (if cols ≤ rows) is assigned, except where
/// `+∞` (forbidden) entries make that impossible: then the matching has the maximum possible
/// number of allowed pairs and, among those, the minimum cost; rows/columns left over are
/// `None`. Zero-sized matrices give an empty assignment.
///
/// # Errors
/// [`DetectError::InvalidCost`] for a NaN or `−∞` entry; [`DetectError::Infeasible`] if the
/// finite costs are so large that sums overflow `f64`.
pub fn solve_assignment(cost: &DMatrix<f64>) -> Result<Assignment> {
    let (n, m) = cost.shape();
    check_costs("cost", cost)?;
    let transposed = n > m;
    let (nr, nc) = if transposed { (m, n) } else { (n, m) };
    // Row-major copy of the (possibly transposed) problem so the inner loop reads contiguously.
    let entry = |i: usize, j: usize| {
        if transposed {
            cost[(j, i)]
        } else {
            cost[(i, j)]
        }
    };
    let col4row = if cost.iter().any(|c| c.is_infinite()) {
        let dense: Vec<Lex> = (0..nr)
            .flat_map(|i| (0..nc).map(move |j| (i, j)))
            .map(|(i, j)| Lex::from_cost(entry(i, j)))
            .collect();
        shortest_augmenting_path(nr, nc, &dense)
    } else {
        let dense: Vec<f64> = (0..nr)
            .flat_map(|i| (0..nc).map(move |j| (i, j)))
            .map(|(i, j)| entry(i, j))
            .collect();
        // Square and far from overflow: Jonker–Volgenant (`crate::lapjv`), faster on dense
        // matrices; otherwise the shortest augmenting path, which detects overflow exactly.
        let max_abs = dense.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        if nr == nc && max_abs < f64::MAX / (4.0 * nr.max(1) as f64) {
            crate::lapjv::lapjv(nr, &dense)
        } else {
            shortest_augmenting_path(nr, nc, &dense)
        }
    }
    .ok_or_else(|| DetectError::Infeasible {
        reason: format!("the costs of the {n}×{m} matrix overflow f64 in the shortest-path sums"),
    })?;
    let mut out = Assignment {
        row_to_col: vec![None; n],
        col_to_row: vec![None; m],
        cost: 0.0,
    };
    for (r, &c) in col4row.iter().enumerate() {
        let (i, j) = if transposed { (c, r) } else { (r, c) };
        let v = cost[(i, j)];
        if v.is_finite() {
            out.row_to_col[i] = Some(j);
            out.col_to_row[j] = Some(i);
            out.cost += v;
        }
    }
    check_total(out, n, m)
}

/// Rejects a total that overflowed `f64`.
fn check_total(out: Assignment, n: usize, m: usize) -> Result<Assignment> {
    if out.cost.is_finite() {
        Ok(out)
    } else {
        Err(DetectError::Infeasible {
            reason: format!(
                "the total cost of the {n}×{m} assignment overflows f64 ({})",
                out.cost
            ),
        })
    }
}

/// Minimum-cost assignment that may leave rows and columns unassigned, at a price: leaving row
/// `i` unassigned costs `row_unassigned_cost[i]`, leaving column `j` unassigned costs
/// `col_unassigned_cost[j]`. This is the matching with a dummy vertex v₀ of
/// 000_3b1454b2b2194811.txt eq. (3.4) (an arc matched to v₀ stays alone), and the "new track /
/// track not seen" choice of track association.
///
/// Solved exactly as a square (n+m)×(m+n) problem: `[[C, diag(r)], [diag(c), 0]]` with `+∞`
/// off the diagonals of the dummy blocks. A pair `(i, j)` is chosen only when that is cheaper
/// than leaving both unassigned. `+∞` entries of `cost` are forbidden pairs; a `+∞`
/// non-assignment cost means that row/column must be assigned.
///
/// # Errors
/// [`DetectError::WrongLength`] if the vectors do not match the matrix, [`DetectError::InvalidCost`]
/// for NaN or `−∞` anywhere, [`DetectError::Infeasible`] if the "must be assigned" rows/columns
/// cannot all be assigned through allowed pairs.
pub fn solve_assignment_with_unassigned(
    cost: &DMatrix<f64>,
    row_unassigned_cost: &[f64],
    col_unassigned_cost: &[f64],
) -> Result<Assignment> {
    let (n, m) = cost.shape();
    if row_unassigned_cost.len() != n {
        return Err(DetectError::WrongLength {
            what: "row_unassigned_cost",
            got: row_unassigned_cost.len(),
            expected: n,
        });
    }
    if col_unassigned_cost.len() != m {
        return Err(DetectError::WrongLength {
            what: "col_unassigned_cost",
            got: col_unassigned_cost.len(),
            expected: m,
        });
    }
    check_costs("cost", cost)?;
    check_vector("row_unassigned_cost", row_unassigned_cost)?;
    check_vector("col_unassigned_cost", col_unassigned_cost)?;
    let size = n + m;
    let mut dense = vec![Lex::FORBIDDEN; size * size];
    for i in 0..n {
        for j in 0..m {
            dense[i * size + j] = Lex::from_cost(cost[(i, j)]);
        }
        dense[i * size + m + i] = Lex::from_cost(row_unassigned_cost[i]);
    }
    for j in 0..m {
        dense[(n + j) * size + j] = Lex::from_cost(col_unassigned_cost[j]);
        for i in 0..n {
            dense[(n + j) * size + m + i] = Lex::ZERO;
        }
    }
    let col4row =
        shortest_augmenting_path(size, size, &dense).ok_or_else(|| DetectError::Infeasible {
            reason: format!(
                "the costs of the {n}×{m} problem overflow f64 in the shortest-path sums"
            ),
        })?;
    let mut out = Assignment {
        row_to_col: vec![None; n],
        col_to_row: vec![None; m],
        cost: 0.0,
    };
    let mut forbidden_used = Vec::new();
    for (r, &c) in col4row.iter().enumerate() {
        let e = dense[r * size + c];
        if e.forbidden > 0 {
            forbidden_used.push((r, c));
            continue;
        }
        out.cost += e.cost;
        if r < n && c < m {
            out.row_to_col[r] = Some(c);
            out.col_to_row[c] = Some(r);
        }
    }
    if !forbidden_used.is_empty() {
        let must: Vec<String> = forbidden_used
            .iter()
            .map(|&(r, c)| {
                if r < n {
                    format!("row {r}")
                } else {
                    format!("column {}", c)
                }
            })
            .collect();
        return Err(DetectError::Infeasible {
            reason: format!(
                "{} cannot be assigned through allowed pairs but has an infinite non-assignment cost",
                must.join(", ")
            ),
        });
    }
    check_total(out, n, m)
}

/// Rejects NaN and −∞ entries.
fn check_costs(what: &'static str, cost: &DMatrix<f64>) -> Result<()> {
    for j in 0..cost.ncols() {
        for i in 0..cost.nrows() {
            let value = cost[(i, j)];
            if value.is_nan() || value == f64::NEG_INFINITY {
                return Err(DetectError::InvalidCost {
                    what,
                    row: i,
                    col: j,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// Rejects NaN and −∞ entries of a per-row/per-column vector.
fn check_vector(what: &'static str, v: &[f64]) -> Result<()> {
    match v.iter().position(|c| c.is_nan() || *c == f64::NEG_INFINITY) {
        Some(row) => Err(DetectError::InvalidCost {
            what,
            row,
            col: 0,
            value: v[row],
        }),
        None => Ok(()),
    }
}

/// A cost type for the shortest-path search: an ordered group with a "not reached" value
/// larger than any sum that can occur.
trait PathCost: Copy + PartialOrd + Add<Output = Self> + Sub<Output = Self> {
    /// The additive identity.
    const ZERO: Self;
    /// Larger than every reachable path cost.
    const UNREACHED: Self;
}

impl PathCost for f64 {
    const ZERO: Self = 0.0;
    const UNREACHED: Self = f64::INFINITY;
}

/// Lexicographic cost (number of forbidden pairs, sum of finite costs). Derived `PartialOrd`
/// compares the fields in order, which is the lexicographic order.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd)]
struct Lex {
    forbidden: i64,
    cost: f64,
}

impl Lex {
    const FORBIDDEN: Lex = Lex {
        forbidden: 1,
        cost: 0.0,
    };

    /// `+∞` becomes one forbidden pair; finite values are kept.
    fn from_cost(c: f64) -> Lex {
        if c == f64::INFINITY {
            Lex::FORBIDDEN
        } else {
            Lex {
                forbidden: 0,
                cost: c,
            }
        }
    }
}

impl Add for Lex {
    type Output = Lex;
    fn add(self, o: Lex) -> Lex {
        Lex {
            forbidden: self.forbidden + o.forbidden,
            cost: self.cost + o.cost,
        }
    }
}

impl Sub for Lex {
    type Output = Lex;
    fn sub(self, o: Lex) -> Lex {
        Lex {
            forbidden: self.forbidden - o.forbidden,
            cost: self.cost - o.cost,
        }
    }
}

impl PathCost for Lex {
    const ZERO: Self = Lex {
        forbidden: 0,
        cost: 0.0,
    };
    // Forbidden counts stay within ±(rows + cols), far below this.
    const UNREACHED: Self = Lex {
        forbidden: i64::MAX,
        cost: f64::INFINITY,
    };
}

/// Crouse 2016 Algorithm 1 on a row-major `nr × nc` matrix with `nr ≤ nc`: returns the column
/// of each row, or `None` when a shortest path is not finite (overflow).
fn shortest_augmenting_path<C: PathCost>(nr: usize, nc: usize, cost: &[C]) -> Option<Vec<usize>> {
    const FREE: usize = usize::MAX;
    debug_assert!(nr <= nc && cost.len() == nr * nc);
    let mut u = vec![C::ZERO; nr];
    let mut v = vec![C::ZERO; nc];
    let mut shortest = vec![C::UNREACHED; nc];
    let mut path = vec![FREE; nc];
    let mut col4row = vec![FREE; nr];
    let mut row4col = vec![FREE; nc];
    let mut row_visited = vec![false; nr];
    let mut col_visited = vec![false; nc];
    let mut remaining: Vec<usize> = Vec::with_capacity(nc);
    for cur in 0..nr {
        // Dijkstra over reduced costs from row `cur` to the nearest free column.
        remaining.clear();
        remaining.extend((0..nc).rev());
        row_visited.fill(false);
        col_visited.fill(false);
        shortest.fill(C::UNREACHED);
        let mut min_val = C::ZERO;
        let mut i = cur;
        let sink = loop {
            row_visited[i] = true;
            let row = &cost[i * nc..(i + 1) * nc];
            let base = min_val - u[i];
            let mut lowest = C::UNREACHED;
            let mut index = FREE;
            for (it, &j) in remaining.iter().enumerate() {
                let r = base + row[j] - v[j];
                if r < shortest[j] {
                    path[j] = i;
                    shortest[j] = r;
                }
                if shortest[j] < lowest || (shortest[j] == lowest && row4col[j] == FREE) {
                    lowest = shortest[j];
                    index = it;
                }
            }
            // Not finite (or NaN from overflow): no usable path.
            if index == FREE || !(lowest < C::UNREACHED) {
                return None;
            }
            min_val = lowest;
            let j = remaining.swap_remove(index);
            col_visited[j] = true;
            if row4col[j] == FREE {
                break j;
            }
            i = row4col[j];
        };
        // Update the dual variables.
        u[cur] = u[cur] + min_val;
        for r in 0..nr {
            if row_visited[r] && r != cur {
                u[r] = u[r] + (min_val - shortest[col4row[r]]);
            }
        }
        for c in 0..nc {
            if col_visited[c] {
                v[c] = v[c] - (min_val - shortest[c]);
            }
        }
        // Augment along the path back to `cur`.
        let mut j = sink;
        loop {
            let i = path[j];
            row4col[j] = i;
            std::mem::swap(&mut col4row[i], &mut j);
            if i == cur {
                break;
            }
        }
    }
    Some(col4row)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// Every matching (each row takes no column or an unused one), visited recursively.
    fn for_each_matching(n: usize, m: usize, f: &mut dyn FnMut(&[Option<usize>])) {
        fn rec(
            i: usize,
            m: usize,
            cur: &mut Vec<Option<usize>>,
            used: &mut Vec<bool>,
            f: &mut dyn FnMut(&[Option<usize>]),
        ) {
            if i == cur.len() {
                f(cur);
                return;
            }
            cur[i] = None;
            rec(i + 1, m, cur, used, f);
            for j in 0..m {
                if !used[j] {
                    used[j] = true;
                    cur[i] = Some(j);
                    rec(i + 1, m, cur, used, f);
                    used[j] = false;
                }
            }
            cur[i] = None;
        }
        rec(0, m, &mut vec![None; n], &mut vec![false; m], f);
    }

    /// Brute force: (maximum number of allowed pairs, minimum cost among those matchings).
    fn brute_force(cost: &DMatrix<f64>) -> (usize, f64) {
        let (n, m) = cost.shape();
        let mut best = (0usize, 0.0f64);
        for_each_matching(n, m, &mut |mt| {
            let mut k = 0;
            let mut c = 0.0;
            for (i, j) in mt.iter().enumerate() {
                if let Some(j) = *j {
                    if !cost[(i, j)].is_finite() {
                        return;
                    }
                    k += 1;
                    c += cost[(i, j)];
                }
            }
            if k > best.0 || (k == best.0 && c < best.1) {
                best = (k, c);
            }
        });
        best
    }

    fn brute_force_unassigned(cost: &DMatrix<f64>, ru: &[f64], cu: &[f64]) -> f64 {
        let (n, m) = cost.shape();
        let mut best = f64::INFINITY;
        for_each_matching(n, m, &mut |mt| {
            let mut c = 0.0;
            let mut col_used = vec![false; m];
            for (i, j) in mt.iter().enumerate() {
                match *j {
                    Some(j) => {
                        c += cost[(i, j)];
                        col_used[j] = true;
                    }
                    None => c += ru[i],
                }
            }
            c += (0..m).filter(|&j| !col_used[j]).map(|j| cu[j]).sum::<f64>();
            best = best.min(c);
        });
        best
    }

    /// The assignment is a valid matching of allowed pairs whose reported cost is its sum.
    fn check_consistent(cost: &DMatrix<f64>, a: &Assignment) -> usize {
        let (n, m) = cost.shape();
        assert_eq!(a.row_to_col.len(), n);
        assert_eq!(a.col_to_row.len(), m);
        let mut sum = 0.0;
        let mut k = 0;
        for (i, c) in a.row_to_col.iter().enumerate() {
            if let Some(j) = *c {
                assert_eq!(a.col_to_row[j], Some(i));
                assert!(cost[(i, j)].is_finite());
                sum += cost[(i, j)];
                k += 1;
            }
        }
        assert_eq!(a.col_to_row.iter().filter(|r| r.is_some()).count(), k);
        assert!(
            (sum - a.cost).abs() < 1e-9,
            "reported {} vs sum {sum}",
            a.cost
        );
        k
    }

    fn random_matrix(
        rng: &mut Pcg64,
        n: usize,
        m: usize,
        p_forbidden: f64,
        integer: bool,
    ) -> DMatrix<f64> {
        DMatrix::from_fn(n, m, |_, _| {
            if rng.random::<f64>() < p_forbidden {
                f64::INFINITY
            } else if integer {
                // Small integers make many ties, which stresses the tie handling.
                rng.random_range(0..4) as f64
            } else {
                rng.random_range(-5.0..10.0)
            }
        })
    }

    #[test]
    fn matches_brute_force_on_random_small_matrices() {
        let mut rng = Pcg64::seed_from_u64(7);
        for trial in 0..600 {
            let n = rng.random_range(1..=6);
            let m = rng.random_range(1..=6);
            let p = [0.0, 0.0, 0.2, 0.5, 0.8][trial % 5];
            let cost = random_matrix(&mut rng, n, m, p, trial % 3 == 0);
            let a = solve_assignment(&cost).unwrap();
            let k = check_consistent(&cost, &a);
            let (bk, bc) = brute_force(&cost);
            assert_eq!(k, bk, "cardinality, trial {trial}, cost {cost}");
            assert!(
                (a.cost - bc).abs() < 1e-9,
                "trial {trial}: {} vs brute force {bc}\n{cost}",
                a.cost
            );
        }
    }

    #[test]
    fn matches_brute_force_on_7x7_and_rectangular_7() {
        let mut rng = Pcg64::seed_from_u64(11);
        for (n, m) in [(7, 7), (7, 4), (3, 7)] {
            for p in [0.0, 0.3] {
                let cost = random_matrix(&mut rng, n, m, p, false);
                let a = solve_assignment(&cost).unwrap();
                let k = check_consistent(&cost, &a);
                let (bk, bc) = brute_force(&cost);
                assert_eq!(k, bk);
                assert!((a.cost - bc).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn forbidden_pairs_do_not_hide_a_cheaper_matching() {
        // Row 0 can only take column 0 (cost 10); row 1 also only column 0 (cost 1).
        // A greedy row-by-row solver that skips unmatchable rows would keep (0, 0).
        let inf = f64::INFINITY;
        let cost = DMatrix::from_row_slice(2, 2, &[10.0, inf, 1.0, inf]);
        let a = solve_assignment(&cost).unwrap();
        assert_eq!(a.row_to_col, vec![None, Some(0)]);
        assert_eq!(a.col_to_row, vec![Some(1), None]);
        assert_eq!(a.cost, 1.0);
    }

    #[test]
    fn degenerate_matrices() {
        // Zero-size in either direction.
        for (n, m) in [(0, 0), (0, 3), (4, 0)] {
            let a = solve_assignment(&DMatrix::zeros(n, m)).unwrap();
            assert_eq!(a.row_to_col, vec![None; n]);
            assert_eq!(a.col_to_row, vec![None; m]);
            assert_eq!(a.cost, 0.0);
        }
        // All equal: any perfect matching, cost n * c.
        let a = solve_assignment(&DMatrix::from_element(5, 5, 2.5)).unwrap();
        assert_eq!(check_consistent(&DMatrix::from_element(5, 5, 2.5), &a), 5);
        assert_eq!(a.cost, 12.5);
        // All forbidden: nothing assigned.
        let all = DMatrix::from_element(3, 4, f64::INFINITY);
        let a = solve_assignment(&all).unwrap();
        assert_eq!(a.row_to_col, vec![None; 3]);
        assert_eq!(a.col_to_row, vec![None; 4]);
        // One fully forbidden row stays unassigned; the others are optimal.
        let inf = f64::INFINITY;
        let cost = DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 3.0, inf, inf, inf, 3.0, 1.0, 2.0]);
        let a = solve_assignment(&cost).unwrap();
        assert_eq!(a.row_to_col, vec![Some(0), None, Some(1)]);
        assert_eq!(a.cost, 2.0);
    }

    #[test]
    fn nan_and_negative_infinity_are_errors() {
        let mut cost = DMatrix::from_element(3, 3, 1.0);
        cost[(1, 2)] = f64::NAN;
        assert!(matches!(
            solve_assignment(&cost),
            Err(DetectError::InvalidCost { row: 1, col: 2, .. })
        ));
        cost[(1, 2)] = f64::NEG_INFINITY;
        assert!(matches!(
            solve_assignment(&cost),
            Err(DetectError::InvalidCost { row: 1, col: 2, .. })
        ));
        let ok = DMatrix::from_element(2, 2, 1.0);
        assert!(matches!(
            solve_assignment_with_unassigned(&ok, &[1.0, f64::NAN], &[1.0, 1.0]),
            Err(DetectError::InvalidCost {
                what: "row_unassigned_cost",
                row: 1,
                ..
            })
        ));
        assert!(matches!(
            solve_assignment_with_unassigned(&ok, &[1.0], &[1.0, 1.0]),
            Err(DetectError::WrongLength {
                what: "row_unassigned_cost",
                got: 1,
                expected: 2
            })
        ));
    }

    #[test]
    fn overflowing_costs_are_an_error_not_a_panic() {
        let cost = DMatrix::from_row_slice(2, 2, &[f64::MAX, -f64::MAX, -f64::MAX, f64::MAX]);
        // Either solved or reported; never a panic or a non-finite total.
        match solve_assignment(&cost) {
            Ok(a) => assert!(a.cost.is_finite()),
            Err(e) => assert!(matches!(e, DetectError::Infeasible { .. })),
        }
    }

    #[test]
    fn with_unassigned_matches_brute_force() {
        let mut rng = Pcg64::seed_from_u64(3);
        for trial in 0..300 {
            let n = rng.random_range(0..=5);
            let m = rng.random_range(0..=5);
            let cost = random_matrix(
                &mut rng,
                n,
                m,
                if trial % 2 == 0 { 0.3 } else { 0.0 },
                trial % 3 == 0,
            );
            let ru: Vec<f64> = (0..n).map(|_| rng.random_range(0.0..6.0)).collect();
            let cu: Vec<f64> = (0..m).map(|_| rng.random_range(0.0..6.0)).collect();
            let a = solve_assignment_with_unassigned(&cost, &ru, &cu).unwrap();
            check_consistent_unassigned(&cost, &ru, &cu, &a);
            let bc = brute_force_unassigned(&cost, &ru, &cu);
            assert!(
                (a.cost - bc).abs() < 1e-9,
                "trial {trial}: {} vs {bc}",
                a.cost
            );
        }
    }

    fn check_consistent_unassigned(cost: &DMatrix<f64>, ru: &[f64], cu: &[f64], a: &Assignment) {
        let mut total = 0.0;
        for (i, c) in a.row_to_col.iter().enumerate() {
            match *c {
                Some(j) => {
                    assert_eq!(a.col_to_row[j], Some(i));
                    total += cost[(i, j)];
                }
                None => total += ru[i],
            }
        }
        for (j, r) in a.col_to_row.iter().enumerate() {
            if r.is_none() {
                total += cu[j];
            }
        }
        assert!((total - a.cost).abs() < 1e-9);
    }

    #[test]
    fn with_unassigned_dummy_arc_example() {
        // Two arcs that fit well together and one that fits nothing: the third stays alone
        // (matched to the dummy arc v0 of eq. 3.4).
        let inf = f64::INFINITY;
        let r = DMatrix::from_row_slice(3, 3, &[inf, 0.3, 5.0, 0.3, inf, 6.0, 5.0, 6.0, inf]);
        let a = solve_assignment_with_unassigned(&r, &[1.0; 3], &[1.0; 3]).unwrap();
        assert_eq!(a.row_to_col, vec![Some(1), Some(0), None]);
        assert!((a.cost - (0.6 + 2.0)).abs() < 1e-12);
    }

    #[test]
    fn with_unassigned_infinite_cost_means_must_assign() {
        let inf = f64::INFINITY;
        let cost = DMatrix::from_row_slice(2, 2, &[5.0, inf, inf, inf]);
        // Row 0 must be assigned even though leaving it is cheaper... it can: (0, 0).
        let a = solve_assignment_with_unassigned(&cost, &[inf, 1.0], &[0.0, 0.0]).unwrap();
        assert_eq!(a.row_to_col, vec![Some(0), None]);
        assert_eq!(a.cost, 6.0);
        // Row 1 must be assigned but every pair of row 1 is forbidden.
        assert!(matches!(
            solve_assignment_with_unassigned(&cost, &[1.0, inf], &[0.0, 0.0]),
            Err(DetectError::Infeasible { .. })
        ));
    }
}

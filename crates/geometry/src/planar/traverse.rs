//! Grid-cell traversal of a segment (Amanatides & Woo, "A fast voxel traversal algorithm for
//! ray tracing", 1987), the free-space part of a laser beam in an occupancy grid (seed
//! 004_815695db12a6b16c.txt §2.1: each node's scan rasterized onto a grid).

/// The integer cell containing a point given in cell units (`floor`).
#[inline]
pub fn cell_of(p: f64) -> i32 {
    p.floor() as i32
}

/// Calls `visit(i, j)` for every cell crossed by the segment `a → b` (coordinates in CELL
/// units, i.e. metres divided by the resolution), in order, starting with the cell of `a` and
/// EXCLUDING the cell of `b` (the beam's end cell, a hit or the max-range end, is the
/// caller's). Each cell is visited once; a segment inside one cell visits nothing.
///
/// Non-finite coordinates visit nothing.
#[inline]
pub fn traverse_cells<F: FnMut(i32, i32)>(a: [f64; 2], b: [f64; 2], mut visit: F) {
    if !(a[0].is_finite() && a[1].is_finite() && b[0].is_finite() && b[1].is_finite()) {
        return;
    }
    let (mut i, mut j) = (cell_of(a[0]), cell_of(a[1]));
    let (ie, je) = (cell_of(b[0]), cell_of(b[1]));
    let n = (ie - i).unsigned_abs() + (je - j).unsigned_abs();
    if n == 0 {
        return;
    }
    let dx = b[0] - a[0];
    let dy = b[1] - a[1];
    let step_i = if dx > 0.0 { 1 } else { -1 };
    let step_j = if dy > 0.0 { 1 } else { -1 };
    // Parameter t ∈ [0, 1] along the segment at which the next vertical / horizontal cell
    // boundary is crossed, and its increment per cell.
    let (mut t_max_x, t_delta_x) = if dx != 0.0 {
        let next = if dx > 0.0 { i as f64 + 1.0 } else { i as f64 };
        ((next - a[0]) / dx, (1.0 / dx).abs())
    } else {
        (f64::INFINITY, f64::INFINITY)
    };
    let (mut t_max_y, t_delta_y) = if dy != 0.0 {
        let next = if dy > 0.0 { j as f64 + 1.0 } else { j as f64 };
        ((next - a[1]) / dy, (1.0 / dy).abs())
    } else {
        (f64::INFINITY, f64::INFINITY)
    };
    // Exactly n boundary crossings lead from the start cell to the end cell (a crossing
    // through a cell corner is taken as two, x first, so the walk never skips a cell).
    for _ in 0..n {
        visit(i, j);
        if t_max_x < t_max_y {
            if i == ie {
                // Rounding: the x boundaries are exhausted; walk y.
                j += step_j;
                t_max_y += t_delta_y;
            } else {
                i += step_i;
                t_max_x += t_delta_x;
            }
        } else if j == je {
            i += step_i;
            t_max_x += t_delta_x;
        } else {
            j += step_j;
            t_max_y += t_delta_y;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent truth: dense sampling of the segment (cells containing sample points).
    fn sampled(a: [f64; 2], b: [f64; 2]) -> Vec<(i32, i32)> {
        let n = 200_000;
        let mut out: Vec<(i32, i32)> = vec![];
        for k in 0..n {
            let t = k as f64 / n as f64;
            let c = (
                cell_of(a[0] + t * (b[0] - a[0])),
                cell_of(a[1] + t * (b[1] - a[1])),
            );
            if out.last() != Some(&c) {
                out.push(c);
            }
        }
        let end = (cell_of(b[0]), cell_of(b[1]));
        while out.last() == Some(&end) {
            out.pop();
        }
        out
    }

    #[test]
    fn traversal_matches_dense_sampling() {
        let cases = [
            ([0.3, 0.2], [7.9, 3.1]),
            ([-2.2, 5.7], [3.3, -4.4]),
            ([10.5, 1.5], [-3.25, 1.75]),
            ([0.5, 0.5], [0.5, -8.5]),
            ([1.1, 1.2], [1.3, 1.4]),
            ([-0.7, -0.3], [-12.9, -5.1]),
        ];
        for (a, b) in cases {
            let mut got = vec![];
            traverse_cells(a, b, |i, j| got.push((i, j)));
            assert_eq!(got, sampled(a, b), "{a:?} -> {b:?}");
        }
    }

    #[test]
    fn non_finite_endpoints_visit_nothing() {
        let mut n = 0;
        traverse_cells([0.0, 0.0], [f64::NAN, 1.0], |_, _| n += 1);
        traverse_cells([0.0, f64::INFINITY], [3.0, 1.0], |_, _| n += 1);
        assert_eq!(n, 0);
    }
}

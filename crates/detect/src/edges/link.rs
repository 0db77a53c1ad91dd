//! Chaining of edge points into ordered curves with 8-connectivity (von Gioi & Randall 2017,
//! §3.3); step 2 of the pipeline in [`crate::edges`].

#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::*;

/// Options of [`link_edges`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkParams {
    /// Smallest cosine between the gradient directions of two linked edgels. Default
    /// `cos 40°`.
    pub min_gradient_cos: f64,
}

impl Default for LinkParams {
    fn default() -> Self {
        Self {
            min_gradient_cos: 40f64.to_radians().cos(),
        }
    }
}

/// Links edgels into chains (000_3b1454b2b2194811.txt §3.2: "An arc is a curve of connected
/// points"). Each edgel `e` is linked forward to the 8-neighbour `f` that lies ahead along the
/// edge direction `t = (g_y, −g_x)/‖g‖` (brighter side on the left, image y down) and whose
/// gradient makes an angle under `acos(min_gradient_cos)` with `e`'s, choosing the closest
/// (sub-pixel distance) one; a neighbour claimed by two edgels keeps the closer one, so
/// junctions split into separate chains (von Gioi & Randall 2017, §3.3). Chains are returned in
/// edge-direction order, as edgel indices; closed contours are cut at their first edgel.
///
/// # Errors
/// [`DetectError::InvalidParameter`] if `min_gradient_cos` is not in `[-1, 1]`.
pub fn link_edges(map: &EdgeMap, params: &LinkParams) -> Result<Vec<Vec<u32>>> {
    if !(params.min_gradient_cos >= -1.0 && params.min_gradient_cos <= 1.0) {
        return Err(DetectError::InvalidParameter {
            what: "min_gradient_cos",
            value: params.min_gradient_cos,
            reason: "must be in [-1, 1]",
        });
    }
    let n = map.edgels.len();
    let (w, h) = (map.width as isize, map.height as isize);
    let mut next = vec![NONE; n];
    let mut prev = vec![NONE; n];
    let mut prev_dist = vec![f64::INFINITY; n];
    // Gradient magnitudes, once per edgel (each is read again by up to eight neighbours).
    let norms: Vec<f64> = map.edgels.iter().map(|e| e.grad.norm()).collect();
    for (i, (e, &gn)) in map.edgels.iter().zip(&norms).enumerate() {
        if !(gn > 0.0) {
            continue;
        }
        let g = e.grad / gn;
        let t = Vector2::new(g.y, -g.x);
        let mut best = (NONE, f64::INFINITY);
        for dy in [-1isize, 0, 1] {
            for dx in [-1isize, 0, 1] {
                if dx == 0 && dy == 0 {
                    continue;
                }
                let (qx, qy) = (e.px as isize + dx, e.py as isize + dy);
                if qx < 0 || qy < 0 || qx >= w || qy >= h {
                    continue;
                }
                let j = map.index[(qy * w + qx) as usize];
                if j == NONE {
                    continue;
                }
                let f = &map.edgels[j as usize];
                let d = f.pos - e.pos;
                if !(d.dot(&t) > 0.0) {
                    continue;
                }
                let fg = norms[j as usize];
                if !(f.grad.dot(&g) >= params.min_gradient_cos * fg) {
                    continue;
                }
                let dist = d.norm();
                if dist < best.1 {
                    best = (j, dist);
                }
            }
        }
        let (j, dist) = best;
        if j == NONE {
            continue;
        }
        let ju = j as usize;
        if dist < prev_dist[ju] {
            // Replace a farther claim on `j`.
            if prev[ju] != NONE {
                next[prev[ju] as usize] = NONE;
            }
            prev[ju] = i as u32;
            prev_dist[ju] = dist;
            next[i] = j;
        }
    }
    let mut visited = vec![false; n];
    let mut chains = Vec::new();
    // Open chains first (start where nothing links in), then what remains (closed loops).
    for pass in 0..2 {
        for start in 0..n {
            if visited[start] || (pass == 0 && prev[start] != NONE) {
                continue;
            }
            let mut chain = Vec::new();
            let mut k = start as u32;
            while k != NONE && !visited[k as usize] {
                visited[k as usize] = true;
                chain.push(k);
                k = next[k as usize];
            }
            chains.push(chain);
        }
    }
    Ok(chains)
}

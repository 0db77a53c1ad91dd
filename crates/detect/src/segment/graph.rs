//! The segmentation graph (seed 004_815695db12a6b16c.txt ch. 4.2): the scan-topology mesh, in
//! which "each point … is connected by a potential edge to its 8 neighbours in the current,
//! previous and subsequent scans", with edges "up to a specified length" kept (the edge cut,
//! Table 4.1); and, for unorganised clouds, a k-nearest-neighbour graph on a k-d tree.

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::{DetectError, Result};

/// An undirected graph over point indices with a compressed adjacency (both directions).
#[derive(Debug, Clone, PartialEq)]
pub struct Graph {
    /// Number of vertices.
    pub n: usize,
    /// Each undirected edge once, `[i, j]` with `i < j`, in generation order.
    pub edges: Vec<[u32; 2]>,
    /// `adjacency[offsets[i]..offsets[i + 1]]` are the neighbours of `i`.
    pub offsets: Vec<u32>,
    /// Concatenated neighbour lists.
    pub adjacency: Vec<u32>,
}

impl Graph {
    /// Builds the adjacency of `edges` over `n` vertices (O(n + m)).
    pub fn from_edges(n: usize, edges: Vec<[u32; 2]>) -> Self {
        let mut offsets = vec![0u32; n + 1];
        for &[i, j] in &edges {
            offsets[i as usize + 1] += 1;
            offsets[j as usize + 1] += 1;
        }
        for k in 0..n {
            offsets[k + 1] += offsets[k];
        }
        let mut fill = offsets.clone();
        let mut adjacency = vec![0u32; edges.len() * 2];
        for &[i, j] in &edges {
            adjacency[fill[i as usize] as usize] = j;
            fill[i as usize] += 1;
            adjacency[fill[j as usize] as usize] = i;
            fill[j as usize] += 1;
        }
        Self {
            n,
            edges,
            offsets,
            adjacency,
        }
    }

    /// Neighbours of vertex `i`.
    #[inline]
    pub fn neighbours(&self, i: usize) -> &[u32] {
        &self.adjacency[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

fn check_edge_cut(edge_cut: f64) -> Result<f64> {
    if !(edge_cut.is_finite() && edge_cut > 0.0) {
        return Err(DetectError::InvalidParameter {
            what: "edge_cut",
            value: edge_cut,
            reason: "the maximum edge length must be positive and finite (metres)",
        });
    }
    Ok(edge_cut * edge_cut)
}

fn check_count(n: usize) -> Result<()> {
    if u32::try_from(n).is_err() {
        return Err(DetectError::InvalidParameter {
            what: "number of points",
            value: n as f64,
            reason: "at most u32::MAX points",
        });
    }
    Ok(())
}

#[inline]
fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// The scan-topology mesh of an organised cloud: `points` holds `lines × beams` rows, scan
/// line by scan line; a row with a NaN coordinate is a missing point (no return, or no colour)
/// and has no edges. Every point is joined to its 8-neighbours in the previous, current and
/// next scan line whose distance is at most `edge_cut` (metres).
///
/// Errors: `WrongLength` if `points.len() != lines * beams`; `NonFinite` for an infinite
/// coordinate; `InvalidParameter` for a bad `edge_cut`.
pub fn scan_graph(points: &[[f64; 3]], lines: usize, beams: usize, edge_cut: f64) -> Result<Graph> {
    let cut2 = check_edge_cut(edge_cut)?;
    let n = lines
        .checked_mul(beams)
        .ok_or(DetectError::InvalidParameter {
            what: "lines * beams",
            value: f64::INFINITY,
            reason: "overflows",
        })?;
    if points.len() != n {
        return Err(DetectError::WrongLength {
            what: "points (lines * beams rows)",
            got: points.len(),
            expected: n,
        });
    }
    check_count(n)?;
    let valid: Vec<bool> = points
        .iter()
        .map(|p| !(p[0].is_nan() || p[1].is_nan() || p[2].is_nan()))
        .collect();
    if let Some((index, value)) = points
        .iter()
        .enumerate()
        .flat_map(|(i, p)| p.iter().map(move |v| (i, *v)))
        .find(|(_, v)| v.is_infinite())
    {
        return Err(DetectError::NonFinite {
            what: "points",
            index,
            value,
        });
    }
    let mut edges = Vec::with_capacity(n * 4);
    for l in 0..lines {
        for b in 0..beams {
            let i = l * beams + b;
            if !valid[i] {
                continue;
            }
            // Forward half of the 8-neighbourhood: right in this line, and the three
            // neighbours in the next line; the other half comes from those points.
            let mut push = |j: usize| {
                if valid[j] && dist2(&points[i], &points[j]) <= cut2 {
                    edges.push([i as u32, j as u32]);
                }
            };
            if b + 1 < beams {
                push(i + 1);
            }
            if l + 1 < lines {
                let nb = i + beams;
                if b > 0 {
                    push(nb - 1);
                }
                push(nb);
                if b + 1 < beams {
                    push(nb + 1);
                }
            }
        }
    }
    Ok(Graph::from_edges(n, edges))
}

/// The k-nearest-neighbour graph of an unorganised cloud (a k-d tree, `kiddo`): each point is
/// joined to its `k` nearest other points, edges longer than `edge_cut` removed, duplicates
/// merged. Every coordinate must be finite (`NonFinite` names the first that is not).
pub fn knn_graph(points: &[[f64; 3]], k: usize, edge_cut: f64) -> Result<Graph> {
    let cut2 = check_edge_cut(edge_cut)?;
    let n = points.len();
    check_count(n)?;
    if k == 0 {
        return Err(DetectError::InvalidParameter {
            what: "k",
            value: 0.0,
            reason: "the k-NN graph needs k >= 1",
        });
    }
    check_points_finite(points)?;
    if n < 2 {
        return Ok(Graph::from_edges(n, Vec::new()));
    }
    let tree =
        ImmutableKdTree::<f64, 3>::new_from_slice(points).map_err(|e| DetectError::Degenerate {
            reason: format!("k-d tree construction failed: {e:?}"),
        })?;
    // More neighbours than the other n − 1 points is the complete graph: k is capped there, so a
    // huge k neither overflows k + 1 nor sizes an impossible edge buffer.
    let k = k.min(n - 1);
    let kk = NonZero::new(k + 1).ok_or(DetectError::TooFewPoints {
        what: "points",
        got: n,
        needed: 1,
    })?;
    let mut edges = Vec::with_capacity(n * k);
    for (i, p) in points.iter().enumerate() {
        for nb in tree
            .query(p)
            .nearest_n::<SquaredEuclidean<f64>>(kk)
            .execute()
        {
            let j = nb.item as usize;
            if j != i && nb.distance <= cut2 {
                let (a, b) = if i < j { (i, j) } else { (j, i) };
                edges.push([a as u32, b as u32]);
            }
        }
    }
    edges.sort_unstable();
    edges.dedup();
    Ok(Graph::from_edges(n, edges))
}

/// Fails with `NonFinite` at the first NaN/inf coordinate.
pub fn check_points_finite<const N: usize>(points: &[[f64; N]]) -> Result<()> {
    for (index, p) in points.iter().enumerate() {
        if let Some(&value) = p.iter().find(|v| !v.is_finite()) {
            return Err(DetectError::NonFinite {
                what: "points",
                index,
                value,
            });
        }
    }
    Ok(())
}

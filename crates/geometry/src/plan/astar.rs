//! A* on a joint-space lattice, 000_3b1454b2b2194811.txt ch. 2.3 ("Search-based path planning
//! in discretized joint space").
//!
//! * Lattice: the planned joints (3 to 5 of them) on a grid anchored at the start with a step
//!   per joint; the other joints stay at their start values (and must equal the goal's). Each
//!   node has the `3^k − 1` neighbours of the king's-move stencil; an edge costs its weighted
//!   Euclidean length `‖w ⊙ Δq‖`.
//! * Heuristic: the cost of the cheapest path on the obstacle-free lattice. With `n_i` steps
//!   of joint `i` left and `c_i = w_i·step_i`, a move changing the joint set `S` costs
//!   `f(S) = √(Σ_{i∈S} c_i²)`, a submodular set function; the cheapest way to make `n` unit
//!   changes is the nested ("octile") decomposition, whose cost is the Lovász extension
//!   `Σ_k (n_(k) − n_(k+1))·f({(1)…(k)})` over the `n` sorted descending, and for submodular
//!   `f` that extension is the convex closure, i.e. a lower bound of every decomposition. It
//!   is a shortest-path distance, so it is admissible and consistent, and A* returns the
//!   cheapest lattice path, as the seed requires ("an admissible heuristic function will make
//!   A* return the shortest path"). In 5-D it is far tighter than the Euclidean distance
//!   (a diagonal of the lattice is as long as the straight line only along the axes).
//! * Lazy collision checks (lazy weighted A*): the seed pre-computes the feasibility of every
//!   node; here neither nodes nor edges are checked when they are generated. An open entry
//!   carries its parent, and only when it is popped is the node's clearance computed (cached)
//!   and its edge to the parent certified: free if `(d_a + d_b − ρ)/2 ≥ margin` for clearance
//!   lower bounds `d_a, d_b` and `ρ` the sweep bound of the edge
//!   ([`PlanWorkspace::sweep_bound`]), else by conservative advancement. A failed edge is
//!   remembered and the node's best parent recomputed among its closed neighbours. The edge
//!   costs are their lengths whatever the checks say (a blocked edge is removed, not made
//!   dearer), so the search still returns the cheapest path over the same free edges, with
//!   about one check per expansion instead of one per generated neighbour (`3^k − 1` of them).
//! * Bookkeeping without searching: one hash map from the node's packed index to its state
//!   (best cost, parent, closed flag, clearance), the seed's "matrix that stores the node's
//!   state", a binary heap as the open set (stale entries skipped on pop) and a hash set of the
//!   edges found blocked.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap, HashSet};

use crate::robot::Joints;

use super::PlanError;
use super::workspace::PlanWorkspace;

/// Settings of [`astar`].
#[derive(Debug, Clone, PartialEq)]
pub struct AStarConfig {
    /// Indices of the planned joints (3 to 5 distinct values in `0..5`).
    pub joints: Vec<usize>,
    /// Lattice step per joint (rad, and m for the lift); only the planned joints' entries are used.
    pub step: Joints,
    /// Metric weights `w` of the cost `‖w ⊙ Δq‖` (1 for angles; the lift in rad per metre).
    pub weights: Joints,
    /// Required clearance (m).
    pub margin: f64,
    /// Budget of nodes popped from the open set (expanded, or found not free or blocked by
    /// the edge to their parent).
    pub max_expansions: usize,
}

impl Default for AStarConfig {
    /// All five joints, 5° steps and 25 mm on the lift, weights 1 and 5 rad/m, 10 mm margin.
    fn default() -> Self {
        let d = 5f64.to_radians();
        Self {
            joints: vec![0, 1, 2, 3, 4],
            step: Joints::new(d, d, d, d, 0.025),
            weights: Joints::new(1.0, 1.0, 1.0, 1.0, 5.0),
            margin: 0.01,
            max_expansions: 5_000_000,
        }
    }
}

/// A planned path.
#[derive(Debug, Clone, PartialEq)]
pub struct PathResult {
    /// Way-points from the start to the goal.
    pub path: Vec<Joints>,
    /// Weighted length `Σ ‖w ⊙ Δq‖` of the path.
    pub cost: f64,
    /// Nodes expanded (A*) or iterations run (RRT*).
    pub iterations: usize,
    /// Configuration collision checks made.
    pub collision_checks: u64,
    /// Seconds spent.
    pub time_s: f64,
}

#[derive(Debug, Clone, Copy)]
struct Node {
    g: f64,
    parent: u64,
    closed: bool,
    /// Clearance lower bound, `NEG_INFINITY` when the node is not free, NaN until computed.
    clearance: f64,
}

#[derive(Debug, PartialEq)]
struct Open {
    f: f64,
    g: f64,
    key: u64,
    /// The parent this entry was pushed for (an entry is stale unless it is the node's current).
    parent: u64,
}

impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on f, ties broken towards larger g (deeper nodes).
        other
            .f
            .total_cmp(&self.f)
            .then_with(|| self.g.total_cmp(&other.g))
            .then_with(|| other.key.cmp(&self.key))
            .then_with(|| other.parent.cmp(&self.parent))
    }
}

/// Bits per joint of the packed node key.
const BITS: u32 = 12;
const OFFSET: i64 = 1 << (BITS - 1);

/// The lattice of a search: anchor, steps, planned joints and index bounds.
pub(crate) struct Lattice {
    pub(crate) start: Joints,
    pub(crate) step: Joints,
    pub(crate) joints: Vec<usize>,
    pub(crate) lo: Vec<i64>,
    pub(crate) hi: Vec<i64>,
}

impl Lattice {
    pub(crate) fn pack(&self, idx: &[i64]) -> u64 {
        idx.iter()
            .fold(0u64, |k, &i| (k << BITS) | (i + OFFSET) as u64)
    }

    pub(crate) fn unpack(&self, key: u64) -> Vec<i64> {
        let n = self.joints.len();
        (0..n)
            .map(|j| ((key >> (BITS as usize * (n - 1 - j))) & ((1 << BITS) - 1)) as i64 - OFFSET)
            .collect()
    }

    pub(crate) fn config(&self, idx: &[i64]) -> Joints {
        let mut q = self.start;
        for (j, &i) in self.joints.iter().zip(idx) {
            q[*j] += self.step[*j] * i as f64;
        }
        q
    }

    pub(crate) fn stencil(&self) -> Vec<Vec<i64>> {
        let n = self.joints.len();
        let mut out = Vec::new();
        for code in 0..3usize.pow(n as u32) {
            let mut c = code;
            let off: Vec<i64> = (0..n)
                .map(|_| {
                    let v = (c % 3) as i64 - 1;
                    c /= 3;
                    v
                })
                .collect();
            if off.iter().any(|&v| v != 0) {
                out.push(off);
            }
        }
        out
    }
}

pub(crate) fn build_lattice(
    ws: &PlanWorkspace,
    start: &Joints,
    goal: &Joints,
    cfg: &AStarConfig,
) -> Result<(Lattice, Vec<i64>), PlanError> {
    let mut seen = [false; 5];
    if !(3..=5).contains(&cfg.joints.len())
        || cfg
            .joints
            .iter()
            .any(|&j| j >= 5 || std::mem::replace(&mut seen[j], true))
    {
        return Err(PlanError::InvalidInput {
            what: "A* joints",
            reason: format!(
                "{:?}: need 3 to 5 distinct joint indices in 0..5",
                cfg.joints
            ),
        });
    }
    for &j in &cfg.joints {
        if !(cfg.step[j].is_finite() && cfg.step[j] > 0.0) {
            return Err(PlanError::InvalidInput {
                what: "A* lattice step",
                reason: format!("joint {j}: step {} must be positive", cfg.step[j]),
            });
        }
    }
    if let Some(j) =
        (0..5).find(|j| !cfg.joints.contains(j) && (goal[*j] - start[*j]).abs() > 1e-12)
    {
        return Err(PlanError::InvalidInput {
            what: "A* goal",
            reason: format!(
                "joint {j} is not planned but differs between start ({}) and goal ({})",
                start[j], goal[j]
            ),
        });
    }
    let lat = Lattice {
        start: *start,
        step: cfg.step,
        joints: cfg.joints.clone(),
        lo: cfg
            .joints
            .iter()
            .map(|&j| ((ws.lower[j] - start[j]) / cfg.step[j]).ceil() as i64)
            .collect(),
        hi: cfg
            .joints
            .iter()
            .map(|&j| ((ws.upper[j] - start[j]) / cfg.step[j]).floor() as i64)
            .collect(),
    };
    if lat.lo.iter().chain(&lat.hi).any(|v| v.abs() >= OFFSET) {
        return Err(PlanError::InvalidInput {
            what: "A* lattice",
            reason: format!("more than {} steps per joint; use a coarser step", OFFSET),
        });
    }
    let goal_idx: Vec<i64> = cfg
        .joints
        .iter()
        .enumerate()
        .map(|(k, &j)| {
            (((goal[j] - start[j]) / cfg.step[j]).round() as i64).clamp(lat.lo[k], lat.hi[k])
        })
        .collect();
    Ok((lat, goal_idx))
}

/// The goal node: among the rounded goal index and its stencil neighbours, the free node
/// nearest the goal that a certified segment joins to it.
pub(crate) fn goal_node(
    ws: &PlanWorkspace,
    lat: &Lattice,
    rounded: &[i64],
    goal: &Joints,
    cfg: &AStarConfig,
    checks: &mut u64,
) -> Result<Vec<i64>, PlanError> {
    let mut cands: Vec<Vec<i64>> = vec![rounded.to_vec()];
    for off in lat.stencil() {
        let nb: Vec<i64> = rounded.iter().zip(&off).map(|(a, b)| a + b).collect();
        if nb
            .iter()
            .enumerate()
            .all(|(k, &v)| v >= lat.lo[k] && v <= lat.hi[k])
        {
            cands.push(nb);
        }
    }
    cands.sort_by(|a, b| {
        let da = weighted(&cfg.weights, &(lat.config(a) - goal));
        let db = weighted(&cfg.weights, &(lat.config(b) - goal));
        da.total_cmp(&db).then_with(|| a.cmp(b))
    });
    cands
        .into_iter()
        .find(|c| ws.segment_free_counted(&lat.config(c), goal, cfg.margin, checks))
        .ok_or_else(|| PlanError::NoPath {
            method: "a*",
            reason: "no lattice node next to the goal can be joined to it by a free segment; use a finer step".into(),
        })
}

fn weighted(w: &Joints, d: &Joints) -> f64 {
    d.component_mul(w).norm()
}

/// A* from `start` to `goal` (module docs). The last lattice node is joined to the exact goal
/// by a certified straight segment. Errors: start or goal not free ([`PlanError::InCollision`]),
/// malformed settings, or [`PlanError::NoPath`] when the reachable lattice or the budget is
/// exhausted.
pub fn astar(
    ws: &PlanWorkspace,
    start: &Joints,
    goal: &Joints,
    cfg: &AStarConfig,
) -> Result<PathResult, PlanError> {
    let t0 = std::time::Instant::now();
    ws.require_free("start", start, cfg.margin)?;
    ws.require_free("goal", goal, cfg.margin)?;
    let (lat, goal_idx) = build_lattice(ws, start, goal, cfg)?;
    let stencil = lat.stencil();
    let w = cfg.weights;
    let goal_idx = goal_node(ws, &lat, &goal_idx, goal, cfg, &mut 0)?;
    let goal_key = lat.pack(&goal_idx);
    let goal_q = lat.config(&goal_idx);
    let unit: Vec<f64> = lat.joints.iter().map(|&j| w[j] * lat.step[j]).collect();
    let h = |idx: &[i64]| lattice_distance(&unit, &goal_idx, idx);
    let mut checks = 0u64;
    let mut nodes: HashMap<u64, Node> = HashMap::with_capacity(1 << 16);
    let mut blocked: HashSet<(u64, u64)> = HashSet::new();
    let mut open = BinaryHeap::new();
    let start_idx = vec![0i64; lat.joints.len()];
    let start_key = lat.pack(&start_idx);
    nodes.insert(
        start_key,
        Node {
            g: 0.0,
            parent: start_key,
            closed: false,
            clearance: f64::NAN,
        },
    );
    open.push(Open {
        f: h(&start_idx),
        g: 0.0,
        key: start_key,
        parent: start_key,
    });
    let mut expansions = 0usize;
    let mut pops = 0usize;
    let mut found = false;
    let mut nb = vec![0i64; lat.joints.len()];
    let in_bounds = |nb: &[i64]| (0..nb.len()).all(|k| nb[k] >= lat.lo[k] && nb[k] <= lat.hi[k]);
    while let Some(Open { g, key, parent, .. }) = open.pop() {
        let node = nodes[&key];
        if node.closed || g != node.g || parent != node.parent {
            continue;
        }
        // The budget counts every entry that costs checks, blocked ones included: a search
        // whose pops are mostly blocked edges must stop too.
        pops += 1;
        if pops > cfg.max_expansions {
            break;
        }
        let idx = lat.unpack(key);
        let q = lat.config(&idx);
        // The node, then its edge to the parent, checked now that it is the best open entry.
        let mut clearance = node.clearance;
        if clearance.is_nan() {
            checks += 1;
            clearance = ws
                .free_distance(&q, cfg.margin)
                .unwrap_or(f64::NEG_INFINITY);
            if let Some(n) = nodes.get_mut(&key) {
                n.clearance = clearance;
            }
        }
        if clearance == f64::NEG_INFINITY {
            if let Some(n) = nodes.get_mut(&key) {
                n.g = f64::INFINITY;
            }
            continue;
        }
        if key != start_key {
            let parent = nodes[&node.parent];
            let qp = lat.config(&lat.unpack(node.parent));
            let rho = ws.sweep_bound(&(q - qp));
            let certified = 0.5 * (parent.clearance + clearance - rho) >= cfg.margin;
            if !certified && !ws.segment_free_counted(&qp, &q, cfg.margin, &mut checks) {
                // Blocked: the best remaining parent among the closed neighbours (open ones
                // offer themselves when they are expanded).
                blocked.insert(edge(key, node.parent));
                let mut best = (f64::INFINITY, key);
                for off in &stencil {
                    for k in 0..idx.len() {
                        nb[k] = idx[k] + off[k];
                    }
                    if !in_bounds(&nb) {
                        continue;
                    }
                    let nk = lat.pack(&nb);
                    if let Some(e) = nodes.get(&nk).filter(|e| e.closed)
                        && !blocked.contains(&edge(key, nk))
                    {
                        let cand = e.g + weighted(&w, &(lat.config(&nb) - q));
                        if cand < best.0 {
                            best = (cand, nk);
                        }
                    }
                }
                if let Some(n) = nodes.get_mut(&key) {
                    (n.g, n.parent) = best;
                }
                if best.0.is_finite() {
                    open.push(Open {
                        f: best.0 + h(&idx),
                        g: best.0,
                        key,
                        parent: best.1,
                    });
                }
                continue;
            }
        }
        if let Some(n) = nodes.get_mut(&key) {
            n.closed = true;
        }
        if key == goal_key {
            found = true;
            break;
        }
        expansions += 1;
        for off in &stencil {
            for k in 0..idx.len() {
                nb[k] = idx[k] + off[k];
            }
            if !in_bounds(&nb) {
                continue;
            }
            let nk = lat.pack(&nb);
            let g_new = node.g + weighted(&w, &(lat.config(&nb) - q));
            let e = nodes.entry(nk).or_insert(Node {
                g: f64::INFINITY,
                parent: nk,
                closed: false,
                clearance: f64::NAN,
            });
            if e.closed || e.clearance == f64::NEG_INFINITY || g_new >= e.g {
                continue;
            }
            if blocked.contains(&edge(key, nk)) {
                continue;
            }
            e.g = g_new;
            e.parent = key;
            open.push(Open {
                f: g_new + h(&nb),
                g: g_new,
                key: nk,
                parent: key,
            });
        }
    }
    if !found {
        return Err(PlanError::NoPath {
            method: "a*",
            reason: format!(
                "{expansions} nodes expanded, {pops} popped (budget {}), {} lattice nodes seen, no lattice path to the goal node",
                cfg.max_expansions,
                nodes.len()
            ),
        });
    }
    let mut path = vec![goal_q];
    let mut k = goal_key;
    while k != start_key {
        k = nodes[&k].parent;
        path.push(lat.config(&lat.unpack(k)));
    }
    path.reverse();
    let mut cost = nodes[&goal_key].g;
    if (goal_q - goal).norm() > 0.0 {
        cost += weighted(&w, &(goal - goal_q));
        path.push(*goal);
    }
    Ok(PathResult {
        path,
        cost,
        iterations: expansions,
        collision_checks: checks,
        time_s: t0.elapsed().as_secs_f64(),
    })
}

/// An undirected lattice edge as an ordered key pair.
fn edge(a: u64, b: u64) -> (u64, u64) {
    (a.min(b), a.max(b))
}

/// Cost of the cheapest obstacle-free lattice path from `idx` to `goal` (the heuristic of the
/// module docs): the Lovász extension of `f(S) = √(Σ_{i∈S} c_i²)` at the step counts
/// `n_i = |goal_i − idx_i|`, `c = unit`.
pub(crate) fn lattice_distance(unit: &[f64], goal: &[i64], idx: &[i64]) -> f64 {
    let mut steps = [(0i64, 0.0f64); 5];
    let k = idx.len().min(5);
    for i in 0..k {
        steps[i] = ((goal[i] - idx[i]).abs(), unit[i] * unit[i]);
    }
    let steps = &mut steps[..k];
    steps.sort_unstable_by_key(|s| std::cmp::Reverse(s.0));
    let (mut cost, mut sq) = (0.0, 0.0);
    for j in 0..k {
        sq += steps[j].1;
        let next = if j + 1 < k { steps[j + 1].0 } else { 0 };
        cost += (steps[j].0 - next) as f64 * sq.sqrt();
    }
    cost
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::plan::workspace::default_scene;
    use std::collections::BTreeMap;

    /// A plain Dijkstra on the same lattice with the same node and edge rules (no heuristic, an
    /// ordered map as the open set): the reference optimal cost.
    fn reference_cost(ws: &PlanWorkspace, start: &Joints, goal: &Joints, cfg: &AStarConfig) -> f64 {
        let (lat, rounded) = build_lattice(ws, start, goal, cfg).unwrap();
        let goal_idx = goal_node(ws, &lat, &rounded, goal, cfg, &mut 0).unwrap();
        let clear = |idx: &[i64]| ws.free_distance(&lat.config(idx), cfg.margin);
        let mut dist: HashMap<Vec<i64>, f64> = HashMap::new();
        let mut open: BTreeMap<(u64, Vec<i64>), ()> = BTreeMap::new();
        let s = vec![0i64; lat.joints.len()];
        dist.insert(s.clone(), 0.0);
        open.insert((0, s), ());
        while let Some(((gbits, idx), ())) = open.pop_first() {
            let g = f64::from_bits(gbits);
            if g > dist[&idx] {
                continue;
            }
            if idx == goal_idx {
                let gq = lat.config(&goal_idx);
                return g + weighted(&cfg.weights, &(goal - gq));
            }
            let q = lat.config(&idx);
            let ca = clear(&idx).unwrap();
            for off in lat.stencil() {
                let nb: Vec<i64> = idx.iter().zip(&off).map(|(a, b)| a + b).collect();
                if nb
                    .iter()
                    .enumerate()
                    .any(|(k, &v)| v < lat.lo[k] || v > lat.hi[k])
                {
                    continue;
                }
                let Some(cb) = clear(&nb) else { continue };
                let qn = lat.config(&nb);
                let ok = 0.5 * (ca + cb - ws.sweep_bound(&(qn - q))) >= cfg.margin
                    || ws.segment_free(&q, &qn, cfg.margin);
                if !ok {
                    continue;
                }
                let gn = g + weighted(&cfg.weights, &(qn - q));
                if dist.get(&nb).is_none_or(|&d| gn < d) {
                    dist.insert(nb.clone(), gn);
                    open.insert((gn.to_bits(), nb), ());
                }
            }
        }
        f64::INFINITY
    }

    /// Two pillars around the robot, no wafer.
    pub(crate) fn pillars() -> PlanWorkspace {
        use crate::collision::{LinkDims, Obstacle};
        use crate::robot::WaferRobot;
        use nalgebra::{Isometry3, Vector3};
        let (lo, hi) = crate::plan::workspace::default_limits();
        let obstacles = vec![
            Obstacle::new(
                "pillar 1",
                Isometry3::translation(0.75, 0.1, 0.3),
                Vector3::new(0.08, 0.08, 0.4),
            )
            .unwrap(),
            Obstacle::new(
                "pillar 2",
                Isometry3::translation(-0.2, 0.8, 0.3),
                Vector3::new(0.08, 0.08, 0.4),
            )
            .unwrap(),
        ];
        PlanWorkspace::new(
            WaferRobot::default(),
            LinkDims::default(),
            None,
            lo,
            hi,
            obstacles,
        )
        .unwrap()
    }

    /// A move between the pillars on a 10° lattice of joints 0–2.
    fn pillars_move() -> (Joints, Joints, AStarConfig) {
        let d = 10f64.to_radians();
        let cfg = AStarConfig {
            joints: vec![0, 1, 2],
            step: Joints::new(d, d, d, d, 0.05),
            ..AStarConfig::default()
        };
        let start = Joints::new(-0.6, 0.4, 0.2, 0.3, 0.1);
        let goal = Joints::new(2.4, -0.4, -0.3, 0.3, 0.1);
        (start, goal, cfg)
    }

    #[test]
    fn astar_cost_equals_reference_dijkstra_and_path_is_free() {
        let ws = pillars();
        let (start, goal, cfg) = pillars_move();
        let r = astar(&ws, &start, &goal, &cfg).unwrap();
        let c_ref = reference_cost(&ws, &start, &goal, &cfg);
        assert!((r.cost - c_ref).abs() < 1e-9, "{} vs {}", r.cost, c_ref);
        // Independent check: the exact clearance along every edge, densely sampled.
        for w in r.path.windows(2) {
            for i in 0..=50 {
                let q = w[0] + (w[1] - w[0]) * (i as f64 / 50.0);
                assert!(ws.signed_distance(&q).unwrap() >= cfg.margin - 1e-12);
            }
        }
        assert!((r.path[0] - start).norm() == 0.0 && (r.path.last().unwrap() - goal).norm() == 0.0);
        // Heuristic: the cost is at least the straight-line distance.
        assert!(r.cost >= (goal - start).norm() - 1e-12);
    }

    /// The heuristic is the exact obstacle-free lattice distance: a Dijkstra over the king's-move
    /// stencil with weighted Euclidean edge costs agrees on every node of a small 4-D box, for
    /// unequal unit costs.
    #[test]
    fn lattice_distance_is_the_free_lattice_shortest_path() {
        let unit = [0.3, 1.0, 0.7, 2.2];
        let n = 4usize;
        let side = 5i64;
        let lat = Lattice {
            start: Joints::zeros(),
            step: Joints::new(1.0, 1.0, 1.0, 1.0, 1.0),
            joints: vec![0, 1, 2, 3],
            lo: vec![-side; n],
            hi: vec![side; n],
        };
        let goal = vec![2i64, -1, 0, 3];
        let mut dist: HashMap<Vec<i64>, f64> = HashMap::new();
        let mut open: BTreeMap<(u64, Vec<i64>), ()> = BTreeMap::new();
        dist.insert(goal.clone(), 0.0);
        open.insert((0, goal.clone()), ());
        while let Some(((gbits, idx), ())) = open.pop_first() {
            let g = f64::from_bits(gbits);
            if g > dist[&idx] {
                continue;
            }
            for off in lat.stencil() {
                let nb: Vec<i64> = idx.iter().zip(&off).map(|(a, b)| a + b).collect();
                if nb.iter().any(|v| v.abs() > side) {
                    continue;
                }
                let c: f64 = off
                    .iter()
                    .zip(&unit)
                    .map(|(o, u)| (*o as f64 * u).powi(2))
                    .sum();
                let gn = g + c.sqrt();
                if dist.get(&nb).is_none_or(|&d| gn < d - 1e-15) {
                    dist.insert(nb.clone(), gn);
                    open.insert((gn.to_bits(), nb), ());
                }
            }
        }
        assert_eq!(dist.len(), 11usize.pow(4));
        for (idx, d) in &dist {
            let h = lattice_distance(&unit, &goal, idx);
            assert!((h - d).abs() < 1e-9, "{idx:?}: {h} vs {d}");
        }
    }

    /// Four planned joints: the lazy search returns the reference Dijkstra's cost.
    #[test]
    fn astar_four_joints_equals_reference() {
        // Joints 2 and 3 confined to ±0.7 rad keep the reference Dijkstra's lattice small.
        let mut ws = pillars();
        for j in [2, 3] {
            ws.lower[j] = -0.7;
            ws.upper[j] = 0.7;
        }
        let start = Joints::new(-0.6, 0.4, 0.2, 0.3, 0.1);
        let goal = Joints::new(1.5, -0.2, -0.1, -0.3, 0.1);
        let d = 20f64.to_radians();
        let cfg = AStarConfig {
            joints: vec![0, 1, 2, 3],
            step: Joints::new(d, d, d, d, 0.05),
            ..AStarConfig::default()
        };
        let r = astar(&ws, &start, &goal, &cfg);
        let c_ref = reference_cost(&ws, &start, &goal, &cfg);
        let r = r.unwrap_or_else(|e| panic!("{e} (reference {c_ref})"));
        assert!((r.cost - c_ref).abs() < 1e-9, "{} vs {}", r.cost, c_ref);
    }

    /// The budget bounds the popped entries (blocked ones included), not only the expansions.
    #[test]
    fn budget_bounds_every_pop() {
        let ws = pillars();
        let (start, goal, mut cfg) = pillars_move();
        cfg.max_expansions = 7;
        let err = astar(&ws, &start, &goal, &cfg).unwrap_err().to_string();
        let popped: usize = err
            .split(" popped")
            .next()
            .and_then(|s| s.rsplit(", ").next())
            .and_then(|s| s.parse().ok())
            .unwrap_or(usize::MAX);
        assert!(popped <= 8, "{err}");
    }

    #[test]
    fn bad_inputs_name_the_constraint() {
        let (ws, poses) = default_scene().unwrap();
        // Push the arm from carrier A's approach pose into the carrier until it collides.
        let bad = (1..200)
            .map(|s| poses[1].q + Joints::new(0.0, -0.01, 0.005, 0.0, 0.0) * s as f64)
            .find(|q| ws.signed_distance(q).unwrap() < 0.0)
            .unwrap();
        let e = astar(&ws, &poses[0].q, &bad, &AStarConfig::default()).unwrap_err();
        assert!(
            matches!(e, PlanError::InCollision { which: "goal", .. }),
            "{e}"
        );
        let cfg = AStarConfig {
            joints: vec![0, 0, 1],
            ..AStarConfig::default()
        };
        assert!(astar(&ws, &poses[0].q, &poses[1].q, &cfg).is_err());
        let cfg = AStarConfig {
            joints: vec![0, 1, 2],
            ..AStarConfig::default()
        };
        // θ4 and h differ between home and carrier A: not plannable with three joints.
        assert!(matches!(
            astar(&ws, &poses[0].q, &poses[1].q, &cfg),
            Err(PlanError::InvalidInput { .. })
        ));
    }
}

//! RRT* in the continuous five-dimensional joint space, 000_3b1454b2b2194811.txt ch. 2.3
//! ("Sampling-based path planning in continuous joint space"), after Karaman & Frazzoli [18].
//!
//! Each iteration samples a configuration (the goal with probability `goal_bias`), steers from
//! its nearest tree node by at most `step`, chooses the parent of least cost among the nodes
//! within the shrinking radius `min(γ (ln n / n)^{1/5}, step)` whose segment is free, and
//! rewires those neighbours through the new node when that lowers their cost (the cost change
//! is propagated to their subtrees). The goal is joined by a free segment from any node within
//! one step, and from the node of every goal-biased sample whatever the distance. Nearest and radius queries use a kiddo k-d tree on the
//! weighted coordinates `w ⊙ q`, so the Euclidean metric of the tree is the path cost's.
//! Segments are certified by conservative advancement ([`PlanWorkspace::segment_free`]).
//! After the budget, the best path to the goal is shortcut: random pairs of way-points joined by
//! a free segment drop the way-points between them. A seeded PCG generator makes the result
//! deterministic.

use kiddo::{MutableKdTree, SquaredEuclidean};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::robot::Joints;

use super::PlanError;
use super::astar::PathResult;
use super::workspace::PlanWorkspace;

/// Settings of [`rrt_star`].
#[derive(Debug, Clone, PartialEq)]
pub struct RrtStarConfig {
    /// Iterations (samples).
    pub max_iterations: usize,
    /// Largest extension (weighted joint-space length).
    pub step: f64,
    /// Probability of sampling the goal.
    pub goal_bias: f64,
    /// Constant `γ` of the rewiring radius.
    pub gamma: f64,
    /// Metric weights `w` (1 for angles; the lift in rad per metre).
    pub weights: Joints,
    /// Required clearance (m).
    pub margin: f64,
    /// Shortcut attempts on the final path.
    pub shortcut_iterations: usize,
    /// Stop at the first iteration after this many seconds once a path exists (`None`: never).
    pub time_limit_s: Option<f64>,
    /// Seed of the random generator.
    pub seed: u64,
}

impl Default for RrtStarConfig {
    fn default() -> Self {
        Self {
            max_iterations: 3000,
            step: 0.5,
            goal_bias: 0.1,
            gamma: 6.0,
            weights: Joints::new(1.0, 1.0, 1.0, 1.0, 5.0),
            margin: 0.01,
            shortcut_iterations: 200,
            time_limit_s: None,
            seed: 7,
        }
    }
}

/// What RRT* returns: the shortcut path and the search's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct RrtStarResult {
    /// The shortcut path (way-points, cost, iterations, collision checks, time).
    pub result: PathResult,
    /// Cost of the tree's path before shortcutting.
    pub tree_cost: f64,
    /// Iteration at which the goal was first reached.
    pub first_solution_iteration: usize,
    /// Seconds to the first solution.
    pub first_solution_s: f64,
    /// Nodes in the tree.
    pub nodes: usize,
}

/// Bytes a tree node takes at least: its joints, parent and cost, its child list, and its k-d
/// tree entry (5 coordinates and an index).
const NODE_BYTES: usize = std::mem::size_of::<Joints>()
    + std::mem::size_of::<usize>()
    + std::mem::size_of::<f64>()
    + std::mem::size_of::<Vec<usize>>()
    + 6 * 8;

fn wdist(w: &Joints, a: &Joints, b: &Joints) -> f64 {
    (a - b).component_mul(w).norm()
}

/// RRT* from `start` to `goal` (module docs). The tree is rooted at the end with the smaller
/// clearance (growing out of a confined pose, such as a blade lined up with a carrier, is easier
/// than finding one) and the path is returned from `start` to `goal`. Errors: start or goal not
/// free, malformed settings, or [`PlanError::NoPath`] if no path was found within the budget.
pub fn rrt_star(
    ws: &PlanWorkspace,
    start: &Joints,
    goal: &Joints,
    cfg: &RrtStarConfig,
) -> Result<RrtStarResult, PlanError> {
    ws.require_free("start", start, cfg.margin)?;
    ws.require_free("goal", goal, cfg.margin)?;
    let from_goal = |ws: &PlanWorkspace| -> Result<RrtStarResult, PlanError> {
        let mut r = rrt_star_rooted(ws, goal, start, cfg)?;
        r.result.path.reverse();
        Ok(r)
    };
    // If the tree from the more confined end fails, the other end gets the same budget.
    if ws.signed_distance(goal)? < ws.signed_distance(start)? {
        from_goal(ws).or_else(|_| rrt_star_rooted(ws, start, goal, cfg))
    } else {
        rrt_star_rooted(ws, start, goal, cfg).or_else(|_| from_goal(ws))
    }
}

fn rrt_star_rooted(
    ws: &PlanWorkspace,
    start: &Joints,
    goal: &Joints,
    cfg: &RrtStarConfig,
) -> Result<RrtStarResult, PlanError> {
    let t0 = std::time::Instant::now();
    if !(cfg.step > 0.0
        && cfg.step.is_finite()
        && (0.0..=1.0).contains(&cfg.goal_bias)
        && cfg.gamma > 0.0)
        || cfg.weights.iter().any(|w| !(*w > 0.0 && w.is_finite()))
    {
        return Err(PlanError::InvalidInput {
            what: "RRT* settings",
            reason: format!(
                "step {} and gamma {} must be positive, goal bias {} in [0, 1], weights positive",
                cfg.step, cfg.gamma, cfg.goal_bias
            ),
        });
    }
    // RRT* refines until its budget is spent, one tree node per iteration: a budget whose tree
    // cannot fit in memory would run for hours and fail at the end, so it is refused up front.
    crate::alloc::ensure_within_physical_memory(
        "an RRT* tree of max_iterations + 1 nodes",
        cfg.max_iterations.saturating_add(1),
        NODE_BYTES,
    )?;
    let w = cfg.weights;
    let key = |q: &Joints| -> [f64; 5] { std::array::from_fn(|i| q[i] * w[i]) };
    let mut rng = Pcg64::seed_from_u64(cfg.seed);
    let mut checks = 0u64;
    let mut nodes = vec![*start];
    let mut parent = vec![0usize];
    let mut cost = vec![0.0f64];
    let mut children: Vec<Vec<usize>> = vec![Vec::new()];
    let mut tree: MutableKdTree<f64, 5> = MutableKdTree::default();
    tree.add(&key(start), 0)
        .map_err(|e| PlanError::InvalidInput {
            what: "k-d tree",
            reason: format!("{e:?}"),
        })?;
    // Nodes joined to the goal by a free segment.
    let mut goal_links: Vec<usize> = Vec::new();
    let mut first: Option<(usize, f64)> = None;
    let mut iterations = 0;
    if ws.segment_free_counted(start, goal, cfg.margin, &mut checks) {
        goal_links.push(0);
        first = Some((0, t0.elapsed().as_secs_f64()));
    }
    for it in 0..cfg.max_iterations {
        if first.is_some()
            && cfg
                .time_limit_s
                .is_some_and(|t| t0.elapsed().as_secs_f64() > t)
        {
            break;
        }
        iterations = it + 1;
        let goal_sample = rng.random::<f64>() < cfg.goal_bias;
        let sample = if goal_sample {
            *goal
        } else {
            Joints::from_fn(|i, _| rng.random_range(ws.lower[i]..=ws.upper[i]))
        };
        let near = tree
            .query(&key(&sample))
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        let from = nodes[near.item as usize];
        let d = wdist(&w, &sample, &from);
        let new = if d > cfg.step {
            from + (sample - from) * (cfg.step / d)
        } else {
            sample
        };
        if d < 1e-9 {
            // The sample is already a tree node (the goal, sampled again).
            continue;
        }
        checks += 1;
        if !ws.is_free(&new, cfg.margin) {
            continue;
        }
        let n = nodes.len() as f64;
        let radius = (cfg.gamma * (n.ln() / n).powf(0.2)).min(cfg.step).max(1e-9);
        let mut neigh: Vec<(usize, f64)> = tree
            .query(&key(&new))
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .execute()
            .into_iter()
            .map(|nn| (nn.item as usize, nn.distance.sqrt()))
            .collect();
        if !neigh.iter().any(|(i, _)| *i == near.item as usize) {
            neigh.push((near.item as usize, wdist(&w, &new, &from)));
        }
        neigh.sort_by(|a, b| (cost[a.0] + a.1).total_cmp(&(cost[b.0] + b.1)));
        let mut best = None;
        for &(i, dd) in &neigh {
            if ws.segment_free_counted(&nodes[i], &new, cfg.margin, &mut checks) {
                best = Some((i, cost[i] + dd));
                break;
            }
        }
        let Some((p, c_new)) = best else { continue };
        let id = nodes.len();
        nodes.push(new);
        parent.push(p);
        cost.push(c_new);
        children.push(Vec::new());
        children[p].push(id);
        tree.add(&key(&new), id as u32)
            .map_err(|e| PlanError::InvalidInput {
                what: "k-d tree",
                reason: format!("{e:?}"),
            })?;
        // Rewire.
        for &(i, dd) in &neigh {
            if i == p || c_new + dd >= cost[i] - 1e-12 {
                continue;
            }
            if !ws.segment_free_counted(&new, &nodes[i], cfg.margin, &mut checks) {
                continue;
            }
            let old = parent[i];
            children[old].retain(|&c| c != i);
            parent[i] = id;
            children[id].push(i);
            let delta = cost[i] - (c_new + dd);
            let mut stack = vec![i];
            while let Some(k) = stack.pop() {
                cost[k] -= delta;
                stack.extend(children[k].iter().copied());
            }
        }
        // The goal is joined from a node within one step, or from the node a goal sample
        // produced (whatever the distance): the goal region of a blade lined up with a carrier
        // is narrow, and a long free segment into it is a good way in.
        let try_goal = goal_sample || wdist(&w, &new, goal) <= cfg.step;
        if try_goal && ws.segment_free_counted(&new, goal, cfg.margin, &mut checks) {
            goal_links.push(id);
            if first.is_none() {
                first = Some((iterations, t0.elapsed().as_secs_f64()));
            }
        }
    }
    let Some((first_it, first_s)) = first else {
        return Err(PlanError::NoPath {
            method: "rrt*",
            reason: format!(
                "goal not reached after {iterations} iterations ({} tree nodes); raise max_iterations",
                nodes.len()
            ),
        });
    };
    let (&best, tree_cost) = goal_links
        .iter()
        .map(|i| (i, cost[*i] + wdist(&w, &nodes[*i], goal)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .ok_or_else(|| PlanError::NoPath {
            method: "rrt*",
            reason: "no goal link".into(),
        })?;
    let mut path = vec![*goal];
    let mut k = best;
    loop {
        path.push(nodes[k]);
        if k == 0 {
            break;
        }
        k = parent[k];
    }
    path.reverse();
    // Shortcutting.
    for _ in 0..cfg.shortcut_iterations {
        if path.len() < 3 {
            break;
        }
        let i = rng.random_range(0..path.len() - 2);
        let j = rng.random_range(i + 2..path.len());
        if ws.segment_free_counted(&path[i], &path[j], cfg.margin, &mut checks) {
            path.drain(i + 1..j);
        }
    }
    let cost_final = path.windows(2).map(|p| wdist(&w, &p[0], &p[1])).sum();
    Ok(RrtStarResult {
        result: PathResult {
            path,
            cost: cost_final,
            iterations,
            collision_checks: checks,
            time_s: t0.elapsed().as_secs_f64(),
        },
        tree_cost,
        first_solution_iteration: first_it,
        first_solution_s: first_s,
        nodes: nodes.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::workspace::default_scene;

    #[test]
    fn rrt_star_finds_free_deterministic_paths_in_the_default_scene() {
        let (ws, poses) = default_scene().unwrap();
        let cfg = RrtStarConfig {
            max_iterations: 1500,
            ..RrtStarConfig::default()
        };
        let (a, b) = (poses[0].q, poses[1].q);
        let r = rrt_star(&ws, &a, &b, &cfg).unwrap();
        let r2 = rrt_star(&ws, &a, &b, &cfg).unwrap();
        assert_eq!(r.result.path, r2.result.path);
        assert!(r.result.cost <= r.tree_cost + 1e-12);
        assert!(r.result.cost >= wdist(&cfg.weights, &a, &b) - 1e-12);
        for w in r.result.path.windows(2) {
            for i in 0..=100 {
                let q = w[0] + (w[1] - w[0]) * (i as f64 / 100.0);
                assert!(ws.signed_distance(&q).unwrap() >= cfg.margin - 1e-12);
            }
        }
    }

    #[test]
    fn a_budget_whose_tree_cannot_fit_in_memory_is_refused_before_sampling() {
        let (ws, poses) = default_scene().unwrap();
        let cfg = RrtStarConfig {
            max_iterations: usize::MAX / 2,
            ..RrtStarConfig::default()
        };
        let t0 = std::time::Instant::now();
        let e = rrt_star(&ws, &poses[0].q, &poses[1].q, &cfg).unwrap_err();
        assert!(
            matches!(
                e,
                PlanError::Geometry(crate::GeometryError::OutOfMemory { bytes_each, .. })
                    if bytes_each == NODE_BYTES
            ),
            "{e}"
        );
        assert!(e.to_string().contains("max_iterations"), "{e}");
        assert!(t0.elapsed().as_secs_f64() < 1.0);
    }

    #[test]
    fn unreachable_goal_is_reported() {
        let ws = crate::plan::astar::tests::pillars();
        // A goal enclosed by the pillar is impossible to construct with two pillars; instead a
        // budget of 0 iterations with a blocked straight line reports NoPath.
        let start = Joints::new(-0.6, 0.4, 0.2, 0.3, 0.1);
        let goal = Joints::new(2.4, -0.4, -0.3, 0.3, 0.1);
        let cfg = RrtStarConfig {
            max_iterations: 0,
            ..RrtStarConfig::default()
        };
        assert!(matches!(
            rrt_star(&ws, &start, &goal, &cfg),
            Err(PlanError::NoPath { .. })
        ));
    }
}

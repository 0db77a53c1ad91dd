//! A robot-team mapping simulator, the embedded default of seed 004_815695db12a6b16c.txt
//! ch. 2 (ground truth for every step): robots exploring a [`World`] with a 270°, 1081-beam
//! laser, wheel odometry with an unmodelled heading drift, scan-matching-like loop closures
//! within and between robots (from ground-truth overlap, with noise), people and vehicles
//! moving through, and every `period` seconds (10 s, §2.6.1) the current SE(2) pose graph
//! solved by the project's sparse least squares ([`crate::lsq`]).

use std::collections::HashMap;
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

use super::scan::ScanGeometry;
use super::world::{World, WorldConfig};
use crate::lsq::se2::{se2_between, se2_compose, wrap_angle};
use crate::lsq::{Loss, Manifold, Problem, Se2BetweenResidual, SolverOptions};
use crate::{EstimateError, Result};

/// Simulator settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TeamConfig {
    /// The world.
    pub world: WorldConfig,
    /// Robots (the seed: 10 at Keswick, 14 in phase 2).
    pub robots: usize,
    /// Graphs to produce.
    pub graphs: usize,
    /// Mission time between graphs (s).
    pub period: f64,
    /// Simulation step (s).
    pub dt: f64,
    /// Robot speed (m/s).
    pub speed: f64,
    /// A node every this many metres travelled …
    pub node_spacing: f64,
    /// … or after this much turning (rad).
    pub node_turn: f64,
    /// The laser.
    pub scan: ScanGeometry,
    /// Range noise σ (m).
    pub range_noise: f64,
    /// People walking through (discs of 0.3 m radius, 1.3 m/s).
    pub people: usize,
    /// Vehicles driving through (discs of 1.2 m radius, 3 m/s).
    pub vehicles: usize,
    /// Whether transients are visible to the lasers (the motion is simulated either way, so
    /// a run without them has identical graphs).
    pub transients_visible: bool,
    /// Odometry translation noise σ per metre (and a 0.01 m floor).
    pub odom_sigma_xy: f64,
    /// Odometry heading noise σ per radian turned (and a 0.002 rad floor).
    pub odom_sigma_theta: f64,
    /// σ of the per-robot heading drift (rad per metre), not in the edge covariance.
    pub heading_drift: f64,
    /// Loop closures: candidate radius (m).
    pub closure_radius: f64,
    /// Probability that scan matching finds a candidate.
    pub closure_probability: f64,
    /// Closure noise σ (m, rad).
    pub closure_sigma: [f64; 2],
    /// Seed.
    pub seed: u64,
}

impl TeamConfig {
    /// The phase-2 scale: 220 × 160 m, 14 robots, 429 graphs (Table 2.2).
    pub fn showgrounds(seed: u64) -> Self {
        Self {
            world: WorldConfig::showgrounds(seed),
            robots: 14,
            graphs: 429,
            period: 10.0,
            dt: 0.5,
            speed: 0.35,
            node_spacing: 3.0,
            node_turn: 0.7,
            scan: ScanGeometry::default(),
            range_noise: 0.01,
            people: 14,
            vehicles: 4,
            transients_visible: true,
            odom_sigma_xy: 0.02,
            odom_sigma_theta: 0.02,
            heading_drift: 0.002,
            closure_radius: 4.0,
            closure_probability: 0.1,
            closure_sigma: [0.03, 0.005],
            seed,
        }
    }

    /// Keswick: 150 × 150 m, 10 robots, 68 graphs (Table 2.2).
    pub fn keswick(seed: u64) -> Self {
        Self {
            world: WorldConfig::keswick(seed),
            robots: 10,
            graphs: 68,
            people: 8,
            vehicles: 2,
            ..Self::showgrounds(seed)
        }
    }

    /// A small stream for tests: 60 × 50 m, 3 robots, 12 graphs, a 15 m laser.
    pub fn small(seed: u64) -> Self {
        Self {
            world: WorldConfig::small(seed),
            robots: 3,
            graphs: 12,
            people: 4,
            vehicles: 1,
            speed: 0.6,
            node_spacing: 2.0,
            closure_probability: 0.3,
            scan: ScanGeometry {
                max_range: 15.0,
                ..ScanGeometry::default()
            },
            ..Self::showgrounds(seed)
        }
    }

    fn validate(&self) -> Result<()> {
        if self.robots == 0 || self.robots > 1000 {
            return Err(EstimateError::InvalidParameter {
                name: "robots",
                value: self.robots as f64,
                reason: "must be in 1..=1000",
            });
        }
        for (name, v) in [
            ("period", self.period),
            ("dt", self.dt),
            ("speed", self.speed),
            ("node_spacing", self.node_spacing),
            ("node_turn", self.node_turn),
            ("closure_radius", self.closure_radius),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "must be positive and finite",
                });
            }
        }
        for (name, v) in [
            ("range_noise", self.range_noise),
            ("odom_sigma_xy", self.odom_sigma_xy),
            ("odom_sigma_theta", self.odom_sigma_theta),
            ("heading_drift", self.heading_drift),
            ("closure_sigma", self.closure_sigma[0]),
            ("closure_sigma", self.closure_sigma[1]),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "must be non-negative and finite",
                });
            }
        }
        if !(0.0..=1.0).contains(&self.closure_probability) {
            return Err(EstimateError::InvalidParameter {
                name: "closure_probability",
                value: self.closure_probability,
                reason: "must be in [0, 1]",
            });
        }
        self.scan.validate()
    }
}

/// Kind of a pose-graph edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdgeKind {
    /// A prior on a robot's first node (known start pose); `from == to`.
    Prior,
    /// Wheel odometry between consecutive nodes of one robot.
    Odometry,
    /// A loop closure (scan match) within or between robots.
    LoopClosure,
}

/// A pose-graph edge: `z` is node `to`'s pose in the frame of node `from` (for a prior,
/// the node's pose in the world), with covariance `cov` (3×3 row-major, tangent of SE(2)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// Kind.
    pub kind: EdgeKind,
    /// First node id.
    pub from: u64,
    /// Second node id.
    pub to: u64,
    /// Measurement `[x, y, θ]`.
    pub z: [f64; 3],
    /// Covariance (row-major 3×3).
    pub cov: [f64; 9],
}

/// One graph G_i of the stream.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphSnapshot {
    /// Index i.
    pub index: usize,
    /// Mission time (s).
    pub time: f64,
    /// Node ids (creation order; the last `new_nodes` are new in this graph).
    pub node_ids: Vec<u64>,
    /// Robot of each node.
    pub robot_ids: Vec<u32>,
    /// ML posteriors `[x, y, θ]`.
    pub poses: Vec<[f64; 3]>,
    /// Ground-truth poses.
    pub truth: Vec<[f64; 3]>,
    /// Nodes new in this graph.
    pub new_nodes: usize,
    /// Edges of the graph.
    pub edges: Vec<Edge>,
    /// Loop closures added since the previous graph.
    pub new_closures: usize,
    /// LM iterations of this graph's solve (0: no new constraint but odometry, so the
    /// previous optimum extended by odometry is the optimum).
    pub solver_iterations: usize,
    /// Wall time of the solve (s).
    pub solve_seconds: f64,
}

struct Mover {
    /// Current road-graph vertex it left and the one it heads to.
    from: usize,
    to: usize,
    /// Distance along the edge (m).
    along: f64,
    speed: f64,
    radius: f64,
    lateral: f64,
    pos: [f64; 2],
}

struct RobotSim {
    pose: [f64; 3],
    from: usize,
    to: usize,
    travelled: f64,
    turned: f64,
    last_node: Option<usize>,
    drift: f64,
}

struct SimNode {
    robot: u32,
    truth: [f64; 3],
    estimate: [f64; 3],
    ranges: Vec<f32>,
    transient_hits: Vec<[f32; 2]>,
}

/// The team simulator: call [`TeamSimulator::step`] for each graph.
pub struct TeamSimulator {
    cfg: TeamConfig,
    world: World,
    rng: Pcg64,
    transient_rng: Pcg64,
    robots: Vec<RobotSim>,
    movers: Vec<Mover>,
    nodes: Vec<SimNode>,
    edges: Vec<Edge>,
    edge_visits: HashMap<(usize, usize), u32>,
    grid: HashMap<(i64, i64), Vec<usize>>,
    time: f64,
    graphs: usize,
    reported_nodes: usize,
    closures_since: usize,
}

impl std::fmt::Debug for TeamSimulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TeamSimulator")
            .field("config", &self.cfg)
            .field("nodes", &self.nodes.len())
            .field("time", &self.time)
            .finish()
    }
}

fn diag_cov(sx: f64, sy: f64, st: f64) -> [f64; 9] {
    [sx * sx, 0.0, 0.0, 0.0, sy * sy, 0.0, 0.0, 0.0, st * st]
}

impl TeamSimulator {
    /// A simulator (world generated, robots at their start intersections).
    pub fn new(cfg: TeamConfig) -> Result<Self> {
        cfg.validate()?;
        let world = World::generate(cfg.world)?;
        let mut rng = Pcg64::seed_from_u64(cfg.seed);
        let mut transient_rng = Pcg64::seed_from_u64(cfg.seed ^ 0x07a5_1e47);
        let n_int = world.intersections.len();
        // Robots start along the bottom street (a start zone, as in MAGIC), heading +x or +y.
        let robots = (0..cfg.robots)
            .map(|r| {
                let from = world.intersections[r % n_int];
                let to = world.adjacency[from][0];
                let (a, b) = (world.roads[from], world.roads[to]);
                let th = (b[1] - a[1]).atan2(b[0] - a[0]);
                RobotSim {
                    pose: [a[0], a[1], th],
                    from,
                    to,
                    travelled: 0.0,
                    turned: 0.0,
                    last_node: None,
                    drift: Normal::new(0.0, cfg.heading_drift.max(1e-300))
                        .map(|n| n.sample(&mut rng))
                        .unwrap_or(0.0),
                }
            })
            .collect();
        let movers = (0..cfg.people + cfg.vehicles)
            .map(|k| {
                let person = k < cfg.people;
                let from = world.intersections[transient_rng.random_range(0..n_int)];
                // Every neighbour of an intersection is on a street.
                let nbrs = &world.adjacency[from];
                let to = nbrs[transient_rng.random_range(0..nbrs.len())];
                let lat = if person { 3.0 } else { 1.5 };
                Mover {
                    from,
                    to,
                    along: 0.0,
                    speed: if person { 1.3 } else { 3.0 },
                    radius: if person { 0.3 } else { 1.2 },
                    lateral: transient_rng.random_range(-lat..lat),
                    pos: world.roads[from],
                }
            })
            .collect();
        let mut sim = Self {
            cfg,
            world,
            rng,
            transient_rng,
            robots,
            movers,
            nodes: Vec::new(),
            edges: Vec::new(),
            edge_visits: HashMap::new(),
            grid: HashMap::new(),
            time: 0.0,
            graphs: 0,
            reported_nodes: 0,
            closures_since: 0,
        };
        sim.place_movers();
        for r in 0..sim.robots.len() {
            sim.add_node(r);
        }
        Ok(sim)
    }

    /// The world (ground truth walls).
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The configuration.
    pub fn config(&self) -> &TeamConfig {
        &self.cfg
    }

    /// Ranges of node `id` (f32 metres; +inf = no return).
    pub fn ranges(&self, id: u64) -> Option<&[f32]> {
        self.nodes.get(id as usize).map(|n| n.ranges.as_slice())
    }

    /// World points where node `id`'s beams hit a transient object (ground truth).
    pub fn transient_hits(&self, id: u64) -> Option<&[[f32; 2]]> {
        self.nodes
            .get(id as usize)
            .map(|n| n.transient_hits.as_slice())
    }

    /// Positions and radii of the transient objects now.
    pub fn transients(&self) -> Vec<[f64; 3]> {
        self.movers
            .iter()
            .map(|m| [m.pos[0], m.pos[1], m.radius])
            .collect()
    }

    fn place_movers(&mut self) {
        for m in &mut self.movers {
            let (a, b) = (self.world.roads[m.from], self.world.roads[m.to]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]).max(1e-9);
            let (ux, uy) = ((b[0] - a[0]) / len, (b[1] - a[1]) / len);
            m.pos = [
                a[0] + ux * m.along - uy * m.lateral,
                a[1] + uy * m.along + ux * m.lateral,
            ];
        }
    }

    fn advance_movers(&mut self, dt: f64) {
        let n_int = self.world.intersections.len();
        for m in &mut self.movers {
            m.along += m.speed * dt;
            loop {
                let (a, b) = (self.world.roads[m.from], self.world.roads[m.to]);
                let len = (b[0] - a[0]).hypot(b[1] - a[1]);
                if m.along < len {
                    break;
                }
                m.along -= len;
                // Transients stay on streets: vertices that are intersections or door
                // points on a street (not building interiors).
                let street: Vec<usize> = self.world.adjacency[m.to]
                    .iter()
                    .copied()
                    .filter(|&v| {
                        v < n_int
                            || (self.world.roads[v][1] - self.world.roads[m.to][1]).abs() < 1e-9
                    })
                    .collect();
                let opts: Vec<usize> = street.iter().copied().filter(|&v| v != m.from).collect();
                let next = if opts.is_empty() {
                    m.from
                } else {
                    opts[self.transient_rng.random_range(0..opts.len())]
                };
                m.from = m.to;
                m.to = next;
            }
        }
        self.place_movers();
    }

    fn advance_robots(&mut self, dt: f64) {
        for r in 0..self.robots.len() {
            let mut left = self.cfg.speed * dt;
            while left > 1e-12 {
                let rb = &self.robots[r];
                let target = self.world.roads[rb.to];
                let (dx, dy) = (target[0] - rb.pose[0], target[1] - rb.pose[1]);
                let d = dx.hypot(dy);
                let step = d.min(left);
                let rb = &mut self.robots[r];
                if d > 1e-12 {
                    rb.pose[0] += dx / d * step;
                    rb.pose[1] += dy / d * step;
                }
                rb.travelled += step;
                left -= step;
                if step >= d {
                    // Arrived: the least-travelled next edge (team-wide), no U-turn unless a
                    // dead end; ties broken at random.
                    let here = rb.to;
                    let prev = rb.from;
                    let nbrs = &self.world.adjacency[here];
                    let visits = |v: usize| {
                        let key = (here.min(v), here.max(v));
                        self.edge_visits.get(&key).copied().unwrap_or(0)
                    };
                    let cands: Vec<usize> = if nbrs.len() > 1 {
                        nbrs.iter().copied().filter(|&v| v != prev).collect()
                    } else {
                        nbrs.clone()
                    };
                    let best = cands.iter().map(|&v| visits(v)).min().unwrap_or(0);
                    let ties: Vec<usize> =
                        cands.into_iter().filter(|&v| visits(v) == best).collect();
                    let next = ties[self.rng.random_range(0..ties.len())];
                    *self
                        .edge_visits
                        .entry((here.min(next), here.max(next)))
                        .or_insert(0) += 1;
                    let (a, b) = (self.world.roads[here], self.world.roads[next]);
                    let th = (b[1] - a[1]).atan2(b[0] - a[0]);
                    let rb = &mut self.robots[r];
                    rb.turned += wrap_angle(th - rb.pose[2]).abs();
                    rb.pose[2] = th;
                    rb.from = here;
                    rb.to = next;
                    if rb.turned >= self.cfg.node_turn {
                        self.add_node(r);
                    }
                }
                if self.robots[r].travelled >= self.cfg.node_spacing {
                    self.add_node(r);
                }
            }
        }
    }

    fn scan(&self, pose: &[f64; 3]) -> (Vec<f32>, Vec<[f32; 2]>) {
        let g = &self.cfg.scan;
        let n = ((270f64.to_radians() / g.angle_increment).round() as usize + 1).max(1);
        let o = [pose[0], pose[1]];
        let near: Vec<&Mover> = if self.cfg.transients_visible {
            self.movers
                .iter()
                .filter(|m| {
                    let d = (m.pos[0] - o[0]).hypot(m.pos[1] - o[1]);
                    d < g.max_range + m.radius && d > m.radius
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut hits = Vec::new();
        let mut noise_rng = Pcg64::seed_from_u64(
            self.cfg.seed ^ (self.nodes.len() as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        let noise = Normal::new(0.0, self.cfg.range_noise.max(1e-300)).ok();
        let ranges = (0..n)
            .map(|k| {
                let a = pose[2] + g.angle_min + k as f64 * g.angle_increment;
                let d = [a.cos(), a.sin()];
                let mut r = self
                    .world
                    .caster
                    .cast(o, a, g.max_range)
                    .unwrap_or(f64::INFINITY);
                let mut transient = false;
                for m in &near {
                    let w = [m.pos[0] - o[0], m.pos[1] - o[1]];
                    let tc = w[0] * d[0] + w[1] * d[1];
                    let h2 = w[0] * w[0] + w[1] * w[1] - tc * tc;
                    let rr = m.radius * m.radius;
                    if tc > 0.0 && h2 < rr {
                        let t = tc - (rr - h2).sqrt();
                        if t < r && t <= g.max_range {
                            r = t;
                            transient = true;
                        }
                    }
                }
                // One noise draw per beam whether or not it returns, so runs with and
                // without visible transients share the noise of every static return.
                let e = noise.map(|n| n.sample(&mut noise_rng)).unwrap_or(0.0);
                if r.is_finite() {
                    if transient {
                        hits.push([(o[0] + r * d[0]) as f32, (o[1] + r * d[1]) as f32]);
                    }
                    ((r + e).max(0.0)) as f32
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        (ranges, hits)
    }

    fn add_node(&mut self, r: usize) {
        let id = self.nodes.len();
        let truth = self.robots[r].pose;
        let (ranges, transient_hits) = self.scan(&truth);
        let (sxy, sth) = (self.cfg.odom_sigma_xy, self.cfg.odom_sigma_theta);
        let estimate = match self.robots[r].last_node {
            None => {
                self.edges.push(Edge {
                    kind: EdgeKind::Prior,
                    from: id as u64,
                    to: id as u64,
                    z: truth,
                    cov: diag_cov(0.01, 0.01, 0.001),
                });
                truth
            }
            Some(prev) => {
                let rel = se2_between(&self.nodes[prev].truth, &truth);
                let dist = rel[0].hypot(rel[1]);
                let (s_xy, s_th) = (0.01 + sxy * dist, 0.002 + sth * rel[2].abs());
                let n = |s: f64, rng: &mut Pcg64| {
                    Normal::new(0.0, s).map(|d| d.sample(rng)).unwrap_or(0.0)
                };
                let z = [
                    rel[0] + n(s_xy, &mut self.rng),
                    rel[1] + n(s_xy, &mut self.rng),
                    wrap_angle(rel[2] + n(s_th, &mut self.rng) + self.robots[r].drift * dist),
                ];
                self.edges.push(Edge {
                    kind: EdgeKind::Odometry,
                    from: prev as u64,
                    to: id as u64,
                    z,
                    cov: diag_cov(s_xy, s_xy, s_th),
                });
                se2_compose(&self.nodes[prev].estimate, &z)
            }
        };
        // Loop closures from ground-truth overlap: earlier nodes within the radius, in line
        // of sight, not the robot's own recent ones; each found with some probability.
        let cell = self.cfg.closure_radius;
        let key = |p: &[f64; 3]| ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64);
        let (ci, cj) = key(&truth);
        let mut cands: Vec<(f64, usize)> = Vec::new();
        for di in -1..=1 {
            for dj in -1..=1 {
                for &u in self
                    .grid
                    .get(&(ci + di, cj + dj))
                    .map_or(&[][..], |v| &v[..])
                {
                    let nu = &self.nodes[u];
                    let d = (nu.truth[0] - truth[0]).hypot(nu.truth[1] - truth[1]);
                    let recent = nu.robot as usize == r && id - u < 12;
                    if d < self.cfg.closure_radius && !recent {
                        cands.push((d, u));
                    }
                }
            }
        }
        cands.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut found = 0;
        for (_, u) in cands {
            if found >= 2 {
                break;
            }
            if self.rng.random::<f64>() >= self.cfg.closure_probability {
                continue;
            }
            let tu = self.nodes[u].truth;
            if !self
                .world
                .line_of_sight([tu[0], tu[1]], [truth[0], truth[1]])
            {
                continue;
            }
            let rel = se2_between(&tu, &truth);
            let [sx, st] = self.cfg.closure_sigma;
            let n =
                |s: f64, rng: &mut Pcg64| Normal::new(0.0, s).map(|d| d.sample(rng)).unwrap_or(0.0);
            let z = [
                rel[0] + n(sx, &mut self.rng),
                rel[1] + n(sx, &mut self.rng),
                wrap_angle(rel[2] + n(st, &mut self.rng)),
            ];
            self.edges.push(Edge {
                kind: EdgeKind::LoopClosure,
                from: u as u64,
                to: id as u64,
                z,
                cov: diag_cov(sx.max(1e-4), sx.max(1e-4), st.max(1e-5)),
            });
            found += 1;
            self.closures_since += 1;
        }
        self.grid.entry((ci, cj)).or_default().push(id);
        self.nodes.push(SimNode {
            robot: r as u32,
            truth,
            estimate,
            ranges,
            transient_hits,
        });
        let rb = &mut self.robots[r];
        rb.last_node = Some(id);
        rb.travelled = 0.0;
        rb.turned = 0.0;
    }

    /// Solves the pose graph by sparse Levenberg–Marquardt (SE(2) blocks, between and prior
    /// residuals) from the current estimates. Returns the iterations.
    fn solve(&mut self) -> Result<usize> {
        let mut p = Problem::new();
        let blocks = self
            .nodes
            .iter()
            .map(|n| p.add_block(&n.estimate, Manifold::Se2))
            .collect::<Result<Vec<_>>>()?;
        for e in &self.edges {
            let cov = nalgebra::Matrix3::from_row_slice(&e.cov);
            match e.kind {
                EdgeKind::Prior => {
                    let c = nalgebra::DMatrix::from_row_slice(3, 3, &e.cov);
                    p.add_prior(blocks[e.from as usize], &e.z, &c)?;
                }
                _ => {
                    let r = Se2BetweenResidual::new(e.z, &cov)?;
                    p.add_residual(
                        r,
                        &[blocks[e.from as usize], blocks[e.to as usize]],
                        Loss::Trivial,
                    )?;
                }
            }
        }
        let opts = SolverOptions {
            max_iterations: 30,
            function_tolerance: 1e-9,
            parameter_tolerance: 1e-9,
            ..SolverOptions::default()
        };
        let summary = p.solve(&opts)?;
        for (n, b) in self.nodes.iter_mut().zip(&blocks) {
            let v = p.values(*b);
            n.estimate = [v[0], v[1], v[2]];
        }
        Ok(summary.iterations)
    }

    /// Advances `period` seconds of mission time and returns the next graph, or `None` after
    /// `graphs` graphs.
    pub fn step(&mut self) -> Result<Option<GraphSnapshot>> {
        if self.graphs >= self.cfg.graphs {
            return Ok(None);
        }
        if self.graphs > 0 {
            let steps = (self.cfg.period / self.cfg.dt).round().max(1.0) as usize;
            for _ in 0..steps {
                self.advance_movers(self.cfg.dt);
                self.advance_robots(self.cfg.dt);
                self.time += self.cfg.dt;
            }
        }
        let new_closures = self.closures_since;
        self.closures_since = 0;
        let t0 = Instant::now();
        // Without new closures the previous optimum extended by odometry is the optimum
        // (each new node has a single odometry edge, whose residual it zeroes).
        let iterations = if new_closures > 0 || self.graphs == 0 {
            self.solve()?
        } else {
            0
        };
        let solve_seconds = t0.elapsed().as_secs_f64();
        let snap = GraphSnapshot {
            index: self.graphs,
            time: self.time,
            node_ids: (0..self.nodes.len() as u64).collect(),
            robot_ids: self.nodes.iter().map(|n| n.robot).collect(),
            poses: self.nodes.iter().map(|n| n.estimate).collect(),
            truth: self.nodes.iter().map(|n| n.truth).collect(),
            new_nodes: self.nodes.len() - self.reported_nodes,
            edges: self.edges.clone(),
            new_closures,
            solver_iterations: iterations,
            solve_seconds,
        };
        self.reported_nodes = self.nodes.len();
        self.graphs += 1;
        Ok(Some(snap))
    }
}

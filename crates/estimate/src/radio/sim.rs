//! A seeded radio simulator for robot teams (the test bed of seed 004 §3.3, simulated): a
//! fine material map of buildings (outer walls, corridors, rooms behind drywall, doors),
//! fences and open ground; robots exploring a roadmap of it; every pair's RSS at 20 Hz from
//!
//! ```text
//! y = L0 − a·log10 max(d, 1 m) − Σ_cells len·att(material) − Σ_indoor-air len·clutter − s
//! ```
//!
//! (eq. 3.1 with the shadowing of eq. 3.2 integrated on the true materials), and `s` the
//! log-normal shadowing of standard deviation σ (4 dB by default): a spatially correlated
//! part `σ√w (F(t) + F(r))/√2` with `F` a unit-variance Gaussian random field (random
//! Fourier features of a squared-exponential covariance, correlation length `ℓ`) — symmetric
//! in transmitter and receiver and a function of position, as shadowing is — plus an
//! independent part `σ√(1 − w) ε` per measurement.
//!
//! The robots' lidar (range 20 m, 1° rays, once per second) labels the cells it sees, giving
//! the ternary occupancy grid the models get: [`Observed::map_at`] at any time of the
//! replay.

use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use super::Link;
use super::grid::{ClassGrid, FREE, GridGeometry, STRUCTURE, UNKNOWN};
use crate::{EstimateError, Result};

/// Materials of the true map, with attenuation in dB per metre of material.
pub const MATERIALS: [(&str, f64); 6] = [
    ("air", 0.0),
    ("drywall", 15.0),
    ("brick", 20.0),
    ("concrete", 30.0),
    ("wood", 10.0),
    ("glass", 8.0),
];
const AIR: u8 = 0;
const DRYWALL: u8 = 1;
const BRICK: u8 = 2;
const CONCRETE: u8 = 3;
const WOOD: u8 = 4;

/// The built-in environments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EnvironmentKind {
    /// One large building: three bands of rooms off two corridors (indoor-heavy), 72 × 48 m.
    Office,
    /// Open ground between five buildings (two enterable) and fences (outdoor-heavy),
    /// 160 × 100 m.
    Campus,
    /// A building with rooms beside a yard with sheds and fences, 120 × 80 m.
    Mixed,
}

impl EnvironmentKind {
    /// Parses `"office"`, `"campus"` or `"mixed"`.
    pub fn from_name(name: &str) -> Result<Self> {
        match name {
            "office" => Ok(Self::Office),
            "campus" => Ok(Self::Campus),
            "mixed" => Ok(Self::Mixed),
            _ => Err(EstimateError::InvalidProblem(format!(
                "unknown environment {name:?} (expected office, campus or mixed)"
            ))),
        }
    }
}

/// Radio propagation parameters of the simulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadioParams {
    /// Power at 1 m, dBm.
    pub l0: f64,
    /// Path-loss exponent `a` (dB per decade).
    pub exponent: f64,
    /// Shadowing standard deviation σ, dB.
    pub sigma: f64,
    /// Share `w` of the shadowing variance that is spatially correlated.
    pub correlated_share: f64,
    /// Correlation length ℓ of the shadowing field, metres.
    pub correlation_length: f64,
    /// Extra attenuation of indoor free space (furniture, people), dB per metre.
    pub clutter: f64,
}

impl Default for RadioParams {
    fn default() -> Self {
        Self {
            l0: -40.0,
            exponent: 22.0,
            sigma: 4.0,
            correlated_share: 0.5,
            correlation_length: 6.0,
            clutter: 0.4,
        }
    }
}

/// A simulated world: the true materials on a fine grid and a roadmap robots drive on.
#[derive(Debug, Clone)]
pub struct Environment {
    /// Its name.
    pub name: &'static str,
    /// The fine grid (0.2 m).
    pub geometry: GridGeometry,
    /// Material index per cell (into [`MATERIALS`]).
    pub material: Vec<u8>,
    /// Whether each cell is inside a building.
    pub indoor: Vec<bool>,
    /// Roadmap nodes.
    pub nodes: Vec<[f64; 2]>,
    /// Roadmap adjacency.
    pub edges: Vec<Vec<usize>>,
}

struct Builder {
    g: GridGeometry,
    material: Vec<u8>,
    indoor: Vec<bool>,
    nodes: Vec<[f64; 2]>,
}

impl Builder {
    fn rect(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, mut f: impl FnMut(&mut u8, &mut bool)) {
        let r = self.g.resolution;
        let j0 = ((x0 - self.g.origin[0]) / r).round().max(0.0) as usize;
        let j1 = (((x1 - self.g.origin[0]) / r).round() as usize).min(self.g.cols);
        let i0 = ((y0 - self.g.origin[1]) / r).round().max(0.0) as usize;
        let i1 = (((y1 - self.g.origin[1]) / r).round() as usize).min(self.g.rows);
        for i in i0..i1 {
            for j in j0..j1 {
                let k = i * self.g.cols + j;
                f(&mut self.material[k], &mut self.indoor[k]);
            }
        }
    }

    fn fill(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, m: u8) {
        self.rect(x0, y0, x1, y1, |c, _| *c = m);
    }

    /// A horizontal (`horizontal`) or vertical wall along `at` from `a` to `b`.
    fn wall(&mut self, horizontal: bool, at: f64, a: f64, b: f64, t: f64, m: u8) {
        if horizontal {
            self.fill(a, at - t / 2.0, b, at + t / 2.0, m);
        } else {
            self.fill(at - t / 2.0, a, at + t / 2.0, b, m);
        }
    }

    /// A door of width `w` centred at `(x, y)` in a wall (`horizontal` wall orientation),
    /// with roadmap nodes 0.9 m either side.
    fn door(&mut self, horizontal: bool, x: f64, y: f64, w: f64) {
        if horizontal {
            self.fill(x - w / 2.0, y - 0.4, x + w / 2.0, y + 0.4, AIR);
            self.nodes.push([x, y - 0.9]);
            self.nodes.push([x, y + 0.9]);
        } else {
            self.fill(x - 0.4, y - w / 2.0, x + 0.4, y + w / 2.0, AIR);
            self.nodes.push([x - 0.9, y]);
            self.nodes.push([x + 0.9, y]);
        }
    }

    /// A building on `[x0, x1] × [y0, y1]` with outer walls of `outer`. `corridors`: the y of
    /// horizontal corridors (2.4 m wide, entrances at both ends); rooms (drywall, one door
    /// each) fill the bands between corridors and outer walls. No corridor: a closed block.
    #[allow(clippy::too_many_arguments)]
    fn building(
        &mut self,
        rng: &mut Pcg64,
        [x0, y0, x1, y1]: [f64; 4],
        outer: u8,
        corridors: &[f64],
        spine: Option<f64>,
    ) {
        self.rect(x0, y0, x1, y1, |_, ind| *ind = true);
        let t = 0.4;
        self.wall(true, y0, x0, x1, t, outer);
        self.wall(true, y1, x0, x1, t, outer);
        self.wall(false, x0, y0, y1, t, outer);
        self.wall(false, x1, y0, y1, t, outer);
        let half = 1.2;
        for &cy in corridors {
            self.wall(true, cy - half, x0, x1, 0.2, DRYWALL);
            self.wall(true, cy + half, x0, x1, 0.2, DRYWALL);
            self.fill(x0 + 0.2, cy - half + 0.1, x1 - 0.2, cy + half - 0.1, AIR);
            self.door(false, x0, cy, 1.6);
            self.door(false, x1, cy, 1.6);
            let mut x = x0 + 2.0;
            while x < x1 - 1.0 {
                self.nodes.push([x, cy]);
                x += 4.0;
            }
        }
        if let Some(sx) = spine {
            self.fill(sx - half + 0.1, y0 + 0.2, sx + half - 0.1, y1 - 0.2, AIR);
            let mut y = y0 + 2.0;
            while y < y1 - 1.0 {
                self.nodes.push([sx, y]);
                y += 4.0;
            }
        }
        if corridors.is_empty() {
            return;
        }
        // Bands of rooms between the horizontal boundaries.
        let mut bounds = vec![(y0, None)];
        for &cy in corridors {
            bounds.push((cy - half, Some(cy)));
            bounds.push((cy + half, Some(cy)));
        }
        bounds.push((y1, None));
        for pair in bounds.chunks(2) {
            let ((ya, ca), (yb, cb)) = (pair[0], pair[1]);
            if yb - ya < 3.0 {
                continue;
            }
            // Split a band between two corridors in two halves, one per corridor.
            let halves: Vec<(f64, f64, f64, f64)> = match (ca, cb) {
                (Some(_), Some(_)) => {
                    let ym = 0.5 * (ya + yb);
                    self.wall(true, ym, x0, x1, 0.2, DRYWALL);
                    vec![(ya, ym, ya, 1.0), (ym, yb, yb, -1.0)]
                }
                (Some(_), None) => vec![(ya, yb, ya, 1.0)],
                (None, Some(_)) => vec![(ya, yb, yb, -1.0)],
                (None, None) => vec![],
            };
            for (ra, rb, door_y, _dir) in halves {
                let mut x = x0;
                while x < x1 - 1.0 {
                    let w = rng.random_range(4.0..7.0f64).min(x1 - x);
                    let xe = if x1 - (x + w) < 3.0 { x1 } else { x + w };
                    if xe < x1 {
                        self.wall(false, xe, ra, rb, 0.2, DRYWALL);
                    }
                    let dx = x + rng.random_range(0.3..0.7) * (xe - x);
                    let in_spine = spine.is_some_and(|sx| (dx - sx).abs() < 2.5);
                    if !in_spine {
                        self.door(true, dx, door_y, 1.0);
                        self.nodes.push([0.5 * (x + xe), 0.5 * (ra + rb)]);
                    }
                    x = xe;
                }
            }
        }
        if let Some(sx) = spine {
            // Re-open the spine through the room walls it crosses, entrances at both ends.
            self.fill(sx - half + 0.1, y0 + 0.2, sx + half - 0.1, y1 - 0.2, AIR);
            self.door(true, sx, y0, 1.6);
            self.door(true, sx, y1, 1.6);
        }
    }

    fn finish(self, name: &'static str, rng: &mut Pcg64) -> Environment {
        let mut env = Environment {
            name,
            geometry: self.g,
            material: self.material,
            indoor: self.indoor,
            nodes: Vec::new(),
            edges: Vec::new(),
        };
        // Outdoor lattice nodes with 1 m clearance, plus the builder's nodes.
        let [x1, y1] = env.geometry.far_corner();
        let mut nodes = Vec::new();
        let mut y = env.geometry.origin[1] + 3.0;
        while y < y1 - 2.0 {
            let mut x = env.geometry.origin[0] + 3.0;
            while x < x1 - 2.0 {
                let p = [
                    x + rng.random_range(-1.0..1.0),
                    y + rng.random_range(-1.0..1.0),
                ];
                if env.clear(p, 1.0) && !env.indoor[env.geometry.cell_of(p).unwrap_or(0)] {
                    nodes.push(p);
                }
                x += 6.0;
            }
            y += 6.0;
        }
        nodes.extend(self.nodes.into_iter().filter(|p| env.clear(*p, 0.3)));
        let n = nodes.len();
        let mut edges = vec![Vec::new(); n];
        for a in 0..n {
            for b in a + 1..n {
                let d = ((nodes[a][0] - nodes[b][0]).powi(2) + (nodes[a][1] - nodes[b][1]).powi(2))
                    .sqrt();
                if d < 8.5 && env.segment_clear(nodes[a], nodes[b]) {
                    edges[a].push(b);
                    edges[b].push(a);
                }
            }
        }
        env.nodes = nodes;
        env.edges = edges;
        env
    }
}

impl Environment {
    /// Builds environment `kind` with `seed` (room widths, door positions, node jitter).
    pub fn new(kind: EnvironmentKind, seed: u64) -> Environment {
        let mut rng = Pcg64::seed_from_u64(seed);
        let (w, h, name) = match kind {
            EnvironmentKind::Office => (72.0, 48.0, "office"),
            EnvironmentKind::Campus => (160.0, 100.0, "campus"),
            EnvironmentKind::Mixed => (120.0, 80.0, "mixed"),
        };
        let res = 0.2;
        let g = GridGeometry {
            rows: (h / res) as usize,
            cols: (w / res) as usize,
            resolution: res,
            origin: [0.0, 0.0],
        };
        let mut b = Builder {
            material: vec![AIR; g.len()],
            indoor: vec![false; g.len()],
            g,
            nodes: Vec::new(),
        };
        match kind {
            EnvironmentKind::Office => {
                b.building(
                    &mut rng,
                    [4.0, 4.0, 68.0, 44.0],
                    CONCRETE,
                    &[16.0, 32.0],
                    Some(36.0),
                );
            }
            EnvironmentKind::Campus => {
                b.building(
                    &mut rng,
                    [10.0, 10.0, 60.0, 38.0],
                    BRICK,
                    &[24.0],
                    Some(35.0),
                );
                b.building(&mut rng, [90.0, 60.0, 140.0, 88.0], CONCRETE, &[74.0], None);
                b.building(&mut rng, [80.0, 12.0, 110.0, 40.0], CONCRETE, &[], None);
                b.building(&mut rng, [125.0, 15.0, 150.0, 40.0], BRICK, &[], None);
                b.building(&mut rng, [15.0, 60.0, 55.0, 85.0], BRICK, &[], None);
                b.wall(false, 70.0, 50.0, 95.0, 0.2, WOOD);
                b.wall(true, 52.0, 100.0, 150.0, 0.2, WOOD);
            }
            EnvironmentKind::Mixed => {
                b.building(
                    &mut rng,
                    [5.0, 8.0, 55.0, 72.0],
                    CONCRETE,
                    &[24.0, 52.0],
                    Some(30.0),
                );
                b.building(&mut rng, [75.0, 10.0, 95.0, 25.0], BRICK, &[], None);
                b.building(&mut rng, [85.0, 50.0, 110.0, 65.0], BRICK, &[], None);
                b.wall(false, 65.0, 30.0, 70.0, 0.2, WOOD);
                b.wall(true, 40.0, 70.0, 115.0, 0.2, WOOD);
                b.fill(70.0, 39.9, 74.0, 40.1, AIR);
            }
        }
        b.finish(name, &mut rng)
    }

    fn clear(&self, p: [f64; 2], radius: f64) -> bool {
        let r = self.geometry.resolution;
        let steps = (radius / r).ceil() as i64;
        (-steps..=steps).all(|di| {
            (-steps..=steps).all(|dj| {
                let q = [p[0] + dj as f64 * r, p[1] + di as f64 * r];
                self.geometry
                    .cell_of(q)
                    .is_some_and(|c| self.material[c] == AIR)
            })
        })
    }

    fn segment_clear(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        let mut ok = true;
        self.geometry
            .traverse(a, b, |c, _| ok &= self.material[c] == AIR);
        // Keep 0.3 m from walls on both sides.
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = (dx * dx + dy * dy).sqrt().max(1e-9);
        let (nx, ny) = (-dy / len * 0.3, dx / len * 0.3);
        for s in [-1.0, 1.0] {
            self.geometry.traverse(
                [a[0] + s * nx, a[1] + s * ny],
                [b[0] + s * nx, b[1] + s * ny],
                |c, _| ok &= self.material[c] == AIR,
            );
        }
        ok
    }

    /// Noise-free RSS of a link (path loss and the true attenuation integral).
    pub fn mean_rss(&self, link: &Link, p: &RadioParams) -> f64 {
        let mut att = 0.0;
        self.geometry.traverse(link.tx, link.rx, |c, w| {
            let m = self.material[c];
            att += w * MATERIALS[m as usize].1;
            if m == AIR && self.indoor[c] {
                att += w * p.clutter;
            }
        });
        p.l0 - p.exponent * link.log_distance() - att
    }

    /// The true attenuation per cell, dB per metre (materials and indoor clutter).
    pub fn attenuation(&self, p: &RadioParams) -> Vec<f64> {
        self.material
            .iter()
            .zip(&self.indoor)
            .map(|(&m, &ind)| {
                MATERIALS[m as usize].1 + if m == AIR && ind { p.clutter } else { 0.0 }
            })
            .collect()
    }
}

/// Robot positions sampled at a fixed rate.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectories {
    /// Sample times, seconds.
    pub times: Vec<f64>,
    /// `positions[robot][sample]`.
    pub positions: Vec<Vec<[f64; 2]>>,
}

/// Robots exploring the roadmap: each goes to the least-visited neighbour of its node (ties
/// at random; team-wide visit counts, so robots spread out and rarely retrace their steps, as
/// in §3.3's exploration missions) at `speed` m/s (±20 % per robot), sampled at `rate` Hz.
/// Errors: `InvalidParameter` for non-positive counts, speed, rate or duration.
pub fn explore(
    env: &Environment,
    robots: usize,
    duration: f64,
    speed: f64,
    rate: f64,
    seed: u64,
) -> Result<Trajectories> {
    for (name, v) in [
        ("robots", robots as f64),
        ("duration", duration),
        ("speed", speed),
        ("rate", rate),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name,
                value: v,
                reason: "must be positive",
            });
        }
    }
    if env.nodes.len() <= robots {
        return Err(EstimateError::InvalidProblem(
            "roadmap too small for the team".into(),
        ));
    }
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut visits = vec![0u32; env.nodes.len()];
    // Start at the `robots` nodes nearest a random outdoor-or-corridor node with neighbours.
    let start = loop {
        let s = rng.random_range(0..env.nodes.len());
        if env.edges[s].len() >= 2 {
            break s;
        }
    };
    let mut order: Vec<usize> = (0..env.nodes.len())
        .filter(|&k| !env.edges[k].is_empty())
        .collect();
    let d2 = |k: usize| {
        (env.nodes[k][0] - env.nodes[start][0]).powi(2)
            + (env.nodes[k][1] - env.nodes[start][1]).powi(2)
    };
    order.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)));
    struct Walker {
        from: usize,
        to: usize,
        progress: f64,
        speed: f64,
    }
    let mut walkers: Vec<Walker> = order[..robots]
        .iter()
        .map(|&s| {
            visits[s] += 1;
            Walker {
                from: s,
                to: s,
                progress: 0.0,
                speed: speed * rng.random_range(0.8..1.2),
            }
        })
        .collect();
    // Sizes and step lengths from the caller: a step longer than the map (speed/rate ≈ 1e300)
    // walked the roadmap edge by edge for ever, and duration·rate ≈ 1e300 steps aborted the
    // process on allocation.
    let g = &env.geometry;
    let extent = g.rows.max(g.cols) as f64 * g.resolution;
    // speed and rate are finite and positive (checked above): no NaN reaches these tests.
    if speed * 1.2 / rate > extent {
        return Err(EstimateError::InvalidParameter {
            name: "speed/rate",
            value: speed / rate,
            reason: "a robot must not move farther than the map's extent in one time step",
        });
    }
    let steps_f = (duration * rate).round();
    if steps_f >= u32::MAX as f64 {
        return Err(EstimateError::InvalidParameter {
            name: "duration·rate",
            value: steps_f,
            reason: "the number of time steps must stay below 2³²",
        });
    }
    let steps = steps_f as usize;
    let dt = 1.0 / rate;
    autoteach_geometry::alloc::ensure_fits::<[f64; 2]>(
        "trajectory samples",
        autoteach_geometry::alloc::checked_count("trajectory samples", steps, robots + 1)?,
    )?;
    let mut times = autoteach_geometry::alloc::try_with_capacity("trajectory times", steps)?;
    let mut positions = vec![Vec::with_capacity(steps); robots];
    for s in 0..steps {
        times.push(s as f64 * dt);
        for (r, w) in walkers.iter_mut().enumerate() {
            let mut travel = w.speed * dt;
            let pos;
            loop {
                let (a, b) = (env.nodes[w.from], env.nodes[w.to]);
                let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2))
                    .sqrt()
                    .max(0.0);
                if w.progress + travel < len {
                    w.progress += travel;
                    let f = w.progress / len;
                    pos = [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])];
                    break;
                }
                travel -= len - w.progress;
                // Arrived at `to`: choose the least-visited neighbour (no immediate return
                // unless it is a dead end).
                let here = w.to;
                let nbrs = &env.edges[here];
                let min = nbrs
                    .iter()
                    .filter(|&&k| k != w.from || nbrs.len() == 1)
                    .map(|&k| visits[k])
                    .min()
                    .unwrap_or(0);
                let best: Vec<usize> = nbrs
                    .iter()
                    .copied()
                    .filter(|&k| (k != w.from || nbrs.len() == 1) && visits[k] == min)
                    .collect();
                let next = best[rng.random_range(0..best.len())];
                visits[next] += 1;
                w.from = here;
                w.to = next;
                w.progress = 0.0;
            }
            positions[r].push(pos);
        }
    }
    Ok(Trajectories { times, positions })
}

/// Time-stamped measurements of every robot pair.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurements {
    /// Measurement times, seconds.
    pub times: Vec<f64>,
    /// The links (transmitter = lower robot index).
    pub links: Vec<Link>,
    /// Robot indices `[tx, rx]`.
    pub pairs: Vec<[usize; 2]>,
    /// Measured RSS, dBm.
    pub rss: Vec<f64>,
    /// Noise-free RSS (path loss and true attenuation), dBm.
    pub mean: Vec<f64>,
}

/// A unit-variance Gaussian random field (random Fourier features of a squared-exponential
/// covariance of length `ell`).
struct Field {
    w: Vec<[f64; 2]>,
    b: Vec<f64>,
}

impl Field {
    fn new(ell: f64, features: usize, rng: &mut Pcg64) -> Self {
        let w = (0..features)
            .map(|_| {
                let a: f64 = StandardNormal.sample(rng);
                let c: f64 = StandardNormal.sample(rng);
                [a / ell, c / ell]
            })
            .collect();
        let b = (0..features)
            .map(|_| rng.random_range(0.0..std::f64::consts::TAU))
            .collect();
        Self { w, b }
    }

    fn at(&self, p: [f64; 2]) -> f64 {
        let s: f64 = self
            .w
            .iter()
            .zip(&self.b)
            .map(|(w, b)| (w[0] * p[0] + w[1] * p[1] + b).cos())
            .sum();
        s * (2.0 / self.w.len() as f64).sqrt()
    }
}

/// Every pair's RSS at every sample of `traj` (20 Hz in §3.3.1). Pairs closer than 0.05 m
/// are skipped (robots never overlap; the guard keeps links valid).
pub fn measure(env: &Environment, traj: &Trajectories, p: &RadioParams, seed: u64) -> Measurements {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x005E_ED0F_5AD0);
    let field = Field::new(p.correlation_length, 256, &mut rng);
    let (sc, si) = (
        p.sigma * p.correlated_share.clamp(0.0, 1.0).sqrt(),
        p.sigma * (1.0 - p.correlated_share.clamp(0.0, 1.0)).sqrt(),
    );
    let robots = traj.positions.len();
    let mut m = Measurements {
        times: Vec::new(),
        links: Vec::new(),
        pairs: Vec::new(),
        rss: Vec::new(),
        mean: Vec::new(),
    };
    for (s, &t) in traj.times.iter().enumerate() {
        for a in 0..robots {
            for b in a + 1..robots {
                let link = Link {
                    tx: traj.positions[a][s],
                    rx: traj.positions[b][s],
                };
                if link.length() < 0.05 {
                    continue;
                }
                let mean = env.mean_rss(&link, p);
                let e: f64 = StandardNormal.sample(&mut rng);
                let shadow = sc * (field.at(link.tx) + field.at(link.rx)) / 2f64.sqrt() + si * e;
                m.times.push(t);
                m.links.push(link);
                m.pairs.push([a, b]);
                m.mean.push(mean);
                m.rss.push(mean - shadow);
            }
        }
    }
    m
}

/// What the robots' lidar has seen: the time each fine cell was first observed.
#[derive(Debug, Clone, PartialEq)]
pub struct Observed {
    /// The fine grid.
    pub geometry: GridGeometry,
    /// Whether each cell is structure (any material) in truth.
    pub solid: Vec<bool>,
    /// First time each cell was seen (∞ if never).
    pub first_seen: Vec<f64>,
}

/// Casts 1° lidar rays of `range` metres once per second from every robot: a ray marks the
/// free cells it crosses and stops at the first solid cell, which it marks as structure.
pub fn observe(env: &Environment, traj: &Trajectories, range: f64) -> Observed {
    let g = env.geometry;
    let mut first_seen = vec![f64::INFINITY; g.len()];
    let period = traj
        .times
        .iter()
        .position(|&t| t >= 1.0)
        .unwrap_or(1)
        .max(1);
    for robot in &traj.positions {
        for s in (0..robot.len()).step_by(period) {
            let t = traj.times[s];
            let p = robot[s];
            for k in 0..360 {
                let ang = (k as f64).to_radians();
                let q = [p[0] + range * ang.cos(), p[1] + range * ang.sin()];
                let mut stop = false;
                g.traverse(p, q, |c, _| {
                    if stop {
                        return;
                    }
                    if first_seen[c] > t {
                        first_seen[c] = t;
                    }
                    if env.material[c] != AIR {
                        stop = true;
                    }
                });
            }
        }
    }
    Observed {
        geometry: g,
        solid: env.material.iter().map(|&m| m != AIR).collect(),
        first_seen,
    }
}

impl Observed {
    /// The ternary occupancy grid known at time `t` (cells not yet seen are unknown).
    pub fn map_at(&self, t: f64) -> ClassGrid {
        let classes = self
            .first_seen
            .iter()
            .zip(&self.solid)
            .map(|(&f, &s)| {
                if f > t {
                    UNKNOWN
                } else if s {
                    STRUCTURE
                } else {
                    FREE
                }
            })
            .collect();
        ClassGrid {
            geometry: self.geometry,
            classes,
        }
    }
}

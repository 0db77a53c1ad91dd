//! Simulated worlds of the kind mapped in seed 004_815695db12a6b16c.txt ch. 2 (Keswick
//! Barracks, Adelaide Showgrounds; Table 2.2): blocks of buildings with doorways and an
//! interior wall, separated by streets, with open yards holding a few containers, inside a
//! perimeter fence. Robots travel a road graph along the streets and into the buildings.

use autoteach_geometry::planar::{Segment, SegmentWorld};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::{EstimateError, Result};

/// Parameters of a generated world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldConfig {
    /// Extent along x (m).
    pub width: f64,
    /// Extent along y (m).
    pub height: f64,
    /// Target distance between street centre lines (m).
    pub block_pitch: f64,
    /// Street width (m).
    pub street: f64,
    /// Fraction of blocks that are open yards instead of buildings.
    pub yard_fraction: f64,
    /// Seed of the layout.
    pub seed: u64,
}

impl WorldConfig {
    /// Keswick Barracks as in Table 2.2 (150 × 150 m; Fig. 2.1's caption says 180 × 100 m,
    /// a slip of the seed, see `docs/design/mapping.md`).
    pub fn keswick(seed: u64) -> Self {
        Self {
            width: 150.0,
            height: 150.0,
            block_pitch: 30.0,
            street: 8.0,
            yard_fraction: 0.25,
            seed,
        }
    }

    /// The Adelaide Showgrounds, MAGIC 2010 phase 2 (220 × 160 m, Table 2.2).
    pub fn showgrounds(seed: u64) -> Self {
        Self {
            width: 220.0,
            height: 160.0,
            ..Self::keswick(seed)
        }
    }

    /// A small world for tests (60 × 50 m).
    pub fn small(seed: u64) -> Self {
        Self {
            width: 60.0,
            height: 50.0,
            ..Self::keswick(seed)
        }
    }

    fn validate(&self) -> Result<()> {
        for (name, v, lo) in [
            ("world width", self.width, 20.0),
            ("world height", self.height, 20.0),
            ("block_pitch", self.block_pitch, 16.0),
            ("street", self.street, 3.0),
        ] {
            if !(v.is_finite() && v >= lo) {
                return Err(EstimateError::InvalidParameter {
                    name,
                    value: v,
                    reason: "too small or not finite (world ≥ 20 m, pitch ≥ 16 m, street ≥ 3 m)",
                });
            }
        }
        if !(0.0..=1.0).contains(&self.yard_fraction) {
            return Err(EstimateError::InvalidParameter {
                name: "yard_fraction",
                value: self.yard_fraction,
                reason: "must be in [0, 1]",
            });
        }
        Ok(())
    }
}

/// A generated world: wall segments (ground truth), a ray caster and the road graph.
#[derive(Debug, Clone)]
pub struct World {
    /// The configuration.
    pub config: WorldConfig,
    /// Every wall, fence and container side.
    pub walls: Vec<Segment>,
    /// Ray caster over `walls`.
    pub caster: SegmentWorld,
    /// Road-graph vertices (m).
    pub roads: Vec<[f64; 2]>,
    /// Road-graph adjacency.
    pub adjacency: Vec<Vec<usize>>,
    /// Street intersections (indices into `roads`), the network transients move on.
    pub intersections: Vec<usize>,
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> [Segment; 4] {
    [
        Segment::new([x0, y0], [x1, y0]),
        Segment::new([x1, y0], [x1, y1]),
        Segment::new([x1, y1], [x0, y1]),
        Segment::new([x0, y1], [x0, y0]),
    ]
}

impl World {
    /// Generates the world.
    pub fn generate(cfg: WorldConfig) -> Result<Self> {
        cfg.validate()?;
        let mut rng = Pcg64::seed_from_u64(cfg.seed ^ 0x005e_ed0f_3a11);
        let s = cfg.street;
        let nbx = (((cfg.width - s) / cfg.block_pitch).round() as usize).max(1);
        let nby = (((cfg.height - s) / cfg.block_pitch).round() as usize).max(1);
        let px = (cfg.width - s) / nbx as f64;
        let py = (cfg.height - s) / nby as f64;
        let xs: Vec<f64> = (0..=nbx).map(|i| s / 2.0 + i as f64 * px).collect();
        let ys: Vec<f64> = (0..=nby).map(|j| s / 2.0 + j as f64 * py).collect();
        let mut walls: Vec<Segment> = rect(0.0, 0.0, cfg.width, cfg.height).to_vec();
        let mut roads: Vec<[f64; 2]> = Vec::new();
        let mut adjacency: Vec<Vec<usize>> = Vec::new();
        let add_node = |p: [f64; 2], roads: &mut Vec<[f64; 2]>, adj: &mut Vec<Vec<usize>>| {
            roads.push(p);
            adj.push(Vec::new());
            roads.len() - 1
        };
        let link = |a: usize, b: usize, adj: &mut Vec<Vec<usize>>| {
            adj[a].push(b);
            adj[b].push(a);
        };
        let inter = |i: usize, j: usize| j * (nbx + 1) + i;
        for &y in &ys {
            for &x in &xs {
                add_node([x, y], &mut roads, &mut adjacency);
            }
        }
        let intersections: Vec<usize> = (0..roads.len()).collect();
        // Vertical streets.
        for i in 0..=nbx {
            for j in 0..nby {
                link(inter(i, j), inter(i, j + 1), &mut adjacency);
            }
        }
        // Blocks (and the horizontal street below each, split at a building's door).
        for j in 0..=nby {
            for i in 0..nbx {
                let door_x = if j < nby {
                    let (bx0, bx1) = (xs[i] + s / 2.0, xs[i + 1] - s / 2.0);
                    let (by0, by1) = (ys[j] + s / 2.0, ys[j + 1] - s / 2.0);
                    let m = |r: &mut Pcg64| r.random_range(0.5..2.0);
                    let (x0, x1) = (bx0 + m(&mut rng), bx1 - m(&mut rng));
                    let (y0, y1) = (by0 + m(&mut rng), by1 - m(&mut rng));
                    let xm = x0 + (x1 - x0) * rng.random_range(0.4..0.6);
                    let ym = y0 + (y1 - y0) * rng.random_range(0.35..0.65);
                    // Too small for two rooms and a doorway: a yard instead.
                    let roomy = xm - x0 >= 4.0 && x1 - xm >= 3.0 && y1 - y0 >= 5.0;
                    if !roomy || rng.random::<f64>() < cfg.yard_fraction {
                        // A yard with a few containers (2.4 × 6 m).
                        for _ in 0..rng.random_range(1..=3) {
                            let (w, h) = if rng.random::<bool>() {
                                (2.4, 6.0)
                            } else {
                                (6.0, 2.4)
                            };
                            if bx1 - bx0 > w + 2.0 && by1 - by0 > h + 2.0 {
                                let x = rng.random_range(bx0 + 1.0..bx1 - w - 1.0);
                                let y = rng.random_range(by0 + 1.0..by1 - h - 1.0);
                                walls.extend(rect(x, y, x + w, y + h));
                            }
                        }
                        None
                    } else {
                        let xd = rng.random_range(x0 + 1.6..xm - 1.6);
                        let half = 0.8;
                        walls.push(Segment::new([x0, y0], [xd - half, y0]));
                        walls.push(Segment::new([xd + half, y0], [x1, y0]));
                        walls.push(Segment::new([x1, y0], [x1, y1]));
                        walls.push(Segment::new([x1, y1], [x0, y1]));
                        walls.push(Segment::new([x0, y1], [x0, y0]));
                        walls.push(Segment::new([xm, y0], [xm, ym - half]));
                        walls.push(Segment::new([xm, ym + half], [xm, y1]));
                        let cy = (y0 + y1) / 2.0;
                        let path = [
                            [xd, y0 + 1.5],
                            [(x0 + xm) / 2.0, cy],
                            [xm - 1.2, ym],
                            [xm + 1.2, ym],
                            [(xm + x1) / 2.0, cy],
                        ];
                        let ids: Vec<usize> = path
                            .iter()
                            .map(|p| add_node(*p, &mut roads, &mut adjacency))
                            .collect();
                        for w in ids.windows(2) {
                            link(w[0], w[1], &mut adjacency);
                        }
                        Some((xd, ids[0]))
                    }
                } else {
                    None
                };
                match door_x {
                    Some((xd, inside)) => {
                        let st = add_node([xd, ys[j]], &mut roads, &mut adjacency);
                        link(inter(i, j), st, &mut adjacency);
                        link(st, inter(i + 1, j), &mut adjacency);
                        link(st, inside, &mut adjacency);
                    }
                    None => link(inter(i, j), inter(i + 1, j), &mut adjacency),
                }
            }
        }
        let caster = SegmentWorld::new(walls.clone(), 4.0)?;
        Ok(Self {
            config: cfg,
            walls,
            caster,
            roads,
            adjacency,
            intersections,
        })
    }

    /// Whether the straight line a → b crosses no wall.
    pub fn line_of_sight(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        let d = (b[0] - a[0]).hypot(b[1] - a[1]);
        if d < 1e-9 {
            return true;
        }
        let ang = (b[1] - a[1]).atan2(b[0] - a[0]);
        self.caster.cast(a, ang, d).is_none()
    }

    /// Distance from a point to the nearest wall.
    pub fn wall_distance(&self, p: [f64; 2]) -> f64 {
        self.walls
            .iter()
            .map(|w| w.distance(p))
            .fold(f64::INFINITY, f64::min)
    }
}

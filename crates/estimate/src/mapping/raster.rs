//! Occupancy-grid rasterization of a sequence of SLAM graphs (seed 004_815695db12a6b16c.txt
//! ch. 2): the three methods of Table 2.1 — NaïveComposite, NaïveCoverComposite and
//! CoverComposite(N) (Algorithm 2.1 COVER_COMPOSITE: slice caching §2.3, node coverings
//! §2.4, transient removal by voting §2.5).
//!
//! Every method projects each node's scan at its RENDERED pose: the posterior at which it was
//! last rendered, replaced by the current posterior as soon as that moves some point of the
//! projection by more than one cell (§2.3's regeneration test, [`footprint_displacement`]).
//! Every map is thus within one cell of the projection of the maximum-likelihood graph, and
//! with coverings off CoverComposite's map equals NaïveComposite's cell for cell (a cached
//! slice is reused only when none of its members was re-rendered); with coverings on the two
//! differ only by the dropped redundant scans.

use std::collections::HashMap;
use std::time::Instant;

use super::cover::CoverTest;
use super::grid::{OccupancyGrid, VoteModel};
use super::scan::{LocalScan, ScanGeometry, footprint_displacement};
use super::votes::{CellBox, DenseVotes, Projection, SparseVotes};
use crate::{EstimateError, Result};

/// The rasterization methods of Table 2.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Every node composited onto a fresh map at every update.
    NaiveComposite,
    /// The nodes of the cover (§2.4) composited onto a fresh map at every update.
    NaiveCoverComposite,
    /// Algorithm 2.1: cover nodes grouped in slices of `slice_size` sequential nodes per
    /// robot, a slice's sub-map regenerated only when a member's projection moved.
    CoverComposite,
}

/// Rasterizer settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RasterConfig {
    /// The method.
    pub method: Method,
    /// N: nodes per slice (CoverComposite).
    pub slice_size: usize,
    /// Metres per cell.
    pub resolution: f64,
    /// Whether CoverComposite drops redundant nodes (always on for NaïveCoverComposite,
    /// always off for NaïveComposite).
    pub covering: bool,
    /// The covering test.
    pub cover: CoverTest,
    /// The scan geometry.
    pub scan: ScanGeometry,
    /// The per-cell vote.
    pub votes: VoteModel,
}

impl Default for RasterConfig {
    fn default() -> Self {
        Self {
            method: Method::CoverComposite,
            slice_size: 4,
            resolution: 0.1,
            covering: true,
            cover: CoverTest::default(),
            scan: ScanGeometry::default(),
            votes: VoteModel::default(),
        }
    }
}

impl RasterConfig {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<()> {
        if !(self.resolution.is_finite() && self.resolution > 0.0) {
            return Err(EstimateError::InvalidParameter {
                name: "resolution",
                value: self.resolution,
                reason: "must be positive and finite",
            });
        }
        if self.slice_size == 0 || self.slice_size > 4096 {
            return Err(EstimateError::InvalidParameter {
                name: "slice_size",
                value: self.slice_size as f64,
                reason: "must be in 1..=4096",
            });
        }
        if self.scan.max_range / self.resolution > 1e6 {
            return Err(EstimateError::InvalidParameter {
                name: "resolution",
                value: self.resolution,
                reason: "more than 10⁶ cells per beam",
            });
        }
        self.cover.validate()?;
        self.scan.validate()?;
        self.votes.validate()
    }

    fn uses_cover(&self) -> bool {
        match self.method {
            Method::NaiveComposite => false,
            Method::NaiveCoverComposite => true,
            Method::CoverComposite => self.covering,
        }
    }
}

/// One node of the current graph as the user hands it over.
#[derive(Debug, Clone, Copy)]
pub struct NodeInput<'a> {
    /// Node id (unique, stable across updates).
    pub id: u64,
    /// The robot that created it.
    pub robot: u32,
    /// ML posterior `[x, y, θ]` (m, rad).
    pub pose: [f64; 3],
    /// Ranges (m) of its scan: required when the node is new, ignored afterwards.
    pub ranges: Option<&'a [f64]>,
}

/// What one update did (Fig. 2.8's quantities).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UpdateReport {
    /// Nodes in the graph.
    pub nodes: usize,
    /// Nodes new in this graph.
    pub new_nodes: usize,
    /// Nodes in the cover (all nodes when coverings are off).
    pub cover_nodes: usize,
    /// Slices (CoverComposite; 0 otherwise).
    pub slices: usize,
    /// Slices regenerated in this update.
    pub slices_regenerated: usize,
    /// Node scans rasterized in this update (into slices or the map).
    pub nodes_rasterized: usize,
    /// Nodes whose votes make up the map.
    pub nodes_composited: usize,
    /// Beams of the new nodes dropped for NaN ranges.
    pub dropped_beams: usize,
    /// Wall time of the update (s).
    pub seconds: f64,
}

struct Node {
    id: u64,
    robot: u32,
    /// The scan (kept only while the node may be rasterized: dropped for uncovered nodes).
    scan: Option<LocalScan>,
    pose: [f64; 3],
    /// The pose its scan is projected at (see the module documentation).
    render: [f64; 3],
    /// Times `render` changed.
    version: u64,
    in_cover: bool,
    /// The tight box of its votes at render version `.0`.
    bbox: Option<(u64, CellBox)>,
}

struct Slice {
    members: Vec<usize>,
    /// The members' render versions when the slice was generated.
    cached: Vec<u64>,
    votes: SparseVotes,
    valid: bool,
}

#[derive(Default)]
struct RobotState {
    cover: Vec<usize>,
    slices: Vec<usize>,
}

/// Rasterizes a sequence of graphs G₁, G₂, … (node sets growing: V_i ⊆ V_{i+1}) into maps.
pub struct Rasterizer {
    cfg: RasterConfig,
    nodes: Vec<Node>,
    index: HashMap<u64, usize>,
    robots: HashMap<u32, RobotState>,
    robot_order: Vec<u32>,
    slices: Vec<Slice>,
    scratch: DenseVotes,
    map: DenseVotes,
}

impl std::fmt::Debug for Rasterizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rasterizer")
            .field("config", &self.cfg)
            .field("nodes", &self.nodes.len())
            .field("slices", &self.slices.len())
            .finish()
    }
}

impl Rasterizer {
    /// A rasterizer with validated settings.
    pub fn new(cfg: RasterConfig) -> Result<Self> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            nodes: Vec::new(),
            index: HashMap::new(),
            robots: HashMap::new(),
            robot_order: Vec::new(),
            slices: Vec::new(),
            scratch: DenseVotes::default(),
            map: DenseVotes::default(),
        })
    }

    /// The settings.
    pub fn config(&self) -> &RasterConfig {
        &self.cfg
    }

    /// Nodes seen so far.
    pub fn num_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Whether node `id` was seen in an earlier update (its scan is then not needed again).
    pub fn is_known(&self, id: u64) -> bool {
        self.index.contains_key(&id)
    }

    /// Approximate bytes held: stored scans, cached slice sub-maps and the map buffer.
    pub fn memory_bytes(&self) -> usize {
        let scans: usize = self
            .nodes
            .iter()
            .filter_map(|n| n.scan.as_ref())
            .map(|s| s.ends.capacity() * 8 + s.hit.capacity())
            .sum();
        let slices: usize = self.slices.iter().map(|s| s.votes.bytes()).sum();
        let map = (self.map.free.capacity() + self.scratch.free.capacity()) * 8;
        scans + slices + map + self.nodes.capacity() * std::mem::size_of::<Node>()
    }

    /// Checks a graph before anything is changed (so a rejected update leaves the state
    /// untouched) and parses the new nodes' scans.
    fn validate(&self, graph: &[NodeInput<'_>]) -> Result<Vec<Option<LocalScan>>> {
        if graph.is_empty() {
            return Err(EstimateError::InvalidMapInput(
                "the graph must have at least one node, got none (nothing to rasterize)".into(),
            ));
        }
        let mut seen: HashMap<u64, usize> = HashMap::with_capacity(graph.len());
        let mut scans = Vec::with_capacity(graph.len());
        for (k, n) in graph.iter().enumerate() {
            if let Some((c, &v)) = n.pose.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(EstimateError::NonFiniteInput {
                    what: format!("pose of node {} (row {k})", n.id),
                    index: c,
                    value: v,
                });
            }
            if let Some(first) = seen.insert(n.id, k) {
                return Err(EstimateError::InvalidMapInput(format!(
                    "node id {} appears twice (rows {first} and {k})",
                    n.id
                )));
            }
            match self.index.get(&n.id) {
                Some(&i) => {
                    if self.nodes[i].robot != n.robot {
                        return Err(EstimateError::InvalidMapInput(format!(
                            "node {} moved from robot {} to robot {}",
                            n.id, self.nodes[i].robot, n.robot
                        )));
                    }
                    scans.push(None);
                }
                None => {
                    let Some(r) = n.ranges else {
                        return Err(EstimateError::InvalidMapInput(format!(
                            "node {} is new but has no scan",
                            n.id
                        )));
                    };
                    scans.push(Some(LocalScan::from_ranges(r, &self.cfg.scan, n.id)?));
                }
            }
        }
        self.check_extent(graph)?;
        let known_present = graph.len() - scans.iter().filter(|s| s.is_some()).count();
        if known_present < self.nodes.len() {
            let gone: Vec<u64> = self
                .nodes
                .iter()
                .filter(|n| !seen.contains_key(&n.id))
                .take(5)
                .map(|n| n.id)
                .collect();
            return Err(EstimateError::InvalidMapInput(format!(
                "{} node(s) of the previous graph are missing (e.g. {gone:?}); graphs must grow \
                 (V_i ⊆ V_(i+1), seed §2.3): start a new Rasterizer for a pruned graph",
                self.nodes.len() - known_present
            )));
        }
        Ok(scans)
    }

    /// The map can only cover the poses' box grown by the sensor range: its cells must have
    /// i32 indices (|x|/resolution < 2³⁰) and its vote buffers must fit in memory. Checked
    /// here so that a pose of 1e8 m is an error rather than an aborting allocation, and 1e300 m
    /// an error rather than a map on saturated cell indices.
    fn check_extent(&self, graph: &[NodeInput<'_>]) -> Result<()> {
        let (res, reach) = (self.cfg.resolution, self.cfg.scan.max_range);
        let limit = f64::from(1u32 << 30);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for n in graph {
            for c in 0..2 {
                let v = n.pose[c];
                if (v.abs() + reach) / res >= limit {
                    return Err(EstimateError::InvalidMapInput(format!(
                        "pose of node {} has coordinate {} m, beyond the map's reach of {:.3e} m \
                         at resolution {res} m: coordinates must stay within it (cell indices are \
                         32-bit)",
                        n.id,
                        autoteach_geometry::error::Num(v),
                        limit * res - reach
                    )));
                }
                lo[c] = lo[c].min(v);
                hi[c] = hi[c].max(v);
            }
        }
        let cells = |c: usize| ((hi[c] - lo[c] + 2.0 * reach) / res).ceil() as usize + 1;
        let area = autoteach_geometry::alloc::checked_count("map cells", cells(0), cells(1))?;
        // Free and occupied votes (u16 each) and a stamp (u32) per cell.
        autoteach_geometry::alloc::ensure_fits::<u64>("map cells", area)?;
        Ok(())
    }

    /// Rasterizes the next graph (Algorithm 2.1 for CoverComposite) and returns its map.
    pub fn update(&mut self, graph: &[NodeInput<'_>]) -> Result<(OccupancyGrid, UpdateReport)> {
        let t0 = Instant::now();
        let scans = self.validate(graph)?;
        let mut report = UpdateReport {
            nodes: graph.len(),
            ..Default::default()
        };
        // Posteriors of the known nodes; a node is re-rendered when its projection moved by
        // more than one cell.
        let (res, reach) = (self.cfg.resolution, self.cfg.scan.max_range);
        for n in graph {
            if let Some(&i) = self.index.get(&n.id) {
                let node = &mut self.nodes[i];
                node.pose = n.pose;
                let moved = footprint_displacement(&node.render, &n.pose, reach) > res;
                if moved {
                    node.render = n.pose;
                    node.version += 1;
                }
            }
        }
        // Lines 1–8: new nodes, the covering test, the next slice of their robot.
        let use_cover = self.cfg.uses_cover();
        for (n, scan) in graph.iter().zip(scans) {
            let Some(scan) = scan else { continue };
            report.new_nodes += 1;
            report.dropped_beams += scan.dropped;
            let idx = self.nodes.len();
            let robot = self.robots.entry(n.robot).or_insert_with(|| {
                self.robot_order.push(n.robot);
                RobotState::default()
            });
            let in_cover = !use_cover
                || self
                    .cfg
                    .cover
                    .admits(&n.pose, robot.cover.iter().map(|&c| &self.nodes[c].pose));
            if in_cover {
                robot.cover.push(idx);
            }
            if in_cover && self.cfg.method == Method::CoverComposite {
                let open = robot
                    .slices
                    .last()
                    .copied()
                    .filter(|&s| self.slices[s].members.len() < self.cfg.slice_size);
                let s = match open {
                    Some(s) => s,
                    None => {
                        self.slices.push(Slice {
                            members: Vec::with_capacity(self.cfg.slice_size),
                            cached: Vec::new(),
                            votes: SparseVotes::default(),
                            valid: false,
                        });
                        robot.slices.push(self.slices.len() - 1);
                        self.slices.len() - 1
                    }
                };
                self.slices[s].members.push(idx);
                self.slices[s].valid = false;
            }
            self.index.insert(n.id, idx);
            self.nodes.push(Node {
                id: n.id,
                robot: n.robot,
                scan: in_cover.then_some(scan),
                pose: n.pose,
                render: n.pose,
                version: 0,
                in_cover,
                bbox: None,
            });
        }
        report.cover_nodes = self.nodes.iter().filter(|n| n.in_cover).count();
        let map = match self.cfg.method {
            Method::CoverComposite => self.cover_composite(&mut report),
            Method::NaiveComposite | Method::NaiveCoverComposite => self.naive(&mut report),
        };
        report.seconds = t0.elapsed().as_secs_f64();
        Ok((map, report))
    }

    fn node_bbox(&mut self, i: usize) -> CellBox {
        let node = &self.nodes[i];
        if let Some((v, b)) = node.bbox
            && v == node.version
        {
            return b;
        }
        let b = match &node.scan {
            Some(s) => Projection::new(s, &node.render, self.cfg.resolution).bbox,
            None => CellBox::EMPTY,
        };
        self.nodes[i].bbox = Some((self.nodes[i].version, b));
        b
    }

    fn projection(&self, i: usize) -> Option<Projection> {
        let node = &self.nodes[i];
        node.scan
            .as_ref()
            .map(|s| Projection::new(s, &node.render, self.cfg.resolution))
    }

    /// NaïveComposite / NaïveCoverComposite: every (cover) node onto a fresh map.
    fn naive(&mut self, report: &mut UpdateReport) -> OccupancyGrid {
        let members: Vec<usize> = match self.cfg.method {
            Method::NaiveComposite => (0..self.nodes.len()).collect(),
            _ => self
                .robot_order
                .iter()
                .flat_map(|r| self.robots[r].cover.iter().copied())
                .collect(),
        };
        let mut bbox = CellBox::EMPTY;
        for &i in &members {
            bbox = bbox.union(&self.node_bbox(i));
        }
        let mut map = std::mem::take(&mut self.map);
        map.reset(bbox);
        for &i in &members {
            if let Some(p) = self.projection(i) {
                map.rasterize(&p);
            }
        }
        report.nodes_rasterized = members.len();
        report.nodes_composited = members.len();
        let grid = OccupancyGrid::from_votes(&map, &self.cfg.votes, self.cfg.resolution);
        self.map = map;
        grid
    }

    /// Algorithm 2.1, lines 9–19. The map's counts are kept between updates: a regenerated
    /// slice's old votes are subtracted and its new ones added, so an update costs the moved
    /// slices, not the whole map (the final threshold pass excepted).
    fn cover_composite(&mut self, report: &mut UpdateReport) -> OccupancyGrid {
        // The map's box: the union of the slices' boxes (each the union of its members'),
        // grown once per update rather than once per slice.
        let mut bbox = CellBox::EMPTY;
        for s in 0..self.slices.len() {
            for k in 0..self.slices[s].members.len() {
                bbox = bbox.union(&self.node_bbox(self.slices[s].members[k]));
            }
        }
        let mut map = std::mem::take(&mut self.map);
        map.grow_to(&bbox);
        // Lines 9–13: regenerate the slices whose members' projections moved.
        for s in 0..self.slices.len() {
            let slice = &self.slices[s];
            let moved = !slice.valid
                || slice
                    .members
                    .iter()
                    .zip(&slice.cached)
                    .any(|(&m, &v)| self.nodes[m].version != v);
            if !moved {
                continue;
            }
            let members = self.slices[s].members.clone();
            let mut bbox = CellBox::EMPTY;
            for &m in &members {
                bbox = bbox.union(&self.node_bbox(m));
            }
            let mut scratch = std::mem::take(&mut self.scratch);
            scratch.reset(bbox);
            for &m in &members {
                if let Some(p) = self.projection(m) {
                    scratch.rasterize(&p);
                }
            }
            let votes = SparseVotes::from_dense(&scratch);
            self.scratch = scratch;
            let slice = &mut self.slices[s];
            let old = std::mem::replace(&mut slice.votes, votes);
            old.remove_from(&mut map);
            slice.votes.composite_onto(&mut map);
            slice.cached = members.iter().map(|&m| self.nodes[m].version).collect();
            slice.valid = true;
            report.slices_regenerated += 1;
            report.nodes_rasterized += members.len();
        }
        // Lines 14–18: a map bounded by the slices (their votes are in `map`), thresholded.
        report.slices = self.slices.len();
        report.nodes_composited = self.slices.iter().map(|s| s.members.len()).sum();
        let grid = OccupancyGrid::from_votes_in(&map, bbox, &self.cfg.votes, self.cfg.resolution);
        self.map = map;
        grid
    }
}

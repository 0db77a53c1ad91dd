//! Bindings of `autoteach_estimate::mapping`: occupancy-grid rasterization for robot teams
//! (seed 004_815695db12a6b16c.txt ch. 2) and the team simulator. The friendly wrapper is
//! `python/autoteach/mapping.py`.

use autoteach_estimate::mapping::{
    CoverTest, EdgeKind, Method, NodeInput, OccupancyGrid, RasterConfig, Rasterizer, ScanGeometry,
    TeamConfig, TeamSimulator, UpdateReport, VoteModel, WorldConfig, transient_residue, wall_gaps,
};
use autoteach_geometry::planar::Segment;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, Array};
use crate::errors;

fn method_arg(name: &str) -> PyResult<Method> {
    match name {
        "naive_composite" => Ok(Method::NaiveComposite),
        "naive_cover_composite" => Ok(Method::NaiveCoverComposite),
        "cover_composite" => Ok(Method::CoverComposite),
        other => Err(errors::invalid_input(format!(
            "method must be 'naive_composite', 'naive_cover_composite' or 'cover_composite', got {other:?}"
        ))),
    }
}

fn ids_arg(a: &PyReadonlyArray1<'_, i64>, name: &str) -> PyResult<Vec<i64>> {
    let v: Vec<i64> = a.as_array().iter().copied().collect();
    match v.iter().position(|&x| x < 0) {
        Some(k) => Err(errors::invalid_input(format!(
            "{name} must be non-negative, got {} at index {k}",
            v[k]
        ))),
        None => Ok(v),
    }
}

fn report_dict<'py>(py: Python<'py>, r: &UpdateReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("nodes", r.nodes)?;
    d.set_item("new_nodes", r.new_nodes)?;
    d.set_item("cover_nodes", r.cover_nodes)?;
    d.set_item("slices", r.slices)?;
    d.set_item("slices_regenerated", r.slices_regenerated)?;
    d.set_item("nodes_rasterized", r.nodes_rasterized)?;
    d.set_item("nodes_composited", r.nodes_composited)?;
    d.set_item("dropped_beams", r.dropped_beams)?;
    d.set_item("seconds", r.seconds)?;
    Ok(d)
}

type GridTuple<'py> = (Bound<'py, numpy::PyArray2<i8>>, f64, f64, f64);

fn grid_out<'py>(py: Python<'py>, g: OccupancyGrid) -> PyResult<GridTuple<'py>> {
    let arr = Array2::from_shape_vec((g.height, g.width), g.cells)
        .map_err(|e| errors::internal(format!("grid shape: {e}")))?;
    Ok((arr.into_pyarray(py), g.origin_x, g.origin_y, g.resolution))
}

fn grid_in(cells: &PyReadonlyArray2<'_, i8>, origin: (f64, f64), resolution: f64) -> OccupancyGrid {
    let shape = cells.shape();
    OccupancyGrid {
        resolution,
        origin_x: origin.0,
        origin_y: origin.1,
        width: shape[1],
        height: shape[0],
        cells: cells.as_array().iter().copied().collect(),
    }
}

/// The compiled rasterizer (Table 2.1's methods); see `autoteach.mapping.Rasterizer`.
#[pyclass(name = "Rasterizer", module = "autoteach._core")]
pub struct PyRasterizer {
    inner: Rasterizer,
}

#[pymethods]
impl PyRasterizer {
    #[new]
    #[pyo3(signature = (method="cover_composite", slice_size=4, resolution=0.1, covering=true,
        cover_distance=0.75, cover_angle=0.5235987755982988, angle_min=-2.356194490192345,
        angle_increment=0.004363323129985824, max_range=30.0, log_odds_hit=0.8472978603872037,
        log_odds_miss=-0.4054651081081643, prior=0.0, threshold=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        method: &str,
        slice_size: usize,
        resolution: f64,
        covering: bool,
        cover_distance: f64,
        cover_angle: f64,
        angle_min: f64,
        angle_increment: f64,
        max_range: f64,
        log_odds_hit: f64,
        log_odds_miss: f64,
        prior: f64,
        threshold: f64,
    ) -> PyResult<Self> {
        let cfg = RasterConfig {
            method: method_arg(method)?,
            slice_size,
            resolution,
            covering,
            cover: CoverTest {
                distance: cover_distance,
                angle: cover_angle,
            },
            scan: ScanGeometry {
                angle_min,
                angle_increment,
                max_range,
            },
            votes: VoteModel {
                log_odds_hit,
                log_odds_miss,
                prior,
                threshold,
            },
        };
        Ok(Self {
            inner: Rasterizer::new(cfg).map_err(errors::estimate)?,
        })
    }

    /// Rasterizes the next graph: `node_ids`, `robot_ids` (int64, (n,)), `poses` (n, 3)
    /// float64 finite; `scan_rows` (int64, (k,)) the node rows that `scans` ((k, B) float64,
    /// NaN/inf allowed) holds. Returns `(cells, origin_x, origin_y, resolution, report)`.
    #[allow(clippy::type_complexity)]
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        node_ids: PyReadonlyArray1<'py, i64>,
        robot_ids: PyReadonlyArray1<'py, i64>,
        poses: &Bound<'py, PyAny>,
        scan_rows: PyReadonlyArray1<'py, i64>,
        scans: &Bound<'py, PyAny>,
    ) -> PyResult<(
        Bound<'py, numpy::PyArray2<i8>>,
        f64,
        f64,
        f64,
        Bound<'py, PyDict>,
    )> {
        let ids = ids_arg(&node_ids, "node_ids")?;
        let robots = ids_arg(&robot_ids, "robot_ids")?;
        let n = ids.len();
        if robots.len() != n {
            return Err(errors::invalid_input(format!(
                "robot_ids must have shape ({n},), got ({},)",
                robots.len()
            )));
        }
        if let Some(&r) = robots.iter().find(|&&r| r > u32::MAX as i64) {
            return Err(errors::invalid_input(format!("robot id {r} exceeds 2³²−1")));
        }
        let p = convert::finite_array(poses, "poses")?.exact(&[n, 3])?;
        let rows = ids_arg(&scan_rows, "scan_rows")?;
        let scans = Array::new(scans, "scans")?;
        let shape = scans.shape().to_vec();
        if shape.len() != 2 || shape[0] != rows.len() {
            return Err(errors::invalid_input(format!(
                "scans must have shape ({}, beams), got {}",
                rows.len(),
                convert::shape_str(&shape)
            )));
        }
        let view = scans.view();
        let mut per_row: Vec<Option<Vec<f64>>> = vec![None; n];
        for (k, &r) in rows.iter().enumerate() {
            let r = r as usize;
            if r >= n {
                return Err(errors::invalid_input(format!(
                    "scan_rows[{k}] = {r} is not a node row (n = {n})"
                )));
            }
            if !self.inner.is_known(ids[r] as u64) {
                per_row[r] = Some(
                    view.index_axis(numpy::ndarray::Axis(0), k)
                        .iter()
                        .copied()
                        .collect(),
                );
            }
        }
        let inner = &mut self.inner;
        let (grid, report) = convert::detached(py, || {
            let nodes: Vec<NodeInput<'_>> = (0..n)
                .map(|k| NodeInput {
                    id: ids[k] as u64,
                    robot: robots[k] as u32,
                    pose: [p[3 * k], p[3 * k + 1], p[3 * k + 2]],
                    ranges: per_row[k].as_deref(),
                })
                .collect();
            inner.update(&nodes).map_err(errors::estimate)
        })?;
        let (cells, ox, oy, res) = grid_out(py, grid)?;
        Ok((cells, ox, oy, res, report_dict(py, &report)?))
    }

    /// Approximate bytes held (stored scans, cached slices, map buffers).
    fn memory_bytes(&self) -> usize {
        self.inner.memory_bytes()
    }

    /// Nodes seen so far.
    fn num_nodes(&self) -> usize {
        self.inner.num_nodes()
    }
}

/// The compiled team simulator; see `autoteach.mapping.TeamSimulator`.
#[pyclass(name = "TeamSimulator", module = "autoteach._core")]
pub struct PyTeamSimulator {
    inner: TeamSimulator,
}

#[pymethods]
impl PyTeamSimulator {
    #[new]
    #[pyo3(signature = (world="showgrounds", robots=None, graphs=None, seed=0, transients=true,
        people=None, vehicles=None, max_range=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        world: &str,
        robots: Option<usize>,
        graphs: Option<usize>,
        seed: u64,
        transients: bool,
        people: Option<usize>,
        vehicles: Option<usize>,
        max_range: Option<f64>,
    ) -> PyResult<Self> {
        let mut cfg = match world {
            "showgrounds" => TeamConfig::showgrounds(seed),
            "keswick" => TeamConfig::keswick(seed),
            "small" => TeamConfig::small(seed),
            other => {
                return Err(errors::invalid_input(format!(
                    "world must be 'showgrounds', 'keswick' or 'small', got {other:?}"
                )));
            }
        };
        cfg.robots = robots.unwrap_or(cfg.robots);
        cfg.graphs = graphs.unwrap_or(cfg.graphs);
        cfg.people = people.unwrap_or(cfg.people);
        cfg.vehicles = vehicles.unwrap_or(cfg.vehicles);
        cfg.scan.max_range = max_range.unwrap_or(cfg.scan.max_range);
        cfg.transients_visible = transients;
        let inner = convert::detached(py, || TeamSimulator::new(cfg).map_err(errors::estimate))?;
        Ok(Self { inner })
    }

    /// The next graph as a dict of arrays, or None at the end of the stream.
    fn step<'py>(&mut self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let inner = &mut self.inner;
        let Some(s) = convert::detached(py, || inner.step().map_err(errors::estimate))? else {
            return Ok(None);
        };
        let n = s.node_ids.len();
        let d = PyDict::new(py);
        d.set_item("index", s.index)?;
        d.set_item("time", s.time)?;
        d.set_item("new_nodes", s.new_nodes)?;
        d.set_item("new_closures", s.new_closures)?;
        d.set_item("solver_iterations", s.solver_iterations)?;
        d.set_item("solve_seconds", s.solve_seconds)?;
        let ids: Vec<i64> = s.node_ids.iter().map(|&v| v as i64).collect();
        d.set_item("node_ids", Array1::from_vec(ids).into_pyarray(py))?;
        let robots: Vec<i64> = s.robot_ids.iter().map(|&v| v as i64).collect();
        d.set_item("robot_ids", Array1::from_vec(robots).into_pyarray(py))?;
        let flat = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<f64>>();
        d.set_item("poses", convert::to_numpy(py, flat(&s.poses), &[n, 3])?)?;
        d.set_item("truth", convert::to_numpy(py, flat(&s.truth), &[n, 3])?)?;
        let m = s.edges.len();
        let ends: Vec<i64> = s
            .edges
            .iter()
            .flat_map(|e| [e.from as i64, e.to as i64])
            .collect();
        let kinds: Vec<i64> = s
            .edges
            .iter()
            .map(|e| match e.kind {
                EdgeKind::Prior => 0,
                EdgeKind::Odometry => 1,
                EdgeKind::LoopClosure => 2,
            })
            .collect();
        let ends = Array2::from_shape_vec((m, 2), ends)
            .map_err(|e| errors::internal(format!("edge shape: {e}")))?;
        d.set_item("edges", ends.into_pyarray(py))?;
        d.set_item("edge_kinds", Array1::from_vec(kinds).into_pyarray(py))?;
        let z: Vec<f64> = s.edges.iter().flat_map(|e| e.z).collect();
        d.set_item("edge_z", convert::to_numpy(py, z, &[m, 3])?)?;
        let cov: Vec<f64> = s.edges.iter().flat_map(|e| e.cov).collect();
        let cov = Array3::from_shape_vec((m, 3, 3), cov)
            .map_err(|e| errors::internal(format!("covariance shape: {e}")))?;
        d.set_item("edge_cov", cov.into_pyarray(py))?;
        Ok(Some(d))
    }

    /// Ranges (float64, (k, B); +inf = no return) of nodes `ids`.
    fn ranges<'py>(
        &self,
        py: Python<'py>,
        ids: PyReadonlyArray1<'py, i64>,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let ids = ids_arg(&ids, "ids")?;
        let mut out = Vec::new();
        let mut beams = 0;
        for &id in &ids {
            let r = self
                .inner
                .ranges(id as u64)
                .ok_or_else(|| errors::invalid_input(format!("unknown node id {id}")))?;
            beams = r.len();
            out.extend(r.iter().map(|&v| v as f64));
        }
        convert::to_numpy(py, out, &[ids.len(), beams])
    }

    /// World points (m, (h, 2)) where node `id`'s beams hit a transient object.
    fn transient_hits<'py>(
        &self,
        py: Python<'py>,
        id: i64,
    ) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let h = u64::try_from(id)
            .ok()
            .and_then(|id| self.inner.transient_hits(id))
            .ok_or_else(|| errors::invalid_input(format!("unknown node id {id}")))?;
        let v: Vec<f64> = h.iter().flat_map(|p| [p[0] as f64, p[1] as f64]).collect();
        convert::to_numpy(py, v, &[h.len(), 2])
    }

    /// Ground-truth walls as (m, 4) rows `[x0, y0, x1, y1]`.
    fn walls<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArrayDyn<f64>>> {
        let w = &self.inner.world().walls;
        let v: Vec<f64> = w
            .iter()
            .flat_map(|s| [s.a[0], s.a[1], s.b[0], s.b[1]])
            .collect();
        convert::to_numpy(py, v, &[w.len(), 4])
    }

    /// Graphs in the stream.
    fn graphs(&self) -> usize {
        self.inner.config().graphs
    }

    /// World extent `(width, height)` in metres.
    fn extent(&self) -> (f64, f64) {
        let c: WorldConfig = self.inner.world().config;
        (c.width, c.height)
    }

    /// Laser geometry `(angle_min, angle_increment, max_range)`.
    fn scan_geometry(&self) -> (f64, f64, f64) {
        let g = self.inner.config().scan;
        (g.angle_min, g.angle_increment, g.max_range)
    }

    /// Transient-object residue of a map (see `autoteach.mapping.transient_residue`):
    /// `(cells, structure, free)` over the nodes `ids` with posteriors `poses` (n, 3).
    #[pyo3(signature = (cells, origin, resolution, ids, poses, truth, margin=0.5))]
    #[allow(clippy::too_many_arguments)]
    fn transient_residue(
        &self,
        cells: PyReadonlyArray2<'_, i8>,
        origin: (f64, f64),
        resolution: f64,
        ids: PyReadonlyArray1<'_, i64>,
        poses: &Bound<'_, PyAny>,
        truth: &Bound<'_, PyAny>,
        margin: f64,
    ) -> PyResult<(usize, usize, usize)> {
        let map = grid_in(&cells, origin, resolution);
        let ids = ids_arg(&ids, "ids")?;
        let n = ids.len();
        let p = convert::finite_array(poses, "poses")?.exact(&[n, 3])?;
        let t = convert::finite_array(truth, "truth")?.exact(&[n, 3])?;
        let mut hits = Vec::with_capacity(n);
        for (k, &id) in ids.iter().enumerate() {
            let h = self
                .inner
                .transient_hits(id as u64)
                .ok_or_else(|| errors::invalid_input(format!("unknown node id {id}")))?;
            hits.push((
                [t[3 * k], t[3 * k + 1], t[3 * k + 2]],
                [p[3 * k], p[3 * k + 1], p[3 * k + 2]],
                h.to_vec(),
            ));
        }
        let r = transient_residue(&map, self.inner.world(), &hits, margin);
        Ok((r.cells, r.structure, r.free))
    }
}

/// Wall samples where `reference` shows structure within `radius` cells and `candidate` does
/// not: `(samples, gaps)` (the connectivity check along every true wall).
#[pyfunction]
#[pyo3(signature = (candidate, candidate_origin, reference, reference_origin, resolution, walls, radius=1))]
fn mapping_wall_gaps(
    candidate: PyReadonlyArray2<'_, i8>,
    candidate_origin: (f64, f64),
    reference: PyReadonlyArray2<'_, i8>,
    reference_origin: (f64, f64),
    resolution: f64,
    walls: &Bound<'_, PyAny>,
    radius: i64,
) -> PyResult<(usize, usize)> {
    let w = convert::finite_array(walls, "walls")?;
    let (rows, _) = w.rows(4, "(m, 4)")?;
    let segs: Vec<Segment> = rows
        .iter()
        .map(|r| Segment::new([r[0], r[1]], [r[2], r[3]]))
        .collect();
    let c = grid_in(&candidate, candidate_origin, resolution);
    let r = grid_in(&reference, reference_origin, resolution);
    let rep = wall_gaps(&c, &r, &segs, radius.clamp(0, 100));
    Ok((rep.samples, rep.gaps))
}

/// Registers the mapping classes and functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRasterizer>()?;
    m.add_class::<PyTeamSimulator>()?;
    m.add_function(wrap_pyfunction!(mapping_wall_gaps, m)?)?;
    Ok(())
}

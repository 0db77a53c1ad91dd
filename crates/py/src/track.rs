//! Bindings of `autoteach_detect::track`: the multi-wafer tracker (000_3b1454b2b2194811.txt
//! ch. 4, Algorithms 4–5).
//!
//! `TrackWaferTracker(...)` holds one `Tracker`; `update(edges, camera_pose)` takes the edges of
//! one frame as tuples `(ellipse (5,), points (N, 2), kind, wafer_id, residual)` and returns, per
//! edge, the id of the track it was registered to; `tracks()` lists the live tracks as dicts.
//! The friendly `autoteach.track.WaferTracker` builds the tuples from any edge object and keeps
//! the per-track histories of the caller's edge objects.

use autoteach_detect::track::registration::RegistrationOptions;
use autoteach_detect::track::{Associator, Track, Tracker, TrackerOptions};
use autoteach_detect::wafers::{RimKind, WaferEdge};
use autoteach_geometry::conic::Ellipse;
use nalgebra::{Matrix3, Point2, Vector3};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, Array};
use crate::errors;

/// Adds the track functions and classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTracker>()?;
    Ok(())
}

/// One frame's edge as passed from Python.
type EdgeTuple<'py> = (Bound<'py, PyAny>, Bound<'py, PyAny>, String, usize, f64);

/// The multi-wafer tracker (`autoteach._core.TrackWaferTracker`); see
/// `autoteach.track.WaferTracker`.
#[pyclass(name = "TrackWaferTracker", module = "autoteach._core")]
pub struct PyTracker {
    inner: Tracker,
}

fn ellipse_tuple(e: &Ellipse) -> (f64, f64, f64, f64, f64) {
    (e.cx, e.cy, e.a, e.b, e.theta)
}

fn edge_from_tuple(i: usize, t: &EdgeTuple<'_>) -> PyResult<WaferEdge> {
    let (ell, pts, kind, wafer_id, residual) = t;
    let e = Array::new(ell, "edge ellipse")?.vector()?;
    if e.len() != 5 {
        return Err(errors::invalid_input(format!(
            "edge {i}: ellipse must have 5 values (cx, cy, a, b, theta), got {}",
            e.len()
        )));
    }
    let ellipse = Ellipse::new(e[0], e[1], e[2], e[3], e[4])
        .map_err(|err| errors::invalid_input(format!("edge {i}: {err}")))?;
    let arr = Array::new(pts, "edge points")?;
    let points = if arr.shape().iter().product::<usize>() == 0 {
        Vec::new()
    } else {
        if arr.shape().len() != 2 || arr.shape()[1] != 2 {
            return Err(errors::invalid_input(format!(
                "edge {i}: points must have shape (N, 2), got {}",
                convert::shape_str(arr.shape())
            )));
        }
        let (data, _) = arr.batch(&[2], "(N, 2)")?;
        data.chunks_exact(2)
            .map(|c| Point2::new(c[0], c[1]))
            .collect()
    };
    let kind = match kind.as_str() {
        "upper" => RimKind::Upper,
        "lower" => RimKind::Lower,
        other => {
            return Err(errors::invalid_input(format!(
                "edge {i}: kind must be 'upper' or 'lower', got {other:?}"
            )));
        }
    };
    Ok(WaferEdge {
        ellipse,
        points,
        residual: *residual,
        covariance: None,
        kind,
        wafer_id: *wafer_id,
    })
}

fn track_dict<'py>(py: Python<'py>, t: &Track) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("id", t.id)?;
    d.set_item("visible", t.visible)?;
    d.set_item("confirmed", t.confirmed)?;
    d.set_item("hits", t.hits)?;
    d.set_item("missed", t.missed)?;
    d.set_item("first_frame", t.first_frame)?;
    d.set_item("last_frame", t.last_frame)?;
    d.set_item("ellipse", t.ellipse().as_ref().map(ellipse_tuple))?;
    d.set_item("predicted", t.predicted.as_ref().map(ellipse_tuple))?;
    let circle = t.circle().map(|c| {
        (
            (c.center.x, c.center.y, c.center.z),
            (c.normal.x, c.normal.y, c.normal.z),
            c.radius,
        )
    });
    d.set_item("circle", circle)?;
    Ok(d)
}

#[pymethods]
impl PyTracker {
    /// Builds the tracker; every option as in `autoteach.track.WaferTracker`.
    #[new]
    #[pyo3(signature = (*, sigma = 3.0, omega = 1e-4, knn = 8, gate = 5.0, min_score = 0.0, min_coverage = 0.0,
        associator = "hierarchical", greedy_gate = 40.0, max_points_per_segment = 48,
        max_missed = 30, min_hits = 2, rim_merge_distance = 4.0, image_size = None,
        intrinsics = None, wafer_radius = 0.15, normal_prior = None, circle_window = 6,
        prefer_projection = false, multiview_circle = true, normal_prior_sigma = 0.05,
        circle_fit_iterations = 1, projection_max_center_std = 0.003, projection_max_rms = 2.0, max_missed_3d = 300, stack_axis_sigma = Some(0.002),
        slot_pitch = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        sigma: f64,
        omega: f64,
        knn: usize,
        gate: f64,
        min_score: f64,
        min_coverage: f64,
        associator: &str,
        greedy_gate: f64,
        max_points_per_segment: usize,
        max_missed: usize,
        min_hits: usize,
        rim_merge_distance: f64,
        image_size: Option<(f64, f64)>,
        intrinsics: Option<&Bound<'_, PyAny>>,
        wafer_radius: f64,
        normal_prior: Option<(f64, f64, f64)>,
        circle_window: usize,
        prefer_projection: bool,
        multiview_circle: bool,
        normal_prior_sigma: f64,
        circle_fit_iterations: usize,
        projection_max_center_std: f64,
        projection_max_rms: f64,
        max_missed_3d: usize,
        stack_axis_sigma: Option<f64>,
        slot_pitch: Option<f64>,
    ) -> PyResult<Self> {
        let associator = match associator {
            "hierarchical" => Associator::Hierarchical,
            "greedy" => Associator::GreedyNearestCentre,
            other => {
                return Err(errors::invalid_input(format!(
                    "associator must be 'hierarchical' or 'greedy', got {other:?}"
                )));
            }
        };
        let intrinsics = intrinsics
            .map(|k| -> PyResult<Matrix3<f64>> {
                let a = convert::finite_array(k, "intrinsics")?;
                Ok(Matrix3::from_row_slice(&a.exact(&[3, 3])?))
            })
            .transpose()?;
        let options = TrackerOptions {
            registration: RegistrationOptions {
                sigma,
                omega,
                knn,
                gate,
                min_score,
                min_coverage,
            },
            associator,
            greedy_gate,
            max_points_per_segment,
            max_missed,
            min_hits,
            rim_merge_distance,
            image_size,
            intrinsics,
            wafer_radius,
            normal_prior: normal_prior.map(|(x, y, z)| Vector3::new(x, y, z)),
            circle_window,
            prefer_projection,
            multiview_circle,
            normal_prior_sigma,
            circle_fit_iterations,
            projection_max_center_std,
            projection_max_rms,
            max_missed_3d,
            stack_axis_sigma,
            slot_pitch,
        };
        Ok(PyTracker {
            inner: Tracker::new(options).map_err(errors::detect)?,
        })
    }

    /// Processes one frame; returns, for each edge, the id of its track (`None`: unregistered).
    #[pyo3(signature = (edges, camera_pose = None))]
    fn update(
        &mut self,
        py: Python<'_>,
        edges: Vec<EdgeTuple<'_>>,
        camera_pose: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Vec<Option<u64>>> {
        let edges: Vec<WaferEdge> = edges
            .iter()
            .enumerate()
            .map(|(i, t)| edge_from_tuple(i, t))
            .collect::<PyResult<_>>()?;
        let pose = camera_pose
            .map(|p| convert::isometry(p, "camera_pose"))
            .transpose()?;
        let tracker = &mut self.inner;
        convert::detached(py, move || {
            tracker
                .update(&edges, pose.as_ref())
                .map_err(errors::detect)?;
            Ok(tracker.edge_tracks().to_vec())
        })
    }

    /// The live tracks as dicts (id, visible, confirmed, hits, missed, first_frame,
    /// last_frame, ellipse, predicted, circle).
    fn tracks<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .tracks()
            .iter()
            .map(|t| track_dict(py, t))
            .collect()
    }

    /// The retired confirmed tracks as dicts.
    fn retired<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .retired()
            .iter()
            .map(|t| track_dict(py, t))
            .collect()
    }

    /// Stage timings (seconds) of the last update: `predict`, `associate` (Algorithm 5 or the
    /// greedy baseline), `manage` (Algorithm 4 with the 3D rim estimates).
    #[getter]
    fn last_timings(&self) -> (f64, f64, f64) {
        let t = self.inner.timings();
        (t.predict, t.associate, t.manage)
    }

    /// Number of frames processed.
    #[getter]
    fn frame(&self) -> usize {
        self.inner.frame()
    }
}

//! Bindings of `autoteach_detect::{voting, polygon}` and of the chamber-opening renderer
//! (`autoteach_geometry::render::opening`). Names carry the `polygon_` prefix; the friendly
//! wrappers live in `python/autoteach/polygon.py`. Options arrive as a dict whose keys are the
//! Rust option fields (unknown keys are an error); results are returned as dicts and arrays.

use autoteach_detect::polygon::{
    PolygonDetection, PolygonInput, PolygonOptions, Segment, SegmentOptions, detect_polygon,
    detect_segments,
};
use autoteach_detect::voting::{
    RigidHypothesis, VoteCount, VotingOptions, global_voting, vote_cells,
};
use autoteach_geometry::render::GrayImage;
use autoteach_geometry::render::opening::{
    ImageLine, ImagePolygon, OpeningScene, RefPolygon, render_opening,
};
use nalgebra::{DMatrix, Matrix3, Vector2};
use numpy::{IntoPyArray, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{self, Array};
use crate::errors;

/// Reads option `key` of `opts` (removing it, so leftovers can be reported).
fn take<'py, T: FromPyObjectOwned<'py>>(
    opts: &Bound<'py, PyDict>,
    key: &str,
) -> PyResult<Option<T>> {
    match opts.get_item(key)? {
        None => Ok(None),
        Some(v) => {
            opts.del_item(key)?;
            if v.is_none() {
                return Ok(None);
            }
            v.extract::<T>().map(Some).map_err(|_| {
                errors::invalid_input(format!(
                    "option {key} must be {}, got {}",
                    python_kind::<T>(),
                    short_repr(&v)
                ))
            })
        }
    }
}

/// What a Rust option type accepts, in Python's words (a negative count is out of range, not
/// of the wrong type).
fn python_kind<T>() -> &'static str {
    match std::any::type_name::<T>() {
        "usize" | "u64" | "u32" | "u16" | "u8" => "a non-negative integer",
        "isize" | "i64" | "i32" => "an integer",
        "f64" | "f32" => "a real number",
        "bool" => "True or False",
        n if n.ends_with("String") => "a string",
        _ => "of another type",
    }
}

/// `repr(value)`, elided in the middle beyond 40 characters (a 300-digit integer).
fn short_repr(v: &Bound<'_, PyAny>) -> String {
    let r = v
        .repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "an unprintable value".to_string());
    let chars: Vec<char> = r.chars().collect();
    if chars.len() <= 40 {
        return r;
    }
    let head: String = chars[..18].iter().collect();
    let tail: String = chars[chars.len() - 18..].iter().collect();
    format!("{head}...{tail} ({} characters)", chars.len())
}

/// Fails if `opts` still has keys.
fn no_leftovers(opts: &Bound<'_, PyDict>, what: &str) -> PyResult<()> {
    if opts.is_empty() {
        return Ok(());
    }
    let keys: Vec<String> = opts.keys().iter().map(|k| k.to_string()).collect();
    Err(errors::invalid_input(format!(
        "unknown {what} option(s): {}",
        keys.join(", ")
    )))
}

/// Copy of the options dict (the caller's dict is left untouched).
fn opts_copy<'py>(
    py: Python<'py>,
    opts: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    match opts {
        Some(d) => d.copy(),
        None => Ok(PyDict::new(py)),
    }
}

fn voting_options(py: Python<'_>, opts: Option<&Bound<'_, PyDict>>) -> PyResult<VotingOptions> {
    let d = opts_copy(py, opts)?;
    let mut o = VotingOptions::default();
    if let Some(v) = take(&d, "neighbours")? {
        o.neighbours = v;
    }
    if let Some(v) = take(&d, "angle_bin")? {
        o.angle_bin = v;
    }
    o.translation_bin = take(&d, "translation_bin")?;
    if let Some(v) = take(&d, "top_k")? {
        o.top_k = v;
    }
    if let Some(v) = take::<String>(&d, "count")? {
        o.count = match v.as_str() {
            "y" | "ycount" | "y_count" => VoteCount::YCount,
            "pairs" => VoteCount::Pairs,
            other => {
                return Err(errors::invalid_input(format!(
                    "count must be 'y' or 'pairs', got {other:?}"
                )));
            }
        };
    }
    if let Some(v) = take(&d, "min_votes")? {
        o.min_votes = v;
    }
    if let Some(v) = take(&d, "max_points")? {
        o.max_points = v;
    }
    o.descriptor_tolerance = take(&d, "descriptor_tolerance")?;
    if let Some(v) = take(&d, "shifted_grid")? {
        o.shifted_grid = v;
    }
    if let Some(v) = take(&d, "max_pairs")? {
        o.max_pairs = v;
    }
    no_leftovers(&d, "voting")?;
    Ok(o)
}

/// An `(N, D)` float64 point set (finiteness and D are checked by the core).
fn point_set(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<DMatrix<f64>> {
    let arr = Array::new(obj, name)?;
    let shape = arr.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (N, D), got {}",
            convert::shape_str(&shape)
        )));
    }
    let (data, _) = arr.batch(&[], "(N, D)")?;
    Ok(DMatrix::from_row_slice(shape[0], shape[1], &data))
}

/// Hypotheses as `(R (K, D, D), t (K, D), votes (K,), pair_votes (K,))`.
type HypothesisArrays<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
);

fn hypothesis_arrays<'py>(
    py: Python<'py>,
    h: &[RigidHypothesis],
    d: usize,
) -> PyResult<HypothesisArrays<'py>> {
    let k = h.len();
    let mut r = Vec::with_capacity(k * d * d);
    let mut t = Vec::with_capacity(k * d);
    for x in h {
        for a in 0..d {
            for b in 0..d {
                r.push(x.rotation[(a, b)]);
            }
        }
        t.extend(x.translation.iter());
    }
    let votes: Vec<i64> = h.iter().map(|x| x.votes as i64).collect();
    let pairs: Vec<i64> = h.iter().map(|x| x.pair_votes as i64).collect();
    Ok((
        convert::to_numpy(py, r, &[k, d, d])?.into_any(),
        convert::to_numpy(py, t, &[k, d])?.into_any(),
        votes.into_pyarray(py).into_any(),
        pairs.into_pyarray(py).into_any(),
    ))
}

/// Global voting (Algorithm 3): the top-K rigid transforms `x ≈ R y + t` mapping `y` onto `x`.
#[pyfunction]
#[pyo3(signature = (x, y, options = None))]
fn polygon_global_voting<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<HypothesisArrays<'py>> {
    let (xm, ym) = (point_set(x, "X")?, point_set(y, "Y")?);
    let o = voting_options(py, options)?;
    let h = convert::detached(py, || global_voting(&xm, &ym, &o).map_err(errors::detect))?;
    hypothesis_arrays(py, &h, xm.ncols())
}

/// Every populated vote cell (the vote map of Fig. 3.13), sorted by the chosen count.
#[pyfunction]
#[pyo3(signature = (x, y, options = None))]
fn polygon_vote_cells<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<HypothesisArrays<'py>> {
    let (xm, ym) = (point_set(x, "X")?, point_set(y, "Y")?);
    let o = voting_options(py, options)?;
    let h = convert::detached(py, || vote_cells(&xm, &ym, &o).map_err(errors::detect))?;
    hypothesis_arrays(py, &h, xm.ncols())
}

fn segment_options(py: Python<'_>, opts: Option<&Bound<'_, PyDict>>) -> PyResult<SegmentOptions> {
    let d = opts_copy(py, opts)?;
    let mut o = SegmentOptions::default();
    if let Some(v) = take(&d, "canny_low")? {
        o.canny_low = v;
    }
    if let Some(v) = take(&d, "canny_high")? {
        o.canny_high = v;
    }
    if let Some(v) = take(&d, "gradient_sigma")? {
        o.gradient_sigma = v;
    }
    if let Some(v) = take(&d, "angle_tolerance")? {
        o.angle_tolerance = v;
    }
    if let Some(v) = take(&d, "min_length")? {
        o.min_length = v;
    }
    if let Some(v) = take(&d, "max_rms")? {
        o.max_rms = v;
    }
    no_leftovers(&d, "segment")?;
    Ok(o)
}

fn polygon_options(py: Python<'_>, opts: Option<&Bound<'_, PyDict>>) -> PyResult<PolygonOptions> {
    let d = opts_copy(py, opts)?;
    let mut o = PolygonOptions::default();
    macro_rules! set {
        ($($k:ident),*) => {$(
            if let Some(v) = take(&d, stringify!($k))? { o.$k = v; }
        )*};
    }
    set!(
        cell,
        rotation_nominal,
        rotation_range,
        rotation_step,
        scale_min,
        scale_max,
        scale_step,
        epsilon,
        min_segment_length,
        support_distance,
        support_angle,
        oriented,
        irls_iterations
    );
    no_leftovers(&d, "polygon")?;
    Ok(o)
}

/// A `(H, W)` uint8 image.
fn gray_image(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<GrayImage> {
    let arr = obj.extract::<PyReadonlyArray2<'_, u8>>().map_err(|_| {
        errors::invalid_input(format!(
            "{name} must be a two-dimensional uint8 NumPy array (H, W)"
        ))
    })?;
    let shape = arr.shape().to_vec();
    let data: Vec<u8> = arr.as_array().iter().copied().collect();
    Ok(GrayImage {
        width: shape[1],
        height: shape[0],
        data,
    })
}

fn segments_arg(obj: &Bound<'_, PyAny>) -> PyResult<Vec<Segment>> {
    let arr = Array::new(obj, "segments")?;
    if arr.shape().len() != 2 || arr.shape()[1] != 4 {
        return Err(errors::invalid_input(format!(
            "segments must have shape (N, 4) [ax, ay, bx, by], got {}",
            convert::shape_str(arr.shape())
        )));
    }
    let (data, _) = arr.batch(&[4], "(N, 4)")?;
    Ok(data
        .chunks_exact(4)
        .map(|c| Segment {
            a: Vector2::new(c[0], c[1]),
            b: Vector2::new(c[2], c[3]),
        })
        .collect())
}

fn segments_array<'py>(py: Python<'py>, s: &[Segment]) -> PyResult<Bound<'py, PyAny>> {
    let data: Vec<f64> = s
        .iter()
        .flat_map(|g| [g.a.x, g.a.y, g.b.x, g.b.y])
        .collect();
    Ok(convert::to_numpy(py, data, &[s.len(), 4])?.into_any())
}

fn matrix3(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Matrix3<f64>> {
    let v = Array::new(obj, name)?.exact(&[3, 3])?;
    Ok(Matrix3::from_row_slice(&v))
}

fn vertices(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<Vector2<f64>>> {
    let arr = Array::new(obj, name)?;
    if arr.shape().len() != 2 || arr.shape()[1] != 2 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (K, 2), got {}",
            convert::shape_str(arr.shape())
        )));
    }
    let (data, _) = arr.batch(&[2], "(K, 2)")?;
    Ok(data
        .chunks_exact(2)
        .map(|c| Vector2::new(c[0], c[1]))
        .collect())
}

/// Line segments of a uint8 image, `(N, 4)` rows `[ax, ay, bx, by]`, dark side on the left.
#[pyfunction]
#[pyo3(signature = (image, options = None))]
fn polygon_detect_segments<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let img = gray_image(image, "image")?;
    let o = segment_options(py, options)?;
    let s = convert::detached(py, || detect_segments(&img, &o).map_err(errors::detect))?;
    segments_array(py, &s)
}

fn detection_dict<'py>(py: Python<'py>, d: &PolygonDetection) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let pose =
        |p: &autoteach_detect::polygon::PolygonPose| (p.centre.x, p.centre.y, p.rotation, p.scale);
    out.set_item("pose", pose(&d.pose))?;
    out.set_item("coarse", pose(&d.coarse))?;
    out.set_item("votes", d.votes)?;
    let sup: Vec<i64> = d
        .support
        .iter()
        .flat_map(|&(j, k)| [j as i64, k as i64])
        .collect();
    let n = d.support.len();
    out.set_item("support", sup.into_pyarray(py).reshape([n, 2])?)?;
    out.set_item("segments", segments_array(py, &d.segments)?)?;
    out.set_item("centre_image", (d.centre_image.x, d.centre_image.y))?;
    out.set_item("rms", d.rms)?;
    let vm = &d.vote_map;
    let map: Vec<f64> = vm.data.iter().map(|&v| v as f64).collect();
    out.set_item("vote_map", convert::to_numpy(py, map, &[vm.rows, vm.cols])?)?;
    out.set_item("vote_map_origin", (vm.origin.x, vm.origin.y))?;
    out.set_item("vote_map_cell", vm.cell)?;
    Ok(out)
}

/// Polygon detection (seed §3.3): `image` (uint8) or `segments` (N, 4), the template `(K, 2)`,
/// the homography (reference plane → image, 3×3). Returns a dict (see the wrapper).
#[pyfunction]
#[pyo3(signature = (template, homography, image = None, segments = None, options = None, segment_options = None))]
#[allow(clippy::too_many_arguments)]
fn polygon_detect<'py>(
    py: Python<'py>,
    template: &Bound<'py, PyAny>,
    homography: &Bound<'py, PyAny>,
    image: Option<&Bound<'py, PyAny>>,
    segments: Option<&Bound<'py, PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
    segment_options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let t = vertices(template, "template")?;
    let h = matrix3(homography, "homography")?;
    let o = polygon_options(py, options)?;
    let so = self::segment_options(py, segment_options)?;
    let det = match (image, segments) {
        (Some(img), None) => {
            let img = gray_image(img, "image")?;
            convert::detached(py, || {
                detect_polygon(PolygonInput::Image(&img, &so), &t, &h, &o).map_err(errors::detect)
            })?
        }
        (None, Some(s)) => {
            let s = segments_arg(s)?;
            convert::detached(py, || {
                detect_polygon(PolygonInput::Segments(&s), &t, &h, &o).map_err(errors::detect)
            })?
        }
        _ => {
            return Err(errors::invalid_input(
                "pass exactly one of image and segments",
            ));
        }
    };
    detection_dict(py, &det)
}

/// Renders a chamber-opening image (uint8, (height, width)). `polygons` and `occluders` are lists
/// of `(vertices (K, 2), intensity)`; `lines` is `(L, 6)` rows `[ax, ay, bx, by, width, intensity]`.
#[pyfunction]
#[pyo3(signature = (width, height, homography, plate, polygons, lines, occluders, supersample = 4, blur_sigma = 0.0, noise_sigma = 0.0, seed = 0))]
#[allow(clippy::too_many_arguments)]
fn polygon_render_opening<'py>(
    py: Python<'py>,
    width: usize,
    height: usize,
    homography: &Bound<'py, PyAny>,
    plate: f64,
    polygons: &Bound<'py, PyList>,
    lines: &Bound<'py, PyAny>,
    occluders: &Bound<'py, PyList>,
    supersample: usize,
    blur_sigma: f64,
    noise_sigma: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyArray2<u8>>> {
    let read_polys = |list: &Bound<'py, PyList>,
                      name: &'static str|
     -> PyResult<Vec<(Vec<Vector2<f64>>, f64)>> {
        list.iter()
            .map(|item| {
                let (v, i): (Bound<'py, PyAny>, f64) = item.extract().map_err(|_| {
                    errors::invalid_input(format!("{name} items must be (vertices, intensity)"))
                })?;
                Ok((vertices(&v, name)?, i))
            })
            .collect()
    };
    let la = Array::new(lines, "lines")?;
    let (ld, _) = la.batch(&[6], "(L, 6)")?;
    if la.shape().len() != 2 {
        return Err(errors::invalid_input(format!(
            "lines must have shape (L, 6), got {}",
            convert::shape_str(la.shape())
        )));
    }
    let scene = OpeningScene {
        width,
        height,
        homography: matrix3(homography, "homography")?,
        plate,
        polygons: read_polys(polygons, "polygons")?
            .into_iter()
            .map(|(vertices, intensity)| RefPolygon {
                vertices,
                intensity,
            })
            .collect(),
        lines: ld
            .chunks_exact(6)
            .map(|c| ImageLine {
                a: Vector2::new(c[0], c[1]),
                b: Vector2::new(c[2], c[3]),
                width: c[4],
                intensity: c[5],
            })
            .collect(),
        occluders: read_polys(occluders, "occluders")?
            .into_iter()
            .map(|(vertices, intensity)| ImagePolygon {
                vertices,
                intensity,
            })
            .collect(),
        supersample,
        blur_sigma,
        noise_sigma,
        seed,
    };
    let img = convert::detached(py, || render_opening(&scene).map_err(errors::geometry))?;
    let arr = img.data.into_pyarray(py).reshape([img.height, img.width])?;
    Ok(arr)
}

/// Adds the polygon and voting functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(polygon_global_voting, m)?)?;
    m.add_function(wrap_pyfunction!(polygon_vote_cells, m)?)?;
    m.add_function(wrap_pyfunction!(polygon_detect_segments, m)?)?;
    m.add_function(wrap_pyfunction!(polygon_detect, m)?)?;
    m.add_function(wrap_pyfunction!(polygon_render_opening, m)?)?;
    Ok(())
}

//! Bindings of `autoteach_detect::fusion`: the sparse non-homogeneous pooling layer (SHPL) and
//! non-zero max-min pooling. Feature maps are `float32` or `float64`, C-contiguous,
//! channels-last; they are read in place (no copy) and results are handed to NumPy without a
//! copy. The friendly wrappers live in `python/autoteach/fusion.py`.

use autoteach_detect::fusion::Feature;
use autoteach_detect::fusion::maxmin::{maxmin_pool, maxmin_pool_backward, output_shape};
use autoteach_detect::fusion::shpl::{BevGrid, Direction, ImageGrid, SparsePooling};
use numpy::{
    Element, IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{self, detached, to_numpy};
use crate::errors;

/// Registers the class and functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySparsePooling>()?;
    m.add_function(wrap_pyfunction!(fusion_maxmin_pool, m)?)?;
    m.add_function(wrap_pyfunction!(fusion_maxmin_pool_backward, m)?)?;
    Ok(())
}

fn direction(s: &str) -> PyResult<Direction> {
    match s {
        "image_to_bev" => Ok(Direction::ImageToBev),
        "bev_to_image" => Ok(Direction::BevToImage),
        _ => Err(errors::invalid_input(format!(
            "direction must be \"image_to_bev\" or \"bev_to_image\", got {s:?}"
        ))),
    }
}

/// A float32 or float64 array, borrowed in place.
enum Feat<'py> {
    F32(PyReadonlyArrayDyn<'py, f32>),
    F64(PyReadonlyArrayDyn<'py, f64>),
}

impl<'py> Feat<'py> {
    fn new(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Self> {
        if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'py, f32>>() {
            return Ok(Feat::F32(a));
        }
        if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'py, f64>>() {
            return Ok(Feat::F64(a));
        }
        let dt = obj
            .getattr("dtype")
            .map(|d| d.to_string())
            .unwrap_or_else(|_| "not an array".into());
        Err(errors::invalid_input(format!(
            "{name} must be a float32 or float64 NumPy array, got {dt}"
        )))
    }

    fn shape(&self) -> Vec<usize> {
        match self {
            Feat::F32(a) => a.shape().to_vec(),
            Feat::F64(a) => a.shape().to_vec(),
        }
    }
}

/// The contiguous data of `a` (finiteness unchecked: the SHPL product checks it itself, fused
/// with the gather, so the features are not read twice).
fn contiguous<'a, T: Element>(a: &'a PyReadonlyArrayDyn<'_, T>, name: &str) -> PyResult<&'a [T]> {
    a.as_slice().map_err(|_| {
        errors::invalid_input(format!(
            "{name} must be C-contiguous (use numpy.ascontiguousarray)"
        ))
    })
}

/// The contiguous data of `a`, checked finite.
fn slice<'a, T: Element + Feature>(
    a: &'a PyReadonlyArrayDyn<'_, T>,
    name: &str,
) -> PyResult<&'a [T]> {
    let s = contiguous(a, name)?;
    // A branch-free pass per chunk (vectorised) first; the index is searched only on failure.
    let finite = s
        .chunks(4096)
        .all(|c| c.iter().fold(true, |ok, v| ok & v.to_f64().is_finite()));
    if finite {
        return Ok(s);
    }
    if let Some((i, v)) = s.iter().enumerate().find(|(_, v)| !v.to_f64().is_finite()) {
        return Err(errors::invalid_input(format!(
            "{name} must be finite, got {v:?} at flat index {i}"
        )));
    }
    Ok(s)
}

/// A kernel as NumPy CSR arrays: `(indptr, indices, data, (rows, cols))`.
type CsrArrays<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyArrayDyn<f64>>,
    (usize, usize),
);

/// The SHPL operator for one point cloud.
#[pyclass(name = "FusionSparsePooling", module = "autoteach._core", frozen)]
pub struct PySparsePooling {
    inner: SparsePooling,
}

impl PySparsePooling {
    fn run<'py>(
        &self,
        py: Python<'py>,
        dir: &str,
        x: &Bound<'py, PyAny>,
        name: &str,
        backward: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let dir = direction(dir)?;
        let (nin, nout) = self.inner.shape(dir);
        let (nin, nout) = if backward { (nout, nin) } else { (nin, nout) };
        let f = Feat::new(x, name)?;
        let shape = f.shape();
        if shape.len() != 2 || shape[0] != nin {
            return Err(errors::invalid_input(format!(
                "{name} must have shape ({nin}, channels), got {}",
                convert::shape_str(&shape)
            )));
        }
        let ch = shape[1];
        #[allow(clippy::too_many_arguments)]
        fn go<'py, T: Element + Feature>(
            py: Python<'py>,
            op: &SparsePooling,
            dir: Direction,
            a: &PyReadonlyArrayDyn<'py, T>,
            name: &str,
            nout: usize,
            ch: usize,
            backward: bool,
        ) -> PyResult<Bound<'py, PyAny>> {
            let s = contiguous(a, name)?;
            let out = detached(py, || {
                let n = nout.checked_mul(ch).ok_or_else(|| {
                    errors::invalid_input(format!("{nout} cells × {ch} channels overflow"))
                })?;
                // A new buffer is written once by the product, without a zeroing pass first.
                let mut out: Vec<T> = Vec::with_capacity(n);
                let slots = &mut out.spare_capacity_mut()[..n];
                if backward {
                    op.backward_uninit(dir, s, ch, slots)
                } else {
                    op.forward_uninit(dir, s, ch, slots)
                }
                .map_err(errors::detect)?;
                // SAFETY: `out` has capacity `n`, and on `Ok` `forward_uninit`/`backward_uninit`
                // have written every one of its first `n` elements.
                unsafe { out.set_len(n) };
                Ok(out)
            })?;
            let arr = out.into_pyarray(py);
            Ok(arr.reshape([nout, ch])?.into_any())
        }
        match &f {
            Feat::F32(a) => go(py, &self.inner, dir, a, name, nout, ch, backward),
            Feat::F64(a) => go(py, &self.inner, dir, a, name, nout, ch, backward),
        }
    }
}

#[pymethods]
impl PySparsePooling {
    /// Builds the operator: `points (n, 3)`, `projection (3, 4)`, `image_grid = (rows, cols,
    /// stride)`, `bev_grid = (x_min, y_min, cell, nx, ny)`, odd `neighbourhood`.
    #[staticmethod]
    #[pyo3(signature = (points, projection, image_grid, bev_grid, neighbourhood=1))]
    fn build(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        projection: &Bound<'_, PyAny>,
        image_grid: (usize, usize, f64),
        bev_grid: (f64, f64, f64, usize, usize),
        neighbourhood: usize,
    ) -> PyResult<Self> {
        let a = convert::finite_array(points, "points")?;
        let (data, lead) = a.batch(&[3], "(n, 3)")?;
        if lead.len() != 1 {
            return Err(errors::invalid_input(format!(
                "points must have shape (n, 3), got {}",
                convert::shape_str(a.shape())
            )));
        }
        let pts: Vec<[f64; 3]> = data.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
        let pm = convert::finite_array(projection, "P")?.exact(&[3, 4])?;
        let p = [
            [pm[0], pm[1], pm[2], pm[3]],
            [pm[4], pm[5], pm[6], pm[7]],
            [pm[8], pm[9], pm[10], pm[11]],
        ];
        // The grids' own errors name their fields (`cell`, `stride`): prefix the argument.
        let ig = ImageGrid::new(image_grid.0, image_grid.1, image_grid.2)
            .map_err(|e| errors::invalid_input(format!("image_grid: {e}")))?;
        let bg = BevGrid::new(bev_grid.0, bev_grid.1, bev_grid.2, bev_grid.3, bev_grid.4)
            .map_err(|e| errors::invalid_input(format!("bev_grid: {e}")))?;
        let inner = detached(py, || {
            SparsePooling::build(&pts, &p, ig, bg, neighbourhood).map_err(errors::detect)
        })?;
        Ok(Self { inner })
    }

    /// Pools `features (input cells, channels)` in `direction`.
    fn forward<'py>(
        &self,
        py: Python<'py>,
        direction: &str,
        features: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.run(py, direction, features, "features", false)
    }

    /// Gradient with respect to the input of `forward`, given `grad (output cells, channels)`.
    fn backward<'py>(
        &self,
        py: Python<'py>,
        direction: &str,
        grad: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.run(py, direction, grad, "grad", true)
    }

    /// The kernel of `direction` as CSR arrays `(indptr, indices, data, (rows, cols))`.
    fn csr<'py>(&self, py: Python<'py>, direction: &str) -> PyResult<CsrArrays<'py>> {
        let k = self.inner.kernel(self::direction(direction)?);
        let ip: Vec<i64> = k.indptr.iter().map(|v| *v as i64).collect();
        let ix: Vec<i64> = k.indices.iter().map(|v| *v as i64).collect();
        Ok((
            ip.into_pyarray(py).into_any(),
            ix.into_pyarray(py).into_any(),
            to_numpy(py, k.data.clone(), &[k.data.len()])?,
            (k.rows, k.cols),
        ))
    }

    /// The dense kernel of `direction` (output cells × input cells).
    fn dense<'py>(
        &self,
        py: Python<'py>,
        direction: &str,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let k = self.inner.kernel(self::direction(direction)?);
        to_numpy(py, k.to_dense(), &[k.rows, k.cols])
    }

    /// Number of points kept.
    #[getter]
    fn kept(&self) -> usize {
        self.inner.kept
    }

    /// Points dropped: `{"behind": …, "outside_image": …, "outside_bev": …}`.
    #[getter]
    fn dropped<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("behind", self.inner.dropped.behind)?;
        d.set_item("outside_image", self.inner.dropped.outside_image)?;
        d.set_item("outside_bev", self.inner.dropped.outside_bev)?;
        Ok(d)
    }

    /// `(image cells, bev cells)`.
    #[getter]
    fn cells(&self) -> (usize, usize) {
        (self.inner.image.len(), self.inner.bev.len())
    }
}

fn hwc(shape: &[usize], name: &str) -> PyResult<(usize, usize, usize)> {
    if shape.len() != 3 {
        return Err(errors::invalid_input(format!(
            "{name} must have shape (h, w, c), got {}",
            convert::shape_str(shape)
        )));
    }
    Ok((shape[0], shape[1], shape[2]))
}

/// Non-zero max-min pooling of `x (h, w, c)` → `(⌈h/2⌉, ⌈w/2⌉, 2c)`.
#[pyfunction]
fn fusion_maxmin_pool<'py>(py: Python<'py>, x: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let f = Feat::new(x, "x")?;
    let (h, w, c) = hwc(&f.shape(), "x")?;
    let (oh, ow, oc) = output_shape(h, w, c);
    fn go<'py, T: Element + Feature>(
        py: Python<'py>,
        a: &PyReadonlyArrayDyn<'py, T>,
        h: usize,
        w: usize,
        c: usize,
        o: [usize; 3],
    ) -> PyResult<Bound<'py, PyAny>> {
        let s = slice(a, "x")?;
        let out = detached(py, || maxmin_pool(s, h, w, c).map_err(errors::detect))?;
        Ok(out.into_pyarray(py).reshape(o)?.into_any())
    }
    match &f {
        Feat::F32(a) => go(py, a, h, w, c, [oh, ow, oc]),
        Feat::F64(a) => go(py, a, h, w, c, [oh, ow, oc]),
    }
}

/// Gradient of [`fusion_maxmin_pool`] with respect to `x`, given `grad_out`.
#[pyfunction]
fn fusion_maxmin_pool_backward<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    grad_out: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let f = Feat::new(x, "x")?;
    let g = Feat::new(grad_out, "grad_out")?;
    let (h, w, c) = hwc(&f.shape(), "x")?;
    let (oh, ow, oc) = output_shape(h, w, c);
    if g.shape() != [oh, ow, oc] {
        return Err(errors::invalid_input(format!(
            "grad_out must have shape ({oh}, {ow}, {oc}), got {}",
            convert::shape_str(&g.shape())
        )));
    }
    fn go<'py, T: Element + Feature>(
        py: Python<'py>,
        a: &PyReadonlyArrayDyn<'py, T>,
        g: &PyReadonlyArrayDyn<'py, T>,
        h: usize,
        w: usize,
        c: usize,
    ) -> PyResult<Bound<'py, PyAny>> {
        let s = slice(a, "x")?;
        let gs = slice(g, "grad_out")?;
        let out = detached(py, || {
            maxmin_pool_backward(s, h, w, c, gs).map_err(errors::detect)
        })?;
        Ok(out.into_pyarray(py).reshape([h, w, c])?.into_any())
    }
    match (&f, &g) {
        (Feat::F32(a), Feat::F32(b)) => go(py, a, b, h, w, c),
        (Feat::F64(a), Feat::F64(b)) => go(py, a, b, h, w, c),
        _ => Err(errors::invalid_input(
            "x and grad_out must have the same dtype",
        )),
    }
}

//! The checks behind [`crate::convert`], free of Python: shapes, finiteness and rigid
//! transforms of ndarray views of any layout.
//!
//! Each function returns the message of the `InvalidInputError` that `convert` raises (naming the
//! argument and the expected shape), so the checks can be exercised by a plain `cargo test`,
//! without an interpreter: the bounded fuzz loop at the end of this file drives them with random
//! shapes, strides (reversed, stepped, transposed views), NaN, infinities and huge values.

/// A shape as Python prints it: `(3,)`, `(2, 2)`, `()` (the core's messages use the same).
pub use autoteach_estimate::error::shape_str;
use autoteach_geometry::error::Num;
use numpy::ndarray::{ArrayViewD, Dimension};

/// The multi-index and value of the first non-finite element in row-major (logical) order.
pub fn first_non_finite(view: &ArrayViewD<'_, f64>) -> Option<(Vec<usize>, f64)> {
    // Fast path over contiguous memory; the (slower) indexed walk only runs to report.
    let all_finite = match view.as_slice() {
        Some(s) => s.iter().all(|v| v.is_finite()),
        None => view.iter().all(|v| v.is_finite()),
    };
    if all_finite {
        return None;
    }
    view.indexed_iter()
        .find(|(_, v)| !v.is_finite())
        .map(|(idx, v)| (idx.slice().to_vec(), *v))
}

/// `Ok` when every element is finite; else the message naming `name`, the value and its index.
pub fn finite(view: &ArrayViewD<'_, f64>, name: &str) -> Result<(), String> {
    match first_non_finite(view) {
        None => Ok(()),
        Some((idx, v)) => Err(format!("{name} must be finite, got {v} at index {idx:?}")),
    }
}

/// The elements in row-major (logical) order, whatever the strides.
fn row_major(view: &ArrayViewD<'_, f64>) -> Vec<f64> {
    match view.as_slice() {
        // C-contiguous: one copy.
        Some(s) => s.to_vec(),
        // `iter` walks the logical (row-major) order whatever the strides.
        None => view.iter().copied().collect(),
    }
}

/// Shape `(..., n)`: the rows (leading dimensions flattened) and the leading shape.
pub fn rows(
    view: &ArrayViewD<'_, f64>,
    name: &str,
    n: usize,
    expected: &str,
) -> Result<(Vec<Vec<f64>>, Vec<usize>), String> {
    let shape = view.shape();
    if shape.is_empty() || shape[shape.len() - 1] != n {
        return Err(format!(
            "{name} must have shape {expected}, got {}",
            shape_str(shape)
        ));
    }
    let lead = shape[..shape.len() - 1].to_vec();
    let data = row_major(view);
    // `n == 0`: as many empty rows as the leading shape holds.
    let count: usize = lead.iter().product();
    let rows = if n == 0 {
        vec![Vec::new(); count]
    } else {
        data.chunks_exact(n).map(<[f64]>::to_vec).collect()
    };
    Ok((rows, lead))
}

/// Exactly `shape`: the elements in row-major order.
pub fn exact(view: &ArrayViewD<'_, f64>, name: &str, shape: &[usize]) -> Result<Vec<f64>, String> {
    if view.shape() != shape {
        return Err(format!(
            "{name} must have shape {}, got {}",
            shape_str(shape),
            shape_str(view.shape())
        ));
    }
    Ok(row_major(view))
}

/// One-dimensional: the elements.
pub fn vector(view: &ArrayViewD<'_, f64>, name: &str) -> Result<Vec<f64>, String> {
    if view.ndim() != 1 {
        return Err(format!(
            "{name} must be one-dimensional, got shape {}",
            shape_str(view.shape())
        ));
    }
    Ok(view.iter().copied().collect())
}

/// Shape `(..., *item)`: the elements in row-major order and the leading shape.
pub fn batch(
    view: &ArrayViewD<'_, f64>,
    name: &str,
    item: &[usize],
    expected: &str,
) -> Result<(Vec<f64>, Vec<usize>), String> {
    let shape = view.shape();
    if shape.len() < item.len() || shape[shape.len() - item.len()..] != *item {
        return Err(format!(
            "{name} must have shape {expected}, got {}",
            shape_str(shape)
        ));
    }
    Ok((row_major(view), shape[..shape.len() - item.len()].to_vec()))
}

/// Tolerance on `|RᵀR − I|` (Frobenius) for a matrix accepted as a rotation.
pub const ROTATION_TOL: f64 = 1e-6;

/// `|RᵀR − I|` (Frobenius); NaN when `RᵀR` overflows.
fn orthonormality_defect(r: &nalgebra::Matrix3<f64>) -> f64 {
    (r.transpose() * r - nalgebra::Matrix3::identity()).norm()
}

/// A 3×3 matrix as a rotation, refusing matrices that are not orthonormal with determinant +1
/// (to [`ROTATION_TOL`]); NaN or overflowing entries are refused too.
pub fn rotation(
    r: &nalgebra::Matrix3<f64>,
    name: &str,
) -> Result<nalgebra::Rotation3<f64>, String> {
    let orth = orthonormality_defect(r);
    // Written so that NaN fails: a huge matrix overflows RᵀR to NaN, which must not pass.
    let is_rotation = orth <= ROTATION_TOL && r.determinant() > 0.0;
    if !is_rotation {
        return Err(format!(
            "{name} is not a rotation matrix (|RᵀR − I| = {orth:.3e}, det R = {}, largest |entry| {:.3e})",
            Num(r.determinant()),
            r.amax()
        ));
    }
    // Re-orthonormalise so tiny input errors do not leak into the core.
    Ok(nalgebra::Rotation3::from_matrix(r))
}

/// A 4×4 homogeneous matrix as an isometry, refusing non-rigid matrices (see [`rotation`]).
pub fn isometry(
    m: &nalgebra::Matrix4<f64>,
    name: &str,
) -> Result<nalgebra::Isometry3<f64>, String> {
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let orth = orthonormality_defect(&r);
    let last_ok =
        (m[(3, 0)].abs() + m[(3, 1)].abs() + m[(3, 2)].abs() + (m[(3, 3)] - 1.0).abs()) <= 1e-9;
    // Written so that NaN fails (see `rotation`).
    let is_rigid = orth <= ROTATION_TOL && r.determinant() > 0.0 && last_ok;
    if !is_rigid {
        return Err(format!(
            "{name} is not a rigid transform (|RᵀR − I| = {orth:.3e}, det R = {}, largest |Rᵢⱼ| {:.3e}, last row [{}, {}, {}, {}])",
            Num(r.determinant()),
            r.amax(),
            Num(m[(3, 0)]),
            Num(m[(3, 1)]),
            Num(m[(3, 2)]),
            Num(m[(3, 3)])
        ));
    }
    let rot = nalgebra::Rotation3::from_matrix(&r);
    let t = nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Ok(nalgebra::Isometry3::from_parts(
        t,
        nalgebra::UnitQuaternion::from_rotation_matrix(&rot),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use numpy::ndarray::{ArrayD, Axis, IxDyn, Slice};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    /// A hostile element: mostly ordinary, sometimes NaN, ±inf, huge, tiny or subnormal.
    fn element(rng: &mut Pcg64Mcg) -> f64 {
        match rng.random_range(0..12) {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => f64::MAX,
            4 => -1e300,
            5 => 5e-324,
            6 => -0.0,
            _ => rng.random_range(-10.0..10.0),
        }
    }

    /// The row-major elements of `view`, computed independently: by walking every multi-index.
    fn reference(view: &ArrayViewD<'_, f64>) -> Vec<f64> {
        let shape = view.shape().to_vec();
        let n: usize = shape.iter().product();
        let mut out = Vec::with_capacity(n);
        let mut idx = vec![0usize; shape.len()];
        for _ in 0..n {
            out.push(view[IxDyn(&idx)]);
            for k in (0..shape.len()).rev() {
                idx[k] += 1;
                if idx[k] < shape[k] {
                    break;
                }
                idx[k] = 0;
            }
        }
        out
    }

    fn same_bits(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    /// Bounded fuzz loop over every check: random shapes (empty axes included), layouts and
    /// values. Each result is compared with an independent truth (the multi-index walk); no
    /// input may panic.
    #[test]
    fn fuzz_validation_of_random_shapes_strides_and_values() {
        let mut rng = Pcg64Mcg::seed_from_u64(38);
        let mut checked = [0usize; 5];
        for _ in 0..3000 {
            let ndim = rng.random_range(0..5);
            let shape: Vec<usize> = (0..ndim).map(|_| rng.random_range(0..5)).collect();
            // A parent twice as large along every axis, so stepped views stay in bounds.
            let parent_shape: Vec<usize> = shape.iter().map(|n| 2 * n).collect();
            let size: usize = parent_shape.iter().product();
            let data: Vec<f64> = (0..size).map(|_| element(&mut rng)).collect();
            let parent = ArrayD::from_shape_vec(IxDyn(&parent_shape), data).unwrap();
            let mut view = parent.view();
            for (k, &n) in shape.iter().enumerate() {
                let slice = match rng.random_range(0..3) {
                    0 => Slice::from(0..n),
                    1 => Slice::from(0..2 * n).step_by(2),
                    _ => Slice::from(n..2 * n).step_by(-1),
                };
                view.slice_axis_inplace(Axis(k), slice);
            }
            if ndim > 1 && rng.random_bool(0.3) {
                view = view.reversed_axes();
            }
            let truth = reference(&view);
            let name = "arg";

            // finite: Ok iff every element is finite; the error names the first bad index.
            match (
                finite(&view, name),
                truth.iter().position(|v| !v.is_finite()),
            ) {
                (Ok(()), None) => {}
                (Err(msg), Some(_)) => {
                    assert!(msg.starts_with("arg must be finite, got"), "{msg}");
                    let (idx, _) = first_non_finite(&view).unwrap();
                    let first = view.indexed_iter().find(|(_, v)| !v.is_finite()).unwrap();
                    assert_eq!(idx, first.0.slice());
                    checked[0] += 1;
                }
                (got, want) => panic!(
                    "finite({:?}) = {got:?}, first non-finite {want:?}",
                    view.shape()
                ),
            }

            // batch, with an item shape that may or may not match the tail.
            let k = rng.random_range(0..=view.ndim().min(3));
            let mut item: Vec<usize> = view.shape()[view.ndim() - k..].to_vec();
            if !item.is_empty() && rng.random_bool(0.3) {
                item[0] += 1;
            }
            let tail_ok = view.shape().ends_with(&item);
            match batch(&view, name, &item, "(..., item)") {
                Ok((data, lead)) => {
                    assert!(tail_ok);
                    assert!(same_bits(&data, &truth));
                    assert_eq!(lead, view.shape()[..view.ndim() - item.len()]);
                    checked[1] += 1;
                }
                Err(msg) => assert!(!tail_ok && msg.starts_with("arg must have shape"), "{msg}"),
            }

            // exact, against the true shape or a perturbed one.
            let mut want = view.shape().to_vec();
            if !want.is_empty() && rng.random_bool(0.4) {
                want[0] = rng.random_range(0..5);
            }
            match exact(&view, name, &want) {
                Ok(data) => {
                    assert_eq!(view.shape(), want.as_slice());
                    assert!(same_bits(&data, &truth));
                    checked[2] += 1;
                }
                Err(msg) => {
                    assert!(view.shape() != want.as_slice() && msg.contains("must have shape"))
                }
            }

            // rows and vector.
            let n = view.shape().last().copied().unwrap_or(0);
            let n = if rng.random_bool(0.2) { n + 1 } else { n };
            match rows(&view, name, n, "(..., n)") {
                Ok((r, lead)) => {
                    assert_eq!(view.shape().last(), Some(&n));
                    assert_eq!(r.len(), lead.iter().product::<usize>());
                    assert!(same_bits(&r.concat(), &truth));
                    checked[3] += 1;
                }
                Err(msg) => {
                    assert!(view.shape().last() != Some(&n) && msg.contains("must have shape"))
                }
            }
            match vector(&view, name) {
                Ok(v) => {
                    assert_eq!(view.ndim(), 1);
                    assert!(same_bits(&v, &truth));
                    checked[4] += 1;
                }
                Err(msg) => assert!(view.ndim() != 1 && msg.contains("one-dimensional")),
            }
        }
        // Every branch was reached on both sides.
        assert!(checked.iter().all(|&c| c > 50), "{checked:?}");
    }

    /// Random 3×3 and 4×4 matrices: proper rotations (exact and perturbed), scaled by huge
    /// factors, with NaN or infinite entries. Accepted iff orthonormal with det +1 (truth: the
    /// construction), and never with a non-finite result.
    #[test]
    fn fuzz_rotations_and_rigid_transforms() {
        let mut rng = Pcg64Mcg::seed_from_u64(3838);
        for _ in 0..3000 {
            let axis = nalgebra::Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let base = nalgebra::Rotation3::new(axis * 3.0).into_inner();
            let (m, proper) = match rng.random_range(0..6) {
                0 => (base, true),
                1 => (base * rng.random_range(2.0..1e300), false),
                2 => (-base, false),
                3 => {
                    let mut b = base;
                    b[(rng.random_range(0..3), rng.random_range(0..3))] = element(&mut rng);
                    let ok = orthonormality_defect(&b) <= ROTATION_TOL && b.determinant() > 0.0;
                    (b, ok)
                }
                4 => (base * 1e200, false),
                _ => (base + nalgebra::Matrix3::from_element(1e-3), false),
            };
            match rotation(&m, "R") {
                Ok(r) => {
                    assert!(proper, "accepted {m}");
                    assert!(r.matrix().iter().all(|v| v.is_finite()));
                }
                Err(msg) => assert!(
                    !proper && msg.starts_with("R is not a rotation matrix"),
                    "{msg}"
                ),
            }
            let mut t = nalgebra::Matrix4::identity();
            t.fixed_view_mut::<3, 3>(0, 0).copy_from(&m);
            t[(0, 3)] = rng.random_range(-5.0..5.0);
            let last_row_ok = rng.random_bool(0.8);
            if !last_row_ok {
                t[(3, rng.random_range(0..4))] = element(&mut rng) + 0.5;
            }
            let rigid = proper
                && t.row(3)
                    .iter()
                    .zip([0.0, 0.0, 0.0, 1.0])
                    .all(|(a, b)| *a == b);
            match isometry(&t, "T") {
                Ok(iso) => {
                    assert!(rigid, "accepted {t}");
                    assert!(iso.to_homogeneous().iter().all(|v| v.is_finite()));
                }
                Err(msg) => assert!(
                    !rigid && msg.starts_with("T is not a rigid transform"),
                    "{msg}"
                ),
            }
        }
    }
}

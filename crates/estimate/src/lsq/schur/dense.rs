//! Dense kernels of the small per-point blocks of the Schur complement: Cholesky of a d × d
//! block, its forward and backward substitutions, and a dot product.

/// In-place Cholesky of a small d × d column-major matrix (lower triangle); `Err(k)` at the
/// first non-positive (or NaN) pivot k.
pub(super) fn small_cholesky(a: &mut [f64], d: usize) -> std::result::Result<(), usize> {
    for j in 0..d {
        let mut s = a[j * d + j];
        for k in 0..j {
            s -= a[k * d + j] * a[k * d + j];
        }
        if s.is_nan() || s <= 0.0 {
            return Err(j);
        }
        let s = s.sqrt();
        a[j * d + j] = s;
        for i in j + 1..d {
            let mut v = a[j * d + i];
            for k in 0..j {
                v -= a[k * d + i] * a[k * d + j];
            }
            a[j * d + i] = v / s;
        }
    }
    Ok(())
}

/// Solves L x = b in place (L lower, d × d column-major).
pub(super) fn forward(l: &[f64], d: usize, x: &mut [f64]) {
    for i in 0..d {
        let mut v = x[i];
        for k in 0..i {
            v -= l[k * d + i] * x[k];
        }
        x[i] = v / l[i * d + i];
    }
}

/// Solves Lᵀ x = b in place.
pub(super) fn backward(l: &[f64], d: usize, x: &mut [f64]) {
    for i in (0..d).rev() {
        let mut v = x[i];
        for k in i + 1..d {
            v -= l[i * d + k] * x[k];
        }
        x[i] = v / l[i * d + i];
    }
}

/// Σ aᵢ bᵢ.
#[inline(always)]
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

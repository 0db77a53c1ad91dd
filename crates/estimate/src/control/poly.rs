//! Real polynomials in descending powers (`c[0] sⁿ + … + c[n]`, NumPy's convention), the
//! arithmetic that transfer functions (ch. 2.5 of 000_3b1454b2b2194811.txt) are built from.

use nalgebra::{Complex, DMatrix, Schur};

/// Complex numbers used for frequency responses.
pub type C64 = Complex<f64>;

/// Removes leading zeros (keeps one coefficient for the zero polynomial).
pub fn trim(p: &[f64]) -> Vec<f64> {
    let first = p
        .iter()
        .position(|&c| c != 0.0)
        .unwrap_or(p.len().saturating_sub(1));
    if p.is_empty() {
        return vec![0.0];
    }
    p[first..].to_vec()
}

/// Degree of a trimmed polynomial (0 for constants, including zero).
pub fn degree(p: &[f64]) -> usize {
    trim(p).len() - 1
}

/// Evaluates `p(s)` at a complex point by Horner's rule.
pub fn eval(p: &[f64], s: C64) -> C64 {
    p.iter().fold(C64::new(0.0, 0.0), |acc, &c| acc * s + c)
}

/// Evaluates `p(x)` at a real point.
pub fn eval_real(p: &[f64], x: f64) -> f64 {
    p.iter().fold(0.0, |acc, &c| acc * x + c)
}

/// Product `a · b`.
pub fn mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    if a.is_empty() || b.is_empty() {
        return vec![0.0];
    }
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, &x) in a.iter().enumerate() {
        for (j, &y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// Sum `a + b` (aligned at the constant term).
pub fn add(a: &[f64], b: &[f64]) -> Vec<f64> {
    let n = a.len().max(b.len());
    let mut out = vec![0.0; n];
    for (i, &x) in a.iter().rev().enumerate() {
        out[n - 1 - i] += x;
    }
    for (i, &y) in b.iter().rev().enumerate() {
        out[n - 1 - i] += y;
    }
    out
}

/// Scales every coefficient by `k`.
pub fn scale(a: &[f64], k: f64) -> Vec<f64> {
    a.iter().map(|&x| x * k).collect()
}

/// Derivative `p'`.
pub fn deriv(p: &[f64]) -> Vec<f64> {
    let n = p.len();
    if n <= 1 {
        return vec![0.0];
    }
    p[..n - 1]
        .iter()
        .enumerate()
        .map(|(i, &c)| c * (n - 1 - i) as f64)
        .collect()
}

/// The monic real polynomial with the given roots (complex roots must come in conjugate
/// pairs; the imaginary residue of the expansion is dropped).
pub fn from_roots(roots: &[C64]) -> Vec<f64> {
    let mut c = vec![C64::new(1.0, 0.0)];
    for r in roots {
        let mut next = vec![C64::new(0.0, 0.0); c.len() + 1];
        for (i, &x) in c.iter().enumerate() {
            next[i] += x;
            next[i + 1] -= x * r;
        }
        c = next;
    }
    c.iter().map(|z| z.re).collect()
}

/// All complex roots of `p`, as the eigenvalues of its companion matrix (what `numpy.roots`
/// computes), each polished by two Newton steps on `p`.
pub fn roots(p: &[f64]) -> Vec<C64> {
    let p = trim(p);
    let mut trailing = 0;
    let mut q = p.clone();
    while q.len() > 1 && q[q.len() - 1] == 0.0 {
        q.pop();
        trailing += 1;
    }
    let n = q.len() - 1;
    let mut out = vec![C64::new(0.0, 0.0); trailing];
    if n == 0 {
        return out;
    }
    // Roots of q(ω0 ŝ) with ω0 = |q_n/q_0|^{1/n}, the geometric mean of the root magnitudes:
    // keeps the companion matrix of resonant models (roots from 1 to 10⁴) near unit scale.
    let w0 = {
        let r = (q[n] / q[0]).abs().powf(1.0 / n as f64);
        if r.is_finite() && r > 0.0 { r } else { 1.0 }
    };
    let mut comp = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        comp[(0, j)] = -q[j + 1] / q[0] / w0.powi(j as i32 + 1);
    }
    for i in 1..n {
        comp[(i, i - 1)] = 1.0;
    }
    let dq = deriv(&q);
    // nalgebra's `complex_eigenvalues` runs the QR iteration without an iteration cap and
    // never returns on some companion matrices (regression test
    // `roots_of_a_companion_matrix_nalgebra_does_not_converge_on`): cap it, and fall back to
    // the Aberth–Ehrlich iteration on the scaled polynomial if the Schur form does not converge.
    let scaled = match Schur::try_new(comp, f64::EPSILON, 200 * n) {
        Some(schur) => schur.complex_eigenvalues().iter().copied().collect(),
        None => aberth(&q, w0),
    };
    for r in scaled.iter() {
        let r = *r * w0;
        let mut z = r;
        for _ in 0..2 {
            let d = eval(&dq, z);
            if d.norm() > 0.0 {
                let step = eval(&q, z) / d;
                let cand = z - step;
                if eval(&q, cand).norm() <= eval(&q, z).norm() {
                    z = cand;
                }
            }
        }
        if r.im == 0.0 {
            z.im = 0.0;
        }
        out.push(z);
    }
    out
}

/// Roots of `q` divided by `w0` (the roots of `q(w0 ŝ)`) by the Aberth–Ehrlich simultaneous
/// iteration, started on a circle of radius 1 off the real axis; used when the companion
/// eigen-solve does not converge.
fn aberth(q: &[f64], w0: f64) -> Vec<C64> {
    let n = q.len() - 1;
    // Coefficients of q(w0 ŝ) / q[0], still in descending powers.
    let qs: Vec<f64> = q
        .iter()
        .enumerate()
        .map(|(k, &c)| c / q[0] * w0.powi((n - k) as i32))
        .collect();
    let dqs = deriv(&qs);
    let mut z: Vec<C64> = (0..n)
        .map(|k| {
            C64::from_polar(
                1.0,
                (2.0 * std::f64::consts::PI * k as f64 + 0.4) / n as f64,
            )
        })
        .collect();
    for _ in 0..500 {
        let mut moved = 0.0f64;
        for i in 0..n {
            let ratio = eval(&qs, z[i]) / eval(&dqs, z[i]);
            let repulsion: C64 = (0..n)
                .filter(|&j| j != i)
                .map(|j| C64::new(1.0, 0.0) / (z[i] - z[j]))
                .sum();
            let step = ratio / (C64::new(1.0, 0.0) - ratio * repulsion);
            if step.re.is_finite() && step.im.is_finite() {
                z[i] -= step;
                moved = moved.max(step.norm() / z[i].norm().max(1.0));
            }
        }
        if moved < 1e-15 {
            break;
        }
    }
    // Real roots come back with a rounding-level imaginary part: snap them, as the
    // companion eigen-solve reports real eigenvalues exactly.
    for r in z.iter_mut() {
        if r.im.abs() <= 1e-12 * r.norm().max(1.0) {
            r.im = 0.0;
        }
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_product_are_the_factors() {
        let p = from_roots(&[
            C64::new(-1.0, 2.0),
            C64::new(-1.0, -2.0),
            C64::new(-3.0, 0.0),
        ]);
        let mut r = roots(&p);
        r.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        assert!((r[0] - C64::new(-3.0, 0.0)).norm() < 1e-12);
        assert!((r[1] - C64::new(-1.0, -2.0)).norm() < 1e-12);
        assert!((r[2] - C64::new(-1.0, 2.0)).norm() < 1e-12);
        assert_eq!(roots(&[1.0, 0.0, 0.0]).len(), 2);
    }

    #[test]
    fn arithmetic_matches_hand_expansion() {
        assert_eq!(mul(&[1.0, 2.0], &[1.0, -2.0]), vec![1.0, 0.0, -4.0]);
        assert_eq!(add(&[1.0, 0.0, 0.0], &[3.0]), vec![1.0, 0.0, 3.0]);
        assert_eq!(deriv(&[1.0, 2.0, 3.0]), vec![2.0, 2.0]);
        assert_eq!(trim(&[0.0, 0.0, 2.0]), vec![2.0]);
    }

    #[test]
    fn roots_of_a_companion_matrix_nalgebra_does_not_converge_on() {
        // The phase-crossover polynomial of the first random pair of tests/test_control.py:
        // nalgebra's uncapped QR iteration never returned on its companion matrix.
        let num = mul(&[128.88265231, 1640.91807592], &[0.10126911, 2.37477161]);
        let den = mul(
            &[1.0, 39.09795842, 222.21881883, 16.88743989, 33.3383792],
            &[1.0, 0.0],
        );
        for p in [num.clone(), den.clone(), mul(&num, &den)] {
            let r = roots(&p);
            assert_eq!(r.len(), trim(&p).len() - 1);
            let scale: f64 = p.iter().map(|c| c.abs()).sum();
            for z in r {
                assert!(
                    eval(&p, z).norm() <= 1e-8 * scale * z.norm().max(1.0).powi(p.len() as i32),
                    "{z}"
                );
            }
        }
        let mut a = aberth(
            &from_roots(&[
                C64::new(-2.0, 0.0),
                C64::new(-0.5, 3.0),
                C64::new(-0.5, -3.0),
            ]),
            1.0,
        );
        a.sort_by(|x, y| x.im.total_cmp(&y.im));
        assert!((a[0] - C64::new(-0.5, -3.0)).norm() < 1e-12);
        assert!((a[1] - C64::new(-2.0, 0.0)).norm() < 1e-12);
        assert!((a[2] - C64::new(-0.5, 3.0)).norm() < 1e-12);
    }
}

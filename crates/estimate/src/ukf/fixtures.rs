//! The 9-state model shared by the unit tests and the criterion bench (`benches/ukf.rs`
//! includes this file by path): 3-D constant acceleration, as in
//! `benchmarks/ukf_vs_filterpy.py`.

use nalgebra::DMatrix;

/// 3-D constant-acceleration model: state [p; v; a] (9 entries), input = jerk·dt, z = p.
/// Returns (F, H, B).
pub fn constant_acceleration(dt: f64) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let mut f = DMatrix::identity(9, 9);
    for i in 0..3 {
        f[(i, 3 + i)] = dt;
        f[(i, 6 + i)] = 0.5 * dt * dt;
        f[(3 + i, 6 + i)] = dt;
    }
    let mut h = DMatrix::zeros(3, 9);
    for i in 0..3 {
        h[(i, i)] = 1.0;
    }
    let mut b = DMatrix::zeros(9, 3);
    for i in 0..3 {
        b[(6 + i, i)] = 1.0;
    }
    (f, h, b)
}

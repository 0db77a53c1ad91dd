use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use super::maxmin::{maxmin_pool, maxmin_pool_backward};
use super::shpl::{BevGrid, Direction, ImageGrid, SparsePooling};
use crate::DetectError;

/// A KITTI-like camera looking along +x: u = 700·(−y/x) + 600, v = 700·(−z/x) + 180.
fn projection() -> [[f64; 4]; 3] {
    [
        [600.0, -700.0, 0.0, 0.0],
        [180.0, 0.0, -700.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
    ]
}

fn cloud(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Pcg64::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            [
                rng.random_range(-5.0..60.0),
                rng.random_range(-30.0..30.0),
                rng.random_range(-2.0..1.0),
            ]
        })
        .collect()
}

fn op(n: usize, k: usize) -> SparsePooling {
    SparsePooling::build(
        &cloud(n, 1),
        &projection(),
        ImageGrid::new(23, 78, 16.0).unwrap(),
        BevGrid::new(0.0, -30.0, 1.0, 60, 60).unwrap(),
        k,
    )
    .unwrap()
}

fn dense_apply(
    d: &[f64],
    rows: usize,
    cols: usize,
    x: &[f64],
    ch: usize,
    transpose: bool,
) -> Vec<f64> {
    let (orows, icols) = if transpose {
        (cols, rows)
    } else {
        (rows, cols)
    };
    let mut out = vec![0.0; orows * ch];
    for r in 0..orows {
        for c in 0..icols {
            let w = if transpose {
                d[c * cols + r]
            } else {
                d[r * cols + c]
            };
            if w != 0.0 {
                for q in 0..ch {
                    out[r * ch + q] += w * x[c * ch + q];
                }
            }
        }
    }
    out
}

#[test]
fn forward_and_backward_equal_the_dense_kernel() {
    for k in [1, 3] {
        let op = op(3000, k);
        assert!(op.kept > 1000 && op.dropped.behind > 0 && op.dropped.outside_image > 0);
        let mut rng = Pcg64::seed_from_u64(2);
        for dir in [Direction::ImageToBev, Direction::BevToImage] {
            let (nin, nout) = op.shape(dir);
            let kern = op.kernel(dir);
            let dense = kern.to_dense();
            // eq. 7.8: every non-empty row sums to 1.
            for r in 0..nout {
                let s: f64 = dense[r * nin..(r + 1) * nin].iter().sum();
                assert!(s == 0.0 || (s - 1.0).abs() < 1e-12);
            }
            let ch = 5;
            let x: Vec<f64> = (0..nin * ch).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut y = vec![0.0; nout * ch];
            op.forward(dir, &x, ch, &mut y).unwrap();
            let yd = dense_apply(&dense, nout, nin, &x, ch, false);
            assert!(y.iter().zip(&yd).all(|(a, b)| (a - b).abs() < 1e-12));
            let g: Vec<f64> = (0..nout * ch)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let mut gx = vec![0.0; nin * ch];
            op.backward(dir, &g, ch, &mut gx).unwrap();
            let gd = dense_apply(&dense, nout, nin, &g, ch, true);
            assert!(gx.iter().zip(&gd).all(|(a, b)| (a - b).abs() < 1e-12));
            // f32 agrees to its precision.
            let x32: Vec<f32> = x.iter().map(|v| *v as f32).collect();
            let mut y32 = vec![0.0f32; nout * ch];
            op.forward(dir, &x32, ch, &mut y32).unwrap();
            assert!(
                y32.iter()
                    .zip(&y)
                    .all(|(a, b)| (*a as f64 - b).abs() < 1e-5)
            );
            // Adjoint identity ⟨K x, g⟩ = ⟨x, Kᵀ g⟩ (what a finite-difference check of a linear
            // map tests).
            let lhs: f64 = y.iter().zip(&g).map(|(a, b)| a * b).sum();
            let rhs: f64 = x.iter().zip(&gx).map(|(a, b)| a * b).sum();
            assert!((lhs - rhs).abs() < 1e-10);
        }
    }
}

#[test]
fn results_are_bit_identical_across_thread_counts() {
    let op = op(5000, 3);
    let ch = 64;
    let (nin, nout) = op.shape(Direction::ImageToBev);
    let x: Vec<f32> = (0..nin * ch)
        .map(|i| ((i * 7919) % 1000) as f32 / 1000.0 - 0.5)
        .collect();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let mut y = vec![0.0f32; nout * ch];
                op.forward(Direction::ImageToBev, &x, ch, &mut y).unwrap();
                y
            })
    };
    let a = run(1);
    assert!(
        a.iter()
            .zip(run(3))
            .all(|(p, q)| p.to_bits() == q.to_bits())
    );
}

#[test]
fn points_outside_are_dropped_and_counted() {
    let p = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let pts = [
        [0.5, 0.5, 0.0],
        [5.0, 0.5, 0.0],
        [0.5, 0.5, 0.0],
        [-0.5, 0.5, 0.0],
        [1.5, 1.5, 0.0],
    ];
    let mut pm = p;
    pm[2] = [0.0, 0.0, 1.0, 0.0]; // w = z: every point at z = 0 is "behind".
    let behind = SparsePooling::build(
        &pts,
        &pm,
        ImageGrid::new(2, 2, 1.0).unwrap(),
        BevGrid::new(0.0, 0.0, 1.0, 1, 1).unwrap(),
        1,
    )
    .unwrap();
    assert_eq!(behind.dropped.behind, 5);
    assert_eq!(behind.kept, 0);
    let op = SparsePooling::build(
        &pts,
        &p,
        ImageGrid::new(2, 2, 1.0).unwrap(),
        BevGrid::new(0.0, 0.0, 1.0, 1, 1).unwrap(),
        1,
    )
    .unwrap();
    // (5, .5) and (−.5, .5) leave the 2×2 image; (1.5, 1.5) is in the image but outside the 1×1 BEV.
    assert_eq!(
        (op.dropped.outside_image, op.dropped.outside_bev, op.kept),
        (2, 1, 2)
    );
    // Two points in the same BEV cell and the same image cell: one merged entry of weight 1.
    assert_eq!(op.image_to_bev.nnz(), 1);
    assert_eq!(op.image_to_bev.data, vec![1.0]);
}

#[test]
fn bad_inputs_give_errors() {
    let p = projection();
    let ig = ImageGrid::new(4, 4, 1.0).unwrap();
    let bg = BevGrid::new(0.0, 0.0, 1.0, 4, 4).unwrap();
    assert!(matches!(
        SparsePooling::build(&[], &p, ig, bg, 1),
        Err(DetectError::TooFewPoints { .. })
    ));
    assert!(matches!(
        SparsePooling::build(&[[f64::NAN, 0.0, 0.0]], &p, ig, bg, 1),
        Err(DetectError::NonFinite { .. })
    ));
    assert!(SparsePooling::build(&[[1.0, 0.0, 0.0]], &p, ig, bg, 2).is_err());
    assert!(ImageGrid::new(0, 4, 1.0).is_err());
    assert!(BevGrid::new(0.0, 0.0, -1.0, 4, 4).is_err());
    // More cells than u32 indices address (the product 60·2⁶² wrapped to 0 before).
    assert!(BevGrid::new(0.0, 0.0, 1.0, 60, 1 << 62).is_err());
    assert!(ImageGrid::new(1 << 16, 1 << 16, 1.0).is_err());
    assert!(ImageGrid::new(1 << 16, (1 << 16) - 1, 1.0).is_ok());
    let op = SparsePooling::build(&[[1.0, 0.0, 0.0]], &p, ig, bg, 1).unwrap();
    let mut out = vec![0.0; 16 * 3];
    let err = op
        .forward(Direction::ImageToBev, &[0.0; 16 * 2], 3, &mut out)
        .unwrap_err();
    assert!(matches!(err, DetectError::WrongLength { .. }), "{err}");
}

/// The product checks finiteness itself (a gathered NaN/∞ reaches the output; cells no row
/// reads are checked apart): both kinds are reported with their flat index, in both directions.
#[test]
fn non_finite_features_are_reported_whether_gathered_or_not() {
    // Pixel (u, v) = (x, y): the point hits image cell (2, 1) and BEV cell (1, 2).
    let p = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let ig = ImageGrid::new(4, 4, 1.0).unwrap();
    let bg = BevGrid::new(0.0, 0.0, 1.0, 4, 4).unwrap();
    let op = SparsePooling::build(&[[1.5, 2.5, 0.0]], &p, ig, bg, 1).unwrap();
    let read = op.image_to_bev.indices[0] as usize;
    let unread = (read + 1) % 16;
    let ch = 3;
    for (cell, bad) in [
        (read, f32::NAN),
        (unread, f32::INFINITY),
        (unread, f32::NAN),
    ] {
        let mut x = vec![1.0f32; 16 * ch];
        x[cell * ch + 2] = bad;
        let mut out = vec![0.0f32; 16 * ch];
        let err = op
            .forward(Direction::ImageToBev, &x, ch, &mut out)
            .unwrap_err();
        assert!(
            matches!(err, DetectError::NonFinite { index, .. } if index == cell * ch + 2),
            "{err}"
        );
        let err = op
            .backward(Direction::BevToImage, &x, ch, &mut out)
            .unwrap_err();
        assert!(matches!(err, DetectError::NonFinite { .. }), "{err}");
    }
    // Finite values too large for f32 overflow to ∞ in the sum: that is the answer, not an error.
    let mut x = vec![0.0f32; 16 * ch];
    x[read * ch] = f32::MAX;
    let mut out = vec![0.0f32; 16 * ch];
    op.forward(Direction::ImageToBev, &x, ch, &mut out).unwrap();
}

/// An 8×8 input in the spirit of Fig. 7.6 (two clusters on a −9 background; the figure's own
/// values are not in the text): three poolings give the 1×1×8 output below, which holds the
/// cluster edges 2, 1, −1, −2 besides the extremes 3 and −9, as the caption says.
pub(crate) const FIG_7_6: [[f64; 8]; 8] = [
    [3.0, 1.0, 1.0, 3.0, -9.0, -9.0, -9.0, -9.0],
    [2.0, 2.0, 2.0, 2.0, -9.0, -9.0, -9.0, -9.0],
    [3.0, 1.0, 2.0, 1.0, -9.0, -9.0, -9.0, -9.0],
    [2.0, 3.0, -1.0, -1.0, -2.0, -2.0, -9.0, -9.0],
    [-9.0, -9.0, -1.0, -2.0, -1.0, -1.0, -9.0, -9.0],
    [-9.0, -9.0, -2.0, -1.0, -2.0, -2.0, -9.0, -9.0],
    [-9.0, -9.0, -1.0, -2.0, -1.0, -1.0, -9.0, -9.0],
    [-9.0, -9.0, -9.0, -9.0, -9.0, -9.0, -9.0, -9.0],
];

#[test]
fn fig_7_6_three_poolings_keep_the_cluster_edges() {
    let x: Vec<f64> = FIG_7_6.iter().flatten().copied().collect();
    let a = maxmin_pool(&x, 8, 8, 1).unwrap();
    let b = maxmin_pool(&a, 4, 4, 2).unwrap();
    let c = maxmin_pool(&b, 2, 2, 4).unwrap();
    assert_eq!(c, vec![3.0, 1.0, 2.0, -1.0, -2.0, -9.0, -9.0, -9.0]);
    // Zeros are undefined (a window holding only 5 has max = min = 5, not min 0), and an
    // all-zero window outputs 0. Output channels per window: [max, min].
    let y = maxmin_pool(
        &[0.0, 5.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        2,
        6,
        1,
    )
    .unwrap();
    assert_eq!(y, vec![5.0, 5.0, -1.0, -1.0, 0.0, 0.0]);
}

#[test]
fn maxmin_gradient_matches_finite_differences() {
    let mut rng = Pcg64::seed_from_u64(4);
    let (h, w, c) = (5, 6, 3);
    let x: Vec<f64> = (0..h * w * c)
        .map(|_| {
            if rng.random_bool(0.3) {
                0.0
            } else {
                rng.random_range(-2.0..2.0)
            }
        })
        .collect();
    let out = maxmin_pool(&x, h, w, c).unwrap();
    let g: Vec<f64> = (0..out.len())
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let grad = maxmin_pool_backward(&x, h, w, c, &g).unwrap();
    let loss = |x: &[f64]| -> f64 {
        maxmin_pool(x, h, w, c)
            .unwrap()
            .iter()
            .zip(&g)
            .map(|(a, b)| a * b)
            .sum()
    };
    let eps = 1e-6;
    for i in 0..x.len() {
        if x[i] == 0.0 {
            // Undefined cells: the layer ignores them (no gradient).
            assert_eq!(grad[i], 0.0);
            continue;
        }
        let mut xp = x.clone();
        xp[i] += eps;
        let mut xm = x.clone();
        xm[i] -= eps;
        let fd = (loss(&xp) - loss(&xm)) / (2.0 * eps);
        assert!(
            (fd - grad[i]).abs() < 1e-6,
            "cell {i}: fd {fd} vs {}",
            grad[i]
        );
    }
    assert!(maxmin_pool(&x, h, w, c + 1).is_err());
    assert!(maxmin_pool(&[f64::NAN], 1, 1, 1).is_err());
}

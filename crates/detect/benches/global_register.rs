//! Global registration (issue 29): a 150-point chevron with a tail in a 2-D scene of ~500 points
//! (target, a partial 0.9-scaled distractor, uniform clutter), and a 3-D cloud of 2000 template
//! points in a scene of ~3000 (target plus uniform clutter).

use std::hint::black_box;

use autoteach_detect::cpd::{GlobalRegisterOptions, global_register};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DMatrix, Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// `n` points spaced along the chevron-with-tail outline.
fn chevron(n: usize) -> DMatrix<f64> {
    let v = [
        [-1.0, 1.0],
        [0.0, 0.0],
        [-1.0, -1.0],
        [-0.55, -1.0],
        [0.45, 0.0],
        [-0.55, 1.0],
        [-1.0, 1.0],
        [0.45, 0.0],
        [1.3, 0.2],
    ];
    let seg: Vec<f64> = v
        .windows(2)
        .map(|w: &[[f64; 2]]| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
        .collect();
    let total: f64 = seg.iter().sum();
    DMatrix::from_fn(n, 2, |i, c| {
        let mut s = (i as f64 + 0.5) / n as f64 * total;
        let mut k = 0;
        while k + 1 < seg.len() && s > seg[k] {
            s -= seg[k];
            k += 1;
        }
        let f = s / seg[k];
        v[k][c] + f * (v[k + 1][c] - v[k][c])
    })
}

fn scene_2d(seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let y = chevron(150);
    let target = chevron(170);
    let (s, c) = 2.0f64.sin_cos();
    let mut rows = Vec::new();
    for i in 0..target.nrows() {
        let (a, b) = (target[(i, 0)], target[(i, 1)]);
        rows.push([c * a - s * b + 0.7, s * a + c * b - 0.3]);
    }
    for i in 0..target.nrows() {
        let (a, b) = (0.9 * target[(i, 0)], 0.9 * target[(i, 1)]);
        if a > -0.5 {
            rows.push([-a - 2.5, -b + 2.0]);
        }
    }
    while rows.len() < 500 {
        rows.push([rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0)]);
    }
    (DMatrix::from_fn(rows.len(), 2, |r, c| rows[r][c]), y)
}

fn scene_3d(seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let centres = [
        [0.0, 0.0, 0.0],
        [0.8, 0.1, 0.0],
        [0.1, 0.5, 0.3],
        [-0.4, -0.3, 0.2],
    ];
    let mut sample = |n: usize| {
        let mut m = DMatrix::zeros(n, 3);
        for i in 0..n {
            let k = i % 4;
            for c in 0..3 {
                m[(i, c)] = centres[k][c] + 0.15 * (rng.random::<f64>() - 0.5) * (1.0 + c as f64);
            }
        }
        m
    };
    let y = sample(2000);
    let t = sample(2000);
    let r = Rotation3::from_euler_angles(0.5, -1.0, 2.0);
    let mut rows: Vec<Vector3<f64>> = (0..t.nrows())
        .map(|i| r * Vector3::new(t[(i, 0)], t[(i, 1)], t[(i, 2)]) + Vector3::new(1.0, 0.5, -0.2))
        .collect();
    for _ in 0..1000 {
        rows.push(Vector3::new(
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
        ));
    }
    (DMatrix::from_fn(rows.len(), 3, |i, c| rows[i][c]), y)
}

fn bench(c: &mut Criterion) {
    let o = GlobalRegisterOptions::default();
    let (x2, y2) = scene_2d(1);
    c.bench_function("global_register 2-D 150/500", |b| {
        b.iter(|| global_register(black_box(&x2), black_box(&y2), &o).expect("2-D scene registers"))
    });
    let (x3, y3) = scene_3d(2);
    let mut g = c.benchmark_group("global_register 3-D");
    g.sample_size(10);
    g.bench_function("2000/3000", |b| {
        b.iter(|| global_register(black_box(&x3), black_box(&y3), &o).expect("3-D scene registers"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! Rotated-box IoU, spatial distributions and JIoU (000_3b1454b2b2194811.txt eq. 8.2–8.4, App. A).
//!
//! Run: `cargo bench -p autoteach-geometry --bench boxes -- --warm-up-time 1 --measurement-time 3`.
#![allow(missing_docs)]

use std::hint::black_box;

use autoteach_geometry::boxes::iou::iou;
use autoteach_geometry::boxes::jiou::{JiouOptions, ProbBox, jiou_batch};
use autoteach_geometry::boxes::spatial::{Grid2, pg_moments_at};
use autoteach_geometry::boxes::{Box2, Cov5};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn diag(d: [f64; 5]) -> Cov5 {
    let mut c = [[0.0; 5]; 5];
    for i in 0..5 {
        c[i][i] = d[i];
    }
    c
}

fn pairs(n: usize) -> (Vec<ProbBox>, Vec<ProbBox>) {
    let mut rng = Pcg64::seed_from_u64(1);
    let mut a = Vec::new();
    let mut b = Vec::new();
    for _ in 0..n {
        let m = Box2::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            4.2,
            1.8,
            rng.random_range(-3.0..3.0),
        )
        .expect("box");
        a.push(ProbBox {
            mean: m,
            cov: diag([0.04, 0.01, 0.06, 0.01, 0.003]),
        });
        let p = Box2::new(
            m.cx + rng.random_range(-0.5..0.5),
            m.cy,
            4.0,
            1.7,
            m.r + 0.05,
        )
        .expect("box");
        b.push(ProbBox {
            mean: p,
            cov: diag([0.02, 0.02, 0.02, 0.02, 0.001]),
        });
    }
    (a, b)
}

fn boxes(c: &mut Criterion) {
    let (a, b) = pairs(1000);
    let mut g = c.benchmark_group("boxes_1000_pairs");
    g.throughput(Throughput::Elements(1000));
    g.bench_function("exact_iou", |bch| {
        bch.iter(|| {
            a.iter()
                .zip(&b)
                .map(|(x, y)| iou(&x.mean, &y.mean))
                .sum::<f64>()
        })
    });
    g.bench_function("jiou_pg_900_cells_64_samples", |bch| {
        bch.iter(|| {
            jiou_batch(black_box(&a), black_box(&b), &JiouOptions::default()).expect("jiou")
        })
    });
    g.finish();
    let grid = Grid2::new(-4.0, -4.0, 0.08, 0.08, 100, 100).expect("grid");
    let pts = grid.centres();
    c.bench_function("pg_moments_10k_points_lattice20", |bch| {
        bch.iter(|| pg_moments_at(&a[0].mean, &a[0].cov, black_box(&pts), 20).expect("pg"))
    });
}

criterion_group!(benches, boxes);
criterion_main!(benches);

//! Linear assignment on random dense matrices (25×25 as in arc merging, 100×100 as in busy
//! track association), with and without forbidden pairs and non-assignment costs; and the
//! Jonker–Volgenant square solver on the families of `benchmarks/peer_rows/assignment.py`.

use std::hint::black_box;

use autoteach_detect::assignment::{solve_assignment, solve_assignment_with_unassigned};
use autoteach_detect::lapjv::solve_assignment_row_major;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn random(n: usize, p_forbidden: f64, seed: u64) -> DMatrix<f64> {
    let mut rng = Pcg64::seed_from_u64(seed);
    DMatrix::from_fn(n, n, |_, _| {
        if rng.random::<f64>() < p_forbidden {
            f64::INFINITY
        } else {
            rng.random::<f64>()
        }
    })
}

fn bench(c: &mut Criterion) {
    for n in [25, 100] {
        let dense = random(n, 0.0, 1);
        c.bench_function(&format!("solve_assignment {n}x{n}"), |b| {
            b.iter(|| solve_assignment(black_box(&dense)))
        });
        let sparse = random(n, 0.5, 2);
        c.bench_function(&format!("solve_assignment {n}x{n} half forbidden"), |b| {
            b.iter(|| solve_assignment(black_box(&sparse)))
        });
        let unassigned = vec![0.3; n];
        c.bench_function(&format!("solve_assignment_with_unassigned {n}x{n}"), |b| {
            b.iter(|| solve_assignment_with_unassigned(black_box(&dense), &unassigned, &unassigned))
        });
    }
}

/// Square dense costs of the issue-36 families, solved from row-major data by Jonker–Volgenant
/// (`lapjv::solve_assignment_row_major`): uniform, integer (ties) and geometric distances.
fn bench_lapjv(c: &mut Criterion) {
    let mut group = c.benchmark_group("lapjv");
    group.sample_size(10);
    for n in [200usize, 1000] {
        let mut rng = Pcg64::seed_from_u64(36);
        let uniform: Vec<f64> = (0..n * n).map(|_| rng.random::<f64>()).collect();
        let integer: Vec<f64> = (0..n * n)
            .map(|_| f64::from(rng.random_range(0..1000u32)))
            .collect();
        let a: Vec<(f64, f64)> = (0..n).map(|_| (rng.random(), rng.random())).collect();
        let b: Vec<(f64, f64)> = (0..n).map(|_| (rng.random(), rng.random())).collect();
        let geometric: Vec<f64> = (0..n * n)
            .map(|k| (a[k / n].0 - b[k % n].0).hypot(a[k / n].1 - b[k % n].1))
            .collect();
        for (family, cost) in [
            ("uniform", &uniform),
            ("integer", &integer),
            ("geometric", &geometric),
        ] {
            group.bench_function(format!("{n}x{n} {family}"), |bch| {
                bch.iter(|| solve_assignment_row_major(n, n, black_box(cost)))
            });
        }
    }
    // Integer costs at the largest size of the peer table (ties; the slowest family for JV's
    // row reduction), on the row-major data the binding passes without a copy.
    let n = 3000usize;
    let mut rng = Pcg64::seed_from_u64(36);
    let integer: Vec<f64> = (0..n * n)
        .map(|_| f64::from(rng.random_range(0..1000u32)))
        .collect();
    group.bench_function("3000x3000 integer", |bch| {
        bch.iter(|| solve_assignment_row_major(n, n, black_box(&integer)))
    });
    group.finish();
}

criterion_group!(benches, bench, bench_lapjv);
criterion_main!(benches);

//! Linear assignment on random dense matrices (25×25 as in arc merging, 100×100 as in busy
//! track association), with and without forbidden pairs and non-assignment costs.

use std::hint::black_box;

use autoteach_detect::assignment::{solve_assignment, solve_assignment_with_unassigned};
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

criterion_group!(benches, bench);
criterion_main!(benches);

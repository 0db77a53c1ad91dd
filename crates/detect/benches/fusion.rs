//! SHPL (000_3b1454b2b2194811.txt eq. 7.4–7.9) and non-zero max-min pooling (Fig. 7.6), at the
//! issue's size: 20 000 points, 512 channels, 155×46 image cells → 75×75 BEV cells.
//!
//! Run: `RAYON_NUM_THREADS=1 cargo bench -p autoteach-detect --bench fusion -- --warm-up-time 1 --measurement-time 3`.
#![allow(missing_docs)]

use std::hint::black_box;

use autoteach_detect::fusion::maxmin::maxmin_pool;
use autoteach_detect::fusion::shpl::{BevGrid, Direction, ImageGrid, SparsePooling};
use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Points in front of a KITTI-like camera (1242×375 px at stride 8 → 155×46 cells).
fn setup() -> (Vec<[f64; 3]>, [[f64; 4]; 3], ImageGrid, BevGrid) {
    let mut rng = Pcg64::seed_from_u64(0);
    let pts: Vec<[f64; 3]> = (0..20_000)
        .map(|_| {
            let x: f64 = rng.random_range(2.0..70.0);
            [
                x,
                rng.random_range(-0.8..0.8) * x,
                rng.random_range(-0.2..0.2) * x,
            ]
        })
        .collect();
    let p = [
        [621.0, -700.0, 0.0, 0.0],
        [187.0, 0.0, -700.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
    ];
    (
        pts,
        p,
        ImageGrid::new(46, 155, 8.0).expect("grid"),
        BevGrid::new(0.0, -37.5, 1.0, 75, 75).expect("grid"),
    )
}

fn shpl(c: &mut Criterion) {
    let (pts, p, ig, bg) = setup();
    c.bench_function("shpl_build_20k", |b| {
        b.iter(|| SparsePooling::build(black_box(&pts), &p, ig, bg, 1).expect("build"))
    });
    let op = SparsePooling::build(&pts, &p, ig, bg, 1).expect("build");
    let ch = 512;
    let x32: Vec<f32> = (0..ig.len() * ch).map(|i| (i % 97) as f32 * 0.01).collect();
    let g32: Vec<f32> = (0..bg.len() * ch).map(|i| (i % 89) as f32 * 0.01).collect();
    let mut y32 = vec![0.0f32; bg.len() * ch];
    let mut gx32 = vec![0.0f32; ig.len() * ch];
    c.bench_function("shpl_forward_f32_512ch", |b| {
        b.iter(|| {
            op.forward(Direction::ImageToBev, &x32, ch, &mut y32)
                .expect("fwd")
        })
    });
    c.bench_function("shpl_backward_f32_512ch", |b| {
        b.iter(|| {
            op.backward(Direction::ImageToBev, &g32, ch, &mut gx32)
                .expect("bwd")
        })
    });
    let x64: Vec<f64> = x32.iter().map(|v| *v as f64).collect();
    let mut y64 = vec![0.0f64; bg.len() * ch];
    c.bench_function("shpl_forward_f64_512ch", |b| {
        b.iter(|| {
            op.forward(Direction::ImageToBev, &x64, ch, &mut y64)
                .expect("fwd")
        })
    });
    let img: Vec<f32> = (0..376 * 1242)
        .map(|i| {
            if i % 7 == 0 {
                (i % 13) as f32 - 6.0
            } else {
                0.0
            }
        })
        .collect();
    c.bench_function("maxmin_pool_376x1242x1", |b| {
        b.iter(|| maxmin_pool(black_box(&img), 376, 1242, 1).expect("pool"))
    });
}

criterion_group!(benches, shpl);
criterion_main!(benches);

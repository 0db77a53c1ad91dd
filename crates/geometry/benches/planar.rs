//! Planar ray-casting benches (seed 004_815695db12a6b16c.txt ch. 2): the grid-cell walk of one
//! 30 m laser beam at 0.1 m cells, and one 1081-beam scan cast against a world of walls.
//!
//! Run: `cargo bench -p autoteach-geometry --bench planar -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use autoteach_geometry::planar::{Segment, SegmentWorld, traverse_cells};
use criterion::{Criterion, criterion_group, criterion_main};

fn planar(c: &mut Criterion) {
    c.bench_function("traverse_cells_300", |b| {
        b.iter(|| {
            let mut n = 0u32;
            traverse_cells(black_box([0.5, 0.5]), black_box([290.3, 77.7]), |_, _| {
                n += 1
            });
            n
        })
    });
    // A 100 × 100 m grid of 10 m rooms (walls every 10 m with 1 m doorways).
    let mut walls = vec![];
    for k in 0..=10 {
        let v = 10.0 * k as f64;
        for s in 0..10 {
            let a = 10.0 * s as f64;
            walls.push(Segment::new([v, a], [v, a + 4.5]));
            walls.push(Segment::new([v, a + 5.5], [v, a + 10.0]));
            walls.push(Segment::new([a, v], [a + 4.5, v]));
            walls.push(Segment::new([a + 5.5, v], [a + 10.0, v]));
        }
    }
    let world = SegmentWorld::new(walls, 4.0).expect("world");
    c.bench_function("scan_1081_beams", |b| {
        b.iter(|| {
            let mut sum = 0.0;
            for k in 0..1081 {
                let a = -2.356 + k as f64 * 0.004363;
                sum += world.cast(black_box([45.3, 47.1]), a, 30.0).unwrap_or(30.0);
            }
            sum
        })
    });
}

criterion_group!(benches, planar);
criterion_main!(benches);

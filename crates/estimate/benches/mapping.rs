//! Criterion benches of occupancy-grid rasterization (seed 004_815695db12a6b16c.txt ch. 2):
//! one update of each Table 2.1 method on the final graph of the small simulated stream,
//! CoverComposite's fully cached update, and one 10 s simulator step with its SE(2) solve.

use autoteach_estimate::mapping::{
    GraphSnapshot, Method, NodeInput, RasterConfig, Rasterizer, TeamConfig, TeamSimulator,
};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn stream() -> (Vec<GraphSnapshot>, Vec<Vec<f64>>, RasterConfig) {
    let cfg = TeamConfig::small(1);
    let mut sim = TeamSimulator::new(cfg).expect("simulator");
    let mut snaps = vec![];
    while let Some(s) = sim.step().expect("step") {
        snaps.push(s);
    }
    let last = snaps.last().expect("a graph");
    let scans = last
        .node_ids
        .iter()
        .map(|&id| {
            sim.ranges(id)
                .expect("ranges")
                .iter()
                .map(|&r| r as f64)
                .collect()
        })
        .collect();
    let rc = RasterConfig {
        scan: cfg.scan,
        ..RasterConfig::default()
    };
    (snaps, scans, rc)
}

fn nodes<'a>(s: &'a GraphSnapshot, scans: &'a [Vec<f64>], shift: f64) -> Vec<NodeInput<'a>> {
    s.node_ids
        .iter()
        .enumerate()
        .map(|(k, &id)| NodeInput {
            id,
            robot: s.robot_ids[k],
            pose: [s.poses[k][0] + shift, s.poses[k][1], s.poses[k][2]],
            ranges: Some(scans[k].as_slice()),
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let (snaps, scans, rc) = stream();
    let last = snaps.last().expect("a graph");
    let mut g = c.benchmark_group("mapping");
    g.sample_size(10);
    for (name, method) in [
        ("naive_composite", Method::NaiveComposite),
        ("naive_cover_composite", Method::NaiveCoverComposite),
    ] {
        let mut r = Rasterizer::new(RasterConfig { method, ..rc }).expect("rasterizer");
        let input = nodes(last, &scans, 0.0);
        g.bench_function(name, |b| {
            b.iter(|| black_box(r.update(&input).expect("update")))
        });
    }
    // CoverComposite(4): every slice regenerated (the whole graph moved by a cell) vs cached.
    let mut r = Rasterizer::new(rc).expect("rasterizer");
    let (a, bb) = (nodes(last, &scans, 0.0), nodes(last, &scans, 0.3));
    let mut flip = false;
    g.bench_function("cover_composite_4_all_moved", |b| {
        b.iter(|| {
            flip = !flip;
            black_box(r.update(if flip { &a } else { &bb }).expect("update"))
        })
    });
    g.bench_function("cover_composite_4_cached", |b| {
        b.iter(|| black_box(r.update(&a).expect("update")))
    });
    g.bench_function("simulator_step_small", |b| {
        b.iter_batched(
            || TeamSimulator::new(TeamConfig::small(2)).expect("simulator"),
            |mut sim| {
                for _ in 0..3 {
                    black_box(sim.step().expect("step"));
                }
            },
            criterion::BatchSize::LargeInput,
        )
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

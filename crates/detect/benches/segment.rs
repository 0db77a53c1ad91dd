//! Coloured point-cloud segmentation (seed 004_815695db12a6b16c.txt Algorithm 4.1): the
//! simulated hallway at the Hokuyo's native ¼° (1081 beams × 140 planes ≈ 151 k points, the
//! seed's 151 201-point figure), graph + normals + segmentation, and its parts; co-registration
//! of the same scan through the 752 × 480 camera.

use std::hint::black_box;

use autoteach_detect::segment::counting_sort::counting_sort_by_key;
use autoteach_detect::segment::felzenszwalb::{RGB_KEY_MAX, rgb_key};
use autoteach_detect::segment::scene::{self, Scanner};
use autoteach_detect::segment::{
    ColorizeParams, FhParams, GraphKind, RgbImage, SegmentParams, colorize, estimate_normals,
    scan_graph, segment_cloud, segment_graph,
};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let sc = scene::preset("hallway").expect("preset");
    let scanner = Scanner {
        tilt_start_deg: -19.5,
        tilt_end_deg: 50.0,
        ..Scanner::hokuyo()
    };
    let s = scene::scan(&sc, &scanner, 3.0, 1).expect("scan");
    let params = SegmentParams {
        graph: GraphKind::Scan {
            lines: s.lines,
            beams: s.beams,
        },
        ..SegmentParams::default()
    };
    let n = s.points.len();
    let mut g = c.benchmark_group("segment");
    g.sample_size(20);
    g.bench_function(
        format!("segment_cloud scan {n} points (graph+normals+FH)"),
        |b| b.iter(|| segment_cloud(black_box(&s.points), &s.true_colors, None, &params)),
    );
    g.bench_function(format!("scan_graph {n}"), |b| {
        b.iter(|| scan_graph(black_box(&s.points), s.lines, s.beams, 0.25))
    });
    let graph = scan_graph(&s.points, s.lines, s.beams, 0.25).expect("graph");
    g.bench_function(format!("estimate_normals {n}"), |b| {
        b.iter(|| estimate_normals(black_box(&s.points), &graph, [0.0; 3]))
    });
    let (normals, _) = estimate_normals(&s.points, &graph, [0.0; 3]);
    g.bench_function(
        format!("segment_graph {n} (sort + merge + min size)"),
        |b| {
            b.iter(|| {
                segment_graph(
                    n,
                    black_box(&graph.edges),
                    &s.true_colors,
                    Some(&normals),
                    &FhParams::default(),
                )
            })
        },
    );
    let keyed: Vec<(u32, [u32; 2])> = graph
        .edges
        .iter()
        .map(|e| {
            let k = rgb_key(s.true_colors[e[0] as usize], s.true_colors[e[1] as usize]);
            (k, *e)
        })
        .collect();
    g.bench_function(
        format!("counting_sort_by_key {} colour keys", keyed.len()),
        |b| b.iter(|| counting_sort_by_key(black_box(keyed.clone()), RGB_KEY_MAX, |e| e.0)),
    );
    let valid: Vec<[f64; 3]> = s
        .points
        .iter()
        .copied()
        .filter(|p| !p[0].is_nan())
        .collect();
    let vcol: Vec<[u8; 3]> = s
        .points
        .iter()
        .zip(&s.true_colors)
        .filter(|(p, _)| !p[0].is_nan())
        .map(|(_, c)| *c)
        .collect();
    let knn = SegmentParams {
        graph: GraphKind::Knn { k: 8 },
        ..SegmentParams::default()
    };
    g.bench_function(
        format!("segment_cloud knn(8) {} points", valid.len()),
        |b| b.iter(|| segment_cloud(black_box(&valid), &vcol, None, &knn)),
    );
    let cam = scene::firefly_camera().expect("camera");
    let t_cam_lidar = scene::default_t_cam_lidar();
    let img = scene::render(
        &sc,
        &cam,
        &(scanner.t_world_lidar * t_cam_lidar.inverse()),
        3.0,
        1,
    );
    let image = RgbImage {
        width: 752,
        height: 480,
        data: &img,
    };
    g.bench_function(format!("colorize {n} points 752x480"), |b| {
        b.iter(|| {
            colorize(
                black_box(&s.points),
                &image,
                &cam,
                &t_cam_lidar,
                &ColorizeParams::default(),
            )
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

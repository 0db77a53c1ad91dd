//! Whole-image wafer-rim detection on a rendered 1280×720 carrier image (target wafer in slot 5,
//! disturbance wafer 2 slots above), and its stages.
//!
//! Run: `cargo bench -p autoteach-detect --bench wafer_detect -- --warm-up-time 1 --measurement-time 3`
//! (prefix `RAYON_NUM_THREADS=1` for single-threaded figures).
//!
//! Per-stage profile: with `AUTOTEACH_DETECT_PROFILE=1` the bench first renders 10 scenes like
//! `benchmarks/wafer_detection.py` (target in slot 5, disturbance 1–20 slots above, camera
//! 0.42–0.55 m away, random lighting; fixed seed) and prints the median milliseconds per image of
//! each stage over 4 repeats: Canny (on an `EdgeWorkspace` kept across the frames, as
//! `detect_wafers` does), linking, arc splitting, Algorithm 1, Algorithm 2, the
//! validation and rim pairing of `detect_wafers` (total without band refinement minus the
//! stages before it) and the band refinement (total minus total without it). With
//! `AUTOTEACH_DETECT_PROFILE=only` it prints the profile and skips the criterion benches.
//! `AUTOTEACH_DETECT_IMAGES=<file>` profiles the frames of a raw file instead (consecutive
//! 1280×720 8-bit grey frames, e.g. the 210 images of `benchmarks/wafer_detection.py` written
//! with numpy's `tofile`), once each; `AUTOTEACH_DETECT_PROFILE=detect` then only times
//! `detect_wafers` over them (`AUTOTEACH_DETECT_REPEATS` passes, default 3; for `perf record`;
//! `AUTOTEACH_DETECT_PRIOR=1` adds the rim offset prior of the benchmark's wafers and the
//! renderer's pixel-grid edge profile).

use autoteach_detect::assembly::{AssemblyParams, assemble, merge_arcs, merge_segments};
use autoteach_detect::edges::{
    ArcParams, CannyParams, EdgeWorkspace, GrayView, LinkParams, canny, detect_arcs, link_edges,
    split_arcs,
};
use autoteach_detect::wafers::{DetectParams, EdgeProfile, RimOffsetPrior, detect_wafers};
use autoteach_geometry::camera::Camera;
use autoteach_geometry::render::{self, Carrier, RenderOptions, Scene};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::hint::black_box;
use std::time::Instant;

fn camera() -> Camera {
    Camera::pinhole(1000.0, 1000.0, 639.5, 359.5, 1280, 720).expect("camera")
}

/// Camera at `(x, y, z)` looking along +x (image x = −y, image y = −z), yawed about z and
/// pitched down (as `camera_pose` of `benchmarks/wafer_detection.py`).
fn camera_pose(x: f64, y: f64, z: f64, yaw: f64, down: f64) -> Isometry3<f64> {
    let axes = Matrix3::from_columns(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
        * Rotation3::from_matrix_unchecked(axes)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), -down);
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

fn image() -> (Vec<u8>, usize, usize) {
    let carrier = Carrier::default();
    let scene = Scene::new(vec![carrier.slot_pose(5), carrier.slot_pose(7)]);
    let t_wc = camera_pose(-0.48, 0.02, 0.09, 0.03, 0.14);
    let img = render::render(&scene, &camera(), &t_wc, &RenderOptions::default()).expect("render");
    (img.data, img.width, img.height)
}

/// Ten scenes of the robustness test (fixed seed).
fn scenes() -> Vec<Vec<u8>> {
    let carrier = Carrier::default();
    let mut rng = Pcg64::seed_from_u64(3);
    (0..10)
        .map(|i| {
            let k = 1 + (2 * i) % 20;
            let scene = Scene::new(vec![carrier.slot_pose(5), carrier.slot_pose(5 + k)]);
            let z0 = 4.0 * carrier.pitch;
            let t_wc = camera_pose(
                rng.random_range(-0.55..-0.42),
                rng.random_range(-0.05..0.05),
                z0 + rng.random_range(0.02..0.07),
                rng.random_range(-3f64..3.0).to_radians(),
                rng.random_range(5f64..10.0).to_radians(),
            );
            let opts = RenderOptions {
                gain: rng.random_range(0.5..1.5),
                gradient: [rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3)],
                seed: rng.random(),
                ..RenderOptions::default()
            };
            render::render(&scene, &camera(), &t_wc, &opts)
                .expect("render")
                .data
        })
        .collect()
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Milliseconds of one call.
fn ms<R>(f: impl FnOnce() -> R) -> (f64, R) {
    let t = Instant::now();
    let r = f();
    (1e3 * t.elapsed().as_secs_f64(), r)
}

/// The frames of `AUTOTEACH_DETECT_IMAGES` (raw 1280×720 8-bit frames), if set.
fn frames_from_file() -> Option<Vec<Vec<u8>>> {
    let path = std::env::var("AUTOTEACH_DETECT_IMAGES").ok()?;
    let raw = std::fs::read(&path).expect("AUTOTEACH_DETECT_IMAGES: readable file");
    let n = 1280 * 720;
    assert!(
        !raw.is_empty() && raw.len() % n == 0,
        "{path}: not a whole number of 1280x720 8-bit frames"
    );
    Some(raw.chunks_exact(n).map(<[u8]>::to_vec).collect())
}

/// `params` with the rim offset prior of the rendered wafers (thickness/radius, focal length)
/// and the renderer's pixel-grid edge profile.
fn with_prior(params: DetectParams) -> DetectParams {
    DetectParams {
        rim_offset: Some(RimOffsetPrior {
            thickness_ratio: 1.0 / 150.0,
            focal_length: 1000.0,
            principal_point: None,
        }),
        edge_profile: EdgeProfile::PixelGrid,
        ..params
    }
}

/// `detect_wafers` alone over the frames of `AUTOTEACH_DETECT_IMAGES` (for `perf record`).
fn detect_only(images: &[Vec<u8>]) {
    let p = match std::env::var("AUTOTEACH_DETECT_PRIOR") {
        Ok(v) if v == "1" => with_prior(DetectParams::default()),
        _ => DetectParams::default(),
    };
    let repeats: usize = std::env::var("AUTOTEACH_DETECT_REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3);
    let mut t = Vec::new();
    let mut rims = 0;
    for _ in 0..repeats {
        rims = 0;
        for data in images {
            let view = GrayView::new(data, 1280, 720).expect("image");
            let (dt, found) = ms(|| detect_wafers(&view, &p).expect("detect"));
            rims += found.len();
            t.push(dt);
        }
    }
    println!(
        "detect_wafers: {} frames x {repeats}, {} rayon thread(s), {rims} rims per pass; median {:.2} ms per image",
        images.len(),
        rayon::current_num_threads(),
        median(&mut t)
    );
}

/// The per-stage profile (see the module documentation).
fn stage_profile(images: &[Vec<u8>], repeats: usize) {
    let p = DetectParams::default();
    let no_band = DetectParams {
        band_refinement: false,
        ..p
    };
    let names = [
        "canny",
        "link_edges",
        "split_arcs",
        "merge_arcs (Alg. 1)",
        "merge_segments (Alg. 2)",
        "validation + pairing",
        "band refinement",
        "detect_wafers total",
    ];
    let mut t: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut rims = 0;
    // The edge map from a workspace kept across frames, as `detect_wafers` does.
    let mut ws = EdgeWorkspace::new();
    for _ in 0..repeats {
        rims = 0;
        for data in images {
            let view = GrayView::new(data, 1280, 720).expect("image");
            let (t0, map) = ms(|| ws.canny(&view, &p.canny).expect("canny"));
            let (t1, chains) = ms(|| link_edges(map, &p.link).expect("link"));
            let (t2, arcs) = ms(|| split_arcs(map, &chains, &p.arcs).expect("split"));
            let (t3, (s0, v0)) = ms(|| merge_arcs(&arcs, &p.assembly).expect("alg 1"));
            let (t4, _) = ms(|| merge_segments(&arcs, s0, v0, &p.assembly).expect("alg 2"));
            let (t5, _) = ms(|| detect_wafers(&view, &no_band).expect("detect"));
            let (t6, found) = ms(|| detect_wafers(&view, &p).expect("detect"));
            rims += found.len();
            let before = t0 + t1 + t2 + t3 + t4;
            for (k, v) in [t0, t1, t2, t3, t4, t5 - before, t6 - t5, t6]
                .into_iter()
                .enumerate()
            {
                t[k].push(v);
            }
        }
    }
    println!(
        "stage profile: {} frames x {repeats} repeats, {} rayon thread(s), {rims} rims per pass; median ms per image",
        images.len(),
        rayon::current_num_threads()
    );
    for (name, v) in names.iter().zip(&mut t) {
        println!("  {name:<26} {:>8.2}", median(v));
    }
}

fn bench(c: &mut Criterion) {
    if let Ok(v) = std::env::var("AUTOTEACH_DETECT_PROFILE") {
        match frames_from_file() {
            Some(frames) if v == "detect" => detect_only(&frames),
            Some(frames) => stage_profile(&frames, 1),
            None => stage_profile(&scenes(), 4),
        }
        if v == "only" || v == "detect" {
            return;
        }
    }
    let (data, w, h) = image();
    let view = GrayView::new(&data, w, h).expect("image");
    let params = DetectParams::default();
    assert!(detect_wafers(&view, &params).expect("detect").len() >= 4);
    c.bench_function("detect_wafers 1280x720", |b| {
        b.iter(|| detect_wafers(black_box(&view), &params))
    });
    // With the rim offset prior (the rendered wafer's thickness/radius, the focal length): the
    // joint fits use it, and the thin and front-band column fits (`thin.rs`) run, with the
    // renderer's pixel-grid edge profile; without the column fits for the comparison.
    let prior = with_prior(params);
    let no_columns = DetectParams {
        thin_band_fit: false,
        front_band_fit: false,
        ..prior
    };
    c.bench_function("detect_wafers 1280x720, rim offset prior", |b| {
        b.iter(|| detect_wafers(black_box(&view), &prior))
    });
    c.bench_function(
        "detect_wafers 1280x720, rim offset prior, no column fits",
        |b| b.iter(|| detect_wafers(black_box(&view), &no_columns)),
    );
    c.bench_function("canny 1280x720", |b| {
        b.iter(|| canny(black_box(&view), &CannyParams::default()))
    });
    let mut ws = EdgeWorkspace::new();
    c.bench_function("canny 1280x720 (reused workspace)", |b| {
        b.iter(|| {
            ws.canny(black_box(&view), &CannyParams::default())
                .map(|m| m.edgels.len())
        })
    });
    let map = canny(&view, &CannyParams::default()).expect("canny");
    c.bench_function("link_edges 1280x720", |b| {
        b.iter(|| link_edges(black_box(&map), &LinkParams::default()))
    });
    let chains = link_edges(&map, &LinkParams::default()).expect("link");
    c.bench_function("split_arcs 1280x720", |b| {
        b.iter(|| split_arcs(black_box(&map), &chains, &ArcParams::default()))
    });
    let arcs = detect_arcs(
        &view,
        &CannyParams::default(),
        &LinkParams::default(),
        &ArcParams::default(),
    )
    .expect("arcs");
    c.bench_function("assemble (Algorithms 1-2)", |b| {
        b.iter(|| assemble(black_box(&arcs), &AssemblyParams::default()))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! Tests of the coloured point-cloud segmentation against independent truths: hand-worked
//! merges, brute-force neighbours, nalgebra's eigen-solver, the simulator's analytic normals
//! and ground-truth labels.

use std::collections::HashMap;

use nalgebra::{Isometry3, Matrix3, SymmetricEigen, Vector3};

use super::felzenszwalb::{Criteria, FhParams, segment_graph};
use super::normals::smallest_eigenvector;
use super::scene::{self, Scanner, SimRng};
use super::*;

fn fh(k_rgb: f64, k_norm: f64, min_size: usize, criteria: Criteria) -> FhParams {
    FhParams {
        k_rgb,
        k_norm,
        min_size,
        criteria,
    }
}

/// A path 0–1–2 with colours 0, 10, 100 (grey). Worked by hand with K_rgb = 30:
/// edge (0,1) w = √300 ≈ 17.3 < 30/1 for both singletons → join, thresh = 17.3 + 30/2 = 32.3;
/// edge (1,2) w = √(3·90²) ≈ 155.9 > 32.3 → rejected: two segments. With K_rgb = 400 the second
/// edge passes (155.9 < 17.3 + 200 and < 400) → one segment.
#[test]
fn path_graph_merges_as_worked_by_hand() {
    let colors = [[0, 0, 0], [10, 10, 10], [100, 100, 100]];
    let edges = [[1, 2], [0, 1]];
    let s = segment_graph(
        3,
        &edges,
        &colors,
        None,
        &fh(30.0, 0.0, 1, Criteria::ColorOnly),
    )
    .unwrap();
    assert_eq!(s.labels, vec![0, 0, 1]);
    let s = segment_graph(
        3,
        &edges,
        &colors,
        None,
        &fh(400.0, 0.0, 1, Criteria::ColorOnly),
    )
    .unwrap();
    assert_eq!(s.labels, vec![0, 0, 0]);
    // The normal criterion vetoes a colour-acceptable union: normals 90° apart (w = π/2) with
    // K_norm = 1 (threshold 1 rad) block both edges.
    let normals = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let s = segment_graph(
        3,
        &edges,
        &colors,
        Some(&normals),
        &fh(400.0, 1.0, 1, Criteria::Both),
    )
    .unwrap();
    assert_eq!(s.num_segments, 3);
    // Minimum size 2 then joins the singletons along the edges in sorted order.
    let s = segment_graph(
        3,
        &edges,
        &colors,
        Some(&normals),
        &fh(400.0, 1.0, 3, Criteria::Both),
    )
    .unwrap();
    assert_eq!(s.num_segments, 1);
}

#[test]
fn closed_form_eigenvector_matches_nalgebra() {
    let mut rng = SimRng::new(5);
    for _ in 0..200 {
        let a = Matrix3::from_fn(|_, _| rng.normal());
        let m = a * a.transpose();
        let c = [
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            m[(1, 1)],
            m[(1, 2)],
            m[(2, 2)],
        ];
        let v = smallest_eigenvector(c).unwrap();
        let eig = SymmetricEigen::new(m);
        let k = eig.eigenvalues.imin();
        let truth = eig.eigenvectors.column(k);
        let dot = (v[0] * truth[0] + v[1] * truth[1] + v[2] * truth[2]).abs();
        assert!(dot > 1.0 - 1e-8, "dot {dot}");
    }
    // Isotropic and rank-one (collinear points) matrices have no unique smallest direction.
    assert!(smallest_eigenvector([1.0, 0.0, 0.0, 1.0, 0.0, 1.0]).is_none());
    assert!(smallest_eigenvector([1.0, 1.0, 0.0, 1.0, 0.0, 0.0]).is_none());
}

#[test]
fn knn_graph_matches_brute_force() {
    let mut rng = SimRng::new(9);
    let pts: Vec<[f64; 3]> = (0..300)
        .map(|_| [rng.uniform(), rng.uniform(), rng.uniform()])
        .collect();
    let k = 5;
    let g = knn_graph(&pts, k, 10.0).unwrap();
    let mut truth = Vec::new();
    for (i, p) in pts.iter().enumerate() {
        let mut d: Vec<(f64, usize)> = pts
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(j, q)| {
                (
                    (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2),
                    j,
                )
            })
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        for &(_, j) in &d[..k] {
            truth.push([i.min(j) as u32, i.max(j) as u32]);
        }
    }
    truth.sort_unstable();
    truth.dedup();
    assert_eq!(g.edges, truth);
}

#[test]
fn scan_graph_is_the_cut_8_neighbourhood() {
    // 3 × 3 grid, 0.1 m apart, centre point pushed 1 m away: only the 8-ring edges remain.
    let mut pts: Vec<[f64; 3]> = (0..9)
        .map(|i| [1.0, (i % 3) as f64 * 0.1, (i / 3) as f64 * 0.1])
        .collect();
    let g = scan_graph(&pts, 3, 3, 0.25).unwrap();
    assert_eq!(g.edges.len(), 20); // 12 axis-aligned + 8 diagonal
    pts[4][0] = 2.0;
    let g = scan_graph(&pts, 3, 3, 0.25).unwrap();
    assert_eq!(g.edges.len(), 12);
    assert!(g.edges.iter().all(|e| e[0] != 4 && e[1] != 4));
    pts[0] = [f64::NAN; 3];
    let g = scan_graph(&pts, 3, 3, 0.25).unwrap();
    assert_eq!(g.edges.len(), 10);
}

/// Noise-free scan of the ramp scene: on the interior of the floor, the ramp and the walls the
/// PCA normals equal the analytic plane normals (the lidar frame is the world translated).
#[test]
fn normals_match_analytic_planes_without_noise() {
    let sc = scene::preset("ramp").unwrap();
    let scanner = Scanner {
        beam_step_deg: 0.75,
        tilt_speed_deg_s: 30.0,
        range_sigma: 0.0,
        ..Scanner::hokuyo()
    };
    let s = scene::scan(&sc, &scanner, 0.0, 1).unwrap();
    let g = scan_graph(&s.points, s.lines, s.beams, 0.25).unwrap();
    let (normals, ok) = estimate_normals(&s.points, &g, [0.0; 3]);
    let mut checked = 0;
    for (i, (&label, n)) in s.labels.iter().zip(&normals).enumerate() {
        let nb = g.neighbours(i);
        // Interior points: a full neighbourhood on the same object, so one plane.
        if label == UNLABELLED || nb.len() < 8 || nb.iter().any(|&j| s.labels[j as usize] != label)
        {
            continue;
        }
        let t = s.true_normals[i];
        let dot = n[0] * t[0] + n[1] * t[1] + n[2] * t[2];
        if label <= 5 {
            // Floor and walls: one plane each (the ramp and the box have several faces).
            assert!(
                ok[i] && dot > 1.0 - 1e-9,
                "point {i} label {label} dot {dot}"
            );
            checked += 1;
        }
    }
    assert!(checked > 5000, "checked {checked}");
}

fn majority(labels: &[u32], truth: &[u32], object: u32) -> u32 {
    let mut count: HashMap<u32, usize> = HashMap::new();
    for (l, t) in labels.iter().zip(truth) {
        if *t == object && *l != UNLABELLED {
            *count.entry(*l).or_default() += 1;
        }
    }
    count
        .into_iter()
        .max_by_key(|&(l, c)| (c, std::cmp::Reverse(l)))
        .map(|(l, _)| l)
        .unwrap_or(UNLABELLED)
}

/// Labels of the simulated hallway at Table 4.1's 0.75° (truth colours, organised scan).
/// The hallway at ¾° beams and 30°/s tilt (colour noise 3, seed 2): the scan the Fig. 4.4 and
/// reference-label tests share.
fn coarse_hallway() -> scene::Scan {
    let scanner = Scanner {
        beam_step_deg: 0.75,
        tilt_speed_deg_s: 30.0,
        ..Scanner::hokuyo()
    };
    scene::scan(&scene::preset("hallway").unwrap(), &scanner, 3.0, 2).unwrap()
}

fn hallway_labels(criteria: Criteria, k_rgb: f64, k_norm: f64) -> (Vec<u32>, Vec<u32>) {
    let s = coarse_hallway();
    let params = SegmentParams {
        fh: fh(k_rgb, k_norm, 100, criteria),
        edge_cut: 0.25,
        graph: GraphKind::Scan {
            lines: s.lines,
            beams: s.beams,
        },
        viewpoint: [0.0; 3],
    };
    let labels = segment_cloud(&s.points, &s.true_colors, None, &params)
        .unwrap()
        .labels;
    (labels, s.labels)
}

const FLOOR: u32 = 1;
const WALL: u32 = 2;
const GREY_BIN: u32 = 6;
const BLUE_BIN: u32 = 7;

/// Fig. 4.4c and 4.4e on the simulated hallway (Table 4.1 constants): colour alone merges the
/// grey bin with the floor and separates the blue bin from the wall; both criteria should
/// separate both pairs. They do not: see "The unsorted threshold" in docs/design/segmentation.md
/// (the seed's literal eq. (4.3) for the normal weight passes this case but fails others).
#[test]
#[ignore = "open (issue 34): both criteria merge the grey bin with the floor (majority segments \
            4 and 4); the same figure is a strict xfail in tests/test_segment.py"]
fn fig_4_4_colour_alone_and_both_criteria() {
    let (color, truth) = hallway_labels(Criteria::ColorOnly, 1000.0, 0.0);
    assert_eq!(
        majority(&color, &truth, GREY_BIN),
        majority(&color, &truth, FLOOR)
    );
    assert_ne!(
        majority(&color, &truth, BLUE_BIN),
        majority(&color, &truth, WALL)
    );
    let (both, truth) = hallway_labels(Criteria::Both, 9000.0, 10.0);
    assert_ne!(
        majority(&both, &truth, GREY_BIN),
        majority(&both, &truth, FLOOR)
    );
    assert_ne!(
        majority(&both, &truth, BLUE_BIN),
        majority(&both, &truth, WALL)
    );
}

/// Fig. 4.4d on the simulated hallway: normals alone separate the grey bin from the floor
/// and should merge the blue bin with the wall. The simulated blue bin is a sharp-edged box
/// 16 cm deep: the PCA normals along its outline turn by tens of degrees, a crease no
/// segment's normal threshold crosses (see docs/design/segmentation.md).
#[test]
#[ignore = "scene property (issue 34): normals alone keep the simulated blue bin (segment 15) \
            apart from the wall (segment 5); the same figure is a strict xfail in \
            tests/test_segment.py"]
fn fig_4_4_normals_alone() {
    let (normal, truth) = hallway_labels(Criteria::NormalOnly, 0.0, 9.0);
    assert_ne!(
        majority(&normal, &truth, GREY_BIN),
        majority(&normal, &truth, FLOOR)
    );
    assert_eq!(
        majority(&normal, &truth, BLUE_BIN),
        majority(&normal, &truth, WALL)
    );
}

#[test]
fn colorize_handles_behind_outside_and_occluded_points() {
    let cam =
        autoteach_geometry::camera::Camera::pinhole(100.0, 100.0, 50.0, 50.0, 101, 101).unwrap();
    let mut data = vec![0u8; 101 * 101 * 3];
    let k = (50 * 101 + 50) * 3;
    data[k..k + 3].copy_from_slice(&[10, 20, 30]);
    let img = RgbImage {
        width: 101,
        height: 101,
        data: &data,
    };
    let pts = [
        [0.0, 0.0, 1.0],      // centre pixel, coloured
        [0.0, 0.0, 3.0],      // same pixel, behind the first: occluded
        [0.0, 0.0, -1.0],     // behind the camera
        [5.0, 0.0, 1.0],      // outside the image
        [f64::NAN, 0.0, 1.0], // missing
    ];
    let out = colorize(
        &pts,
        &img,
        &cam,
        &Isometry3::identity(),
        &ColorizeParams::default(),
    )
    .unwrap();
    assert_eq!(
        out.status,
        vec![
            PointStatus::Colored,
            PointStatus::Occluded,
            PointStatus::Behind,
            PointStatus::Outside,
            PointStatus::Missing
        ]
    );
    assert_eq!(out.colors[0], [10, 20, 30]);
}

#[test]
fn segmentation_is_deterministic_and_rejects_bad_input() {
    let sc = scene::preset("hallway").unwrap();
    let scanner = Scanner {
        beam_step_deg: 1.0,
        tilt_speed_deg_s: 40.0,
        ..Scanner::hokuyo()
    };
    let s = scene::scan(&sc, &scanner, 3.0, 4).unwrap();
    let valid: Vec<usize> = (0..s.points.len())
        .filter(|&i| s.labels[i] != UNLABELLED)
        .collect();
    let pts: Vec<[f64; 3]> = valid.iter().map(|&i| s.points[i]).collect();
    let cols: Vec<[u8; 3]> = valid.iter().map(|&i| s.true_colors[i]).collect();
    let p = SegmentParams::default();
    let a = segment_cloud(&pts, &cols, None, &p).unwrap();
    let b = segment_cloud(&pts, &cols, None, &p).unwrap();
    assert_eq!(a, b);
    assert!(matches!(
        segment_cloud(&[], &[], None, &p),
        Err(DetectError::TooFewPoints { got: 0, .. })
    ));
    let mut bad = pts.clone();
    bad[17][1] = f64::NAN;
    assert!(matches!(
        segment_cloud(&bad, &cols, None, &p),
        Err(DetectError::NonFinite { index: 17, .. })
    ));
    assert!(matches!(
        segment_cloud(&pts, &cols[1..], None, &p),
        Err(DetectError::WrongLength { .. })
    ));
    let bad_cut = SegmentParams {
        edge_cut: -1.0,
        ..p
    };
    assert!(matches!(
        segment_cloud(&pts, &cols, None, &bad_cut),
        Err(DetectError::InvalidParameter { .. })
    ));
    // Duplicated points: every copy lands in its original's segment.
    let dup: Vec<[f64; 3]> = pts.iter().chain(&pts).copied().collect();
    let dcol: Vec<[u8; 3]> = cols.iter().chain(&cols).copied().collect();
    let d = segment_cloud(
        &dup,
        &dcol,
        None,
        &SegmentParams {
            graph: GraphKind::Knn { k: 9 },
            ..p
        },
    )
    .unwrap();
    let n = pts.len();
    assert!((0..n).all(|i| d.labels[i] == d.labels[i + n]));
}

#[test]
fn simulated_hokuyo_has_the_seed_geometry() {
    let s = Scanner::hokuyo();
    assert_eq!(s.beams(), 1081); // 270° / ¼° + 1
    let tilts = s.tilts();
    assert_eq!(tilts.len(), 121); // 60° at 20°/s = 3 s at 40 Hz
    for t in &tilts {
        let steps = t.to_degrees() * 3.0; // ⅓° servo resolution
        assert!((steps - steps.round()).abs() < 1e-6);
    }
    // A ray straight down from 1 m hits the floor at 1 m.
    let sc = scene::preset("hallway").unwrap();
    let hit = sc
        .intersect(
            &nalgebra::Point3::new(0.0, 0.0, 1.0),
            &Vector3::new(0.0, 0.0, -1.0),
        )
        .unwrap();
    assert!((hit.t - 1.0).abs() < 1e-12 && sc.objects[hit.object].label == 1);
}

/// The segmentation as first written (weights for every edge, a permutation from the one-pass
/// counting sort, weights gathered through it, parents and internal weights in separate
/// arrays): the reference the cache-friendly [`segment_graph`] must reproduce label for label.
fn reference_segment_graph(
    n: usize,
    edges: &[[u32; 2]],
    colors: &[[u8; 3]],
    normals: Option<&[[f64; 3]]>,
    params: &FhParams,
) -> (Vec<u32>, usize) {
    use super::counting_sort::counting_sort_order;
    use super::felzenszwalb::{NORMAL_KEY_QUANTUM, RGB_KEY_MAX, normal_weight, rgb_key};
    use super::union_find::UnionFind;
    let normals = if params.criteria == Criteria::ColorOnly {
        None
    } else {
        normals
    };
    let m = edges.len();
    let mut w_rgb = Vec::with_capacity(m);
    let mut w_norm = Vec::with_capacity(m);
    let mut keys = Vec::with_capacity(m);
    for &[i, j] in edges {
        let k = rgb_key(colors[i as usize], colors[j as usize]);
        w_rgb.push(f64::from(k).sqrt());
        if let Some(nr) = normals {
            w_norm.push(normal_weight(&nr[i as usize], &nr[j as usize]));
        }
        keys.push(k);
    }
    let order = if params.criteria == Criteria::NormalOnly {
        let buckets = (std::f64::consts::PI / NORMAL_KEY_QUANTUM).ceil() as u32 + 1;
        for (k, w) in keys.iter_mut().zip(&w_norm) {
            *k = ((w / NORMAL_KEY_QUANTUM).round() as u32).min(buckets - 1);
        }
        counting_sort_order(&keys, buckets as usize)
    } else {
        counting_sort_order(&keys, RGB_KEY_MAX as usize + 1)
    };
    let use_rgb = params.criteria != Criteria::NormalOnly;
    let use_norm = params.criteria != Criteria::ColorOnly;
    let mut uf = UnionFind::new(n);
    let mut int_rgb = vec![0.0f64; n];
    let mut int_norm = vec![0.0f64; n];
    for &e in &order {
        let e = e as usize;
        let [i, j] = edges[e];
        let (a, b) = (uf.find(i), uf.find(j));
        if a == b {
            continue;
        }
        let (sa, sb) = (f64::from(uf.size(a)), f64::from(uf.size(b)));
        let (ai, bi) = (a as usize, b as usize);
        let wr = w_rgb[e];
        if use_rgb
            && !(wr < int_rgb[ai] + params.k_rgb / sa && wr < int_rgb[bi] + params.k_rgb / sb)
        {
            continue;
        }
        let wn = if use_norm { w_norm[e] } else { 0.0 };
        if use_norm
            && !(wn < int_norm[ai] + params.k_norm / sa && wn < int_norm[bi] + params.k_norm / sb)
        {
            continue;
        }
        let r = uf.union_roots(a, b) as usize;
        int_rgb[r] = int_rgb[ai].max(int_rgb[bi]).max(wr);
        int_norm[r] = int_norm[ai].max(int_norm[bi]).max(wn);
    }
    if params.min_size > 1 {
        let min = params.min_size as u32;
        for &e in &order {
            let [i, j] = edges[e as usize];
            let (a, b) = (uf.find(i), uf.find(j));
            if a != b && (uf.size(a) < min || uf.size(b) < min) {
                uf.union_roots(a, b);
            }
        }
    }
    uf.labels()
}

/// The speed-up (records sorted digit by digit, normal weights only for edges the colour test
/// passes, packed union–find records) leaves the labels unchanged: the simulated hallway in
/// all three modes, and random graphs with random colours and normals.
#[test]
fn fast_segmentation_matches_the_reference_labels() {
    let s = coarse_hallway();
    let graph = scan_graph(&s.points, s.lines, s.beams, 0.25).unwrap();
    let (normals, _) = estimate_normals(&s.points, &graph, [0.0; 3]);
    let n = s.points.len();
    for p in [
        fh(9000.0, 10.0, 100, Criteria::Both),
        fh(1000.0, 0.0, 100, Criteria::ColorOnly),
        fh(0.0, 9.0, 100, Criteria::NormalOnly),
        fh(300.0, 0.5, 1, Criteria::Both),
    ] {
        let fast = segment_graph(n, &graph.edges, &s.true_colors, Some(&normals), &p).unwrap();
        let (labels, k) =
            reference_segment_graph(n, &graph.edges, &s.true_colors, Some(&normals), &p);
        assert_eq!(fast.num_segments, k, "{p:?}");
        assert_eq!(fast.labels, labels, "{p:?}");
    }
    let mut rng = SimRng::new(7);
    for trial in 0..20 {
        let n = 50 + trial * 20;
        let edges: Vec<[u32; 2]> = (0..3 * n)
            .map(|_| {
                let i = (rng.uniform() * n as f64) as u32 % n as u32;
                let j = (rng.uniform() * n as f64) as u32 % n as u32;
                [i.min(j), i.max(j)]
            })
            .filter(|e| e[0] != e[1])
            .collect();
        // Few colour levels, so equal keys (ties in the sort) are common.
        let colors: Vec<[u8; 3]> = (0..n)
            .map(|_| [0; 3].map(|_: u8| ((rng.uniform() * 4.0) as u8) * 20))
            .collect();
        let normals: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                let v = [rng.normal(), rng.normal(), rng.normal() + 3.0];
                let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                [v[0] / l, v[1] / l, v[2] / l]
            })
            .collect();
        for p in [
            fh(60.0, 0.8, 3, Criteria::Both),
            fh(60.0, 0.0, 1, Criteria::ColorOnly),
            fh(0.0, 0.8, 4, Criteria::NormalOnly),
        ] {
            let fast = segment_graph(n, &edges, &colors, Some(&normals), &p).unwrap();
            let (labels, _) = reference_segment_graph(n, &edges, &colors, Some(&normals), &p);
            assert_eq!(fast.labels, labels, "trial {trial} {p:?}");
        }
    }
}

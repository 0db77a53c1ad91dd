use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

use super::iou::iou;
use super::jiou::{JiouOptions, ProbBox, jiou, jiou_batch, probabilistic_jaccard};
use super::moments::{BoxMoments, linearised_point_cov};
use super::scan::{ScanOptions, ray_hit, scan_box, simulate_cars};
use super::spatial::{Grid2, Weighting, pg_moments_at, rasterize};
use super::*;

fn zero() -> Cov5 {
    [[0.0; 5]; 5]
}

fn diag(d: [f64; 5]) -> Cov5 {
    let mut c = zero();
    for i in 0..5 {
        c[i][i] = d[i];
    }
    c
}

#[test]
fn iou_of_axis_aligned_boxes_is_the_closed_form() {
    let a = Box2::new(0.0, 0.0, 4.0, 2.0, 0.0).unwrap();
    let b = Box2::new(1.0, 0.5, 4.0, 2.0, 0.0).unwrap();
    // Overlap 3 × 1.5.
    let inter = 3.0 * 1.5;
    assert!((iou(&a, &b) - inter / (16.0 - inter)).abs() < 1e-12);
    // A box rotated by 90° about its centre covers a 2×2 square of the original: 4/(8+8−4).
    let c = Box2::new(0.0, 0.0, 4.0, 2.0, std::f64::consts::FRAC_PI_2).unwrap();
    assert!((iou(&a, &c) - 4.0 / 12.0).abs() < 1e-12);
    // A square rotated by 45° inside a square of side 2: octagon area 8(√2−1).
    let s = Box2::new(0.0, 0.0, 2.0, 2.0, 0.0).unwrap();
    let t = Box2::new(0.0, 0.0, 2.0, 2.0, std::f64::consts::FRAC_PI_4).unwrap();
    let oct = 8.0 * (2f64.sqrt() - 1.0);
    assert!((iou(&s, &t) - oct / (8.0 - oct)).abs() < 1e-12);
    let far = Box2::new(10.0, 0.0, 1.0, 1.0, 0.3).unwrap();
    assert_eq!(iou(&a, &far), 0.0);
    assert!((iou(&a, &a) - 1.0).abs() < 1e-12);
}

#[test]
fn bad_boxes_and_covariances_are_rejected() {
    assert!(Box2::new(0.0, 0.0, 0.0, 1.0, 0.0).is_err());
    assert!(Box2::new(0.0, 0.0, 1.0, -1.0, 0.0).is_err());
    assert!(Box2::new(f64::NAN, 0.0, 1.0, 1.0, 0.0).is_err());
    let mut c = diag([1.0, 1.0, 1.0, 1.0, 1.0]);
    c[0][1] = 2.0;
    c[1][0] = 2.0;
    let err = check_covariance(&c).unwrap_err();
    assert!(err.to_string().contains("positive semi-definite"), "{err}");
    c[1][0] = 0.0;
    assert!(
        check_covariance(&c)
            .unwrap_err()
            .to_string()
            .contains("symmetric")
    );
    // Singular but PSD is fine.
    assert!(check_covariance(&diag([1.0, 0.0, 0.0, 0.0, 0.0])).is_ok());
}

#[test]
fn moments_match_closed_form_under_heading_uncertainty() {
    // Only r uncertain: E[V(½,0)] = c + l/2·e^{−σ²/2}(cos μ, sin μ) and
    // Cov = (l/2)²·[[E cos² − (E cos)², …]].
    let b = Box2::new(1.0, 2.0, 4.0, 2.0, 0.3).unwrap();
    let s2 = 0.2f64.powi(2);
    let m = BoxMoments::new(&b, &diag([0.0, 0.0, 0.0, 0.0, s2]));
    let (mean, cov) = m.point([0.5, 0.0]);
    let e = (-s2 / 2.0).exp();
    assert!((mean[0] - (1.0 + 2.0 * e * 0.3f64.cos())).abs() < 1e-12);
    assert!((mean[1] - (2.0 + 2.0 * e * 0.3f64.sin())).abs() < 1e-12);
    // E[cos² r] = ½(1 + e^{−2σ²} cos 2μ).
    let ecos2 = 0.5 * (1.0 + (-2.0 * s2).exp() * (0.6f64).cos());
    let var_x = 4.0 * (ecos2 - (e * 0.3f64.cos()).powi(2));
    assert!(
        (cov[0][0] - var_x).abs() < 1e-12,
        "{} vs {}",
        cov[0][0],
        var_x
    );
}

#[test]
fn moments_match_monte_carlo_and_linearisation() {
    let b = Box2::new(0.5, -1.0, 4.5, 1.9, 1.1).unwrap();
    let mut c = diag([0.04, 0.03, 0.09, 0.02, 0.01]);
    c[0][2] = -0.03;
    c[2][0] = -0.03;
    c[3][4] = 0.005;
    c[4][3] = 0.005;
    let l = check_covariance(&c).unwrap();
    let m = BoxMoments::new(&b, &c);
    let v0 = [0.5, -0.5];
    let (mean, cov) = m.point(v0);
    let mut rng = Pcg64::seed_from_u64(3);
    let n = 200_000;
    let (mut s, mut ss) = ([0.0; 2], [[0.0; 2]; 2]);
    for _ in 0..n {
        let z: [f64; 5] = std::array::from_fn(|_| StandardNormal.sample(&mut rng));
        let mut y = b.params();
        for i in 0..5 {
            for j in 0..5 {
                y[i] += l[i][j] * z[j];
            }
        }
        let p = Box2 {
            cx: y[0],
            cy: y[1],
            l: y[2],
            w: y[3],
            r: y[4],
        }
        .point(v0);
        for a in 0..2 {
            s[a] += p[a];
            for bb in 0..2 {
                ss[a][bb] += p[a] * p[bb];
            }
        }
    }
    for a in 0..2 {
        let mc = s[a] / n as f64;
        assert!((mc - mean[a]).abs() < 3e-3, "mean {a}: {mc} vs {}", mean[a]);
        for bb in 0..2 {
            let mc = ss[a][bb] / n as f64 - s[a] / n as f64 * s[bb] / n as f64;
            assert!(
                (mc - cov[a][bb]).abs() < 0.02 * cov[a][a].max(cov[bb][bb]),
                "cov {a}{bb}: {mc} vs {}",
                cov[a][bb]
            );
        }
    }
    // Small heading variance: linearisation agrees to first order.
    let lin = linearised_point_cov(&b, &c, v0);
    assert!((lin[0][0] - cov[0][0]).abs() < 0.05 * cov[0][0]);
}

/// Brute-force `Σ_i 1/Σ_j max(p1_j/p1_i, p2_j/p2_i)`.
fn jaccard_naive(p1: &[f64], p2: &[f64]) -> f64 {
    let mut j = 0.0;
    for i in 0..p1.len() {
        if p1[i] > 0.0 && p2[i] > 0.0 {
            let s: f64 = (0..p1.len())
                .map(|k| (p1[k] / p1[i]).max(p2[k] / p2[i]))
                .sum();
            j += 1.0 / s;
        }
    }
    j
}

#[test]
fn probabilistic_jaccard_equals_the_quadratic_definition() {
    let mut rng = Pcg64::seed_from_u64(11);
    for _ in 0..50 {
        let n = rng.random_range(1..200);
        let gen_p = |rng: &mut Pcg64| -> Vec<f64> {
            (0..n)
                .map(|_| {
                    if rng.random_bool(0.3) {
                        0.0
                    } else {
                        rng.random_range(0.0..1.0)
                    }
                })
                .collect()
        };
        let mut p1 = gen_p(&mut rng);
        let mut p2 = gen_p(&mut rng);
        p1[0] = 0.5;
        p2[0] = 0.25;
        // Ties in the ratio.
        if n > 3 {
            p1[1] = 1.0;
            p2[1] = 0.5;
        }
        let fast = probabilistic_jaccard(&p1, &p2).unwrap();
        assert!((fast - jaccard_naive(&p1, &p2)).abs() < 1e-12);
        // Scale invariance.
        let p3: Vec<f64> = p1.iter().map(|v| 7.0 * v).collect();
        assert!((probabilistic_jaccard(&p3, &p2).unwrap() - fast).abs() < 1e-12);
    }
    assert!(probabilistic_jaccard(&[0.0, 0.0], &[1.0, 0.0]).is_err());
    assert!(probabilistic_jaccard(&[1.0], &[1.0, 0.0]).is_err());
    assert!(probabilistic_jaccard(&[-1.0, 1.0], &[1.0, 0.0]).is_err());
}

/// The packed sort keys (cell index in the ratio's low bits) may swap ratios within a relative
/// `2^(k−52)`; the result stays within that of the exact tuple sort and of the definition, also
/// when many ratios are that close.
#[test]
fn packed_sort_keys_stay_within_their_stated_bound() {
    let mut rng = Pcg64::seed_from_u64(12);
    let n = 900;
    let bound = 2f64.powi(10 - 52);
    for _ in 0..20 {
        let p2: Vec<f64> = (0..n).map(|_| rng.random_range(0.1..1.0)).collect();
        // Ratios in a handful of clusters, each spread over a few ulps of the packing.
        let p1: Vec<f64> = p2
            .iter()
            .map(|b| {
                let t = [0.5, 1.0, 2.0][rng.random_range(0..3)]
                    * (1.0 + bound * rng.random_range(-4.0..4.0));
                if rng.random_bool(0.2) { 0.0 } else { b * t }
            })
            .collect();
        let (mut buf, mut keys) = (Vec::new(), Vec::new());
        let packed = super::jiou::jaccard_unchecked(&p1, &p2, &mut buf, &mut keys);
        let exact = super::jiou::jaccard_tuples(&p1, &p2, &mut buf);
        let naive = jaccard_naive(&p1, &p2);
        assert!(
            (packed - exact).abs() <= 8.0 * bound * exact,
            "{packed} {exact}"
        );
        assert!((packed - naive).abs() <= 1e-12 * naive, "{packed} {naive}");
    }
}

#[test]
fn fig_8_5_jiou_is_one_half_under_pg_and_near_zero_under_pdq() {
    // Label: two equally likely boxes, a large and a small one (disjoint); prediction = the small.
    let big = Box2::new(0.0, 0.0, 8.0, 4.0, 0.0).unwrap();
    let small = Box2::new(7.0, 0.0, 2.0, 1.0, 0.0).unwrap();
    let grid = Grid2::new(-5.0, -3.0, 0.05, 0.05, 260, 120).unwrap();
    let (label_g, _) = rasterize(&[big, small], &[0.5, 0.5], &grid, Weighting::Density).unwrap();
    let (pred, _) = rasterize(&[small], &[1.0], &grid, Weighting::Density).unwrap();
    let j = probabilistic_jaccard(&label_g, &pred).unwrap();
    assert!((j - 0.5).abs() < 1e-12, "JIoU under p_G = {j}");
    let (label_pdq, _) =
        rasterize(&[big, small], &[0.5, 0.5], &grid, Weighting::Indicator).unwrap();
    let jp = probabilistic_jaccard(&label_pdq, &pred).unwrap();
    // Closed form on the grid: n_small / (n_small + n_big).
    let count = |b: &Box2| grid.centres().iter().filter(|u| b.contains(**u)).count() as f64;
    let (ns, nb) = (count(&small), count(&big));
    assert!((jp - ns / (ns + nb)).abs() < 1e-12);
    assert!(jp < 0.06, "JIoU under P_PDQ = {jp}");
}

#[test]
fn jiou_of_nested_label_boxes_is_the_closed_form() {
    // When the small box lies inside the large one the seed's "0.5 whatever the sizes" becomes
    // (A_s + A_b)/(2 A_b) (cell counts): documented in docs/design/boxes-pooling.md.
    let big = Box2::new(0.0, 0.0, 8.0, 4.0, 0.0).unwrap();
    let small = Box2::new(1.0, 0.5, 2.0, 1.0, 0.0).unwrap();
    let grid = Grid2::new(-5.0, -3.0, 0.05, 0.05, 200, 120).unwrap();
    let (label, _) = rasterize(&[big, small], &[0.5, 0.5], &grid, Weighting::Density).unwrap();
    let (pred, _) = rasterize(&[small], &[1.0], &grid, Weighting::Density).unwrap();
    let count = |b: &Box2| grid.centres().iter().filter(|u| b.contains(**u)).count() as f64;
    let (ns, nb) = (count(&small), count(&big));
    let j = probabilistic_jaccard(&label, &pred).unwrap();
    assert!((j - (ns + nb) / (2.0 * nb)).abs() < 1e-12);
}

#[test]
fn deterministic_jiou_is_iou_and_grid_jiou_approaches_it() {
    let a = ProbBox::new(Box2::new(0.0, 0.0, 4.0, 2.0, 0.2).unwrap(), zero()).unwrap();
    let b = ProbBox::new(Box2::new(0.7, 0.3, 3.5, 1.8, -0.1).unwrap(), zero()).unwrap();
    let exact = iou(&a.mean, &b.mean);
    assert_eq!(jiou(&a, &b, &JiouOptions::default()).unwrap(), exact);
    // A tiny covariance goes through the grid: cell IoU on 300² cells.
    let tiny = diag([1e-14; 5]);
    let a2 = ProbBox::new(a.mean, tiny).unwrap();
    let j = jiou(
        &a2,
        &b,
        &JiouOptions {
            grid: 300,
            ..Default::default()
        },
    )
    .unwrap();
    assert!((j - exact).abs() < 0.01, "{j} vs {exact}");
}

#[test]
fn jiou_batch_matches_single_calls_and_thread_counts() {
    let mut rng = Pcg64::seed_from_u64(5);
    let mut a = Vec::new();
    let mut b = Vec::new();
    for _ in 0..40 {
        let m = Box2::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            4.0,
            1.8,
            rng.random_range(-0.3..0.3),
        )
        .unwrap();
        a.push(ProbBox::new(m, diag([0.04, 0.02, 0.05, 0.01, 0.005])).unwrap());
        b.push(ProbBox::new(Box2::new(0.0, 0.0, 4.2, 1.7, 0.0).unwrap(), zero()).unwrap());
    }
    let opts = JiouOptions::default();
    let all = jiou_batch(&a, &b, &opts).unwrap();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| jiou_batch(&a, &b, &opts).unwrap());
    assert_eq!(all, one);
    for i in [0, 17, 39] {
        assert_eq!(all[i], jiou(&a[i], &b[i], &opts).unwrap());
    }
}

#[test]
fn sampled_pg_sums_to_one_and_moment_pg_integrates_to_one() {
    let m = Box2::new(0.0, 0.0, 4.0, 2.0, 0.4).unwrap();
    let c = diag([0.04, 0.04, 0.09, 0.04, 0.01]);
    let grid = Grid2::new(-5.0, -5.0, 0.1, 0.1, 100, 100).unwrap();
    let table = spatial::normal_table(64, 1);
    let p = spatial::sampled_on_grid(&m, &c, &grid, &table, Weighting::Density).unwrap();
    assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-9);
    let q = pg_moments_at(&m, &c, &grid.centres(), 20).unwrap();
    let integral: f64 = q.iter().sum::<f64>() * 0.01;
    assert!((integral - 1.0).abs() < 1e-3, "{integral}");
    // A deterministic box: the moment p_G is ≈ 1/A well inside and ≈ 0 well outside.
    let d = pg_moments_at(&m, &zero(), &[[0.0, 0.0], [3.0, 3.0]], 40).unwrap();
    assert!((d[0] * m.area() - 1.0).abs() < 0.02, "{}", d[0] * m.area());
    assert!(d[1] < 1e-6);
}

#[test]
fn scans_hit_the_visible_boundary() {
    let b = Box2::new(10.0, 3.0, 4.2, 1.8, 0.5).unwrap();
    let opts = ScanOptions {
        sigma: 0.0,
        ..Default::default()
    };
    let mut rng = Pcg64::seed_from_u64(1);
    let pts = scan_box(&b, &opts, false, &mut rng).unwrap();
    assert!(pts.len() > 20);
    let (s, c) = b.r.sin_cos();
    for p in &pts {
        let (dx, dy) = (p[0] - b.cx, p[1] - b.cy);
        let (u, v) = ((c * dx + s * dy).abs(), (-s * dx + c * dy).abs());
        let d = (u - 0.5 * b.l).abs().min((v - 0.5 * b.w).abs());
        assert!(d < 1e-9 && u <= 0.5 * b.l + 1e-9 && v <= 0.5 * b.w + 1e-9);
    }
    assert!(ray_hit(&b, 3.0).is_none());
    let cars = simulate_cars(20, &ScanOptions::default(), 10, 7).unwrap();
    assert_eq!(cars.len(), 20);
    assert!(cars.iter().all(|(_, p)| p.len() >= 10));
}

#[test]
fn boundary_unit_points_lie_on_the_unit_box_boundary() {
    let b = Box2::new(0.0, 0.0, 4.0, 2.0, 0.0).unwrap();
    let pts = b.boundary_unit_points(120);
    assert_eq!(pts.len(), 120);
    for p in &pts {
        assert!(((p[0].abs() - 0.5).abs() < 1e-12) || ((p[1].abs() - 0.5).abs() < 1e-12));
    }
    // Even arc-length spacing: 4 m sides hold twice the points of 2 m sides.
    let long = pts
        .iter()
        .filter(|p| (p[1].abs() - 0.5).abs() < 1e-12)
        .count();
    assert_eq!(long, 80);
}

#[test]
fn box3_follows_eq_8_1() {
    let b = Box3::new(
        [1.0, 2.0, 0.5],
        [4.0, 2.0, 1.5],
        std::f64::consts::FRAC_PI_2,
    )
    .unwrap();
    let p = b.point([0.5, 0.0, 0.5]);
    assert!(
        (p[0] - 1.0).abs() < 1e-12 && (p[1] - 4.0).abs() < 1e-12 && (p[2] - 1.25).abs() < 1e-12
    );
    assert!((b.volume() - 12.0).abs() < 1e-12);
    assert_eq!(b.bev().l, 4.0);
    assert!(Box3::new([0.0; 3], [1.0, 1.0, 0.0], 0.0).is_err());
}

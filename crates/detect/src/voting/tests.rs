use super::*;
use nalgebra::{Rotation2, Vector2};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::collections::HashMap;

/// A chevron-like 2-D model: two arms of different length and a short hook.
fn model2(spacing: f64) -> Vec<Vector2<f64>> {
    let mut pts = Vec::new();
    let mut seg = |a: Vector2<f64>, b: Vector2<f64>| {
        let n = ((b - a).norm() / spacing).round() as usize;
        for k in 0..n {
            pts.push(a + (b - a) * (k as f64 / n as f64));
        }
    };
    seg(Vector2::new(0.0, 0.0), Vector2::new(2.0, 1.0));
    seg(Vector2::new(2.0, 1.0), Vector2::new(3.2, -0.4));
    seg(Vector2::new(3.2, -0.4), Vector2::new(2.7, -0.9));
    pts
}

fn to_mat2(p: &[Vector2<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(p.len(), 2, |r, c| p[r][c])
}

fn angle(r: &DMatrix<f64>) -> f64 {
    r[(1, 0)].atan2(r[(0, 0)])
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

#[test]
fn recovers_2d_transform_with_clutter_and_angle_wrap() {
    let y = model2(0.05);
    for (seed, deg) in [(1u64, 179.0f64), (2, -179.0), (3, 90.0), (4, 3.0)] {
        let mut rng = Pcg64::seed_from_u64(seed);
        let rot = Rotation2::new(deg.to_radians());
        let t = Vector2::new(5.0, -2.0);
        let mut x: Vec<Vector2<f64>> = y
            .iter()
            .map(|p| rot * p + t + Vector2::new(rng.random_range(-0.005..0.005), 0.0))
            .collect();
        for _ in 0..60 {
            x.push(Vector2::new(
                rng.random_range(0.0..10.0),
                rng.random_range(-6.0..2.0),
            ));
        }
        let h = global_voting(&to_mat2(&x), &to_mat2(&y), &VotingOptions::default()).unwrap();
        assert!(!h.is_empty() && h.len() <= 3);
        let best = &h[0];
        assert!(
            wrap(angle(&best.rotation) - deg.to_radians()).abs() < 0.05,
            "{deg}: {:?}",
            best.rotation
        );
        let moved = &best.rotation * DVector::from_vec(vec![1.0, 0.5]) + &best.translation;
        let truth = rot * Vector2::new(1.0, 0.5) + t;
        assert!(
            (moved[0] - truth[0]).hypot(moved[1] - truth[1]) < 0.08,
            "{deg}: {moved:?} vs {truth:?}"
        );
        assert!(
            best.votes as f64 > 0.8 * y.len() as f64,
            "votes {} of {}",
            best.votes,
            y.len()
        );
        assert!(best.pair_votes >= best.votes);
        // Rotation is proper.
        assert!((best.rotation.determinant() - 1.0).abs() < 1e-9);
    }
}

/// A 3-D model with distinct local shapes: a helix-like curve plus two planar patches.
fn model3(rng: &mut Pcg64) -> Vec<Vector3<f64>> {
    let mut pts = Vec::new();
    for k in 0..150 {
        let s = k as f64 / 150.0 * 3.0;
        pts.push(Vector3::new(s.cos(), s.sin(), 0.3 * s));
    }
    for _ in 0..150 {
        pts.push(Vector3::new(
            rng.random_range(-1.0..0.0),
            rng.random_range(-0.5..0.5),
            -0.5,
        ));
    }
    for _ in 0..100 {
        pts.push(Vector3::new(
            1.3,
            rng.random_range(-0.3..0.3),
            rng.random_range(0.0..0.8),
        ));
    }
    pts
}

#[test]
fn recovers_3d_transform() {
    let mut rng = Pcg64::seed_from_u64(7);
    let y = model3(&mut rng);
    let rot = Rotation3::from_euler_angles(2.5, -0.7, -3.0);
    let t = Vector3::new(0.4, -1.0, 2.0);
    let x: Vec<Vector3<f64>> = y.iter().map(|p| rot * p + t).collect();
    let xm = DMatrix::from_fn(x.len(), 3, |r, c| x[r][c]);
    let ym = DMatrix::from_fn(y.len(), 3, |r, c| y[r][c]);
    let opts = VotingOptions {
        max_points: 200,
        ..VotingOptions::default()
    };
    let h = global_voting(&xm, &ym, &opts).unwrap();
    let best = &h[0];
    let r = Matrix3::from_fn(|a, b| best.rotation[(a, b)]);
    let err = rotation_angle_between(&r, rot.matrix());
    assert!(err < 0.1, "rotation error {err}");
    let c = Vector3::new(0.0, 0.0, 0.5);
    let moved = r * c
        + Vector3::new(
            best.translation[0],
            best.translation[1],
            best.translation[2],
        );
    assert!((moved - (rot * c + t)).norm() < 0.15, "{moved:?}");
}

/// Fig. 3.12: X holds a sparse copy of the model and a dense straight edge; the dense edge
/// collects more *pairs* for a wrong transform, the Y-count still picks the right one.
#[test]
fn y_count_beats_pair_count_on_density_mismatch() {
    let y = model2(0.05);
    let rot = Rotation2::new(0.6);
    let t = Vector2::new(1.0, 4.0);
    let mut x: Vec<Vector2<f64>> = y.iter().map(|p| rot * p + t).collect();
    // Dense outlier edge (10× the sampling density), far from the model copy.
    for k in 0..600 {
        x.push(Vector2::new(6.0 + k as f64 * 0.005, -3.0));
    }
    let (xm, ym) = (to_mat2(&x), to_mat2(&y));
    let ok = |h: &RigidHypothesis| {
        let moved = &h.rotation * DVector::from_vec(vec![1.0, 0.5]) + &h.translation;
        let truth = rot * Vector2::new(1.0, 0.5) + t;
        (moved[0] - truth[0]).hypot(moved[1] - truth[1]) < 0.1
    };
    let ycount = global_voting(&xm, &ym, &VotingOptions::default()).unwrap();
    let pairs = global_voting(
        &xm,
        &ym,
        &VotingOptions {
            count: VoteCount::Pairs,
            ..VotingOptions::default()
        },
    )
    .unwrap();
    assert!(ok(&ycount[0]), "Y-count picked {:?}", ycount[0]);
    assert!(
        !ok(&pairs[0]),
        "pair count should be fooled by the dense edge: {:?}",
        pairs[0]
    );
    assert!(pairs[0].pair_votes > ycount[0].pair_votes);
}

/// Algorithm 3's recursive bucketing finds exactly the cells of a brute-force grouping by the
/// full bin tuple.
#[test]
fn recursive_bucketing_matches_hash_grouping() {
    let mut rng = Pcg64::seed_from_u64(11);
    let y: Vec<Vector2<f64>> = (0..60)
        .map(|_| Vector2::new(rng.random(), rng.random()))
        .collect();
    let x: Vec<Vector2<f64>> = (0..80)
        .map(|_| Vector2::new(rng.random(), rng.random::<f64>() * 2.0))
        .collect();
    let o = VotingOptions {
        min_votes: 2,
        ..VotingOptions::default()
    };
    let p = prepare(&to_mat2(&x), &to_mat2(&y), &o).unwrap();
    let pairs = candidate_pairs(&p, &o).unwrap();
    for shift in [0.0, 0.5] {
        let b = binners(&p, &pairs, shift).unwrap();
        let cells = cluster(&pairs, &b, p.y_sub.len(), o.min_votes);
        let mut groups: HashMap<Vec<usize>, Vec<u32>> = HashMap::new();
        for q in 0..pairs.i.len() {
            let key: Vec<usize> = (0..pairs.dv)
                .map(|d| b[d].bin(pairs.vals[q * pairs.dv + d]))
                .collect();
            groups.entry(key).or_default().push(q as u32);
        }
        let mut expected: Vec<(usize, usize)> = groups
            .values()
            .map(|m| {
                let mut js: Vec<u32> = m.iter().map(|&q| pairs.j[q as usize]).collect();
                js.sort_unstable();
                js.dedup();
                (m.len(), js.len())
            })
            .filter(|&(n, v)| n >= 2 && v >= 2)
            .collect();
        let mut got: Vec<(usize, usize)> = cells.iter().map(|c| (c.pair_votes, c.votes)).collect();
        expected.sort_unstable();
        got.sort_unstable();
        assert!(!got.is_empty());
        assert_eq!(got, expected);
    }
}

#[test]
fn local_frames_follow_circle_tangents() {
    let n = 200;
    let p = DMatrix::from_fn(n, 2, |r, c| {
        let a = r as f64 / n as f64 * 2.0 * PI;
        if c == 0 { 3.0 * a.cos() } else { 3.0 * a.sin() }
    });
    let f = local_frames(&p, 7).unwrap();
    for (r, fr) in f.iter().enumerate() {
        let fr = fr.as_ref().unwrap();
        let a = r as f64 / n as f64 * 2.0 * PI;
        // First axis ⟂ radius.
        assert!((fr[(0, 0)] * a.cos() + fr[(1, 0)] * a.sin()).abs() < 1e-9);
        assert!((fr.determinant() - 1.0).abs() < 1e-9);
    }
}

#[test]
fn deterministic() {
    let y = model2(0.05);
    let x: Vec<Vector2<f64>> = y.iter().map(|p| Rotation2::new(1.0) * p).collect();
    let a = global_voting(&to_mat2(&x), &to_mat2(&y), &VotingOptions::default()).unwrap();
    let b = global_voting(&to_mat2(&x), &to_mat2(&y), &VotingOptions::default()).unwrap();
    assert_eq!(a, b);
}

/// Voting is invariant to the units: the same scene in units 1e±150 (where squared
/// distances and f32 votes would overflow or underflow) gives the same rotation and the
/// translation scaled by the unit.
#[test]
fn huge_and_tiny_coordinates_give_the_scaled_answer() {
    let y = model2(0.05);
    let rot = Rotation2::new(0.7);
    let t = Vector2::new(3.0, -1.0);
    let x: Vec<Vector2<f64>> = y.iter().map(|p| rot * p + t).collect();
    let o = VotingOptions::default();
    let base = global_voting(&to_mat2(&x), &to_mat2(&y), &o).unwrap();
    for unit in [1e-150, 1e40, 1e155, 1e300] {
        let xs = to_mat2(&x) * unit;
        let ys = to_mat2(&y) * unit;
        let h = global_voting(&xs, &ys, &o).unwrap();
        assert_eq!(h.len(), base.len(), "unit {unit}");
        assert!(
            (&h[0].rotation - &base[0].rotation).amax() < 1e-9,
            "unit {unit}"
        );
        let tr = &h[0].translation / unit;
        assert!((tr - &base[0].translation).amax() < 1e-6, "unit {unit}");
        assert!((angle(&h[0].rotation) - 0.7).abs() < 0.05);
    }
    // A bin too small for the data is reported in the caller's units.
    let tiny = VotingOptions {
        translation_bin: Some(1e-9),
        ..VotingOptions::default()
    };
    match global_voting(&(to_mat2(&x) * 1e40), &(to_mat2(&y) * 1e40), &tiny) {
        Err(DetectError::InvalidParameter {
            what: "translation_bin",
            value,
            ..
        }) => assert!((value / 1e-9 - 1.0).abs() < 1e-9, "{value}"),
        other => panic!("{other:?}"),
    }
}
#[test]
fn bad_inputs_are_errors() {
    let y = to_mat2(&model2(0.1));
    let o = VotingOptions::default();
    // Fewer points than dimensions + 1.
    let few = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 1.0, 1.0]);
    assert!(matches!(
        global_voting(&few, &y, &o),
        Err(DetectError::TooFewPoints {
            got: 2,
            needed: 3,
            ..
        })
    ));
    // Identical points.
    let same = DMatrix::from_element(10, 2, 1.5);
    assert!(matches!(
        global_voting(&same, &y, &o),
        Err(DetectError::Degenerate { .. })
    ));
    // NaN.
    let mut nan = y.clone();
    nan[(4, 1)] = f64::NAN;
    assert!(matches!(
        global_voting(&y, &nan, &o),
        Err(DetectError::NonFinite {
            what: "Y",
            index: 4,
            ..
        })
    ));
    // Mismatched dimensions.
    let y3 = DMatrix::from_fn(10, 3, |r, c| (r * 3 + c) as f64);
    assert!(matches!(
        global_voting(&y, &y3, &o),
        Err(DetectError::WrongLength {
            got: 3,
            expected: 2,
            ..
        })
    ));
    // Wrong dimension.
    let y4 = DMatrix::from_fn(10, 4, |r, c| (r * 4 + c) as f64);
    assert!(matches!(
        global_voting(&y4, &y4, &o),
        Err(DetectError::InvalidParameter { .. })
    ));
    // Bad options.
    for bad in [
        VotingOptions {
            angle_bin: 0.0,
            ..o.clone()
        },
        VotingOptions {
            angle_bin: f64::NAN,
            ..o.clone()
        },
        VotingOptions {
            translation_bin: Some(-1.0),
            ..o.clone()
        },
        VotingOptions {
            top_k: 0,
            ..o.clone()
        },
        VotingOptions {
            max_pairs: 10,
            ..o.clone()
        },
    ] {
        assert!(
            matches!(
                global_voting(&y, &y, &bad),
                Err(DetectError::InvalidParameter { .. })
            ),
            "{bad:?}"
        );
    }
}

//! Tests of `global_register` against generated ground truth.

use super::*;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Points spaced `step` along the polyline `v`.
fn polyline(v: &[[f64; 2]], step: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    for w in v.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        let n = (len / step).ceil() as usize;
        for k in 0..n {
            let f = k as f64 / n as f64;
            out.push([a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]);
        }
    }
    out
}

fn mat(p: &[[f64; 2]]) -> DMatrix<f64> {
    DMatrix::from_fn(p.len(), 2, |r, c| p[r][c])
}

fn rot2(a: f64) -> DMatrix<f64> {
    let (s, c) = a.sin_cos();
    DMatrix::from_row_slice(2, 2, &[c, -s, s, c])
}

/// The chevron with a tail of issue 29.
fn chevron(step: f64) -> Vec<[f64; 2]> {
    let mut p = polyline(
        &[
            [-1.0, 1.0],
            [0.0, 0.0],
            [-1.0, -1.0],
            [-0.55, -1.0],
            [0.45, 0.0],
            [-0.55, 1.0],
            [-1.0, 1.0],
        ],
        step,
    );
    p.extend(polyline(&[[0.45, 0.0], [1.3, 0.2]], step));
    p
}

fn rms(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    ((a - b).norm_squared() / a.nrows() as f64).sqrt()
}

#[test]
fn chevron_with_partial_distractor_and_clutter_is_found() {
    let y = mat(&chevron(0.03));
    let size = extent(&y);
    for seed in 0..4u64 {
        let mut rng = Pcg64::seed_from_u64(seed);
        let a = rng.random_range(-3.1..3.1);
        let (r, t) = (rot2(a), DVector::from_vec(vec![1.0, -0.5]));
        let truth = apply(&y, &r, &t);
        // Scene: the chevron resampled at another phase, a 0.9-scaled copy with 30 % cut
        // away at another pose, and uniform clutter.
        let target = apply(&mat(&chevron(0.027)), &r, &t);
        let copy: Vec<[f64; 2]> = chevron(0.03)
            .into_iter()
            .filter(|p| p[0] > -0.6)
            .map(|p| [0.9 * p[0], 0.9 * p[1]])
            .collect();
        let distractor = apply(
            &mat(&copy),
            &rot2(a + 2.0),
            &DVector::from_vec(vec![-2.5, 2.0]),
        );
        let mut rows: Vec<[f64; 2]> = Vec::new();
        for m in [&target, &distractor] {
            for i in 0..m.nrows() {
                let n = [
                    rng.random_range(-0.005..0.005),
                    rng.random_range(-0.005..0.005),
                ];
                rows.push([m[(i, 0)] + n[0], m[(i, 1)] + n[1]]);
            }
        }
        for _ in 0..200 {
            rows.push([rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0)]);
        }
        let x = mat(&rows);
        let res = global_register(&x, &y, &GlobalRegisterOptions::default()).unwrap();
        let e = rms(&res.rigid.transformed, &truth);
        assert!(e < 0.02 * size, "seed {seed}: RMS {e} ≥ 2 % of {size}");
        assert!(
            !res.ambiguous,
            "seed {seed}: the chevron has no rotational symmetry"
        );
        // The distractor's candidate (if refined) explains less of the template.
        assert!(res.candidates[0].explained > 0.95);
    }
}

#[test]
fn square_reports_its_four_fold_symmetry() {
    let y = mat(&polyline(
        &[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]],
        0.025,
    ));
    let a = 0.3;
    let t = DVector::from_vec(vec![2.0, 1.0]);
    let x = apply(
        &mat(&polyline(
            &[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]],
            0.02,
        )),
        &rot2(a),
        &t,
    );
    let res = global_register(&x, &y, &GlobalRegisterOptions::default()).unwrap();
    assert!(res.ambiguous);
    assert_eq!(res.symmetries.len(), 3, "rotations by 90°, 180°, 270°");
    // Every equivalent pose a + kπ/2 is among the candidates, each explaining the scene.
    let eq: Vec<&RegistrationCandidate> = std::iter::once(&res.candidates[0])
        .chain(res.candidates.iter().filter(|c| c.equivalent))
        .collect();
    assert_eq!(eq.len(), 4);
    for k in 0..4 {
        let want = rot2(a + k as f64 * std::f64::consts::FRAC_PI_2);
        assert!(
            eq.iter().any(|c| rotation_angle(&c.rotation, &want) < 0.02),
            "pose {k}·90° missing"
        );
    }
    for c in eq {
        assert!(c.explained > 0.95);
    }
}

#[test]
fn bad_options_and_data_are_errors() {
    let y = mat(&chevron(0.05));
    let o = GlobalRegisterOptions {
        w: 0.0,
        ..GlobalRegisterOptions::default()
    };
    assert!(matches!(
        global_register(&y, &y, &o),
        Err(DetectError::InvalidParameter { what: "w", .. })
    ));
    let mut bad = y.clone();
    bad[(3, 1)] = f64::NAN;
    assert!(matches!(
        global_register(&bad, &y, &GlobalRegisterOptions::default()),
        Err(DetectError::NonFinite { .. })
    ));
}

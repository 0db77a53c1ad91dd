use super::*;
use proptest::prelude::*;

/// A valid camera (test shorthand for `Camera::new(..).unwrap()`).
fn camera(model: CameraModel, params: &[f64], width: u32, height: u32) -> Camera {
    Camera::new(model, params, width, height).unwrap()
}

/// Mild barrel distortion, invertible over the whole 1280×960 image.
fn bc_camera() -> Camera {
    camera(
        CameraModel::BrownConrady,
        &[
            600.0, 580.0, 640.5, 479.25, -0.1, 0.01, 0.001, -0.0005, -0.0002,
        ],
        1280,
        960,
    )
}

/// A fisheye whose image reaches past 90° from the axis (rays behind the camera).
fn kb_camera() -> Camera {
    camera(
        CameraModel::KannalaBrandt,
        &[350.0, 345.0, 639.5, 481.0, -0.02, 0.004, -0.0005, 0.00002],
        1280,
        960,
    )
}

fn pinhole_camera() -> Camera {
    Camera::pinhole(520.0, 515.0, 320.0, 240.0, 640, 480).unwrap()
}

fn cameras() -> Vec<Camera> {
    vec![pinhole_camera(), bc_camera(), kb_camera()]
}

/// Direction at incidence angle `theta` and azimuth `phi`.
fn direction(theta: f64, phi: f64) -> Vector3<f64> {
    Vector3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

#[test]
fn model_names_parse_and_param_names() {
    for m in CameraModel::ALL {
        assert_eq!(m.name().parse::<CameraModel>().unwrap(), m);
        assert_eq!(m.to_string(), m.name());
        assert_eq!(m.num_params(), m.param_names().len());
        assert_eq!(&m.param_names()[..4], &["fx", "fy", "cx", "cy"]);
    }
    assert_eq!(
        "opencv".parse::<CameraModel>().unwrap(),
        CameraModel::BrownConrady
    );
    assert_eq!(
        " Brown-Conrady ".parse::<CameraModel>().unwrap(),
        CameraModel::BrownConrady
    );
    assert_eq!(
        "fisheye".parse::<CameraModel>().unwrap(),
        CameraModel::KannalaBrandt
    );
    assert_eq!(
        "KB".parse::<CameraModel>().unwrap(),
        CameraModel::KannalaBrandt
    );
    assert_eq!(
        "mei".parse::<CameraModel>(),
        Err(GeometryError::UnknownModel { name: "mei".into() })
    );
    assert_eq!(
        CameraModel::BrownConrady.param_names()[4..],
        ["k1", "k2", "p1", "p2", "k3"]
    );
    assert_eq!(
        CameraModel::KannalaBrandt.param_names()[4..],
        ["k1", "k2", "k3", "k4"]
    );
}

#[test]
fn invalid_parameters_are_rejected() {
    for m in CameraModel::ALL {
        let n = m.num_params();
        let good: Vec<f64> = (0..n).map(|i| if i < 4 { 300.0 } else { 0.0 }).collect();
        assert!(Camera::new(m, &good, 640, 480).is_ok());
        for len in [0, n - 1, n + 1] {
            let p = vec![300.0; len];
            assert_eq!(
                Camera::new(m, &p, 640, 480),
                Err(GeometryError::WrongLength {
                    what: "params (camera parameters)",
                    got: len,
                    expected: n
                })
            );
        }
        for i in 0..n {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                let mut p = good.clone();
                p[i] = bad;
                assert!(matches!(
                    Camera::new(m, &p, 640, 480),
                    Err(GeometryError::NonFinite { .. })
                ));
            }
        }
        for (i, name) in [(0, "fx"), (1, "fy")] {
            for bad in [0.0, -1.0] {
                let mut p = good.clone();
                p[i] = bad;
                assert!(matches!(
                    Camera::new(m, &p, 640, 480),
                    Err(GeometryError::InvalidParameter { what, .. }) if what == name
                ));
            }
        }
        assert!(matches!(
            Camera::new(m, &good, 0, 480),
            Err(GeometryError::InvalidParameter { what: "width", .. })
        ));
        assert!(matches!(
            Camera::new(m, &good, 640, 0),
            Err(GeometryError::InvalidParameter { what: "height", .. })
        ));
    }
}

#[test]
fn accessors_and_k_matrix() {
    let cam = bc_camera();
    assert_eq!(cam.model(), CameraModel::BrownConrady);
    assert_eq!(cam.params().len(), 9);
    assert_eq!(cam.distortion(), &[-0.1, 0.01, 0.001, -0.0005, -0.0002]);
    assert_eq!((cam.width(), cam.height()), (1280, 960));
    assert_eq!(
        (cam.fx(), cam.fy(), cam.cx(), cam.cy()),
        (600.0, 580.0, 640.5, 479.25)
    );
    assert!(pinhole_camera().distortion().is_empty());
    // K (x/z, y/z, 1) is the pinhole projection.
    let pin = pinhole_camera();
    let p = Vector3::new(0.3, -0.2, 1.7);
    let h = pin.k_matrix() * (p / p.z);
    let px = pin.project(&p).unwrap();
    assert!((h.xy() - px).norm() < 1e-12 && (h.z - 1.0).abs() < 1e-15);
}

#[test]
fn brown_conrady_hand_computed_value() {
    // x = 0.2, y = -0.1, r² = 0.05, radial = 1 + 0.1·0.05 + 0.01·0.0025 + 0.001·0.000125
    // = 1.005025125; x'' = 0.2·radial + 2·0.001·(-0.02) + 0.002·(0.05 + 0.08) = 0.201225025;
    // y'' = -0.1·radial + 0.001·(0.05 + 0.02) + 2·0.002·(-0.02) = -0.1005125125.
    // (cv2.projectPoints gives the same two numbers.)
    let cam = camera(
        CameraModel::BrownConrady,
        &[500.0, 400.0, 320.0, 240.0, 0.1, 0.01, 0.001, 0.002, 0.001],
        640,
        480,
    );
    for scale in [1.0, 3.5, 0.01] {
        let px = cam
            .project(&(Vector3::new(0.2, -0.1, 1.0) * scale))
            .unwrap();
        assert!((px.x - (500.0 * 0.201225025 + 320.0)).abs() < 1e-10, "{px}");
        assert!(
            (px.y - (400.0 * -0.1005125125 + 240.0)).abs() < 1e-10,
            "{px}"
        );
    }
}

#[test]
fn kannala_brandt_closed_form_values() {
    let (k1, k2) = (0.1, 0.01);
    let cam = camera(
        CameraModel::KannalaBrandt,
        &[400.0, 380.0, 320.0, 240.0, k1, k2, 0.0, 0.0],
        640,
        480,
    );
    let td = |t: f64| t * (1.0 + k1 * t.powi(2) + k2 * t.powi(4));
    // On the axis, at 45°, at 90° (z = 0) and at 135° (behind the camera).
    let cases = [
        (Vector3::new(0.0, 0.0, 2.0), 320.0, 240.0),
        (
            Vector3::new(1.0, 0.0, 1.0),
            320.0 + 400.0 * td(PI / 4.0),
            240.0,
        ),
        (
            Vector3::new(0.0, 3.0, 0.0),
            320.0,
            240.0 + 380.0 * td(PI / 2.0),
        ),
        (
            Vector3::new(0.0, -2.0, -2.0),
            320.0,
            240.0 - 380.0 * td(3.0 * PI / 4.0),
        ),
        (
            Vector3::new(-1.0, -1.0, 2.0_f64.sqrt()),
            320.0 - 400.0 * td(PI / 4.0) / 2.0_f64.sqrt(),
            240.0 - 380.0 * td(PI / 4.0) / 2.0_f64.sqrt(),
        ),
    ];
    for (p, u, v) in cases {
        let px = cam.project(&p).unwrap();
        assert!(
            (px.x - u).abs() < 1e-10 && (px.y - v).abs() < 1e-10,
            "{p} -> {px}, want ({u}, {v})"
        );
    }
    // With k = 0 the model is the equidistant projection r = f θ.
    let eq = camera(
        CameraModel::KannalaBrandt,
        &[300.0, 300.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        10,
        10,
    );
    let p = direction(1.2, 0.7);
    let px = eq.project(&p).unwrap();
    assert!((px - Vector2::new(0.7_f64.cos(), 0.7_f64.sin()) * 300.0 * 1.2).norm() < 1e-10);
}

#[test]
fn zero_distortion_brown_conrady_is_pinhole() {
    let bc = camera(
        CameraModel::BrownConrady,
        &[520.0, 515.0, 320.0, 240.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        640,
        480,
    );
    let pin = pinhole_camera();
    let p = Vector3::new(-0.4, 0.25, 1.3);
    let (a, ja, jpa) = bc.project_jacobians(&p).unwrap();
    let (b, jb, jpb) = pin.project_jacobians(&p).unwrap();
    assert!((a - b).norm() < 1e-12 && (ja - jb).norm() < 1e-12);
    assert!((jpa.columns(0, 4) - &jpb).norm() < 1e-12);
    assert_eq!(jpb.shape(), (2, 4));
}

#[test]
fn behind_the_camera_is_rejected_for_pinhole_and_brown_conrady() {
    for cam in [pinhole_camera(), bc_camera()] {
        for p in [
            Vector3::new(0.1, 0.2, 0.0),
            Vector3::new(0.1, 0.2, -1.0),
            Vector3::zeros(),
        ] {
            assert!(
                matches!(cam.project(&p), Err(GeometryError::NotProjectable { .. })),
                "{p}"
            );
            assert!(matches!(
                cam.project_jacobians(&p),
                Err(GeometryError::NotProjectable { .. })
            ));
        }
        assert!(matches!(
            cam.project(&Vector3::new(f64::NAN, 0.0, 1.0)),
            Err(GeometryError::NonFinite { what: "point", .. })
        ));
        // Overflow near the focal plane is reported, not returned as inf.
        assert!(matches!(
            cam.project(&Vector3::new(1.0, 1.0, 1e-310)),
            Err(GeometryError::NotProjectable { .. })
        ));
    }
}

#[test]
fn kannala_brandt_domain() {
    let cam = kb_camera();
    // Behind the camera off the axis is fine …
    assert!(cam.project(&Vector3::new(1.0, 0.5, -0.3)).is_ok());
    // … on the axis behind it or at the centre it is not.
    for p in [
        Vector3::new(0.0, 0.0, -1.0),
        Vector3::zeros(),
        Vector3::new(0.0, 0.0, 0.0),
    ] {
        assert!(matches!(
            cam.project(&p),
            Err(GeometryError::NotProjectable { .. })
        ));
        assert!(matches!(
            cam.project_jacobians(&p),
            Err(GeometryError::NotProjectable { .. })
        ));
    }
    assert!(matches!(
        cam.project(&Vector3::new(0.0, f64::INFINITY, 1.0)),
        Err(GeometryError::NonFinite { .. })
    ));
    // Tiny and huge points project like their unit direction.
    let d = direction(1.9, -2.2);
    let want = cam.project(&d).unwrap();
    for s in [1e-200, 1e-160, 1e160, 1e250] {
        assert!(
            (cam.project(&(d * s)).unwrap() - want).norm() < 1e-9,
            "scale {s}"
        );
        assert!((cam.project_jacobians(&(d * s)).unwrap().0 - want).norm() < 1e-9);
    }
}

#[test]
fn kannala_brandt_monotonic_limit_matches_closed_forms() {
    let kb = |k: [f64; 4]| {
        camera(
            CameraModel::KannalaBrandt,
            &[300.0, 300.0, 320.0, 240.0, k[0], k[1], k[2], k[3]],
            640,
            480,
        )
    };
    // All terms increasing: monotonic up to π.
    assert_eq!(kb([0.1, 0.01, 0.001, 0.0001]).max_incidence_angle(), PI);
    assert_eq!(kb([0.0; 4]).max_incidence_angle(), PI);
    // dθ_d/dθ = 1 - 0.9 t + 0.1 t² (t = θ²): first root t = (0.9 - √0.41)/0.2.
    let t = (0.9 - 0.41_f64.sqrt()) / 0.2;
    assert!((kb([-0.3, 0.02, 0.0, 0.0]).max_incidence_angle() - t.sqrt()).abs() < 1e-12);
    // 1 + 7 k3 t³ with k3 = -0.01: t = (1/0.07)^(1/3).
    let t = (1.0_f64 / 0.07).cbrt();
    assert!((kb([0.0, 0.0, -0.01, 0.0]).max_incidence_angle() - t.sqrt()).abs() < 1e-12);
    // (t - 2)(t - 2.1)(1 + t²)/4.2: negative only on the narrow interval (2, 2.1).
    let c = [-4.1 / 4.2, 5.2 / 4.2, -4.1 / 4.2, 1.0 / 4.2];
    let cam = kb([c[0] / 3.0, c[1] / 5.0, c[2] / 7.0, c[3] / 9.0]);
    assert!((cam.max_incidence_angle() - 2.0_f64.sqrt()).abs() < 1e-12);
    assert!(cam.project(&direction(1.41, 0.3)).is_ok());
    assert!(matches!(
        cam.project(&direction(1.42, 0.3)),
        Err(GeometryError::NotProjectable { .. })
    ));
    assert!(matches!(
        cam.project(&direction(1.5, 0.3)),
        Err(GeometryError::NotProjectable { .. })
    ));
    // Pixels beyond θ_d(θ_max) have no ray.
    let td_max = kb_theta_d(&cam.c, cam.max_incidence_angle());
    let px = Vector2::new(320.0 + 300.0 * td_max * 1.001, 240.0);
    assert!(matches!(
        cam.unproject(&px),
        Err(GeometryError::NotUnprojectable { .. })
    ));
    let px = Vector2::new(320.0 + 300.0 * td_max * 0.999, 240.0);
    let ray = cam.unproject(&px).unwrap();
    assert!((cam.project(&ray).unwrap() - px).norm() < 1e-9);
}

/// Pixel → ray → pixel over a grid covering the whole image, and point → pixel → ray for
/// directions across the field of view.
#[test]
fn round_trips() {
    for cam in cameras() {
        let (w, h) = (f64::from(cam.width()), f64::from(cam.height()));
        let mut max_theta: f64 = 0.0;
        for i in 0..=24 {
            for j in 0..=18 {
                let px = Vector2::new(
                    -0.5 + w * f64::from(i) / 24.0,
                    -0.5 + h * f64::from(j) / 18.0,
                );
                let ray = cam
                    .unproject(&px)
                    .unwrap_or_else(|e| panic!("{:?} {px}: {e}", cam.model()));
                assert!((ray.norm() - 1.0).abs() < 1e-14);
                max_theta = max_theta.max(ray.z.acos());
                let back = cam.project(&(ray * 2.5)).unwrap();
                assert!(
                    (back - px).norm() < 1e-9,
                    "{:?} {px} -> {back}",
                    cam.model()
                );
            }
        }
        match cam.model() {
            // The fisheye's image covers more than a 180° field of view (rays with z < 0).
            CameraModel::KannalaBrandt => {
                assert!(max_theta > 100f64.to_radians(), "{max_theta}")
            }
            CameraModel::BrownConrady => assert!(max_theta > 55f64.to_radians(), "{max_theta}"),
            CameraModel::Pinhole => assert!(max_theta > 35f64.to_radians(), "{max_theta}"),
        }
        // Directions out to 85° (pinhole/BC: within the image; KB: 170°+ field of view).
        let top = match cam.model() {
            CameraModel::KannalaBrandt => 85f64.to_radians(),
            _ => 40f64.to_radians(),
        };
        for i in 0..=20 {
            for k in 0..12 {
                let d = direction(top * f64::from(i) / 20.0, f64::from(k) * PI / 6.0 + 0.1);
                let px = cam.project(&(d * 3.0)).unwrap();
                let ray = cam.unproject(&px).unwrap();
                assert!((ray - d).norm() < 1e-11, "{:?} {d} -> {ray}", cam.model());
            }
        }
    }
}

#[test]
fn kannala_brandt_round_trip_behind_the_camera() {
    let cam = kb_camera();
    let limit = cam.max_incidence_angle();
    assert!(limit > 2.0, "{limit}");
    for i in 1..=40 {
        let theta = (limit - 1e-3) * f64::from(i) / 40.0;
        for k in 0..8 {
            let d = direction(theta, f64::from(k) * PI / 4.0 - 0.3);
            let px = cam.project(&d).unwrap();
            let ray = cam.unproject(&px).unwrap();
            assert!((ray - d).norm() < 1e-10, "θ={theta}: {d} -> {ray}");
        }
    }
}

/// Central finite differences of `f` at `x` (step relative to each coordinate).
fn central_diff(x: &[f64], f: impl Fn(&[f64]) -> Vector2<f64>) -> DMatrix<f64> {
    let mut j = DMatrix::zeros(2, x.len());
    for i in 0..x.len() {
        let h = 1e-6 * x[i].abs().max(1.0);
        let (mut a, mut b) = (x.to_vec(), x.to_vec());
        a[i] += h;
        b[i] -= h;
        let d = (f(&a) - f(&b)) / (2.0 * h);
        j[(0, i)] = d.x;
        j[(1, i)] = d.y;
    }
    j
}

fn assert_close(analytic: &DMatrix<f64>, numeric: &DMatrix<f64>, what: &str) {
    let scale = analytic.amax().max(1.0);
    let err = (analytic - numeric).amax();
    assert!(
        err <= 1e-6 * scale,
        "{what}: error {err:e}\n{analytic}\n{numeric}"
    );
}

fn check_jacobians(cam: &Camera, p: Vector3<f64>) {
    let (px, jp, jk) = cam.project_jacobians(&p).unwrap();
    assert!((px - cam.project(&p).unwrap()).norm() < 1e-9);
    let num_p = central_diff(p.as_slice(), |q| {
        cam.project(&Vector3::new(q[0], q[1], q[2])).unwrap()
    });
    let jp_dyn = DMatrix::from_iterator(2, 3, jp.iter().copied());
    assert_close(
        &jp_dyn,
        &num_p,
        &format!("{:?} d/dpoint at {p}", cam.model()),
    );
    let num_k = central_diff(cam.params(), |k| {
        camera(cam.model(), k, cam.width(), cam.height())
            .project(&p)
            .unwrap()
    });
    assert_eq!(jk.shape(), (2, cam.model().num_params()));
    assert_close(&jk, &num_k, &format!("{:?} d/dparams at {p}", cam.model()));
}

#[test]
fn jacobians_match_finite_differences() {
    let stronger_bc = camera(
        CameraModel::BrownConrady,
        &[450.0, 470.0, 300.0, 250.0, 0.3, -0.2, 0.01, -0.02, 0.05],
        640,
        480,
    );
    let points = [
        Vector3::new(0.3, -0.2, 1.5),
        Vector3::new(-0.9, 0.6, 1.1),
        Vector3::new(0.0, 0.0, 2.0),
        Vector3::new(1e-9, -2e-9, 1.5),
        Vector3::new(0.05, 0.4, 0.7),
    ];
    for cam in [pinhole_camera(), bc_camera(), stronger_bc, kb_camera()] {
        for p in points {
            check_jacobians(&cam, p);
        }
    }
    // Kannala–Brandt across the whole angular range, including behind the camera.
    let kb = kb_camera();
    for theta in [
        1e-6,
        0.5 * SMALL_THETA,
        2.0 * SMALL_THETA,
        0.3,
        1.2,
        PI / 2.0,
        2.0,
        2.3,
    ] {
        check_jacobians(&kb, direction(theta, 0.8) * 1.7);
    }
}

#[test]
fn brown_conrady_undistortion_stays_in_the_invertible_region() {
    // x'' = x (1 - x²) on the x axis: radial > 0 and increasing only for x < 1/√3. For
    // x'' = 0.3 the roots of x³ - x + 0.3 = 0 are 2/√3 cos(φ/3 - 2πk/3) with
    // φ = arccos(-0.45 √3); the one in the invertible region is k = 1.
    let cam = camera(
        CameraModel::BrownConrady,
        &[100.0, 100.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0],
        64,
        64,
    );
    let phi = (-0.45 * 3.0_f64.sqrt()).acos();
    let root = 2.0 / 3.0_f64.sqrt() * (phi / 3.0 - 2.0 * PI / 3.0).cos();
    assert!(root > 0.0 && root < 1.0 / 3.0_f64.sqrt());
    let ray = cam.unproject(&Vector2::new(30.0, 0.0)).unwrap();
    assert!(
        (ray.x / ray.z - root).abs() < 1e-12 && ray.y.abs() < 1e-15,
        "{ray} vs {root}"
    );
}

#[test]
fn brown_conrady_absurd_distortion_does_not_converge() {
    // k1 = -10: the distortion folds at r = 1/√30 where x'' ≈ 0.12; x'' = 0.5 has no
    // preimage in the invertible region (only one with a negative radial factor).
    let cam = camera(
        CameraModel::BrownConrady,
        &[100.0, 100.0, 0.0, 0.0, -10.0, 0.0, 0.0, 0.0, 0.0],
        64,
        64,
    );
    match cam.unproject(&Vector2::new(50.0, 0.0)) {
        Err(GeometryError::NoConvergence { residual, .. }) => {
            assert!(residual > 0.1, "{residual}")
        }
        other => panic!("expected NoConvergence, got {other:?}"),
    }
    // Every pixel either converges to a true preimage or fails; none returns a wrong ray.
    for i in 0..40 {
        let px = Vector2::new(f64::from(i) * 2.0, f64::from(i) * 1.3 - 20.0);
        if let Ok(ray) = cam.unproject(&px) {
            assert!((cam.project(&ray).unwrap() - px).norm() < 1e-9, "{px}");
        }
    }
    assert!(matches!(
        cam.unproject(&Vector2::new(f64::NAN, 0.0)),
        Err(GeometryError::NonFinite { what: "pixel", .. })
    ));
}

#[test]
fn batch_apis_match_single_point_calls() {
    for cam in cameras() {
        let n = 10_000;
        let pts: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let d = direction(0.7 * (i as f64 * 0.618_034).fract(), i as f64 * 0.37)
                    * (1.0 + (i % 7) as f64);
                [d.x, d.y, d.z]
            })
            .collect();
        let mut out = vec![[0.0; 2]; n];
        let mut par = vec![[0.0; 2]; n];
        cam.project_into(&pts, &mut out).unwrap();
        cam.par_project_into(&pts, &mut par).unwrap();
        let many = cam.project_many(&pts.iter().map(|p| Vector3::from(*p)).collect::<Vec<_>>());
        for i in 0..n {
            let single = cam.project(&Vector3::from(pts[i])).unwrap();
            assert_eq!([single.x, single.y], out[i]);
            assert_eq!(out[i], par[i]);
            assert_eq!(many[i].as_ref().unwrap(), &single);
        }
        let mut rays = vec![[0.0; 3]; n];
        let mut rays_par = vec![[0.0; 3]; n];
        cam.unproject_into(&out, &mut rays).unwrap();
        cam.par_unproject_into(&out, &mut rays_par).unwrap();
        let rays_many =
            cam.unproject_many(&out.iter().map(|p| Vector2::from(*p)).collect::<Vec<_>>());
        for i in 0..n {
            let single = cam.unproject(&Vector2::from(out[i])).unwrap();
            assert_eq!([single.x, single.y, single.z], rays[i]);
            assert_eq!(rays[i], rays_par[i]);
            assert_eq!(rays_many[i].as_ref().unwrap(), &single);
            assert!((Vector3::from(rays[i]) - Vector3::from(pts[i]).normalize()).norm() < 1e-10);
        }

        // The first failing element is reported with its index, serially and in parallel.
        let mut bad = pts.clone();
        bad[9000] = [0.0, 0.0, -1.0];
        bad[7000] = [f64::NAN, 0.0, 1.0];
        for result in [
            cam.project_into(&bad, &mut out),
            cam.par_project_into(&bad, &mut par),
        ] {
            match result {
                Err(GeometryError::AtIndex {
                    index: 7000,
                    source,
                }) => {
                    assert!(matches!(
                        *source,
                        GeometryError::NonFinite { what: "point", .. }
                    ));
                }
                other => panic!("{other:?}"),
            }
        }
        bad[7000] = pts[7000];
        match cam.par_project_into(&bad, &mut par) {
            Err(GeometryError::AtIndex {
                index: 9000,
                source,
            }) => {
                assert!(matches!(*source, GeometryError::NotProjectable { .. }));
            }
            other => panic!("{other:?}"),
        }
        let mut bad_px = out.clone();
        bad_px[5000] = [f64::INFINITY, 0.0];
        assert!(matches!(
            cam.par_unproject_into(&bad_px, &mut rays),
            Err(GeometryError::AtIndex { index: 5000, .. })
        ));
        assert!(cam.project_many(&[Vector3::new(0.0, 0.0, -1.0)])[0].is_err());

        // Mismatched output lengths.
        let wrong = Err(GeometryError::WrongLength {
            what: "output buffer",
            got: n - 1,
            expected: n,
        });
        assert_eq!(cam.project_into(&pts, &mut out[..n - 1]), wrong);
        assert_eq!(cam.par_project_into(&pts, &mut par[..n - 1]), wrong);
        assert_eq!(cam.unproject_into(&out, &mut rays[..n - 1]), wrong);
        assert_eq!(cam.par_unproject_into(&out, &mut rays_par[..n - 1]), wrong);
    }
}

#[test]
fn in_image_uses_pixel_centre_convention() {
    let cam = pinhole_camera(); // 640 × 480
    assert!(cam.in_image(&Vector2::new(-0.5, -0.5)));
    assert!(cam.in_image(&Vector2::new(639.499_999, 479.499_999)));
    assert!(!cam.in_image(&Vector2::new(639.5, 0.0)));
    assert!(!cam.in_image(&Vector2::new(0.0, 479.5)));
    assert!(!cam.in_image(&Vector2::new(-0.500_001, 10.0)));
    assert!(!cam.in_image(&Vector2::new(10.0, -0.500_001)));
    assert!(!cam.in_image(&Vector2::new(f64::NAN, 10.0)));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random points within each model's field of view survive project ∘ unproject.
    #[test]
    fn prop_round_trip(theta in 0.0..1.0f64, phi in -PI..PI, dist in 0.05..50.0f64, which in 0usize..3) {
        let cam = &cameras()[which];
        let theta = theta * match cam.model() {
            CameraModel::KannalaBrandt => cam.max_incidence_angle() - 1e-3,
            _ => 0.75,
        };
        let d = direction(theta, phi);
        let px = cam.project(&(d * dist)).unwrap();
        let ray = cam.unproject(&px).unwrap();
        prop_assert!((ray - d).norm() < 1e-10, "{} -> {}", d, ray);
    }
}

//! Tests of the renderer and of the rim ground truth.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};

use super::*;
use crate::camera::{Camera, CameraModel};

/// A pinhole camera with the principal point at the image centre.
fn pinhole(f: f64, w: u32, h: u32) -> Camera {
    Camera::pinhole(f, f, (w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0, w, h).unwrap()
}

/// Camera at `eye` looking along world +x, pitched down by `pitch` radians (image x = world −y).
fn camera_pose(eye: Vector3<f64>, pitch: f64) -> Isometry3<f64> {
    let z = Vector3::new(pitch.cos(), 0.0, -pitch.sin());
    let x = Vector3::new(0.0, -1.0, 0.0);
    let y = z.cross(&x);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Isometry3::from_parts(
        Translation3::from(eye),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

fn carrier_scene() -> Scene {
    let c = Carrier::default();
    let mut wafers: Vec<Isometry3<f64>> = (1..=26)
        .filter(|k| k % 7 != 3)
        .map(|k| c.slot_pose(k))
        .collect();
    // One tilted and shifted wafer.
    wafers[5] = Isometry3::new(
        Vector3::new(0.004, -0.003, wafers[5].translation.z + 0.001),
        Vector3::new(0.01, 0.02, 0.3),
    );
    Scene::new(wafers)
}

fn no_noise() -> RenderOptions {
    RenderOptions {
        blur_sigma: 0.0,
        noise_sigma: 0.0,
        ..RenderOptions::default()
    }
}

fn bilinear(img: &GrayImage, p: Vector2<f64>) -> Option<f64> {
    let (x0, y0) = (p.x.floor(), p.y.floor());
    if x0 < 0.0 || y0 < 0.0 || x0 + 1.0 >= img.width as f64 || y0 + 1.0 >= img.height as f64 {
        return None;
    }
    let (fx, fy) = (p.x - x0, p.y - y0);
    let (u, v) = (x0 as usize, y0 as usize);
    let g = |du: usize, dv: usize| img.get(u + du, v + dv).unwrap() as f64;
    Some(
        (1.0 - fy) * ((1.0 - fx) * g(0, 0) + fx * g(1, 0))
            + fy * ((1.0 - fx) * g(0, 1) + fx * g(1, 1)),
    )
}

/// Signed distance along `n` (from `p`) of the half-way crossing of the intensity profile
/// through `p` along `n`, if the profile within ±1.5 px is a clean step.
fn edge_offset(img: &GrayImage, p: Vector2<f64>, n: Vector2<f64>) -> Option<f64> {
    let steps = 150;
    let s: Vec<f64> = (0..=steps)
        .map(|i| -1.5 + 3.0 * i as f64 / steps as f64)
        .collect();
    let prof: Vec<f64> = s
        .iter()
        .map(|&t| bilinear(img, p + n * t))
        .collect::<Option<_>>()?;
    let lo = prof.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = prof.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if hi - lo < 100.0 {
        return None;
    }
    // The ends must sit on opposite plateaus.
    let (first, last) = (prof[0], prof[steps]);
    if (first - last).abs() < 0.8 * (hi - lo) {
        return None;
    }
    let mid = 0.5 * (lo + hi);
    let mut best: Option<f64> = None;
    for i in 0..steps {
        let (a, b) = (prof[i] - mid, prof[i + 1] - mid);
        if a == 0.0 || a * b < 0.0 {
            let t = s[i] + (s[i + 1] - s[i]) * a / (a - b);
            if best.is_none_or(|x: f64| t.abs() < x.abs()) {
                best = Some(t);
            }
        }
    }
    best
}

/// Renders one wafer (no carrier, no blur, no noise) and checks that the image edge lies on
/// the ground-truth rim at every visible, side-facing sample (normal from the neighbouring
/// ground-truth samples, so distortion models are checked too).
fn check_edges(cam: &Camera, thickness: f64, eye: Vector3<f64>, pitch: f64, pose: Isometry3<f64>) {
    let t_wc = camera_pose(eye, pitch);
    let scene = Scene {
        wafers: vec![pose],
        shape: WaferShape {
            radius: 0.15,
            thickness,
        },
        carrier: None,
    };
    let img = render(&scene, cam, &t_wc, &no_noise()).unwrap();
    let n_samples = 720;
    let step = std::f64::consts::TAU / n_samples as f64;
    let truth = rim_visibility(&scene, cam, &t_wc, n_samples).unwrap();
    let mut candidates = 0;
    let mut all = Vec::new();
    for rt in &truth {
        let mut signed = Vec::new();
        for j in 1..rt.points.len().saturating_sub(1) {
            let consecutive = (rt.angles[j + 1] - rt.angles[j - 1] - 2.0 * step).abs() < 1e-9;
            if !rt.side_facing[j] || !consecutive {
                continue;
            }
            candidates += 1;
            let t = rt.points[j + 1] - rt.points[j - 1];
            let n = Vector2::new(-t.y, t.x).normalize();
            signed.extend(edge_offset(&img, rt.points[j], n));
        }
        // No systematic shift (a half-pixel convention error would show here).
        let bias = signed.iter().sum::<f64>() / signed.len().max(1) as f64;
        assert!(
            bias.abs() < 0.02,
            "{:?} rim: mean signed offset {bias} px",
            rt.rim
        );
        all.extend(signed.iter().map(|x| x.abs()));
    }
    let n = all.len();
    assert!(
        n * 2 > candidates && n > 200,
        "only {n} of {candidates} profiles were clean steps"
    );
    let max = all.iter().cloned().fold(0.0, f64::max);
    let mean = all.iter().sum::<f64>() / n as f64;
    assert!(
        max < 0.25,
        "max edge offset {max} px (mean {mean}, {n} points)"
    );
    assert!(mean < 0.08, "mean edge offset {mean} px");
}

#[test]
fn edges_lie_on_the_ground_truth_ellipses() {
    let cam = pinhole(900.0, 640, 480);
    // A thick band: both rims are clean steps against plateaus.
    check_edges(
        &cam,
        0.003,
        Vector3::new(-0.36, 0.0, 0.09),
        0.3,
        Isometry3::identity(),
    );
    // The default 1 mm wafer, tilted and shifted, seen closer.
    let pose = Isometry3::new(
        Vector3::new(0.01, -0.02, 0.005),
        Vector3::new(0.03, -0.05, 0.4),
    );
    check_edges(&cam, 0.001, Vector3::new(-0.3, 0.01, 0.06), 0.25, pose);
    // The ground-truth points are exact projections of the rim circle, on the ellipse.
    let t_wc = camera_pose(Vector3::new(-0.3, 0.01, 0.06), 0.25);
    let scene = Scene {
        wafers: vec![pose],
        shape: WaferShape::default(),
        carrier: None,
    };
    for rt in rim_visibility(&scene, &cam, &t_wc, 360).unwrap() {
        let e = rt.ellipse.unwrap();
        let h = if rt.rim == Rim::Upper {
            0.0005
        } else {
            -0.0005
        };
        for (p, phi) in rt.points.iter().zip(&rt.angles) {
            let x = pose * nalgebra::Point3::new(0.15 * phi.cos(), 0.15 * phi.sin(), h);
            let q = cam.project(&(t_wc.inverse() * x).coords).unwrap();
            assert!((q - p).norm() < 1e-9);
            assert!(e.orthogonal_distance(p).abs() < 1e-6);
        }
    }
}

#[test]
fn edges_follow_the_distortion_models() {
    let (w, h, f) = (640u32, 480u32, 700.0);
    let (cx, cy) = (318.7, 241.2);
    let bc = Camera::new(
        CameraModel::BrownConrady,
        &[f, f, cx, cy, -0.25, 0.08, 0.001, -0.0005, 0.0],
        w,
        h,
    )
    .unwrap();
    let kb = Camera::new(
        CameraModel::KannalaBrandt,
        &[f, f, cx, cy, 0.05, -0.01, 0.002, -0.0003],
        w,
        h,
    )
    .unwrap();
    let pose = Isometry3::new(
        Vector3::new(0.01, -0.02, 0.005),
        Vector3::new(0.03, -0.05, 0.4),
    );
    for cam in [&bc, &kb] {
        check_edges(
            cam,
            0.003,
            Vector3::new(-0.33, 0.0, 0.08),
            0.3,
            Isometry3::identity(),
        );
        check_edges(cam, 0.001, Vector3::new(-0.27, 0.01, 0.06), 0.25, pose);
    }
}

#[test]
fn same_seed_same_bytes_other_seed_other_noise() {
    let cam = pinhole(500.0, 160, 120);
    let t_wc = camera_pose(Vector3::new(-0.5, 0.0, 0.15), 0.1);
    let scene = carrier_scene();
    let opts = RenderOptions {
        seed: 7,
        ..RenderOptions::default()
    };
    let a = render(&scene, &cam, &t_wc, &opts).unwrap();
    let b = render(&scene, &cam, &t_wc, &opts).unwrap();
    assert_eq!(a, b);
    let c = render(&scene, &cam, &t_wc, &RenderOptions { seed: 8, ..opts }).unwrap();
    let differ = a.data.iter().zip(&c.data).filter(|(x, y)| x != y).count();
    assert!(differ > a.data.len() / 2, "only {differ} pixels differ");
    // Without noise the seed does not matter.
    let quiet = RenderOptions {
        noise_sigma: 0.0,
        ..opts
    };
    let d = render(&scene, &cam, &t_wc, &quiet).unwrap();
    let e = render(&scene, &cam, &t_wc, &RenderOptions { seed: 8, ..quiet }).unwrap();
    assert_eq!(d, e);
}

#[test]
fn wafer_hidden_behind_another_is_not_visible() {
    let cam = pinhole(800.0, 640, 480);
    // Camera exactly in the wafers' plane: the front wafer hides the one behind it.
    let t_wc = camera_pose(Vector3::new(-0.6, 0.0, 0.0), 0.0);
    let front = Isometry3::identity();
    let back = Isometry3::translation(0.5, 0.0, 0.0);
    let shape = WaferShape::default();
    let both = Scene {
        wafers: vec![front, back],
        shape,
        carrier: None,
    };
    let truth = rim_visibility(&both, &cam, &t_wc, 360).unwrap();
    assert_eq!(truth.len(), 4);
    for t in &truth[..2] {
        assert_eq!(t.wafer, 0);
        assert!(
            t.fraction > 0.3,
            "front wafer {:?} fraction {}",
            t.rim,
            t.fraction
        );
    }
    for t in &truth[2..] {
        assert_eq!(t.wafer, 1);
        assert_eq!(t.fraction, 0.0, "hidden wafer {:?}", t.rim);
        assert!(t.points.is_empty() && t.intervals.is_empty());
    }
    // Alone, the back wafer is visible.
    let alone = Scene {
        wafers: vec![back],
        shape,
        carrier: None,
    };
    let truth = rim_visibility(&alone, &cam, &t_wc, 360).unwrap();
    assert!(truth.iter().all(|t| t.fraction > 0.3));
}

#[test]
fn wafer_seen_from_above_shows_whole_upper_rim_and_front_third_of_lower_rim() {
    let cam = pinhole(400.0, 640, 480);
    let eye = Vector3::new(-0.3, 0.0, 0.3);
    // Look at the wafer centre.
    let t_wc = camera_pose(eye, std::f64::consts::FRAC_PI_4);
    let scene = Scene {
        wafers: vec![Isometry3::identity()],
        shape: WaferShape::default(),
        carrier: None,
    };
    let truth = rim_visibility(&scene, &cam, &t_wc, 720).unwrap();
    let (upper, lower) = (&truth[0], &truth[1]);
    assert_eq!((upper.rim, lower.rim), (Rim::Upper, Rim::Lower));
    // The top face faces the camera everywhere: the whole upper rim is visible.
    assert_eq!(upper.intervals, vec![[0.0, std::f64::consts::TAU]]);
    assert_eq!(upper.points.len(), 720);
    // Lower rim: visible where the side face faces the camera, (cos φ, sin φ)·(C − P) > 0,
    // i.e. −0.3·cos φ > r = 0.15, φ ∈ (2π/3, 4π/3): one third of the circle.
    assert_eq!(lower.intervals.len(), 1);
    let [a, b] = lower.intervals[0];
    let pi = std::f64::consts::PI;
    assert!(
        (a - 2.0 * pi / 3.0).abs() < 1e-8 && (b - 4.0 * pi / 3.0).abs() < 1e-8,
        "{a} {b}"
    );
    assert!((lower.fraction - 1.0 / 3.0).abs() < 1e-8);
    assert!(lower.side_facing.iter().all(|&s| s));
    // The visible points lie on the ground-truth ellipse and are the projections of the rim.
    for rt in &truth {
        let e = rt.ellipse.unwrap();
        for (p, phi) in rt.points.iter().zip(&rt.angles) {
            assert!(e.orthogonal_distance(p).abs() < 1e-6);
            let h = if rt.rim == Rim::Upper {
                0.0005
            } else {
                -0.0005
            };
            let pc = t_wc.inverse() * nalgebra::Point3::new(0.15 * phi.cos(), 0.15 * phi.sin(), h);
            assert!((cam.project(&pc.coords).unwrap() - p).norm() < 1e-9);
        }
    }
}

#[test]
fn points_behind_the_camera_are_excluded() {
    let cam = pinhole(300.0, 640, 480);
    // Camera over the wafer centre, looking horizontally along +x: half the rim is behind.
    let t_wc = camera_pose(Vector3::new(0.0, 0.0, 0.05), 0.0);
    let scene = Scene {
        wafers: vec![Isometry3::identity()],
        shape: WaferShape::default(),
        carrier: None,
    };
    let truth = rim_visibility(&scene, &cam, &t_wc, 720).unwrap();
    for rt in &truth {
        assert!(
            rt.ellipse.is_none(),
            "the circle crosses the principal plane"
        );
        assert!(rt.angles.iter().all(|phi| phi.cos() > 0.0));
    }
    assert!(truth[0].fraction > 0.2 && truth[0].fraction < 0.5);
}

#[test]
fn bad_inputs_are_errors() {
    let cam = pinhole(300.0, 64, 48);
    let t_wc = camera_pose(Vector3::new(-0.5, 0.0, 0.05), 0.0);
    let ok = Scene {
        wafers: vec![Isometry3::identity()],
        shape: WaferShape::default(),
        carrier: None,
    };
    let opts = RenderOptions::default();
    assert!(render(&ok, &cam, &t_wc, &opts).is_ok());
    for shape in [
        WaferShape {
            radius: 0.0,
            thickness: 0.001,
        },
        WaferShape {
            radius: -0.1,
            thickness: 0.001,
        },
        WaferShape {
            radius: 0.15,
            thickness: 0.0,
        },
        WaferShape {
            radius: f64::NAN,
            thickness: 0.001,
        },
    ] {
        let s = Scene {
            shape,
            ..ok.clone()
        };
        assert!(render(&s, &cam, &t_wc, &opts).is_err());
        assert!(rim_visibility(&s, &cam, &t_wc, 100).is_err());
    }
    let mut nan = Isometry3::identity();
    nan.translation.x = f64::NAN;
    let s = Scene {
        wafers: vec![nan],
        ..ok.clone()
    };
    assert!(matches!(
        render(&s, &cam, &t_wc, &opts),
        Err(GeometryError::AtIndex { index: 0, .. })
    ));
    assert!(render(&ok, &cam, &nan, &opts).is_err());
    assert!(rim_visibility(&ok, &cam, &nan, 100).is_err());
    assert!(rim_visibility(&ok, &cam, &t_wc, 2).is_err());
    for bad in [
        RenderOptions {
            supersample: 0,
            ..opts
        },
        RenderOptions {
            noise_sigma: -1.0,
            ..opts
        },
        RenderOptions {
            gain: f64::NAN,
            ..opts
        },
        RenderOptions {
            blur_sigma: f64::INFINITY,
            ..opts
        },
    ] {
        assert!(render(&ok, &cam, &t_wc, &bad).is_err());
    }
    let bad_carrier = Scene {
        carrier: Some(Carrier {
            pitch: 0.0,
            ..Carrier::default()
        }),
        ..ok.clone()
    };
    assert!(render(&bad_carrier, &cam, &t_wc, &opts).is_err());
    assert!(rim_points_visible(&ok, &cam, &t_wc, 1, Rim::Upper, &[0.0]).is_err());
    assert!(rim_points_visible(&ok, &cam, &t_wc, 0, Rim::Upper, &[f64::NAN]).is_err());
}

#[test]
fn rendered_rim_bands_agree_with_the_visibility_truth_in_the_carrier() {
    let cam = pinhole(800.0, 640, 480);
    // From the front left, turned right: the wafers' left sides face the camera, partly
    // behind the slot ridges and the wall.
    let yaw = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -0.45);
    let t_wc = Isometry3::from_parts(
        Translation3::new(-0.33, 0.17, 0.105),
        yaw * camera_pose(Vector3::zeros(), 0.12).rotation,
    );
    let scene = carrier_scene();
    let img = render(&scene, &cam, &t_wc, &no_noise()).unwrap();
    let n = 720;
    let truth = rim_visibility(&scene, &cam, &t_wc, n).unwrap();
    let t_cw = t_wc.inverse();
    let (mut vis, mut vis_bright, mut hid, mut hid_bright) = (0, 0, 0, 0);
    for (i, pose) in scene.wafers.iter().enumerate() {
        let (upper, lower) = (&truth[2 * i], &truth[2 * i + 1]);
        let status = |rt: &RimTruth, j: usize| {
            let phi = std::f64::consts::TAU * j as f64 / n as f64;
            rt.angles
                .iter()
                .position(|a| (a - phi).abs() < 1e-12)
                .map(|k| rt.side_facing[k])
        };
        for j in 0..n {
            // The same status over ±2 samples for both rims: away from occlusion boundaries.
            let s: Vec<_> = (j + n - 2..=j + n + 2)
                .flat_map(|k| [status(upper, k % n), status(lower, k % n)])
                .collect();
            if s.iter().any(|x| *x != s[0]) || s[0] == Some(false) {
                continue;
            }
            let phi = std::f64::consts::TAU * j as f64 / n as f64;
            let px = |z: f64| {
                let x = pose * nalgebra::Point3::new(0.15 * phi.cos(), 0.15 * phi.sin(), z);
                cam.project(&(t_cw * x).coords).ok()
            };
            let (Some(a), Some(b)) = (px(0.0005), px(-0.0005)) else {
                continue;
            };
            let m = (a + b) / 2.0;
            let rim_point = pose * nalgebra::Point3::new(0.15 * phi.cos(), 0.15 * phi.sin(), 0.0);
            let normal = pose.rotation * Vector3::new(phi.cos(), phi.sin(), 0.0);
            let side = normal.dot(&(t_wc.translation.vector - rim_point.coords));
            if side <= 0.0 {
                continue;
            }
            if s[0].is_none() {
                eprintln!(
                    "hidden cand band {:.2} at {:.1},{:.1}",
                    (a - b).norm(),
                    a.x,
                    a.y
                );
            }
            if (a - b).norm() < 2.5 {
                continue;
            }
            let Some(value) = img
                .get(m.x.round() as usize, m.y.round() as usize)
                .filter(|_| m.x >= 0.0 && m.y >= 0.0)
            else {
                continue;
            };
            if s[0] == Some(true) {
                vis += 1;
                vis_bright += usize::from(value > 150);
            } else {
                hid += 1;
                hid_bright += usize::from(value > 150);
            }
        }
    }
    eprintln!("visible {vis_bright}/{vis} bright, hidden {hid_bright}/{hid} bright");
    assert!(vis > 500 && hid > 100, "visible {vis}, hidden {hid}");
    assert!(
        vis_bright as f64 > 0.98 * vis as f64,
        "visible bands: {vis_bright} of {vis} bright"
    );
    assert!(
        (hid_bright as f64) < 0.05 * hid as f64,
        "hidden bands: {hid_bright} of {hid} bright"
    );
}

use super::*;
use autoteach_geometry::conic::project_circle;
use nalgebra::{Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const RADIUS: f64 = 0.15;
/// A thick wafer (5 mm), so that its two rims are ≈ 8 px apart in the test camera and a 2 px
/// gate can tell them apart.
const THICKNESS: f64 = 0.005;

fn k() -> Matrix3<f64> {
    Matrix3::new(800.0, 0.0, 640.0, 0.0, 800.0, 512.0, 0.0, 0.0, 1.0)
}

/// A camera 0.45 m in front of the stack and 0.2 m above it, looking along +y and tilted down.
fn camera(dx: f64) -> Isometry3<f64> {
    let a: f64 = 0.37;
    let (s, c) = a.sin_cos();
    let x = Vector3::x();
    let y = Vector3::new(0.0, -s, -c);
    let z = Vector3::new(0.0, c, -s);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Isometry3::from_parts(
        Translation3::new(dx, -0.45, 0.2),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

fn wafers() -> Vec<Option<Vector5<f64>>> {
    (0..3)
        .map(|i| {
            Some(Vector5::new(
                0.002 * i as f64,
                0.0,
                0.01 * i as f64,
                0.004 * i as f64,
                -0.003,
            ))
        })
        .collect()
}

fn geometry() -> WaferGeometry {
    WaferGeometry::new(RADIUS, THICKNESS).unwrap()
}

/// Points of a rim's image arc (eccentric angles `t0..t1`), with Gaussian pixel noise.
fn rim_arc(
    t_wc: &Isometry3<f64>,
    w: &Vector5<f64>,
    rim: Rim,
    t0: f64,
    n: usize,
    rng: &mut rand_pcg::Pcg64,
) -> Vec<Vector2<f64>> {
    let (t_wo, _) = crate::handeye::wafer::rim_pose(w, rim, THICKNESS);
    let e = project_circle(&k(), &(t_wc.inverse() * t_wo), RADIUS).unwrap();
    let noise = Normal::new(0.0, 0.3).unwrap();
    e.sample(n, t0, t0 + 1.6)
        .unwrap()
        .into_iter()
        .map(|p| p + Vector2::new(noise.sample(rng), noise.sample(rng)))
        .collect()
}

struct Scene {
    points: Vec<Vector2<f64>>,
    start: Vec<usize>,
    frames: Vec<usize>,
    /// Truth of each edge: (wafer, rim) or `None` for clutter.
    truth: Vec<Option<(usize, Rim)>>,
}

impl Scene {
    fn push(&mut self, frame: usize, pts: Vec<Vector2<f64>>, truth: Option<(usize, Rim)>) {
        self.points.extend(pts);
        self.start.push(self.points.len());
        self.frames.push(frame);
        self.truth.push(truth);
    }
    fn edges(&self) -> DetectedEdges<'_> {
        DetectedEdges {
            points: &self.points,
            start: &self.start,
            frames: &self.frames,
        }
    }
}

/// Two frames; every rim of the three wafers as one arc per frame, a straight clutter edge, a
/// short edge (too few points), and the upper rim of a fourth wafer 10 mm above the stack that
/// has no estimate.
fn scene() -> (Vec<Isometry3<f64>>, Scene) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let cams = vec![camera(0.0), camera(0.06)];
    let mut s = Scene {
        points: Vec::new(),
        start: vec![0],
        frames: Vec::new(),
        truth: Vec::new(),
    };
    for (f, cam) in cams.iter().enumerate() {
        for (w, wafer) in wafers().iter().enumerate() {
            for rim in [Rim::Upper, Rim::Lower] {
                let t0 = 3.6 + 0.3 * w as f64;
                s.push(
                    f,
                    rim_arc(cam, wafer.as_ref().unwrap(), rim, t0, 60, &mut rng),
                    Some((w, rim)),
                );
            }
        }
        s.push(
            f,
            (0..40)
                .map(|i| Vector2::new(500.0 + 4.0 * i as f64, 300.0 + 1.5 * i as f64))
                .collect(),
            None,
        );
        s.push(
            f,
            rim_arc(
                cam,
                &Vector5::new(0.0, 0.0, 0.01, 0.0, 0.0),
                Rim::Upper,
                4.0,
                8,
                &mut rng,
            ),
            Some((1, Rim::Upper)),
        );
        let unknown = Vector5::new(0.0, 0.0, 0.03, 0.0, 0.0);
        s.push(
            f,
            rim_arc(cam, &unknown, Rim::Upper, 4.2, 60, &mut rng),
            None,
        );
    }
    (cams, s)
}

fn gate(
    cams: &[Isometry3<f64>],
    w: &[Option<Vector5<f64>>],
    e: &DetectedEdges<'_>,
    c: &GateConfig,
) -> Result<Gated> {
    gate_edges(&k(), cams, w, geometry(), e, c)
}

#[test]
fn every_rim_edge_goes_to_its_wafer_and_rim_and_clutter_is_rejected() {
    let (cams, s) = scene();
    let g = gate(&cams, &wafers(), &s.edges(), &GateConfig::default()).unwrap();
    // 6 rims × 2 frames associated; per frame the clutter line and the unknown wafer rejected,
    // the 8-point edge not scored.
    assert_eq!(g.observations.len(), 12);
    assert_eq!(g.stats.edges, 16);
    assert_eq!(g.stats.edges_rejected, 4);
    assert_eq!(g.stats.rims_associated, 12);
    assert_eq!(g.stats.frames_used, 2);
    for o in &g.observations {
        assert!(
            o.points.len() <= 24 && o.points.len() >= 12,
            "{} points",
            o.points.len()
        );
        // Every kept point is a point of the true edge of that (frame, wafer, rim).
        let e = (0..s.truth.len())
            .find(|e| {
                s.frames[*e] == o.frame
                    && s.truth[*e] == Some((o.wafer, o.rim))
                    && s.start[e + 1] - s.start[*e] == 60
            })
            .unwrap();
        let edge = &s.points[s.start[e]..s.start[e + 1]];
        assert!(o.points.iter().all(|p| edge.contains(p)));
        assert!(o.sigma_scale.is_empty());
    }
    // Sorted by (frame, wafer, rim).
    let keys: Vec<_> = g
        .observations
        .iter()
        .map(|o| (o.frame, o.wafer, o.rim as u8))
        .collect();
    assert!(keys.windows(2).all(|w| w[0] < w[1]));
}

#[test]
fn a_wafer_without_estimate_predicts_no_rim() {
    let (cams, s) = scene();
    let mut w = wafers();
    w[2] = None;
    let g = gate(&cams, &w, &s.edges(), &GateConfig::default()).unwrap();
    assert!(g.observations.iter().all(|o| o.wafer != 2));
    assert_eq!(g.observations.len(), 8);
}

#[test]
fn band_weights_and_the_band_floor_thin_and_weight_points() {
    let (cams, s) = scene();
    let weighted = GateConfig {
        band_weights: true,
        ..GateConfig::default()
    };
    let g = gate(&cams, &wafers(), &s.edges(), &weighted).unwrap();
    for o in &g.observations {
        assert_eq!(o.sigma_scale.len(), o.points.len());
        assert!(o.sigma_scale.iter().all(|s| *s >= 1.0));
    }
    // Every band here is ≈ 8 px wide: a 100 px floor drops every point and rejects every edge.
    let floor = GateConfig {
        min_band_px: 100.0,
        ..GateConfig::default()
    };
    let g = gate(&cams, &wafers(), &s.edges(), &floor).unwrap();
    assert!(g.observations.is_empty());
    assert_eq!(g.stats.rims_associated, 12);
    assert!(g.stats.points_narrow_band >= 12 * 12);
}

#[test]
fn band_width_at_the_front_of_a_level_rim_is_the_projected_thickness() {
    // Camera in the wafer's symmetry plane x = 0: the front rim point (φ = −90°, nearest the
    // camera) has a horizontal image tangent, and the band there is the image length of the
    // vertical segment between the two rims' front points.
    let cam = camera(0.0);
    let w = Vector5::zeros();
    let t_cw = cam.inverse();
    let (up, _) = crate::handeye::wafer::rim_pose(&w, Rim::Upper, THICKNESS);
    let (lo, _) = crate::handeye::wafer::rim_pose(&w, Rim::Lower, THICKNESS);
    let rims = project_rims(&k(), &cam, &[Some(w)], geometry()).unwrap();
    let proj = |p: Point3<f64>| {
        let x = k() * (t_cw * p).coords;
        Vector2::new(x.x / x.z, x.y / x.z)
    };
    let front_up = proj(up * Point3::new(0.0, -RADIUS, 0.0));
    let front_lo = proj(lo * Point3::new(0.0, -RADIUS, 0.0));
    let band = band_width(
        &[front_up],
        &rims[0].h_inv,
        &rims[1].t_co,
        &rims[0].conic,
        &k(),
        RADIUS,
    );
    approx::assert_relative_eq!(band[0], (front_up - front_lo).norm(), max_relative = 1e-9);
}

#[test]
fn band_sigma_scale_interpolates_the_measured_table_and_never_goes_below_one() {
    for (i, x) in BAND_NOISE_WIDTH_PX.iter().enumerate() {
        assert_eq!(
            band_sigma_scale(*x, Rim::Upper),
            BAND_NOISE_UPPER[i].max(1.0)
        );
        assert_eq!(
            band_sigma_scale(*x, Rim::Lower),
            BAND_NOISE_LOWER[i].max(1.0)
        );
    }
    let mid = 0.5 * (BAND_NOISE_WIDTH_PX[1] + BAND_NOISE_WIDTH_PX[2]);
    approx::assert_relative_eq!(
        band_sigma_scale(mid, Rim::Lower),
        0.5 * (BAND_NOISE_LOWER[1] + BAND_NOISE_LOWER[2]),
        max_relative = 1e-12
    );
    assert_eq!(band_sigma_scale(-1.0, Rim::Upper), BAND_NOISE_UPPER[0]);
    assert_eq!(band_sigma_scale(99.0, Rim::Upper), 1.0);
    assert_eq!(band_sigma_scale(f64::NAN, Rim::Lower), 5.61);
}

#[test]
fn sampson_distance_matches_the_orthogonal_distance_near_the_curve() {
    let cam = camera(0.0);
    let (t_wo, _) = crate::handeye::wafer::rim_pose(&Vector5::zeros(), Rim::Upper, THICKNESS);
    let t_co = cam.inverse() * t_wo;
    let e = project_circle(&k(), &t_co, RADIUS).unwrap();
    let c = autoteach_geometry::conic::circle_image_conic(&k(), &t_co, RADIUS).unwrap();
    for p in e.sample(40, 0.0, 6.0).unwrap() {
        for off in [-1.5, 0.5, 2.0] {
            let n = (p - e.closest_point(&(p * 1.0001))).normalize();
            let q = p + n * off;
            let exact = e.orthogonal_distance(&q).abs();
            approx::assert_relative_eq!(
                sampson_distance(&c, &q),
                exact,
                max_relative = 0.05,
                epsilon = 1e-3
            );
        }
    }
}

#[test]
fn subsample_indices_pick_what_numpy_linspace_rounds_to() {
    let cases: [(usize, usize, &[usize]); 5] = [
        (
            50,
            24,
            &[
                0, 2, 4, 6, 9, 11, 13, 15, 17, 19, 21, 23, 26, 28, 30, 32, 34, 36, 38, 40, 43, 45,
                47, 49,
            ],
        ),
        (13, 4, &[0, 4, 8, 12]),
        (6, 3, &[0, 2, 5]),
        (4, 3, &[0, 2, 3]),
        (3, 5, &[0, 1, 2]),
    ];
    for (n, m, want) in cases {
        assert_eq!(subsample_indices(n, m), want, "n = {n}, m = {m}");
    }
}

#[test]
fn inconsistent_input_is_refused_with_what_is_wrong() {
    let (cams, s) = scene();
    let mut start = s.start.clone();
    start[3] = start[2] - 1;
    let bad = DetectedEdges {
        points: &s.points,
        start: &start,
        frames: &s.frames,
    };
    let err = gate(&cams, &wafers(), &bad, &GateConfig::default()).unwrap_err();
    assert!(err.to_string().contains("edge offsets"), "{err}");
    let err = gate(&cams[..1], &wafers(), &s.edges(), &GateConfig::default()).unwrap_err();
    assert!(err.to_string().contains("camera poses"), "{err}");
    let mut pts = s.points.clone();
    pts[5].y = f64::NAN;
    let bad = DetectedEdges {
        points: &pts,
        start: &s.start,
        frames: &s.frames,
    };
    let err = gate(&cams, &wafers(), &bad, &GateConfig::default()).unwrap_err();
    assert!(
        matches!(err, EstimateError::NonFiniteInput { index: 5, .. }),
        "{err}"
    );
    let cfg = GateConfig {
        gate_px: 0.0,
        ..GateConfig::default()
    };
    assert!(gate(&cams, &wafers(), &s.edges(), &cfg).is_err());
    let cfg = GateConfig {
        min_inlier_fraction: 1.5,
        ..GateConfig::default()
    };
    assert!(gate(&cams, &wafers(), &s.edges(), &cfg).is_err());
    let mut w = wafers();
    w[0] = Some(Vector5::new(f64::INFINITY, 0.0, 0.0, 0.0, 0.0));
    assert!(gate(&cams, &w, &s.edges(), &GateConfig::default()).is_err());
}

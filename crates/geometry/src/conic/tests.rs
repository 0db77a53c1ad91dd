use super::*;
use crate::lie::se3_plus;
use nalgebra::{Point3, Vector6};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn rng(seed: u64) -> Pcg64 {
    Pcg64::seed_from_u64(seed)
}

/// Random ellipses in pixel units, plus near-circles and θ near ±π/2.
fn ellipses(seed: u64, n: usize) -> Vec<Ellipse> {
    let mut r = rng(seed);
    let mut out = Vec::new();
    for i in 0..n {
        let a = r.random_range(1.0..400.0);
        let ratio: f64 = match i % 5 {
            0 => 1.0 - 1e-10,
            1 => 1.0,
            _ => r.random_range(0.05..1.0),
        };
        let theta = match i % 7 {
            0 => FRAC_PI_2 - 1e-12,
            1 => -FRAC_PI_2 + 1e-12,
            2 => FRAC_PI_2,
            _ => r.random_range(-FRAC_PI_2..FRAC_PI_2),
        };
        let e = Ellipse::new(
            r.random_range(-500.0..1500.0),
            r.random_range(-500.0..1500.0),
            a,
            a * ratio,
            theta,
        )
        .unwrap();
        out.push(e);
    }
    out
}

/// Angle difference modulo π, in (−π/2, π/2].
fn dtheta(a: f64, b: f64) -> f64 {
    wrap_half_pi(a - b)
}

/// Max distance of points of `e` from `f`, a parameter-free comparison of two ellipses.
fn set_distance(e: &Ellipse, f: &Ellipse) -> f64 {
    e.sample(64, 0.0, 2.0 * PI)
        .unwrap()
        .iter()
        .map(|p| f.orthogonal_distance(p).abs())
        .fold(0.0, f64::max)
}

fn assert_same_ellipse(e: &Ellipse, f: &Ellipse, tol: f64) {
    let scale = e.a + e.cx.abs() + e.cy.abs();
    assert!((e.cx - f.cx).abs() <= tol * scale, "{e:?} vs {f:?}");
    assert!((e.cy - f.cy).abs() <= tol * scale, "{e:?} vs {f:?}");
    assert!((e.a - f.a).abs() <= tol * e.a, "{e:?} vs {f:?}");
    assert!((e.b - f.b).abs() <= tol * e.b, "{e:?} vs {f:?}");
    assert!(set_distance(e, f) <= tol * scale, "{e:?} vs {f:?}");
    if e.a - e.b > 1e-3 * e.a {
        assert!(
            dtheta(e.theta, f.theta).abs() <= tol * e.a / (e.a - e.b),
            "{e:?} vs {f:?}"
        );
    }
    assert!(f.theta > -FRAC_PI_2 && f.theta <= FRAC_PI_2 && f.a >= f.b);
}

#[test]
fn new_canonicalises_and_validates() {
    let e = Ellipse::new(1.0, 2.0, 3.0, 5.0, 0.2).unwrap();
    assert_eq!((e.a, e.b), (5.0, 3.0));
    assert!((e.theta - (0.2 + FRAC_PI_2 - PI)).abs() < 1e-15);
    let e = Ellipse::new(0.0, 0.0, 5.0, 3.0, 3.0 * PI + 0.1).unwrap();
    assert!((e.theta - 0.1).abs() < 1e-12);
    let e = Ellipse::new(0.0, 0.0, 5.0, 3.0, -FRAC_PI_2).unwrap();
    assert_eq!(e.theta, FRAC_PI_2);
    // The same point set before and after canonicalisation.
    let raw = Ellipse {
        cx: 1.0,
        cy: 2.0,
        a: 3.0,
        b: 5.0,
        theta: 0.2,
    };
    let canon = Ellipse::new(1.0, 2.0, 3.0, 5.0, 0.2).unwrap();
    assert!(set_distance(&canon, &raw) < 1e-12);
    assert!(matches!(
        Ellipse::new(0.0, 0.0, 0.0, 1.0, 0.0),
        Err(GeometryError::InvalidParameter { what: "a", .. })
    ));
    assert!(matches!(
        Ellipse::new(0.0, 0.0, 1.0, -1.0, 0.0),
        Err(GeometryError::InvalidParameter { what: "b", .. })
    ));
    assert!(matches!(
        Ellipse::new(f64::NAN, 0.0, 1.0, 1.0, 0.0),
        Err(GeometryError::NonFinite { .. })
    ));
}

#[test]
fn conic_matches_eq_3_3_product() {
    for e in ellipses(1, 30) {
        let t = Matrix3::new(1.0, 0.0, -e.cx, 0.0, 1.0, -e.cy, 0.0, 0.0, 1.0);
        let (s, c) = e.theta.sin_cos();
        // Q takes image offsets into the ellipse frame (eq. 3.1).
        let q = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        let d = Matrix3::from_diagonal(&Vector3::new(e.a.powi(-2), e.b.powi(-2), -1.0));
        let expected = t.transpose() * q.transpose() * d * q * t;
        let got = e.conic();
        assert!((got - expected).norm() <= 1e-12 * expected.norm(), "{e:?}");
        assert_eq!(got, got.transpose());
        let centre = Vector3::new(e.cx, e.cy, 1.0);
        assert!((centre.dot(&(got * centre)) + 1.0).abs() < 1e-9);
    }
}

#[test]
fn conic_round_trip_any_scale_and_sign() {
    for e in ellipses(2, 200) {
        for s in [1.0, -7.0, 1e-6, -3e4] {
            let back = Ellipse::from_conic(&(e.conic() * s)).unwrap();
            assert_same_ellipse(&e, &back, 1e-9);
        }
        let coeffs = e.conic_coefficients();
        let n = coeffs.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((n - 1.0).abs() < 1e-14);
        assert!(coeffs[0] + coeffs[2] > 0.0);
        let back = Ellipse::from_coefficients(&coeffs.map(|x| -2.5 * x)).unwrap();
        assert_same_ellipse(&e, &back, 1e-9);
    }
}

#[test]
fn samples_satisfy_the_conic() {
    for e in ellipses(3, 100) {
        let c = e.conic();
        let pts = e.sample(37, -1.0, 2.5).unwrap();
        assert_eq!(pts.len(), 37);
        assert_eq!(pts[0], e.point_at(-1.0));
        assert_eq!(pts[36], e.point_at(2.5));
        for p in &pts {
            let h = Vector3::new(p.x, p.y, 1.0);
            let scale = h.abs().dot(&(c.abs() * h.abs()));
            assert!(h.dot(&(c * h)).abs() <= 1e-12 * scale, "{e:?} {p:?}");
            assert!(e.algebraic_distance(p).abs() < 1e-12);
            assert!(e.orthogonal_distance(p).abs() <= 1e-12 * (e.a + p.norm()));
        }
        if e.a - e.b > 1e-6 * e.a {
            for t in [-3.0, -1.2, 0.0, 0.4, 1.5, 3.1] {
                let got = e.parameter_of(&e.point_at(t));
                assert!((got - t).abs() < 1e-8, "{e:?} t={t} got={got}");
            }
        }
    }
    let e = Ellipse::new(0.0, 0.0, 2.0, 1.0, 0.0).unwrap();
    assert!(matches!(
        e.sample(1, 0.0, 1.0),
        Err(GeometryError::InvalidParameter { what: "n", .. })
    ));
    assert!(e.sample(5, 0.0, f64::INFINITY).is_err());
}

/// Brute force: dense sampling of eq. (3.2), then golden section and Newton on every
/// local minimum of the squared distance.
fn brute_distance(e: &Ellipse, p: &Vector2<f64>) -> f64 {
    let n = 2048;
    let h = 2.0 * PI / n as f64;
    let d2 = |t: f64| (e.point_at(t) - p).norm_squared();
    let vals: Vec<f64> = (0..n).map(|i| d2(h * i as f64)).collect();
    let mut best = f64::INFINITY;
    for i in 0..n {
        if vals[i] > vals[(i + n - 1) % n] || vals[i] > vals[(i + 1) % n] {
            continue;
        }
        let (mut lo, mut hi) = (h * (i as f64 - 1.0), h * (i as f64 + 1.0));
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..80 {
            let m1 = hi - g * (hi - lo);
            let m2 = lo + g * (hi - lo);
            if d2(m1) < d2(m2) {
                hi = m2;
            } else {
                lo = m1;
            }
        }
        let mut t = 0.5 * (lo + hi);
        let (s, c) = e.theta.sin_cos();
        for _ in 0..8 {
            let (st, ct) = t.sin_cos();
            let r = e.point_at(t) - p;
            let dp = Vector2::new(-e.a * st * c - e.b * ct * s, -e.a * st * s + e.b * ct * c);
            let ddp = -(e.point_at(t) - Vector2::new(e.cx, e.cy));
            let g1 = r.dot(&dp);
            let g2 = dp.dot(&dp) + r.dot(&ddp);
            if g2 > 0.0 {
                let tn = t - g1 / g2;
                if d2(tn) <= d2(t) {
                    t = tn;
                }
            }
        }
        best = best.min(d2(t).sqrt());
    }
    best
}

#[test]
fn orthogonal_distance_matches_brute_force() {
    let mut r = rng(4);
    for e in ellipses(5, 60) {
        let f = Frame::of(&e);
        for k in 0..40 {
            // Local coordinates: general, near the curve, on the axes, near the centre.
            let (u, v) = match k % 8 {
                0 => (0.0, 0.0),
                1 => (r.random_range(-1.5..1.5) * e.a, 0.0),
                2 => (0.0, r.random_range(-2.0..2.0) * e.b),
                3 => (
                    r.random_range(-1e-9..1e-9) * e.a,
                    r.random_range(-1e-9..1e-9) * e.b,
                ),
                4 => (r.random_range(-1.0..1.0) * e.a, 1e-12 * e.b),
                5 => {
                    let t: f64 = r.random_range(-PI..PI);
                    let s = 1.0 + r.random_range(-1e-6..1e-6);
                    (s * e.a * t.cos(), s * e.b * t.sin())
                }
                _ => (
                    r.random_range(-3.0..3.0) * e.a,
                    r.random_range(-3.0..3.0) * e.a,
                ),
            };
            let p = f.global(u, v);
            let d = e.orthogonal_distance(&p);
            let truth = brute_distance(&e, &p);
            let tol = 1e-12 * (e.a + p.norm());
            assert!(
                (d.abs() - truth).abs() <= tol,
                "{e:?} p={p:?} d={d} truth={truth}"
            );
            let inside = (u / e.a).powi(2) + (v / e.b).powi(2) < 1.0;
            assert_eq!(d < 0.0, inside && d != 0.0, "{e:?} p={p:?} d={d}");
            assert_eq!(e.contains(&p), e.algebraic_distance(&p) <= 0.0);
            // The closest point is on the curve, at that distance, along the normal.
            let q = e.closest_point(&p);
            assert!(
                e.algebraic_distance(&q).abs() < 1e-12,
                "{e:?} p={p:?} q={q:?}"
            );
            assert!(((q - p).norm() - d.abs()).abs() <= tol);
            let (qu, qv) = f.local(&q);
            let normal = Vector2::new(qu / (e.a * e.a), qv / (e.b * e.b)).normalize();
            let (pu, pv) = f.local(&p);
            let off = Vector2::new(pu - qu, pv - qv);
            assert!(
                (off.x * normal.y - off.y * normal.x).abs() <= tol,
                "{e:?} p={p:?}"
            );
            let t = e.parameter_of(&p);
            assert!((e.point_at(t) - q).norm() <= 1e-9 * (e.a + q.norm()));
        }
    }
}

#[test]
fn centre_and_axis_points_closed_forms() {
    let (a, b) = (5.0, 3.0);
    let e = Ellipse::new(10.0, -4.0, a, b, 0.7).unwrap();
    let f = Frame::of(&e);
    // Centre: one semi-minor axis inside, nearest points the co-vertices.
    let c = Vector2::new(10.0, -4.0);
    assert!((e.orthogonal_distance(&c) + b).abs() < 1e-14);
    let q = e.closest_point(&c);
    assert!((q - f.global(0.0, b)).norm() < 1e-12 || (q - f.global(0.0, -b)).norm() < 1e-12);
    // Major axis inside the evolute: d = b·sqrt(1 − x²/(a² − b²)).
    for x in [0.5, -1.0, 3.0, -3.19] {
        let want = -b * (1.0 - x * x / (a * a - b * b)).sqrt();
        let got = e.orthogonal_distance(&f.global(x, 0.0));
        assert!((got - want).abs() < 1e-13, "x={x}: {got} vs {want}");
    }
    // Major axis beyond the evolute cusp (a² − b²)/a = 3.2, and outside: the vertex.
    for x in [3.3f64, -4.0, 4.99, 7.0, -100.0] {
        let want = x.abs() - a;
        assert!((e.orthogonal_distance(&f.global(x, 0.0)) - want).abs() < 1e-13);
    }
    // Minor axis: always the co-vertex.
    for y in [0.5f64, -2.9, 3.0, 4.0, -50.0] {
        let want = y.abs() - b;
        let got = e.orthogonal_distance(&f.global(0.0, y));
        assert!((got - want).abs() < 1e-13, "y={y}: {got} vs {want}");
    }
    // A circle: every point is at |p − c| − r.
    let circ = Ellipse::new(1.0, 2.0, 4.0, 4.0, 0.3).unwrap();
    for p in [
        Vector2::new(1.0, 2.0),
        Vector2::new(1.5, 2.0),
        Vector2::new(-7.0, 9.0),
    ] {
        let want = (p - Vector2::new(1.0, 2.0)).norm() - 4.0;
        assert!((circ.orthogonal_distance(&p) - want).abs() < 1e-13);
    }
    // Non-finite points give NaN rather than a panic or a hang.
    assert!(e.orthogonal_distance(&Vector2::new(f64::NAN, 0.0)).is_nan());
}

/// Regression for points a hair off the major axis inside the evolute, where the root
/// `s ≈ −1` of Eberly's formulation loses all digits of `x1 = y1/(s + 1)`; and for thin
/// ellipses and far points. Checks the optimality conditions and a brute-force bound.
#[test]
fn closest_point_is_robust_for_extreme_points() {
    for e1 in [1.0, 0.999999, 0.5, 1e-3, 1e-6] {
        let e0 = 1.0;
        let samples: Vec<(f64, f64)> = (0..20000)
            .map(|i| {
                let t = 2.0 * PI * i as f64 / 20000.0;
                (e0 * t.cos(), e1 * t.sin())
            })
            .collect();
        for y0 in [0.0, 1e-200, 1e-9, 0.3, 0.999, 1.0, 1.5, 1e6] {
            for y1 in [0.0, 1e-300, 1e-150, 1e-20, 1e-8, 0.3 * e1, e1, 2.0, 1e6] {
                for (sy0, sy1) in [(1.0, 1.0), (-1.0, -1.0)] {
                    let (py0, py1) = (sy0 * y0, sy1 * y1);
                    let (x0, x1) = closest_in_frame(e0, e1, py0, py1);
                    let on = (x0 / e0).powi(2) + (x1 / e1).powi(2) - 1.0;
                    assert!(on.abs() < 1e-13, "e1={e1} y=({py0}, {py1}): off by {on}");
                    let d = (py0 - x0).hypot(py1 - x1);
                    let brute = samples
                        .iter()
                        .map(|(u, v)| (py0 - u).hypot(py1 - v))
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        d <= brute * (1.0 + 1e-14) + 1e-15,
                        "e1={e1} y=({py0}, {py1}): {d} > {brute}"
                    );
                    // Same quadrant, and p − x along the normal (x0/e0², x1/e1²).
                    assert!(x0 * py0 >= 0.0 && x1 * py1 >= 0.0);
                    let n = Vector2::new(x0 / (e0 * e0), x1 / (e1 * e1)).normalize();
                    let cross = (py0 - x0) * n.y - (py1 - x1) * n.x;
                    assert!(
                        cross.abs() <= 1e-12 * (1.0 + d),
                        "e1={e1} y=({py0}, {py1}): {cross}"
                    );
                    // Continuity with the on-axis closed form.
                    if y1 < 1e-100 {
                        let (a0, a1) = closest_in_frame(e0, e1, py0, 0.0);
                        let d_axis = (py0 - a0).hypot(a1);
                        assert!(
                            (d - d_axis).abs() <= 1e-14 * (1.0 + d),
                            "e1={e1} y0={py0}: {d} vs {d_axis}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn sampson_approximates_orthogonal_near_the_curve() {
    let mut r = rng(6);
    for e in ellipses(7, 50) {
        let f = Frame::of(&e);
        for _ in 0..20 {
            let t: f64 = r.random_range(-PI..PI);
            let q = e.point_at(t);
            let (qu, qv) = f.local(&q);
            let n = Vector2::new(qu / (e.a * e.a), qv / (e.b * e.b)).normalize();
            // Sampson's first-order error is about δ·λmax(∇²f)/(2‖∇f‖): step on that scale.
            let grad = 2.0 * Vector2::new(qu / (e.a * e.a), qv / (e.b * e.b)).norm();
            let step = grad / (2.0 / (e.b * e.b));
            for sign in [-1.0, 1.0] {
                let mut errs = Vec::new();
                for rel in [1e-4, 1e-5] {
                    let delta = sign * rel * step;
                    let p = f.global(qu + delta * n.x, qv + delta * n.y);
                    let s = e.sampson_distance(&p);
                    let o = e.orthogonal_distance(&p);
                    assert!((o - delta).abs() <= 1e-9 * (e.a + p.norm()));
                    assert!((s - o.abs()).abs() <= 1e-3 * o.abs(), "{e:?} s={s} o={o}");
                    errs.push(((s - o.abs()) / o).abs());
                }
                // First order: ten times closer, about ten times smaller relative error.
                assert!(errs[1] <= 0.2 * errs[0] + 1e-7, "{e:?} {errs:?}");
            }
        }
        assert_eq!(e.sampson_distance(&Vector2::new(e.cx, e.cy)), f64::INFINITY);
    }
}

#[test]
fn batched_equals_scalar() {
    let e = Ellipse::new(3.0, 4.0, 7.0, 2.0, 0.4).unwrap();
    let mut r = rng(8);
    let pts: Vec<Vector2<f64>> = (0..PAR_MIN + 7)
        .map(|_| Vector2::new(r.random_range(-20.0..20.0), r.random_range(-20.0..20.0)))
        .collect();
    let od = e.orthogonal_distances(&pts);
    let sd = e.sampson_distances(&pts);
    let ad = e.algebraic_distances(&pts);
    let cp = e.closest_points(&pts);
    for (i, p) in pts.iter().enumerate() {
        assert_eq!(od[i], e.orthogonal_distance(p));
        assert_eq!(sd[i], e.sampson_distance(p));
        assert_eq!(ad[i], e.algebraic_distance(p));
        assert_eq!(cp[i], e.closest_point(p));
    }
    assert_eq!(e.orthogonal_distances(&pts[..3]), od[..3].to_vec());
}

#[test]
fn degenerate_conics_are_rejected_by_name() {
    let cases: [(&str, Matrix3<f64>); 8] = [
        (
            "hyperbola",
            Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
        ),
        (
            "parabola",
            Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -0.5, 0.0, -0.5, 0.0),
        ),
        (
            "intersecting lines",
            Matrix3::new(1.0, 0.0, 0.0, 0.0, -4.0, 0.0, 0.0, 0.0, 0.0),
        ),
        (
            "parallel or coincident lines",
            Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0),
        ),
        (
            "imaginary",
            Matrix3::new(1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0),
        ),
        (
            "point ellipse",
            Ellipse::new(3.0, 1.0, 2.0, 1.0, 0.3).unwrap().conic()
                + Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
        ),
        (
            "no quadratic part",
            Matrix3::new(0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0),
        ),
        ("zero", Matrix3::zeros()),
    ];
    for (name, c) in cases {
        for s in [1.0, -3.0] {
            match Ellipse::from_conic(&(c * s)) {
                Err(GeometryError::DegenerateConic { reason }) => {
                    assert!(reason.contains(name), "{name}: {reason}");
                    if name != "zero" {
                        assert!(reason.contains("discriminant"), "{reason}");
                    }
                }
                other => panic!("{name}: expected DegenerateConic, got {other:?}"),
            }
        }
    }
    let mut nan = Ellipse::new(0.0, 0.0, 2.0, 1.0, 0.0).unwrap().conic();
    nan[(1, 2)] = f64::NAN;
    assert!(matches!(
        Ellipse::from_conic(&nan),
        Err(GeometryError::NonFinite { .. })
    ));
    // The coefficient form shares the checks: y = x² is a parabola.
    let err = Ellipse::from_coefficients(&[1.0, 0.0, 0.0, 0.0, -1.0, 0.0]).unwrap_err();
    assert!(err.to_string().contains("parabola"), "{err}");
}

#[test]
fn area_and_perimeter() {
    for e in ellipses(9, 20) {
        assert!((e.area() - PI * e.a * e.b).abs() <= 1e-15 * e.area());
        // Polyline through 2^18 points of eq. (3.2): error O(n⁻²) ≈ 1e-10 relative.
        let n = 1 << 18;
        let pts = e.sample(n + 1, 0.0, 2.0 * PI).unwrap();
        let poly: f64 = pts.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        assert!(
            (e.perimeter() - poly).abs() <= 1e-9 * poly,
            "{e:?}: {} vs {poly}",
            e.perimeter()
        );
    }
    let c = Ellipse::new(0.0, 0.0, 2.0, 2.0, 0.0).unwrap();
    assert!((c.perimeter() - 4.0 * PI).abs() < 1e-14);
    let thin = Ellipse::new(0.0, 0.0, 1.0, 1e-9, 0.0).unwrap();
    assert!((thin.perimeter() - 4.0).abs() < 1e-6);
    assert!(c.contains(&Vector2::new(1.9, 0.0)) && !c.contains(&Vector2::new(2.1, 0.0)));
}

fn intrinsics() -> Matrix3<f64> {
    Matrix3::new(910.0, 0.7, 640.5, 0.0, 880.0, 361.2, 0.0, 0.0, 1.0)
}

/// Random camera poses of a wafer half a metre or so in front of the camera.
fn poses(seed: u64, n: usize) -> Vec<Isometry3<f64>> {
    let mut r = rng(seed);
    (0..n)
        .map(|_| {
            let t = Vector3::new(
                r.random_range(-0.2..0.2),
                r.random_range(-0.2..0.2),
                r.random_range(0.4..1.2),
            );
            let axis = Vector3::new(
                r.random_range(-1.0..1.0),
                r.random_range(-1.0..1.0),
                r.random_range(-1.0..1.0),
            );
            let w = axis.normalize() * r.random_range(0.05..0.9);
            Isometry3::new(t, w)
        })
        .collect()
}

fn project(k: &Matrix3<f64>, x: &Point3<f64>) -> Vector2<f64> {
    let h = k * x.coords;
    Vector2::new(h.x / h.z, h.y / h.z)
}

#[test]
fn projected_rim_conic_passes_through_projected_rim_points() {
    let k = intrinsics();
    let radius = 0.15;
    for t_co in poses(10, 100) {
        let c = circle_image_conic(&k, &t_co, radius).unwrap();
        assert!((c.norm() - 1.0).abs() < 1e-14);
        let e = project_circle(&k, &t_co, radius).unwrap();
        for i in 0..64 {
            let phi = 2.0 * PI * i as f64 / 64.0;
            let x = t_co * Point3::new(radius * phi.cos(), radius * phi.sin(), 0.0);
            let p = project(&k, &x);
            let h = Vector3::new(p.x, p.y, 1.0);
            let scale = h.abs().dot(&(c.abs() * h.abs()));
            assert!(h.dot(&(c * h)).abs() <= 1e-12 * scale);
            let d = e.orthogonal_distance(&p);
            assert!(d.abs() < 1e-9, "pose {t_co:?}: {d} px");
            // Points of the wafer surface inside the rim are inside, outside are outside.
            for (s, inside) in [(0.5, true), (1.5, false)] {
                let y = t_co * Point3::new(s * radius * phi.cos(), s * radius * phi.sin(), 0.0);
                let q = project(&k, &y);
                let hq = Vector3::new(q.x, q.y, 1.0);
                assert_eq!(hq.dot(&(c * hq)) < 0.0, inside);
                assert_eq!(e.contains(&q), inside);
            }
        }
    }
}

#[test]
fn fronto_parallel_circle_images_to_a_circle() {
    let k = Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0);
    let t = Vector3::new(0.03, -0.02, 0.6);
    let e = project_circle(&k, &Isometry3::new(t, Vector3::zeros()), 0.15).unwrap();
    let want = 800.0 * 0.15 / 0.6;
    assert!((e.a - want).abs() < 1e-10 && (e.b - want).abs() < 1e-10);
    assert!((e.cx - (320.0 + 800.0 * 0.03 / 0.6)).abs() < 1e-10);
    assert!((e.cy - (240.0 - 800.0 * 0.02 / 0.6)).abs() < 1e-10);
    // θ is undefined there, so the pose Jacobian refuses.
    let err = project_circle_jacobian(&k, &Isometry3::new(t, Vector3::zeros()), 0.15).unwrap_err();
    assert!(err.to_string().contains("circular"), "{err}");
}

#[test]
fn project_circle_world_matches_circle_image_conic() {
    let k = intrinsics();
    let mut r = rng(11);
    for t_co in poses(12, 40) {
        // Any world frame and any in-plane rotation of the object frame.
        let t_wc = Isometry3::new(
            Vector3::new(
                r.random_range(-1.0..1.0),
                r.random_range(-1.0..1.0),
                r.random_range(-1.0..1.0),
            ),
            Vector3::new(
                r.random_range(-2.0..2.0),
                r.random_range(-2.0..2.0),
                r.random_range(-2.0..2.0),
            ),
        );
        let spin = Isometry3::new(Vector3::zeros(), Vector3::z() * r.random_range(-PI..PI));
        let t_wo = t_wc * t_co * spin;
        let center = t_wo.translation.vector;
        let normal = t_wo.rotation * Vector3::z() * r.random_range(0.1..10.0);
        let t_cw = t_wc.inverse();
        let got = project_circle_world(&k, &t_cw, &center, &normal, 0.15).unwrap();
        let want = project_circle(&k, &t_co, 0.15).unwrap();
        assert_same_ellipse(&want, &got, 1e-9);
        let cw = circle_image_conic(&k, &(t_cw * t_wo), 0.15).unwrap();
        let co = circle_image_conic(&k, &t_co, 0.15).unwrap();
        assert!((cw - co).norm() < 1e-12);
    }
    let err = project_circle_world(
        &k,
        &Isometry3::identity(),
        &Vector3::z(),
        &Vector3::zeros(),
        0.1,
    );
    assert!(matches!(
        err,
        Err(GeometryError::InvalidParameter {
            what: "normal length",
            ..
        })
    ));
}

#[test]
fn circle_image_errors() {
    let k = intrinsics();
    let front = Isometry3::new(Vector3::new(0.0, 0.0, 0.5), Vector3::new(0.3, 0.0, 0.0));
    for r in [0.0, -0.1] {
        assert!(matches!(
            circle_image_conic(&k, &front, r),
            Err(GeometryError::InvalidParameter { what: "radius", .. })
        ));
    }
    assert!(matches!(
        circle_image_conic(&k, &front, f64::NAN),
        Err(GeometryError::NonFinite { .. })
    ));
    // Camera centre in the circle plane: the plane x = 0 of the camera (rotate the object
    // z axis onto the camera x axis) with the circle ahead.
    let edge_on = Isometry3::new(
        Vector3::new(0.0, 0.0, 0.5),
        Vector3::new(0.0, FRAC_PI_2, 0.0),
    );
    match circle_image_conic(&k, &edge_on, 0.1) {
        Err(GeometryError::DegenerateConic { reason }) => {
            assert!(reason.contains("plane"), "{reason}")
        }
        other => panic!("{other:?}"),
    }
    // Tilted so that part of the rim is behind the camera.
    let crossing = Isometry3::new(Vector3::new(0.0, 0.0, 0.1), Vector3::new(1.2, 0.0, 0.0));
    match circle_image_conic(&k, &crossing, 0.15) {
        Err(GeometryError::NotProjectable { z, reason, .. }) => {
            assert!(z <= 0.0 && reason.contains("crosses"), "{z} {reason}");
        }
        other => panic!("{other:?}"),
    }
    let behind = Isometry3::new(Vector3::new(0.0, 0.0, -0.5), Vector3::new(0.3, 0.0, 0.0));
    match project_circle(&k, &behind, 0.15) {
        Err(GeometryError::NotProjectable { reason, .. }) => assert!(reason.contains("behind")),
        other => panic!("{other:?}"),
    }
    let mut bad_k = k;
    bad_k[(2, 0)] = 0.1;
    assert!(matches!(
        circle_image_conic(&bad_k, &front, 0.1),
        Err(GeometryError::InvalidParameter { .. })
    ));
    let mut singular = k;
    singular[(0, 0)] = 0.0;
    singular[(0, 1)] = 0.0;
    singular[(0, 2)] = 0.0;
    assert!(matches!(
        circle_image_conic(&singular, &front, 0.1),
        Err(GeometryError::InvalidParameter { .. })
    ));
}

fn unit(i: usize) -> Vector6<f64> {
    let mut v = Vector6::zeros();
    v[i] = 1.0;
    v
}

#[test]
fn conic_pose_jacobian_matches_finite_differences() {
    let k = intrinsics();
    let radius = 0.15;
    let h = 1e-6;
    for t_co in poses(13, 30) {
        let (c, dc) = circle_image_conic_jacobian(&k, &t_co, radius).unwrap();
        assert_eq!(c, circle_image_conic(&k, &t_co, radius).unwrap());
        for (i, d) in dc.iter().enumerate() {
            let plus = circle_image_conic(&k, &se3_plus(&t_co, &(unit(i) * h)), radius).unwrap();
            let minus = circle_image_conic(&k, &se3_plus(&t_co, &(unit(i) * -h)), radius).unwrap();
            let fd = (plus - minus) / (2.0 * h);
            assert!(
                (d - fd).norm() <= 1e-6 * fd.norm().max(1e-3),
                "δ{i}: {d} vs {fd}"
            );
        }
    }
}

#[test]
fn ellipse_pose_jacobian_matches_finite_differences() {
    let k = intrinsics();
    let radius = 0.15;
    let h = 1e-6;
    for t_co in poses(14, 30) {
        let (e, j) = project_circle_jacobian(&k, &t_co, radius).unwrap();
        assert_eq!(e, project_circle(&k, &t_co, radius).unwrap());
        for i in 0..6 {
            let p = project_circle(&k, &se3_plus(&t_co, &(unit(i) * h)), radius).unwrap();
            let m = project_circle(&k, &se3_plus(&t_co, &(unit(i) * -h)), radius).unwrap();
            let fd = [
                (p.cx - m.cx) / (2.0 * h),
                (p.cy - m.cy) / (2.0 * h),
                (p.a - m.a) / (2.0 * h),
                (p.b - m.b) / (2.0 * h),
                dtheta(p.theta, m.theta) / (2.0 * h),
            ];
            for (row, f) in fd.iter().enumerate() {
                let scale = j.row(row).norm();
                assert!(
                    (j[(row, i)] - f).abs() <= 1e-6 * scale,
                    "row {row} δ{i}: {} vs {f}",
                    j[(row, i)]
                );
            }
        }
    }
}

#[test]
fn conic_to_ellipse_gradient_matches_finite_differences() {
    let mut r = rng(15);
    for e in ellipses(16, 60)
        .into_iter()
        .filter(|e| e.a - e.b > 1e-3 * e.a)
    {
        // Arbitrary scale and sign of the input conic.
        let c = e.conic() * if r.random::<bool>() { -0.37 } else { 12.0 };
        let (back, grads) = Ellipse::from_conic_with_gradient(&c).unwrap();
        assert_eq!(back, Ellipse::from_conic(&c).unwrap());
        // Perturb each entry on its own scale: in pixel units the entries of eq. (3.3)
        // grow like σᵢσⱼ with σ = (1, 1, |c| + a).
        let l = e.cx.abs() + e.cy.abs() + e.a;
        let sigma = Vector3::new(1.0, 1.0, l);
        let m_scale = c.fixed_view::<2, 2>(0, 0).norm();
        for _ in 0..4 {
            let dir = sym(&Matrix3::from_fn(|i, j| {
                r.random_range(-1.0..1.0) * sigma[i] * sigma[j] * m_scale
            }));
            // f₀ is a difference of terms ~(|c|/b)² larger, which amplifies the step (and
            // the truncation error); a smaller step would drown θ ≈ ±π/2 in rounding.
            let h = 1e-7;
            let p = Ellipse::from_conic(&(c + dir * h)).unwrap();
            let m = Ellipse::from_conic(&(c - dir * h)).unwrap();
            let fd = [
                (p.cx - m.cx) / (2.0 * h),
                (p.cy - m.cy) / (2.0 * h),
                (p.a - m.a) / (2.0 * h),
                (p.b - m.b) / (2.0 * h),
                dtheta(p.theta, m.theta) / (2.0 * h),
            ];
            let values = [e.cx, e.cy, e.a, e.b, e.theta];
            for k in 0..5 {
                let an = grads[k].dot(&dir);
                // Sensitivity scale of this parameter to this perturbation, plus the
                // rounding of the parameter value over the step.
                let scale = grads[k].abs().dot(&dir.abs());
                let rounding = 16.0 * f64::EPSILON * values[k].abs() / h;
                assert!(
                    (an - fd[k]).abs() <= 1e-6 * scale + rounding,
                    "{e:?} param {k}: {an} vs {} (scale {scale})",
                    fd[k]
                );
            }
        }
    }
}

#[test]
fn conic_parameter_jacobian_matches_finite_differences() {
    for e in ellipses(17, 40) {
        let j = e.conic_jacobian();
        let base = [e.cx, e.cy, e.a, e.b, e.theta];
        for k in 0..5 {
            let h = 1e-6 * if k < 4 { e.a } else { 1.0 };
            let mut p = base;
            let mut m = base;
            p[k] += h;
            m[k] -= h;
            // Build without canonicalisation: eq. (3.3) is smooth in the raw parameters.
            let ep = Ellipse {
                cx: p[0],
                cy: p[1],
                a: p[2],
                b: p[3],
                theta: p[4],
            };
            let em = Ellipse {
                cx: m[0],
                cy: m[1],
                a: m[2],
                b: m[3],
                theta: m[4],
            };
            let fd = (ep.conic() - em.conic()) / (2.0 * h);
            assert!(
                (j[k] - fd).norm() <= 1e-6 * (fd.norm() + e.conic().norm() / e.a),
                "{e:?} k={k}"
            );
        }
    }
}

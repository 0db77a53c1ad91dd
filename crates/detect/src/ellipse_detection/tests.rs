//! Tests of [`super`] against closed-form truth: drawn ellipses of both polarities, thin
//! lines, partial arcs, noise, and the false alarms on pure noise.

use super::a_contrario::{covered_extent, score};
use super::noise::gradient_noise;
use super::*;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;

/// Fraction of the pixel `(x, y)` inside the ellipse (`inside(u, v)` on a 8×8 subgrid).
fn coverage(x: usize, y: usize, inside: &dyn Fn(f64, f64) -> bool) -> f64 {
    let s = 8;
    let mut c = 0;
    for j in 0..s {
        for i in 0..s {
            let u = x as f64 - 0.5 + (i as f64 + 0.5) / s as f64;
            let v = y as f64 - 0.5 + (j as f64 + 0.5) / s as f64;
            if inside(u, v) {
                c += 1;
            }
        }
    }
    c as f64 / (s * s) as f64
}

/// Value `q(u, v)` of eq. (3.1) minus 1 in the ellipse frame, scaled to pixels near the
/// curve (`≈` signed distance for `|q| ≪ 1`): `(√q − 1)·b`-like. Used for thin rings.
fn frame(e: &Ellipse, u: f64, v: f64) -> (f64, f64) {
    let (s, c) = e.theta.sin_cos();
    let (du, dv) = (u - e.cx, v - e.cy);
    (c * du + s * dv, -s * du + c * dv)
}

/// Grey image (f32, 0–255) with `inside` at `fg`, elsewhere `bg`, antialiased.
fn draw(w: usize, h: usize, bg: f64, fg: f64, inside: &dyn Fn(f64, f64) -> bool) -> Vec<f32> {
    let mut img = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let c = coverage(x, y, inside);
            img[y * w + x] = (bg + (fg - bg) * c) as f32;
        }
    }
    img
}

fn disc(e: Ellipse) -> impl Fn(f64, f64) -> bool {
    move |u, v| {
        let (x, y) = frame(&e, u, v);
        (x / e.a).powi(2) + (y / e.b).powi(2) <= 1.0
    }
}

/// A ring of width `width` centred on `e`: between the ellipses with semi-axes `± width/2`.
fn ring(e: Ellipse, width: f64) -> impl Fn(f64, f64) -> bool {
    move |u, v| {
        let (x, y) = frame(&e, u, v);
        let outer = (x / (e.a + width / 2.0)).powi(2) + (y / (e.b + width / 2.0)).powi(2) <= 1.0;
        let inner = (x / (e.a - width / 2.0)).powi(2) + (y / (e.b - width / 2.0)).powi(2) <= 1.0;
        outer && !inner
    }
}

fn add_noise(img: &mut [f32], sigma: f64, seed: u64) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = Normal::new(0.0, sigma).unwrap();
    for p in img.iter_mut() {
        *p = (f64::from(*p) + n.sample(&mut rng)).clamp(0.0, 255.0) as f32;
    }
}

fn to_u8(img: &[f32]) -> Vec<u8> {
    img.iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect()
}

fn detect(img: &[u8], w: usize, h: usize, params: &EllipseDetectParams) -> Vec<EllipseDetection> {
    detect_ellipses(&GrayView::new(img, w, h).unwrap(), params).unwrap()
}

fn assert_close(d: &EllipseDetection, e: &Ellipse, centre_tol: f64, axis_tol: f64) {
    let f = &d.ellipse;
    let dc = ((f.cx - e.cx).powi(2) + (f.cy - e.cy).powi(2)).sqrt();
    assert!(dc < centre_tol, "centre off by {dc}: {f:?} vs {e:?}");
    assert!((f.a - e.a).abs() < axis_tol, "a: {f:?} vs {e:?}");
    assert!((f.b - e.b).abs() < axis_tol, "b: {f:?} vs {e:?}");
}

#[test]
fn bright_and_dark_discs_have_their_polarity() {
    let (w, h) = (240, 180);
    let e = Ellipse::new(118.3, 92.6, 70.0, 40.0, 0.3).unwrap();
    for (bg, fg, pol) in [(30.0, 200.0, -1), (210.0, 60.0, 1)] {
        let img = to_u8(&draw(w, h, bg, fg, &disc(e)));
        let found = detect(&img, w, h, &EllipseDetectParams::default());
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].polarity, pol);
        assert_close(&found[0], &e, 0.1, 0.15);
        assert!(found[0].score > 20.0, "{}", found[0].score);
        let cov = found[0].covariance.unwrap();
        assert!(cov[(0, 0)] > 0.0 && cov[(0, 0)] < 0.01);
    }
}

#[test]
fn thin_line_is_reported_on_its_centre() {
    let (w, h) = (240, 180);
    let e = Ellipse::new(121.0, 88.4, 80.0, 30.0, -0.2).unwrap();
    let img = to_u8(&draw(w, h, 20.0, 180.0, &ring(e, 1.5)));
    let params = EllipseDetectParams {
        max_line_width: Some(4.0),
        ..EllipseDetectParams::default()
    };
    let found = detect(&img, w, h, &params);
    let brief: Vec<_> = found
        .iter()
        .map(|d| (d.ellipse, d.points.len(), d.score, d.polarity))
        .collect();
    assert_eq!(found.len(), 1, "{brief:?}");
    assert_eq!(found[0].polarity, 0);
    assert_close(&found[0], &e, 0.15, 0.3);
    // Without line pairing the two edges come out, one of each polarity, either side.
    let edges = detect(&img, w, h, &EllipseDetectParams::default());
    assert_eq!(edges.len(), 2, "{edges:?}");
    let mut pols: Vec<i8> = edges.iter().map(|d| d.polarity).collect();
    pols.sort();
    assert_eq!(pols, vec![-1, 1]);
    let b_out = edges.iter().map(|d| d.ellipse.b).fold(0.0, f64::max);
    assert!(b_out > e.b + 0.3, "{b_out}");
}

#[test]
fn partial_arc_under_an_occluder() {
    // Only the lower 40 % of a dark ring's disc is visible below a bright occluder.
    let (w, h) = (320, 200);
    let e = Ellipse::new(160.2, 70.7, 120.0, 50.0, 0.0).unwrap();
    let d = disc(e);
    let occluded = move |u: f64, v: f64| d(u, v) && v > 90.0;
    let mut img = draw(w, h, 40.0, 190.0, &occluded);
    add_noise(&mut img, 2.0, 7);
    let found = detect(&to_u8(&img), w, h, &EllipseDetectParams::default());
    let best = found
        .iter()
        .find(|f| (f.ellipse.a - e.a).abs() < 5.0)
        .unwrap_or_else(|| panic!("{found:?}"));
    assert_close(best, &e, 1.0, 1.2);
}

#[test]
fn noisy_low_contrast_ellipse_is_found() {
    let (w, h) = (240, 180);
    let e = Ellipse::new(120.5, 90.5, 60.0, 45.0, 1.0).unwrap();
    let mut img = draw(w, h, 100.0, 140.0, &disc(e));
    add_noise(&mut img, 4.0, 11);
    let found = detect(&to_u8(&img), w, h, &EllipseDetectParams::default());
    assert!(!found.is_empty());
    assert_close(&found[0], &e, 0.3, 0.4);
}

#[test]
fn pure_noise_gives_no_detection() {
    // The a-contrario guarantee: fewer than max_nfa = 1 false detections per image on
    // average; over 6 images of Gaussian noise none is expected.
    let (w, h) = (320, 240);
    let mut total = 0;
    for seed in 0..6 {
        let mut img = vec![128f32; w * h];
        add_noise(&mut img, 8.0 + 4.0 * seed as f64, 100 + seed);
        total += detect(&to_u8(&img), w, h, &EllipseDetectParams::default()).len();
    }
    assert_eq!(total, 0);
}

#[test]
fn flat_images_give_nothing() {
    let (w, h) = (64, 48);
    for v in [0u8, 128, 255] {
        let img = vec![v; w * h];
        assert!(detect(&img, w, h, &EllipseDetectParams::default()).is_empty());
    }
}

#[test]
fn bad_options_and_tiny_images_are_errors() {
    let img = vec![0u8; 100];
    let view = GrayView::new(&img, 10, 10).unwrap();
    for p in [
        EllipseDetectParams {
            max_nfa: 0.0,
            ..Default::default()
        },
        EllipseDetectParams {
            min_arc_points: 2,
            ..Default::default()
        },
        EllipseDetectParams {
            max_line_width: Some(f64::NAN),
            ..Default::default()
        },
        EllipseDetectParams {
            blur_sigma: -1.0,
            ..Default::default()
        },
    ] {
        assert!(matches!(
            detect_ellipses(&view, &p),
            Err(DetectError::InvalidParameter { .. })
        ));
    }
    let small = GrayView::new(&img[..16], 4, 4).unwrap();
    assert!(detect_ellipses(&small, &EllipseDetectParams::default()).is_err());
}

#[test]
fn nfa_score_matches_the_binomial_sum() {
    // Independent truth: the tail summed term by term with exact binomial coefficients.
    let p: f64 = 0.125;
    for (n, k) in [(20usize, 10usize), (40, 12), (60, 60), (30, 5), (100, 40)] {
        let mut tail = 0.0;
        for i in k..=n {
            let mut c = 1.0f64;
            for j in 0..i {
                c = c * (n - j) as f64 / (j + 1) as f64;
            }
            tail += c * p.powi(i as i32) * (1.0 - p).powi((n - i) as i32);
        }
        let s = score(n, k, p, 3.0);
        assert!((s - (-tail.log10() - 3.0)).abs() < 1e-9, "{n} {k}: {s}");
    }
    // At or below chance the score is −log10 N_tests.
    assert_eq!(score(80, 10, p, 3.0), -3.0);
}

#[test]
fn covered_extent_is_the_circle_minus_the_largest_gap() {
    let (s, l) = covered_extent(&[0.1, 0.5, 1.0]);
    assert!((s - 0.1).abs() < 1e-12 && (l - 0.9).abs() < 1e-12);
    // Across 0: points at −0.3 … 0.4.
    let (s, l) = covered_extent(&[-0.3, 0.0, 0.4]);
    assert!((s - (TAU - 0.3)).abs() < 1e-12 && (l - 0.7).abs() < 1e-12);
}

use std::f64::consts::TAU;

#[test]
fn gradient_noise_estimates_the_sobel_noise() {
    // White noise of σ grey levels gives Sobel/8 components of σ·√(12/64).
    let (w, h) = (300, 200);
    for sigma in [3.0, 10.0] {
        let mut img = vec![128f32; w * h];
        let mut rng = Pcg64::seed_from_u64(3);
        let n = Normal::new(0.0, sigma).unwrap();
        for p in img.iter_mut() {
            *p = (f64::from(*p) + n.sample(&mut rng)) as f32 / 255.0;
        }
        let est = gradient_noise(&GrayView::new(&img, w, h).unwrap(), 1);
        let truth = sigma * (12.0f64 / 64.0).sqrt();
        assert!((est / truth - 1.0).abs() < 0.05, "{est} vs {truth}");
    }
}

/// Lines found on their centres ([`ridges`]): the thin-ring cases of the edge tests.
mod lines_on_their_centre {
    use super::super::ridges::{RidgeField, detect_line_ellipses, ridge_scale};
    use super::*;

    fn lines(img: &[u8], w: usize, h: usize, sigma: f64) -> Vec<EllipseDetection> {
        detect_line_ellipses(
            &GrayView::new(img, w, h).unwrap(),
            &EllipseDetectParams::default(),
            sigma,
        )
        .unwrap()
    }

    #[test]
    fn bright_and_dark_thin_rings_are_found_on_their_centre_lines() {
        let (w, h) = (260, 190);
        let e = Ellipse::new(130.4, 95.3, 95.0, 28.0, 0.15).unwrap();
        for (bg, fg, width) in [(20.0, 200.0, 1.0), (210.0, 70.0, 1.4), (30.0, 140.0, 0.7)] {
            let mut img = draw(w, h, bg, fg, &ring(e, width));
            add_noise(&mut img, 2.0, 3);
            let found = lines(&to_u8(&img), w, h, 0.8);
            let brief: Vec<_> = found
                .iter()
                .map(|d| (d.ellipse, d.points.len(), d.score))
                .collect();
            assert_eq!(found.len(), 1, "width {width}: {brief:?}");
            assert_eq!(found[0].polarity, 0);
            assert_close(&found[0], &e, 0.15, 0.25);
            assert!(found[0].score > 20.0);
        }
    }

    #[test]
    fn two_lines_three_pixels_apart_stay_apart() {
        // The two rims of a wafer drawn as lines: one ellipse moved 3 px along its minor axis.
        let (w, h) = (300, 160);
        let upper = Ellipse::new(150.2, 70.6, 120.0, 30.0, 0.0).unwrap();
        let lower = Ellipse::new(150.2, 73.6, 120.0, 30.6, 0.0).unwrap();
        let (ru, rl) = (ring(upper, 1.0), ring(lower, 1.0));
        let mut img = draw(w, h, 15.0, 190.0, &move |u, v| ru(u, v) || rl(u, v));
        add_noise(&mut img, 2.0, 5);
        let found = lines(&to_u8(&img), w, h, 0.8);
        for truth in [upper, lower] {
            let best = found
                .iter()
                .min_by(|p, q| {
                    let d = |f: &EllipseDetection| (f.ellipse.cy - truth.cy).abs();
                    d(p).total_cmp(&d(q))
                })
                .unwrap_or_else(|| panic!("{found:?}"));
            assert_close(best, &truth, 0.3, 0.5);
        }
    }

    #[test]
    fn pure_noise_gives_no_line() {
        let (w, h) = (320, 240);
        let mut total = 0;
        for seed in 0..6 {
            let mut img = vec![128f32; w * h];
            add_noise(&mut img, 6.0 + 4.0 * seed as f64, 200 + seed);
            total += lines(&to_u8(&img), w, h, 0.8).len();
        }
        assert_eq!(total, 0);
    }

    #[test]
    fn anisotropic_part_is_rayleigh_under_white_noise() {
        // The noise model of the thresholds: on white Gaussian noise the median of
        // q = √(((r_xx − r_yy)/2)² + r_xy²) is the Rayleigh median s_q·√(2 ln 2).
        let (w, h) = (400, 300);
        let mut img = vec![100f32; w * h];
        add_noise(&mut img, 10.0, 9);
        let view = GrayView::new(&img, w, h).unwrap();
        let sigma_g = gradient_noise(&view, 1);
        for sigma in [0.6, 0.8, 1.5] {
            let field = RidgeField::new(&view, sigma, sigma_g);
            let mut q = field.anisotropy_sample(3);
            let mid = q.len() / 2;
            q.select_nth_unstable_by(mid, f64::total_cmp);
            let expected = field.noise * (2.0 * std::f64::consts::LN_2).sqrt();
            let ratio = q[mid] / expected;
            assert!((ratio - 1.0).abs() < 0.1, "sigma {sigma}: ratio {ratio}");
        }
    }

    #[test]
    fn scale_covers_the_widest_line() {
        assert_eq!(ridge_scale(1.0), 0.6);
        assert!((ridge_scale(4.0) - 4.0 / (2.0 * 3f64.sqrt())).abs() < 1e-12);
    }
}

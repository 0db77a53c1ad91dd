use super::*;
use autoteach_geometry::render::opening::{
    ImageLine, ImagePolygon, OpeningScene, Placement, RefPolygon, render_opening, to_image,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Cross-shaped opening template (reference units ≈ pixels at scale 1).
fn cross() -> Vec<Vector2<f64>> {
    [
        (-80.0, -20.0),
        (-30.0, -20.0),
        (-30.0, -40.0),
        (30.0, -40.0),
        (30.0, -20.0),
        (80.0, -20.0),
        (80.0, 20.0),
        (30.0, 20.0),
        (30.0, 40.0),
        (-30.0, 40.0),
        (-30.0, 20.0),
        (-80.0, 20.0),
    ]
    .iter()
    .map(|&(x, y)| Vector2::new(x, y))
    .collect()
}

/// A random chamber-opening scene: perspective homography, the opening slightly rotated and
/// scaled, a bar-shaped distractor, clutter lines, an occluder over part of the opening, blur
/// and noise. Returns the scene and the true image centre.
fn scene(seed: u64) -> (OpeningScene, Matrix3<f64>, Vector2<f64>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let (w, h) = (480usize, 360usize);
    let psi: f64 = rng.random_range(-0.3..0.3);
    let k: f64 = rng.random_range(0.85..1.15);
    let (s, c) = psi.sin_cos();
    let a = Matrix3::new(k * c, -k * s, 0.0, k * s, k * c, 0.0, 0.0, 0.0, 1.0);
    let p = Matrix3::new(
        1.0,
        0.0,
        0.0,
        0.0,
        1.0,
        0.0,
        rng.random_range(-6e-4..6e-4),
        rng.random_range(-6e-4..6e-4),
        1.0,
    );
    let t = Matrix3::new(1.0, 0.0, 240.0, 0.0, 1.0, 180.0, 0.0, 0.0, 1.0);
    let hmat = t * p * a;
    let place = Placement {
        centre: Vector2::new(rng.random_range(-40.0..40.0), rng.random_range(-30.0..30.0)),
        rotation: rng.random_range(-0.1..0.1),
        scale: rng.random_range(0.93..1.07),
    };
    let bar: Vec<Vector2<f64>> = [(-80.0, -20.0), (80.0, -20.0), (80.0, 20.0), (-80.0, 20.0)]
        .iter()
        .map(|&(x, y)| Vector2::new(x, y))
        .collect();
    let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
    let distractor = Placement {
        centre: place.centre + Vector2::new(rng.random_range(-30.0..30.0), side * 115.0),
        rotation: rng.random_range(-0.1..0.1),
        scale: 1.0,
    };
    let centre_img = to_image(&hmat, &place.centre).unwrap();
    let lines = (0..3)
        .map(|_| ImageLine {
            a: Vector2::new(rng.random_range(0.0..w as f64), 0.0),
            b: Vector2::new(rng.random_range(0.0..w as f64), h as f64),
            width: rng.random_range(1.5..3.0),
            intensity: rng.random_range(40.0..120.0),
        })
        .collect();
    // Occluder: a blob over part of one arm.
    let oc = to_image(&hmat, &(place.centre + Vector2::new(side * 70.0, 0.0))).unwrap();
    let occluders = vec![ImagePolygon {
        vertices: vec![
            oc + Vector2::new(-18.0, -35.0),
            oc + Vector2::new(20.0, -30.0),
            oc + Vector2::new(12.0, 35.0),
        ],
        intensity: 150.0,
    }];
    let sc = OpeningScene {
        width: w,
        height: h,
        homography: hmat,
        plate: 190.0,
        polygons: vec![
            RefPolygon {
                vertices: distractor.apply(&bar),
                intensity: 45.0,
            },
            RefPolygon {
                vertices: place.apply(&cross()),
                intensity: 35.0,
            },
        ],
        lines,
        occluders,
        supersample: 4,
        blur_sigma: 0.8,
        noise_sigma: 3.0,
        seed,
    };
    (sc, hmat, centre_img)
}

#[test]
fn detects_rendered_openings_to_subpixel() {
    let mut ok = 0;
    let n = 10;
    for seed in 0..n {
        let (sc, hmat, truth) = scene(seed);
        let img = render_opening(&sc).unwrap();
        let det = detect_polygon(
            PolygonInput::Image(&img, &SegmentOptions::default()),
            &cross(),
            &hmat,
            &PolygonOptions::default(),
        )
        .unwrap();
        let err = (det.centre_image - truth).norm();
        if err < 1.0 {
            ok += 1;
        }
        eprintln!(
            "seed {seed}: err {err:.3} px, coarse err {:.2}, votes {:.0}, support {}, rms {:.3}",
            (to_image(&hmat, &det.coarse.centre).unwrap() - truth).norm(),
            det.votes,
            det.support.len(),
            det.rms
        );
    }
    assert!(ok >= n - 1, "{ok}/{n} under 1 px");
}

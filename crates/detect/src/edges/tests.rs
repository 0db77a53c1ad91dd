use super::arcs::side_bends;
use super::*;
use autoteach_geometry::conic::Ellipse;

/// A synthetic image: a bright filled ellipse (antialiased by supersampling) on dark.
fn disc_image(w: usize, h: usize, cx: f64, cy: f64, a: f64, b: f64) -> Vec<u8> {
    let mut img = vec![0u8; w * h];
    let s = 8;
    for y in 0..h {
        for x in 0..w {
            let mut inside = 0;
            for j in 0..s {
                for i in 0..s {
                    let u = x as f64 - 0.5 + (i as f64 + 0.5) / s as f64;
                    let v = y as f64 - 0.5 + (j as f64 + 0.5) / s as f64;
                    let q = ((u - cx) / a).powi(2) + ((v - cy) / b).powi(2);
                    if q <= 1.0 {
                        inside += 1;
                    }
                }
            }
            img[y * w + x] = (30.0 + 170.0 * inside as f64 / (s * s) as f64).round() as u8;
        }
    }
    img
}

/// The whole-image implementation of `canny` (Sobel, magnitude, state and
/// offset images, hysteresis over all pixels): the reference of the fused pass.
fn canny_reference<T: Pixel>(image: &GrayView<'_, T>, params: &CannyParams) -> Result<EdgeMap> {
    params.validate()?;
    let (w, h) = (image.width, image.height);
    let mut img: Vec<f32> = image.data.par_iter().map(|p| p.grey()).collect();
    if params.blur_sigma > 0.0 {
        gaussian_blur(&mut img, w, h, params.blur_sigma);
    }
    let (gx, gy) = sobel(&img, w, h);
    let low = params.low as f32;
    let high = params.high as f32;
    // Squared magnitudes: monotone in the magnitude, so the suppression can compare them; the
    // square roots are taken only for the parabolic refinement of the maxima.
    let mag: Vec<f32> = gx
        .par_iter()
        .zip(gy.par_iter())
        .map(|(a, b)| a * a + b * b)
        .collect();
    let (low, high) = (low * low, high * high);
    // Non-maximum suppression (rows in parallel); `state`: 0 none, 1 candidate (≥ low),
    // 2 strong (≥ high).
    let mut state = vec![0u8; w * h];
    let mut offset = vec![0.0f32; w * h];
    if w >= 5 && h >= 5 {
        state
            .par_chunks_mut(w)
            .zip(offset.par_chunks_mut(w))
            .enumerate()
            .filter(|(y, _)| *y >= 2 && *y + 2 < h)
            .for_each(|(y, (srow, orow))| {
                for x in 2..w - 2 {
                    let k = y * w + x;
                    let m = mag[k];
                    if !(m >= low) || m == 0.0 {
                        continue;
                    }
                    let horizontal = gx[k].abs() >= gy[k].abs();
                    let (ma, mb) = if horizontal {
                        (mag[k - 1], mag[k + 1])
                    } else {
                        (mag[k - w], mag[k + w])
                    };
                    // Strict on one side, non-strict on the other (von Gioi & Randall 2017).
                    if m > ma && m >= mb {
                        srow[x] = if m >= high { 2 } else { 1 };
                        let (ma, m, mb) = (ma.sqrt(), m.sqrt(), mb.sqrt());
                        let den = ma - 2.0 * m + mb;
                        orow[x] = if den < 0.0 {
                            (0.5 * (ma - mb) / den).clamp(-0.5, 0.5)
                        } else {
                            0.0
                        };
                    }
                }
            });
    }
    // Hysteresis: grow from strong pixels through 8-connected candidates.
    let mut keep = vec![false; w * h];
    let mut stack = Vec::new();
    for k in 0..w * h {
        if state[k] == 2 && !keep[k] {
            keep[k] = true;
            stack.push(k);
            while let Some(p) = stack.pop() {
                let (px, py) = (p % w, p / w);
                for dy in [-1isize, 0, 1] {
                    for dx in [-1isize, 0, 1] {
                        let (qx, qy) = (px as isize + dx, py as isize + dy);
                        if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                            continue;
                        }
                        let q = qy as usize * w + qx as usize;
                        if state[q] != 0 && !keep[q] {
                            keep[q] = true;
                            stack.push(q);
                        }
                    }
                }
            }
        }
    }
    let mut edgels = Vec::new();
    let mut index = vec![NONE; w * h];
    for k in 0..w * h {
        if !keep[k] {
            continue;
        }
        let (x, y) = (k % w, k / w);
        let horizontal = gx[k].abs() >= gy[k].abs();
        let o = f64::from(offset[k]);
        let pos = if horizontal {
            Vector2::new(x as f64 + o, y as f64)
        } else {
            Vector2::new(x as f64, y as f64 + o)
        };
        index[k] = edgels.len() as u32;
        edgels.push(Edgel {
            pos,
            grad: Vector2::new(f64::from(gx[k]), f64::from(gy[k])),
            px: x as u32,
            py: y as u32,
        });
    }
    Ok(EdgeMap {
        width: w,
        height: h,
        edgels,
        index,
    })
}

/// Two overlapping bright ellipses, a dark disc and deterministic noise.
fn textured_image(w: usize, h: usize) -> Vec<u8> {
    let a = disc_image(
        w,
        h,
        0.45 * w as f64,
        0.5 * h as f64,
        0.3 * w as f64,
        0.2 * h as f64,
    );
    let b = disc_image(
        w,
        h,
        0.6 * w as f64,
        0.45 * h as f64,
        0.15 * w as f64,
        0.3 * h as f64,
    );
    let mut state = 12345u64;
    a.iter()
        .zip(&b)
        .enumerate()
        .map(|(k, (&p, &q))| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((state >> 33) % 9) as f64 - 4.0;
            let (x, y) = ((k % w) as f64, (k / w) as f64);
            let dark = if (x - 0.2 * w as f64).hypot(y - 0.3 * h as f64) < 0.1 * h as f64 {
                -60.0
            } else {
                0.0
            };
            (f64::from(p) + 0.6 * f64::from(q) + noise + dark).clamp(0.0, 255.0) as u8
        })
        .collect()
}

#[test]
fn fused_canny_equals_the_whole_image_reference() {
    // Sizes that leave partial row blocks; u8 and f32 pixels, with and without pre-blur.
    for (w, h) in [(211, 157), (64, 5), (5, 64), (320, 97)] {
        let data = textured_image(w, h);
        let floats: Vec<f32> = data.iter().map(|&v| f32::from(v) / 255.0).collect();
        for params in [
            CannyParams::default(),
            CannyParams {
                low: 3.0,
                high: 8.0,
                blur_sigma: 1.2,
            },
        ] {
            let view = GrayView::new(&data, w, h).unwrap();
            let (got, want) = (
                canny(&view, &params).unwrap(),
                canny_reference(&view, &params).unwrap(),
            );
            assert!(
                w < 6 || h < 6 || got.edgels.len() > 20,
                "{w}x{h}: {}",
                got.edgels.len()
            );
            assert_eq!(got.edgels, want.edgels, "{w}x{h} u8 {params:?}");
            assert_eq!(got.index, want.index);
            let view = GrayView::new(&floats, w, h).unwrap();
            let (got, want) = (
                canny(&view, &params).unwrap(),
                canny_reference(&view, &params).unwrap(),
            );
            assert_eq!(got.edgels, want.edgels, "{w}x{h} f32 {params:?}");
            assert_eq!(got.index, want.index);
        }
    }
}

#[test]
fn workspace_canny_equals_the_reference_over_a_sequence_of_frames() {
    // One workspace over frames of changing content, size, pixel type and parameters, a
    // rejected call and a call that did not finish: every map equals the whole-image
    // reference (the sparse reset leaves no edgel of an earlier frame behind).
    let mut ws = EdgeWorkspace::new();
    let blur = CannyParams {
        low: 3.0,
        high: 8.0,
        blur_sigma: 1.2,
    };
    let frames = [
        (211, 157, CannyParams::default()),
        (211, 157, blur),
        (211, 157, CannyParams::default()),
        (64, 5, CannyParams::default()),
        (320, 97, blur),
        (320, 97, CannyParams::default()),
    ];
    for (f, &(w, h, params)) in frames.iter().enumerate() {
        // Shift the content between frames of one size so that the edgels move.
        let mut data = textured_image(w, h);
        let shift = f * 7 % data.len();
        data.rotate_left(shift);
        let view = GrayView::new(&data, w, h).unwrap();
        let want = canny_reference(&view, &params).unwrap();
        let got = ws.canny(&view, &params).unwrap();
        assert!(w < 6 || h < 6 || got.edgels.len() > 20);
        assert_eq!(got.edgels, want.edgels, "frame {f} {w}x{h}");
        assert_eq!(got.index, want.index, "frame {f} {w}x{h}");
        assert!(ws.state.iter().all(|&s| s == 0), "state not cleared");
        let floats: Vec<f32> = data.iter().map(|&v| f32::from(v) / 255.0).collect();
        let view = GrayView::new(&floats, w, h).unwrap();
        let got = ws.canny(&view, &params).unwrap();
        assert_eq!(got.edgels, canny_reference(&view, &params).unwrap().edgels);
    }
    let (w, h) = (211, 157);
    let data = textured_image(w, h);
    let view = GrayView::new(&data, w, h).unwrap();
    let bad = CannyParams {
        low: f64::NAN,
        ..CannyParams::default()
    };
    assert!(matches!(
        ws.canny(&view, &bad),
        Err(DetectError::InvalidParameter { .. })
    ));
    let want = canny_reference(&view, &CannyParams::default()).unwrap();
    assert_eq!(
        ws.canny(&view, &CannyParams::default()).unwrap().index,
        want.index
    );
    // A call that stopped half-way (a panic inside) leaves garbage: the next call must not
    // trust the buffers.
    ws.busy = true;
    ws.state.iter_mut().for_each(|s| *s = 2);
    ws.map.index.iter_mut().for_each(|i| *i = 7);
    let got = ws.canny(&view, &CannyParams::default()).unwrap();
    assert_eq!(got.edgels, want.edgels);
    assert_eq!(got.index, want.index);
}

#[test]
fn detect_arcs_with_the_thread_workspace_equals_the_allocating_steps() {
    let (w, h) = (320, 240);
    let mut ws = EdgeWorkspace::new();
    for (k, (cx, cy)) in [(150.0, 120.0), (170.0, 110.0), (150.0, 120.0)]
        .into_iter()
        .enumerate()
    {
        let data = disc_image(w, h, cx, cy, 90.0 + 5.0 * k as f64, 60.0);
        let view = GrayView::new(&data, w, h).unwrap();
        let (cp, lp, ap) = (
            CannyParams::default(),
            LinkParams::default(),
            ArcParams::default(),
        );
        let map = canny(&view, &cp).unwrap();
        let chains = link_edges(&map, &lp).unwrap();
        let want = split_arcs(&map, &chains, &ap).unwrap();
        assert!(want.len() >= 4, "{} arcs", want.len());
        assert_eq!(detect_arcs(&view, &cp, &lp, &ap).unwrap(), want);
        assert_eq!(
            detect_arcs_with(&mut ws, &view, &cp, &lp, &ap).unwrap(),
            want
        );
    }
}

#[test]
fn sobel_matches_imageproc() {
    let (w, h) = (40, 30);
    let data = disc_image(w, h, 20.3, 14.8, 12.0, 8.0);
    let img: Vec<f32> = data.iter().map(|&v| f32::from(v)).collect();
    let (gx, gy) = sobel(&img, w, h);
    let gi = image::GrayImage::from_raw(w as u32, h as u32, data).unwrap();
    let hx = imageproc::gradients::horizontal_sobel(&gi);
    let hy = imageproc::gradients::vertical_sobel(&gi);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let k = y * w + x;
            assert_eq!(gx[k] * 8.0, f32::from(hx.get_pixel(x as u32, y as u32)[0]));
            assert_eq!(gy[k] * 8.0, f32::from(hy.get_pixel(x as u32, y as u32)[0]));
        }
    }
}

#[test]
fn subpixel_edges_lie_on_the_disc_boundary() {
    let (w, h) = (200, 150);
    let (cx, cy, a, b) = (100.3, 74.6, 70.0, 45.0);
    let data = disc_image(w, h, cx, cy, a, b);
    let view = GrayView::new(&data, w, h).unwrap();
    let map = canny(&view, &CannyParams::default()).unwrap();
    assert!(map.edgels.len() > 300, "{}", map.edgels.len());
    let truth = autoteach_geometry::conic::Ellipse::new(cx, cy, a, b, 0.0).unwrap();
    let mut d: Vec<f64> = map
        .edgels
        .iter()
        .map(|e| truth.orthogonal_distance(&e.pos).abs())
        .collect();
    d.sort_by(f64::total_cmp);
    let median = d[d.len() / 2];
    assert!(median < 0.1, "median edge distance {median}");
    assert!(d[d.len() * 95 / 100] < 0.3);
    // Gradient points from dark (outside) to bright (inside).
    for e in &map.edgels {
        let out = e.pos - Vector2::new(cx, cy);
        assert!(e.grad.dot(&out) < 0.0);
    }
}

#[test]
fn disc_gives_four_quadrant_arcs_of_negative_polarity() {
    let (w, h) = (200, 150);
    let data = disc_image(w, h, 100.3, 74.6, 70.0, 45.0);
    let view = GrayView::new(&data, w, h).unwrap();
    let arcs = detect_arcs(
        &view,
        &CannyParams::default(),
        &LinkParams::default(),
        &ArcParams::default(),
    )
    .unwrap();
    let mut quads: Vec<Quadrant> = arcs.iter().map(|a| a.quadrant).collect();
    quads.sort_by_key(|q| *q as u8);
    quads.dedup();
    assert_eq!(
        quads.len(),
        4,
        "{:?}",
        arcs.iter().map(|a| a.quadrant).collect::<Vec<_>>()
    );
    let total: usize = arcs.iter().map(|a| a.points.len()).sum();
    assert!(total > 300, "{total}");
    for arc in &arcs {
        // Brighter inside: the gradient points to the concave side.
        assert_eq!(arc.polarity, -1);
        let c = Vector2::new(100.3, 74.6);
        let mid = arc.points[arc.points.len() / 2] - c;
        let (su, sv) = arc.quadrant.bulge();
        assert!(
            mid.x * su > 0.0 && mid.y * sv > 0.0,
            "{:?} at {mid:?}",
            arc.quadrant
        );
    }
}

#[test]
fn straight_edges_give_no_arcs() {
    let (w, h) = (120, 80);
    let data: Vec<u8> = (0..w * h)
        .map(|k| {
            if (k % w) as f64 > 0.4 * (k / w) as f64 + 40.0 {
                200
            } else {
                20
            }
        })
        .collect();
    let view = GrayView::new(&data, w, h).unwrap();
    let map = canny(&view, &CannyParams::default()).unwrap();
    assert!(map.edgels.len() > 50);
    let chains = link_edges(&map, &LinkParams::default()).unwrap();
    assert!(chains.iter().any(|c| c.len() > 50));
    let arcs = split_arcs(&map, &chains, &ArcParams::default()).unwrap();
    assert!(arcs.is_empty(), "{} arcs from a straight edge", arcs.len());
}

#[test]
fn side_bends_detects_the_sign_of_a_bend_against_the_noise() {
    // Points along a chord of 60 px with white noise σ = 0.1 px across it; a parabolic
    // bend of sagitta h bulges to the left of the chord (h > 0) or to the right.
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let sigma = 0.1;
    let side = |h: f64, seed: u64| {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        (0..=60)
            .map(|k| {
                let s = k as f64 / 30.0 - 1.0;
                // Chord along +u: "left" of it (a positive turn) is −v.
                Vector2::new(k as f64, -h * (1.0 - s * s) + noise.sample(&mut rng))
            })
            .collect::<Vec<_>>()
    };
    let mut straight_hits = 0;
    for seed in 0..200 {
        // Sagitta 0.6 px = 6 σ: found with its sign, never with the other one.
        let left = side(0.6, seed);
        assert!(side_bends(&left, 0, 60, 1.0, sigma, 3.0), "seed {seed}");
        assert!(!side_bends(&left, 0, 60, -1.0, sigma, 3.0), "seed {seed}");
        let right = side(-0.6, seed);
        assert!(side_bends(&right, 0, 60, -1.0, sigma, 3.0), "seed {seed}");
        // A straight side bends significantly only by chance (one-sided 3σ: 0.13 %).
        let line = side(0.0, seed);
        straight_hits += usize::from(side_bends(&line, 0, 60, 1.0, sigma, 3.0));
    }
    assert!(straight_hits <= 2, "{straight_hits} of 200");
    // The noise estimate of a long straight noisy chain is σ (MAD: ≈ 4 % spread on 1000
    // points).
    for seed in 0..20 {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1000 + seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let line: Vec<_> = (0..1000)
            .map(|k| {
                Vector2::new(0.8 * k as f64, 0.6 * k as f64)
                    + Vector2::new(-0.6, 0.8) * noise.sample(&mut rng)
            })
            .collect();
        let est = chain_noise(&line);
        assert!((est - sigma).abs() < 0.15 * sigma, "seed {seed}: {est}");
    }
}

#[test]
fn bad_images_are_errors_or_empty() {
    assert!(matches!(
        GrayView::<u8>::new(&[], 0, 0),
        Err(DetectError::InvalidParameter { .. })
    ));
    assert!(matches!(
        GrayView::new(&[0u8; 5], 2, 3),
        Err(DetectError::WrongLength { .. })
    ));
    let nan = [0.0f32, f32::NAN, 0.0, 0.0];
    assert!(matches!(
        GrayView::new(&nan, 2, 2),
        Err(DetectError::NonFinite { index: 1, .. })
    ));
    for v in [0u8, 255u8] {
        let data = vec![v; 64 * 48];
        let view = GrayView::new(&data, 64, 48).unwrap();
        assert!(
            canny(&view, &CannyParams::default())
                .unwrap()
                .edgels
                .is_empty()
        );
    }
    // Tiny images have no interior: no edges, no panic.
    let data = [0u8, 255, 0, 255, 0, 255];
    let view = GrayView::new(&data, 3, 2).unwrap();
    assert!(
        canny(&view, &CannyParams::default())
            .unwrap()
            .edgels
            .is_empty()
    );
    let bad = CannyParams {
        low: 10.0,
        high: 5.0,
        ..CannyParams::default()
    };
    let data = vec![0u8; 64];
    let view = GrayView::new(&data, 8, 8).unwrap();
    assert!(canny(&view, &bad).is_err());
}

/// An edge chain like the upper rim of a thin disturbance wafer on wafer-benchmark image 21
/// (seed 3) whose edge runs on into a slot tooth's edge at the rim's left tip: a straight
/// tooth edge rising toward the tip, then the front half of the rim `(637, 214)`,
/// `a = 358`, `b = 6.4` (sampled every pixel in u, gradient along the rim's outward
/// normal). The junction turns against the rim (a quadrant change: v falls, then rises).
fn tooth_and_thin_rim_chain() -> (EdgeMap, Vec<Vec<u32>>, Ellipse) {
    let e = Ellipse {
        cx: 637.0,
        cy: 214.0,
        a: 358.0,
        b: 6.4,
        theta: 0.0,
    };
    let mut pts = Vec::new();
    let tip = e.cx - e.a;
    // The tooth edge: 120 px rising by 4 px toward the tip.
    for k in 0..120 {
        let u = tip - 120.0 + k as f64;
        pts.push((
            Vector2::new(u, e.cy + 4.0 * (tip - u) / 120.0),
            Vector2::new(0.0, 1.0),
        ));
    }
    // The rim's front half, tip to tip (v grows downward: the lower half of the ellipse).
    for k in 0..=(2.0 * e.a) as usize {
        let u = tip + k as f64;
        let x = ((u - e.cx) / e.a).clamp(-1.0, 1.0);
        let y = e.b * (1.0 - x * x).sqrt();
        let n = Vector2::new(x / e.a, y / (e.b * e.b)).normalize();
        pts.push((Vector2::new(u, e.cy + y), n));
    }
    let edgels: Vec<Edgel> = pts
        .iter()
        .map(|(p, n)| Edgel {
            pos: *p,
            grad: 50.0 * n,
            px: p.x.round() as u32,
            py: p.y.round() as u32,
        })
        .collect();
    let chain = (0..edgels.len() as u32).collect();
    let map = EdgeMap {
        width: 1280,
        height: 720,
        edgels,
        index: Vec::new(),
    };
    (map, vec![chain], e)
}

#[test]
fn restart_turn_at_cuts_keeps_the_side_after_a_junction_at_the_tip() {
    let (map, chains, e) = tooth_and_thin_rim_chain();
    let tip = e.cx - e.a;
    // The u range of the arc of the rim's left half (quadrant III: bulging toward −u, +v).
    let left_half = |params: &ArcParams| {
        let arcs = split_arcs(&map, &chains, params).unwrap();
        let third: Vec<&Arc> = arcs
            .iter()
            .filter(|a| a.quadrant == Quadrant::III)
            .collect();
        assert_eq!(third.len(), 1, "{params:?}");
        third[0]
            .points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
                (l.min(p.x), h.max(p.x))
            })
    };
    let restart = ArcParams {
        restart_turn_at_cuts: true,
        ..ArcParams::default()
    };
    // Without the rule the junction's turn (against the rim's) makes the rim's first own
    // polygon vertex an inflection: the arc starts there, tens of pixels into the rim (on
    // the noisy edges of the benchmark image, far enough in that the rest of the flat side
    // is dropped as straight).
    let plain = ArcParams {
        restart_turn_at_cuts: false,
        ..ArcParams::default()
    };
    let (lo, _) = left_half(&plain);
    assert!(lo > tip + 20.0, "{lo} vs tip {tip}");
    // With it the left half is one arc from the tip (the junction vertex) to the bottom,
    // and no point of the tooth edge is on it.
    let (lo, hi) = left_half(&restart);
    assert!(lo >= tip && lo < tip + 2.0, "{lo} vs tip {tip}");
    assert!(hi > e.cx, "{hi}");
}

#[test]
fn flat_half_of_a_front_arc_before_a_junction_is_kept() {
    // The lower rim of a flat target wafer (a = 378, b = 25, as on wafer-benchmark image 30
    // of seed 3) from its right tip past its lowest point to u = cx − 0.55·a, where a
    // straight foreign contour (a slot tooth's edge) leaves it downward to the left (an
    // inflection). The half between the lowest point (a quadrant change) and the junction
    // lies within 1.1 px of its chord.
    let e = Ellipse {
        cx: 500.0,
        cy: 270.0,
        a: 378.0,
        b: 25.0,
        theta: 0.0,
    };
    let mut pts = Vec::new();
    let (right, junction) = (e.cx + e.a, e.cx - 0.55 * e.a);
    let mut u = right;
    while u >= junction {
        let x = ((u - e.cx) / e.a).clamp(-1.0, 1.0);
        let y = e.b * (1.0 - x * x).sqrt();
        pts.push(Vector2::new(u, e.cy + y));
        u -= 1.0;
    }
    let end = pts[pts.len() - 1];
    for k in 1..=150 {
        pts.push(end + Vector2::new(-(k as f64), 0.3 * k as f64));
    }
    let edgels: Vec<Edgel> = pts
        .iter()
        .map(|p| Edgel {
            pos: *p,
            grad: Vector2::new(0.0, -50.0),
            px: p.x.round() as u32,
            py: p.y.round() as u32,
        })
        .collect();
    let chains = vec![(0..edgels.len() as u32).collect::<Vec<_>>()];
    let map = EdgeMap {
        width: 1280,
        height: 720,
        edgels,
        index: Vec::new(),
    };
    // The u range of the quadrant-III arcs (the left half of the front arc).
    let left_half = |keep: bool| {
        let params = ArcParams {
            keep_flat_run_pieces: keep,
            ..ArcParams::default()
        };
        let arcs = split_arcs(&map, &chains, &params).unwrap();
        assert!(arcs.iter().any(|a| a.quadrant == Quadrant::IV));
        arcs.iter()
            .filter(|a| a.quadrant == Quadrant::III)
            .map(|a| {
                let us = a.points.iter().map(|p| p.x);
                (
                    us.clone().fold(f64::INFINITY, f64::min),
                    us.fold(0.0, f64::max),
                )
            })
            .collect::<Vec<_>>()
    };
    assert!(left_half(false).is_empty());
    let kept = left_half(true);
    assert_eq!(kept.len(), 1, "{kept:?}");
    // From about the lowest point to the junction; nothing of the straight contour.
    let (lo, hi) = kept[0];
    assert!(
        lo >= junction - 2.0 && lo < junction + 20.0,
        "{lo} vs {junction}"
    );
    assert!(hi > e.cx - 60.0 && hi < e.cx + 60.0, "{hi}");
}

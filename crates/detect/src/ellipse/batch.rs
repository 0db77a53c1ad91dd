//! Many ellipse fits in one call: the arcs of an image (or of many images) as one point array
//! delimited by offsets, each fitted by [`fit_ellipse`] (000_3b1454b2b2194811.txt §3.2,
//! `FitEllipse`), in parallel over the arcs with rayon.
//!
//! The fits are exactly those of one [`fit_ellipse`] call per arc: same start, same iteration,
//! same result bit for bit; only the per-call overhead of a caller looping over the arcs (a
//! Python→Rust crossing, argument checks, result objects) is paid once. One bad arc does not
//! spoil the others: each arc gets its own `Result`.

use nalgebra::Vector2;
use rayon::prelude::*;

use super::{EllipseFit, FitMethod, fit_ellipse};
use crate::{DetectError, Result};

/// Arcs below this many points in total are fitted on the calling thread (rayon's task
/// overhead exceeds a fit of a few hundred points only when there is nothing to share).
const PARALLEL_MIN_POINTS: usize = 2_000;

/// Checks `offsets` against `n` points: `offsets[0] = 0`, non-decreasing, `offsets[last] = n`.
/// Arc `i` is `points[offsets[i]..offsets[i + 1]]`.
///
/// # Errors
/// `InvalidParameter` naming the first bad offset.
pub fn check_offsets(offsets: &[usize], n: usize) -> Result<()> {
    let Some((&first, &last)) = offsets.first().zip(offsets.last()) else {
        return Err(DetectError::InvalidParameter {
            what: "offsets",
            value: 0.0,
            reason: "needs at least one entry (0, then the end of every arc)",
        });
    };
    if first != 0 {
        return Err(DetectError::InvalidParameter {
            what: "offsets[0]",
            value: first as f64,
            reason: "must be 0",
        });
    }
    if last != n {
        return Err(DetectError::WrongLength {
            what: "points (offsets[-1] is the number of points)",
            got: n,
            expected: last,
        });
    }
    if let Some(w) = offsets.windows(2).find(|w| w[1] < w[0]) {
        return Err(DetectError::InvalidParameter {
            what: "offsets",
            value: w[1] as f64,
            reason: "must be non-decreasing",
        });
    }
    Ok(())
}

/// Fits one ellipse per arc of `points` delimited by `offsets` (see [`check_offsets`]) with
/// `method`; the fits are those of [`fit_ellipse`] on each arc alone, in arc order.
///
/// # Errors
/// The outer `Result`: bad `offsets`. Each inner `Result`: as [`fit_ellipse`] on that arc
/// (fewer than 5 points, NaN, degenerate points, …).
pub fn fit_ellipses(
    points: &[Vector2<f64>],
    offsets: &[usize],
    method: FitMethod,
) -> Result<Vec<Result<EllipseFit>>> {
    check_offsets(offsets, points.len())?;
    let fit = |w: &[usize]| fit_ellipse(&points[w[0]..w[1]], method);
    let windows: Vec<&[usize]> = offsets.windows(2).collect();
    Ok(if points.len() < PARALLEL_MIN_POINTS {
        windows.into_iter().map(fit).collect()
    } else {
        windows.into_par_iter().with_max_len(1).map(fit).collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoteach_geometry::conic::Ellipse;

    fn arcs() -> (Vec<Vector2<f64>>, Vec<usize>) {
        let mut pts = Vec::new();
        let mut offsets = vec![0];
        for k in 0..12 {
            let e = Ellipse::new(
                100.0 + k as f64,
                50.0,
                80.0 + 3.0 * k as f64,
                40.0,
                0.1 * k as f64,
            )
            .unwrap();
            let arc = e
                .sample(60 + 40 * k, 0.2 * k as f64, 0.2 * k as f64 + 2.0)
                .unwrap();
            // Deterministic, non-symmetric perturbation (about 0.3 px).
            pts.extend(arc.iter().enumerate().map(|(i, p)| {
                p + Vector2::new(0.3 * (1.7 * i as f64).sin(), 0.3 * (2.3 * i as f64).cos())
            }));
            offsets.push(pts.len());
        }
        (pts, offsets)
    }

    #[test]
    fn batch_equals_one_call_per_arc() {
        let (pts, offsets) = arcs();
        assert!(
            pts.len() >= PARALLEL_MIN_POINTS,
            "exercise the parallel path"
        );
        for method in [FitMethod::Geometric, FitMethod::Direct] {
            let batch = fit_ellipses(&pts, &offsets, method).unwrap();
            assert_eq!(batch.len(), offsets.len() - 1);
            for (w, b) in offsets.windows(2).zip(&batch) {
                let one = fit_ellipse(&pts[w[0]..w[1]], method).unwrap();
                assert_eq!(b.as_ref().unwrap(), &one);
            }
        }
    }

    #[test]
    fn bad_arcs_fail_alone() {
        let (mut pts, mut offsets) = arcs();
        let end = pts.len();
        // An arc of 3 points and an arc with a NaN, after the good ones.
        pts.extend([
            Vector2::new(0.0, 0.0),
            Vector2::new(1.0, 0.0),
            Vector2::new(0.0, 1.0),
        ]);
        offsets.push(pts.len());
        let mut nan_arc = pts[0..20].to_vec();
        nan_arc[7].y = f64::NAN;
        pts.extend(nan_arc);
        offsets.push(pts.len());
        let out = fit_ellipses(&pts, &offsets, FitMethod::Geometric).unwrap();
        assert!(out[..12].iter().all(|r| r.is_ok()));
        assert_eq!(
            out[12],
            Err(DetectError::TooFewPoints {
                what: "points",
                got: 3,
                needed: 5
            })
        );
        assert!(matches!(
            out[13],
            Err(DetectError::NonFinite { index: 7, .. })
        ));
        assert!(end > 0);
    }

    #[test]
    fn bad_offsets_are_rejected() {
        let (pts, offsets) = arcs();
        let n = pts.len();
        assert!(fit_ellipses(&pts, &[], FitMethod::Geometric).is_err());
        assert!(matches!(
            fit_ellipses(&pts, &[1, n], FitMethod::Geometric),
            Err(DetectError::InvalidParameter {
                what: "offsets[0]",
                ..
            })
        ));
        assert!(matches!(
            fit_ellipses(&pts, &[0, n - 1], FitMethod::Geometric),
            Err(DetectError::WrongLength { .. })
        ));
        assert!(matches!(
            fit_ellipses(&pts, &[0, 50, 20, n], FitMethod::Geometric),
            Err(DetectError::InvalidParameter {
                what: "offsets",
                ..
            })
        ));
        // Empty batch: no arcs, no fits.
        assert_eq!(
            fit_ellipses(&[], &[0], FitMethod::Geometric).unwrap().len(),
            0
        );
        assert_eq!(offsets[0], 0);
    }
}

//! Ray casting against a 2-D world of wall segments (the simulated 270° laser of seed
//! 004_815695db12a6b16c.txt ch. 2), accelerated by a uniform grid of buckets walked with the
//! same cell traversal as the occupancy grid.

use crate::{GeometryError, Result};

/// A wall segment from `a` to `b` (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// First end.
    pub a: [f64; 2],
    /// Second end.
    pub b: [f64; 2],
}

impl Segment {
    /// A segment between two points.
    pub fn new(a: [f64; 2], b: [f64; 2]) -> Self {
        Self { a, b }
    }

    /// Length (m).
    pub fn length(&self) -> f64 {
        (self.b[0] - self.a[0]).hypot(self.b[1] - self.a[1])
    }

    /// Distance from a point to the segment.
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        let (dx, dy) = (self.b[0] - self.a[0], self.b[1] - self.a[1]);
        let l2 = dx * dx + dy * dy;
        let t = if l2 > 0.0 {
            (((p[0] - self.a[0]) * dx + (p[1] - self.a[1]) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p[0] - self.a[0] - t * dx).hypot(p[1] - self.a[1] - t * dy)
    }

    /// Range along the unit direction `d` from `o` to the segment, if hit with range ≥ 0.
    #[inline]
    pub fn intersect(&self, o: [f64; 2], d: [f64; 2]) -> Option<f64> {
        let e = [self.b[0] - self.a[0], self.b[1] - self.a[1]];
        let denom = d[0] * e[1] - d[1] * e[0];
        if denom.abs() < 1e-15 {
            return None;
        }
        let w = [self.a[0] - o[0], self.a[1] - o[1]];
        let t = (w[0] * e[1] - w[1] * e[0]) / denom;
        let s = (w[0] * d[1] - w[1] * d[0]) / denom;
        (t >= 0.0 && (0.0..=1.0).contains(&s)).then_some(t)
    }
}

/// A static world of wall segments with a bucket grid for ray casting.
#[derive(Debug, Clone)]
pub struct SegmentWorld {
    segments: Vec<Segment>,
    bucket: f64,
    origin: [f64; 2],
    nx: usize,
    ny: usize,
    /// Segment indices per bucket (row-major, `ny` rows of `nx`).
    buckets: Vec<Vec<u32>>,
}

impl SegmentWorld {
    /// Builds the bucket grid (`bucket` metres per side, positive) over the segments' extent.
    pub fn new(segments: Vec<Segment>, bucket: f64) -> Result<Self> {
        if !(bucket.is_finite() && bucket > 0.0) {
            return Err(GeometryError::InvalidParameter {
                what: "bucket",
                value: bucket,
                reason: "must be positive and finite",
            });
        }
        for s in &segments {
            for v in s.a.iter().chain(&s.b) {
                if !v.is_finite() {
                    return Err(GeometryError::NonFinite {
                        what: "segment end",
                        value: *v,
                    });
                }
            }
        }
        let (mut lo, mut hi) = ([0.0f64; 2], [1.0f64; 2]);
        if let Some(first) = segments.first() {
            lo = first.a;
            hi = first.a;
        }
        for s in &segments {
            for p in [s.a, s.b] {
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        let nx = (((hi[0] - lo[0]) / bucket).floor() as usize + 1).min(1 << 14);
        let ny = (((hi[1] - lo[1]) / bucket).floor() as usize + 1).min(1 << 14);
        let mut buckets = vec![Vec::new(); nx * ny];
        for (k, s) in segments.iter().enumerate() {
            let (a, b) = (
                [(s.a[0] - lo[0]) / bucket, (s.a[1] - lo[1]) / bucket],
                [(s.b[0] - lo[0]) / bucket, (s.b[1] - lo[1]) / bucket],
            );
            let mut add = |i: i32, j: i32| {
                if i >= 0 && j >= 0 && (i as usize) < nx && (j as usize) < ny {
                    let cell = &mut buckets[j as usize * nx + i as usize];
                    if cell.last() != Some(&(k as u32)) {
                        cell.push(k as u32);
                    }
                }
            };
            super::traverse_cells(a, b, &mut add);
            add(a[0].floor() as i32, a[1].floor() as i32);
            add(b[0].floor() as i32, b[1].floor() as i32);
        }
        // A segment running exactly along a bucket border may belong to both sides.
        let mut widened = buckets.clone();
        for j in 0..ny {
            for i in 0..nx {
                for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (ii, jj) = (i as i64 + di, j as i64 + dj);
                    if ii >= 0 && jj >= 0 && (ii as usize) < nx && (jj as usize) < ny {
                        let src = &buckets[jj as usize * nx + ii as usize];
                        let dst = &mut widened[j * nx + i];
                        for k in src {
                            if !dst.contains(k) {
                                dst.push(*k);
                            }
                        }
                    }
                }
            }
        }
        Ok(Self {
            segments,
            bucket,
            origin: lo,
            nx,
            ny,
            buckets: widened,
        })
    }

    /// The segments.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Range of the first wall along heading `angle` (rad) from `o`, if within `max_range`.
    pub fn cast(&self, o: [f64; 2], angle: f64, max_range: f64) -> Option<f64> {
        let d = [angle.cos(), angle.sin()];
        let a = [
            (o[0] - self.origin[0]) / self.bucket,
            (o[1] - self.origin[1]) / self.bucket,
        ];
        let b = [
            a[0] + d[0] * max_range / self.bucket,
            a[1] + d[1] * max_range / self.bucket,
        ];
        let mut best = f64::INFINITY;
        let mut test = |i: i32, j: i32| -> bool {
            if i < 0 || j < 0 || i as usize >= self.nx || j as usize >= self.ny {
                return false;
            }
            for &k in &self.buckets[j as usize * self.nx + i as usize] {
                if let Some(t) = self.segments[k as usize].intersect(o, d) {
                    best = best.min(t);
                }
            }
            // A hit inside this bucket (or before it) is final: later buckets are farther.
            let far_x = if d[0] > 0.0 { i + 1 } else { i } as f64 * self.bucket + self.origin[0];
            let far_y = if d[1] > 0.0 { j + 1 } else { j } as f64 * self.bucket + self.origin[1];
            let tx = if d[0].abs() > 1e-15 {
                (far_x - o[0]) / d[0]
            } else {
                f64::INFINITY
            };
            let ty = if d[1].abs() > 1e-15 {
                (far_y - o[1]) / d[1]
            } else {
                f64::INFINITY
            };
            best <= tx.min(ty)
        };
        let mut done = false;
        super::traverse_cells(a, b, |i, j| {
            if !done {
                done = test(i, j);
            }
        });
        if !done {
            test(b[0].floor() as i32, b[1].floor() as i32);
        }
        (best <= max_range).then_some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cast_matches_brute_force() {
        // A room with an inner pillar, cast from many origins/angles.
        let mut segs = vec![
            Segment::new([0.0, 0.0], [20.0, 0.0]),
            Segment::new([20.0, 0.0], [20.0, 12.0]),
            Segment::new([20.0, 12.0], [0.0, 12.0]),
            Segment::new([0.0, 12.0], [0.0, 0.0]),
        ];
        segs.push(Segment::new([8.0, 4.0], [9.0, 7.5]));
        segs.push(Segment::new([14.0, 2.0], [14.0, 2.0 + 4.0]));
        let w = SegmentWorld::new(segs.clone(), 1.5).unwrap();
        for (ox, oy) in [(2.0, 2.0), (10.3, 6.1), (17.7, 9.9)] {
            for k in 0..720 {
                let ang = k as f64 * std::f64::consts::TAU / 720.0;
                let d = [ang.cos(), ang.sin()];
                let brute = segs
                    .iter()
                    .filter_map(|s| s.intersect([ox, oy], d))
                    .fold(f64::INFINITY, f64::min);
                let got = w.cast([ox, oy], ang, 100.0).unwrap_or(f64::INFINITY);
                assert!(
                    (got - brute).abs() < 1e-9,
                    "{ox},{oy} @ {ang}: {got} vs {brute}"
                );
                let short = w.cast([ox, oy], ang, 3.0);
                assert_eq!(short.is_some(), brute <= 3.0);
            }
        }
    }
}

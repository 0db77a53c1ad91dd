//! The exact IoU of two rotated BEV boxes: Sutherland–Hodgman clipping of one box by the
//! other (both convex) and the shoelace area. This is what JIoU (eq. 8.4) reduces to when both
//! boxes are deterministic.

use super::Box2;

/// Shoelace area of a simple polygon (positive when counter-clockwise).
pub fn polygon_area(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    let mut s = 0.0;
    for i in 0..n {
        let (a, b) = (p[i], p[(i + 1) % n]);
        s += a[0] * b[1] - a[1] * b[0];
    }
    0.5 * s
}

/// The polygon `subject ∩ clip` for convex counter-clockwise polygons (Sutherland–Hodgman).
pub fn clip_convex(subject: &[[f64; 2]], clip: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = subject.to_vec();
    let m = clip.len();
    for e in 0..m {
        if out.is_empty() {
            break;
        }
        let (a, b) = (clip[e], clip[(e + 1) % m]);
        // Signed side: ≥ 0 is inside (left of a→b).
        let side = |p: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        let input = std::mem::take(&mut out);
        let n = input.len();
        for i in 0..n {
            let (p, q) = (input[i], input[(i + 1) % n]);
            let (sp, sq) = (side(p), side(q));
            if sp >= 0.0 {
                out.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                let t = sp / (sp - sq);
                out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
    }
    out
}

/// Area of the intersection of two rotated boxes.
pub fn intersection_area(a: &Box2, b: &Box2) -> f64 {
    let poly = clip_convex(&a.corners(), &b.corners());
    if poly.len() < 3 {
        0.0
    } else {
        polygon_area(&poly).max(0.0)
    }
}

/// Exact IoU of two rotated boxes.
pub fn iou(a: &Box2, b: &Box2) -> f64 {
    let inter = intersection_area(a, b);
    let union = a.area() + b.area() - inter;
    if union > 0.0 {
        (inter / union).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

//! The stages of the wafer-rim detector on one 8-bit grey image: the arcs of the edge chains,
//! the elliptic segments assembled from them (000_3b1454b2b2194811.txt §3.2, Algorithms 1
//! and 2) and the labelled rims, printed one per line (tab-separated) for inspection.
//!
//! ```text
//! cargo run --release -p autoteach-detect --example wafer_stages -- IMAGE.raw WIDTH HEIGHT
//! ```
//! `IMAGE.raw` holds `WIDTH × HEIGHT` bytes, row-major (e.g. NumPy's `image.tofile(path)`).

use autoteach_detect::assembly::{merge_arcs, merge_segments};
use autoteach_detect::edges::{GrayView, detect_arcs};
use autoteach_detect::wafers::{DetectParams, detect_wafers};
use std::error::Error;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, path, width, height] = args.as_slice() else {
        return Err("usage: wafer_stages IMAGE.raw WIDTH HEIGHT".into());
    };
    let (width, height): (usize, usize) = (width.parse()?, height.parse()?);
    let data = std::fs::read(path)?;
    if data.len() != width * height {
        return Err(format!(
            "{path}: {} bytes, expected {width} × {height} = {}",
            data.len(),
            width * height
        )
        .into());
    }
    let image = GrayView::new(&data, width, height)?;
    let params = DetectParams::default();
    let arcs = detect_arcs(&image, &params.canny, &params.link, &params.arcs)?;
    for (k, arc) in arcs.iter().enumerate() {
        let (first, last) = (arc.points[0], arc.points[arc.points.len() - 1]);
        println!(
            "arc\t{k}\t{}\t{:.1},{:.1}\t{:.1},{:.1}\tpolarity {}\t{:?}\tcontrast {:.1}\tturn {:.3}",
            arc.points.len(),
            first.x,
            first.y,
            last.x,
            last.y,
            arc.polarity,
            arc.quadrant,
            arc.contrast,
            arc.turn
        );
    }
    let (s0, v0) = merge_arcs(&arcs, &params.assembly)?;
    let (segments, rest) = merge_segments(&arcs, s0, v0, &params.assembly)?;
    for seg in &segments {
        let e = &seg.fit.ellipse;
        println!(
            "segment\t{:?}\t{:.2} {:.2} {:.2} {:.2} {:.4}\tresidual {:.3}",
            seg.arcs, e.cx, e.cy, e.a, e.b, e.theta, seg.fit.residual_mean
        );
    }
    println!("unassembled\t{rest:?}");
    for rim in detect_wafers(&image, &params)? {
        let e = &rim.ellipse;
        println!(
            "rim\t{}\twafer {}\t{:.2} {:.2} {:.2} {:.2} {:.4}\tresidual {:.3}\tpoints {}",
            rim.kind.as_str(),
            rim.wafer_id,
            e.cx,
            e.cy,
            e.a,
            e.b,
            e.theta,
            rim.residual,
            rim.points.len()
        );
    }
    Ok(())
}

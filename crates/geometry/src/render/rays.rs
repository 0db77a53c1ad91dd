//! Camera rays for the renderer: closed form for the pinhole model; for the distortion models,
//! a per-camera table of the unit bearings at integer pixel positions (computed once with the
//! model's exact unprojection and cached), bilinearly interpolated in between. The table's
//! interpolation error is of second order in the pixel spacing (below 1e-3 px for the
//! distortions of real lenses), and each ray stays exactly on the model where the table holds
//! it.

use std::sync::{Arc, Mutex};

use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;

use super::RayCamera;
use crate::camera::{Camera, CameraModel};

/// Bearings at integer pixel positions `u ∈ −1..=width`, `v ∈ −1..=height` (NaN where the
/// model has no ray).
struct Table {
    /// Grid width (`width + 2`).
    gw: usize,
    /// Grid height (`height + 2`).
    gh: usize,
    data: Vec<[f64; 3]>,
}

impl Table {
    fn new(cam: &Camera) -> Self {
        let (gw, gh) = (cam.width() as usize + 2, cam.height() as usize + 2);
        let mut data = vec![[f64::NAN; 3]; gw * gh];
        data.par_chunks_mut(gw).enumerate().for_each(|(j, row)| {
            for (i, b) in row.iter_mut().enumerate() {
                let px = Vector2::new(i as f64 - 1.0, j as f64 - 1.0);
                if let Ok(r) = cam.unproject(&px) {
                    *b = [r.x, r.y, r.z];
                }
            }
        });
        Self { gw, gh, data }
    }

    #[inline]
    fn bearing(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let (x, y) = (u + 1.0, v + 1.0);
        if !(x >= 0.0 && y >= 0.0 && x <= (self.gw - 1) as f64 && y <= (self.gh - 1) as f64) {
            return None;
        }
        let i = (x.floor() as usize).min(self.gw - 2);
        let j = (y.floor() as usize).min(self.gh - 2);
        let (fx, fy) = (x - i as f64, y - j as f64);
        let at = |di: usize, dj: usize| Vector3::from(self.data[(j + dj) * self.gw + i + di]);
        let top = at(0, 0) * (1.0 - fx) + at(1, 0) * fx;
        let bottom = at(0, 1) * (1.0 - fx) + at(1, 1) * fx;
        let b = top * (1.0 - fy) + bottom * fy;
        b.iter().all(|c| c.is_finite()).then_some(b)
    }
}

/// Tables of the distortion cameras used recently (most recent last).
static TABLES: Mutex<Vec<(Camera, Arc<Table>)>> = Mutex::new(Vec::new());
/// How many tables [`TABLES`] keeps.
const CACHED_TABLES: usize = 2;

fn table(cam: &Camera) -> Arc<Table> {
    let mut cache = TABLES.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(pos) = cache.iter().position(|(c, _)| c == cam) {
        let entry = cache.remove(pos);
        let t = entry.1.clone();
        cache.push(entry);
        return t;
    }
    let t = Arc::new(Table::new(cam));
    if cache.len() >= CACHED_TABLES {
        cache.remove(0);
    }
    cache.push((cam.clone(), t.clone()));
    t
}

enum Kind {
    Pinhole(Matrix3<f64>),
    Table(Arc<Table>),
}

/// The rays of a [`Camera`].
pub(crate) struct Rays<'a> {
    cam: &'a Camera,
    kind: Kind,
}

impl<'a> Rays<'a> {
    /// Rays of `cam`; for a distortion model this builds (or reuses) its bearing table.
    pub fn new(cam: &'a Camera) -> Self {
        let kind = match cam.model() {
            CameraModel::Pinhole => {
                let (fx, fy, cx, cy) = (cam.fx(), cam.fy(), cam.cx(), cam.cy());
                Kind::Pinhole(Matrix3::new(
                    1.0 / fx,
                    0.0,
                    -cx / fx,
                    0.0,
                    1.0 / fy,
                    -cy / fy,
                    0.0,
                    0.0,
                    1.0,
                ))
            }
            _ => Kind::Table(table(cam)),
        };
        Self { cam, kind }
    }
}

impl RayCamera for Rays<'_> {
    fn width(&self) -> usize {
        self.cam.width() as usize
    }

    fn height(&self) -> usize {
        self.cam.height() as usize
    }

    #[inline]
    fn bearing(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        match &self.kind {
            Kind::Pinhole(k_inv) => Some(k_inv * Vector3::new(u, v, 1.0)),
            Kind::Table(t) => t.bearing(u, v),
        }
    }

    fn project(&self, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        self.cam.project(p).ok()
    }

    fn k_matrix(&self) -> Matrix3<f64> {
        self.cam.k_matrix()
    }
}

//! Radio signal-strength prediction for teams of mobile robots (seed
//! 004_815695db12a6b16c.txt ch. 3): every node moves, so a prediction is a function of a
//! *link* — a transmitter and a receiver position — not of a point.
//!
//! * [`grid`]: the ternary occupancy grid (free / structure / unknown, §3.2.3) and the
//!   line-of-sight traversal giving each cell's segment length (the weights of eq. 3.2).
//! * [`logfit`]: the log-distance path-loss fit of eq. 3.1 (the baseline).
//! * [`kernel`], [`mrgp`]: the multi-robot Gaussian process (§3.2.1, eqs. 3.3–3.4) on a
//!   compactly supported, symmetric link kernel, solved by sparse Cholesky.
//! * [`normal`]: fast assembly of the tomographic normal matrix (dense blocks, counting
//!   sort).
//! * [`tomo`]: the bordered sparse least-squares solver shared by the tomographic models.
//! * [`mrt`]: multi-robot tomography (§3.2.2, eqs. 3.2, 3.5).
//! * [`matte`]: MATTE (§3.2.3, Algorithms 3.1–3.2): per-class attenuation on a coarse grid
//!   looked up through the fine occupancy grid.
//! * [`sim`]: a seeded radio simulator (path loss, per-wall attenuation by material,
//!   correlated log-normal shadowing, robots on trajectories measuring at 20 Hz).
//!
//! Sign convention (that of Algorithm 3.1 and Table 3.1): `y = L0 − a·log10 d + Σ wᵢ vᵢ`,
//! so an attenuating cell has a *negative* value `vᵢ` in dB per metre, and `g = −Σ wᵢ vᵢ`
//! is the shadowing of eq. 3.1. Distances below [`REFERENCE_DISTANCE`] (1 m, where `L0`
//! is defined) are clamped to it (near field); transmitter and receiver closer than
//! [`MIN_LINK_LENGTH`] are rejected as coincident.
//!
//! ```
//! use autoteach_estimate::radio::{Link, logfit::LogFit};
//!
//! // Pure path loss L0 = -40 dBm, a = 25: the fit recovers both.
//! let links: Vec<Link> = (1..30).map(|k| Link { tx: [0.0, 0.0], rx: [k as f64, 1.0] }).collect();
//! let rss: Vec<f64> = links.iter().map(|l| -40.0 - 25.0 * l.length().log10()).collect();
//! let fit = LogFit::fit(&links, &rss)?;
//! assert!((fit.l0 + 40.0).abs() < 1e-9 && (fit.exponent - 25.0).abs() < 1e-9);
//! # Ok::<(), autoteach_estimate::EstimateError>(())
//! ```

pub mod grid;
pub mod kernel;
pub mod logfit;
pub mod matte;
pub mod mrgp;
pub mod mrt;
pub mod normal;
pub mod sim;
pub mod sparse;
pub mod tomo;

#[cfg(test)]
mod tests;

use crate::{EstimateError, Result};

/// Reference distance of the path-loss model in metres: `L0` is the power at 1 m, and
/// shorter links are clamped to it.
pub const REFERENCE_DISTANCE: f64 = 1.0;

/// Links shorter than this (metres) have coincident transmitter and receiver: an error.
pub const MIN_LINK_LENGTH: f64 = 1e-6;

/// One radio link: transmitter and receiver positions in world metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    /// Transmitter position `[x, y]`.
    pub tx: [f64; 2],
    /// Receiver position `[x, y]`.
    pub rx: [f64; 2],
}

impl Link {
    /// Transmitter–receiver distance ‖r − t‖.
    pub fn length(&self) -> f64 {
        // hypot: no overflow of the squares for coordinates beyond 1e154.
        (self.rx[0] - self.tx[0]).hypot(self.rx[1] - self.tx[1])
    }

    /// The path-loss regressor `log10(max(‖r − t‖, 1 m))` of eq. 3.1.
    pub fn log_distance(&self) -> f64 {
        self.length().max(REFERENCE_DISTANCE).log10()
    }

    /// The link with transmitter and receiver swapped.
    pub fn swapped(&self) -> Link {
        Link {
            tx: self.rx,
            rx: self.tx,
        }
    }
}

/// Checks `links`: every coordinate finite, no coincident transmitter and receiver.
pub fn check_links(what: &str, links: &[Link]) -> Result<()> {
    for (index, l) in links.iter().enumerate() {
        let coords = [l.tx[0], l.tx[1], l.rx[0], l.rx[1]];
        if let Some(k) = coords.iter().position(|v| !v.is_finite()) {
            return Err(EstimateError::NonFiniteInput {
                what: format!("{what} (link {index})"),
                index: 4 * index + k,
                value: coords[k],
            });
        }
        let d = l.length();
        if d < MIN_LINK_LENGTH {
            return Err(EstimateError::CoincidentLink {
                what: what.to_string(),
                index,
                distance: d,
                minimum: MIN_LINK_LENGTH,
            });
        }
    }
    Ok(())
}

/// Checks a training set: non-empty, one finite RSS per valid link.
pub fn check_training(links: &[Link], rss: &[f64]) -> Result<()> {
    if links.is_empty() {
        return Err(EstimateError::EmptyInput("the training set".into()));
    }
    if rss.len() != links.len() {
        return Err(EstimateError::DimensionMismatch {
            what: "rss (one value per link)".into(),
            expected: vec![links.len()],
            got: vec![rss.len()],
        });
    }
    if let Some(index) = rss.iter().position(|v| !v.is_finite()) {
        return Err(EstimateError::NonFiniteInput {
            what: "rss".into(),
            index,
            value: rss[index],
        });
    }
    check_links("training links", links)
}

/// `OutsideMap` for the first link with an endpoint outside `grid` (the message names the
/// link and the endpoint).
pub fn check_links_inside(grid: &grid::GridGeometry, what: &str, links: &[Link]) -> Result<()> {
    for (index, l) in links.iter().enumerate() {
        for (end, p) in [("tx", l.tx), ("rx", l.rx)] {
            if !grid.contains(p) {
                let [x1, y1] = grid.far_corner();
                return Err(EstimateError::OutsideMap {
                    what: format!("{what} ({end} of link {index})"),
                    index,
                    x: p[0],
                    y: p[1],
                    x0: grid.origin[0],
                    x1,
                    y0: grid.origin[1],
                    y1,
                });
            }
        }
    }
    Ok(())
}

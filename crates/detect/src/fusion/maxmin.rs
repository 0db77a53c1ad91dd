//! Non-zero max-min pooling (§7.4, Figs. 7.5–7.6).
//!
//! A projected LiDAR map is sparse: undefined pixels hold 0. The layer down-samples an
//! `H × W × C` map by 2×2 windows into `⌈H/2⌉ × ⌈W/2⌉ × 2C`: channel `c` holds the maximum and
//! channel `C + c` the minimum of the window's non-zero values of channel `c`, and 0 when the
//! window has none (the red square of Fig. 7.5). Windows at an odd border hold the cells that
//! exist. Repeated `n` times it keeps every max/min combination (`2ⁿC` channels), which is what
//! Fig. 7.6 shows: the edges of local clusters survive, not only the global extremes.
//!
//! The gradient routes each output's gradient to the input cell that produced it (the first
//! such cell in row-major window order on ties), like max pooling; outputs with no non-zero
//! input have no source and pass no gradient.

use rayon::prelude::*;

use super::Feature;
use crate::{DetectError, Result};

/// Output shape `(⌈h/2⌉, ⌈w/2⌉, 2c)` of a `(h, w, c)` input.
pub fn output_shape(h: usize, w: usize, c: usize) -> (usize, usize, usize) {
    (h.div_ceil(2), w.div_ceil(2), 2 * c)
}

fn check<T: Feature>(input: &[T], h: usize, w: usize, c: usize) -> Result<()> {
    if h == 0 || w == 0 || c == 0 {
        return Err(DetectError::InvalidParameter {
            what: "max-min pooling shape (h, w, c)",
            value: 0.0,
            reason: "every dimension must be ≥ 1",
        });
    }
    if input.len() != h * w * c {
        return Err(DetectError::WrongLength {
            what: "max-min pooling input (h·w·c)",
            got: input.len(),
            expected: h * w * c,
        });
    }
    if let Some((index, v)) = input
        .iter()
        .enumerate()
        .find(|(_, v)| !v.to_f64().is_finite())
    {
        return Err(DetectError::NonFinite {
            what: "max-min pooling input",
            index,
            value: v.to_f64(),
        });
    }
    Ok(())
}

/// For output cell `(i, j)` and channel `k`: the flat input indices of the max and the min
/// (`None` when the window has no non-zero value).
fn arg_extremes<T: Feature>(
    input: &[T],
    h: usize,
    w: usize,
    c: usize,
    i: usize,
    j: usize,
    k: usize,
) -> Option<(usize, usize)> {
    let mut best: Option<(usize, usize)> = None;
    for a in 2 * i..(2 * i + 2).min(h) {
        for b in 2 * j..(2 * j + 2).min(w) {
            let idx = (a * w + b) * c + k;
            let v = input[idx];
            if v == T::ZERO {
                continue;
            }
            best = Some(match best {
                None => (idx, idx),
                Some((mx, mn)) => (
                    if v > input[mx] { idx } else { mx },
                    if v < input[mn] { idx } else { mn },
                ),
            });
        }
    }
    best
}

/// Non-zero max-min pooling of a channels-last `(h, w, c)` map; returns the `(⌈h/2⌉, ⌈w/2⌉, 2c)`
/// output.
pub fn maxmin_pool<T: Feature>(input: &[T], h: usize, w: usize, c: usize) -> Result<Vec<T>> {
    check(input, h, w, c)?;
    let (oh, ow, oc) = output_shape(h, w, c);
    let mut out = vec![T::ZERO; oh * ow * oc];
    out.par_chunks_mut(ow * oc)
        .enumerate()
        .for_each(|(i, row)| {
            for j in 0..ow {
                for k in 0..c {
                    if let Some((mx, mn)) = arg_extremes(input, h, w, c, i, j, k) {
                        row[j * oc + k] = input[mx];
                        row[j * oc + c + k] = input[mn];
                    }
                }
            }
        });
    Ok(out)
}

/// The gradient of [`maxmin_pool`] with respect to its input, given the gradient `grad_out`
/// with respect to its output.
pub fn maxmin_pool_backward<T: Feature>(
    input: &[T],
    h: usize,
    w: usize,
    c: usize,
    grad_out: &[T],
) -> Result<Vec<T>> {
    check(input, h, w, c)?;
    let (oh, ow, oc) = output_shape(h, w, c);
    if grad_out.len() != oh * ow * oc {
        return Err(DetectError::WrongLength {
            what: "max-min pooling gradient",
            got: grad_out.len(),
            expected: oh * ow * oc,
        });
    }
    let mut grad = vec![T::ZERO; input.len()];
    // Each input cell belongs to exactly one window: rows of windows write disjoint input rows.
    let row_len = 2 * w * c;
    grad.par_chunks_mut(row_len).enumerate().for_each(|(i, g)| {
        let base = i * row_len;
        for j in 0..ow {
            for k in 0..c {
                if let Some((mx, mn)) = arg_extremes(input, h, w, c, i, j, k) {
                    g[mx - base] = g[mx - base] + grad_out[(i * ow + j) * oc + k];
                    g[mn - base] = g[mn - base] + grad_out[(i * ow + j) * oc + c + k];
                }
            }
        }
    });
    Ok(grad)
}

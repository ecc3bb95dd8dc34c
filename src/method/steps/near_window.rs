//! The near window (`Steps::near_window`): the window's `M` bent to the smooth shape of the `M` of a shorter window
//! around the same photo ([`near_shape`]; the window's length: [`crate::method::window::near_window`]), so `F`
//! follows the lights' footprint as the vehicle's altitude and roll change, while the full window still sets the
//! detail.

use crate::method::raster::Raster;
use crate::method::seen::Window;
use crate::method::steps::nodes::{between_nodes, near_nodes, node_medians_grid};
use crate::method::steps::{bright_spots, levelling, quantile};
use crate::method::window::near_range;

/// `m` bent to the near window's shape, when the near window is on and shorter than the photo's window. The near
/// window is levelled where its own exposure jumps only when the window was (`levelled`): the ghosts levelling keeps
/// out are a photo's scene, which the window's `M` gives and the smooth shape leaves out, while a window whose near
/// window alone sees a jump is one where the light's swing turns, which the shape is there to follow
/// (docs/method.md).
pub(crate) fn shape(w: &Window, m: Raster, levelled: bool) -> Raster {
    let Some(near) = w.near.filter(|&k| k < w.members.len()) else {
        return m;
    };
    // The photos of the window nearest to the photo in time (in a window chosen by altitude, the nearest of those).
    let own = w.members.iter().position(|&j| j == w.i).unwrap_or(0);
    let seen = &w.seen[near_range(own, near, &(0..w.members.len()))];
    let stack: Vec<&Raster> = seen.iter().map(|e| &e.low).collect();
    let steps = &w.params.steps;
    let m_near = quantile::of(&stack, w.quantile);
    let (m_near, _) = levelling::level(
        &stack,
        m_near,
        w.s_low,
        w.quantile,
        steps.level_exposures && levelled,
    );
    let m_near = bright_spots::fill(m_near, seen, steps.bright_spots);
    near_shape(&m, &m_near, w.s_low)
}

/// Radius of [`near_shape`]'s squares, as a share of the longer side (in blocks): 1/8 of the frame (1/4 and
/// 1/16 measured alike on the dive matrix with a mean over the square).
pub const NEAR_SHAPE_RADIUS: f64 = 0.125;

/// Smallest `M − S` (linear light, both windows) whose ratio [`near_shape`] uses: a third of the step of an 8-bit
/// sRGB camera's first code. Blocks at or below it (backscatter-dominated corners) carry no ratio worth taking:
/// measured with a mean over the square, with any positive value admitted the matrix's pattern medians came out
/// 2–3 % higher than with this threshold
/// (a11 1.42× instead of 1.13× the pattern without the near window), and 10 % of the lit level (0.1 × its 95th
/// percentile) left a12's dim rim unfollowed (0.70× → 0.80× the paper's).
pub const NEAR_MIN_LIT: f32 = 1e-4;

/// `M` of the window bent to the smooth shape of `near`, the `M` of a shorter window around the same photo:
/// `S + (M − S)·exp(g)` per channel, where `g` is the smooth log ratio `log((near − S) / (M − S))`: its median over a
/// square of `2r + 1` blocks (cut at the edges; `r` = [`NEAR_SHAPE_RADIUS`] of the longer side) at grid nodes `r`
/// blocks apart (and on the last row and column), interpolated bilinearly between them; only blocks where both are
/// above [`NEAR_MIN_LIT`] vote. What is kept changes smoothly across the frame — the lights' footprint, which moves
/// with the vehicle's altitude and roll; the near window's noise and its local breakdowns (it has fewer photos to
/// outvote a nodule or a rock) are outvoted by the median (a mean over the square let the large dark blobs of a
/// test dive without `--contamination` through: albedo error 0.104 → 0.133). Where no node nearby has a vote, `M`
/// is kept.
pub fn near_shape(m: &Raster, near: &Raster, s: Option<&Raster>) -> Raster {
    assert_eq!(
        m.layout(),
        near.layout(),
        "window and near window differ in size"
    );
    let (w, h, c) = (m.width, m.height, m.channels);
    let r = near_radius(w, h);
    let sv = |i: usize| s.map_or(0.0, |s| s.data[i]);
    let (gx, gy) = (near_nodes(w, r), near_nodes(h, r));
    let mut out = m.clone();
    for ch in 0..c {
        // Each block's ratio once (NaN: no vote; a ratio taken is positive and finite): a block votes in the
        // squares of up to four nodes.
        let ratios: Vec<f32> = (0..w * h)
            .map(|b| {
                let i = b * c + ch;
                let (a, b) = (m.data[i] - sv(i), near.data[i] - sv(i));
                match a > NEAR_MIN_LIT && b > NEAR_MIN_LIT && (b / a).is_finite() {
                    true => b / a,
                    false => f32::NAN,
                }
            })
            .collect();
        // The median log ratio around each node (NaN without votes): the log of the median ratio, since the median
        // picks one of the votes and the logarithm keeps their order (one logarithm per node, not per vote).
        let mut node = node_medians_grid(&gx, &gy, r, (w, h), &ratios);
        for v in &mut node {
            *v = v.ln();
        }
        for y in 0..h {
            for x in 0..w {
                if let Some(g) = between_nodes(|j, k| node[j * gx.len() + k], &gx, &gy, x, y) {
                    let i = (y * w + x) * c + ch;
                    out.data[i] = sv(i) + (m.data[i] - sv(i)) * g.exp();
                }
            }
        }
    }
    out
}

/// [`near_shape`]'s radius in blocks for a `w`×`h`-block raster.
fn near_radius(w: usize, h: usize) -> usize {
    ((w.max(h) as f64 * NEAR_SHAPE_RADIUS).round() as usize).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`near_shape`] against a direct computation: the median log ratio over each node's square by sorting, then
    /// bilinear interpolation between the nodes.
    #[test]
    fn near_shape_against_a_direct_median_and_interpolation() {
        let (w, h, c) = (37, 23, 2);
        let m = Raster::from_fn(w, h, c, |x, y, ch| {
            0.2 + 0.01 * ((x * 7 + y * 3 + ch * 5) % 13) as f32
        });
        let s = Raster::from_fn(w, h, c, |x, _, _| 0.02 + 0.001 * x as f32);
        // The near window: a tilt, some noise, and blocks the ratio cannot use (below S, NaN, barely above S).
        let near = Raster::from_fn(w, h, c, |x, y, ch| {
            let v = 0.2 + 0.01 * ((x * 7 + y * 3 + ch * 5) % 13) as f32;
            match (x * 31 + y * 17 + ch) % 23 {
                0 => 0.0,
                1 => f32::NAN,
                2 => s.get(x, y, ch) + 0.5 * NEAR_MIN_LIT,
                k => {
                    s.get(x, y, ch)
                        + (v - s.get(x, y, ch)) * (1.0 + 0.02 * x as f32 - 0.003 * k as f32)
                }
            }
        });
        let got = near_shape(&m, &near, Some(&s));
        let r = near_radius(w, h);
        assert_eq!(r, 5);
        // Nodes every r blocks and on the last one.
        let (nx, ny): (Vec<usize>, Vec<usize>) = (
            (0..w).filter(|x| x % r == 0 || *x == w - 1).collect(),
            (0..h).filter(|y| y % r == 0 || *y == h - 1).collect(),
        );
        for ch in 0..c {
            let node = |x0: usize, y0: usize| {
                let mut logs = Vec::new();
                for y in y0.saturating_sub(r)..(y0 + r + 1).min(h) {
                    for x in x0.saturating_sub(r)..(x0 + r + 1).min(w) {
                        let a = m.get(x, y, ch) - s.get(x, y, ch);
                        let b = near.get(x, y, ch) - s.get(x, y, ch);
                        if a > NEAR_MIN_LIT && b > NEAR_MIN_LIT {
                            logs.push((b / a).ln());
                        }
                    }
                }
                logs.sort_by(f32::total_cmp);
                logs[((logs.len() - 1) as f64 * 0.5).round() as usize]
            };
            // The nodes around `v` and how far along between them it lies.
            let around = |nodes: &[usize], v: usize| {
                let j = nodes.iter().rposition(|&n| n <= v).unwrap();
                let (a, b) = (nodes[j], nodes[(j + 1).min(nodes.len() - 1)]);
                let t = if b > a {
                    (v - a) as f32 / (b - a) as f32
                } else {
                    0.0
                };
                (a, b, t)
            };
            for y in 0..h {
                let (y0, y1, ty) = around(&ny, y);
                for x in 0..w {
                    let (x0, x1, tx) = around(&nx, x);
                    let g = node(x0, y0) * (1.0 - tx) * (1.0 - ty)
                        + node(x1, y0) * tx * (1.0 - ty)
                        + node(x0, y1) * (1.0 - tx) * ty
                        + node(x1, y1) * tx * ty;
                    let sv = s.get(x, y, ch);
                    let expect = sv + (m.get(x, y, ch) - sv) * g.exp();
                    let v = got.get(x, y, ch);
                    assert!(
                        (v - expect).abs() < 1e-5,
                        "({x}, {y}, {ch}): {v} against {expect}"
                    );
                }
            }
        }
    }

    /// A few broken blocks (a dark rock in the near window's median) do not move the shape: the median outvotes
    /// them, where a mean would carry them into every block of their square.
    #[test]
    fn near_shape_outvotes_a_local_breakdown() {
        let m = Raster::from_fn(40, 30, 1, |x, _, _| 0.3 + 0.002 * x as f32);
        let mut near = m.clone();
        for y in 12..16 {
            for x in 18..22 {
                near.data[y * 40 + x] *= 0.2;
            }
        }
        let got = near_shape(&m, &near, None);
        for (a, b) in m.data.iter().zip(&got.data) {
            assert!((a - b).abs() < 1e-6, "{a} -> {b}");
        }
    }

    /// A near window that is the window times a constant per channel gives exactly that gain on `M − S`; the same
    /// `M` gives `M` back.
    #[test]
    fn near_shape_takes_a_uniform_change_whole_and_keeps_an_equal_window() {
        let m = Raster::from_fn(40, 30, 3, |x, y, ch| {
            0.1 + 0.005 * (x + y) as f32 + 0.1 * ch as f32
        });
        let s = Raster::from_fn(40, 30, 3, |_, _, ch| 0.03 + 0.01 * ch as f32);
        let gains = [0.8f32, 1.0, 1.25];
        let near = Raster::from_fn(40, 30, 3, |x, y, ch| {
            s.get(x, y, ch) + (m.get(x, y, ch) - s.get(x, y, ch)) * gains[ch]
        });
        let got = near_shape(&m, &near, Some(&s));
        let same = near_shape(&m, &m, Some(&s));
        for y in 0..30 {
            for x in 0..40 {
                for (ch, g) in gains.iter().enumerate() {
                    let (sv, mv) = (s.get(x, y, ch), m.get(x, y, ch));
                    assert!((got.get(x, y, ch) - (sv + (mv - sv) * g)).abs() < 1e-5);
                    assert!((same.get(x, y, ch) - mv).abs() < 1e-6);
                }
            }
        }
    }
}

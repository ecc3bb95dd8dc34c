//! Bright spots that move from photo to photo — laser dots whose place in the frame changes with the altitude,
//! specular highlights, glints — and the window's `M` where they held it (`--bright-spots`, off by default).
//!
//! The window's `M` is a median (or the `(1 + c)/2` quantile) over photos, so it outvotes objects that are at
//! another place in most photos of the window. A laser dot may not be: its place in the frame changes only with the
//! altitude, so over a window it can sit on the same few blocks in most photos, and the window's `M` takes it into
//! `F` there — on the real Nephrops runs a red blob in `F` beside each dot, and the corrected photos show a teal
//! stain (red divided by too much) wherever the dot is not. `--mask-auto` finds only what never moves.
//!
//! [`bright_spots`] marks, per photo, the blocks of its block-median image that stand far above the seafloor
//! around them in some channel (twice the local level, and by a tenth of the brightest channel's lit level, so noise
//! in dark regions never qualifies), in compact groups (a long bright edge of a narrow beam is lighting, not a
//! spot), and the blocks around them (glare). The engine fills `M` from the blocks around wherever such blocks held
//! more than half of the window, and leaves it alone elsewhere. The dots themselves then keep their full brightness
//! (before, `F` held part of them and dimmed them), which raises the overlap difference of the Nephrops runs; that
//! is why it is not the default (docs/evaluation.md, "Bright spots that move").

use crate::method::raster::Raster;
use crate::method::refine::{between_nodes, near_nodes, node_medians, quantile};

/// A block is bright when one of its channels is at least this many times the channel's local level.
pub const SPOT_RATIO: f32 = 2.0;

/// … and above the local level by at least this share of the brightest channel's lit level (its 99th percentile
/// over the frame): sensor noise in a dark corner, or in a channel starved of light, can double a block's value,
/// never by a tenth of that.
pub const SPOT_MARGIN: f32 = 0.1;

/// A group of bright blocks (8-connected) larger than this share of the frame's blocks is left alone: not a spot.
pub const SPOT_MAX_SHARE: f32 = 0.005;

/// Blocks around a spot marked with it (the glare).
pub const SPOT_GROW: usize = 2;

/// The blocks of `low` (a photo's block medians, linear light) that are bright spots, with the blocks within
/// [`SPOT_GROW`] of them; an empty vector when there are none. The local level is the median over a square of blocks a sixteenth of the
/// longer side across around grid nodes that far apart, interpolated bilinearly (as
/// [`crate::method::refine::near_shape`] does); NaN blocks (a mask) are never spots and do not vote.
pub fn bright_spots(low: &Raster) -> Vec<bool> {
    let (w, h, c) = (low.width, low.height, low.channels);
    if w < 8 || h < 8 {
        return Vec::new();
    }
    let r = ((w.max(h) as f64 / 32.0).round() as usize).max(2);
    let local = local_level(low, r);
    let lit: Vec<f32> = (0..c)
        .map(|ch| {
            let mut v: Vec<f32> = low.data[ch..]
                .iter()
                .step_by(c)
                .copied()
                .filter(|v| v.is_finite())
                .collect();
            if v.is_empty() {
                0.0
            } else {
                quantile(&mut v, 0.99)
            }
        })
        .collect();
    // The margin against the brightest channel's lit level: a channel starved of light (red at depth) has noise
    // that doubles its dim blocks and rises by a tenth of its own small lit level.
    let top = lit.iter().copied().fold(0.0f32, f32::max);
    let bright: Vec<bool> = (0..w * h)
        .map(|b| {
            (0..c).any(|ch| {
                let (v, l) = (low.data[b * c + ch], local[b * c + ch]);
                v.is_finite() && l.is_finite() && v >= SPOT_RATIO * l && v - l >= SPOT_MARGIN * top
            })
        })
        .collect();

    if !bright.contains(&true) {
        return Vec::new();
    }
    // Compact groups only.
    let max_blocks = ((w * h) as f32 * SPOT_MAX_SHARE).ceil() as usize;
    let mut seen = vec![false; w * h];
    let mut spots = vec![false; w * h];
    let mut stack = Vec::new();
    let mut members = Vec::new();
    for start in 0..w * h {
        if !bright[start] || seen[start] {
            continue;
        }
        members.clear();
        stack.push(start);
        seen[start] = true;
        while let Some(b) = stack.pop() {
            members.push(b);
            let (x, y) = (b % w, b / w);
            for ny in y.saturating_sub(1)..(y + 2).min(h) {
                for nx in x.saturating_sub(1)..(x + 2).min(w) {
                    let n = ny * w + nx;
                    if bright[n] && !seen[n] {
                        seen[n] = true;
                        stack.push(n);
                    }
                }
            }
        }
        if members.len() <= max_blocks {
            for &b in &members {
                spots[b] = true;
            }
        }
    }
    if !spots.contains(&true) {
        return Vec::new();
    }
    // With the blocks around them: the glare around a dot lifts them by less than the ratio.
    let g = SPOT_GROW;
    let mut out = vec![false; w * h];
    for b in (0..w * h).filter(|&b| spots[b]) {
        let (x, y) = (b % w, b / w);
        for ny in y.saturating_sub(g)..(y + g + 1).min(h) {
            for nx in x.saturating_sub(g)..(x + g + 1).min(w) {
                out[ny * w + nx] = true;
            }
        }
    }
    out
}

/// The local level of each block and channel: the median over the `(2r + 1)`² square around grid nodes `r` blocks
/// apart (and the last row and column), interpolated bilinearly between the nodes.
fn local_level(low: &Raster, r: usize) -> Vec<f32> {
    let (w, h, c) = (low.width, low.height, low.channels);
    let (gx, gy) = (near_nodes(w, r), near_nodes(h, r));
    let nodes: Vec<Vec<f32>> = (0..c)
        .map(|ch| {
            node_medians(&gx, &gy, r, (w, h), |x, y| {
                Some(low.data[(y * w + x) * c + ch]).filter(|v| v.is_finite())
            })
        })
        .collect();
    let mut out = vec![f32::NAN; w * h * c];
    for y in 0..h {
        for x in 0..w {
            for (ch, node) in nodes.iter().enumerate() {
                if let Some(v) = between_nodes(|j, k| node[j * gx.len() + k], &gx, &gy, x, y) {
                    out[(y * w + x) * c + ch] = v;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A light cone over grey seafloor (block medians), with: a 2×2 red dot (4× the red around it), a long bright
    /// band down the right edge (a narrow beam's lit edge: 2.5× the level, far more blocks than a spot), and blocks
    /// tripled by noise in the dark corner (a tenth of the lit level is more than they rise).
    fn scene() -> Raster {
        let (w, h) = (64, 48);
        Raster::from_fn(w, h, 3, |x, y, ch| {
            let (fx, fy) = (x as f32 - 32.0, y as f32 - 24.0);
            let mut v = 0.4 * (-(fx * fx + fy * fy) / (2.0 * 12.0f32.powi(2))).exp();
            if x >= 56 {
                v *= 2.5;
            }
            if (20..22).contains(&x) && (20..22).contains(&y) && ch == 0 {
                v *= 4.0;
            }
            if x < 4 && y < 4 && (x + y) % 2 == 0 {
                v *= 3.0;
            }
            v
        })
    }

    #[test]
    fn a_dot_is_found_with_the_blocks_around_it_a_lit_band_and_dark_noise_are_not() {
        let low = scene();
        let spots = bright_spots(&low);
        assert_eq!(spots.len(), 64 * 48);
        for y in 0..48 {
            for x in 0..64 {
                let around = 20 - SPOT_GROW..22 + SPOT_GROW;
                let want = around.contains(&x) && around.contains(&y);
                assert_eq!(spots[y * 64 + x], want, "block ({x}, {y})");
            }
        }
    }

    #[test]
    fn nothing_bright_gives_an_empty_vector() {
        let low = Raster::from_fn(40, 30, 3, |x, y, _| 0.2 + 0.001 * (x + y) as f32);
        assert!(bright_spots(&low).is_empty());
        // Too small to tell a spot from the scene.
        assert!(bright_spots(&Raster::filled(7, 7, 3, 0.5)).is_empty());
    }

    #[test]
    fn a_spot_in_a_masked_frame_is_found_and_nan_blocks_are_never_spots() {
        let mut low = scene();
        for x in 0..10 {
            for ch in 0..3 {
                low.data[(40 * 64 + x) * 3 + ch] = f32::NAN;
            }
        }
        let spots = bright_spots(&low);
        assert!(spots[20 * 64 + 20]);
        assert!((0..10).all(|x| !spots[40 * 64 + x]));
    }
}

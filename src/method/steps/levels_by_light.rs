//! The levels by light (`Steps::level_by_light`): the blend's block levels evened out across light levels
//! ([`level_by_light`]; by bins' trimmed means on dense fields), so dim regions are not left darker than lit ones.

use crate::method::median::quantile;
use crate::method::raster::Raster;
use crate::method::seen::Window;
use crate::method::steps::blend::{Blended, LEVEL_MIN};

/// The blend's levels evened out by light, where the step is on and there is a blend.
pub(crate) fn even(w: &Window, blended: Option<&mut Blended>, f: &Raster) {
    if let (Some(b), true) = (blended, w.params.steps.level_by_light) {
        level_by_light(&mut b.level, f, w.colour, w.masked_blocks, w.dense());
    }
}

/// Bins of `F` (equal numbers of blocks) in which [`level_by_light`] measures the blocks' typical level.
pub const LIGHT_BINS: usize = 16;

/// Blocks that [`level_by_light`] samples at most for its bins (every `k`-th block beyond that).
pub const MAX_LIGHT_SAMPLES: usize = 16384;

/// Largest factor by which [`level_by_light`] moves a block level, either way.
pub const MAX_LEVEL_SHIFT: f32 = 2.0;

/// The blend's block levels evened out across light levels, per channel: each level `A_low` is divided by the
/// typical level of the photo's blocks that get the same light `F`, relative to its brightest quarter's.
///
/// In a block where noise is comparable to the signal, `(median − S)/F` is biased low: the noise pulls the median
/// of a skewed albedo (dark nodules in pale sediment) towards its mean, the window's quantile `M` sits further
/// above a noisy block's median, and a water-column `S` that over-estimates the survey's backscatter takes a larger
/// share of a small signal. All of these depend on the block's light, not on its place or content, so the blocks
/// of one light level share them: their median level against the brightest quarter's measures the bias on the
/// photo itself. A block keeps its difference from the blocks lit like it (a patch of nodules stays darker);
/// where the light is good (the blend's weight near 1, where the level hardly counts) the factor is about 1.
///
/// The factor is the typical `A_low/C` of the brightest quarter of blocks over that of the block's bin of `F`
/// ([`LIGHT_BINS`] bins at the median `F` of each, linear between bin centres, constant beyond them), at most
/// [`MAX_LEVEL_SHIFT`] either way. Typical is the median, or with `dense` (a field whose window was chosen for
/// dense clutter) the mean without the lowest and highest [`LEVEL_TRIM`] of the values: where nodules cover
/// nearly half the ground a bin's median sits at the edge between the nodules' levels and the sediment's and jumps
/// from one to the other with the share of nodules in the bin, so the factor changed from photo to photo (the red
/// of a 45 % field by ±13 %) and overlapping photos disagreed; the trimmed mean moves in proportion to the share.
/// On sparse ground the median stays: the blend pulls a dim block's clutter towards the seafloor's level, which
/// lifts a dim bin's mean but not its median. Blocks flagged in `keep` (overlays, vehicle parts) neither count nor
/// change. A channel with fewer than `8·LIGHT_BINS` blocks is left as it is; on large photos the bins are measured on every `k`-th block (at most
/// [`MAX_LIGHT_SAMPLES`]) and every block is corrected. Measured on the dive matrix: docs/evaluation.md.
pub fn level_by_light(
    level: &mut Raster,
    f: &Raster,
    colour: &[f32],
    keep: Option<&[bool]>,
    dense: bool,
) {
    let c = f.channels;
    let blocks = f.data.len() / c;
    // The bins' typical levels from at most about MAX_LIGHT_SAMPLES blocks (a 12 MP photo has 187,500).
    let step = blocks.div_ceil(MAX_LIGHT_SAMPLES).max(1);
    for (ch, &colour) in colour.iter().enumerate().take(c) {
        let mut pts: Vec<(f32, f32)> = (0..blocks)
            .step_by(step)
            .filter(|&b| !keep.is_some_and(|m| m[b]))
            .map(|b| (f.data[b * c + ch], level.data[b * c + ch] / colour))
            .filter(|(fv, l)| fv.is_finite() && *fv > 0.0 && l.is_finite())
            .collect();
        let n = pts.len();
        if n < 8 * LIGHT_BINS {
            continue;
        }
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let typical_of = |part: &[(f32, f32)]| {
            let mut v: Vec<f32> = part.iter().map(|p| p.1).collect();
            if dense {
                trimmed_mean(&mut v, LEVEL_TRIM)
            } else {
                quantile(&mut v, 0.5)
            }
        };
        let reference = typical_of(&pts[n - n / 4..]);
        if reference.is_nan() || reference <= 0.0 {
            continue;
        }
        let (centres, typical): (Vec<f32>, Vec<f32>) = (0..LIGHT_BINS)
            .map(|i| {
                let part = &pts[i * n / LIGHT_BINS..(i + 1) * n / LIGHT_BINS];
                let mut fs: Vec<f32> = part.iter().map(|p| p.0).collect();
                (quantile(&mut fs, 0.5), typical_of(part))
            })
            .unzip();
        let factor = |fv: f32| {
            let j = centres.partition_point(|&x| x < fv);
            let t = if j == 0 {
                typical[0]
            } else if j == LIGHT_BINS {
                typical[LIGHT_BINS - 1]
            } else {
                let u =
                    (fv - centres[j - 1]) / (centres[j] - centres[j - 1]).max(f32::MIN_POSITIVE);
                typical[j - 1] + u * (typical[j] - typical[j - 1])
            };
            (reference / t).clamp(1.0 / MAX_LEVEL_SHIFT, MAX_LEVEL_SHIFT)
        };
        for b in 0..blocks {
            let i = b * c + ch;
            if keep.is_some_and(|m| m[b]) || !f.data[i].is_finite() || f.data[i] <= 0.0 {
                continue;
            }
            level.data[i] = (level.data[i] * factor(f.data[i])).max(LEVEL_MIN);
        }
    }
}

/// Share of a bin's values left out at each end of the trimmed mean of [`level_by_light`].
pub const LEVEL_TRIM: f32 = 0.1;

/// The mean of `v` without its lowest and highest `trim` share (sorted in place; NaN when `v` is empty).
fn trimmed_mean(v: &mut [f32], trim: f32) -> f32 {
    v.sort_unstable_by(|a, b| a.total_cmp(b));
    let cut = (v.len() as f32 * trim) as usize;
    let kept = &v[cut..v.len() - cut];
    (kept.iter().map(|&x| x as f64).sum::<f64>() / kept.len() as f64) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Block levels `C·bias(F)·v` on a frame lit from one side: `v` a block's own deviation (±20 %, pseudo-random),
    /// `bias` a loss that grows as the light fades, as noise and an over-estimated `S` make it.
    fn levels(bias: impl Fn(f32) -> f32) -> (Raster, Raster, Vec<f32>) {
        levels_sized(48, 36, bias)
    }

    fn levels_sized(w: usize, h: usize, bias: impl Fn(f32) -> f32) -> (Raster, Raster, Vec<f32>) {
        let mut next = crate::method::xorshift32(0x9E37_79B9);
        let mut v = Vec::new();
        let f = Raster::from_fn(w, h, 1, |x, y, _| {
            0.002 + (x as f32 / (w - 1) as f32).powi(2) * (1.0 - 0.3 * y as f32 / h as f32)
        });
        let level = Raster::from_fn(w, h, 1, |x, y, _| {
            let dev = 0.8 + 0.4 * (next() as f32 / u32::MAX as f32);
            v.push(dev);
            0.4 * bias(f.get(x, y, 0)) * dev
        });
        (f, level, v)
    }

    /// Median of `level/C` of the blocks with `F` in `range`.
    fn typical(level: &Raster, f: &Raster, range: std::ops::Range<f32>) -> f32 {
        let mut v: Vec<f32> = (0..f.data.len())
            .filter(|&i| range.contains(&f.data[i]))
            .map(|i| level.data[i] / 0.4)
            .collect();
        assert!(v.len() > 30, "{range:?}: {} blocks", v.len());
        quantile(&mut v, 0.5)
    }

    #[test]
    fn level_by_light_removes_a_loss_that_follows_the_light_and_keeps_each_block_s_own() {
        let bias = |f: f32| 0.7 + 0.3 * (f / 0.25).min(1.0);
        // The second size has more blocks than the bins sample (every second block is measured, all corrected).
        for (w, h) in [(48, 36), (200, 150)] {
            removes_the_loss(levels_sized(w, h, bias));
        }
    }

    fn removes_the_loss((f, before, dev): (Raster, Raster, Vec<f32>)) {
        let mut after = before.clone();
        level_by_light(&mut after, &f, &[0.4], None, false);
        // Before: the dimmest blocks' typical level is about 0.7 of the bright ones'; after, within 4 %.
        let bright = typical(&after, &f, 0.5..2.0);
        for range in [0.0..0.01, 0.01..0.03, 0.03..0.08, 0.08..0.2] {
            let (was, now) = (
                typical(&before, &f, range.clone()),
                typical(&after, &f, range.clone()),
            );
            assert!(
                (now / bright - 1.0).abs() < 0.04,
                "{range:?}: {was} -> {now}, bright {bright}"
            );
        }
        assert!(typical(&before, &f, 0.0..0.01) < 0.8 * typical(&before, &f, 0.5..2.0));
        // The factor depends on F alone: a block keeps its deviation v from its light level's peers, so between
        // neighbours of nearly equal F the ratio after/v moves smoothly, never by the ±20 % of v.
        let mut pairs = 0;
        for i in 0..f.data.len() - 1 {
            let (a, b) = (after.data[i] / dev[i], after.data[i + 1] / dev[i + 1]);
            if (f.data[i] - f.data[i + 1]).abs() < 0.002 {
                assert!((a / b - 1.0).abs() < 0.05, "block {i}: {a} vs {b}");
                pairs += 1;
            }
        }
        assert!(pairs > 50, "{pairs} pairs of neighbours");
    }

    #[test]
    fn level_by_light_leaves_levels_without_a_loss_within_their_spread() {
        let (f, before, _) = levels(|_| 1.0);
        let mut after = before.clone();
        level_by_light(&mut after, &f, &[0.4], None, false);
        for (a, b) in after.data.iter().zip(&before.data) {
            assert!((a / b - 1.0).abs() < 0.06, "{b} -> {a}");
        }
    }

    #[test]
    fn level_by_light_does_not_level_a_nodule_field_by_its_share_of_nodules() {
        // No loss at any light: sediment at 1, nodules at 0.3 (±5 % each), the nodules' share 40 % on the frame's
        // dim half and 55 % on its bright half. A bin's median is then sediment on one half and nodule on the
        // other (the clamp's factor of 2); the means without the lowest and highest tenth move with the share
        // only: (0.3·0.3 + 0.5)/0.8 on the dim half against (0.45·0.3 + 0.35)/0.8 on the bright one.
        let (w, h) = (96, 72);
        let mut next = crate::method::xorshift32(0x51ED_270B);
        let mut unit = move || next() as f32 / u32::MAX as f32;
        let f = Raster::from_fn(w, h, 1, |x, _, _| 0.002 + x as f32 / w as f32);
        let before = Raster::from_fn(w, h, 1, |x, _, _| {
            let share = if x < w / 2 { 0.40 } else { 0.55 };
            let own = if unit() < share { 0.3 } else { 1.0 };
            0.4 * own * (0.95 + 0.1 * unit())
        });
        let mut after = before.clone();
        level_by_light(&mut after, &f, &[0.4], None, true);
        let dim_factor = (0.45 * 0.3 + 0.35) / (0.3 * 0.3 + 0.5);
        for (i, (a, b)) in after.data.iter().zip(&before.data).enumerate() {
            // The bins next to the change of share mix both halves.
            let x = i % w;
            if x.abs_diff(w / 2) < w / 8 {
                continue;
            }
            // Each bin's share of nodules varies by a few per cent around its half's.
            let expected = if x < w / 2 { dim_factor } else { 1.0 };
            assert!(
                (a / b / expected - 1.0).abs() < 0.08,
                "block {i}: {b} -> {a}"
            );
        }
        // Levelled by its bins' medians (as on sparse ground), the same field's dim half would move by the clamp.
        let mut medians = before.clone();
        level_by_light(&mut medians, &f, &[0.4], None, false);
        assert!(
            (0..w * h).any(|i| medians.data[i] / before.data[i] <= 1.0 / MAX_LEVEL_SHIFT + 1e-6)
        );
    }

    #[test]
    fn trimmed_mean_is_the_mean_of_the_sorted_middle() {
        let mut next = crate::method::xorshift32(0x00DD_BA11);
        for n in [1usize, 2, 9, 10, 11, 100, 257] {
            let v: Vec<f32> = (0..n).map(|_| (next() % 50) as f32 * 0.1).collect();
            let mut sorted = v.clone();
            sorted.sort_by(|a, b| a.partial_cmp(b).unwrap());
            for trim in [0.0f32, 0.1, 0.25] {
                let cut = (n as f32 * trim).floor() as usize;
                let middle = &sorted[cut..n - cut];
                let want = middle.iter().map(|&x| x as f64).sum::<f64>() / middle.len() as f64;
                let got = trimmed_mean(&mut v.clone(), trim);
                assert!(
                    (got as f64 - want).abs() < 1e-6,
                    "n {n} trim {trim}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn level_by_light_skips_kept_blocks_and_small_photos() {
        let bias = |f: f32| 0.7 + 0.3 * (f / 0.25).min(1.0);
        let (f, before, _) = levels(bias);
        let keep: Vec<bool> = (0..f.data.len()).map(|i| i % 3 == 0).collect();
        let mut after = before.clone();
        level_by_light(&mut after, &f, &[0.4], Some(&keep), false);
        for (i, &kept) in keep.iter().enumerate() {
            if kept {
                assert_eq!(after.data[i], before.data[i]);
            }
        }
        assert!((0..f.data.len()).any(|i| !keep[i] && after.data[i] != before.data[i]));
        let small_f = Raster::from_fn(10, 10, 1, |x, _, _| 0.01 + x as f32 * 0.1);
        let small = Raster::from_fn(10, 10, 1, |x, _, _| 0.4 * bias(0.01 + x as f32 * 0.1));
        let mut got = small.clone();
        level_by_light(&mut got, &small_f, &[0.4], None, false);
        assert_eq!(got, small);
    }
}

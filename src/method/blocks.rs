//! The block images the method works on: each photo's `K`×`K` block medians in linear light (the pixels a mask
//! ignores left out), looked up by table for 8-bit sRGB photos, and the survey's cheaper stand-in from a JPEG's
//! block means.

use crate::method::mask::{block_median_masked, Mask};
use crate::method::median::block_median;
use crate::method::raster::{Photo, Raster, Sample, Samples};
use crate::method::transfer::Transfer;

/// The table the engine converts block medians by: every value an 8-bit block median takes, computed as `block_median`
/// computes it (`(a + b)·0.5·(1/255)`), with its linear light. Empty for a linear curve.
pub(crate) fn median_linear_table(transfer: Transfer) -> Vec<(f32, f32)> {
    if transfer.is_linear() {
        return Vec::new();
    }
    let scale = 1.0 / <u8 as Sample>::MAX;
    (0..=510u16)
        .map(|s| {
            let v = s as f32 * 0.5 * scale;
            (v, transfer.to_linear(v))
        })
        .collect()
}

/// `transfer.to_linear(v)`, looked up in `table` (see [`median_linear_table`]) when `v` is one of its values.
fn median_to_linear(table: &[(f32, f32)], transfer: Transfer, v: f32) -> f32 {
    let j = (v * 510.0).round();
    match table.get(j as usize) {
        Some(&(key, lin)) if key.to_bits() == v.to_bits() => lin,
        _ => transfer.to_linear(v),
    }
}

/// A photo's `k`×`k` block medians in linear light, the pixels `mask` ignores left out (NaN where a whole block
/// is); `table` is [`median_linear_table`]`(transfer)`.
pub(crate) fn linear_block_medians(
    photo: &Photo,
    k: usize,
    mask: Option<&Mask>,
    transfer: Transfer,
    table: &[(f32, f32)],
) -> Raster {
    let l = photo.layout;
    let mut low = match (&photo.samples, mask) {
        (Samples::U8(v), None) => block_median(v, l.width, l.height, l.channels, k),
        (Samples::U16(v), None) => block_median(v, l.width, l.height, l.channels, k),
        (Samples::U8(v), Some(m)) => block_median_masked(v, l, k, m),
        (Samples::U16(v), Some(m)) => block_median_masked(v, l, k, m),
    };
    if !transfer.is_linear() {
        // The value computed exactly as the block median computes it is looked up; any other (16-bit samples, NaN
        // under a mask) is converted directly: the same result either way.
        for v in &mut low.data {
            *v = median_to_linear(table, transfer, *v);
        }
    }
    low
}

/// The survey's block image from a JPEG's 8×8 block means (sRGB levels as shares of 255, `blocks` across and down,
/// `channels` interleaved; [`crate::io::survey_block_means`]) instead of the block medians of the decoded photo:
/// each `k`×`k` block the mean of the 8×8 means it covers, in linear light (`curve`). `None` where `k` is not a
/// multiple of 8 or the means are not `blocks` × `channels`.
pub(crate) fn from_means(
    means: &[f32],
    blocks: (usize, usize),
    channels: usize,
    k: usize,
    curve: Transfer,
) -> Option<Raster> {
    if k == 0 || !k.is_multiple_of(8) || means.len() != blocks.0 * blocks.1 * channels {
        return None;
    }
    let m = k / 8;
    let (bw, bh) = (blocks.0.div_ceil(m), blocks.1.div_ceil(m));
    let mut out = Raster::filled(bw, bh, channels, 0.0);
    for by in 0..bh {
        for bx in 0..bw {
            for c in 0..channels {
                let (mut sum, mut n) = (0.0f32, 0.0f32);
                for y in by * m..((by + 1) * m).min(blocks.1) {
                    for x in bx * m..((bx + 1) * m).min(blocks.0) {
                        sum += means[(y * blocks.0 + x) * channels + c];
                        n += 1.0;
                    }
                }
                out.data[(by * bw + bx) * channels + c] = curve.to_linear(sum / n);
            }
        }
    }
    Some(out)
}

/// One flag per `k`×`k` block: does the block, or one of its 8 neighbours, hold a masked pixel? (The margin
/// keeps the noise-aware blend off overlay pixels an automatic mask missed at its edge.)
pub(crate) fn masked_blocks(m: &Mask, k: usize) -> Vec<bool> {
    let (bw, bh) = (m.width.div_ceil(k), m.height.div_ceil(k));
    let mut hit = vec![false; bw * bh];
    for (i, &ignored) in m.ignore.iter().enumerate() {
        if ignored {
            hit[(i / m.width / k) * bw + (i % m.width) / k] = true;
        }
    }
    let mut out = vec![false; bw * bh];
    for by in 0..bh {
        for bx in 0..bw {
            out[by * bw + bx] = (by.saturating_sub(1)..(by + 2).min(bh))
                .any(|y| (bx.saturating_sub(1)..(bx + 2).min(bw)).any(|x| hit[y * bw + x]));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::engine::Engine;
    use crate::method::params::Params;

    /// The look-up gives `to_linear` bit for bit: on every value the block median makes (including the
    /// neighbouring floats, which miss the table and are converted directly) and on NaN.
    #[test]
    fn median_to_linear_is_to_linear() {
        for t in [Transfer::Srgb, Transfer::Gamma(2.2)] {
            let table = median_linear_table(t);
            assert_eq!(table.len(), 511);
            for (a, b) in (0..=255u16).flat_map(|a| [(a, a), (a, a.saturating_add(1).min(255))]) {
                let v = (a as f32 + b as f32) * 0.5 * (1.0 / 255.0f32);
                for w in [v, f32::from_bits(v.to_bits() + 1), v * 0.999] {
                    assert_eq!(
                        median_to_linear(&table, t, w).to_bits(),
                        t.to_linear(w).to_bits(),
                        "{t:?} {w}"
                    );
                }
            }
            assert!(median_to_linear(&table, t, f32::NAN).is_nan());
        }
        assert!(median_linear_table(Transfer::Linear).is_empty());
    }

    /// The survey's block image from 8×8 block means: each `K`×`K` block the mean of the 8×8 means it covers (fewer
    /// at the right and bottom border), in linear light, against a brute-force sum; none for `K` not a multiple
    /// of 8 or means of another size.
    #[test]
    fn block_image_from_means_averages_the_means_it_covers() {
        let (bw, bh) = (5usize, 3usize);
        let means: Vec<f32> = (0..bw * bh * 3)
            .map(|i| 0.1 + ((i * 37) % 200) as f32 / 255.0)
            .collect();
        for k in [8usize, 16, 24, 4, 12] {
            let params = Params {
                downsample: k,
                transfer: Some(Transfer::Srgb),
                ..Params::default()
            };
            let mut engine = Engine::<usize>::new(params, None, None).unwrap();
            let engine = engine.first_pass();
            let got = engine.block_image_from_means(&means, (bw, bh), 3);
            assert_eq!(engine.takes_block_means(), k % 8 == 0, "K = {k}");
            let Some(got) = got else {
                assert!(k % 8 != 0, "K = {k}");
                continue;
            };
            let m = k / 8;
            assert_eq!(
                (got.width, got.height, got.channels),
                (bw.div_ceil(m), bh.div_ceil(m), 3)
            );
            for y in 0..got.height {
                for x in 0..got.width {
                    for c in 0..3 {
                        let covered: Vec<f32> = (0..bh)
                            .flat_map(|by| (0..bw).map(move |bx| (bx, by)))
                            .filter(|&(bx, by)| bx / m == x && by / m == y)
                            .map(|(bx, by)| means[(by * bw + bx) * 3 + c])
                            .collect();
                        let want = Transfer::Srgb
                            .to_linear(covered.iter().sum::<f32>() / covered.len() as f32);
                        let v = got.data[(y * got.width + x) * 3 + c];
                        assert!(
                            (v - want).abs() < 1e-6,
                            "K = {k} ({x}, {y}) {c}: {v} vs {want}"
                        );
                    }
                }
            }
            assert!(engine
                .block_image_from_means(&means[1..], (bw, bh), 3)
                .is_none());
        }
    }
}

//! The per-photo refinements of `--method abyss` (the default), on top of the paper's sliding-window `F`:
//!
//! - [`photo_gain`]: one robust gain per photo and channel, fitted on the photo's own seafloor against its
//!   window's `M` — absorbs altitude bounce and exposure jumps that the window's median averages away;
//! - [`soft_floor`]: a floor relative to the photo's lit level (a high percentile of `F` per channel) with a smooth
//!   hand-over instead of a hard clamp, applied to `F` at block resolution (so the correction kernel is unchanged);
//! - not built yet: a scale on the water-column `S`, estimated from the mission itself (survey rays end at the
//!   floor, water-column rays do not, so the water-column `S` over-estimates the survey's backscatter; see
//!   docs/evaluation.md).
//!
//! All work on block-resolution rasters in linear light.

use crate::method::params::Params;
use crate::method::raster::Raster;

/// Percentile of `F` (per channel, over blocks) taken as the photo's lit level.
pub const LIT_PERCENTILE: f64 = 0.95;

/// The value at quantile `q` (0..=1, nearest rank) of `v` (reordered in place, by selection: linear time); NaN
/// for an empty slice.
pub fn quantile(v: &mut [f32], q: f64) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    *v.select_nth_unstable_by(i, f32::total_cmp).1
}

/// Lit level of each channel of `f`: its [`LIT_PERCENTILE`] over the finite samples.
pub fn lit_level(f: &Raster) -> Vec<f32> {
    let c = f.channels;
    (0..c)
        .map(|ch| {
            let mut v: Vec<f32> = f
                .data
                .iter()
                .skip(ch)
                .step_by(c)
                .copied()
                .filter(|x| x.is_finite())
                .collect();
            quantile(&mut v, LIT_PERCENTILE)
        })
        .collect()
}

/// Smooth floor: `F' = (max(F, 0)⁴ + φ⁴)^¼` with `φ = relative · lit level` per channel. Equal to `F` (within
/// 1 %) from `F ≥ 2.3 φ` up, `φ` for `F ≤ 0`, monotone and smooth in between: no hard edge where the clamp
/// starts (no rings at the edge of narrow beams), and unlit corners get at most a gain of `1/φ`. Returns `φ`.
pub fn soft_floor(f: &mut Raster, relative: f32) -> Vec<f32> {
    // Per channel: the floor follows each channel's own lit level, so the colour of dim regions is not biased
    // (one level for all channels from the brightest one darkened red-starved regions: residual pattern ×7 on
    // the dive matrix, docs/evaluation.md).
    let phi: Vec<f32> = lit_level(f)
        .into_iter()
        .map(|l| (relative * l).max(1e-6))
        .collect();
    let c = f.channels;
    for (i, v) in f.data.iter_mut().enumerate() {
        let p = phi[i % c];
        let x = if v.is_finite() { v.max(0.0) } else { 0.0 };
        *v = (x.powi(4) + p.powi(4)).powf(0.25);
    }
    phi
}

/// One robust gain per channel of a photo against its window: the median over the photo's lit blocks of
/// `(own − S) / (M − S)`, where lit means `M − S` at least `min_lit` of the channel's lit level. Blocks of the
/// photo that are not seafloor (nodules, objects) are outvoted by the median as long as they are fewer than half.
/// Gains are clamped to `[0.25, 4]`; a channel with fewer than 8 lit blocks keeps gain 1.
pub fn photo_gain(own: &Raster, m: &Raster, s: Option<&Raster>, min_lit: f32) -> Vec<f32> {
    assert_eq!(own.layout(), m.layout(), "photo and window differ in size");
    let c = own.channels;
    let sv = |i: usize| s.map_or(0.0, |s| s.data[i]);
    let lit: Vec<f32> = m.data.iter().enumerate().map(|(i, &v)| v - sv(i)).collect();
    let lit_raster = Raster {
        data: lit.clone(),
        ..m.clone()
    };
    let level = lit_level(&lit_raster);
    (0..c)
        .map(|ch| {
            let mut r: Vec<f32> = (ch..own.data.len())
                .step_by(c)
                .filter(|&i| lit[i] >= min_lit * level[ch] && lit[i] > 0.0)
                .map(|i| (own.data[i] - sv(i)) / lit[i])
                .filter(|x| x.is_finite())
                .collect();
            if r.len() < 8 {
                1.0
            } else {
                quantile(&mut r, 0.5).clamp(0.25, 4.0)
            }
        })
        .collect()
}

/// Multiply each channel of `f` by its gain.
pub fn apply_gain(f: &mut Raster, gain: &[f32]) {
    let c = f.channels;
    for (i, v) in f.data.iter_mut().enumerate() {
        *v *= gain[i % c];
    }
}

/// What the abyss method does to one photo's `F` (block resolution, linear light): the per-photo gain against the
/// window's `M` (when `params.photo_gain`), then the soft relative floor. `own` is the photo's block-median image,
/// `s_low` the (scaled) backscatter at block resolution. Returns the floor levels `φ` per channel.
pub fn refine_factor(
    f: &mut Raster,
    own: &Raster,
    m: &Raster,
    s_low: Option<&Raster>,
    params: &Params,
) -> Vec<f32> {
    if params.photo_gain {
        let g = photo_gain(own, m, s_low, 0.3);
        apply_gain(f, &g);
    }
    soft_floor(f, params.relative_floor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_nearest_rank() {
        let mut v = vec![5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(quantile(&mut v, 0.5), 3.0);
        assert_eq!(quantile(&mut v, 0.0), 1.0);
        assert_eq!(quantile(&mut v, 1.0), 5.0);
        // 21 values 0..=20: the 95th percentile by nearest rank is index round(20·0.95) = 19.
        let mut w: Vec<f32> = (0..=20).rev().map(|x| x as f32).collect();
        assert_eq!(quantile(&mut w, 0.95), 19.0);
        assert!(quantile(&mut [], 0.5).is_nan());
    }

    #[test]
    fn soft_floor_against_the_formula() {
        // One channel, 21 blocks 0.0, 0.1, …, 2.0: lit level 1.9 (95th percentile), φ = 0.1 · 1.9.
        let mut f = Raster::from_fn(21, 1, 1, |x, _, _| x as f32 * 0.1);
        let orig = f.clone();
        let phi = soft_floor(&mut f, 0.1);
        assert!((phi[0] - 0.19).abs() < 1e-6);
        for (a, b) in orig.data.iter().zip(&f.data) {
            let expect = ((*a as f64).powi(4) + 0.19f64.powi(4)).powf(0.25);
            assert!((*b as f64 - expect).abs() < 1e-5, "{a} -> {b}, {expect}");
            assert!(*b >= *a && *b >= 0.19 - 1e-6);
        }
        // Far above φ the floor changes nothing that matters; negatives and NaN get φ.
        let mut g = Raster {
            width: 3,
            height: 1,
            channels: 1,
            data: vec![-0.5, f32::NAN, 10.0],
        };
        let phi = soft_floor(&mut g, 0.01);
        assert!((g.data[0] - phi[0]).abs() < 1e-6 && (g.data[1] - phi[0]).abs() < 1e-6);
        assert!((g.data[2] - 10.0).abs() < 1e-4);
    }

    #[test]
    fn photo_gain_recovers_a_known_gain_despite_outliers() {
        // M − S a smooth ramp, the photo 1.3× brighter (red), 0.8× (green), 1× (blue) on its seafloor, with 30 %
        // of its blocks dark nodules (ratio 0.1) and S = 0.05 everywhere.
        let (w, h) = (20, 10);
        let s = Raster::filled(w, h, 3, 0.05);
        let m = Raster::from_fn(w, h, 3, |x, y, _| {
            0.05 + 0.2 + 0.02 * x as f32 + 0.01 * y as f32
        });
        let gains = [1.3f32, 0.8, 1.0];
        let own = Raster::from_fn(w, h, 3, |x, y, c| {
            let lit = 0.2 + 0.02 * x as f32 + 0.01 * y as f32;
            let nodule = (x * 7 + y * 3) % 10 < 3;
            0.05 + lit * if nodule { 0.1 } else { gains[c] }
        });
        let g = photo_gain(&own, &m, Some(&s), 0.3);
        for c in 0..3 {
            assert!((g[c] - gains[c]).abs() < 1e-5, "{c}: {}", g[c]);
        }
        // Too few lit blocks: gain 1.
        let tiny = Raster::filled(2, 2, 3, 0.5);
        assert_eq!(photo_gain(&tiny, &tiny, None, 0.3), vec![1.0; 3]);
    }
}

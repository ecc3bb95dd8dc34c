//! The blend (`Steps::denoise`): dim regions blended towards their local level by their signal-to-noise ratio,
//! measured on each photo, instead of amplifying noise.
//!
//! Where a photo has little light, `(I − S)/F` mostly amplifies sensor noise (a red channel boosted ×6 by the white
//! balance, unlit corners). There the best estimate of the albedo is not the amplified sample but a blend of it with
//! the local level, weighted by how much of the sample is signal — the Wiener estimate
//!
//! ```text
//! A = A_low + w·((I − S)/F − A_low),   w = τ²F² / (τ²F² + σ²)
//! ```
//!
//! with `σ²` the sensor noise variance (linear light), `τ²` the variance of the albedo within a block around its
//! level, and `A_low` the block's own level `(median(I) − S)/F` (itself blended towards the seafloor colour `C`
//! where even a block median is mostly noise). `w ≈ 1` wherever the lights reach (the correction is the paper's
//! there), `w → 0` in unlit corners (they show the local level instead of noise).
//!
//! Both variances are measured on each photo, per channel ([`NoiseModel::fit`]): the variance of the samples within
//! a block is `τ²F² + σ²`; the dimmest blocks give `σ²`, the brightest `τ²`. Nothing is assumed about the camera.
//!
//! The blend is handed to the correction kernel as `F/w` and an offset `(1 − w)·A_low`, both at block resolution.

use rayon::prelude::*;

use crate::method::median::quantile;
use crate::method::raster::{Layout, Photo, Raster, Sample, Samples};
use crate::method::seen::Window;
use crate::method::steps::lit_level::lit_level;
use crate::method::transfer::Curve;

/// The noise and texture measured on the photo (with `denoise`), against its `F`.
pub(crate) fn noise(w: &Window, photo: Option<&Photo>, f: &Raster) -> Option<NoiseModel> {
    let k = w.params.downsample;
    let blocks = match (photo, w.params.steps.denoise) {
        (Some(p), true) => {
            // Every second block in both directions, fewer on large photos (about 2000 blocks sampled: plenty for
            // two medians, and the pass stays a small share of a 12 MP photo's time).
            let blocks = p.layout.width.div_ceil(k) * p.layout.height.div_ceil(k);
            let stride = ((blocks as f64 / 2000.0).sqrt() as usize).max(2);
            block_stats(p, k, stride, w.curves)
        }
        _ => Vec::new(),
    };
    NoiseModel::fit(&blocks, f).map(|m| m.with_texture_capped(w.colour))
}

/// The blend of dim regions towards their local level (held more firmly to the channels' shared level where the
/// window was chosen for a dense field), against `s` (the `S` in effect); `None` where it changes nothing (no noise
/// measured: most camera JPEGs), so the photo takes the plain path.
pub(crate) fn fields(
    w: &Window,
    model: Option<&NoiseModel>,
    f: &Raster,
    s: Option<&Raster>,
) -> Option<Blended> {
    let b = model?.blend(
        f,
        &w.own.low,
        s,
        w.colour,
        w.params.downsample,
        w.masked_blocks,
        w.dense(),
    );
    b.weight
        .data
        .iter()
        .any(|&v| v < 1.0 - NEGLIGIBLE_BLEND)
        .then_some(b)
}

/// Where the lights fade out, the blend's fields faded to the fill. A block whose own median is at or below `S` in
/// every channel (`own`, `s`: the photo's block medians and the `S` in effect) where the window's light `f` is
/// below [`UNLIT_F`] of the photo's lit level (a dark object in the light is not a corner the lights do not
/// reach) shows none of the seafloor: its level
/// and weight are the blend's fill (the level the channels share, held to the prior). Its neighbour one code above
/// black shows the seafloor's full level, and the bilinear ramp between their centres is a step in the output: the
/// border of an unlit corner a staircase of blocks, where the input fades smoothly (and a sample one code above
/// black, divided by a tiny `F`, a speck). Every block within [`FADE_REACH`] blocks of an unlit one has its level
/// moved towards the fill of the unlit blocks around it (`(1 − w)·A_low`, their Gaussian-weighted mean over
/// [`FADE_SIGMA`] blocks) and its weight towards 0, by `1 −` [`fade_weight`] of its share of lit blocks there. Blocks
/// farther from every unlit block keep their fields (photos without unlit blocks are unchanged bit for bit).
pub(crate) fn fade_unlit(b: Option<&mut Blended>, own: &Raster, s: Option<&Raster>, f: &Raster) {
    let Some(b) = b else { return };
    let (bw, bh, c) = (b.level.width, b.level.height, b.level.channels);
    if own.layout() != b.level.layout() || own.layout() != f.layout() {
        return;
    }
    let lit = lit_level(f);
    let unlit: Vec<f32> = (0..bw * bh)
        .map(|i| {
            let dark = (i * c..(i + 1) * c).all(|j| {
                let v = own.data[j] - s.map_or(0.0, |s| s.data[j]);
                v.is_finite() && v <= 0.0 && f.data[j] < UNLIT_F * lit[j % c]
            });
            f32::from(u8::from(dark))
        })
        .collect();
    if !unlit.iter().any(|&u| u > 0.0) {
        return;
    }
    // The fill an unlit block shows at a black sample, `(1 − w)·A_low`, as a level of weight 0: the same output
    // at black, and no sample a code above black amplified by `1/F` into a speck.
    let fill: Vec<f32> = (0..bw * bh * c)
        .map(|j| {
            if unlit[j / c] > 0.0 {
                (1.0 - b.weight.data[j]) * b.level.data[j]
            } else {
                0.0
            }
        })
        .collect();
    let near = gaussian_sum(&unlit, bw, bh, 1);
    let fill = gaussian_sum(&fill, bw, bh, c);
    for (i, &n) in near.iter().enumerate() {
        if n <= 0.0 {
            continue;
        }
        let g = fade_weight(1.0 - n);
        let px = i * c..(i + 1) * c;
        for ((l, w), &fl) in b.level.data[px.clone()]
            .iter_mut()
            .zip(&mut b.weight.data[px.clone()])
            .zip(&fill[px])
        {
            let to = fl / n;
            *l = to + (*l - to) * g;
            *w *= g;
        }
    }
}

/// The share of the photo's lit level of `F` (its 95th percentile) below which a block whose own median is black
/// is unlit ([`fade_unlit`]): ten times the default relative floor. AQUALOC's unlit corners sit at the floor; on the
/// dive matrix, blocks whose median is at or below `S` in full light (dark ground under an over-estimated `S`) are
/// left alone.
pub const UNLIT_F: f32 = 0.01;

/// Standard deviation, in blocks, of the Gaussian over which [`fade_unlit`] measures a block's share of unlit blocks.
pub const FADE_SIGMA: f32 = 2.0;

/// Reach, in blocks, of the Gaussian of [`fade_unlit`] (3 [`FADE_SIGMA`]): blocks farther from every unlit block keep
/// their fields.
pub const FADE_REACH: usize = 6;

/// The fade of a block whose share of lit blocks around it is `lit`: 0 up to half lit (the unlit side of a straight
/// border), rising smoothly (a smoothstep, squared so the output's codes rise about evenly on an sRGB curve) to 1
/// where all are lit.
pub fn fade_weight(lit: f32) -> f32 {
    let x = ((lit - 0.5) / 0.5).clamp(0.0, 1.0);
    let s = x * x * (3.0 - 2.0 * x);
    s * s
}

/// Each block's Gaussian-weighted mean of `u` (`c` values a block, `bw`×`bh` blocks) over the blocks within
/// [`FADE_REACH`] inside the frame (the weights renormalised at the frame's edges); exactly 0 where no `u` within
/// reach is nonzero.
fn gaussian_sum(u: &[f32], bw: usize, bh: usize, c: usize) -> Vec<f32> {
    let r = FADE_REACH as isize;
    let taps: Vec<f32> = (-r..=r)
        .map(|d| (-0.5 * (d as f32 / FADE_SIGMA).powi(2)).exp())
        .collect();
    // One pass along rows (`horizontal`) or columns.
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut out = vec![0.0f32; src.len()];
        for y in 0..bh {
            for x in 0..bw {
                let (p, len) = if horizontal { (x, bw) } else { (y, bh) };
                for ch in 0..c {
                    let (mut num, mut den) = (0.0f32, 0.0f32);
                    for (t, &g) in taps.iter().enumerate() {
                        let q = p as isize + t as isize - r;
                        if q >= 0 && (q as usize) < len {
                            let (qx, qy) = if horizontal {
                                (q as usize, y)
                            } else {
                                (x, q as usize)
                            };
                            num += g * src[(qy * bw + qx) * c + ch];
                            den += g;
                        }
                    }
                    out[(y * bw + x) * c + ch] = num / den;
                }
            }
        }
        out
    };
    pass(&pass(u, true), false)
}

/// Blend weights `w` at or above `1 − NEGLIGIBLE_BLEND` count as no blend (the correction of such a row changes by at
/// most 0.1 % of a pixel's detail).
pub const NEGLIGIBLE_BLEND: f32 = 1e-3;

/// Sensor noise and albedo texture of one photo, per channel, in linear light.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    /// `σ²`: variance of the sensor noise (and quantisation), as measured in the photo's dimmest blocks, at their
    /// median level [`NoiseModel::noise_level`].
    pub noise_var: Vec<f32>,
    /// `τ²`: variance of the albedo within a block (output units: the seafloor colour `C` is the level).
    pub texture_var: Vec<f32>,
    /// `dσ²/dL`: how the noise variance grows with the block's level `L` (linear; shot noise), at least 0.
    pub noise_slope: Vec<f32>,
    /// The level at which `σ²` is [`NoiseModel::noise_var`] (the dim blocks' median level).
    pub noise_level: Vec<f32>,
}

/// Statistics of one sampled block, per channel, in linear light: the variance of its samples (`var`: texture,
/// noise and the light's gradient across the block) and the noise-only estimate `diag`, the mean of `d²` over its
/// 2×2 cells with `d = (a − b − c + e)/2` (`a b` over `c e`), which is `σ²` for white noise and 0 for any plane:
/// a light-cone edge across the block does not count as noise. Both are NaN in a channel where the block has a
/// sample at black (code 0) or at the top code: clipping takes noise away, and a black block reads none.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockStats {
    /// Index of the block in the low-resolution raster (`by · blocks_x + bx`).
    pub index: usize,
    /// Variance of the block's samples, per channel.
    pub var: Vec<f32>,
    /// Mean squared diagonal difference, per channel.
    pub diag: Vec<f32>,
    /// Mean of the block's samples (linear), per channel.
    pub mean: Vec<f32>,
}

/// [`BlockStats`] of every `stride`-th block in both directions (`k`×`k` blocks; blocks cut by the photo's edge
/// are skipped), in block-row order. An odd `k` is measured on the block's top-left `(k − 1)`² samples, the 2×2
/// cells that fit (cells that ran one sample into the next block, with the variance divided by `k²` for
/// `(k + 1)²` samples, turned every photo flat grey at `--downsample 3`, 5, 7 or 9). Block rows
/// run in parallel.
pub fn block_stats(
    photo: &Photo,
    k: usize,
    stride: usize,
    curves: (&Curve, &Curve),
) -> Vec<BlockStats> {
    match &photo.samples {
        Samples::U8(v) => stats(v, photo.layout, k, stride, curves.0),
        Samples::U16(v) => stats(v, photo.layout, k, stride, curves.1),
    }
}

fn stats<T: Sample>(v: &[T], l: Layout, k: usize, stride: usize, curve: &Curve) -> Vec<BlockStats> {
    let c = l.channels;
    let bw = l.width.div_ceil(k);
    let stride = stride.max(1);
    // The even part of the block: whole 2×2 cells only.
    let ke = k - k % 2;
    let n = (ke * ke) as f64;
    let cells = ((ke / 2) * (ke / 2)) as f64;
    let at =
        |x: usize, y: usize, ch: usize| curve.linear(v[(y * l.width + x) * c + ch].to_u16()) as f64;
    let top = T::MAX as u16;
    let clipped = |x: usize, y: usize, ch: usize| {
        let code = v[(y * l.width + x) * c + ch].to_u16();
        code == 0 || code == top
    };
    if ke < 2 {
        return Vec::new();
    }
    let rows: Vec<usize> = (0..l.height / k).step_by(stride).collect();
    rows.par_iter()
        .flat_map_iter(|&by| {
            // Offset odd block rows by half a stride so the sampled blocks do not line up in columns.
            let x0 = if (by / stride) % 2 == 1 {
                stride / 2
            } else {
                0
            };
            (x0..l.width / k).step_by(stride).map(move |bx| {
                let (px, py) = (bx * k, by * k);
                let mut var = Vec::with_capacity(c);
                let mut diag = Vec::with_capacity(c);
                let mut mean = Vec::with_capacity(c);
                for ch in 0..c {
                    let (mut sum, mut sq, mut dd) = (0.0f64, 0.0f64, 0.0f64);
                    let mut clip = false;
                    for y in (py..py + ke).step_by(2) {
                        for x in (px..px + ke).step_by(2) {
                            clip |= clipped(x, y, ch)
                                || clipped(x + 1, y, ch)
                                || clipped(x, y + 1, ch)
                                || clipped(x + 1, y + 1, ch);
                            let (a, b, cc, e) = (
                                at(x, y, ch),
                                at(x + 1, y, ch),
                                at(x, y + 1, ch),
                                at(x + 1, y + 1, ch),
                            );
                            sum += a + b + cc + e;
                            sq += a * a + b * b + cc * cc + e * e;
                            let d = (a - b - cc + e) / 2.0;
                            dd += d * d;
                        }
                    }
                    // A block with a sample at black or at the top code has lost part of its noise to the clip
                    // (a black block reads no noise at all): NaN, left out of the fit.
                    if clip {
                        var.push(f32::NAN);
                        diag.push(f32::NAN);
                        mean.push(f32::NAN);
                        continue;
                    }
                    let m = sum / n;
                    var.push(((sq / n - m * m).max(0.0) * n / (n - 1.0)) as f32);
                    diag.push((dd / cells) as f32);
                    mean.push(m as f32);
                }
                BlockStats {
                    index: by * bw + bx,
                    var,
                    diag,
                    mean,
                }
            })
        })
        .collect()
}

impl NoiseModel {
    /// Fit the model per channel to block statistics (from `block_stats`) and `F` at block resolution. The noise
    /// grows with the light a sample gathers (shot noise: a red channel's noise follows its backscatter across the
    /// frame), so `σ²` is a line in the block's level `L`: over the dimmest 10 % of the blocks (by `F`), `σ²` is the
    /// median of `diag − τ_d²F²` at their median level, and the slope is the difference between the medians of
    /// their upper and lower halves by level over the difference of those halves' levels (at least 0); `τ_d²` (the
    /// fine texture seen by `diag`) is the median of `(diag − σ²(L))/F²` over the brightest 25 % (two rounds from
    /// `τ_d² = 0`); then `τ²` is the median of `(var − σ²(L))/F²` over the brightest 25 %. With one `σ²` for the
    /// whole photo, the brightest blocks' extra shot noise was read as texture: in a starved channel, divided by a
    /// tiny `F²`, many times the seafloor's. A noise-free dim photo gets a small `σ²` and is left as the paper corrects
    /// it. `None` with fewer than 50 blocks (too small a photo to tell noise from texture); a channel with fewer than
    /// 20 blocks free of clipped samples gets `σ² = τ² = 0` (divided as the paper does), `None` when no channel has
    /// them.
    pub fn fit(blocks: &[BlockStats], f: &Raster) -> Option<NoiseModel> {
        let c = f.channels;
        if blocks.len() < 50 {
            return None;
        }
        let mut noise_var = vec![0.0f32; c];
        let mut texture_var = vec![0.0f32; c];
        let mut noise_slope = vec![0.0f32; c];
        let mut noise_level = vec![0.0f32; c];
        let mut measured = 0;
        for ch in 0..c {
            // (F, var, diag, level)
            let pts: Vec<(f32, f32, f32, f32)> = blocks
                .iter()
                .map(|b| (f.data[b.index * c + ch], b.var[ch], b.diag[ch], b.mean[ch]))
                .filter(|(f, v, d, l)| {
                    f.is_finite() && v.is_finite() && d.is_finite() && l.is_finite()
                })
                .collect();
            if pts.len() < 20 {
                // Too few blocks without clipped samples (a channel black over most of the frame): no noise or
                // texture measured, so this channel is divided as the paper does; the others still blend.
                continue;
            }
            measured += 1;
            let fitted = fit_channel(pts);
            noise_var[ch] = fitted.noise_var;
            noise_slope[ch] = fitted.noise_slope;
            noise_level[ch] = fitted.noise_level;
            texture_var[ch] = fitted.texture_var;
        }
        (measured > 0).then_some(NoiseModel {
            noise_var,
            texture_var,
            noise_slope,
            noise_level,
        })
    }

    /// A model whose noise does not depend on the level (`σ²` the same everywhere).
    pub fn flat(noise_var: Vec<f32>, texture_var: Vec<f32>) -> NoiseModel {
        let c = noise_var.len();
        NoiseModel {
            noise_var,
            texture_var,
            noise_slope: vec![0.0; c],
            noise_level: vec![0.0; c],
        }
    }

    /// `σ²` of channel `ch` at the level `l` (linear): [`NoiseModel::noise_var`] at the dim blocks' level, plus
    /// the slope times the difference, at least a tenth of it.
    pub fn noise_at(&self, ch: usize, l: f32) -> f32 {
        let s2 = self.noise_var[ch];
        let b = self.noise_slope.get(ch).copied().unwrap_or(0.0);
        let l0 = self.noise_level.get(ch).copied().unwrap_or(0.0);
        noise_line(s2, b, l0, l)
    }

    /// The model with each channel's texture `τ_c` at most `TEXTURE_SPREAD` times the median channel's relative
    /// texture `τ/C` (times its own `C`), counting the channels whose texture was measured (`τ² > 0`). A channel
    /// starved of light measures its texture as `(var − σ²)/F²` with a tiny `F`: a noise level that differs by a
    /// few per cent between its dimmest blocks (where `σ²` is read) and its brightest (shot noise on a strong
    /// backscatter, JPEG compression keeping noise only near edges) is then read as an albedo texture tens of times
    /// the seafloor's, and the blend keeps the amplified noise (a red channel at 8 m: `τ/C` 1.1 where green and
    /// blue read 0.11 and 0.10). Seafloors differ little between channels in relative texture (the real sets:
    /// largest over smallest channel 1.1–1.8 on the median photo, 2.0 on the most uneven); one or two channels are
    /// left as measured.
    pub fn with_texture_capped(mut self, colour: &[f32]) -> Self {
        let mut rel: Vec<f32> = self
            .texture_var
            .iter()
            .zip(colour)
            .filter(|(t, c)| **t > 0.0 && **c > 0.0)
            .map(|(t, c)| t / (c * c))
            .collect();
        if rel.len() < 3 {
            return self;
        }
        let cap = TEXTURE_SPREAD * TEXTURE_SPREAD * quantile(&mut rel, 0.5);
        for (t, c) in self.texture_var.iter_mut().zip(colour) {
            *t = t.min(cap * c * c);
        }
        self
    }

    /// The blend for one photo, at block resolution: from `F` (refined), the photo's block medians `own` and the
    /// backscatter `s` (both linear) and the seafloor colour `C`, the block's level `A_low = (own − S)/F` (blended
    /// towards `C·λ*` with the weight of a block median, noise variance `σ²·π/(2K²)` for `K`×`K` blocks, where `λ*`
    /// is the block's relative level `A_low/C` pooled over the channels by their precision, prior 1) and the
    /// Wiener weight `w = τ²F²/(τ²F² + σ²)`, per channel. Blocks flagged in `keep` (one flag per block: overlays,
    /// vehicle parts) get `w = 1`, no blend. Blending towards block means instead of medians was worse on every
    /// score of the dive matrix.
    ///
    /// With `dense` (a field whose window was chosen for dense clutter), a block median's noise variance is counted
    /// [`DENSE_LEVEL_NOISE`] times, so each channel's block level is held more firmly to the level the channels
    /// share: on nodule fields a starved channel's own block level disagreed between overlapping photos far more
    /// than its sensor noise accounts for (docs/nodules.md).
    #[allow(clippy::too_many_arguments)]
    pub fn blend(
        &self,
        f: &Raster,
        own: &Raster,
        s: Option<&Raster>,
        colour: &[f32],
        k: usize,
        keep: Option<&[bool]>,
        dense: bool,
    ) -> Blended {
        let c = f.channels;
        let mut level = f.clone();
        let mut weight = f.clone();
        let median_var = std::f32::consts::FRAC_PI_2 / (k * k) as f32;
        // The weight of a block's own level against the channels' shared one (more noise counted where dense; the
        // shared level itself pools the channels by their noise alone).
        let level_var = median_var * if dense { DENSE_LEVEL_NOISE } else { 1.0 };
        // The same prior holds the block levels' shared relative level λ* below.
        let prior = self.detail_prior(colour, c);
        let (mut own_rel, mut w, mut w_low) = (vec![f32::NAN; c], vec![1.0f32; c], vec![1.0f32; c]);
        for b in 0..f.data.len() / c {
            // Per channel: the pixel weight, the block's own relative level λ_c = ((median − S)/F)/C and the
            // weight of a block median against the seafloor colour; λ* pools the channels by the precision of their
            // levels, so a starved channel's level follows the well-lit ones (a nodule as large as a block stays
            // dark in red too, instead of red falling back to the seafloor colour alone).
            let (mut num, mut den) = (prior, prior);
            for ch in 0..c {
                let i = b * c + ch;
                let (s2, t2) = (self.noise_at(ch, own.data[i]), self.texture_var[ch]);
                let fv = f.data[i];
                let signal = t2 * fv * fv;
                w[ch] = wiener(signal, s2);
                w_low[ch] = wiener(signal, s2 * level_var);
                let lam = (own.data[i] - s.map_or(0.0, |s| s.data[i])) / fv / colour[ch];
                own_rel[ch] = lam;
                if lam.is_finite() && t2 > 0.0 {
                    let p = (fv * colour[ch]).powi(2) / (s2 * median_var).max(1e-12);
                    let p = p.min(1e8);
                    num += p * lam;
                    den += p;
                }
            }
            let shared = num / den;
            for ch in 0..c {
                let i = b * c + ch;
                let lam = if own_rel[ch].is_finite() {
                    shared + w_low[ch] * (own_rel[ch] - shared)
                } else {
                    shared
                };
                level.data[i] = (colour[ch] * lam).max(LEVEL_MIN);
                weight.data[i] = if keep.is_some_and(|m| m[b]) {
                    1.0
                } else {
                    w[ch].clamp(0.0, 1.0)
                };
            }
        }
        Blended {
            level,
            weight,
            noise_var: self.guide_noise_var(c),
            prior_precision: prior,
        }
    }

    /// The precision of the prior on the relative detail ρ = A/A_low (1 ± τ/C), from the channels' texture.
    fn detail_prior(&self, colour: &[f32], c: usize) -> f32 {
        let rel: f32 = (0..c)
            .map(|ch| self.texture_var[ch] / (colour[ch] * colour[ch]))
            .sum::<f32>()
            / c as f32;
        if rel > 0.0 {
            1.0 / rel
        } else {
            1e6
        }
    }

    /// Each of the `c` channels' `σ²`, infinite for a channel without measured texture (black or clipped throughout): it
    /// cannot guide the others.
    fn guide_noise_var(&self, c: usize) -> Vec<f32> {
        (0..c)
            .map(|ch| {
                if self.texture_var[ch] > 0.0 {
                    self.noise_var[ch]
                } else {
                    f32::INFINITY
                }
            })
            .collect()
    }
}

/// Wiener weight of a signal against a noise variance (1 where neither is measured).
fn wiener(signal: f32, noise: f32) -> f32 {
    if signal + noise > 0.0 {
        signal / (signal + noise)
    } else {
        1.0
    }
}

/// One channel's noise and texture fit (see [`NoiseModel::fit`]).
struct ChannelFit {
    noise_var: f32,
    texture_var: f32,
    noise_slope: f32,
    noise_level: f32,
}

/// The median of `v` (0 when empty).
fn raw_median(mut v: Vec<f32>) -> f32 {
    if v.is_empty() {
        0.0
    } else {
        quantile(&mut v, 0.5)
    }
}

/// The median of `v`, at least 0.
fn median_of(v: Vec<f32>) -> f32 {
    raw_median(v).max(0.0)
}

/// Fit one channel's `σ²` line and `τ²` from its `(F, var, diag, level)` points (at least 20, see [`NoiseModel::fit`]).
fn fit_channel(mut pts: Vec<(f32, f32, f32, f32)>) -> ChannelFit {
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let n = pts.len();
    let dim = &pts[..(n / 10).max(5)];
    let top = &pts[n - (n / 4).max(5)..];
    // A channel that gets no light anywhere (its brightest quarter's median F under MIN_LIT_F) has no
    // measurable texture: dividing by a near-zero F² would make one up.
    let unlit = top[top.len() / 2].0 < MIN_LIT_F;
    let bright: Vec<(f32, f32, f32, f32)> = top
        .iter()
        .copied()
        .filter(|p| p.0 > 0.0 && !unlit)
        .collect();
    // The dim blocks by level: lower and upper half.
    let mut by_level: Vec<(f32, f32, f32, f32)> = dim.to_vec();
    by_level.sort_by(|a, b| a.3.total_cmp(&b.3));
    let half = by_level.len() / 2;
    let level0 = raw_median(by_level.iter().map(|p| p.3).collect());
    let (mut sigma2, mut slope, mut tau_d2) = (0.0f32, 0.0f32, 0.0f32);
    let at = |s2: f32, b: f32, l: f32| noise_line(s2, b, level0, l);
    for _ in 0..2 {
        let resid = |p: &(f32, f32, f32, f32)| p.2 - tau_d2 * p.0.max(0.0).powi(2);
        sigma2 = median_of(dim.iter().map(resid).collect());
        let (lo, hi) = by_level.split_at(half);
        let (l1, l2) = (
            raw_median(lo.iter().map(|p| p.3).collect()),
            raw_median(hi.iter().map(|p| p.3).collect()),
        );
        let (d1, d2) = (
            raw_median(lo.iter().map(resid).collect()),
            raw_median(hi.iter().map(resid).collect()),
        );
        slope = if l2 - l1 > 1e-6 {
            ((d2 - d1) / (l2 - l1)).max(0.0)
        } else {
            0.0
        };
        tau_d2 = median_of(
            bright
                .iter()
                .map(|&(f, _, d, l)| (d - at(sigma2, slope, l)) / (f * f))
                .collect(),
        );
    }
    ChannelFit {
        noise_var: sigma2,
        noise_slope: slope,
        noise_level: level0,
        texture_var: median_of(
            bright
                .iter()
                .map(|&(f, v, _, l)| (v - at(sigma2, slope, l)) / (f * f))
                .collect(),
        ),
    }
}

/// `σ²` at the level `l` on the line through `(l0, s2)` with slope `b`, at least a tenth of `s2`; `s2` itself where
/// there is no slope or no level (a masked block).
fn noise_line(s2: f32, b: f32, l0: f32, l: f32) -> f32 {
    if b > 0.0 && l.is_finite() {
        (s2 + b * (l - l0)).max(0.1 * s2)
    } else {
        s2
    }
}

/// How many times the median channel's relative texture `τ/C` a channel's may be
/// ([`NoiseModel::with_texture_capped`]).
pub const TEXTURE_SPREAD: f32 = 3.0;

/// How many times its sensor noise a block median's noise is counted in [`NoiseModel::blend`] on a dense field:
/// each channel's block level is held that much more firmly to the level the channels share. Chosen on the tuning
/// nodule dives from 1, 4, 8, 16 and 32 (docs/nodules.md): every albedo error, consistency and overlap difference
/// fell with it up to 32; the residual pattern moved a few per cent either way, least at 8.
pub const DENSE_LEVEL_NOISE: f32 = 8.0;

/// Smallest median `F` of a channel's brightest quarter of blocks for its texture `τ²` to be measured (a channel
/// with no light at all, e.g. red over many metres of water, would otherwise divide its variance by a near-zero
/// `F²`).
pub const MIN_LIT_F: f32 = 1e-3;

/// Smallest block level `A_low` the blend divides by.
pub const LEVEL_MIN: f32 = 1e-3;

/// What the correction kernel needs for the noise-aware blend of one photo.
///
/// Per pixel, with `Â_c = (I − S)/F` per channel and `A_low`, `w` upsampled like `F`: the relative detail
/// `ρ_c = Â_c/A_low_c` is estimated once for all channels, as the precision-weighted mean
/// `r = (Σ p_c ρ_c + p₀)/(Σ p_c + p₀)` with `p_c = (F_c·A_low_c)²/σ_c²` and the prior `ρ = 1` of precision `p₀`;
/// then `A_c = w_c·Â_c + (1 − w_c)·A_low_c·r`. A channel starved of light (red, ×6 white balance) takes its detail
/// from the well-lit ones instead of from its own noise, so dark nodules stay dark in every channel rather than
/// turning red.
#[derive(Debug, Clone, PartialEq)]
pub struct Blended {
    /// `A_low` per block and channel (linear, at least `LEVEL_MIN`).
    pub level: Raster,
    /// `w` per block and channel.
    pub weight: Raster,
    /// `σ²` per channel (infinite for a channel that cannot guide the others: no texture measured in it).
    pub noise_var: Vec<f32>,
    /// `p₀`.
    pub prior_precision: f32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::transfer::Transfer;

    /// A 16-bit grey photo `A·F + S + noise` with a known texture and noise, F falling off to the right.
    fn photo(w: usize, h: usize, sigma: f32, tau: f32) -> (Photo, Raster) {
        photo_with_offset(w, h, sigma, tau, 0.05)
    }

    /// [`photo`] with another additive offset (negative: the dim side is clipped at black).
    fn photo_with_offset(w: usize, h: usize, sigma: f32, tau: f32, offset: f32) -> (Photo, Raster) {
        synthetic(w, h, 0x2545_F491, |_, fv, g| {
            (0.4 + tau * g()) * fv + offset + sigma * g()
        })
    }

    /// A 16-bit grey photo `A·F + S + noise` with shot noise: `σ² = a + b·I` at the clean level `I`, `S` rising from
    /// 0.05 at the top to 0.45 at the bottom (a backscatter gradient), `F` falling off to the right.
    fn shot_photo(w: usize, h: usize, tau: f32, a: f32, b: f32) -> (Photo, Raster) {
        synthetic(w, h, 0x1234_5677, |y, fv, g| {
            let clean = (0.4 + tau * g()) * fv + 0.05 + 0.4 * y as f32 / h as f32;
            clean + (a + b * clean).sqrt() * g()
        })
    }

    /// A 16-bit grey `w`×`h` photo whose sample in row `y` is `value(y, F, gauss)` (clamped to `[0, 1]`), with `F`
    /// on 8-pixel blocks falling off to the right, and that `F`; `gauss` draws unit normal noise from `seed`.
    fn synthetic(
        w: usize,
        h: usize,
        seed: u32,
        mut value: impl FnMut(usize, f32, &mut dyn FnMut() -> f32) -> f32,
    ) -> (Photo, Raster) {
        let mut next = crate::method::xorshift32(seed);
        let mut gauss = move || {
            // Irwin–Hall: sum of 12 uniforms minus 6, unit variance.
            (0..12)
                .map(|_| next() as f32 / u32::MAX as f32)
                .sum::<f32>()
                - 6.0
        };
        let k = 8;
        let f = Raster::from_fn(w / k, h / k, 1, |x, _, _| 1.0 - x as f32 / (w / k) as f32);
        let mut v = vec![0u16; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = value(y, f.get(x / k, y / k, 0), &mut gauss);
                v[y * w + x] = (i.clamp(0.0, 1.0) * 65535.0).round() as u16;
            }
        }
        let layout = Layout {
            width: w,
            height: h,
            channels: 1,
        };
        (
            Photo {
                layout,
                samples: Samples::U16(v),
                alpha: None,
            },
            f,
        )
    }

    /// [`block_stats`] of 8×8 blocks of a linear photo, every `stride`-th block.
    fn linear_blocks(p: &Photo, stride: usize) -> Vec<BlockStats> {
        let curves = (
            Curve::new(Transfer::Linear, 256),
            Curve::new(Transfer::Linear, 65536),
        );
        block_stats(p, 8, stride, (&curves.0, &curves.1))
    }

    #[test]
    fn odd_blocks_are_measured_on_their_even_part() {
        // Every block size 2..=9: `var` is the sample variance of the block's top-left (k − k mod 2)² samples and
        // `diag` the mean squared diagonal difference of their 2×2 cells, computed here directly (in f64; the
        // kernel reads each sample as f32, hence the 0.1 % tolerance: the diagonal difference cancels); with white
        // noise of σ = 0.02 on a flat albedo the blocks read σ² on average.
        let (p, _) = photo(72, 48, 0.02, 0.0);
        let Samples::U16(v) = &p.samples else {
            unreachable!()
        };
        let curves = (
            Curve::new(Transfer::Linear, 256),
            Curve::new(Transfer::Linear, 65536),
        );
        let px = |x: usize, y: usize| v[y * 72 + x] as f64 / 65535.0;
        for k in 2..=9 {
            let got = block_stats(&p, k, 1, (&curves.0, &curves.1));
            assert!(!got.is_empty(), "k {k}");
            let bw = 72usize.div_ceil(k);
            let ke = k - k % 2;
            for b in &got {
                let (x0, y0) = ((b.index % bw) * k, (b.index / bw) * k);
                let xs: Vec<f64> = (0..ke * ke).map(|j| px(x0 + j % ke, y0 + j / ke)).collect();
                let n = xs.len() as f64;
                let m = xs.iter().sum::<f64>() / n;
                let var = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
                let mut dd = 0.0;
                for cy in (0..ke).step_by(2) {
                    for cx in (0..ke).step_by(2) {
                        let (x, y) = (x0 + cx, y0 + cy);
                        let d = (px(x, y) - px(x + 1, y) - px(x, y + 1) + px(x + 1, y + 1)) / 2.0;
                        dd += d * d;
                    }
                }
                let diag = dd / ((ke / 2) * (ke / 2)) as f64;
                assert!(
                    (b.var[0] as f64 - var).abs() <= 1e-3 * var,
                    "k {k}: var {} vs {var}",
                    b.var[0]
                );
                assert!(
                    (b.diag[0] as f64 - diag).abs() <= 1e-3 * diag,
                    "k {k}: diag {} vs {diag}",
                    b.diag[0]
                );
            }
            let mean = got.iter().map(|b| b.diag[0] as f64).sum::<f64>() / got.len() as f64;
            assert!(
                (mean / 0.0004 - 1.0).abs() < 0.15,
                "k {k}: mean diag {mean} against σ² 0.0004"
            );
        }
    }

    #[test]
    fn variances_against_a_direct_computation() {
        let (p, _) = photo(64, 48, 0.02, 0.1);
        let got = linear_blocks(&p, 2);
        let Samples::U16(v) = &p.samples else {
            unreachable!()
        };
        assert!(!got.is_empty());
        for b in &got {
            let (i, var) = (b.index, &b.var);
            let (bx, by) = (i % 8, i / 8);
            let xs: Vec<f64> = (0..64)
                .map(|j| v[(by * 8 + j / 8) * 64 + bx * 8 + j % 8] as f64 / 65535.0)
                .collect();
            let m = xs.iter().sum::<f64>() / 64.0;
            let s = xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / 63.0;
            assert!(
                (var[0] as f64 - s).abs() < 1e-6 * s.max(1e-6),
                "{i}: {} vs {s}",
                var[0]
            );
            let px = |j: usize| v[(by * 8 + j / 8) * 64 + bx * 8 + j % 8] as f64 / 65535.0;
            let mut dd = 0.0;
            for cy in (0..8).step_by(2) {
                for cx in (0..8).step_by(2) {
                    let d = (px(cy * 8 + cx) - px(cy * 8 + cx + 1) - px(cy * 8 + cx + 8)
                        + px(cy * 8 + cx + 9))
                        / 2.0;
                    dd += d * d / 16.0;
                }
            }
            assert!(
                (b.diag[0] as f64 - dd).abs() < 1e-6 * dd.max(1e-6),
                "{i}: {} vs {dd}",
                b.diag[0]
            );
        }
    }

    #[test]
    fn fit_recovers_noise_and_texture() {
        let (sigma, tau) = (0.03f32, 0.08f32);
        let (p, f) = photo(640, 320, sigma, tau);
        let blocks = linear_blocks(&p, 1);
        let m = NoiseModel::fit(&blocks, &f).expect("enough blocks");
        let (s2, t2) = (m.noise_var[0], m.texture_var[0]);
        assert!((s2.sqrt() / sigma - 1.0).abs() < 0.15, "σ {}", s2.sqrt());
        assert!((t2.sqrt() / tau - 1.0).abs() < 0.15, "τ {}", t2.sqrt());
        // The same blocks under a channel with no light (F ~ 1e-5): no texture is made up from dividing by F².
        let dark = Raster::from_fn(f.width, f.height, 1, |x, _, _| 1e-5 * (1.0 + x as f32));
        let m = NoiseModel::fit(&blocks, &dark).expect("enough blocks");
        assert_eq!(m.texture_var[0], 0.0);
    }

    #[test]
    fn shot_noise_is_not_taken_for_texture() {
        // σ² = 1e-5 + 2e-3·I: from 1.1e-4 where only S = 0.05 is seen to 1.7e-3 at the brightest samples; the
        // texture τ = 0.04 gives the brightest quarter about as much variance as their extra noise.
        let (tau, a, b) = (0.04f32, 1e-5f32, 2e-3f32);
        let (p, f) = shot_photo(640, 480, tau, a, b);
        let blocks = linear_blocks(&p, 1);
        let m = NoiseModel::fit(&blocks, &f).expect("enough blocks");
        assert!(
            (m.noise_slope[0] / b - 1.0).abs() < 0.25,
            "slope {} against {b}",
            m.noise_slope[0]
        );
        for l in [0.1f32, 0.3, 0.6] {
            let want = a + b * l;
            let got = m.noise_at(0, l);
            assert!(
                (got / want - 1.0).abs() < 0.2,
                "σ² at {l}: {got} against {want}"
            );
        }
        let t = m.texture_var[0].sqrt();
        assert!((t / tau - 1.0).abs() < 0.15, "τ {t} against {tau}");
        // One σ² for the photo (the dim blocks' median, as before) reads the brightest blocks' extra noise as
        // texture: computed here directly, it is off by more than the fit's tolerance.
        let mut pts: Vec<(f32, f32)> = blocks.iter().map(|b| (f.data[b.index], b.var[0])).collect();
        pts.sort_by(|x, y| x.0.total_cmp(&y.0));
        let n = pts.len();
        let mut dim: Vec<f32> = blocks
            .iter()
            .filter(|bl| f.data[bl.index] <= pts[n / 10].0)
            .map(|bl| bl.diag[0])
            .collect();
        let s2 = quantile(&mut dim, 0.5);
        let mut top: Vec<f32> = pts[n - n / 4..]
            .iter()
            .map(|&(fv, v)| (v - s2) / (fv * fv))
            .collect();
        let flat = quantile(&mut top, 0.5).sqrt();
        assert!(
            (flat / tau - 1.0).abs() > 0.15,
            "the flat model's τ {flat} is as good"
        );
    }

    #[test]
    fn noise_at_a_level_follows_the_line_and_stays_positive() {
        let m = NoiseModel {
            noise_var: vec![1e-4, 2e-4],
            texture_var: vec![0.01, 0.01],
            noise_slope: vec![1e-3, 0.0],
            noise_level: vec![0.2, 0.2],
        };
        // On the line through (0.2, 1e-4) with slope 1e-3.
        for l in [0.2f32, 0.3, 0.8] {
            let want = 1e-4 + 1e-3 * (l - 0.2);
            assert!(
                (m.noise_at(0, l) - want).abs() < 1e-9,
                "{l}: {}",
                m.noise_at(0, l)
            );
        }
        // Far below the dim blocks' level the line would go negative: at least a tenth of σ².
        assert!((m.noise_at(0, 0.0) - 1e-5).abs() < 1e-12);
        // A block without a level (masked: NaN) and a channel without slope take the dim blocks' σ².
        assert_eq!(m.noise_at(0, f32::NAN), 1e-4);
        assert_eq!(m.noise_at(1, 0.9), 2e-4);
        // A flat model is flat.
        let flat = NoiseModel::flat(vec![3e-4], vec![0.01]);
        assert_eq!(flat.noise_at(0, 0.9), 3e-4);
    }

    #[test]
    fn blocks_clipped_at_black_do_not_hide_the_noise() {
        // The dim side of the frame reads below black and is clipped there: those blocks show less noise than
        // the sensor has (an all-black block none). They are left out, and σ comes from the dim blocks that are not
        // clipped.
        let (sigma, tau) = (0.02f32, 0.08f32);
        let (p, f) = photo_with_offset(640, 320, sigma, tau, -0.03);
        let blocks = linear_blocks(&p, 1);
        let clipped = blocks.iter().filter(|b| b.diag[0].is_nan()).count();
        assert!(
            clipped > blocks.len() / 10,
            "the test needs more than the dimmest tenth clipped: {clipped} of {}",
            blocks.len()
        );
        let m = NoiseModel::fit(&blocks, &f).expect("enough blocks");
        let s = m.noise_var[0].sqrt();
        assert!((s / sigma - 1.0).abs() < 0.2, "σ {s}");
    }

    #[test]
    fn a_channel_clipped_throughout_does_not_stop_the_others() {
        // Channel 0 black in every block (NaN statistics), channel 1 a measurable photo: the model keeps
        // channel 1's noise and texture and leaves channel 0 at zero (divided as the paper does).
        let (sigma, tau) = (0.03f32, 0.08f32);
        let (p, f1) = photo(640, 320, sigma, tau);
        let grey = linear_blocks(&p, 1);
        let blocks: Vec<BlockStats> = grey
            .iter()
            .map(|b| BlockStats {
                index: b.index,
                var: vec![f32::NAN, b.var[0]],
                diag: vec![f32::NAN, b.diag[0]],
                mean: vec![f32::NAN, b.mean[0]],
            })
            .collect();
        let f = Raster::from_fn(f1.width, f1.height, 2, |x, y, _| f1.get(x, y, 0));
        let m = NoiseModel::fit(&blocks, &f).expect("channel 1 is measurable");
        assert_eq!((m.noise_var[0], m.texture_var[0]), (0.0, 0.0));
        assert!(
            (m.noise_var[1].sqrt() / sigma - 1.0).abs() < 0.15,
            "σ {}",
            m.noise_var[1].sqrt()
        );
        // No channel measurable: no model.
        let none: Vec<BlockStats> = blocks
            .iter()
            .map(|b| BlockStats {
                index: b.index,
                var: vec![f32::NAN; 2],
                diag: vec![f32::NAN; 2],
                mean: vec![f32::NAN; 2],
            })
            .collect();
        assert!(NoiseModel::fit(&none, &f).is_none());
    }

    #[test]
    fn a_starved_channel_takes_its_block_level_from_the_well_lit_ones() {
        // Two blocks, three channels: channel 0 drowned in noise, 1 and 2 clean. Block 1 is a dark object (30 % of
        // the seafloor's level in every channel). The clean channels keep their own levels; the starved channel's
        // level follows them (0.3·C) instead of falling back to the seafloor colour C, which made dark objects red.
        let m = NoiseModel::flat(vec![1.0, 1e-6, 1e-6], vec![0.01, 0.01, 0.01]);
        let f = Raster::filled(2, 1, 3, 0.5);
        let colour = [0.4f32, 0.4, 0.4];
        let own = Raster::from_fn(2, 1, 3, |x, _, _| {
            0.5 * 0.4 * if x == 1 { 0.3 } else { 1.0 }
        });
        let b = m.blend(&f, &own, None, &colour, 8, None, false);
        for ch in 1..3 {
            assert!(
                (b.level.get(1, 0, ch) - 0.12).abs() < 1e-3,
                "ch {ch}: {}",
                b.level.get(1, 0, ch)
            );
        }
        let starved = b.level.get(1, 0, 0);
        assert!(
            (starved - 0.12).abs() < 0.01,
            "starved channel's level {starved}, want about 0.12"
        );
        // On the seafloor block every channel stays at C.
        for ch in 0..3 {
            assert!((b.level.get(0, 0, ch) - 0.4).abs() < 1e-3);
        }
    }

    #[test]
    fn on_a_dense_field_a_block_level_is_held_to_the_shared_level_by_more_noise() {
        // One block, three channels, each with its own relative level; channel 0 noisy enough that its own level
        // counts for about half. The shared level λ* pools the channels by their noise alone (the same with and
        // without `dense`); each channel's level is λ* + w_low·(λ_c − λ*), with w_low the Wiener weight of the
        // block median's noise σ²·π/(2K²), counted DENSE_LEVEL_NOISE times where dense. Computed here by hand.
        let (s2, t2, fv, k) = ([0.002f32, 1e-5, 2e-5], 0.01f32, 0.5f32, 4usize);
        let m = NoiseModel::flat(s2.to_vec(), vec![t2; 3]);
        let f = Raster::filled(1, 1, 3, fv);
        let colour = [0.4f32, 0.4, 0.4];
        let rel = [0.7f32, 1.0, 0.95];
        let own = Raster::from_fn(1, 1, 3, |_, _, ch| fv * colour[ch] * rel[ch]);
        let median_var = std::f32::consts::FRAC_PI_2 / (k * k) as f32;
        let prior = m.detail_prior(&colour, 3);
        let precision = |ch: usize| ((fv * colour[ch]).powi(2) / (s2[ch] * median_var)).min(1e8);
        let shared = (prior + (0..3).map(|ch| precision(ch) * rel[ch]).sum::<f32>())
            / (prior + (0..3).map(precision).sum::<f32>());
        let mut moved = [0.0f32; 2];
        for (i, (dense, times)) in [(false, 1.0f32), (true, DENSE_LEVEL_NOISE)]
            .into_iter()
            .enumerate()
        {
            let b = m.blend(&f, &own, None, &colour, k, None, dense);
            for ch in 0..3 {
                let signal = t2 * fv * fv;
                let w_low = signal / (signal + s2[ch] * median_var * times);
                let want = colour[ch] * (shared + w_low * (rel[ch] - shared));
                let got = b.level.get(0, 0, ch);
                assert!(
                    (got - want).abs() < 1e-5,
                    "dense {dense}, ch {ch}: {got} vs {want}"
                );
                // The pixels' weight does not change.
                let w = signal / (signal + s2[ch]);
                assert!((b.weight.get(0, 0, ch) - w).abs() < 1e-6);
            }
            moved[i] = (b.level.get(0, 0, 0) / colour[0] - rel[0]).abs();
        }
        // The noisy channel's level moved towards the shared level more on the dense field.
        assert!(moved[1] > 1.5 * moved[0] && moved[0] > 0.01, "{moved:?}");
    }

    #[test]
    fn an_unlit_corner_fades_to_its_fill_and_far_blocks_keep_their_fields() {
        // 30×20 blocks, one channel: the left 8 columns unlit (own median 0 = S, F at the floor), the rest lit.
        let (bw, bh) = (30, 20);
        let own = Raster::from_fn(bw, bh, 1, |x, _, _| if x < 8 { 0.0 } else { 0.3 });
        let f = Raster::from_fn(bw, bh, 1, |x, _, _| if x < 8 { 0.001 } else { 0.8 });
        let level = Raster::from_fn(bw, bh, 1, |x, _, _| if x < 8 { 0.02 } else { 0.4 });
        let weight = Raster::from_fn(bw, bh, 1, |x, _, _| if x < 8 { 0.5 } else { 0.9 });
        let blended = || Blended {
            level: level.clone(),
            weight: weight.clone(),
            noise_var: vec![1e-6],
            prior_precision: 10.0,
        };
        let mut b = blended();
        fade_unlit(Some(&mut b), &own, None, &f);
        let fill = 0.5 * 0.02;
        for y in 0..bh {
            // The unlit blocks: the fill (1 − w)·A_low with weight 0.
            for x in 0..8 {
                assert!((b.level.get(x, y, 0) - fill).abs() < 1e-6);
                assert_eq!(b.weight.get(x, y, 0), 0.0);
            }
            // The lit ones: monotone from the fill towards their own fields, within reach; unchanged bit for bit
            // beyond it.
            let mut last = fill;
            for x in 8..bw {
                let (l, w) = (b.level.get(x, y, 0), b.weight.get(x, y, 0));
                if x > 7 + FADE_REACH {
                    assert_eq!((l, w), (0.4, 0.9));
                    continue;
                }
                // Independently: the share of lit blocks along the row (a Gaussian renormalised at the edge; every
                // row alike), and the smoothstep squared.
                let r = FADE_REACH as i64;
                let (mut num, mut den) = (0.0f64, 0.0f64);
                for q in (x as i64 - r).max(0)..=(x as i64 + r).min(bw as i64 - 1) {
                    let g = (-0.5 * ((q - x as i64) as f64 / FADE_SIGMA as f64).powi(2)).exp();
                    den += g;
                    num += if q >= 8 { g } else { 0.0 };
                }
                let t = ((num / den - 0.5) / 0.5).clamp(0.0, 1.0);
                let g = (t * t * (3.0 - 2.0 * t)).powi(2);
                assert!(
                    (l as f64 - (fill as f64 + (0.4 - fill as f64) * g)).abs() < 1e-5,
                    "{x}: {l}"
                );
                assert!((w as f64 - 0.9 * g).abs() < 1e-5, "{x}: {w}");
                assert!(l >= last - 1e-7, "{x}: {l} < {last}");
                last = l;
            }
        }
        // The block next to the border is nearly the fill: no step.
        assert!(b.level.get(8, 0, 0) < fill + 0.05 * (0.4 - fill));
        // A dark block in full light (own median 0, F high) is no unlit corner: nothing changes.
        let own = Raster::from_fn(
            bw,
            bh,
            1,
            |x, y, _| if (x, y) == (15, 10) { 0.0 } else { 0.3 },
        );
        let f = Raster::filled(bw, bh, 1, 0.8);
        let mut b = blended();
        fade_unlit(Some(&mut b), &own, None, &f);
        assert_eq!((b.level, b.weight), (level, weight));
    }

    #[test]
    fn blend_is_the_wiener_weight() {
        let m = NoiseModel::flat(vec![0.01], vec![0.04]);
        let f = Raster::from_fn(4, 1, 1, |x, _, _| [1.0, 0.5, 0.1, 0.0][x]);
        let own = Raster::from_fn(4, 1, 1, |x, _, _| 0.05 + 0.4 * [1.0, 0.5, 0.1, 0.0][x]);
        let s = Raster::filled(4, 1, 1, 0.05);
        let b = m.blend(&f, &own, Some(&s), &[0.4], 8, None, false);
        for x in 0..4 {
            let fv = f.data[x];
            let w = 0.04 * fv * fv / (0.04 * fv * fv + 0.01);
            assert!((b.weight.data[x] - w).abs() < 1e-6, "{x}");
            // The block's level is the seafloor colour here (or C itself where F = 0).
            assert!(
                (b.level.data[x] - 0.4).abs() < 1e-5,
                "{x}: {}",
                b.level.data[x]
            );
        }
        // A masked block keeps w = 1.
        let b = m.blend(
            &f,
            &own,
            Some(&s),
            &[0.4],
            8,
            Some(&[false, false, true, false]),
            false,
        );
        assert_eq!(b.weight.data[2], 1.0);
        assert!((b.prior_precision - 0.16 / 0.04).abs() < 1e-3);
    }

    #[test]
    fn a_channels_texture_is_capped_at_three_times_the_median_channels_relative_texture() {
        // Relative textures τ²/C²: red 4.0 (a starved channel's noise read as texture), green 0.04, blue 0.09.
        let colour = [0.5f32, 0.4, 0.3];
        let rel = [4.0f32, 0.04, 0.09];
        let model = NoiseModel::flat(
            vec![1e-4; 3],
            (0..3).map(|c| rel[c] * colour[c] * colour[c]).collect(),
        );
        let capped = model.clone().with_texture_capped(&colour);
        // The median of 4.0, 0.04 and 0.09 is 0.09; the cap is 3² times it, in each channel's own units.
        let cap = 9.0 * 0.09;
        for c in 0..3 {
            let want = rel[c].min(cap) * colour[c] * colour[c];
            assert!(
                (capped.texture_var[c] - want).abs() <= 1e-6 * want,
                "channel {c}: {} against {want}",
                capped.texture_var[c]
            );
        }
        assert!(capped.texture_var[0] < model.texture_var[0]);
        assert_eq!(capped.noise_var, model.noise_var);
        // Within three times the median: nothing changes.
        let even = NoiseModel::flat(vec![1e-4; 3], vec![0.01, 0.02, 0.05]);
        assert_eq!(even.clone().with_texture_capped(&[0.4; 3]), even);
        // Fewer than three channels with a measured texture: no median to go by.
        let two = NoiseModel::flat(vec![1e-4; 3], vec![1.0, 0.001, 0.0]);
        assert_eq!(two.clone().with_texture_capped(&[0.4; 3]), two);
        let grey = NoiseModel::flat(vec![1e-4], vec![1.0]);
        assert_eq!(grey.clone().with_texture_capped(&[0.4]), grey);
    }
}

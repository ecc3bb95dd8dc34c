//! The correction `A = (I − S) / F`, in `f32`, one pass over the photo. `F` is upsampled on the fly (the full-size
//! `F` never exists), floored so dark corners do not explode, and the result is rounded and clamped to the
//! photo's own range.

use rayon::prelude::*;
use serde::Serialize;

use crate::method::factor::{lerp_rows, taps, Tap};
use crate::method::raster::{Layout, Raster, Sample};
use crate::method::scatter::Prepared;
use crate::method::steps::blend::{Blended, LEVEL_MIN, NEGLIGIBLE_BLEND};
use crate::method::transfer::Curve;
use crate::simd::Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2;

/// The taps along a row ([`taps`]) and each sample's weight `t` (the tap's, repeated for each channel: the
/// vectorised expansion of `F` reads eight samples' weights at once).
#[derive(Clone, Copy)]
struct Along<'a> {
    tx: &'a [Tap],
    tq: &'a [f32],
}

/// Each sample's weight along a row of `c` channels.
fn sample_weights(tx: &[Tap], c: usize) -> Vec<f32> {
    tx.iter()
        .flat_map(|t| std::iter::repeat_n(t.t, c))
        .collect()
}

/// What the correction of one photo did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CorrectStats {
    /// Pixels where `F` (in at least one channel) was below the floor and the floor was used instead.
    pub floored_pixels: u64,
    /// Samples clipped to the output range.
    pub clipped_samples: u64,
}

impl std::ops::AddAssign for CorrectStats {
    fn add_assign(&mut self, o: Self) {
        self.floored_pixels += o.floored_pixels;
        self.clipped_samples += o.clipped_samples;
    }
}

/// Correct `samples` (interleaved, `layout`) in place: `A = (I − S) / max(F, floor)`, where `F` is `factor_low`
/// (one sample per `k`×`k` block) upsampled bilinearly between block centres, in linear light, and `S` is
/// `scatter` at full resolution (`None`: `S = 0`). `curve` converts stored codes to linear light and back; it must
/// follow the transfer `scatter` was prepared for.
///
/// With linear codes the arithmetic is done in units of the output code, `(m·I − q) / (m·F)` with `m = 65535 /
/// max` (257 for 8-bit photos, 1 for 16-bit ones) and `q` the grid index of `S`: the numerator is an exact
/// integer and the one rounding left before the output code is the division's (then `+ 0.5` and the floor).
#[allow(clippy::too_many_arguments)]
pub fn correct_in_place<T: Sample>(
    samples: &mut [T],
    layout: Layout,
    scatter: Option<&Prepared>,
    factor_low: &Raster,
    k: usize,
    floor: f32,
    curve: &Curve,
) -> CorrectStats {
    correct_with_offset(samples, layout, scatter, factor_low, None, k, floor, curve)
}

/// What `--method abyss` adds to the correction: `S` scaled per channel, and the noise-aware blend of dim regions.
#[derive(Debug, Clone, Copy)]
pub struct Blend<'a> {
    /// The blend's fields at block resolution, upsampled bilinearly like `F` ([`Blended`]);
    /// `None`: no blend, `A = (I − k·S)/F`.
    pub fields: Option<&'a Blended>,
    /// `k`: the scale of `S`, one per channel (`backscatter_scale`).
    pub scatter_scale: &'a [f32],
}

/// [`correct_in_place`] with a [`Blend`]: `S` scaled by `k`, and per pixel the blend of
/// the per-pixel blend of [`Blended`]. With `blend: None` this is [`correct_in_place`], bit for bit.
#[allow(clippy::too_many_arguments)]
pub fn correct_with_offset<T: Sample>(
    samples: &mut [T],
    layout: Layout,
    scatter: Option<&Prepared>,
    factor_low: &Raster,
    blend: Option<Blend>,
    k: usize,
    floor: f32,
    curve: &Curve,
) -> CorrectStats {
    check_inputs(samples.len(), layout, scatter, factor_low, blend, curve);
    let Layout {
        width,
        height,
        channels: c,
    } = layout;
    let s_linear = scatter.and_then(|s| s.linear_table()).unwrap_or(&[]);
    let row_len = width * c;
    if row_len == 0 {
        return CorrectStats::default();
    }
    let tx = taps(width, k);
    let tq = sample_weights(&tx, c);
    let along = Along { tx: &tx, tq: &tq };
    let ty = taps(height, k);
    samples
        .par_chunks_mut(row_len)
        .enumerate()
        .map_init(
            || {
                let extra = if blend.is_some() { row_len } else { 0 };
                (
                    vec![0.0f32; factor_low.width * c],
                    vec![0.0f32; row_len],
                    vec![0.0f32; extra],
                    vec![0.0f32; extra],
                    vec![0.0f32; extra],
                )
            },
            |(frow, fx, lx, wx, ax), (y, row)| {
                let t = ty[y];
                lerp_rows(
                    factor_low.row(t.i0 as usize),
                    factor_low.row(t.i1 as usize),
                    t.t,
                    frow,
                );
                let srow = scatter.map(|s| s.row(y));
                match blend {
                    None => {
                        correct_row_dispatch(row, frow, fx, along, c, floor, srow, s_linear, curve)
                    }
                    Some(blend) => blend_row_dispatch(
                        row,
                        RowScratch {
                            frow,
                            fx,
                            lx,
                            wx,
                            ax,
                        },
                        &BlendRow {
                            along,
                            rows: (t.i0 as usize, t.i1 as usize, t.t),
                            blend,
                            c,
                            floor,
                            srow,
                            s_linear,
                            curve,
                        },
                    ),
                }
            },
        )
        .reduce(CorrectStats::default, |mut a, b| {
            a += b;
            a
        })
}

/// The preconditions of [`correct_with_offset`]: sizes that agree, `S` prepared for `curve`'s transfer.
fn check_inputs(
    samples: usize,
    layout: Layout,
    scatter: Option<&Prepared>,
    factor_low: &Raster,
    blend: Option<Blend>,
    curve: &Curve,
) {
    let c = layout.channels;
    assert_eq!(samples, layout.width * layout.height * c);
    assert_eq!(factor_low.channels, c);
    if let Some(b) = blend {
        if let Some(f) = b.fields {
            assert_eq!(
                f.level.layout(),
                factor_low.layout(),
                "blend and factor differ in size"
            );
            assert_eq!(
                f.weight.layout(),
                factor_low.layout(),
                "blend and factor differ in size"
            );
        }
        assert_eq!(b.scatter_scale.len(), c, "one scale of S per channel");
        assert!(
            c <= 4,
            "the blend handles up to 4 channels, the photo has {c}"
        );
    }
    if let Some(s) = scatter {
        assert_eq!(
            s.layout, layout,
            "scatter image size differs from the photo"
        );
        assert_eq!(
            s.linear_table().is_none(),
            curve.is_identity(),
            "scatter prepared for another transfer"
        );
    }
}

/// One row: `F` upsampled along the row and floored into `fx`, then `A = (I − S) / F`. Runs the AVX2 build of
/// the same code where the CPU has it (IEEE arithmetic, no fused operations: the same bits either way).
#[allow(clippy::too_many_arguments)]
#[inline]
fn correct_row_dispatch<T: Sample>(
    row: &mut [T],
    frow: &[f32],
    fx: &mut [f32],
    along: Along,
    c: usize,
    floor: f32,
    srow: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
) -> CorrectStats {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = Avx2::detect() {
        return avx2::correct_row(t, row, frow, fx, along, c, floor, srow, s_linear, curve);
    }
    correct_row_portable(row, frow, fx, along, c, floor, srow, s_linear, curve, None)
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn correct_row_portable<T: Sample>(
    row: &mut [T],
    frow: &[f32],
    fx: &mut [f32],
    along: Along,
    c: usize,
    floor: f32,
    srow: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
    simd: Option<Avx2>,
) -> CorrectStats {
    // F of this row at full resolution, floored (one row: the full-size F never exists). The channel count is
    // made a constant for RGB and grey so the per-pixel loop unrolls.
    let tx = along.tx;
    let tq = simd.map(|t| (t, along.tq));
    let floored_pixels = match c {
        3 => expand_f::<3, 24, false>(frow, fx, tx, tq, floor),
        1 => expand_f::<1, 8, false>(frow, fx, tx, tq, floor),
        _ => expand_f_dyn(frow, fx, tx, c, floor),
    };
    CorrectStats {
        floored_pixels,
        clipped_samples: correct_row(row, fx, srow, s_linear, curve, simd),
    }
}

/// Upsample one low-resolution `F` row (`frow`, already interpolated between block rows) along x into `fx`,
/// floored; returns the pixels where any channel was floored. `N` = 8·`C`.
///
/// Runs of 8 pixels between the same two block centres (most of a row for 8×8 blocks) are done as one
/// straight-line group of `N` samples, which vectorises; the rest pixel by pixel. With `tq` (the AVX2 token and
/// each sample's weight, [`sample_weights`]; from callers compiled for AVX2) the group is `avx2::expand_group`.
/// Same operations, same bits as [`expand_f_dyn`] (tested).
#[inline(always)]
// `!(f >= floor)` on purpose: true for NaN too, in one comparison.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn expand_f<const C: usize, const N: usize, const BY_PIXEL: bool>(
    frow: &[f32],
    fx: &mut [f32],
    tx: &[Tap],
    tq: Option<(Avx2, &[f32])>,
    floor: f32,
) -> u64 {
    debug_assert_eq!(N, 8 * C);
    let mut floored_pixels = 0u64;
    let w = tx.len();
    let mut x = 0;
    while x < w {
        // i0 and i1 never decrease along x: equal at both ends of the run means equal throughout.
        if x + 8 <= w && tx[x].i0 == tx[x + 7].i0 && tx[x].i1 == tx[x + 7].i1 {
            let (i0, i1) = (tx[x].i0 as usize * C, tx[x].i1 as usize * C);
            let (a, b) = (&frow[i0..i0 + C], &frow[i1..i1 + C]);
            let mut av = [0.0f32; C];
            let mut dv = [0.0f32; C];
            for ch in 0..C {
                av[ch] = a[ch];
                dv[ch] = b[ch] - a[ch];
            }
            let taps: &[Tap; 8] = tx[x..x + 8].try_into().unwrap();
            let out: &mut [f32; N] = (&mut fx[x * C..x * C + N]).try_into().unwrap();
            let any_low = if let Some((t, tq)) = tq.map(|(t, tq)| (t, &tq[x * C..x * C + N])) {
                #[cfg(target_arch = "x86_64")]
                {
                    avx2::expand_group::<C>(t, a, b, tq, out, floor)
                }
                #[cfg(not(target_arch = "x86_64"))]
                match (t, tq).0 {}
            } else {
                expand_group::<C, N, BY_PIXEL>(&av, &dv, taps, out, floor)
            };
            if any_low {
                // Rare (dark corners): count the floored pixels of the group again, one by one.
                for tp in taps {
                    floored_pixels += (0..C).any(|ch| !(av[ch] + dv[ch] * tp.t >= floor)) as u64;
                }
            }
            x += 8;
            continue;
        }
        let tp = tx[x];
        let (i0, i1) = (tp.i0 as usize * C, tp.i1 as usize * C);
        let (a, b) = (&frow[i0..i0 + C], &frow[i1..i1 + C]);
        let fpx = &mut fx[x * C..x * C + C];
        let mut floored = false;
        for ch in 0..C {
            let mut f = a[ch] + (b[ch] - a[ch]) * tp.t;
            if f < floor || f.is_nan() {
                f = floor;
                floored = true;
            }
            fpx[ch] = f;
        }
        floored_pixels += floored as u64;
        x += 1;
    }
    floored_pixels
}

/// One group of [`expand_f`] without AVX2: the 8 pixels of `taps` between the same two block centres, `a + d·t` per
/// channel (`av`, `dv`), floored, into `out`; whether any sample was floored.
#[inline(always)]
// `!(f >= floor)` on purpose: true for NaN too, in one comparison.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn expand_group<const C: usize, const N: usize, const BY_PIXEL: bool>(
    av: &[f32; C],
    dv: &[f32; C],
    taps: &[Tap; 8],
    out: &mut [f32; N],
    floor: f32,
) -> bool {
    let mut any_low = false;
    if BY_PIXEL {
        // Pixel by pixel, channel by channel (the same values as below): in the blend's row the compiler kept the
        // `q % C`, `q / C` index arithmetic of the flat loop, at three times the cost; in the plain row the flat
        // loop is the faster (`cargo bench --bench kernels`).
        for (p, tp) in taps.iter().enumerate() {
            for ch in 0..C {
                let f = av[ch] + dv[ch] * tp.t;
                // `f < floor || f.is_nan()`
                let low = !(f >= floor);
                out[p * C + ch] = if low { floor } else { f };
                any_low |= low;
            }
        }
    } else {
        for q in 0..N {
            let f = av[q % C] + dv[q % C] * taps[q / C].t;
            // `f < floor || f.is_nan()`
            let low = !(f >= floor);
            out[q] = if low { floor } else { f };
            any_low |= low;
        }
    }
    any_low
}

/// [`expand_f`] for 3 and 1 channels, [`expand_f_dyn`] otherwise (inlined, so that it is compiled for the
/// caller's target features: a closure would not be).
#[inline(always)]
fn expand_any(
    frow: &[f32],
    out: &mut [f32],
    along: Along,
    simd: Option<Avx2>,
    c: usize,
    floor: f32,
) -> u64 {
    let (tx, tq) = (along.tx, simd.map(|t| (t, along.tq)));
    match c {
        3 => expand_f::<3, 24, true>(frow, out, tx, tq, floor),
        1 => expand_f::<1, 8, true>(frow, out, tx, tq, floor),
        _ => expand_f_dyn(frow, out, tx, c, floor),
    }
}

/// [`expand_f`] for any channel count.
fn expand_f_dyn(frow: &[f32], fx: &mut [f32], tx: &[Tap], c: usize, floor: f32) -> u64 {
    let mut floored_pixels = 0u64;
    for (tp, fpx) in tx.iter().zip(fx.chunks_exact_mut(c)) {
        let (i0, i1) = (tp.i0 as usize * c, tp.i1 as usize * c);
        let mut floored = false;
        for (ch, out) in fpx.iter_mut().enumerate() {
            let (a, b) = (frow[i0 + ch], frow[i1 + ch]);
            let mut f = a + (b - a) * tp.t;
            if f < floor || f.is_nan() {
                f = floor;
                floored = true;
            }
            *out = f;
        }
        floored_pixels += floored as u64;
    }
    floored_pixels
}

/// `x.clamp(0, max) as u16` (NaN gives 0), for `max` ≤ 65535, written so that it vectorises: the saturating
/// float-to-integer cast (`as`) checks every lane for NaN and overflow, which made the compiler fall back to
/// scalar code. `max(0.0)` returns 0 for NaN (as the saturating cast of a NaN does), then the value is an integer
/// in `[0, 65535]` after `floor` (= truncation for non-negative values) and is read from the float's bits after
/// adding 2²³ (exact below 2²⁴).
#[inline(always)]
fn code_of(x: f32, max: f32) -> u16 {
    let x = x.max(0.0).min(max).floor();
    ((x + 8_388_608.0).to_bits() - 0x4B00_0000) as u16
}

/// `A = (I − S) / F` over one row, `F` already upsampled and floored, `S` given by its grid indices `q` (and
/// `s_linear`, `S` in linear light by grid index, for a non-linear `curve`); returns the clipped samples. A
/// sample is clipped when `A` falls outside `[0, 1]` (then its code is 0 or the largest code).
#[inline(always)]
fn correct_row<T: Sample>(
    row: &mut [T],
    f: &[f32],
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
    simd: Option<Avx2>,
) -> u64 {
    // Counted in `u32` (a row has fewer than 2³² samples): a `u64` counter made the compiler vectorise the whole
    // loop 4 lanes wide (to match the 64-bit accumulator) instead of 8.
    let mut clipped = 0u32;
    if curve.is_identity() {
        // Linear codes, in units of the output code: A·max = (I − S)/F·max = (m·code − q) / (m·F) with
        // m = 65535 / max, an integer for 8- and 16-bit codes, so the numerator is exact. Straight-line arithmetic
        // the compiler vectorises (no table look-ups).
        let max = curve.max();
        let m = 65535.0 / max;
        let mut one = |v: &mut T, f: f32, q: f32| {
            let a = (v.to_u16() as f32 * m - q) / (f * m);
            #[allow(clippy::manual_range_contains)]
            // NaN is not clipped; `contains` would say it is
            let out = (a < 0.0) | (a > max);
            clipped += out as u32;
            *v = T::from_code(code_of(a + 0.5, max));
        };
        match q {
            Some(q) => {
                for ((v, &f), &q) in row.iter_mut().zip(f).zip(q) {
                    one(v, f, q as f32);
                }
            }
            None => {
                for (v, &f) in row.iter_mut().zip(f) {
                    one(v, f, 0.0);
                }
            }
        }
    } else {
        // Eight samples at a time with AVX2 gathers (the same bits: tested); the rest one by one.
        #[cfg(target_arch = "x86_64")]
        let done = match simd {
            Some(t) if curve.has_vector_codes() => {
                let (n, c) = avx2::curve_row(t, row, f, q, s_linear, curve);
                clipped += c;
                n
            }
            _ => 0,
        };
        #[cfg(not(target_arch = "x86_64"))]
        let done = simd.map_or(0, |t| match t {});
        for (i, (v, &f)) in row.iter_mut().zip(f).enumerate().skip(done) {
            let s = q.map_or(0.0, |q| s_linear[q[i] as usize]);
            let a = (curve.linear(v.to_u16()) - s) / f;
            #[allow(clippy::manual_range_contains)]
            // NaN is not clipped; `contains` would say it is
            let out = (a < 0.0) | (a > 1.0);
            clipped += out as u32;
            *v = T::from_code(curve.code(a));
        }
    }
    clipped as u64
}

/// What a row with a [`Blend`] reads: the taps along x, the two block rows and the weight between them, the blend,
/// the channel count, the floor of `F`, the row of `S` and the curve.
struct BlendRow<'a> {
    along: Along<'a>,
    rows: (usize, usize, f32),
    blend: Blend<'a>,
    c: usize,
    floor: f32,
    srow: Option<&'a [u16]>,
    s_linear: &'a [f32],
    curve: &'a Curve,
}

/// A row's scratch: `frow` (`F` interpolated between block rows, on entry), and `fx`, `lx`, `wx` (`F`, the blend's
/// level and weight upsampled along the row), `ax` (`Â` of each sample, for `avx2::blend_row_passes`).
struct RowScratch<'b> {
    frow: &'b mut [f32],
    fx: &'b mut [f32],
    lx: &'b mut [f32],
    wx: &'b mut [f32],
    ax: &'b mut [f32],
}

/// One row with a [`Blend`]: `F` (floored) and the blend's level and weight upsampled along the row, then
/// [`correct_row_blend`]. Runs the AVX2 build where the CPU has it (IEEE arithmetic, no fused operations: the same
/// bits either way).
#[inline]
fn blend_row_dispatch<T: Sample>(row: &mut [T], s: RowScratch, r: &BlendRow) -> CorrectStats {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = Avx2::detect() {
        return avx2::blend_row(t, row, s, r);
    }
    blend_row_portable(row, s, r, None)
}

#[inline(always)]
fn blend_row_portable<T: Sample>(
    row: &mut [T],
    s: RowScratch,
    r: &BlendRow,
    simd: Option<Avx2>,
) -> CorrectStats {
    let RowScratch {
        frow,
        fx,
        lx,
        wx,
        ax,
    } = s;
    let BlendRow {
        along,
        rows,
        blend,
        c,
        floor,
        srow,
        s_linear,
        curve,
    } = *r;
    let floored_pixels = expand_any(frow, fx, along, simd, c, floor);
    // Where the blend would change nothing (w ≥ 1 − NEGLIGIBLE_BLEND in both block rows: well-lit or noise-free
    // photos, e.g. most camera JPEGs) and S is not scaled, the plain vectorised row.
    let unscaled = blend.scatter_scale.iter().all(|&k| k == 1.0);
    let negligible = blend.fields.is_none_or(|b| {
        [rows.0, rows.1]
            .iter()
            .all(|&r| b.weight.row(r).iter().all(|&w| w >= 1.0 - NEGLIGIBLE_BLEND))
    });
    if unscaled && negligible {
        return CorrectStats {
            floored_pixels,
            clipped_samples: correct_row(row, fx, srow, s_linear, curve, None),
        };
    }
    if let Some(fields) = blend.fields {
        for (r, out) in [(&fields.level, &mut *lx), (&fields.weight, &mut *wx)] {
            lerp_rows(r.row(rows.0), r.row(rows.1), rows.2, frow);
            expand_any(frow, out, along, simd, c, f32::NEG_INFINITY);
        }
    }
    CorrectStats {
        floored_pixels,
        clipped_samples: correct_row_blend(
            row, fx, lx, wx, ax, blend, c, srow, s_linear, curve, simd,
        ),
    }
}

/// [`correct_row`] with `S` scaled per channel and, with [`Blend::fields`], the noise-aware blend
/// (the formula of [`Blended`]) before the result is coded. `lx` and `wx` hold the blend's level and weight upsampled to the
/// row.
#[allow(clippy::too_many_arguments)]
// `ax` is the AVX2 passes' buffer: unused where there is no AVX2.
#[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
#[inline(always)]
fn correct_row_blend<T: Sample>(
    row: &mut [T],
    f: &mut [f32],
    lx: &mut [f32],
    wx: &[f32],
    ax: &mut [f32],
    blend: Blend,
    c: usize,
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
    simd: Option<Avx2>,
) -> u64 {
    let k = blend.scatter_scale;
    match (c, blend.fields, simd) {
        // With AVX2: the same blend in passes, 8 samples at a time.
        #[cfg(target_arch = "x86_64")]
        (3, Some(b), Some(t)) => {
            avx2::blend_row_passes::<T, 3>(t, row, f, lx, wx, ax, k, b, q, s_linear, curve)
        }
        #[cfg(target_arch = "x86_64")]
        (1, Some(b), Some(t)) => {
            avx2::blend_row_passes::<T, 1>(t, row, f, lx, wx, ax, k, b, q, s_linear, curve)
        }
        (3, Some(b), _) => blend_row::<T, 3>(row, f, lx, wx, k, b, q, s_linear, curve),
        (1, Some(b), _) => blend_row::<T, 1>(row, f, lx, wx, k, b, q, s_linear, curve),
        _ => scaled_row(row, f, blend.scatter_scale, c, q, s_linear, curve),
    }
}

/// Linear light of a sample and of its `S`, for either kind of curve.
#[inline(always)]
fn sample_and_scatter<T: Sample>(
    v: T,
    i: usize,
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
    inv_max: f32,
) -> (f32, f32) {
    if curve.is_identity() {
        (
            v.to_u16() as f32 * inv_max,
            q.map_or(0.0, |q| q[i] as f32 * (1.0 / 65535.0)),
        )
    } else {
        (
            curve.linear(v.to_u16()),
            q.map_or(0.0, |q| s_linear[q[i] as usize]),
        )
    }
}

/// The code of linear light `a`, and whether it was clipped.
#[inline(always)]
fn code_and_clip<T: Sample>(a: f32, curve: &Curve) -> (T, bool) {
    #[allow(clippy::manual_range_contains)]
    let clipped = (a < 0.0) | (a > 1.0);
    let code = if curve.is_identity() {
        let max = curve.max();
        code_of(a * max + 0.5, max)
    } else {
        curve.code(a)
    };
    (T::from_code(code), clipped)
}

/// `A = (I − k·S)/F` for any channel count (no blend).
fn scaled_row<T: Sample>(
    row: &mut [T],
    f: &[f32],
    scale: &[f32],
    c: usize,
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
) -> u64 {
    let inv_max = 1.0 / curve.max();
    let mut clipped = 0u32;
    for (i, v) in row.iter_mut().enumerate() {
        let (lin, s) = sample_and_scatter(*v, i, q, s_linear, curve, inv_max);
        let (code, o) = code_and_clip((lin - scale[i % c] * s) / f[i], curve);
        *v = code;
        clipped += o as u32;
    }
    clipped as u64
}

/// `1/σ²` of a channel's noise variance in the blend. A noise-free channel gets a large precision (1e8: `p` stays
/// finite in f32 for `F·A_low` up to 10³).
#[inline(always)]
fn precision(noise_var: f32) -> f32 {
    if noise_var > 0.0 {
        (1.0 / noise_var).min(1e8)
    } else {
        1e8
    }
}

/// The blend of [`Blended`] over one row of `C`-channel pixels (its formula, rearranged without the
/// divisions by `A_low`: `p·ρ = (F·A_low)²/σ² · Â/A_low = F²·A_low·Â/σ²`), one pixel at a time; with AVX2
/// `avx2::blend_row_passes` does the same in passes.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn blend_row<T: Sample, const C: usize>(
    row: &mut [T],
    f: &[f32],
    lx: &[f32],
    wx: &[f32],
    scale: &[f32],
    b: &Blended,
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
) -> u64 {
    let inv_max = 1.0 / curve.max();
    let top = curve.max() as u16;
    let mut inv_var = [0.0f32; C];
    let mut k = [1.0f32; C];
    for ch in 0..C {
        inv_var[ch] = precision(b.noise_var[ch]);
        k[ch] = scale[ch];
    }
    let prior = b.prior_precision;
    let mut clipped = 0u32;
    for (x, px) in row.chunks_exact_mut(C).enumerate() {
        let i0 = x * C;
        let mut ahat = [0.0f32; C];
        let (mut num, mut den) = (prior, prior);
        for ch in 0..C {
            let i = i0 + ch;
            let code = px[ch].to_u16();
            let (lin, s) = sample_and_scatter(px[ch], i, q, s_linear, curve, inv_max);
            let a = (lin - k[ch] * s) / f[i];
            ahat[ch] = a;
            let lv = lx[i].max(LEVEL_MIN);
            // Weight 0 for a black or clipped sample (it says nothing of the detail) and for a non-finite Â.
            let ok = (code > 0) & (code < top) & a.is_finite();
            // p = (F·A_low)²/σ², and p·ρ = p·Â/A_low = F²·A_low·Â/σ² (no division).
            let g = if ok {
                f[i] * f[i] * lv * inv_var[ch]
            } else {
                0.0
            };
            num += g * a;
            den += g * lv;
        }
        let r = num / den;
        for ch in 0..C {
            let i = i0 + ch;
            let w = wx[i];
            let a = w * ahat[ch] + (1.0 - w) * lx[i].max(LEVEL_MIN) * r;
            let (code, o) = code_and_clip::<T>(a, curve);
            px[ch] = code;
            clipped += o as u32;
        }
    }
    clipped as u64
}

/// Pass 2 of `avx2::blend_row_passes`: per pixel, `r` from its samples' precision weights `g` (in `f`) and `Â` (in
/// `ax`), written over its `g`s.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn pixel_ratios<const C: usize>(f: &mut [f32], ax: &[f32], lx: &[f32], prior: f32) {
    for ((g, a), l) in f
        .chunks_exact_mut(C)
        .zip(ax.chunks_exact(C))
        .zip(lx.chunks_exact(C))
    {
        let (mut num, mut den) = (prior, prior);
        for ch in 0..C {
            num += g[ch] * a[ch];
            den += g[ch] * l[ch].max(LEVEL_MIN);
        }
        let r = num / den;
        g.fill(r);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grouped_expansion_matches_pixel_by_pixel() {
        let mut next = crate::method::xorshift32(0x9E37_79B9);
        for width in [1usize, 5, 7, 8, 9, 16, 23, 37, 64, 100, 333] {
            for k in [1usize, 2, 3, 5, 8, 13, 16] {
                let tx = taps(width, k);
                let nb = crate::method::median::blocks(width, k);
                for c in [1usize, 3] {
                    let frow: Vec<f32> = (0..nb * c)
                        .map(|_| match next() % 10 {
                            0 => f32::NAN,
                            1 => -0.5,
                            2 => 0.01,
                            _ => (next() % 1000) as f32 / 997.0,
                        })
                        .collect();
                    // Both loop forms of the grouped expansion, with a floor and with none (−∞: the blend's fields).
                    for floor in [0.05, f32::NEG_INFINITY] {
                        let mut want = vec![0.0f32; width * c];
                        let n_want = expand_f_dyn(&frow, &mut want, &tx, c, floor);
                        // The AVX2 group where the CPU has it.
                        let tq = sample_weights(&tx, c);
                        for (by_pixel, tq) in [
                            (false, None),
                            (true, None),
                            (true, Avx2::detect().map(|t| (t, &tq[..]))),
                        ] {
                            let mut got = vec![0.0f32; width * c];
                            let n_got = match (c, by_pixel) {
                                (3, false) => {
                                    expand_f::<3, 24, false>(&frow, &mut got, &tx, tq, floor)
                                }
                                (3, true) => {
                                    expand_f::<3, 24, true>(&frow, &mut got, &tx, tq, floor)
                                }
                                (_, false) => {
                                    expand_f::<1, 8, false>(&frow, &mut got, &tx, tq, floor)
                                }
                                (_, true) => {
                                    expand_f::<1, 8, true>(&frow, &mut got, &tx, tq, floor)
                                }
                            };
                            let what = format!(
                                "width {width}, k {k}, c {c}, floor {floor}, {by_pixel}, {}",
                                tq.is_some()
                            );
                            assert_eq!(n_got, n_want, "{what}");
                            let bits =
                                |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                            assert_eq!(bits(&got), bits(&want), "{what}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn code_of_is_the_saturating_cast() {
        let specials = [
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            0.5,
            -0.5,
            254.99998,
            255.0,
            255.5,
            65534.996,
            65535.0,
            65535.5,
            1e9,
            -1e9,
            f32::MIN_POSITIVE,
        ];
        for max in [255.0f32, 65535.0] {
            let reference = |x: f32| x.clamp(0.0, max) as i32 as u16;
            for &x in &specials {
                assert_eq!(code_of(x, max), reference(x), "x = {x}, max = {max}");
            }
            // Every code, its neighbouring floats and the half-way points.
            // (`next_up`/`next_down` by hand: the crate's MSRV predates them.)
            let up = |x: f32| f32::from_bits(x.to_bits() + 1);
            let down = |x: f32| {
                if x > 0.0 {
                    f32::from_bits(x.to_bits() - 1)
                } else {
                    -f32::MIN_POSITIVE
                }
            };
            for c in 0..=(max as u32) {
                let f = c as f32;
                for x in [f, f + 0.5, down(f), up(f), down(f + 0.5)] {
                    assert_eq!(code_of(x, max), reference(x), "x = {x}, max = {max}");
                }
            }
        }
        let mut next = crate::method::xorshift32(0x1234_5678);
        for _ in 0..200_000 {
            let x = f32::from_bits(next());
            for max in [255.0f32, 65535.0] {
                assert_eq!(code_of(x, max), x.clamp(0.0, max) as i32 as u16, "x = {x}");
            }
        }
    }
    use crate::method::factor::upsample;
    use crate::method::transfer::Transfer;

    /// Unfused reference: build the full-size F first, then apply the formula pixel by pixel in f64.
    fn reference(
        samples: &[u16],
        layout: Layout,
        scatter: Option<&Prepared>,
        low: &Raster,
        k: usize,
        floor: f32,
    ) -> Vec<u16> {
        let f = upsample(low, k, layout.width, layout.height);
        samples
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let fv = (f.data[i] as f64).max(floor as f64);
                let s = scatter.map_or(0.0, |s| s.q[i] as f64 / 65535.0);
                let a = (v as f64 / 65535.0 - s) / fv * 65535.0;
                a.round().clamp(0.0, 65535.0) as u16
            })
            .collect()
    }

    /// The frame of the reference tests: a 29×17 RGB photo's layout, blocks of 4, a low-resolution `F` from
    /// `base` up (some blocks under the floor 0.05 when `base` is below it) and a full-resolution `S`.
    fn reference_frame(base: f32) -> (Layout, usize, Raster, Raster) {
        let layout = Layout {
            width: 29,
            height: 17,
            channels: 3,
        };
        let low = Raster::from_fn(8, 5, 3, |x, y, c| {
            base + 0.15 * ((x * 3 + y * 5 + c) % 9) as f32
        });
        let scatter = Raster::from_fn(29, 17, 3, |x, y, c| 0.001 * ((x + 2 * y + c) % 40) as f32);
        (layout, 4, low, scatter)
    }

    #[test]
    fn fused_correction_matches_unfused_reference() {
        let (layout, k, low, scatter) = reference_frame(0.02);
        let scatter = Prepared::from_raster(&scatter, Transfer::Linear);
        let samples: Vec<u16> = (0..29 * 17 * 3)
            .map(|i| ((i * 7919) % 65536) as u16)
            .collect();
        for s in [None, Some(&scatter)] {
            let expect = reference(&samples, layout, s, &low, k, 0.05);
            let mut got = samples.clone();
            let curve = Curve::new(Transfer::Linear, 65536);
            let stats = correct_in_place(&mut got, layout, s, &low, k, 0.05, &curve);
            for (i, (g, e)) in got.iter().zip(&expect).enumerate() {
                assert!((*g as i32 - *e as i32).abs() <= 1, "sample {i}: {g} vs {e}");
            }
            assert!(
                stats.floored_pixels > 0,
                "the low-res F has values under the floor"
            );
        }
    }

    /// The blend fields of the reference tests: levels, weights from 0 to 1, noise variances (one of 0).
    fn reference_fields() -> Blended {
        Blended {
            level: Raster::from_fn(8, 5, 3, |x, y, c| 0.2 + 0.05 * ((x + 2 * y + c) % 7) as f32),
            weight: Raster::from_fn(8, 5, 3, |x, y, c| ((x * 5 + y + c) % 11) as f32 / 10.0),
            noise_var: vec![0.001, 0.0002, 0.0],
            prior_precision: 12.0,
        }
    }

    /// `correct_with_offset` on 16-bit samples (linear curve) or on the same codes as 8-bit samples.
    #[allow(clippy::too_many_arguments)]
    fn corrected(
        samples: &[u16],
        layout: Layout,
        prepared: &Prepared,
        low: &Raster,
        blend: Option<Blend>,
        k: usize,
        curve: &Curve,
    ) -> Vec<u16> {
        let s = Some(prepared);
        if curve.is_identity() {
            let mut got = samples.to_vec();
            correct_with_offset(&mut got, layout, s, low, blend, k, 0.05, curve);
            got
        } else {
            let mut g8: Vec<u8> = samples.iter().map(|&v| v as u8).collect();
            correct_with_offset(&mut g8, layout, s, low, blend, k, 0.05, curve);
            g8.into_iter().map(u16::from).collect()
        }
    }

    /// The blend of one pixel in f64 from its full-size fields (`i` its first sample): `Â = (I − k·S)/max(F,
    /// 0.05)`, `r = (prior + Σ p·Â/l)/(prior + Σ p)` with `p = (F·l)²/σ²` (0 for clipped codes), `A = w·Â + (1 −
    /// w)·l·r`.
    #[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
    fn reference_pixel(
        i: usize,
        codes: &[u16],
        s_lin: &dyn Fn(usize) -> f64,
        curve: &Curve,
        (f, lv, wt): (&Raster, &Raster, &Raster),
        fields: &Blended,
        kscale: &[f32],
        out: &mut [f64],
    ) {
        let top = curve.max() as u16;
        let ahat: Vec<f64> = (0..3)
            .map(|c| {
                let j = i + c;
                (curve.linear(codes[j]) as f64 - kscale[c] as f64 * s_lin(j))
                    / (f.data[j] as f64).max(0.05)
            })
            .collect();
        let (mut num, mut den) = (12.0f64, 12.0f64);
        for c in 0..3 {
            let j = i + c;
            let l = (lv.data[j] as f64).max(1e-3);
            let clipped = codes[j] == 0 || codes[j] == top;
            let inv_var = if fields.noise_var[c] > 0.0 {
                (1.0 / fields.noise_var[c] as f64).min(1e8)
            } else {
                1e8
            };
            let p = if clipped {
                0.0
            } else {
                ((f.data[j] as f64).max(0.05) * l).powi(2) * inv_var
            };
            num += p * ahat[c] / l;
            den += p;
        }
        for c in 0..3 {
            let j = i + c;
            let w = wt.data[j] as f64;
            out[j] = w * ahat[c] + (1.0 - w) * (lv.data[j] as f64).max(1e-3) * num / den;
        }
    }

    #[test]
    fn blend_correction_matches_unfused_reference() {
        // A = w·Â + (1 − w)·A_low·r per pixel (blend::Blended), Â = (I − k·S)/max(F, floor), with F, A_low and
        // w upsampled first to full size, in f64: for linear 16-bit codes and sRGB 8-bit codes.
        let (layout, k, low, scatter) = reference_frame(0.03);
        let fields = reference_fields();
        let up = |r: &Raster| upsample(r, k, 29, 17);
        let (f, lv, wt) = (up(&low), up(&fields.level), up(&fields.weight));
        let kscale = [0.7f32, 0.9, 1.0];
        let blend = Blend {
            fields: Some(&fields),
            scatter_scale: &kscale,
        };
        for t in [Transfer::Linear, Transfer::Srgb] {
            let prepared = Prepared::from_raster(&scatter, t);
            let levels = if t == Transfer::Linear { 65536 } else { 256 };
            let curve = Curve::new(t, levels);
            let samples: Vec<u16> = (0..29 * 17 * 3)
                .map(|i| ((i * 7919) % levels) as u16)
                .collect();
            let s_lin = |i: usize| match prepared.linear_table() {
                Some(table) => table[prepared.q[i] as usize] as f64,
                None => prepared.q[i] as f64 / 65535.0,
            };
            let mut expect = vec![0.0f64; samples.len()];
            for px in 0..29 * 17 {
                let full = (&f, &lv, &wt);
                reference_pixel(
                    px * 3,
                    &samples,
                    &s_lin,
                    &curve,
                    full,
                    &fields,
                    &kscale,
                    &mut expect,
                );
            }
            let got = corrected(&samples, layout, &prepared, &low, Some(blend), k, &curve);
            for (i, (g, e)) in got.iter().zip(&expect).enumerate() {
                let want = curve.code(e.clamp(0.0, 1.0) as f32);
                assert!(
                    (*g as i32 - want as i32).abs() <= 1,
                    "{t:?} sample {i}: {g} vs {want}"
                );
            }
        }
    }

    #[test]
    fn a_blend_that_changes_nothing_is_the_plain_correction() {
        let (layout, k, low, scatter) = reference_frame(0.03);
        let prepared = Prepared::from_raster(&scatter, Transfer::Linear);
        let curve = Curve::new(Transfer::Linear, 65536);
        let samples: Vec<u16> = (0..29 * 17 * 3)
            .map(|i| ((i * 7919) % 65536) as u16)
            .collect();
        let mut plain = samples.clone();
        correct_in_place(&mut plain, layout, Some(&prepared), &low, k, 0.05, &curve);
        // Weights of 1 everywhere (nothing to blend) and k = 1: the plain correction, bit for bit.
        let ones = Blended {
            weight: Raster::filled(8, 5, 3, 1.0),
            ..reference_fields()
        };
        let unblended = Blend {
            fields: Some(&ones),
            scatter_scale: &[1.0; 3],
        };
        let a = corrected(
            &samples,
            layout,
            &prepared,
            &low,
            Some(unblended),
            k,
            &curve,
        );
        assert_eq!(a, plain);
        // Without blend fields and with k = 1 the linear path is the plain correction (within one code).
        let none = Blend {
            fields: None,
            scatter_scale: &[1.0; 3],
        };
        let a = corrected(&samples, layout, &prepared, &low, Some(none), k, &curve);
        assert!(a
            .iter()
            .zip(&plain)
            .all(|(x, y)| (*x as i32 - *y as i32).abs() <= 1));
    }

    /// A random row of `n` samples for the blend: codes with black and top ones, F near 0 and NaN, levels below
    /// LEVEL_MIN and NaN, weights 0 to 1, S's grid indices (for the tests of the AVX2 passes).
    #[cfg(target_arch = "x86_64")]
    #[allow(clippy::type_complexity)]
    fn random_blend_row<T: Sample>(
        next: &mut dyn FnMut() -> u32,
        levels: usize,
        n: usize,
    ) -> (Vec<T>, Vec<f32>, Vec<f32>, Vec<f32>, Vec<u16>) {
        let codes: Vec<T> = (0..n)
            .map(|_| {
                let v = match next() % 12 {
                    0 => 0,
                    1 => levels - 1,
                    _ => next() as usize % levels,
                };
                T::from_code(v as u16)
            })
            .collect();
        let f: Vec<f32> = (0..n)
            .map(|_| match next() % 20 {
                0 => f32::NAN,
                1 => 1e-7,
                _ => (next() % 1000) as f32 / 500.0 + 1e-4,
            })
            .collect();
        let lx: Vec<f32> = (0..n)
            .map(|_| match next() % 20 {
                0 => f32::NAN,
                1 => 1e-5,
                _ => (next() % 1000) as f32 / 1000.0,
            })
            .collect();
        let wx: Vec<f32> = (0..n).map(|_| (next() % 1001) as f32 / 1000.0).collect();
        let q: Vec<u16> = (0..n).map(|_| next() as u16).collect();
        (codes, f, lx, wx, q)
    }

    /// One random row of `len` pixels through [`blend_row`] and `avx2::blend_row_passes`: the same codes and clipped
    /// counts, with S unscaled, scaled and absent.
    #[cfg(target_arch = "x86_64")]
    fn passes_agree<T: Sample, const C: usize>(
        t: Avx2,
        next: &mut dyn FnMut() -> u32,
        transfer: Transfer,
        levels: usize,
        len: usize,
    ) {
        let curve = Curve::new(transfer, levels);
        let prepared_table: Vec<f32> = (0..65536).map(|i| i as f32 / 65535.0 * 0.2).collect();
        let n = len * C;
        let (codes, f, lx, wx, q) = random_blend_row::<T>(next, levels, n);
        let b = Blended {
            level: Raster::filled(1, 1, C, 0.4),
            weight: Raster::filled(1, 1, C, 0.5),
            noise_var: (0..C).map(|c| [1e-4, 0.0, 3e-3][c % 3]).collect(),
            prior_precision: 17.0,
        };
        for (scale, with_s) in [
            (vec![1.0f32; C], true),
            (vec![0.8f32; C], true),
            (vec![1.0; C], false),
        ] {
            let qs = with_s.then_some(q.as_slice());
            let mut want = codes.clone();
            let c_want = blend_row::<T, C>(
                &mut want,
                &f,
                &lx,
                &wx,
                &scale,
                &b,
                qs,
                &prepared_table,
                &curve,
            );
            let mut got = codes.clone();
            let (mut f2, mut l2, mut ax) = (f.clone(), lx.clone(), vec![0.0f32; n]);
            let c_got = avx2::blend_row_passes::<T, C>(
                t,
                &mut got,
                &mut f2,
                &mut l2,
                &wx,
                &mut ax,
                &scale,
                &b,
                qs,
                &prepared_table,
                &curve,
            );
            assert_eq!(
                c_got, c_want,
                "clipped, {transfer:?}, {levels} levels, {C} channels, {len} px"
            );
            let as16 = |v: &[T]| v.iter().map(|x| x.to_u16()).collect::<Vec<_>>();
            assert_eq!(
                as16(&got),
                as16(&want),
                "{transfer:?}, {levels} levels, {C} channels, {len} px"
            );
        }
    }

    /// Pass 2 eight pixels at a time against [`pixel_ratios`], bit for bit: 1 and 3 channels, lengths with and
    /// without a tail, weights of 0, levels below LEVEL_MIN and NaN, NaN `Â`.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn pixel_ratios_in_eights_are_pixel_ratios() {
        let Some(token) = Avx2::detect() else {
            eprintln!("no AVX2: pixel_ratios_avx2 is not used on this CPU");
            return;
        };
        let mut next = crate::method::xorshift32(0x9E37_79B9);
        fn check<const C: usize>(t: Avx2, next: &mut dyn FnMut() -> u32, px: usize) {
            let n = px * C;
            let mut value = |special: f32| -> f32 {
                match next() % 16 {
                    0 => special,
                    1 => 0.0,
                    _ => (next() % 100_000) as f32 / 37_000.0,
                }
            };
            let g: Vec<f32> = (0..n).map(|_| value(0.0)).collect();
            let a: Vec<f32> = (0..n).map(|_| value(f32::NAN)).collect();
            let l: Vec<f32> = (0..n).map(|_| value(f32::NAN) * 1e-3).collect();
            let (mut want, mut got) = (g.clone(), g);
            pixel_ratios::<C>(&mut want, &a, &l, 3.5);
            avx2::pixel_ratios_avx2::<C>(t, &mut got, &a, &l, 3.5);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "{C} channels, {px} px");
        }
        for px in [0usize, 1, 7, 8, 9, 16, 23, 64, 333] {
            check::<1>(token, &mut next, px);
            check::<3>(token, &mut next, px);
        }
    }

    /// The blend in passes (AVX2) against the per-pixel blend, bit for bit: codes and clipped counts, for 8- and
    /// 16-bit rows, sRGB and linear, of 1 and 3 channels whose lengths leave a tail, with black and top codes, F near 0 and
    /// NaN, levels below LEVEL_MIN and NaN, weights 0 to 1, S scaled or absent, noise variances of 0.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn blend_in_passes_is_the_per_pixel_blend_bit_for_bit() {
        let Some(token) = Avx2::detect() else {
            eprintln!("no AVX2: the passes are not used on this CPU");
            return;
        };
        let mut next = crate::method::xorshift32(0x2545_F491);
        for t in [Transfer::Srgb, Transfer::Linear] {
            for len in [1usize, 7, 8, 13, 61, 200] {
                passes_agree::<u8, 3>(token, &mut next, t, 256, len);
                passes_agree::<u8, 1>(token, &mut next, t, 256, len);
                passes_agree::<u16, 3>(token, &mut next, t, 65536, len);
                passes_agree::<u16, 1>(token, &mut next, t, 65536, len);
            }
        }
        for len in [13usize, 200] {
            passes_agree::<u16, 3>(token, &mut next, Transfer::Gamma(10.0), 65536, len);
        }
    }

    #[test]
    fn blend_keeps_a_dark_nodule_dark_in_every_channel() {
        // One pixel, three channels: green and blue well lit, red starved and noisy. A dark nodule (Â/A_low = 0.2 in
        // green and blue): red takes the shared detail and stays dark too. Linear 16-bit codes, one block of 1 px.
        let layout = Layout {
            width: 1,
            height: 1,
            channels: 3,
        };
        let ahat = [0.30f64, 0.08, 0.085];
        let f = [0.05f32, 1.0, 0.9];
        let level = [0.4f32, 0.4, 0.42];
        let weight = [0.1f32, 0.95, 0.9];
        let var = [0.0004f32, 0.0001, 0.0001];
        let prior = 10.0f32;
        let codes: Vec<u16> = (0..3)
            .map(|c| (ahat[c] * f[c] as f64 * 65535.0).round() as u16)
            .collect();
        let low = Raster::from_fn(1, 1, 3, |_, _, c| f[c]);
        let fields = Blended {
            level: Raster::from_fn(1, 1, 3, |_, _, c| level[c]),
            weight: Raster::from_fn(1, 1, 3, |_, _, c| weight[c]),
            noise_var: var.to_vec(),
            prior_precision: prior,
        };
        let curve = Curve::new(Transfer::Linear, 65536);
        let run = |fields: &Blended| {
            let mut got = codes.clone();
            let blend = Blend {
                fields: Some(fields),
                scatter_scale: &[1.0; 3],
            };
            correct_with_offset(&mut got, layout, None, &low, Some(blend), 1, 1e-6, &curve);
            got
        };
        let got = run(&fields);
        // Independent computation in f64, from the Â the codes carry.
        let a: Vec<f64> = (0..3)
            .map(|c| codes[c] as f64 / 65535.0 / f[c] as f64)
            .collect();
        let (mut num, mut den) = (prior as f64, prior as f64);
        for c in 0..3 {
            let p = ((f[c] * level[c]) as f64).powi(2) / var[c] as f64;
            num += p * a[c] / level[c] as f64;
            den += p;
        }
        let r = num / den;
        for c in 0..3 {
            let w = weight[c] as f64;
            let want = (w * a[c] + (1.0 - w) * level[c] as f64 * r) * 65535.0;
            assert!(
                (got[c] as f64 - want).abs() <= 1.0,
                "{c}: {} vs {want}",
                got[c]
            );
        }
        assert!(r < 0.25, "shared detail {r}");
        assert!(got[0] as f64 / 65535.0 < 0.15, "red stays dark: {}", got[0]);
        // With w = 1 everywhere the pixel is the plain correction.
        let ones = Blended {
            weight: Raster::filled(1, 1, 3, 1.0),
            ..fields.clone()
        };
        let mut plain = codes.clone();
        correct_in_place(&mut plain, layout, None, &low, 1, 1e-6, &curve);
        assert_eq!(run(&ones), plain);
    }

    #[test]
    fn avx2_and_portable_rows_agree_bitwise() {
        let c = 3;
        let width = 301;
        let tx = taps(width, 8);
        let frow: Vec<f32> = (0..width.div_ceil(8) * c)
            .map(|i| 0.01 + 0.37 * ((i * 7) % 11) as f32 / 10.0)
            .collect();
        let srow = Raster::from_fn(width, 1, c, |x, _, ch| 0.002 * ((x * c + ch) % 29) as f32);
        // One row through both builds, with and without S.
        fn agree<T: Sample + std::fmt::Debug>(
            row: &[T],
            t: Transfer,
            levels: usize,
            frow: &[f32],
            tx: &[Tap],
            srow: &Raster,
        ) {
            let (c, n) = (srow.channels, row.len());
            let curve = Curve::new(t, levels);
            let prepared = Prepared::from_raster(srow, t);
            let table = prepared.linear_table().unwrap_or(&[]);
            let tq = sample_weights(tx, c);
            let along = Along { tx, tq: &tq };
            for s in [None, Some(prepared.row(0))] {
                let (mut a, mut b) = (row.to_vec(), row.to_vec());
                let (mut fa, mut fb) = (vec![0.0; n], vec![0.0; n]);
                let sa =
                    correct_row_dispatch(&mut a, frow, &mut fa, along, c, 0.05, s, table, &curve);
                let sb = correct_row_portable(
                    &mut b, frow, &mut fb, along, c, 0.05, s, table, &curve, None,
                );
                assert_eq!(a, b, "{t:?}");
                assert_eq!(sa, sb, "{t:?}");
            }
        }
        let row8: Vec<u8> = (0..width * c).map(|i| ((i * 31) % 256) as u8).collect();
        for t in [Transfer::Linear, Transfer::Srgb] {
            agree(&row8, t, 256, &frow, &tx, &srow);
        }
        // 16-bit codes through the sRGB and a gamma curve (the AVX2 path gathers from 65536-entry tables).
        let row16: Vec<u16> = (0..width * c)
            .map(|i| ((i * 7919) % 65536) as u16)
            .collect();
        // gamma:10 at 16 bits has no vector codes (its first threshold is 0 in f32): the scalar codes, not a read
        // past an empty table.
        for t in [Transfer::Srgb, Transfer::Gamma(2.2), Transfer::Gamma(10.0)] {
            agree(&row16, t, 65536, &frow, &tx, &srow);
        }
    }

    #[test]
    fn uniform_lighting_recovers_albedo() {
        // I = A·F + S with F, S constant: the correction returns A exactly (in 8-bit units).
        let layout = Layout {
            width: 16,
            height: 8,
            channels: 1,
        };
        let (f, s) = (0.5f32, 0.1f32);
        let albedo: Vec<u8> = (0..128).map(|i| (i * 2) as u8).collect();
        let mut photo: Vec<u8> = albedo
            .iter()
            .map(|&a| u8::from_f32((a as f32 / 255.0 * f + s) * 255.0))
            .collect();
        let low = Raster::filled(2, 1, 1, f);
        let sc = Prepared::from_raster(&Raster::filled(16, 8, 1, s), Transfer::Linear);
        let curve = Curve::new(Transfer::Linear, 256);
        let stats = correct_in_place(&mut photo, layout, Some(&sc), &low, 8, 0.05, &curve);
        for (g, a) in photo.iter().zip(&albedo) {
            assert!((*g as i32 - *a as i32).abs() <= 1, "{g} vs {a}");
        }
        assert_eq!(stats.floored_pixels, 0);
    }

    #[test]
    fn srgb_correction_works_in_linear_light() {
        // Stored sRGB codes of I = A·F + S (linear light); the correction must return sRGB codes of A.
        let layout = Layout {
            width: 8,
            height: 2,
            channels: 1,
        };
        let (f, s) = (0.4f32, 0.05f32);
        let t = Transfer::Srgb;
        let albedo: Vec<f32> = (0..16).map(|i| 0.05 + 0.05 * i as f32).collect();
        let mut photo: Vec<u8> = albedo
            .iter()
            .map(|&a| (t.from_linear(a * f + s) * 255.0).round() as u8)
            .collect();
        let curve = Curve::new(t, 256);
        correct_in_place(
            &mut photo,
            layout,
            // S is given in stored (sRGB) units, as estimated from the water-column frames.
            Some(&Prepared::from_raster(
                &Raster::filled(8, 2, 1, t.from_linear(s)),
                t,
            )),
            &Raster::filled(1, 1, 1, f),
            8,
            0.05,
            &curve,
        );
        for (i, (&g, &a)) in photo.iter().zip(&albedo).enumerate() {
            let expect = t.from_linear(a) * 255.0;
            assert!((g as f32 - expect).abs() <= 1.5, "{i}: {g} vs {expect}");
        }
    }

    /// Every 8-bit code against an exact calculation in `f64`: the output code is `round(clamp((m·I − q) /
    /// (m·F)))`, with a tolerance of one code only where the exact value lies within 10⁻³ of a rounding boundary
    /// (there `f32`'s rounding of the division may land on either side), and a sample counts as clipped exactly
    /// when the exact value is outside `[0, max]` (away from the two ends by the same margin).
    #[test]
    fn linear_codes_match_exact_arithmetic() {
        for (levels, codes) in [
            (256usize, (0..=255u32).collect::<Vec<_>>()),
            (65536, {
                let mut c: Vec<u32> = (0..=65535u32).step_by(97).collect();
                c.extend([1, 2, 65534, 65535]);
                c
            }),
        ] {
            let curve = Curve::new(Transfer::Linear, levels);
            let max = curve.max() as f64;
            let m = 65535.0 / max;
            let qs = [0u16, 1, 257, 3000, 12_345, 40_000, 65_535];
            let fs = [0.05f32, 0.1, 0.3333, 0.5, 0.77, 1.0, 1.9];
            let width = codes.len();
            for &q in &qs {
                for &fv in &fs {
                    let layout = Layout {
                        width,
                        height: 1,
                        channels: 1,
                    };
                    let mut row: Vec<u16> = codes.iter().map(|&c| c as u16).collect();
                    let mut s = Raster::filled(width, 1, 1, 0.0);
                    s.data.iter_mut().for_each(|v| *v = q as f32 / 65535.0);
                    let prepared = Prepared::from_raster(&s, Transfer::Linear);
                    assert!(
                        prepared.q.iter().all(|&g| g == q),
                        "grid index kept exactly"
                    );
                    let low = Raster::filled(width.div_ceil(8), 1, 1, fv);
                    let stats =
                        correct_in_place(&mut row, layout, Some(&prepared), &low, 8, 0.01, &curve);
                    let mut clipped = 0u64;
                    let mut unsure = 0u64;
                    for (&c, &got) in codes.iter().zip(&row) {
                        let exact = (m * c as f64 - q as f64) / (m * fv as f64);
                        let near_edge = exact.abs() < 1e-3 || (exact - max).abs() < 1e-3;
                        if (exact < 0.0 || exact > max) && !near_edge {
                            clipped += 1;
                        }
                        unsure += near_edge as u64;
                        let want = (exact + 0.5).floor().clamp(0.0, max) as i64;
                        let frac = (exact + 0.5) - (exact + 0.5).floor();
                        let tie = !(1e-3..=1.0 - 1e-3).contains(&frac);
                        let d = (got as i64 - want).abs();
                        assert!(
                            d == 0 || (tie && d == 1),
                            "levels {levels}, code {c}, q {q}, F {fv}: {got} vs exact {exact}"
                        );
                    }
                    assert!(
                        stats.clipped_samples >= clipped
                            && stats.clipped_samples <= clipped + unsure,
                        "levels {levels}, q {q}, F {fv}: {} clipped vs {clipped} (+{unsure})",
                        stats.clipped_samples
                    );
                }
            }
        }
    }
}

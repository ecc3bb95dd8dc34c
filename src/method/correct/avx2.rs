//! The correction's AVX2 kernels. Each entry takes an [`Avx2`] token (made only by runtime detection,
//! [`crate::simd`]) and runs code compiled with AVX2 enabled: the portable rows of the parent module inlined into an
//! AVX2 function, and the kernels written with intrinsics. The same operations in the same order as the portable
//! code, so the same bits (tested in the parent module).

use std::arch::x86_64::*;

use super::{
    blend_row_portable, code_of, correct_row_portable, pixel_ratios, precision, sample_and_scatter,
    Along, BlendRow, CorrectStats, RowScratch,
};
use crate::method::raster::Sample;
use crate::method::steps::blend::{Blended, LEVEL_MIN};
use crate::method::transfer::Curve;
use crate::simd::Avx2;

/// [`correct_row_portable`] compiled for AVX2.
#[allow(clippy::too_many_arguments)]
pub(super) fn correct_row<T: Sample>(
    t: Avx2,
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
    // SAFETY: `t` proves the CPU has AVX2, the one feature `correct_row_in` is compiled for.
    unsafe { correct_row_in(t, row, frow, fx, along, c, floor, srow, s_linear, curve) }
}

#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
fn correct_row_in<T: Sample>(
    t: Avx2,
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
    correct_row_portable(
        row,
        frow,
        fx,
        along,
        c,
        floor,
        srow,
        s_linear,
        curve,
        Some(t),
    )
}

/// [`blend_row_portable`] compiled for AVX2.
pub(super) fn blend_row<T: Sample>(
    t: Avx2,
    row: &mut [T],
    s: RowScratch,
    r: &BlendRow,
) -> CorrectStats {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `blend_row_in` is compiled for.
    unsafe { blend_row_in(t, row, s, r) }
}

#[target_feature(enable = "avx2")]
fn blend_row_in<T: Sample>(t: Avx2, row: &mut [T], s: RowScratch, r: &BlendRow) -> CorrectStats {
    blend_row_portable(row, s, r, Some(t))
}

/// One group of the parent's `expand_f`: eight pixels of `C` (1 or 3) channels between the same two block centres
/// `a` and `b`, `a + (b − a)·t` with each sample's `t` from `tq`, floored where `!(f >= floor)` (NaN too); whether
/// any sample was. The scalar group's operations (no fused multiply-add), eight lanes at a time. `a`, `b` hold `C`
/// values, `tq` and `out` `8·C` (checked).
#[inline(always)]
pub(super) fn expand_group<const C: usize>(
    t: Avx2,
    a: &[f32],
    b: &[f32],
    tq: &[f32],
    out: &mut [f32],
    floor: f32,
) -> bool {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `expand_group_in` is compiled for.
    unsafe { expand_group_in::<C>(t, a, b, tq, out, floor) }
}

#[target_feature(enable = "avx2")]
#[inline]
fn expand_group_in<const C: usize>(
    t: Avx2,
    a: &[f32],
    b: &[f32],
    tq: &[f32],
    out: &mut [f32],
    floor: f32,
) -> bool {
    assert!((C == 1 || C == 3) && a.len() >= C && b.len() >= C);
    assert!(tq.len() >= 8 * C && out.len() >= 8 * C);
    // Lane j of vector v holds channel (8v + j) % C.
    const P: [[i32; 8]; 3] = [
        [0, 1, 2, 0, 1, 2, 0, 1],
        [2, 0, 1, 2, 0, 1, 2, 0],
        [1, 2, 0, 1, 2, 0, 1, 2],
    ];
    let (mut a3, mut d3) = ([0.0f32; 8], [0.0f32; 8]);
    for ch in 0..C {
        a3[ch] = a[ch];
        d3[ch] = b[ch] - a[ch];
    }
    let (a3, d3) = (t.load_ps(&a3), t.load_ps(&d3));
    let fl = _mm256_set1_ps(floor);
    let mut low = 0;
    for v in 0..C {
        let p = if C == 1 {
            _mm256_setzero_si256()
        } else {
            t.load_epi32(&P[v])
        };
        let (av, dv) = (
            _mm256_permutevar8x32_ps(a3, p),
            _mm256_permutevar8x32_ps(d3, p),
        );
        let tv = t.load_ps(&tq[8 * v..]);
        let f = _mm256_add_ps(av, _mm256_mul_ps(dv, tv));
        let m = _mm256_cmp_ps::<_CMP_NGE_UQ>(f, fl);
        t.store_ps(&mut out[8 * v..], _mm256_blendv_ps(f, fl, m));
        low |= _mm256_movemask_ps(m);
    }
    low != 0
}

/// Whether every code a `T` sample can hold indexes `curve`'s linear table, and every grid index of `S` (any
/// `u16`, where there is an `S`) indexes `s_linear`: what the gathers of [`gather_lin_and_s`] need. Tables of 256
/// entries for 8-bit samples, 65536 for 16-bit ones and for `S`, as `Curve::new` and `Prepared::new` make them.
fn gathers_in_bounds<T: Sample>(curve: &Curve, q: Option<&[u16]>, s_linear: &[f32]) -> bool {
    // The codes come from the samples' bytes where `as_bytes` gives them, else from `to_u16`.
    let largest = match T::as_bytes(&[T::default()]) {
        Some(_) => u8::MAX as usize,
        None => u16::MAX as usize,
    };
    curve.linear_table().len() > largest && (q.is_none() || s_linear.len() > u16::MAX as usize)
}

/// The non-linear branch of the parent's `correct_row` for the first `8·⌊len/8⌋` samples, 8 at a time: `to_lin`
/// and `S` gathered, `A = (I − S)/F`, codes by `Curve::codes_avx2`. Returns the samples done and the clipped
/// count. Panics where the tables do not cover the codes ([`gathers_in_bounds`]) or the curve has no vector
/// codes (`Curve::has_vector_codes`: the caller checks).
#[inline(always)]
pub(super) fn curve_row<T: Sample>(
    t: Avx2,
    row: &mut [T],
    f: &[f32],
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
) -> (usize, u32) {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `curve_row_in` is compiled for.
    unsafe { curve_row_in(t, row, f, q, s_linear, curve) }
}

#[target_feature(enable = "avx2")]
fn curve_row_in<T: Sample>(
    t: Avx2,
    row: &mut [T],
    f: &[f32],
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
) -> (usize, u32) {
    assert!(gathers_in_bounds::<T>(curve, q, s_linear) && curve.has_vector_codes());
    let n = row.len() / 8 * 8;
    let to_lin = curve.linear_table();
    let mut clipped = 0u32;
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    for k in (0..n).step_by(8) {
        // SAFETY: the codes index `to_lin`, the `q` index `s_linear` (asserted above).
        let (_, lin, s) = unsafe {
            gather_lin_and_s(t, &row[k..k + 8], q.map(|q| &q[k..k + 8]), to_lin, s_linear)
        };
        let a = _mm256_div_ps(_mm256_sub_ps(lin, s), t.load_ps(&f[k..]));
        let out = _mm256_or_ps(
            _mm256_cmp_ps::<_CMP_LT_OQ>(a, zero),
            _mm256_cmp_ps::<_CMP_GT_OQ>(a, one),
        );
        clipped += (_mm256_movemask_ps(out) as u32).count_ones();
        // SAFETY: the curve has vector codes (asserted above).
        let codes = unsafe { curve.codes_avx2(t, a) };
        store_codes(t, &mut row[k..k + 8], codes);
    }
    (n, clipped)
}

/// The parent's `blend_row` in three passes, so that the per-sample work runs 8 samples at a time: (1) per sample
/// `Â = (I − k·S)/F` (into `ax`) and the precision weight `g` (into `f`, not needed after), 8 at a time (with AVX2
/// gathers for a non-linear curve); (2) per pixel `r` from its samples' `g` and `Â`, written over its `g`s; (3) per
/// sample `w·Â + (1 − w)·A_low·r` (into `lx`), then coded (8 at a time by [`codes_into`] for a non-linear curve).
/// The same operations in the same order as `blend_row`, so the same bits (tested). Panics, for a non-linear
/// curve, where the tables do not cover the codes ([`gathers_in_bounds`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn blend_row_passes<T: Sample, const C: usize>(
    t: Avx2,
    row: &mut [T],
    f: &mut [f32],
    lx: &mut [f32],
    wx: &[f32],
    ax: &mut [f32],
    scale: &[f32],
    b: &Blended,
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
) -> u64 {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `passes_in` is compiled for.
    unsafe { passes_in::<T, C>(t, row, f, lx, wx, ax, scale, b, q, s_linear, curve) }
}

#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
fn passes_in<T: Sample, const C: usize>(
    t: Avx2,
    row: &mut [T],
    f: &mut [f32],
    lx: &mut [f32],
    wx: &[f32],
    ax: &mut [f32],
    scale: &[f32],
    b: &Blended,
    q: Option<&[u16]>,
    s_linear: &[f32],
    curve: &Curve,
) -> u64 {
    let len = row.len();
    let (f, lx, wx, ax) = (&mut f[..len], &mut lx[..len], &wx[..len], &mut ax[..len]);
    let top = curve.max() as u16;
    let to_lin = curve.linear_table();
    let (identity, inv_max) = (curve.is_identity(), 1.0 / curve.max());
    assert!(identity || gathers_in_bounds::<T>(curve, q, s_linear));
    // Per-channel constants repeated along a group of 8: lane j of the group at sample i is channel (i + j) % C.
    let kpat: [f32; 16] = std::array::from_fn(|j| scale[j % C]);
    let vpat: [f32; 16] = std::array::from_fn(|j| precision(b.noise_var[j % C]));
    // Pass 1.
    let n = len / 8 * 8;
    let (zero, lmin) = (_mm256_setzero_ps(), _mm256_set1_ps(LEVEL_MIN));
    let (zeroi, topi) = (_mm256_setzero_si256(), _mm256_set1_epi32(top as i32));
    for i in (0..n).step_by(8) {
        // A match, not `Option::map`: the closure was not inlined into this AVX2 function (a call per 8 samples).
        #[allow(clippy::manual_map)]
        let q8 = match q {
            Some(q) => Some(&q[i..i + 8]),
            None => None,
        };
        let (cv, lin, s) = if identity {
            linear_lin_and_s(t, &row[i..i + 8], q8, inv_max)
        } else {
            // SAFETY: the codes index `to_lin`, the `q` index `s_linear` (asserted above: not linear).
            unsafe { gather_lin_and_s(t, &row[i..i + 8], q8, to_lin, s_linear) }
        };
        let (kv, iv) = (t.load_ps(&kpat[i % C..]), t.load_ps(&vpat[i % C..]));
        let fv = t.load_ps(&f[i..]);
        let a = _mm256_div_ps(_mm256_sub_ps(lin, _mm256_mul_ps(kv, s)), fv);
        // `lx.max(LEVEL_MIN)`: max_ps returns its second operand for a NaN, as f32::max returns the other value.
        let lv = _mm256_max_ps(t.load_ps(&lx[i..]), lmin);
        let ok = _mm256_and_ps(
            _mm256_castsi256_ps(_mm256_and_si256(
                _mm256_cmpgt_epi32(cv, zeroi),
                _mm256_cmpgt_epi32(topi, cv),
            )),
            // finite: a − a is 0 (NaN for NaN and ±∞)
            _mm256_cmp_ps::<_CMP_EQ_OQ>(_mm256_sub_ps(a, a), zero),
        );
        let g = _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(fv, fv), lv), iv);
        t.store_ps(&mut ax[i..], a);
        t.store_ps(&mut f[i..], _mm256_and_ps(ok, g));
    }
    for i in n..len {
        let ch = i % C;
        let code = row[i].to_u16();
        let (lin, s) = sample_and_scatter(row[i], i, q, s_linear, curve, inv_max);
        let a = (lin - kpat[ch] * s) / f[i];
        let lv = lx[i].max(LEVEL_MIN);
        let ok = (code > 0) & (code < top) & a.is_finite();
        ax[i] = a;
        f[i] = if ok { f[i] * f[i] * lv * vpat[ch] } else { 0.0 };
    }
    pixel_ratios_in::<C>(t, f, ax, lx, b.prior_precision);
    let clipped = blend_pass3(lx, wx, ax, f);
    codes_into(t, row, lx, curve);
    clipped as u64
}

/// Pass 3 of [`blend_row_passes`]: `lx = w·Â + (1 − w)·A_low·r`, counting the samples outside 0..1.
#[target_feature(enable = "avx2")]
fn blend_pass3(lx: &mut [f32], wx: &[f32], ax: &[f32], f: &[f32]) -> u32 {
    let mut clipped = 0u32;
    for (((l, &w), &a), &r) in lx.iter_mut().zip(wx).zip(ax.iter()).zip(f.iter()) {
        let v = w * a + (1.0 - w) * l.max(LEVEL_MIN) * r;
        #[allow(clippy::manual_range_contains)]
        // NaN is not clipped; `contains` would say it is
        let o = (v < 0.0) | (v > 1.0);
        clipped += o as u32;
        *l = v;
    }
    clipped
}

/// `row[k] = ` the code of linear light `l[k]` (8 at a time by `Curve::codes_avx2` for a curve that has them).
#[target_feature(enable = "avx2")]
#[inline]
fn codes_into<T: Sample>(t: Avx2, row: &mut [T], l: &[f32], curve: &Curve) {
    if curve.is_identity() {
        let max = curve.max();
        for (v, &a) in row.iter_mut().zip(l) {
            *v = T::from_code(code_of(a * max + 0.5, max));
        }
    } else {
        let done = if curve.has_vector_codes() {
            // SAFETY: the curve has vector codes (checked).
            unsafe { codes_into_avx2(t, row, l, curve) }
        } else {
            0
        };
        for (v, &a) in row.iter_mut().zip(l).skip(done) {
            *v = T::from_code(curve.code(a));
        }
    }
}

/// `row[k] = curve.code(l[k])` for the first `8·⌊len/8⌋` samples, 8 at a time by `Curve::codes_avx2` (the same
/// codes, tested); returns how many.
///
/// # Safety
/// `curve.has_vector_codes()` must be true.
#[target_feature(enable = "avx2")]
unsafe fn codes_into_avx2<T: Sample>(t: Avx2, row: &mut [T], l: &[f32], curve: &Curve) -> usize {
    let n = row.len().min(l.len()) / 8 * 8;
    for k in (0..n).step_by(8) {
        // SAFETY: the caller's contract.
        let codes = unsafe { curve.codes_avx2(t, t.load_ps(&l[k..k + 8])) };
        store_codes(t, &mut row[k..k + 8], codes);
    }
    n
}

/// Eight samples' codes, their linear light and their `S` for a linear curve, as `sample_and_scatter` gives
/// them: code / max, and `S`'s grid index / 65535 (0 without). `samples` and `q` hold at least 8 values
/// (checked). Always inlined, into callers compiled for AVX2.
#[inline(always)]
fn linear_lin_and_s<T: Sample>(
    t: Avx2,
    samples: &[T],
    q: Option<&[u16]>,
    inv_max: f32,
) -> (__m256i, __m256, __m256) {
    let cv = widen_codes(t, samples);
    // SAFETY: `t` proves the CPU has AVX2, all these intrinsics need (no memory access).
    let lin = unsafe { _mm256_mul_ps(_mm256_cvtepi32_ps(cv), _mm256_set1_ps(inv_max)) };
    let s = match q {
        Some(q) => {
            let q8 = t.load_epu16x8(q);
            // SAFETY: as above.
            unsafe {
                let qv = _mm256_cvtepi32_ps(_mm256_cvtepu16_epi32(q8));
                _mm256_mul_ps(qv, _mm256_set1_ps(1.0 / 65535.0))
            }
        }
        // SAFETY: as above.
        None => unsafe { _mm256_setzero_ps() },
    };
    (cv, lin, s)
}

/// The parent's `pixel_ratios` 8 pixels at a time (their samples split by channel; the same operations in the same
/// order, so the same bits), the pixels left over by `pixel_ratios`. The run reaches it inside
/// [`blend_row_passes`]; the tests, alone.
#[cfg(test)]
pub(super) fn pixel_ratios_avx2<const C: usize>(
    t: Avx2,
    f: &mut [f32],
    ax: &[f32],
    lx: &[f32],
    prior: f32,
) {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `pixel_ratios_in` is compiled for.
    unsafe { pixel_ratios_in::<C>(t, f, ax, lx, prior) }
}

#[target_feature(enable = "avx2")]
fn pixel_ratios_in<const C: usize>(t: Avx2, f: &mut [f32], ax: &[f32], lx: &[f32], prior: f32) {
    let len = f.len().min(ax.len()).min(lx.len()) / C * C;
    let n = len / (8 * C) * (8 * C);
    let (p, lmin) = (_mm256_set1_ps(prior), _mm256_set1_ps(LEVEL_MIN));
    // Lane k of output vector v holds the ratio of pixel (8·v + k) / C.
    let mut at = [[0i32; 8]; 3];
    for (v, lanes) in at.iter_mut().enumerate() {
        for (k, p) in lanes.iter_mut().enumerate() {
            *p = ((8 * v + k) / C) as i32;
        }
    }
    let spread = [0, 1, 2].map(|v| t.load_epi32(&at[v]));
    for base in (0..n).step_by(8 * C) {
        let (g, a, l) = (
            by_channel::<C>(t, &f[base..base + 8 * C]),
            by_channel::<C>(t, &ax[base..base + 8 * C]),
            by_channel::<C>(t, &lx[base..base + 8 * C]),
        );
        let (mut num, mut den) = (p, p);
        for ch in 0..C {
            num = _mm256_add_ps(num, _mm256_mul_ps(g[ch], a[ch]));
            den = _mm256_add_ps(den, _mm256_mul_ps(g[ch], _mm256_max_ps(l[ch], lmin)));
        }
        let r = _mm256_div_ps(num, den);
        if C == 1 {
            t.store_ps(&mut f[base..base + 8], r);
        } else {
            for (v, &at) in spread.iter().enumerate().take(C) {
                let out = &mut f[base + 8 * v..base + 8 * v + 8];
                t.store_ps(out, _mm256_permutevar8x32_ps(r, at));
            }
        }
    }
    pixel_ratios::<C>(&mut f[n..len], &ax[n..len], &lx[n..len], prior);
}

/// Eight pixels of `C` (1 or 3) interleaved channels, one vector per channel (lane k: pixel k): for 3 channels
/// two blends and a permute each (moves only). `v` holds at least `8·C` values (checked). Always inlined, into
/// callers compiled for AVX2.
#[inline(always)]
fn by_channel<const C: usize>(t: Avx2, v: &[f32]) -> [__m256; 3] {
    let v0 = t.load_ps(&v[..8]);
    if C == 1 {
        return [v0; 3];
    }
    let (v1, v2) = (t.load_ps(&v[8..16]), t.load_ps(&v[16..24]));
    let idx = |a: [i32; 8]| t.load_epi32(&a);
    let (i0, i1, i2) = (
        idx([0, 3, 6, 1, 4, 7, 2, 5]),
        idx([1, 4, 7, 2, 5, 0, 3, 6]),
        idx([2, 5, 0, 3, 6, 1, 4, 7]),
    );
    // SAFETY: `t` proves the CPU has AVX2, all these intrinsics need (no memory access).
    unsafe {
        // Channel 0 sits in lanes 0, 3, 6 of v0, 1, 4, 7 of v1 and 2, 5 of v2 (channels 1 and 2 one lane later).
        let x = _mm256_blend_ps::<0x24>(_mm256_blend_ps::<0x92>(v0, v1), v2);
        let y = _mm256_blend_ps::<0x49>(_mm256_blend_ps::<0x24>(v0, v1), v2);
        let z = _mm256_blend_ps::<0x92>(_mm256_blend_ps::<0x49>(v0, v1), v2);
        [
            _mm256_permutevar8x32_ps(x, i0),
            _mm256_permutevar8x32_ps(y, i1),
            _mm256_permutevar8x32_ps(z, i2),
        ]
    }
}

/// Eight samples' codes, their linear light (`to_lin` by code) and their `S` (`s_linear` by the grid indices `q`;
/// 0 without), gathered. `samples` and `q` hold at least 8 values (checked). Always inlined, into callers compiled
/// for AVX2 (as a function of its own it cost the sRGB row 5–10 %).
///
/// # Safety
/// Every code must index `to_lin` and every `q` index `s_linear` (the gathers do not check).
#[inline(always)]
unsafe fn gather_lin_and_s<T: Sample>(
    t: Avx2,
    samples: &[T],
    q: Option<&[u16]>,
    to_lin: &[f32],
    s_linear: &[f32],
) -> (__m256i, __m256, __m256) {
    let cv = widen_codes(t, samples);
    // SAFETY: `t` proves the CPU has AVX2; the caller's contract keeps each lane's index inside `to_lin`.
    let lin = unsafe { _mm256_i32gather_ps::<4>(to_lin.as_ptr(), cv) };
    let s = match q {
        Some(q) => {
            let q8 = t.load_epu16x8(q);
            // SAFETY: `t` proves the CPU has AVX2; the caller's contract keeps each `q` inside `s_linear`.
            unsafe { _mm256_i32gather_ps::<4>(s_linear.as_ptr(), _mm256_cvtepu16_epi32(q8)) }
        }
        // SAFETY: `t` proves the CPU has AVX (no memory access).
        None => unsafe { _mm256_setzero_ps() },
    };
    (cv, lin, s)
}

/// The first eight samples' codes, one per lane. `samples` holds at least 8 values (checked). Always inlined,
/// into callers compiled for AVX2.
#[inline(always)]
fn widen_codes<T: Sample>(t: Avx2, samples: &[T]) -> __m256i {
    match T::as_bytes(&samples[..8]) {
        Some(b) => {
            let b: &[u8; 8] = b.try_into().expect("8 bytes");
            // SAFETY: `t` proves the CPU has AVX2; `b` holds the 8 bytes the load reads, unaligned.
            unsafe { _mm256_cvtepu8_epi32(_mm_loadl_epi64(b.as_ptr().cast())) }
        }
        None => {
            let mut codes = [0i32; 8];
            for (c, v) in codes.iter_mut().zip(samples) {
                *c = v.to_u16() as i32;
            }
            t.load_epi32(&codes)
        }
    }
}

/// Eight codes (`0..=max`, one per lane) into eight samples. `out` holds 8 (checked).
#[target_feature(enable = "avx2")]
#[inline]
fn store_codes<T: Sample>(t: Avx2, out: &mut [T], codes: __m256i) {
    let out = &mut out[..8];
    if let Some(bytes) = T::as_bytes_mut(out) {
        // 8-bit samples: the codes (0..=255) packed to bytes in registers (a byte-by-byte store of the lanes was
        // a fifth of the sRGB row's time).
        let p16 = _mm256_packus_epi32(codes, codes);
        let p8 = _mm256_packus_epi16(p16, p16);
        let lo = _mm_cvtsi128_si32(_mm256_castsi256_si128(p8)).to_le_bytes();
        let hi = _mm_cvtsi128_si32(_mm256_extracti128_si256::<1>(p8)).to_le_bytes();
        bytes[..4].copy_from_slice(&lo);
        bytes[4..].copy_from_slice(&hi);
    } else {
        for (v, &c) in out.iter_mut().zip(&t.to_epi32(codes)) {
            *v = T::from_code(c as u16);
        }
    }
}

//! The median kernels' AVX2 builds. Each entry takes an [`Avx2`] token (made only by runtime detection,
//! [`crate::simd`]): the generic sorting network is the portable code compiled with AVX2 enabled, the unrolled
//! networks run on AVX2 registers ([`U8x32`], [`U16x16`]: twice the lanes of SSE2 per instruction), and the gather
//! of 8-bit RGB blocks is written with intrinsics. Same results as the portable code (tested bit for bit in the
//! parent module and in `unrolled`).

use std::arch::x86_64::*;

use super::apply_network_portable;
use super::unrolled::{columns_of, NetworkSample, Vector};
use crate::simd::Avx2;

/// The parent's `apply_network` compiled with AVX2 enabled.
pub(super) fn apply_network<T: Copy + PartialOrd>(
    t: Avx2,
    net: &[(u16, u16)],
    v: &mut [T],
    lanes: usize,
) {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `apply_network_in` is compiled for.
    unsafe { apply_network_in(t, net, v, lanes) }
}

#[target_feature(enable = "avx2")]
fn apply_network_in<T: Copy + PartialOrd>(_t: Avx2, net: &[(u16, u16)], v: &mut [T], lanes: usize) {
    apply_network_portable(net, v, lanes)
}

/// `unrolled::columns_of` on AVX2 registers (`T::Wide`).
pub(super) fn columns<T: NetworkSample>(t: Avx2, v: &mut [T], kk: usize, lanes: usize) -> bool {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `columns_in` is compiled for.
    unsafe { columns_in::<T>(t, v, kk, lanes) }
}

#[target_feature(enable = "avx2")]
fn columns_in<T: NetworkSample>(_t: Avx2, v: &mut [T], kk: usize, lanes: usize) -> bool {
    columns_of::<T, T::Wide>(v, kk, lanes)
}

/// 32 8-bit lanes in an AVX2 register. Its operations are AVX2 instructions: values of it are made only in the
/// networks that `columns_in` runs, compiled for AVX2 and reached only through an [`Avx2`] token.
#[derive(Clone, Copy)]
pub(in crate::method::median) struct U8x32(__m256i);

/// 16 16-bit lanes in an AVX2 register, made and used as [`U8x32`] is.
#[derive(Clone, Copy)]
pub(in crate::method::median) struct U16x16(__m256i);

/// [`Vector`] for an AVX2 register type `$v` of `$w` lanes of `$t`, with `min`/`max` the intrinsics `$min`/`$max`.
macro_rules! avx2_vector {
    ($v:ident, $t:ty, $w:expr, $min:ident, $max:ident) => {
        impl Vector<$t> for $v {
            const W: usize = $w;
            #[inline(always)]
            fn load(v: &[$t]) -> Self {
                let v = &v[..$w];
                // SAFETY: `v` holds 32 bytes; the load needs no alignment; the CPU has AVX (see the type).
                $v(unsafe { _mm256_loadu_si256(v.as_ptr().cast()) })
            }
            #[inline(always)]
            fn store(self, out: &mut [$t]) {
                let out = &mut out[..$w];
                // SAFETY: `out` holds 32 bytes; the store needs no alignment; the CPU has AVX (see the type).
                unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), self.0) }
            }
            #[inline(always)]
            fn min(self, o: Self) -> Self {
                // SAFETY: the CPU has AVX2 (see the type).
                $v(unsafe { $min(self.0, o.0) })
            }
            #[inline(always)]
            fn max(self, o: Self) -> Self {
                // SAFETY: the CPU has AVX2 (see the type).
                $v(unsafe { $max(self.0, o.0) })
            }
        }
    };
}

avx2_vector!(U8x32, u8, 32, _mm256_min_epu8, _mm256_max_epu8);
avx2_vector!(U16x16, u16, 16, _mm256_min_epu16, _mm256_max_epu16);

/// The parent's `gather_rgb8_k8` eight blocks at a time: an 8×8 transpose of pixels held in 32-bit lanes.
pub(super) fn gather_rgb8_k8(t: Avx2, rows: &[&[u8]; 8], v: &mut [u8], lanes: usize, lane0: usize) {
    // SAFETY: `t` proves the CPU has AVX2, the one feature `gather_rgb8_k8_in` is compiled for.
    unsafe { gather_rgb8_k8_in(t, rows, v, lanes, lane0) }
}

#[target_feature(enable = "avx2")]
fn gather_rgb8_k8_in(_t: Avx2, rows: &[&[u8]; 8], v: &mut [u8], lanes: usize, lane0: usize) {
    debug_assert!(lane0.is_multiple_of(3) && lanes.is_multiple_of(3));
    let (bx0, nb) = (lane0 / 3, lanes / 3);
    // 3-byte pixels to 32-bit lanes (the fourth byte zero), within each 128-bit half: pixels 0–3 of a block
    // row from its bytes 0–11 in the low half, pixels 4–7 from bytes 12–23 in the high half.
    let widen = _mm256_setr_epi8(
        0, 1, 2, -1, 3, 4, 5, -1, 6, 7, 8, -1, 9, 10, 11, -1, 0, 1, 2, -1, 3, 4, 5, -1, 6, 7, 8,
        -1, 9, 10, 11, -1,
    );
    // And back: 12 bytes at the start of each half, then the two halves' 3 + 3 words made contiguous.
    let narrow = _mm256_setr_epi8(
        0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1, 0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13,
        14, -1, -1, -1, -1,
    );
    let join = _mm256_setr_epi32(0, 1, 2, 4, 5, 6, 3, 7);
    let mut g = 0;
    // A group of 8 blocks reads 28 bytes from its last block's row start (4 past it): stay inside the row.
    let row_len = rows[0].len();
    while g + 8 <= nb && (bx0 + g + 7) * 24 + 28 <= row_len {
        for (dy, row) in rows.iter().enumerate() {
            let mut r = [_mm256_setzero_si256(); 8];
            for (j, rj) in r.iter_mut().enumerate() {
                let src = &row[(bx0 + g + j) * 24..(bx0 + g + j) * 24 + 28];
                // SAFETY: `src` holds 28 bytes; the loads read bytes 0–15 and 12–27, unaligned.
                let (lo, hi) = unsafe {
                    (
                        _mm_loadu_si128(src.as_ptr() as *const __m128i),
                        _mm_loadu_si128(src.as_ptr().add(12) as *const __m128i),
                    )
                };
                *rj = _mm256_shuffle_epi8(_mm256_set_m128i(hi, lo), widen);
            }
            // t[dx] = pixel dx of blocks g..g+8.
            let t = transpose_8x8(&r);
            for (dx, &tx) in t.iter().enumerate() {
                let packed = _mm256_permutevar8x32_epi32(_mm256_shuffle_epi8(tx, narrow), join);
                let at = (dy * 8 + dx) * lanes + g * 3;
                let dst = &mut v[at..at + 24];
                let (lo, hi) = (
                    _mm256_castsi256_si128(packed),
                    _mm256_extracti128_si256::<1>(packed),
                );
                // SAFETY: `dst` holds 24 bytes; the stores write bytes 0–15 and 16–23, unaligned.
                unsafe {
                    _mm_storeu_si128(dst.as_mut_ptr() as *mut __m128i, lo);
                    _mm_storel_epi64(dst.as_mut_ptr().add(16) as *mut __m128i, hi);
                }
            }
        }
        g += 8;
    }
    if g < nb {
        // The blocks left over, into lanes g·3.. of every element row.
        let rest = rows.iter().copied();
        super::gather_blocks::<u8, 3, 4>(
            rest,
            &mut v[g * 3..],
            8,
            lanes,
            (nb - g) * 3,
            lane0 + g * 3,
        );
    }
}

/// The 8×8 transpose of 32-bit lanes: lane `j` of the result's row `i` is lane `i` of `r[j]`.
#[target_feature(enable = "avx2")]
#[inline]
fn transpose_8x8(r: &[__m256i; 8]) -> [__m256i; 8] {
    let a0 = _mm256_unpacklo_epi32(r[0], r[1]);
    let a1 = _mm256_unpackhi_epi32(r[0], r[1]);
    let a2 = _mm256_unpacklo_epi32(r[2], r[3]);
    let a3 = _mm256_unpackhi_epi32(r[2], r[3]);
    let a4 = _mm256_unpacklo_epi32(r[4], r[5]);
    let a5 = _mm256_unpackhi_epi32(r[4], r[5]);
    let a6 = _mm256_unpacklo_epi32(r[6], r[7]);
    let a7 = _mm256_unpackhi_epi32(r[6], r[7]);
    let b0 = _mm256_unpacklo_epi64(a0, a2);
    let b1 = _mm256_unpackhi_epi64(a0, a2);
    let b2 = _mm256_unpacklo_epi64(a1, a3);
    let b3 = _mm256_unpackhi_epi64(a1, a3);
    let b4 = _mm256_unpacklo_epi64(a4, a6);
    let b5 = _mm256_unpackhi_epi64(a4, a6);
    let b6 = _mm256_unpacklo_epi64(a5, a7);
    let b7 = _mm256_unpackhi_epi64(a5, a7);
    [
        _mm256_permute2x128_si256(b0, b4, 0x20),
        _mm256_permute2x128_si256(b1, b5, 0x20),
        _mm256_permute2x128_si256(b2, b6, 0x20),
        _mm256_permute2x128_si256(b3, b7, 0x20),
        _mm256_permute2x128_si256(b0, b4, 0x31),
        _mm256_permute2x128_si256(b1, b5, 0x31),
        _mm256_permute2x128_si256(b2, b6, 0x31),
        _mm256_permute2x128_si256(b3, b7, 0x31),
    ]
}

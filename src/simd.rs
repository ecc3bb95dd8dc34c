//! Instructions beyond the target's baseline (AVX2 on x86-64), and the one way to reach them: a token that only
//! runtime detection makes.
//!
//! The vector kernels live in files of their own, one per instruction set (`method/correct/avx2.rs`,
//! `method/median/avx2.rs`, `method/transfer/avx2.rs`). Each kernel those files offer takes an [`Avx2`] by value:
//! holding one is the proof that the CPU running the process has AVX2, so the kernel may call the functions it
//! compiled with `#[target_feature(enable = "avx2")]`. Callers ask [`Avx2::detect`] and take the portable code when
//! it says no. The vector kernels do the scalar code's operations in the same order (no fused multiply-add), so
//! both give the same bits (tested in each file's module).

/// Proof that the CPU running this process has AVX2 (and so AVX, SSE4.2 and below). Zero-sized, and made only by
/// [`Avx2::detect`].
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2(());

/// No AVX2 off x86-64: a type without values, so `Option<Avx2>` is always `None` and the portable code runs.
#[cfg(not(target_arch = "x86_64"))]
#[derive(Clone, Copy, Debug)]
pub(crate) enum Avx2 {}

#[cfg(not(target_arch = "x86_64"))]
impl Avx2 {
    /// Never: this is not an x86-64 CPU. (Its callers are x86-64 code and the tests.)
    #[inline]
    #[allow(dead_code)]
    pub(crate) fn detect() -> Option<Self> {
        None
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::Avx2;

    impl Avx2 {
        /// The token where the CPU has AVX2, else `None` (the answer is cached by the standard library: a load and
        /// a test after the first call).
        #[inline]
        pub(crate) fn detect() -> Option<Self> {
            std::arch::is_x86_feature_detected!("avx2").then_some(Avx2(()))
        }

        /// The first 8 values of `v` (panics on fewer), unaligned.
        #[inline(always)]
        pub(crate) fn load_ps(self, v: &[f32]) -> __m256 {
            let v = &v[..8];
            // SAFETY: `self` proves the CPU has AVX; `v` holds 8 floats; the load needs no alignment.
            unsafe { _mm256_loadu_ps(v.as_ptr()) }
        }

        /// `x` into the first 8 values of `out` (panics on fewer), unaligned.
        #[inline(always)]
        pub(crate) fn store_ps(self, out: &mut [f32], x: __m256) {
            let out = &mut out[..8];
            // SAFETY: `self` proves the CPU has AVX; `out` holds 8 floats; the store needs no alignment.
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), x) }
        }

        /// The first 8 values of `v` (panics on fewer), unaligned.
        #[inline(always)]
        pub(crate) fn load_epi32(self, v: &[i32]) -> __m256i {
            let v = &v[..8];
            // SAFETY: `self` proves the CPU has AVX; `v` holds 32 bytes; the load needs no alignment.
            unsafe { _mm256_loadu_si256(v.as_ptr().cast()) }
        }

        /// `x` as 8 `i32`.
        #[inline(always)]
        pub(crate) fn to_epi32(self, x: __m256i) -> [i32; 8] {
            let mut out = [0i32; 8];
            // SAFETY: `self` proves the CPU has AVX; `out` holds 32 bytes; the store needs no alignment.
            unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), x) };
            out
        }

        /// The first 8 values of `v` (panics on fewer), unaligned, as one 128-bit vector.
        #[inline(always)]
        pub(crate) fn load_epu16x8(self, v: &[u16]) -> __m128i {
            let v = &v[..8];
            // SAFETY: `self` proves the CPU has SSE2; `v` holds 16 bytes; the load needs no alignment.
            unsafe { _mm_loadu_si128(v.as_ptr().cast()) }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_token_follows_the_cpu() {
        #[cfg(target_arch = "x86_64")]
        assert_eq!(
            Avx2::detect().is_some(),
            std::arch::is_x86_feature_detected!("avx2")
        );
        #[cfg(not(target_arch = "x86_64"))]
        assert!(Avx2::detect().is_none());
        assert_eq!(std::mem::size_of::<Avx2>(), 0);
    }
}

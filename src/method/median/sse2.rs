//! The unrolled networks' registers on any x86-64 CPU: SSE2 is part of the x86-64 baseline, so these need no
//! detection. 8-bit lanes have SSE2's unsigned `min`/`max`; 16-bit lanes have them only from SSE4.1 on, so here
//! they come from the saturating subtraction (`a − (a ⊖ b)` is the smaller, `b + (a ⊖ b)` the larger).

use std::arch::x86_64::*;

use super::unrolled::Vector;

/// 16 8-bit lanes in an SSE2 register.
#[derive(Clone, Copy)]
pub(in crate::method::median) struct U8x16(__m128i);

/// 8 16-bit lanes in an SSE2 register.
#[derive(Clone, Copy)]
pub(in crate::method::median) struct U16x8(__m128i);

/// The loads and stores of an SSE2 register type `$v` of `$w` lanes of `$t`.
macro_rules! sse2_memory {
    ($v:ident, $t:ty, $w:expr) => {
        #[inline(always)]
        fn load(v: &[$t]) -> Self {
            let v = &v[..$w];
            // SAFETY: `v` holds 16 bytes; the load needs no alignment; SSE2 is in the x86-64 baseline.
            $v(unsafe { _mm_loadu_si128(v.as_ptr().cast()) })
        }
        #[inline(always)]
        fn store(self, out: &mut [$t]) {
            let out = &mut out[..$w];
            // SAFETY: `out` holds 16 bytes; the store needs no alignment; SSE2 is in the x86-64 baseline.
            unsafe { _mm_storeu_si128(out.as_mut_ptr().cast(), self.0) }
        }
    };
}

impl Vector<u8> for U8x16 {
    const W: usize = 16;
    sse2_memory!(U8x16, u8, 16);
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        // SAFETY: SSE2 is in the x86-64 baseline.
        U8x16(unsafe { _mm_min_epu8(self.0, o.0) })
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        // SAFETY: SSE2 is in the x86-64 baseline.
        U8x16(unsafe { _mm_max_epu8(self.0, o.0) })
    }
}

impl Vector<u16> for U16x8 {
    const W: usize = 8;
    sse2_memory!(U16x8, u16, 8);
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        // SAFETY: SSE2 is in the x86-64 baseline.
        U16x8(unsafe { _mm_sub_epi16(self.0, _mm_subs_epu16(self.0, o.0)) })
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        // SAFETY: SSE2 is in the x86-64 baseline.
        U16x8(unsafe { _mm_add_epi16(o.0, _mm_subs_epu16(self.0, o.0)) })
    }
}

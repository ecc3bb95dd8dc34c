//! The lit level of `F` (or of a window's `M − S`): its [`LIT_PERCENTILE`] per channel, what the floor
//! ([`crate::method::steps::floor`]) and the per-photo gain ([`crate::method::steps::gain`], and the levelling with it)
//! take their shares of.

use crate::method::median::quantile;
use crate::method::raster::Raster;

/// Percentile of `F` (per channel, over blocks) taken as the photo's lit level.
pub const LIT_PERCENTILE: f64 = 0.95;

/// Lit level of each channel of `f`: its [`LIT_PERCENTILE`] over the finite samples.
pub fn lit_level(f: &Raster) -> Vec<f32> {
    lit_level_every(&f.data, f.channels, 1)
}

/// [`lit_level`] of interleaved `data` with `c` channels, taken on every `stride`-th block.
pub(crate) fn lit_level_every(data: &[f32], c: usize, stride: usize) -> Vec<f32> {
    (0..c)
        .map(|ch| {
            let mut v: Vec<f32> = (ch..data.len())
                .step_by(c * stride)
                .map(|i| data[i])
                .filter(|x| x.is_finite())
                .collect();
            quantile(&mut v, LIT_PERCENTILE)
        })
        .collect()
}

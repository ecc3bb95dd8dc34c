//! The blend (`Steps::denoise`): dim regions blended towards their local level by their signal-to-noise ratio,
//! measured on each photo ([`crate::method::noise`]), instead of amplifying noise.

use crate::method::correct::NEGLIGIBLE_BLEND;
use crate::method::noise::{block_stats, Blended, NoiseModel};
use crate::method::raster::{Photo, Raster};
use crate::method::seen::Window;

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

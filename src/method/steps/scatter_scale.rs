//! The scale of `S` (`Steps::backscatter_scale`, `--backscatter-scale`): the water-column `S` scaled per channel for
//! the survey photos, given or estimated per window ([`backscatter_scale`]).

use crate::method::raster::Raster;
use crate::method::refine::backscatter_scale;
use crate::method::steps::Window;

/// The scale of `S` per channel for the window's `m` (1 without `S`).
pub(crate) fn of(w: &Window, m: &Raster) -> Vec<f32> {
    match (w.params.steps.backscatter_scale, w.s_low) {
        (Some(v), Some(_)) => vec![v; m.channels],
        (None, Some(s)) => backscatter_scale(&w.stack(), m, s),
        _ => vec![1.0; m.channels],
    }
}

//! The per-photo gain (`Steps::photo_gain`): one robust gain per photo and channel against its window's `M`, at the
//! window's quantile where the survey chose it (the median elsewhere: docs/nodules.md).

use crate::method::raster::Raster;
use crate::method::refine::{apply_gain, photo_gain, GAIN_MIN_LIT};
use crate::method::steps::Window;

/// `f` times the photo's gain against `m` (`s`: the `S` in effect), where the step is on.
pub(crate) fn apply(w: &Window, f: &mut Raster, m: &Raster, s: Option<&Raster>) {
    if w.params.steps.photo_gain {
        // The engine gives the median unless the window is chosen per stretch: the window's quantile here wins on
        // dense nodule fields but moved the twelve dives of the matrix by up to 8 % either way (docs/nodules.md).
        let g = photo_gain(&w.own.low, m, s, GAIN_MIN_LIT, w.gain_quantile);
        apply_gain(f, &g);
    }
}

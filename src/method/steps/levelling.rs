//! Exposure levelling (`Steps::level_exposures`): where the exposure jumps from photo to photo within the window, its
//! photos levelled to one exposure, each by its gain against the window's `M`, before `M` is taken again; the
//! quantile otherwise takes the middle-exposure photo's scene whole (ghosts). A window shorter than
//! [`LEVEL_MIN_WINDOW`] is left alone, and a near window is levelled only with its window (docs/method.md).

use crate::method::raster::Raster;
use crate::method::refine::levelled_stack;
pub(crate) use crate::method::refine::LEVEL_MIN_WINDOW;
use crate::method::steps::quantile;

/// `m`, the `q` quantile of `stack`, taken again over the photos levelled to one exposure where `on` (the step is
/// on and the window may be levelled) and its exposure jumps ([`levelled_stack`]); and whether it was.
pub(crate) fn level(
    stack: &[&Raster],
    m: Raster,
    s_low: Option<&Raster>,
    q: f32,
    on: bool,
) -> (Raster, bool) {
    if !on {
        return (m, false);
    }
    match levelled_stack(stack, &m, s_low, q as f64) {
        Some(levelled) => (quantile::of(&levelled.iter().collect::<Vec<_>>(), q), true),
        None => (m, false),
    }
}

//! The floor of `F` (`Steps::relative_floor`, `--relative-floor`): a share of the photo's lit level, with a smooth
//! hand-over ([`soft_floor`]), so that dark corners are not amplified without bound.

use crate::method::raster::Raster;
use crate::method::refine::soft_floor;
use crate::method::steps::Window;

/// `f` floored softly at the step's share of its lit level.
pub(crate) fn apply(w: &Window, f: &mut Raster) {
    soft_floor(f, w.params.steps.relative_floor);
}

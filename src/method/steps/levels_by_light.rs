//! The levels by light (`Steps::level_by_light`): the blend's block levels evened out across light levels
//! ([`level_by_light`]; by bins' trimmed means on dense fields), so dim regions are not left darker than lit ones.

use crate::method::noise::{level_by_light, Blended};
use crate::method::raster::Raster;
use crate::method::seen::Window;

/// The blend's levels evened out by light, where the step is on and there is a blend.
pub(crate) fn even(w: &Window, blended: Option<&mut Blended>, f: &Raster) {
    if let (Some(b), true) = (blended, w.params.steps.level_by_light) {
        level_by_light(&mut b.level, f, w.colour, w.masked_blocks, w.dense());
    }
}

//! The near window (`Steps::near_window`): the window's `M` bent to the smooth shape of the `M` of a shorter window
//! around the same photo ([`near_shape`]), so `F` follows the lights as the vehicle's altitude and roll change.

use crate::method::raster::Raster;
use crate::method::refine::near_shape;
use crate::method::steps::{bright_spots, levelling, quantile, Window};
use crate::method::window::near_range;

/// `m` bent to the near window's shape, when the near window is on and shorter than the photo's window. The near
/// window is levelled where its own exposure jumps only when the window was (`levelled`): the ghosts levelling keeps
/// out are a photo's scene, which the window's `M` gives and the smooth shape leaves out, while a window whose near
/// window alone sees a jump is one where the light's swing turns, which the shape is there to follow
/// (docs/method.md).
pub(crate) fn shape(w: &Window, m: Raster, levelled: bool) -> Raster {
    let Some(near) = w.near.filter(|&k| k < w.members.len()) else {
        return m;
    };
    // The photos of the window nearest to the photo in time (in a window chosen by altitude, the nearest of those).
    let own = w.members.iter().position(|&j| j == w.i).unwrap_or(0);
    let seen = &w.seen[near_range(own, near, &(0..w.members.len()))];
    let stack: Vec<&Raster> = seen.iter().map(|e| &e.low).collect();
    let steps = &w.params.steps;
    let m_near = quantile::of(&stack, w.quantile);
    let (m_near, _) = levelling::level(
        &stack,
        m_near,
        w.s_low,
        w.quantile,
        steps.level_exposures && levelled,
    );
    let m_near = bright_spots::fill(m_near, seen, steps.bright_spots);
    near_shape(&m, &m_near, w.s_low)
}

//! Bright spots that move (`Steps::bright_spots`, `--bright-spots`): laser dots and highlights that held more than
//! half of the window at a block, filled from the blocks around them as under a mask ([`crate::method::outliers`]).

use crate::method::mask::fill_missing;
use crate::method::outliers::bright_spots;
use crate::method::raster::Raster;
use crate::method::seen::Seen;

/// The per-photo half, as each photo comes: its blocks of bright spots that move (laser dots, highlights), when the
/// step is `on` and it has any.
pub(crate) fn spots(low: &Raster, on: bool) -> Option<Vec<bool>> {
    on.then(|| bright_spots(low)).filter(|s| !s.is_empty())
}

/// `m` (the `M` of the photos `seen`) with the blocks where bright spots held more than half of them filled from the
/// blocks around them. Elsewhere `m` stands: the quantile outvoted the spots. (Two ways that also changed the blocks
/// where spots were fewer were measured and dropped: leaving them out of the quantile's count moved the `(1 + c)/2`
/// quantile down wherever the simulator's bright particles were frequent, and ranking them above every value moved
/// it up; both raised the residual pattern of high-contamination matrix dives, a09 by 1.15–1.75×:
/// docs/evaluation.md, "Bright spots that move".)
pub(crate) fn fill(mut m: Raster, seen: &[&Seen], on: bool) -> Raster {
    if !on || seen.iter().all(|e| e.spots.is_none()) {
        return m;
    }
    let (n, c) = (seen.len(), m.channels);
    let mut holes = false;
    // Counted once per block: a block's samples are NaN in every channel or in none (a mask leaves a block without
    // pixels in all of them).
    for (b, px) in m.data.chunks_exact_mut(c).enumerate() {
        let out = seen
            .iter()
            .filter(|e| e.spots.as_ref().is_some_and(|s| s[b]) && !e.low.data[b * c].is_nan())
            .count();
        if 2 * out > n {
            px.fill(f32::NAN);
            holes = true;
        }
    }
    if holes {
        fill_missing(&mut m);
    }
    m
}

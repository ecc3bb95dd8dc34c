//! Overlaps (`Steps::overlaps`, `--overlaps`): `M − S` bent to the `F` that the window's overlapping photos give
//! ([`crate::method::overlap`]), with the window's `M` as the prior for what they leave undetermined.

use crate::method::matching::{match_pair, reduction, texture, Texture};
use crate::method::overlap::{chained_pairs, overlap_correction};
use crate::method::raster::Raster;
use crate::method::seen::Window;

/// The per-photo half, as each photo comes: its block medians registered against the photo before's.
#[derive(Debug, Clone, Default)]
pub(crate) struct Registration {
    /// The texture of the last photo's block medians, to match the next one against.
    previous: Option<Texture>,
}

impl Registration {
    /// Where the step is `on`: the shift of the ground from the last photo to this one, in blocks, by phase
    /// correlation of the block medians' textures (`None`: no match, or the step is off).
    pub(crate) fn step(&mut self, low: &Raster, on: bool) -> Option<(f64, f64)> {
        if !on {
            return None;
        }
        let t = texture(low, reduction(low.width, low.height));
        let m = self.previous.as_ref().map(|p| match_pair(p, &t));
        self.previous = Some(t);
        m.filter(|m| m.accepted).map(|m| m.shift)
    }

    /// Start again from the next photo (the photos held are seen again, in order).
    pub(crate) fn restart(&mut self) {
        self.previous = None;
    }
}

/// `m` bent to the overlaps' `F` where the step is on and the window's photos were registered.
pub(crate) fn shape(w: &Window, mut m: Raster) -> Raster {
    if !w.params.steps.overlaps {
        return m;
    }
    let steps: Vec<Option<(f64, f64)>> = w
        .seen
        .iter()
        .enumerate()
        .map(|(j, e)| e.step.filter(|_| j > 0))
        .collect();
    let pairs = chained_pairs(&steps, m.width, m.height);
    let lit: Vec<Raster> = w
        .seen
        .iter()
        .map(|e| less_scatter(&e.low, w.s_low))
        .collect();
    let refs: Vec<&Raster> = lit.iter().collect();
    let prior = less_scatter(&m, w.s_low);
    // The overlaps' gains (`Overlaps::gains`) are not used: the per-photo gain stays the median's (taking theirs
    // instead measured worse on the nodule dives: docs/overlaps.md).
    let Some(overlaps) = overlap_correction(&refs, &pairs, &prior) else {
        return m;
    };
    for ((v, p), d) in m.data.iter_mut().zip(&prior.data).zip(&overlaps.delta.data) {
        if *p > 0.0 {
            *v += p * (d.exp() - 1.0);
        }
    }
    m
}

/// `r − S` (`r` itself without `S`).
fn less_scatter(r: &Raster, s: Option<&Raster>) -> Raster {
    let mut out = r.clone();
    if let Some(s) = s {
        for (v, s) in out.data.iter_mut().zip(&s.data) {
            *v -= s;
        }
    }
    out
}

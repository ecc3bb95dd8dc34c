//! What the [`Engine`](crate::method::engine::Engine) keeps of the photos it has seen ([`Seen`]), and one photo's
//! window of them as the recipes of [`crate::method::chain`] and their steps ([`crate::method::steps`]) read it
//! ([`Window`]).

use crate::method::factor::factor_filled;
use crate::method::params::Params;
use crate::method::raster::Raster;
use crate::method::transfer::Curve;

/// What the engine keeps of a photo it has seen, for the windows of the photos around it.
pub(crate) struct Seen {
    /// Its block medians, in linear light.
    pub low: Raster,
    /// The same pooled for the monitor (when the blocks are smaller than 8 pixels).
    pub judged: Option<Raster>,
    /// With `--bright-spots`, when it had any: its blocks of bright spots ([`crate::method::outliers`]).
    pub spots: Option<Vec<bool>>,
    /// With `steps.overlaps`: the shift of the ground from the photo before, in blocks (`None`: no match).
    pub step: Option<(f64, f64)>,
    /// The photo's altitude, where known ([`crate::method::altitude`]).
    pub altitude: Option<f32>,
}

/// One photo's window, as the steps read it.
pub(crate) struct Window<'a> {
    /// The photo's number in the mission.
    pub i: usize,
    /// The photos of its window, in order (contiguous unless chosen by altitude: [`crate::method::altitude`]).
    pub members: &'a [usize],
    /// What the engine kept of them, in order.
    pub seen: Vec<&'a Seen>,
    /// The photo's own.
    pub own: &'a Seen,
    /// `S` at block resolution, linear light.
    pub s_low: Option<&'a Raster>,
    /// `C`, linear light, per channel.
    pub colour: &'a [f32],
    /// The method's parameters (resolved).
    pub params: &'a Params,
    /// The quantile the window's `M` takes.
    pub quantile: f32,
    /// The near window (`None`: off).
    pub near: Option<usize>,
    /// The quantile of the per-photo gain (the window's, where the survey chose it; else the median).
    pub gain_quantile: f64,
    /// A mask left blocks without samples (filled in `F`).
    pub masked: bool,
    /// One flag per block: near a masked pixel (no blend there).
    pub masked_blocks: Option<&'a [bool]>,
    /// `M` of [`Method::Mean`](crate::method::baseline::Method::Mean).
    pub mission_mean: Option<&'a Raster>,
    /// The transfer tables of 8- and 16-bit photos.
    pub curves: (&'a Curve, &'a Curve),
}

impl Window<'_> {
    /// The block images of the window's photos, in order.
    pub fn stack(&self) -> Vec<&Raster> {
        self.seen.iter().map(|e| &e.low).collect()
    }

    /// The window was chosen for a dense field (its quantile above the median).
    pub fn dense(&self) -> bool {
        self.gain_quantile > 0.5
    }

    /// `F = (M − S)/C`, with the blocks a mask left without samples filled from their neighbours.
    pub fn factor(&self, m: &Raster, s: Option<&Raster>) -> Raster {
        factor_filled(m, s, self.colour, self.masked)
    }
}

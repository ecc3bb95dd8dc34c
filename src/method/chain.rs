//! The estimate of one photo's `F` from its window, as a chain of steps in the order they run: the paper's
//! ([`paper`]), the baselines it compares with ([`baseline`]) and the default's ([`abyss`], whose steps are in
//! [`crate::method::steps`], one file each). The [`Engine`](crate::method::engine::Engine) keeps the stream (the
//! ring of block images, the photos waiting, the survey) and gives each photo's [`Window`] to one of them.

use crate::method::baseline::{polynomial_m, Method};
use crate::method::factor::factor_filled;
use crate::method::median::stack_median;
use crate::method::noise::{Blended, NoiseModel};
use crate::method::params::Params;
use crate::method::raster::{Photo, Raster};
use crate::method::refine::scaled;
use crate::method::steps::levelling::LEVEL_MIN_WINDOW;
use crate::method::steps::{
    blend, bright_spots, floor, gain, levelling, levels_by_light, near_window, overlaps, quantile,
    scatter_scale,
};
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
    /// `M` of [`Method::Mean`].
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

/// What corrects one photo: its window's `M` and `F`, and how `F` is applied.
pub(crate) struct Estimate {
    /// The window's `M` (before the steps that bend it: what the monitor judges).
    pub window_m: Raster,
    /// `F` at block resolution.
    pub f: Raster,
    /// The smallest `F` a pixel is divided by.
    pub floor: f32,
    /// The scale of `S` per channel (empty: none).
    pub scale: Vec<f32>,
    /// The noise and texture measured on the photo.
    pub noise: Option<NoiseModel>,
    /// The blend of dim regions.
    pub blended: Option<Blended>,
    /// Correct with the blend and the scale of `S` (else the plain `(I − S)/F`).
    pub use_blend: bool,
}

impl Estimate {
    /// `F` of `m` applied plainly with the absolute floor (the paper and the baselines).
    fn plain(w: &Window, m: Raster) -> Self {
        Estimate {
            f: w.factor(&m, w.s_low),
            window_m: m,
            floor: w.params.factor_floor,
            scale: Vec::new(),
            noise: None,
            blended: None,
            use_blend: false,
        }
    }
}

/// The paper's estimate (Köser et al.): `M`, the per-block median over the window's photos, and `F = (M − S)/C`.
pub(crate) fn paper(w: &Window) -> Estimate {
    let m = stack_median(&w.stack());
    Estimate::plain(w, m)
}

/// The baselines the paper compares with: `M` the mission's mean image ([`Method::Mean`]; the window's median
/// while none is known) or the photo's own polynomial fit ([`Method::Polynomial`]).
pub(crate) fn baseline(w: &Window) -> Estimate {
    let m = window_m(
        w.params,
        &w.own.low,
        &w.stack(),
        w.s_low,
        w.mission_mean,
        w.quantile,
    );
    Estimate::plain(w, m)
}

/// The default's estimate ([`Method::Abyss`]): the paper's, with the steps it adds in the order they run
/// (docs/method.md, one section each).
pub(crate) fn abyss(w: &Window, photo: Option<&Photo>) -> Estimate {
    let steps = &w.params.steps;
    let stack = w.stack();
    let may_level = steps.level_exposures && stack.len() >= LEVEL_MIN_WINDOW;
    let m = quantile::of(&stack, w.quantile);
    let (m, levelled) = levelling::level(&stack, m, w.s_low, w.quantile, may_level);
    let window_m = bright_spots::fill(m, &w.seen, steps.bright_spots);
    let m = near_window::shape(w, window_m.clone(), levelled);
    let m = overlaps::shape(w, m);
    let scale = scatter_scale::of(w, &m);
    let s_k = w.s_low.map(|s| scaled(s, &scale));
    let rescaled = scale.iter().any(|&v| v != 1.0);
    let mut f = w.factor(&m, if rescaled { s_k.as_ref() } else { w.s_low });
    gain::apply(w, &mut f, &m, s_k.as_ref());
    floor::apply(w, &mut f);
    let noise = blend::noise(w, photo, &f);
    let mut blended = blend::fields(w, noise.as_ref(), &f, s_k.as_ref());
    levels_by_light::even(w, blended.as_mut(), &f);
    Estimate {
        window_m,
        use_blend: blended.is_some() || rescaled,
        f,
        // The soft floor is in `F`: the kernel's floor only guards against 0.
        floor: 1e-6,
        scale,
        noise,
        blended,
    }
}

/// The window's `M` of the photo whose block images are `own` and `stack`, as [`abyss`], [`paper`] and
/// [`baseline`] take it before bending it (the `M` the monitor judges), for block images other than the engine's
/// own (the monitor's pooled ones): no bright spots are known there.
pub(crate) fn window_m(
    params: &Params,
    own: &Raster,
    stack: &[&Raster],
    s_low: Option<&Raster>,
    mission_mean: Option<&Raster>,
    q: f32,
) -> Raster {
    match (params.method, mission_mean) {
        (Method::Mean, Some(mean)) if mean.layout() == own.layout() => mean.clone(),
        (Method::Polynomial, _) => polynomial_m(own, s_low, params.degree),
        (Method::Abyss, _) => {
            let may_level = params.steps.level_exposures && stack.len() >= LEVEL_MIN_WINDOW;
            let m = quantile::of(stack, q);
            levelling::level(stack, m, s_low, q, may_level).0
        }
        _ => stack_median(stack),
    }
}

/// The monitor's `F` and `F·C` of the photo of `w` from its window's block images pooled to about 8 pixels (the
/// monitor's thresholds were set there; [`Seen::judged`]), with `S` and the mission's mean pooled alike (`fixed`);
/// `None` where the blocks are not pooled.
pub(crate) fn pooled(
    w: &Window,
    fixed: &(Option<Raster>, Option<Raster>),
) -> Option<(Raster, Raster)> {
    let own = w.own.judged.as_ref()?;
    let stack: Vec<&Raster> = w.seen.iter().filter_map(|e| e.judged.as_ref()).collect();
    let (s, mean) = (fixed.0.as_ref(), fixed.1.as_ref());
    let m = window_m(w.params, own, &stack, s, mean, w.quantile);
    let f = factor_filled(&m, s, w.colour, w.masked);
    let lit = crate::method::factor::lit_seafloor(&f, w.colour);
    Some((f, lit))
}

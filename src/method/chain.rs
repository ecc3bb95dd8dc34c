//! The estimate of one photo's `F` from its window, as a chain of steps in the order they run: the paper's
//! ([`paper`]), the baselines it compares with ([`baseline`]) and the default's ([`abyss`], whose steps are in
//! [`crate::method::steps`], one file each). The [`Engine`](crate::method::engine::Engine) keeps the stream (the
//! ring of block images, the photos waiting, the survey) and gives each photo's [`Window`] to one of them; each
//! gives the photo's [`Estimate`].

use crate::method::baseline::{polynomial_m, Method};
use crate::method::estimate::Estimate;
use crate::method::factor::factor_filled;
use crate::method::median::stack_median;
use crate::method::params::Params;
use crate::method::raster::{Photo, Raster};
use crate::method::seen::Window;
use crate::method::steps::levelling::LEVEL_MIN_WINDOW;
use crate::method::steps::{
    blend, bright_spots, floor, gain, levelling, levels_by_light, near_window, overlaps, quantile,
    scatter_scale,
};

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
    let s_k = w.s_low.map(|s| scatter_scale::scaled(s, &scale));
    let rescaled = scale.iter().any(|&v| v != 1.0);
    let mut f = w.factor(&m, if rescaled { s_k.as_ref() } else { w.s_low });
    gain::apply(w, &mut f, &m, s_k.as_ref());
    floor::apply(w, &mut f);
    let noise = blend::noise(w, photo, &f);
    let mut blended = blend::fields(w, noise.as_ref(), &f, s_k.as_ref());
    levels_by_light::even(w, blended.as_mut(), &f);
    blend::fade_unlit(blended.as_mut(), &w.own.low, s_k.as_ref(), &f);
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
/// monitor's thresholds were set there; [`crate::method::seen::Seen::judged`]), with `S` and the mission's mean pooled alike (`fixed`);
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

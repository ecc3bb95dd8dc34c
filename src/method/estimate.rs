//! What corrects one photo ([`Estimate`]): its window's `M` and `F` and how `F` is applied, as a recipe of
//! [`crate::method::chain`] gives it to the [`Engine`](crate::method::engine::Engine).

use crate::method::raster::Raster;
use crate::method::seen::Window;
use crate::method::steps::blend::{Blended, NoiseModel};

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
    pub fn plain(w: &Window, m: Raster) -> Self {
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

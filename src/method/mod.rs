//! The method of Köser et al. on photos in memory: no files, no threads visible to the caller.
//!
//! A pixel sees `I = A·F + S`. The modules follow the paper:
//!
//! - [`scatter`]: `S`, the temporal median of water-column frames;
//! - [`median`]: the spatial (block) and temporal median kernels;
//! - [`window`]: the sliding window and its size `n` from the contamination rate;
//! - [`factor`]: `F = (M − S) / C` and its upsampling;
//! - [`correct`]: `A = (I − S) / F`;
//! - [`engine`]: all of it over a stream of photos, in order, with memory bounded by the window;
//! - [`params`]: the method's parameters;
//! - [`mask`]: static regions (overlays, vehicle parts) left out of the medians;
//! - [`outliers`]: bright spots that move (laser dots, highlights), and `M` where they held the window;
//! - [`survey`] and [`stretch`]: the first pass, the window per stretch of the mission, from its dark share and the
//!   camera's motion;
//! - [`overlap`]: `F` from the ratios of overlapping photos, where the window's `M` holds the scene;
//! - [`monitor`]: health figures that say where the method's assumptions fail;
//! - [`baseline`]: the methods the paper compares with (mission mean, log-polynomial);
//! - [`raster`] and [`transfer`]: photos, low-resolution images and camera curves.
//!
//! Nothing here reads or writes files; [`crate::io`] does, and [`crate::run`] streams whole missions.

pub mod altitude;
pub mod baseline;
pub(crate) mod blocks;
pub(crate) mod chain;
pub mod correct;
pub mod engine;
pub(crate) mod estimate;
pub mod factor;
pub mod mask;
pub mod matching;
pub mod median;
pub mod members;
pub mod monitor;
pub mod outliers;
pub mod overlap;
pub mod params;
pub mod raster;
pub(crate) mod ring;
pub(crate) mod running;
pub mod scatter;
pub(crate) mod seen;
pub(crate) mod steps;
pub mod stretch;
pub mod survey;
pub mod transfer;
pub mod window;

/// Marsaglia's xorshift32 from `seed` (not 0): deterministic pseudo-random numbers for the unit tests.
#[cfg(test)]
pub(crate) fn xorshift32(seed: u32) -> impl FnMut() -> u32 {
    let mut r = seed;
    move || {
        r ^= r << 13;
        r ^= r >> 17;
        r ^= r << 5;
        r
    }
}

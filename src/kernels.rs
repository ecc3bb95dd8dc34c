//! The method's kernels, for callers who want one step alone rather than the [`Engine`](crate::Engine) or a mission.
//!
//! Every kernel here is what the engine runs; each is tested against an independent computation (a brute-force
//! median, the exact binomial sum, the sRGB curve on every code boundary). In the order of the method:
//!
//! - medians: [`block_median`] (the photo shrunk by `k` with a spatial median per block), [`stack_median`] and
//!   [`stack_quantile`] (per pixel over a window of block images: `M`);
//! - the factor image: [`factor`] (`F = (M − S) / C`), [`auto_block`] (the block size `auto` takes), [`upsample`]
//!   (`F` back to full resolution, bilinear from the block centres);
//! - the window: [`p_half`](crate::p_half) and [`choose_window`](crate::choose_window) at the crate's root,
//!   [`near_window`] (the shorter window beside an exposure step);
//! - the correction: [`correct_in_place`] (`A = (I − S) / F` on the photo's samples) and [`correct_with_offset`]
//!   (the same with a scaled `S` and the noise-aware [`Blend`]), with their [`CorrectStats`]; [`Prepared`] is the
//!   water-column `S` at a photo's resolution, [`Curve`] a transfer curve's tables, [`Blended`] the blend's fields.

pub use crate::method::correct::{correct_in_place, correct_with_offset, Blend, CorrectStats};
pub use crate::method::factor::{auto_block, factor, upsample};
pub use crate::method::median::{block_median, stack_median, stack_quantile};
pub use crate::method::scatter::Prepared;
pub use crate::method::steps::blend::Blended;
pub use crate::method::transfer::Curve;
pub use crate::method::window::near_window;

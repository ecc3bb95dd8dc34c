//! The window's `M`: the `q` quantile over its photos' block images, per block (the median at 0.5; `(1 + c)/2` on
//! dense fields, where dark clutter covers a share `c`: that is the seafloor's own median).

use crate::method::median::{stack_median, stack_quantile};
use crate::method::raster::Raster;

/// The `q` quantile of `stack`, per sample (the median at `q = 0.5`).
pub(crate) fn of(stack: &[&Raster], q: f32) -> Raster {
    if q != 0.5 {
        stack_quantile(stack, q as f64)
    } else {
        stack_median(stack)
    }
}

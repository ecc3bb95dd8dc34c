//! Evaluation: a renderer of dives with known ground truth, the scores, the demo and the speed bench.

pub(crate) mod bench;
pub(crate) mod demo;
pub mod evaluate;
/// The dive matrix: the simulated dives the project scores itself on (`examples/dive_matrix.rs`, the quality
/// tests). A harness of the project's own, public for the example and the tests, not part of the API.
#[doc(hidden)]
pub mod matrix;
pub(crate) mod register;
pub mod simulate;

// Helpers of the project's own examples, tests, benches and Python binding: public for them, not part of the
// documented interface.
#[doc(hidden)]
pub use crate::run::pictures::{before_after_sheet, save_png};

#[doc(hidden)]
/// `value` within `lo..=hi` (and not NaN), or a usage error naming `flag`: the range checks of the subcommands'
/// numeric flags (`simulate`, `evaluate`, ...), the same for the command and the Python binding.
pub fn within<T: PartialOrd + std::fmt::Display + Copy>(
    flag: &str,
    value: T,
    lo: T,
    hi: T,
) -> crate::Result<()> {
    // `!(a <= b)` is true for NaN, unlike `a > b`.
    if !(lo <= value && value <= hi) {
        return Err(crate::Error::Usage(format!(
            "{flag} must be within {lo}..={hi}, got {value}"
        )));
    }
    Ok(())
}
#[doc(hidden)]
pub use bench::{machine, noisy_photo, synthetic_photo};

//! Range checks of the numeric flags of the subcommands other than `correct` (whose options are checked by
//! `Options::validate`): a value outside its range is a usage error naming the flag, before anything is read or
//! written.

use abysslight::Error;

/// `value` within `lo..=hi` (and not NaN), or a usage error naming `flag`.
pub fn within<T: PartialOrd + std::fmt::Display + Copy>(
    flag: &str,
    value: T,
    lo: T,
    hi: T,
) -> Result<(), Error> {
    // `!(a <= b)` is true for NaN, unlike `a > b`.
    if !(lo <= value && value <= hi) {
        return Err(Error::Usage(format!(
            "{flag} must be within {lo}..={hi}, got {value}"
        )));
    }
    Ok(())
}

/// Largest photo side the simulator, the bench and the sheet make (pixels).
pub const SIDE: usize = 16384;

/// `simulate`: sizes, counts and the physical parameters of the dive.
#[allow(clippy::too_many_arguments)]
pub fn simulate(
    frames: usize,
    water_column: usize,
    size: (usize, usize),
    contamination: f64,
    floats: &[(&str, f32, f32, f32)],
    white_balance: [f32; 3],
) -> Result<(), Error> {
    within("--frames", frames, 1, 1_000_000)?;
    within("--water-column", water_column, 1, 1_000_000)?;
    within("--size (width)", size.0, 8, SIDE)?;
    within("--size (height)", size.1, 8, SIDE)?;
    within("--contamination", contamination, 0.0, 1.0)?;
    for &(flag, v, lo, hi) in floats {
        within(flag, v, lo, hi)?;
    }
    for g in white_balance {
        within("--white-balance", g, 0.01, 100.0)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_and_out_of_range_values_are_refused() {
        assert!(within("--noise", f32::NAN, 0.0, 100.0).is_err());
        assert!(within("--noise", f32::INFINITY, 0.0, 100.0).is_err());
        assert!(within("--noise", -0.1, 0.0, 100.0).is_err());
        assert!(within("--noise", 0.0, 0.0, 100.0).is_ok());
        let e = within("--width", 0u32, 16, 8192).unwrap_err().to_string();
        assert!(e.contains("--width") && e.contains("16..=8192"), "{e}");
    }
}

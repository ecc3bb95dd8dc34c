//! Range checks of the numeric flags of the subcommands other than `correct` (whose options are checked by
//! `Options::validate`): a value outside its range is a usage error naming the flag, before anything is read or
//! written.

pub use abysslight::eval::within;

/// Largest photo side the simulator, the bench and the sheet make (pixels).
pub const SIDE: usize = abysslight::eval::simulate::MAX_SIDE;

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

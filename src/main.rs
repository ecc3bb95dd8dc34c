//! The `abysslight` command: parses arguments, turns them into library options and calls the library
//! ([`abysslight::cli`], also run by the Python package's `abysslight` command).

use std::process::ExitCode;

fn main() -> ExitCode {
    abysslight::cli::run()
}

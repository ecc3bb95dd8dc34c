//! The `abysslight` command: parses arguments, turns them into library options and calls the library.

mod cli;
mod cli_extras;

use std::process::ExitCode;

fn main() -> ExitCode {
    cli::run()
}

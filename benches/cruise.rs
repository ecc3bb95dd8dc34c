//! `cargo bench --bench cruise`: the same benchmark as `abysslight bench` with its defaults (12 MP JPEG mission of
//! 20 and 200 photos, 2 threads). Set ABYSSLIGHT_BENCH_ARGS="--photos 4 --size 1000x750" for a quick run: the
//! arguments are those of `abysslight bench`, passed to the binary.

use std::process::{Command, ExitCode};

fn main() -> ExitCode {
    let exe = env!("CARGO_BIN_EXE_abysslight");
    let extra = std::env::var("ABYSSLIGHT_BENCH_ARGS").unwrap_or_default();
    let status = Command::new(exe)
        .arg("bench")
        .args(extra.split_whitespace())
        .status();
    match status {
        Ok(s) if s.success() => ExitCode::SUCCESS,
        Ok(_) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("cannot run {exe}: {e}");
            ExitCode::FAILURE
        }
    }
}

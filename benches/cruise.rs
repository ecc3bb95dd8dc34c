//! `cargo bench --bench cruise`: the same benchmark as `abysslight bench` with its defaults (a noisy dive of 60
//! camera-like 12 MP JPEGs and 9 water-column frames, 2 threads, against the libjpeg-turbo floor measured through
//! OpenCV in the same run). Set ABYSSLIGHT_BENCH_ARGS="--photos 4 --size 1000x750" for a quick run, or
//! "--python /path/to/venv/bin/python --peer /path/to/peer.py": the arguments are those of `abysslight bench`,
//! passed to the binary.

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

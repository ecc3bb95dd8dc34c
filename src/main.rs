//! The `abysslight` command: parses arguments, turns them into library options and calls the library.

// Console output that never panics: a closed stdout or stderr (`abysslight ... 2>&1 | head`) must not end a
// mission; what cannot be printed is dropped (the run report still holds it). These shadow the std macros in
// the command's modules.
macro_rules! eprintln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}
macro_rules! println {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}
macro_rules! print {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout(), $($t)*);
    }};
}

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    cli::run()
}

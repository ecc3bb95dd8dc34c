//! What the CLI adds around a run for the people at the console: shell completions and the man page (from the
//! same clap definition as `--help`), the note before a re-run into a used folder, the hint after Ctrl-C.

use std::path::Path;
use std::process::ExitCode;

use abysslight::Error;

/// Print the completion script for `shell` to stdout.
pub fn completions(shell: clap_complete::Shell, cmd: &mut clap::Command) {
    // Into a buffer first: a closed stdout (`| head`) ends the command quietly instead of a panic.
    let mut buf = Vec::new();
    clap_complete::generate(shell, cmd, "abysslight", &mut buf);
    let _ = std::io::Write::write_all(&mut std::io::stdout(), &buf);
}

/// Print the man page (roff) of the whole tool, or of one subcommand, to stdout.
pub fn manpage(cmd: clap::Command, sub: Option<&str>) -> Result<ExitCode, Error> {
    let mut cmd = cmd;
    cmd.build();
    let page = match sub {
        None => cmd,
        Some(name) => {
            let found = cmd.find_subcommand(name).cloned().ok_or_else(|| {
                Error::Usage(format!(
                    "manpage: no command {name:?} (one of: {})",
                    cmd.get_subcommands()
                        .map(|c| c.get_name().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })?;
            // The page's title: abysslight-correct(1), as git and cargo name theirs. Leaked: a one-shot command,
            // and clap takes a &'static str without its `string` feature.
            let title: &'static str = Box::leak(format!("abysslight-{name}").into_boxed_str());
            found.name(title)
        }
    };
    let mut out = Vec::new();
    clap_mangen::Man::new(page)
        .render(&mut out)
        .map_err(|e| Error::Usage(format!("cannot render the man page: {e}")))?;
    use std::io::Write;
    std::io::stdout()
        .write_all(&out)
        .map_err(|e| Error::Usage(format!("cannot write the man page: {e}")))?;
    Ok(ExitCode::SUCCESS)
}

/// One line before a batch run into an output folder that already holds files: what will happen to them.
pub fn note_non_empty_out(out: &Path, resume: bool) {
    if let Some(line) = non_empty_out_note(out, resume) {
        eprintln!("abysslight: note: {line}");
    }
}

fn non_empty_out_note(out: &Path, resume: bool) -> Option<String> {
    std::fs::read_dir(out).ok()?.next()?.ok()?;
    Some(if resume {
        format!(
            "{} already holds files: --resume keeps the photos whose output is complete and corrects the rest",
            out.display()
        )
    } else {
        format!(
            "{} already holds files: outputs of the same name will be overwritten (to keep finished photos and \
             correct only the rest, add --resume)",
            out.display()
        )
    })
}

/// A file-size limit (`ulimit -f`, `prlimit --fsize`, a scheduler passing on the submitting shell's limits) must
/// cost the one file that outgrows it, not the run: by default the kernel kills the process with SIGXFSZ at the
/// first write past the limit (exit 153, no report, a temporary file left). With a handler installed, the write
/// fails with `EFBIG` instead and the run's per-file error handling takes over (the file is named, its temporary
/// file removed, the run goes on and writes its report). The handler only sets a flag nobody reads
/// (signal-hook's, async-signal-safe); unlike `SIG_IGN` it is not inherited by programs the command starts.
/// Python ignores SIGXFSZ itself at start-up, so `correct()` from Python is covered without it.
pub fn survive_file_size_limit() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        // Failing to install it leaves the kernel's default, as before: not worth refusing to run for.
        let _ = signal_hook::flag::register(signal_hook::consts::SIGXFSZ, flag);
    });
}

/// In a batch run, Ctrl-C (SIGINT) or SIGTERM (a scheduler's time limit) says how to go on before the process
/// exits with 128 + the signal (130 for Ctrl-C). Outputs are only renamed into place when complete, so what is
/// in the output folder is whole photos; `--resume` corrects the rest with the same result as one run.
///
/// signal-hook's iterator: the signal handler itself only writes to a pipe (async-signal-safe); the message is
/// printed by an ordinary thread.
pub fn hint_on_interrupt() -> Result<(), Error> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])
        .map_err(|e| Error::Usage(format!("cannot install the signal handler: {e}")))?;
    std::thread::spawn(move || {
        if let Some(sig) = signals.forever().next() {
            eprintln!("\n{}", interrupted_hint(sig));
            std::process::exit(128 + sig);
        }
    });
    Ok(())
}

fn interrupted_hint(sig: i32) -> String {
    let what = if sig == signal_hook::consts::SIGINT {
        "interrupted (Ctrl-C)"
    } else {
        "stopped (SIGTERM)"
    };
    format!(
        "abysslight: {what}: the photos written so far are complete. To finish, run the same command again \
         with --resume: finished photos are skipped and the result equals an uninterrupted run."
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_note_tells_overwrite_from_resume_and_stays_quiet_on_an_empty_folder() {
        let d = tempfile::tempdir().unwrap();
        assert_eq!(non_empty_out_note(d.path(), false), None, "empty folder");
        assert_eq!(
            non_empty_out_note(&d.path().join("missing"), false),
            None,
            "no folder yet"
        );
        std::fs::write(d.path().join("img1.jpg"), b"x").unwrap();
        let plain = non_empty_out_note(d.path(), false).unwrap();
        assert!(
            plain.contains("overwritten") && plain.contains("--resume"),
            "{plain}"
        );
        let resume = non_empty_out_note(d.path(), true).unwrap();
        assert!(!resume.contains("overwritten"), "{resume}");
    }

    #[test]
    fn the_hint_names_resume_for_both_signals() {
        for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            assert!(interrupted_hint(sig).contains("--resume"));
        }
        assert!(interrupted_hint(signal_hook::consts::SIGINT).contains("Ctrl-C"));
    }
}

//! Faults cost one file, never the mission (docs/threat-model.md): a closed stdout or stderr, an unreadable first
//! photo, a run picture or factor image that cannot be written.

#![cfg(unix)]

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use common::{report, s, BIN};

/// `root/survey` (6 photos) and `root/water` (3 frames).
fn mission(root: &Path) -> (PathBuf, PathBuf) {
    common::tiny_mission(root, 6)
}

/// A pipe whose reading end is already closed: every write to it fails with EPIPE.
fn closed_pipe() -> Stdio {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    Stdio::from(writer)
}

/// stderr a closed pipe (`correct ... 2>&1 | head`) and one bad photo: the run goes on, the report is written,
/// exit 1 (before: a panic, exit 101, no report). The same for stdout of window, completions and --dry-run.
#[test]
fn a_closed_stdout_or_stderr_ends_nothing() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = mission(d.path());
    std::fs::write(survey.join("IMG_0003.png"), b"not a png").unwrap();
    let out = d.path().join("out");
    #[rustfmt::skip]
    let st = Command::new(BIN)
        .args(["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out), "--window", "3"])
        .stdout(closed_pipe())
        .stderr(closed_pipe())
        .status()
        .unwrap();
    assert_eq!(st.code(), Some(1));
    let r = report(&out);
    assert_eq!(r["failed"], 1);
    assert_eq!(r["corrected"], 5);
    let dry = d.path().join("dry");
    #[rustfmt::skip]
    let printing: [&[&str]; 4] = [
        &["window", "--contamination", "0.2"],
        &["completions", "bash"],
        &["manpage"],
        &["correct", "--dry-run", "--survey", s(&survey), "--out", s(&dry)],
    ];
    for args in printing {
        let st = Command::new(BIN)
            .args(args)
            .stdout(closed_pipe())
            .stderr(closed_pipe())
            .status()
            .unwrap();
        assert_ne!(st.code(), Some(101), "{args:?} panicked");
    }
}

/// The first survey photo cannot be read (an I/O error, as permission denied gives): it is one skipped photo (before:
/// the whole mission failed with exit 2; as the 7th photo it was already skipped).
#[test]
fn an_unreadable_first_photo_is_one_skipped_photo() {
    if !Path::new("/proc/self/mem").exists() {
        eprintln!("no /proc: skipped");
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = mission(d.path());
    // Reading /proc/self/mem from offset 0 fails (EIO), for root as well as for anyone.
    std::fs::rename(survey.join("IMG_0000.png"), d.path().join("aside.png")).unwrap();
    std::os::unix::fs::symlink("/proc/self/mem", survey.join("IMG_0000.png")).unwrap();
    let out = d.path().join("out");
    #[rustfmt::skip]
    let o = Command::new(BIN)
        .args(["correct", "-q", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out), "--window", "3"])
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r = report(&out);
    assert_eq!(r["failed"], 1);
    assert_eq!(r["corrected"], 5);
}

/// A run picture (overview.png) or a factor image that cannot be written costs that file, not the mission (before:
/// exit 2, no report). A folder in the way stands in for a full disk: the write fails the same way, at that file.
#[test]
fn a_picture_or_factor_image_that_cannot_be_written_costs_that_file() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = mission(d.path());
    let out = d.path().join("out");
    std::fs::create_dir_all(out.join("_abysslight/overview.png")).unwrap();
    std::fs::create_dir_all(out.join("_abysslight/factors/IMG_0002.png")).unwrap();
    #[rustfmt::skip]
    let o = Command::new(BIN)
        .args(["correct", "-q", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out), "--window", "3",
               "--save-factors"])
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r = report(&out);
    assert_eq!(r["corrected"], 6);
    assert_eq!(r["failed"], 1, "{r}");
    assert!(
        r["warnings"].to_string().contains("overview.png"),
        "{}",
        r["warnings"]
    );
    for i in 0..6 {
        assert!(out.join(format!("IMG_{i:04}.png")).is_file());
    }
}

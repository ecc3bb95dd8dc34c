//! Runs that share an output folder (docs/threat-model.md): the lock is the operating system's, taken by every
//! mode before anything is written, released however a run ends; the stale-temp sweep stays in its own folder.

#![cfg(unix)]

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{s, BIN};

/// `root/survey` (8 photos) and `root/water` (3 frames).
fn mission(root: &Path) -> (PathBuf, PathBuf) {
    common::tiny_mission(root, 8)
}

fn correct(survey: &Path, water: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(BIN);
    c.args([
        "correct",
        "-q",
        "--survey",
        s(survey),
        "--water-column",
        s(water),
        "--out",
        s(out),
    ])
    .args(extra)
    .stdout(Stdio::null())
    .stderr(Stdio::piped());
    c
}

/// A plain run and a one-shard run with another window, started together into one folder: exactly one of them
/// runs (before, both were accepted in most tries and the folder mixed their photos).
#[test]
fn a_plain_run_and_a_shard_with_other_options_never_both_run() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = mission(d.path());
    for k in 0..4 {
        let out = d.path().join(format!("out{k}"));
        let a = correct(&survey, &water, &out, &["--window", "3"])
            .spawn()
            .unwrap();
        let b = correct(&survey, &water, &out, &["--window", "5", "--shard", "1/1"])
            .spawn()
            .unwrap();
        let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
        let ok = [&a, &b].iter().filter(|o| o.status.success()).count();
        assert_eq!(
            ok,
            1,
            "try {k}: {}\n{}",
            String::from_utf8_lossy(&a.stderr),
            String::from_utf8_lossy(&b.stderr)
        );
        let refused = if a.status.success() { &b } else { &a };
        assert_eq!(refused.status.code(), Some(2));
    }
}

/// A run killed with SIGKILL (or in a container whose pid 1 it was) leaves no lock that stops the next run.
#[test]
fn a_killed_run_leaves_no_lock_behind() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = mission(d.path());
    let out = d.path().join("out");
    let mut live = correct(
        &survey,
        &water,
        &out,
        &[
            "--window",
            "3",
            "--watch",
            "--poll-interval",
            "50",
            "--idle-timeout",
            "60",
        ],
    )
    .spawn()
    .unwrap();
    let lock = out.join("_abysslight/lock");
    let t = Instant::now();
    while !std::fs::read_to_string(&lock).is_ok_and(|t| t.contains("pid")) {
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "the watch never took its lock"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let second = correct(&survey, &water, &out, &["--window", "3"])
        .output()
        .unwrap();
    assert_eq!(
        second.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&second.stderr)
    );
    live.kill().unwrap();
    live.wait().unwrap();
    let after = correct(&survey, &water, &out, &["--window", "3"])
        .output()
        .unwrap();
    assert!(
        after.status.success(),
        "{}",
        String::from_utf8_lossy(&after.stderr)
    );
    // A lock file naming pid 1 (a run killed in a container) does not stop a run either.
    std::fs::write(&lock, r#"{"pid": 1, "options": {}}"#).unwrap();
    let again = correct(&survey, &water, &out, &["--window", "3"])
        .output()
        .unwrap();
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
}

/// The sweep of a run into `OUT` leaves the temp files of a run writing into `OUT/quick` alone (before, all of
/// that run's photos failed), and still removes its own stale ones.
#[test]
fn the_sweep_stays_in_its_own_folder() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = mission(d.path());
    let out = d.path().join("out");
    std::fs::create_dir_all(out.join("quick/_abysslight")).unwrap();
    let theirs = out.join("quick/.IMG_0003.png.Ab12Cd.abysslight-tmp");
    let mine = out.join(".IMG_0001.png.Zz99Yy.abysslight-tmp");
    std::fs::write(&theirs, b"being written").unwrap();
    std::fs::write(&mine, b"left by a killed run").unwrap();
    let o = correct(&survey, &water, &out, &["--window", "3"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(theirs.exists(), "another run's temp file was removed");
    assert!(!mine.exists(), "this folder's stale temp file was kept");
}

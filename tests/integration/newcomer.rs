//! What a newcomer tripped on in the first hour, through the `abysslight` binary: water-column frames of another
//! size than the survey (the dry run says so; the failed run does not block the corrected one), a contamination
//! given in per cent, a missing survey folder, where `--window` stands in `-h`, the floor the dry run names, and the
//! paths the plain log prints.

use crate::common;

use std::path::Path;

use common::*;

/// `n` water-column frames of `w`×`h` in `dir`.
fn frames(dir: &Path, n: u8, w: u32, h: u32) {
    std::fs::create_dir_all(dir).unwrap();
    for i in 0..n {
        image::RgbImage::from_pixel(w, h, image::Rgb([10 + i, 12, 14]))
            .save(dir.join(format!("wc{i}.png")))
            .unwrap();
    }
}

#[test]
fn water_column_frames_of_another_size_are_named_and_a_failed_run_does_not_block_the_next() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 5);
    let small = d.path().join("small-water");
    frames(&small, 3, 16, 12);
    let out = d.path().join("out");
    let run = |water: &Path, extra: &[&str]| {
        let mut args = vec![
            "correct",
            "--survey",
            s(&survey),
            "--water-column",
            s(water),
            "--out",
            s(&out),
            "--window",
            "3",
        ];
        args.extend_from_slice(extra);
        abysslight(&args)
    };
    let dry = run(&small, &["--dry-run"]);
    assert_eq!(dry.status.code(), Some(0), "{}", stderr(&dry));
    let text = stdout(&dry);
    assert!(
        text.contains("warning: the water-column frames")
            && text.contains("16x12")
            && text.contains("32x24"),
        "{text}"
    );
    assert!(!text.contains("nothing found"), "{text}");
    // The run stops before it writes a photo…
    let failed = run(&small, &["-q"]);
    assert_eq!(failed.status.code(), Some(2), "{}", stderr(&failed));
    assert!(!out.join("IMG_0000.png").exists());
    // …and the same folder takes the corrected run.
    let water = d.path().join("water");
    let ok = run(&water, &["-q"]);
    assert_eq!(ok.status.code(), Some(0), "{}", stderr(&ok));
    assert!(out.join("IMG_0004.png").exists());
    // Once photos are there, other options are refused, named as flags with both values.
    let other = run(&water, &["-q", "--downsample", "2"]);
    assert_eq!(other.status.code(), Some(2));
    let e = stderr(&other);
    assert!(e.contains("--downsample 4 before, 2 now"), "{e}");
    assert!(!e.contains("window-in-effect"), "{e}");
}

#[test]
fn a_contamination_in_per_cent_gets_the_share_suggested() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 3);
    let out = d.path().join("out");
    #[rustfmt::skip]
    let o = abysslight(&["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out),
                         "--contamination", "20"]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.contains("did you mean 0.2") && e.contains("20 %"), "{e}");
    // A share out of range that is not a percentage gets no such guess.
    #[rustfmt::skip]
    let o = abysslight(&["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out),
                         "--contamination", "0.7"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(!stderr(&o).contains("did you mean"), "{}", stderr(&o));
    assert!(!out.exists(), "nothing written");
}

#[test]
fn a_missing_survey_folder_names_the_flag() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("out");
    let missing = d.path().join("no-such-survey");
    let o = abysslight(&["correct", "--survey", s(&missing), "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("--survey") && e.contains("no-such-survey"),
        "{e}"
    );
    // The same for the water-column folder.
    let (survey, _) = tiny_mission(d.path(), 3);
    let water = d.path().join("no-such-descent");
    #[rustfmt::skip]
    let o = abysslight(&["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("--water-column") && e.contains("no-such-descent"),
        "{e}"
    );
    assert!(!out.exists(), "nothing written");
}

#[test]
fn the_window_leads_the_method_options_in_short_help() {
    let o = abysslight(&["correct", "-h"]);
    let help = stdout(&o);
    let method = help.split("Method:").nth(1).expect("a Method section");
    let first = method
        .lines()
        .map(str::trim_start)
        .find(|l| l.starts_with("--"))
        .unwrap();
    assert!(first.starts_with("--window"), "{method}");
}

#[test]
fn the_dry_run_names_the_floor_the_method_uses() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 3);
    let out = d.path().join("out");
    let dry = |method: &str| {
        #[rustfmt::skip]
        let o = abysslight(&["correct", "--dry-run", "--survey", s(&survey), "--water-column", s(&water),
                             "--out", s(&out), "--method", method]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        stdout(&o)
    };
    let abyss = dry("abyss");
    assert!(
        abyss.contains("relative floor 0.001") && !abyss.contains("factor floor"),
        "{abyss}"
    );
    let paper = dry("paper");
    assert!(
        paper.contains("factor floor 0.05") && !paper.contains("relative floor"),
        "{paper}"
    );
}

/// Without a terminal the log names each photo below the current folder by its path from there, not by the
/// machine's absolute path (a config file's folders, or absolute flags, gave it before).
#[test]
fn the_plain_log_prints_paths_below_the_current_folder() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 4);
    #[rustfmt::skip]
    let o = abysslight_in(&["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", "out",
                            "--window", "3"], d.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let e = stderr(&o);
    let done: Vec<&str> = e.lines().filter(|l| l.contains("] done ")).collect();
    assert_eq!(done.len(), 4, "{e}");
    let root = d.path().canonicalize().unwrap();
    for l in done {
        assert!(l.ends_with(".png") && l.contains("survey/IMG_"), "{l}");
        assert!(!l.contains(s(&root)) && !l.contains(s(d.path())), "{l}");
    }
}

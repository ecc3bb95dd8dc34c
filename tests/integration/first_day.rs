//! A newcomer's first day through the `abysslight` binary: what `correct --dry-run` warns about before a run,
//! the traps a run or an evaluation warns about (a water-column folder that is the survey, a curve other than the
//! run's), `evaluate` writing no file unasked, and `sheet` with its folders given the wrong way round or a photo
//! the run skipped.

use crate::common;

use std::path::Path;
use std::process::Output;

use common::*;

fn text(o: &Output) -> (String, String) {
    (stdout(o), stderr(o))
}

/// A small photo of a varied pattern, `w`×`h`, saved at `path` (PNG or JPEG by its name).
fn photo(path: &Path, w: u32, h: u32, i: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    pattern(w, h, i).save(path).unwrap();
}

#[test]
fn dry_run_reports_what_would_go_wrong_and_writes_nothing() {
    let d = tempfile::tempdir().unwrap();
    // Six PNGs of one dive, two seconds apart by their names; then a JPEG and a smaller PNG a day later.
    for i in 0..6 {
        photo(
            &d.path()
                .join(format!("survey/D2023-06-03T16-27-{:02}.png", 10 + 2 * i)),
            32,
            24,
            i,
        );
    }
    photo(&d.path().join("survey/D2023-06-04T16-30-00.jpg"), 32, 24, 7);
    photo(&d.path().join("survey/D2023-06-04T16-30-02.png"), 16, 12, 8);
    let dry = |extra: &[&str]| {
        let mut args = vec!["correct", "--dry-run", "--survey", "survey", "--out", "out"];
        args.extend(extra);
        let o = abysslight_in(&args, d.path());
        assert!(o.status.success(), "{:?}", text(&o));
        text(&o).0
    };
    let out = dry(&["--window", "15", "--save-factors"]);
    for expected in [
        "warning: 1 photo(s) of another size than the mission's 32x24",
        "D2023-06-04T16-30-02.png (16x12)",
        "warning: the survey mixes formats: 7 PNG",
        "1 JPEG (first D2023-06-04T16-30-00.jpg)",
        "warning: the survey has 8 photo(s), fewer than the window n = 15",
        "warning: two dives (or cameras) in one survey?",
        "the capture times in the file names jump by 24.0 h",
        "checks: 4 warning(s) above",
        "for --save-factors",
        "free there",
    ] {
        assert!(out.contains(expected), "{expected:?} missing from:\n{out}");
    }
    assert!(!d.path().join("out").exists(), "a dry run writes nothing");
    // Without --save-factors no factor images are counted.
    assert!(!dry(&["--window", "15"]).contains("--save-factors"));

    // The first dive alone, one format, one size, enough photos: nothing to warn about.
    for f in ["D2023-06-04T16-30-00.jpg", "D2023-06-04T16-30-02.png"] {
        std::fs::remove_file(d.path().join("survey").join(f)).unwrap();
    }
    let out = dry(&["--window", "5"]);
    assert!(!out.contains("warning"), "{out}");
    assert!(
        out.contains("checks: photo sizes, water-column size, formats, window, one dive, disk: nothing found"),
        "{out}"
    );
}

#[test]
fn a_water_column_that_is_the_survey_is_a_warning_before_and_during_a_run() {
    let d = tempfile::tempdir().unwrap();
    tiny_mission(d.path(), 6);
    let said = "--water-column survey is the --survey folder";
    let run = |water: &str, extra: &[&str]| {
        let mut args = vec!["correct", "--survey", "survey", "--water-column", water];
        args.extend(["--out", "out", "--window", "3"]);
        args.extend(extra);
        abysslight_in(&args, d.path())
    };
    let (out, _) = text(&run("survey", &["--dry-run"]));
    assert!(out.contains(&format!("warning: {said}")), "{out}");
    let (out, _) = text(&run("water", &["--dry-run"]));
    assert!(!out.contains("warning"), "{out}");

    // A run warns on the console and in its report.
    let o = run("survey", &[]);
    let (_, err) = text(&o);
    assert!(err.contains(said), "{err}");
    let report = std::fs::read_to_string(d.path().join("out/_abysslight/report.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&report).unwrap();
    let warnings = report["warnings"].as_array().unwrap();
    assert!(
        warnings.iter().any(|w| w.as_str().unwrap().contains(said)),
        "{warnings:?}"
    );
}

#[test]
fn evaluate_warns_of_another_curve_says_what_scores_mean_and_writes_json_only_when_asked() {
    let d = tempfile::tempdir().unwrap();
    let o = abysslight_in(
        &[
            "simulate",
            "--out",
            "dive",
            "--frames",
            "8",
            "--water-column",
            "4",
            "--size",
            "64x48",
        ],
        d.path(),
    );
    assert!(o.status.success(), "{:?}", text(&o));
    // The simulated dive is encoded linearly; this run took the photos for sRGB.
    let o = abysslight_in(
        &[
            "correct",
            "--survey",
            "dive/survey",
            "--water-column",
            "dive/water",
            "--out",
            "out",
            "--window",
            "5",
            "--transfer",
            "srgb",
        ],
        d.path(),
    );
    assert!(o.status.success(), "{:?}", text(&o));
    let o = abysslight_in(&["evaluate", "--truth", "dive", "out"], d.path());
    let (table, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(table.contains("| out | 8 |"), "{table}");
    assert!(
        err.contains("warning: out: the correct run that wrote out took the camera curve srgb"),
        "{err}"
    );
    assert!(err.contains("give --transfer srgb"), "{err}");
    for meaning in [
        "lower is better for every score",
        "albedo error: ",
        "residual pattern: ",
        "consistency: ",
        "overlap difference: ",
        "clipped: ",
    ] {
        assert!(err.contains(meaning), "{meaning:?} missing: {err}");
    }
    let mut files: Vec<String> = std::fs::read_dir(d.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(files, ["dive", "out"], "evaluate wrote nothing unasked");

    // Scored with the run's own curve: no warning; --json writes where asked.
    let o = abysslight_in(
        &[
            "evaluate",
            "--truth",
            "dive",
            "--transfer",
            "srgb",
            "--json",
            "scores.json",
            "out",
        ],
        d.path(),
    );
    let (_, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("warning"), "{err}");
    let json = std::fs::read_to_string(d.path().join("scores.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(json["transfer"], "srgb");
    assert_eq!(json["sets"][0]["photos"], 8);
}

#[test]
fn sheet_takes_swapped_folders_the_right_way_round_and_labels_skipped_photos() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 6);
    // A photo of another size, last in the dive: the run skips it.
    photo(&survey.join("IMG_0006.png"), 16, 12, 9);
    let o = abysslight_in(
        &[
            "correct",
            "--survey",
            "survey",
            "--water-column",
            "water",
            "--out",
            "out",
            "--window",
            "3",
        ],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(1), "{:?}", text(&o));
    let sheet = |a: &str, b: &str, png: &str| {
        let args = ["sheet", a, b, png, "--rows", "7", "--width", "160"];
        let o = abysslight_in(&args, d.path());
        assert!(o.status.success(), "{:?}", text(&o));
        text(&o).1
    };
    let right = sheet("survey", "out", "right.png");
    assert!(!right.contains("warning"), "{right}");
    let swapped = sheet("out", "survey", "swapped.png");
    assert!(
        swapped.contains("warning: out holds a correct run's report and survey does not"),
        "{swapped}"
    );
    let right = std::fs::read(d.path().join("right.png")).unwrap();
    assert_eq!(
        right,
        std::fs::read(d.path().join("swapped.png")).unwrap(),
        "the same sheet either way round"
    );
    // Rows of 160x120 tiles, 4 pixels apart under a 12-pixel caption line: the last row is the skipped photo,
    // its corrected column a grey tile with SKIPPED in red (not a white gap).
    let img = image::load_from_memory(&right).unwrap().to_rgb8();
    let (x0, y0) = (4 + 160 + 4, 4 + 12 + 6 * (120 + 4));
    assert_eq!(img.get_pixel(x0 + 150, y0 + 110).0, [225, 225, 225]);
    let red = (0..40)
        .flat_map(|y| (0..160).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x0 + x, y0 + y).0 == [220, 30, 30])
        .count();
    assert!(red > 100, "SKIPPED drawn in red: {red} pixels");
    // A corrected row's tile is the photo (not grey).
    assert_ne!(img.get_pixel(x0 + 150, 4 + 12 + 110).0, [225, 225, 225]);
}

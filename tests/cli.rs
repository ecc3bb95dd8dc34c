//! The `abysslight` binary as a user runs it: exit codes, messages, config files, refusals.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use common::*;

fn abysslight(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_abysslight"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run abysslight")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn window_prints_n_and_p_half() {
    let d = tempfile::tempdir().unwrap();
    let o = abysslight(
        &["window", "--contamination", "0.2", "--risk", "0.05"],
        d.path(),
    );
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("n = 7"), "{out}");
    assert!(out.contains("0.033344"), "{out}");
    let o = abysslight(&["window", "--contamination", "0.6"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("0.5"), "{}", stderr(&o));
}

#[test]
fn bad_photo_is_reported_and_the_batch_goes_on() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(32, 24, 6, 3, 0.1, false, 1);
    write_all(&dive.water, &d.path().join("water"), "w", "png");
    write_all(&dive.photos, &d.path().join("survey"), "img", "jpg");
    std::fs::write(d.path().join("survey/img4.jpg"), b"\xff\xd8\xff truncated").unwrap();
    std::fs::write(d.path().join("survey/readme.txt"), b"notes").unwrap();
    let o = abysslight(
        &[
            "correct",
            "--water-column",
            "water",
            "--survey",
            "survey",
            "--out",
            "out",
            "--window",
            "3",
        ],
        d.path(),
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("img4.jpg"), "{err}");
    assert!(
        err.contains("readme.txt"),
        "ignored files are mentioned: {err}"
    );
    for i in [1, 2, 3, 5, 6] {
        assert!(d.path().join(format!("out/img{i}.jpg")).is_file(), "img{i}");
    }
    assert!(!d.path().join("out/img4.jpg").exists());
    let report: serde_json::Value = serde_json::from_slice(
        &std::fs::read(d.path().join("out/_abysslight/report.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["corrected"], 5);
    assert_eq!(report["failed"], 1);
    assert!(report["errors"][0]["path"]
        .as_str()
        .unwrap()
        .ends_with("img4.jpg"));
    assert_eq!(report["errors"][0]["kind"], "decode");
    assert_eq!(report["frames"].as_array().unwrap().len(), 5);
    // The bad photo is absent from every window: the five good ones are indices 0..=4.
    assert_eq!(report["frames"][4]["index"], 4);
}

#[test]
fn output_inside_input_is_refused_before_any_work() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(16, 16, 3, 0, 0.0, false, 2);
    write_all(&dive.photos, &d.path().join("survey"), "img", "png");
    for out in ["survey", "survey/corrected"] {
        let o = abysslight(&["correct", "--survey", "survey", "--out", out], d.path());
        assert_eq!(o.status.code(), Some(2));
        assert!(stderr(&o).contains("--out"), "{}", stderr(&o));
    }
    assert!(!d.path().join("survey/corrected").exists());
    assert!(!d.path().join("survey/_abysslight").exists());
}

#[test]
fn usage_errors_exit_2_with_a_clear_message() {
    let d = tempfile::tempdir().unwrap();
    let o = abysslight(
        &["correct", "--survey", "nowhere", "--out", "out"],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("nowhere"), "{}", stderr(&o));
    let o = abysslight(&["correct", "--survey", "."], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--out"));
    let o = abysslight(
        &["correct", "--survey", ".", "--out", "o", "--window", "4"],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("odd"), "{}", stderr(&o));
    let o = abysslight(
        &[
            "correct",
            "--survey",
            ".",
            "--out",
            "o",
            "--seafloor-colour",
            "pink",
        ],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(2));
    std::fs::create_dir(d.path().join("empty")).unwrap();
    let o = abysslight(&["correct", "--survey", "empty", "--out", "o"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("no photos") && stderr(&o).contains("empty"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn config_file_with_flag_override() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(24, 16, 5, 0, 0.0, false, 4);
    write_all(&dive.photos, &d.path().join("m/survey"), "img", "png");
    std::fs::write(
        d.path().join("m/mission.toml"),
        "survey = \"survey\"\nout = \"corrected\"\nwindow = 5\nseafloor-colour = \"#8a7560\"\n",
    )
    .unwrap();
    let o = abysslight(
        &[
            "correct",
            "--config",
            "m/mission.toml",
            "--window",
            "3",
            "--quiet",
        ],
        d.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).is_empty(),
        "--quiet prints nothing on success: {}",
        stderr(&o)
    );
    let report: serde_json::Value = serde_json::from_slice(
        &std::fs::read(d.path().join("m/corrected/_abysslight/report.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["window"]["n"], 3, "flag overrides the file");
    assert_eq!(
        report["options"]["seafloor-colour"],
        "0.5411765,0.45882353,0.3764706"
    );
    let o = abysslight(&["correct", "--config", "m/missing.toml"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("missing.toml"));
}

#[test]
fn plain_log_lines_when_not_on_a_terminal() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(16, 16, 3, 0, 0.0, false, 5);
    write_all(&dive.photos, &d.path().join("survey"), "img", "png");
    let o = abysslight(&["correct", "--survey", "survey", "--out", "out"], d.path());
    assert!(o.status.success());
    let err = stderr(&o);
    assert!(err.contains("[3/3] done"), "{err}");
    assert!(
        err.contains("S = 0"),
        "missing water column is warned about: {err}"
    );
}

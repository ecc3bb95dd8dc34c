//! The `abysslight` binary as a user runs it: exit codes, messages, config files, refusals.

use crate::common;

use std::path::Path;
use std::process::Command;

use common::*;

#[test]
fn window_prints_n_and_p_half() {
    let d = tempfile::tempdir().unwrap();
    let o = abysslight_in(
        &["window", "--contamination", "0.2", "--risk", "0.05"],
        d.path(),
    );
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("n = 7"), "{out}");
    assert!(out.contains("0.033344"), "{out}");
    let o = abysslight_in(&["window", "--contamination", "0.6"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("0.5"), "{}", stderr(&o));
}

#[test]
fn bad_photo_is_reported_and_the_batch_goes_on() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(32, 24, 6, 3, 0.1, false, 1);
    write_dive(&dive, d.path(), "jpg");
    std::fs::write(d.path().join("survey/img4.jpg"), b"\xff\xd8\xff truncated").unwrap();
    std::fs::write(d.path().join("survey/readme.txt"), b"notes").unwrap();
    let o = correct_dive(d.path(), "out", &["--window", "3"]);
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
        let o = abysslight_in(&["correct", "--survey", "survey", "--out", out], d.path());
        assert_eq!(o.status.code(), Some(2));
        assert!(stderr(&o).contains("--out"), "{}", stderr(&o));
    }
    assert!(!d.path().join("survey/corrected").exists());
    assert!(!d.path().join("survey/_abysslight").exists());
}

#[test]
fn usage_errors_exit_2_with_a_clear_message() {
    let d = tempfile::tempdir().unwrap();
    let o = abysslight_in(
        &["correct", "--survey", "nowhere", "--out", "out"],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("nowhere"), "{}", stderr(&o));
    let o = abysslight_in(&["correct", "--survey", "."], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--out"));
    let o = abysslight_in(
        &["correct", "--survey", ".", "--out", "o", "--window", "4"],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("odd"), "{}", stderr(&o));
    let o = abysslight_in(
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
    let o = abysslight_in(&["correct", "--survey", "empty", "--out", "o"], d.path());
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
        "survey = \"survey\"\nout = \"corrected\"\nwindow = 5\nnear-window = \"auto\"\nseafloor-colour = \"#8a7560\"\n",
    )
    .unwrap();
    let o = abysslight_in(
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
    // --near-window auto resolved and recorded: 5 photos are not fewer than the window's 3, so off.
    assert_eq!(report["options"]["near-window"], 0);
    assert_eq!(
        report["options"]["seafloor-colour"],
        "0.5411765,0.45882353,0.3764706"
    );
    let o = abysslight_in(&["correct", "--config", "m/missing.toml"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("missing.toml"));
    // A file's contamination, and `auto` asked for by name on the command line or in the file: the window chosen
    // per stretch of the mission, as with neither given.
    std::fs::write(
        d.path().join("m/dense.toml"),
        "survey = \"survey\"\nout = \"dense\"\ncontamination = 0.3\n",
    )
    .unwrap();
    std::fs::write(
        d.path().join("m/auto.toml"),
        "survey = \"survey\"\nout = \"auto\"\ncontamination = \"auto\"\nwindow = \"auto\"\n",
    )
    .unwrap();
    let dry = |args: &[&str]| {
        let o = abysslight_in(&[&["correct", "--dry-run"], args].concat(), d.path());
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        stdout(&o)
    };
    let per_stretch = "window: auto, chosen per stretch of the mission";
    let file = dry(&["--config", "m/dense.toml"]);
    assert!(
        file.contains("at contamination 0.3") && !file.contains(per_stretch),
        "{file}"
    );
    for args in [
        &["--config", "m/dense.toml", "--contamination", "auto"][..],
        &["--config", "m/auto.toml"],
        &["--survey", "m/survey", "--out", "x"],
    ] {
        let plan = dry(args);
        assert!(plan.contains(per_stretch), "{args:?}: {plan}");
    }
    let o = abysslight_in(
        &[
            "correct",
            "--config",
            "m/dense.toml",
            "--contamination",
            "high",
        ],
        d.path(),
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--contamination") && stderr(&o).contains("auto"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn plain_log_lines_when_not_on_a_terminal() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(16, 16, 3, 0, 0.0, false, 5);
    write_all(&dive.photos, &d.path().join("survey"), "img", "png");
    let o = abysslight_in(&["correct", "--survey", "survey", "--out", "out"], d.path());
    assert!(o.status.success());
    let err = stderr(&o);
    assert!(err.contains("[3/3] done"), "{err}");
    assert!(
        err.contains("S = 0"),
        "missing water column is warned about: {err}"
    );
}

/// Headings of a clap help text: unindented lines ending in ':' ("Inputs:", "Run control:").
fn headings(help: &str) -> Vec<String> {
    help.lines()
        .filter(|l| !l.starts_with(' ') && l.ends_with(':'))
        .map(|l| l.trim_end_matches(':').to_string())
        .collect()
}

#[test]
fn correct_help_groups_options_shows_required_arguments_and_examples() {
    let d = tempfile::tempdir().unwrap();
    let short = stdout(&abysslight_in(&["correct", "-h"], d.path()));
    let long = stdout(&abysslight_in(&["correct", "--help"], d.path()));
    for h in [&short, &long] {
        let found = headings(h);
        for want in ["Inputs", "Outputs", "Method", "Monitoring", "Run control"] {
            assert!(found.iter().any(|f| f == want), "no {want:?} in {found:?}");
        }
        assert!(
            h.contains("Usage: abysslight correct [OPTIONS] --survey DIR --out DIR"),
            "{h}"
        );
        assert!(h.contains("--resume"), "exit status 130 says how to go on");
    }
    // -h: one line per option; --help: paragraphs and examples.
    assert!(!short.contains("Examples:"), "{short}");
    assert!(long.contains("Examples:"), "{long}");
    assert!(
        long.contains("byte-identical"),
        "long help has the paragraphs"
    );
    assert!(!short.contains("byte-identical"));
    assert!(long.len() > short.len() * 3 / 2);
    // The old spellings still work.
    assert!(long.contains("--seafloor-color"));
}

#[test]
fn each_subcommand_has_its_own_help_and_the_top_level_lists_them() {
    let d = tempfile::tempdir().unwrap();
    let scatter = stdout(&abysslight_in(&["scatter", "--help"], d.path()));
    assert!(scatter.contains("water-column"), "{scatter}");
    for correct_only in ["every photo was corrected", "report.json", "--resume"] {
        assert!(!scatter.contains(correct_only), "{correct_only}: {scatter}");
    }
    let top = abysslight_in(&["--help"], d.path());
    assert!(top.status.success());
    let top = stdout(&top);
    for sub in [
        "correct",
        "window",
        "scatter",
        "sheet",
        "bench",
        "simulate",
        "evaluate",
        "demo",
        "completions",
        "manpage",
    ] {
        let line = top
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{sub} ")))
            .unwrap_or_else(|| panic!("{sub} not listed: {top}"));
        assert!(
            line.split_whitespace().count() > 3,
            "{sub} has a description: {line}"
        );
    }
}

#[test]
fn completions_and_manpage_come_from_the_same_definition() {
    let d = tempfile::tempdir().unwrap();
    let bash = abysslight_in(&["completions", "bash"], d.path());
    assert!(bash.status.success(), "{}", stderr(&bash));
    let bash = stdout(&bash);
    assert!(
        bash.contains("correct") && bash.contains("--survey") && bash.contains("complete"),
        "{bash}"
    );
    for shell in ["zsh", "fish", "powershell", "elvish"] {
        let o = abysslight_in(&["completions", shell], d.path());
        assert!(o.status.success(), "{shell}: {}", stderr(&o));
        assert!(stdout(&o).contains("water-column"), "{shell}");
    }
    assert_eq!(
        abysslight_in(&["completions", "tcsh"], d.path())
            .status
            .code(),
        Some(2)
    );
    let man = abysslight_in(&["manpage"], d.path());
    assert!(man.status.success());
    let man = stdout(&man);
    assert!(man.contains(".TH") && man.contains("correct"), "{man}");
    let man = stdout(&abysslight_in(&["manpage", "correct"], d.path()));
    assert!(man.contains(".TH") && man.contains("correct"), "{man}");
    assert!(man.contains("survey"), "{man}");
    let o = abysslight_in(&["manpage", "nonsense"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("nonsense"));
}

/// Every flag in README's options table is one `correct --help` knows, and the other way round.
#[test]
fn readme_options_table_matches_correct_help() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let table = readme
        .split("## `abysslight correct` options")
        .nth(1)
        .expect("README has the options table")
        .split("\n## ")
        .next()
        .unwrap();
    let flags_in = |text: &str| -> Vec<String> {
        let mut v: Vec<String> = text
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
            .filter(|w| w.starts_with("--") && w.len() > 2)
            .map(String::from)
            .collect();
        v.sort();
        v.dedup();
        v
    };
    let rows: String = table
        .lines()
        .filter(|l| l.starts_with("| `-"))
        .map(|l| l.split('|').nth(1).unwrap().to_string() + "\n")
        .collect();
    let readme_flags = flags_in(&rows);
    assert!(readme_flags.len() > 20, "{readme_flags:?}");
    let d = tempfile::tempdir().unwrap();
    let help = stdout(&abysslight_in(&["correct", "--help"], d.path()));
    let help_flags: Vec<String> = help
        .lines()
        .map(str::trim_start)
        .filter(|l| l.starts_with("--") || l.starts_with("-j") || l.starts_with("-q"))
        .flat_map(|l| flags_in(l.split("  ").next().unwrap()))
        .filter(|f| f != "--help" && f != "--version")
        .collect();
    for f in &readme_flags {
        assert!(
            help_flags.contains(f),
            "README lists {f}, correct --help does not"
        );
    }
    for f in &help_flags {
        assert!(
            readme_flags.contains(f),
            "correct --help has {f}, README's table does not"
        );
    }
}

#[test]
fn previews_sheet_summary_and_rerun_note() {
    let d = tempfile::tempdir().unwrap();
    // Three photos and the default window of 7: every photo is flagged ("too few photos for the window").
    let dive = dive(48, 32, 3, 3, 0.1, false, 8);
    write_dive(&dive, d.path(), "png");
    let o = correct_dive(d.path(), "out", &["--save-factors"]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("note:"), "a new folder needs no note: {err}");
    // The closing summary names the flagged photos and where to look.
    for name in ["img1.png", "img2.png", "img3.png"] {
        assert!(
            err.contains("flagged #") && err.contains(name),
            "{name}: {err}"
        );
    }
    assert!(
        err.contains("report.json") && err.contains("overview.png"),
        "{err}"
    );
    // 16-bit data one pixel per block (4×4 for photos this small: --downsample auto), and an 8-bit preview at
    // least 640 wide.
    let data = image::open(d.path().join("out/_abysslight/factors/img2.png")).unwrap();
    assert_eq!((data.width(), data.height()), (12, 8));
    assert!(matches!(data, image::DynamicImage::ImageRgb16(_)));
    let preview = image::open(d.path().join("out/_abysslight/factors-preview/img2.png")).unwrap();
    assert!(matches!(preview, image::DynamicImage::ImageRgb8(_)));
    assert_eq!((preview.width(), preview.height()), (640, 426));
    let brightest = preview.to_rgb8().pixels().map(|p| p.0[1]).max().unwrap();
    assert!(
        brightest > 200,
        "scaled to its range, not black: {brightest}"
    );
    // A before/after sheet from the CLI: input | corrected | F·C, 3 rows of 200-pixel tiles.
    let o = abysslight_in(
        &[
            "sheet",
            "survey",
            "out",
            "sheet.png",
            "--rows",
            "3",
            "--width",
            "200",
        ],
        d.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("input | corrected | F·C"),
        "{}",
        stderr(&o)
    );
    let sheet = image::open(d.path().join("sheet.png")).unwrap();
    assert!(
        sheet.width() >= 3 * 200 && sheet.height() >= 3 * 133,
        "{:?}",
        (sheet.width(), sheet.height())
    );
    // Without saved factors: two columns, and the message says how to get the third.
    std::fs::remove_dir_all(d.path().join("out/_abysslight/factors")).unwrap();
    let o = abysslight_in(
        &[
            "sheet",
            "survey",
            "out",
            "sheet2.png",
            "--rows",
            "3",
            "--width",
            "200",
        ],
        d.path(),
    );
    assert!(stderr(&o).contains("--save-factors"), "{}", stderr(&o));
    let two = image::open(d.path().join("sheet2.png")).unwrap();
    // Two 200-pixel tiles and three 4-pixel gaps: no captioned empty column beside them.
    assert_eq!(
        two.width(),
        2 * 200 + 3 * 4,
        "{:?}",
        (two.width(), sheet.width())
    );
    let o = abysslight_in(&["sheet", "nowhere", "out", "s.png"], d.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("nowhere"));
    // Running again into the same folder says what happens to what is there.
    let err = stderr(&correct_dive(d.path(), "out", &["--save-factors"]));
    assert!(
        err.contains("note:") && err.contains("overwritten"),
        "{err}"
    );
    let err = stderr(&correct_dive(
        d.path(),
        "out",
        &["--save-factors", "--resume"],
    ));
    assert!(
        err.contains("note:") && err.contains("--resume keeps"),
        "{err}"
    );
}

/// The note on the non-empty output folder is printed once the handler is installed, before the first photo is
/// read; Ctrl-C comes right after it, while the run still has its 240 photos of 320×240 to survey and correct
/// (seconds of work against the milliseconds a signal takes). A FIFO as `--scatter`, which once blocked the run
/// for this test, is refused now.
#[cfg(unix)]
#[test]
fn ctrl_c_in_a_batch_run_says_how_to_resume_and_exits_130() {
    use std::io::{BufRead, BufReader};
    let d = tempfile::tempdir().unwrap();
    let dive = dive(320, 240, 240, 0, 0.1, false, 9);
    write_all(&dive.photos, &d.path().join("survey"), "img", "png");
    std::fs::create_dir(d.path().join("out")).unwrap();
    std::fs::write(d.path().join("out/earlier.txt"), b"x").unwrap();
    let mut child = Command::new(BIN)
        .args(["correct", "--survey", "survey", "--out", "out"])
        .current_dir(d.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let mut log = String::new();
    for l in lines.by_ref() {
        let l = l.unwrap();
        log += &l;
        log.push('\n');
        if l.contains("note:") {
            break;
        }
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    for l in lines {
        log += &l.unwrap();
        log.push('\n');
    }
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{log}");
    assert!(
        log.contains("interrupted (Ctrl-C)")
            && log.contains("run the same command again with --resume"),
        "{log}"
    );
}

#[test]
fn dry_run_writes_nothing_and_limit_corrects_the_first_photos_as_a_whole_run_does() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(32, 24, 9, 3, 0.1, false, 2);
    write_dive(&dive, d.path(), "png");
    let run = |out: &str, extra: &[&str]| {
        let mut args = vec!["--window", "3", "--quiet"];
        args.extend_from_slice(extra);
        correct_dive(d.path(), out, &args)
    };
    let listing = |dir: &Path| -> Vec<std::path::PathBuf> {
        let mut v: Vec<_> = walk(dir);
        v.sort();
        v
    };
    let before = listing(d.path());
    let o = run("out", &["--dry-run"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("9 photos"), "{said}");
    assert!(said.contains("n = 3"), "{said}");
    assert!(said.contains("water-column"), "{said}");
    assert_eq!(listing(d.path()), before, "a dry run writes nothing");
    assert!(!d.path().join("out").exists());

    // --limit 4: the first four photos, byte-identical to the same photos of a whole run.
    let o = run("limited", &["--limit", "4"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = run("whole", &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let photos = |dir: &str| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d.path().join(dir))
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".png"))
            .collect();
        v.sort();
        v
    };
    let limited = photos("limited");
    assert_eq!(limited, ["img1.png", "img2.png", "img3.png", "img4.png"]);
    for name in &limited {
        assert_eq!(
            std::fs::read(d.path().join("limited").join(name)).unwrap(),
            std::fs::read(d.path().join("whole").join(name)).unwrap(),
            "{name}"
        );
    }
    let o = run("zero", &["--limit", "0"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--limit"), "{}", stderr(&o));
}

/// Every file below `dir`.
fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        }
        out.push(p);
    }
    out
}

#[test]
fn transfer_auto_is_the_default_and_reads_what_the_files_declare() {
    // The simulator's photos declare their curve (PNG sRGB chunk or gAMA 1.0). With no --transfer, correct takes
    // it from the first survey photo, says so, records it, and writes the same bytes as when told the curve.
    let d = tempfile::tempdir().unwrap();
    for (encode, said) in [("srgb", "PNG sRGB chunk"), ("linear", "PNG gAMA 1.0")] {
        let dive = d.path().join(format!("dive-{encode}"));
        let dive_s = dive.to_str().unwrap();
        let o = abysslight_in(
            &[
                "simulate",
                "--out",
                dive_s,
                "--frames",
                "8",
                "--water-column",
                "3",
                "--size",
                "96x64",
                "--encode",
                encode,
            ],
            d.path(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let (water, survey) = (format!("{dive_s}/water"), format!("{dive_s}/survey"));
        let auto = format!("{dive_s}-auto");
        let told = format!("{dive_s}-told");
        let correct = |out: &str, extra: &[&str]| {
            let mut args = vec![
                "correct",
                "--water-column",
                &water,
                "--survey",
                &survey,
                "--out",
                out,
            ];
            args.extend_from_slice(extra);
            abysslight_in(&args, d.path())
        };
        let o = correct(&auto, &[]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(
            stderr(&o).contains(&format!("camera curve {encode}: {said}")),
            "{}",
            stderr(&o)
        );
        let report = std::fs::read_to_string(format!("{auto}/_abysslight/report.json")).unwrap();
        assert!(report.contains(said), "{report}");
        let o = correct(&told, &["--transfer", encode]);
        assert!(o.status.success(), "{}", stderr(&o));
        for i in 1..=8 {
            let name = format!("{i:04}.png");
            assert_eq!(
                std::fs::read(format!("{auto}/{name}")).unwrap(),
                std::fs::read(format!("{told}/{name}")).unwrap(),
                "{encode} {name}"
            );
        }
    }
    // An explicit curve wins over what the files say, and auto can be asked for by name.
    let dive_s = d.path().join("dive-srgb");
    let survey = format!("{}/survey", dive_s.display());
    let o = abysslight_in(
        &[
            "correct",
            "--survey",
            &survey,
            "--out",
            "lin",
            "--transfer",
            "linear",
            "--dry-run",
        ],
        d.path(),
    );
    assert!(
        o.status.success() && stdout(&o).contains("transfer linear"),
        "{}",
        stdout(&o)
    );
    let o = abysslight_in(
        &[
            "correct",
            "--survey",
            &survey,
            "--out",
            "a",
            "--transfer",
            "auto",
            "--dry-run",
        ],
        d.path(),
    );
    assert!(
        stdout(&o).contains("transfer auto, srgb: PNG sRGB chunk"),
        "{}",
        stdout(&o)
    );
}

/// README's demo scores are what `abysslight demo` prints: each figure of its table is the demo's `scores.md`
/// figure rounded to three decimals.
#[test]
fn readme_demo_scores_are_the_demos() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let d = tempfile::tempdir().unwrap();
    let o = abysslight_in(&["demo", "--out", "demo"], d.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let scores = std::fs::read_to_string(d.path().join("demo/scores.md")).unwrap();
    // scores.md: method | photos | albedo error | residual pattern | consistency | overlap difference | clipped.
    let demo = |method: &str| -> [f64; 3] {
        let cells: Vec<&str> = scores
            .lines()
            .find(|l| l.starts_with(&format!("| {method} |")))
            .unwrap_or_else(|| panic!("{method} in scores.md: {scores}"))
            .split('|')
            .map(str::trim)
            .collect();
        [cells[3], cells[4], cells[6]].map(|c| c.parse().unwrap())
    };
    // README: method | albedo error | residual pattern | overlap difference.
    let rows = [
        ("raw photos", "raw"),
        ("`--method mean`", "mean"),
        ("`--method polynomial`", "polynomial"),
        ("`--method paper`", "paper"),
        ("`--method abyss` (default)", "abyss"),
    ];
    for (label, method) in rows {
        let line = readme
            .lines()
            .find(|l| l.starts_with(&format!("| {label}")))
            .unwrap_or_else(|| panic!("README's demo table has no row {label}"));
        let said: Vec<f64> = line
            .split('|')
            .map(str::trim)
            .skip(2)
            .filter(|c| !c.is_empty())
            .map(|c| c.parse().unwrap())
            .collect();
        let done = demo(method);
        for (s, v) in said.iter().zip(done) {
            assert!(
                (s - v).abs() <= 0.0005 + 1e-9,
                "README says {s} for {label}, the demo prints {v}"
            );
        }
        assert_eq!(said.len(), 3, "{line}");
    }
}

//! Issue 13, "never lose a photo": attacks on the inputs, the decoders, the folder scan, the flags and the output
//! folder. Each scenario runs in fresh temp folders, and every input file is hashed before and after it: inputs
//! are never modified, whatever the outcome.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use abysslight::io::{decode, find_photos, majority_size, Entry};
use abysslight::{Options, Silent};
use common::{json, pattern, report, s, snapshot, stderr, tiny_mission, BIN};
use proptest::prelude::*;

/// Run `scenario` and assert that no file below `inputs` changed, appeared or vanished.
fn untouched<T>(inputs: &[&Path], scenario: impl FnOnce() -> T) -> T {
    let before = snapshot(inputs);
    assert!(!before.is_empty(), "the harness must see the inputs");
    let r = scenario();
    assert_eq!(snapshot(inputs), before, "an input was modified");
    r
}

fn run(args: &[&str]) -> Output {
    Command::new(BIN)
        .arg("correct")
        .arg("-q")
        .args(args)
        .output()
        .unwrap()
}

fn code(o: &Output) -> i32 {
    o.status.code().unwrap_or(-1)
}

// --- 1. path safety ---------------------------------------------------------------------------------------------

#[test]
fn outputs_over_in_or_around_inputs_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 3);
    let nested_water = survey.join("water");
    std::fs::create_dir_all(&nested_water).unwrap();
    std::fs::copy(water.join("wc0.png"), nested_water.join("wc0.png")).unwrap();
    let elsewhere = d.path().join("elsewhere");
    let cases: Vec<(Vec<String>, &str)> = vec![
        // Issue 13: `..` after a folder that does not exist.
        (
            vec![
                "--out".into(),
                format!("{}/nonexistent/../survey", d.path().display()),
            ],
            "--out",
        ),
        // The report onto a photo.
        (
            vec![
                "--out".into(),
                s(&elsewhere).into(),
                "--report".into(),
                s(&survey.join("IMG_0002.png")).into(),
            ],
            "--report",
        ),
        // An output folder that contains the survey.
        (
            vec!["--out".into(), s(d.path()).into()],
            "contains the survey",
        ),
        // An output folder that contains the water column (which lies in the survey here).
        (
            vec![
                "--out".into(),
                s(&survey).into(),
                "--water-column".into(),
                s(&nested_water).into(),
            ],
            "--out",
        ),
    ];
    for (extra, needle) in cases {
        let o = untouched(&[&survey, &water], || {
            let mut args = vec!["--survey", s(&survey)];
            args.extend(extra.iter().map(String::as_str));
            run(&args)
        });
        assert_eq!(code(&o), 2, "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{extra:?}: {}", stderr(&o));
    }
    assert!(!elsewhere.exists(), "nothing is created before the checks");
}

#[cfg(unix)]
#[test]
fn writes_never_follow_a_link_out_of_the_output_folder() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 4);
    std::fs::create_dir_all(survey.join("a")).unwrap();
    pattern(32, 24, 9)
        .save(survey.join("a/IMG_0009.png"))
        .unwrap();
    let outside = d.path().join("outside");
    std::fs::create_dir_all(&outside).unwrap();
    let out = d.path().join("out");
    std::fs::create_dir_all(&out).unwrap();

    // `_abysslight` a link: refused up front, nothing written.
    std::os::unix::fs::symlink(&outside, out.join("_abysslight")).unwrap();
    let o = untouched(&[&survey, &water], || {
        run(&["--survey", s(&survey), "--out", s(&out), "--window", "3"])
    });
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("symbolic link"), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(&outside).unwrap().count(), 0);
    std::fs::remove_file(out.join("_abysslight")).unwrap();

    // A sub-folder a link: that photo fails (exit 1), the others are written, nothing lands outside.
    std::os::unix::fs::symlink(&outside, out.join("a")).unwrap();
    let o = untouched(&[&survey, &water], || {
        run(&["--survey", s(&survey), "--out", s(&out), "--window", "3"])
    });
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    assert!(stderr(&o).contains("symbolic link"), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(&outside).unwrap().count(), 0);
    assert!(out.join("IMG_0003.png").is_file());
    let r = report(&out);
    assert_eq!(r["failed"], 1);
}

#[cfg(unix)]
#[test]
fn a_survey_link_to_the_output_folder_is_not_read_back() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 4);
    let out = d.path().join("out");
    let o = run(&["--survey", s(&survey), "--out", s(&out), "--window", "3"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    std::os::unix::fs::symlink(&out, survey.join("old")).unwrap();
    let o = untouched(&[&water], || {
        run(&["--survey", s(&survey), "--out", s(&out), "--window", "3"])
    });
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    let r = report(&out);
    assert_eq!(r["survey_photos"], 4, "outputs were read back as photos");
    assert_eq!(r["corrected"], 4);
    assert!(r["errors"].to_string().contains("output folder"), "{r}");
}

// --- 2. decoding that notices missing data -----------------------------------------------------------------------

fn jpeg(w: u16, h: u16, restart: Option<u16>) -> Vec<u8> {
    let img = pattern(w as u32, h as u32, 3);
    let mut out = Vec::new();
    let mut enc = jpeg_encoder::Encoder::new(&mut out, 90);
    if let Some(r) = restart {
        enc.set_restart_interval(r);
    }
    enc.encode(img.as_raw(), w, h, jpeg_encoder::ColorType::Rgb)
        .unwrap();
    out
}

/// Cut at `frac` of the file and close with an end-of-image marker (issue 13's first truncation).
fn cut_with_eoi(j: &[u8], frac: f64) -> Vec<u8> {
    let mut v = j[..(j.len() as f64 * frac) as usize].to_vec();
    v.extend_from_slice(&[0xFF, 0xD9]);
    v
}

/// The tail from `frac` on replaced by zeros (a preallocated file after a power cut).
fn zero_tail(j: &[u8], frac: f64) -> Vec<u8> {
    let mut v = j.to_vec();
    let at = (j.len() as f64 * frac) as usize;
    v[at..].fill(0);
    v
}

#[test]
fn truncated_and_zero_padded_jpegs_are_errors_naming_the_file() {
    let d = tempfile::tempdir().unwrap();
    for restart in [None, Some(4)] {
        let good = jpeg(96, 64, restart);
        abysslight::io::check_jpeg(&good).unwrap();
        let p = d.path().join("good.jpg");
        std::fs::write(&p, &good).unwrap();
        assert!(decode(&p).is_ok());
        for (name, bytes) in [
            ("half.jpg", cut_with_eoi(&good, 0.5)),
            ("most.jpg", cut_with_eoi(&good, 0.9)),
            ("zeros.jpg", zero_tail(&good, 0.6)),
            ("zeros_late.jpg", zero_tail(&good, 0.98)),
            ("cut.jpg", good[..good.len() * 3 / 4].to_vec()),
        ] {
            let p = d.path().join(name);
            std::fs::write(&p, &bytes).unwrap();
            let e = decode(&p).unwrap_err().to_string();
            assert!(
                e.contains(name) && e.contains("JPEG"),
                "{restart:?} {name}: {e}"
            );
        }
    }
}

/// The frame marker (SOF0, SOF2, ...) of a JPEG, walking the header segments.
fn sof_marker(d: &[u8]) -> Option<u8> {
    let mut i = 2;
    while i + 4 <= d.len() && d[i] == 0xFF {
        let m = d[i + 1];
        if (0xC0..=0xCF).contains(&m) && ![0xC4, 0xC8, 0xCC].contains(&m) {
            return Some(m);
        }
        i += 2 + u16::from_be_bytes([d[i + 2], d[i + 3]]) as usize;
    }
    None
}

/// Real camera JPEGs (../shared/data/real) are never rejected, and their truncated forms always are.
#[test]
#[ignore = "needs ../shared/data/real beside the project (real photos are not shipped); .ci/run runs it where they are"]
fn real_jpegs_pass_and_their_truncations_fail() {
    // Beside the project (../shared), or beside the folder of worktrees (../../shared).
    let here = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let Some(root) = ["../shared/data/real", "../../shared/data/real"]
        .iter()
        .map(|r| here.join(r))
        .find(|p| p.is_dir())
    else {
        panic!("../shared/data/real is absent");
    };
    let mut files: Vec<PathBuf> = walkdir::WalkDir::new(&root)
        .into_iter()
        .flatten()
        .map(|e| e.into_path())
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| e.eq_ignore_ascii_case("jpg") || e.eq_ignore_ascii_case("jpeg"))
        })
        .collect();
    files.sort();
    // Every 4th file keeps the test short; all of them are checked in the report's measurement.
    let step = std::env::var("ABYSSLIGHT_ALL_REAL").map_or(4, |_| 1);
    let (mut checked, mut progressives) = (0, 0);
    let (mut t_check, mut t_decode) = (0.0, 0.0);
    for p in files.iter().step_by(step) {
        let bytes = std::fs::read(p).unwrap();
        let t = std::time::Instant::now();
        abysslight::io::check_jpeg(&bytes).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        t_check += t.elapsed().as_secs_f64();
        if step == 1 {
            // The measurement for the report: the check's share of a whole decode (which includes it).
            let t = std::time::Instant::now();
            decode(p).unwrap_or_else(|e| panic!("{e}"));
            t_decode += t.elapsed().as_secs_f64();
        }
        // A progressive JPEG cut between scans and closed is a valid, coarser JPEG: only baseline files can be
        // checked for that (see src/jpeg_check.rs); the zero-filled tail is noticed in both.
        let progressive = sof_marker(&bytes) == Some(0xC2);
        progressives += progressive as usize;
        let mut bad = vec![zero_tail(&bytes, 0.7)];
        if !progressive {
            bad.push(cut_with_eoi(&bytes, 0.5));
        }
        for bad in bad {
            assert!(
                abysslight::io::check_jpeg(&bad).is_err(),
                "{}: truncation not noticed",
                p.display()
            );
        }
        checked += 1;
    }
    eprintln!(
        "{checked} real JPEGs checked ({progressives} progressive); completeness check {:.1} ms per file, {:.0} % of a whole decode",
        1000.0 * t_check / checked.max(1) as f64,
        if t_decode > 0.0 { 100.0 * t_check / t_decode } else { f64::NAN }
    );
}

#[test]
fn absurd_sizes_are_refused_from_the_header() {
    let d = tempfile::tempdir().unwrap();
    // A small JPEG whose frame header is patched to declare 20000 x 20000.
    let mut j = jpeg(16, 16, None);
    let sof = j.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
    j[sof + 5..sof + 7].copy_from_slice(&20000u16.to_be_bytes());
    j[sof + 7..sof + 9].copy_from_slice(&20000u16.to_be_bytes());
    let p = d.path().join("huge.jpg");
    std::fs::write(&p, &j).unwrap();
    let e = decode(&p).unwrap_err().to_string();
    assert!(e.contains("huge.jpg") && e.contains("20000x20000"), "{e}");
    // A PNG header declaring 30000 x 30000 (its data is irrelevant: refused before decoding).
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&[0u8; 3], 1, 1, image::ExtendedColorType::Rgb8)
        .unwrap();
    png[16..20].copy_from_slice(&30000u32.to_be_bytes());
    png[20..24].copy_from_slice(&30000u32.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    let p = d.path().join("huge.png");
    std::fs::write(&p, &png).unwrap();
    let e = decode(&p).unwrap_err().to_string();
    assert!(e.contains("huge.png") && e.contains("30000x30000"), "{e}");
}

use image::ImageEncoder;

#[test]
fn huge_pnm_header_on_stdin_is_one_failed_frame_and_the_report_is_written() {
    let d = tempfile::tempdir().unwrap();
    let rep = d.path().join("report.json");
    let mut input = Vec::new();
    for i in 0..3u8 {
        input.extend_from_slice(b"P6 8 6 255\n");
        input.extend((0..8 * 6 * 3).map(|k| (k as u8).wrapping_mul(7).wrapping_add(i)));
    }
    input.extend_from_slice(b"P5 1000000 1000000 255\n");
    let mut child = Command::new(BIN)
        .args([
            "correct", "-q", "--survey", "-", "--out", "-", "--window", "3",
        ])
        .args(["--report", s(&rep)])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(&input).unwrap();
    }
    let o = child.wait_with_output().unwrap();
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    let r = json(&rep);
    assert_eq!(r["corrected"], 3);
    assert!(r["errors"].to_string().contains("1000000x1000000"), "{r}");
}

// --- 3. one stray entry never sinks the mission ------------------------------------------------------------------

#[cfg(unix)]
#[test]
fn stray_entries_are_named_skipped_entries() {
    use std::os::unix::ffi::OsStrExt;
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 4);
    std::os::unix::fs::symlink(d.path().join("gone"), survey.join("dangling.png")).unwrap();
    std::fs::create_dir_all(survey.join("loop")).unwrap();
    std::os::unix::fs::symlink(&survey, survey.join("loop/back")).unwrap();
    let bad_name = std::ffi::OsStr::from_bytes(b"IMG_\xff\xfe.png");
    std::fs::write(survey.join(bad_name), b"x").unwrap();
    let found = find_photos(&survey).unwrap();
    assert_eq!(found.photos.len(), 4, "{:?}", found.photos);
    let reasons: Vec<String> = found.skipped.iter().map(|s| s.reason.clone()).collect();
    assert_eq!(found.skipped.len(), 3, "{reasons:?}");
    for needle in ["dangling", "loop", "UTF-8"] {
        assert!(
            reasons.iter().any(|r| r.contains(needle)),
            "{needle}: {reasons:?}"
        );
    }
    // Through the binary: every photo corrected, the report written and naming them, exit 1.
    let out = d.path().join("out");
    let o = untouched(&[&survey], || {
        run(&["--survey", s(&survey), "--out", s(&out), "--window", "3"])
    });
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    let r = report(&out);
    assert_eq!(r["corrected"], 4);
    assert_eq!(r["errors"].as_array().unwrap().len(), 3, "{r}");
}

#[test]
fn the_mission_size_is_the_majority_of_the_first_headers() {
    let d = tempfile::tempdir().unwrap();
    let mut entries = Vec::new();
    // A thumbnail sorts first; then photos of the mission's size; a damaged file does not vote.
    for (i, (w, h)) in [(8, 6), (32, 24), (32, 24), (16, 12), (32, 24)]
        .iter()
        .enumerate()
    {
        let p = d.path().join(format!("p{i}.png"));
        pattern(*w, *h, i as u32).save(&p).unwrap();
        entries.push(Entry {
            relative: p.file_name().unwrap().into(),
            path: p,
        });
    }
    let junk = d.path().join("junk.png");
    std::fs::write(&junk, b"not a png").unwrap();
    entries.insert(
        0,
        Entry {
            relative: "junk.png".into(),
            path: junk,
        },
    );
    assert_eq!(majority_size(&entries, 15), Some((32, 24)));
    // Ties go to the earlier photo; only the first `sample` vote.
    assert_eq!(majority_size(&entries, 2), Some((8, 6)));
    assert_eq!(majority_size(&entries[..1], 15), None);
    let e = abysslight::io::decode_expecting(&entries[1].path, Some((32, 24)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("8x6") && e.contains("32x24"), "{e}");
}

/// Issue 57: a file-size limit (`ulimit -f`, `prlimit --fsize`, passed on by SLURM from the submitting shell)
/// costs the photos whose output outgrows it, each named, and the run goes on to write its report. Before, the
/// kernel's SIGXFSZ killed the process at the first such write (exit 153, no message, no report, a temp file left).
/// The limit is set by the shell's `ulimit -f` (512- or 1024-byte blocks by the shell: 20 or 40 KB here, between
/// the report's few KB and the noisy photos' 90 KB).
#[test]
fn a_file_size_limit_costs_the_files_that_outgrow_it_not_the_run() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = (d.path().join("survey"), d.path().join("water"));
    for dir in [&survey, &water] {
        std::fs::create_dir_all(dir).unwrap();
    }
    let mut state = 12345u32;
    let mut noise = |x: u32, y: u32, i: u32| {
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
        ((state >> 16) % 120) as u8 + ((x + y + i) % 60) as u8 + 40
    };
    for i in 0..5u32 {
        let img = image::RgbImage::from_fn(200, 150, |x, y| {
            image::Rgb([noise(x, y, i), noise(x, y, i), noise(x, y, i)])
        });
        img.save(survey.join(format!("IMG_{i:04}.png"))).unwrap();
        assert!(
            std::fs::metadata(survey.join(format!("IMG_{i:04}.png")))
                .unwrap()
                .len()
                > 60_000
        );
    }
    for i in 0..3u8 {
        image::RgbImage::from_pixel(200, 150, image::Rgb([10 + i, 12, 14]))
            .save(water.join(format!("wc{i}.png")))
            .unwrap();
    }
    let out = d.path().join("out");
    let o = untouched(&[&survey, &water], || {
        Command::new("sh")
            .args(["-c", "ulimit -f 40 && exec \"$0\" \"$@\""])
            .args([BIN, "correct", "--water-column"])
            .args([
                &water,
                Path::new("--survey"),
                &survey,
                Path::new("--out"),
                &out,
            ])
            .output()
            .unwrap()
    });
    let err = stderr(&o);
    // An ordinary exit, not a signal's; some photos failed.
    assert_eq!(o.status.code(), Some(1), "{err}");
    let too_large: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("File too large"))
        .collect();
    assert!(
        !too_large.is_empty(),
        "no write named as over the limit: {err}"
    );
    for line in &too_large {
        assert!(
            line.contains(s(&out)),
            "the error names the output file: {line}"
        );
    }
    // The report is written, with every photo in it as corrected or failed.
    let r = json(&out.join("_abysslight/report.json"));
    let failed = r["failed"].as_u64().unwrap() as usize;
    assert!(failed > 0, "{r}");
    assert_eq!(failed + r["corrected"].as_u64().unwrap() as usize, 5, "{r}");
    let errors = r["errors"].as_array().unwrap();
    assert_eq!(errors.len(), failed, "{r}");
    // Nothing half-written is left: every file in the output folder decodes, no temporary files.
    for e in std::fs::read_dir(&out).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        assert!(!name.contains("abysslight-tmp"), "temp file left: {name}");
        if p.is_file() {
            decode(&p).unwrap_or_else(|e| panic!("{name} is not a whole photo: {e}"));
        }
    }
}

// --- 4. numeric flags ----------------------------------------------------------------------------------------------

#[test]
fn the_numeric_flags_of_issue_13_are_usage_errors() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 3);
    let out = d.path().join("out");
    for (flag, value, extra) in [
        ("--downsample", "4294967296", None),
        ("--window", "999999999999999999", None),
        ("--idle-timeout", "1e300", Some("--watch")),
        ("--idle-timeout", "NaN", Some("--watch")),
        ("--factor-floor", "inf", None),
        ("--risk", "-0.5", None),
        ("--contamination", "nan", None),
        ("--poll-interval", "0", Some("--watch")),
        ("--threads", "0", None),
        ("--degree", "99", None),
        ("--jpeg-quality", "0", None),
        ("--shard", "1/99999999999", None),
        ("--near-window", "4", None),
        ("--near-window", "99999999", None),
    ] {
        let arg = format!("{flag}={value}");
        let o = untouched(&[&survey, &water], || {
            let mut args = vec!["--survey", s(&survey), "--out", s(&out), arg.as_str()];
            args.extend(extra);
            run(&args)
        });
        assert_eq!(code(&o), 2, "{flag} {value}: {}", stderr(&o));
        assert!(stderr(&o).contains(flag), "{flag} {value}: {}", stderr(&o));
        assert!(!out.exists(), "{flag} {value}: created the output folder");
    }
}

/// Values drawn for the numeric flags: in range, at the edges, absurd, and not numbers at all.
fn value() -> impl Strategy<Value = String> {
    prop_oneof![
        (0u64..20).prop_map(|v| v.to_string()),
        any::<u64>().prop_map(|v| v.to_string()),
        any::<i64>().prop_map(|v| v.to_string()),
        (-1.0f64..2.0).prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| v.to_string()),
        prop::sample::select(vec![
            "nan",
            "inf",
            "-inf",
            "1e300",
            "-0",
            "4294967296",
            "18446744073709551616",
            "0.5",
            "",
        ])
        .prop_map(String::from),
    ]
}

const NUMERIC_FLAGS: &[&str] = &[
    "--window",
    "--contamination",
    "--risk",
    "--downsample",
    "--near-window",
    "--factor-floor",
    "--jpeg-quality",
    "--threads",
    "--degree",
    "--idle-timeout",
    "--poll-interval",
    "--shard",
    "--seafloor-colour",
];

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]

    /// Random numbers into one numeric flag of `correct` at a time, through the binary on a tiny mission: the
    /// exit code is 0, 1 or 2, never a panic (101), and the inputs are untouched.
    #[test]
    fn random_numbers_never_panic(flag in prop::sample::select(NUMERIC_FLAGS), v in value(), k in value()) {
        let d = tempfile::tempdir().unwrap();
        let (survey, water) = tiny_mission(d.path(), 4);
        let out = d.path().join("out");
        let v = match flag {
            "--shard" => format!("{v}/{k}"),
            "--seafloor-colour" => format!("{v},{k},0.3"),
            _ => v,
        };
        // A valid idle timeout would make the watch wait that long: those values are covered by
        // `validate_decides_before_the_run`.
        prop_assume!(!(flag == "--idle-timeout" && v.parse::<f64>().is_ok_and(|t| t > 0.3 && t <= 1e9)));
        let arg = format!("{flag}={v}");
        let o = untouched(&[&survey, &water], || {
            let mut args = vec!["--survey", s(&survey), "--out", s(&out), "--water-column", s(&water)];
            if !matches!(flag, "--window" | "--contamination") {
                args.push("--window=3");
            }
            args.push(arg.as_str());
            match flag {
                "--idle-timeout" => args.push("--watch"),
                // A watch that ends at its first look when the value is valid.
                "--poll-interval" => args.extend(["--watch", "--idle-timeout=0"]),
                _ => {}
            }
            run(&args)
        });
        prop_assert!(matches!(code(&o), 0..=2), "{flag} {v}: exit {:?}: {}", o.status, stderr(&o));
    }

    /// Every numeric option through `Options::validate`: an error or a run that does not panic.
    #[test]
    fn validate_decides_before_the_run(window in any::<usize>(), downsample in any::<usize>(),
                                        floor in any::<f32>(), idle in any::<f64>(), poll in any::<u64>()) {
        let o = Options { window: Some(window), downsample: Some(downsample), factor_floor: floor, idle_timeout: Some(idle),
                          poll_interval: poll, watch: true, ..Options::default() };
        if o.validate().is_ok() {
            prop_assert!(window % 2 == 1 && window <= abysslight::limits::WINDOW);
            prop_assert!((1..=abysslight::limits::DOWNSAMPLE).contains(&downsample));
            prop_assert!(floor > 0.0 && floor <= 1.0);
            prop_assert!((0.0..=abysslight::limits::IDLE_TIMEOUT_S).contains(&idle));
            prop_assert!(poll >= 1);
            // What the watch does with them must not panic.
            let _ = std::time::Duration::from_secs_f64(idle);
        }
    }
}

// --- 5. resume and concurrency ---------------------------------------------------------------------------------------

#[test]
fn a_concurrent_run_and_other_options_are_refused_stale_temps_removed() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 4);
    let out = d.path().join("out");
    let o = run(&["--survey", s(&survey), "--out", s(&out), "--window", "3"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let work = out.join("_abysslight");

    // Another options set into the same folder: refused, naming the option.
    let o = untouched(&[&survey, &water, &out], || {
        run(&[
            "--survey",
            s(&survey),
            "--out",
            s(&out),
            "--window",
            "5",
            "--resume",
        ])
    });
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("window"), "{}", stderr(&o));

    // A live run holds the lock (this test process stands in for it: the lock is the operating system's).
    let held = std::fs::OpenOptions::new()
        .write(true)
        .open(work.join("lock"))
        .unwrap();
    held.lock().unwrap();
    let o = untouched(&[&survey, &water], || {
        run(&["--survey", s(&survey), "--out", s(&out), "--window", "3"])
    });
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("another abysslight run"),
        "{}",
        stderr(&o)
    );
    drop(held);

    // A killed run's temp files are removed by the next run; the same options with --resume are welcome.
    let stale = out.join(".IMG_0001.png.Ab12Cd.abysslight-tmp");
    std::fs::write(&stale, b"half a photo").unwrap();
    let o = untouched(&[&survey, &water], || {
        run(&[
            "--survey",
            s(&survey),
            "--out",
            s(&out),
            "--window",
            "3",
            "--resume",
        ])
    });
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(!stale.exists());
    let lock = std::fs::File::open(work.join("lock")).unwrap();
    assert!(lock.try_lock().is_ok(), "the lock is released at the end");
}

#[test]
fn library_run_refuses_the_same_paths() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = tiny_mission(d.path(), 3);
    let opts = Options {
        survey: Some(survey.clone()),
        out: Some(d.path().join("x/../survey/out")),
        ..Options::default()
    };
    let e = untouched(&[&survey, &water], || {
        abysslight::correct_mission(&opts, &Silent).unwrap_err()
    });
    assert!(matches!(e, abysslight::Error::Usage(_)), "{e}");
}

// --- files read whole: regular files within their limit; inputs recorded by content ----------------------------

/// `abysslight correct -q ARGS` in `cwd`, stopped after `secs`: a run that blocks fails the test instead of
/// hanging it.
fn run_within(args: &[&str], cwd: &Path, secs: u64) -> Output {
    command_within(&[&["correct", "-q"][..], args].concat(), cwd, secs)
}

/// `abysslight ARGS` run in `cwd`, killed (and the test failed) if it has not finished within `secs` seconds.
fn command_within(args: &[&str], cwd: &Path, secs: u64) -> Output {
    use std::process::Stdio;
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed().as_secs() >= secs {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!("blocked for {secs} s: {args:?}: {}", stderr(&o));
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

#[cfg(unix)]
fn mkfifo(p: &Path) {
    let ok = Command::new("mkfifo").arg(p).status().unwrap().success();
    assert!(ok, "mkfifo {}", p.display());
}

#[cfg(unix)]
#[test]
fn a_fifo_or_a_device_given_as_a_file_is_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 4);
    let fifo = d.path().join("nav.csv");
    mkfifo(&fifo);
    let zero = d.path().join("zero.csv");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let out = d.path().join("out");
    let base = ["--survey", s(&survey), "--out", s(&out)];
    fn with<'a>(base: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
        [base, extra].concat()
    }
    for (flag, file, kind) in [
        ("--navigation", &fifo, "a FIFO"),
        ("--navigation", &zero, "a device"),
        ("--config", &fifo, "a FIFO"),
        ("--config", &zero, "a device"),
        ("--mask", &fifo, "a FIFO"),
        ("--mask", &zero, "a device"),
        ("--scatter", &fifo, "a FIFO"),
        ("--scatter", &zero, "a device"),
    ] {
        let o = run_within(&with(&base, &[flag, s(file)]), d.path(), 60);
        assert_eq!(code(&o), 2, "{flag} {}: {}", file.display(), stderr(&o));
        assert!(
            stderr(&o).contains(s(file)) && stderr(&o).contains(kind),
            "{flag}: {}",
            stderr(&o)
        );
    }
    // A config file past its limit (1 MiB) is refused, not read on.
    let cfg = d.path().join("big.toml");
    std::fs::write(&cfg, "#".repeat((1 << 20) + 1)).unwrap();
    let o = run_within(&with(&base, &["--config", s(&cfg)]), d.path(), 60);
    assert!(
        code(&o) == 2 && stderr(&o).contains("longer than 1048576 bytes"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists(), "nothing written");
}

#[cfg(unix)]
#[test]
fn a_cruise_log_that_is_a_folder_or_a_fifo_is_that_dives_error() {
    let d = tempfile::tempdir().unwrap();
    let cruise = d.path().join("cruise");
    tiny_mission(&cruise.join("d1"), 4);
    let nav = cruise.join("d1").join("navigation.csv");
    std::fs::create_dir(&nav).unwrap();
    let dives = abysslight::cruise::find_dives(&cruise).unwrap();
    assert_eq!(dives[0].navigation.as_deref(), Some(nav.as_path()));
    let out = d.path().join("out");
    let o = run_within(&["--cruise", s(&cruise), "--out", s(&out)], d.path(), 60);
    assert_ne!(code(&o), 0, "{}", stderr(&o));
    assert!(
        stderr(&o).contains(s(&nav)) && stderr(&o).contains("a folder"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_dir(&nav).unwrap();
    mkfifo(&nav);
    let o = run_within(
        &["--cruise", s(&cruise), "--out", s(&d.path().join("out2"))],
        d.path(),
        60,
    );
    assert_ne!(code(&o), 0, "{}", stderr(&o));
    assert!(stderr(&o).contains("a FIFO"), "{}", stderr(&o));
}

#[test]
fn shards_that_read_other_logs_or_masks_do_not_mix() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 8);
    let names: Vec<String> = (0..8).map(|i| format!("IMG_{i:04}.png")).collect();
    let log = |phase: usize| {
        let rows: String = (names.iter().enumerate())
            .map(|(i, n)| format!("{n},{}\n", 2 + (i + phase) % 2))
            .collect();
        format!("file,altitude\n{rows}")
    };
    // Two folders, each with its own nav.csv.
    let (a, b) = (d.path().join("a"), d.path().join("b"));
    for (dir, phase) in [(&a, 0), (&b, 1)] {
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(dir.join("nav.csv"), log(phase)).unwrap();
    }
    let out = d.path().join("out");
    let shard = |cwd: &Path, nav: &str, k: &str, extra: &[&str]| {
        let args = [
            &["--survey", s(&survey), "--out", s(&out), "--window", "3"][..],
            &["--navigation", nav, "--shard", k],
            extra,
        ]
        .concat();
        run_within(&args, cwd, 300)
    };
    let merge = || {
        Command::new(BIN)
            .args(["merge-shards", s(&out)])
            .output()
            .unwrap()
    };
    // The same name in two folders: two logs.
    let o = shard(&a, "nav.csv", "1/2", &[]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let o = shard(&b, "nav.csv", "2/2", &[]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("--navigation"), "{}", stderr(&o));
    // `./nav.csv` is `nav.csv`: the shards merge.
    let o = shard(&a, "./nav.csv", "2/2", &[]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let m = merge();
    assert!(m.status.success(), "{}", stderr(&m));
    let r = report(&out);
    assert_eq!(
        r["options"]["navigation"].as_str(),
        Some(s(&std::fs::canonicalize(a.join("nav.csv")).unwrap()))
    );
    assert_eq!(
        r["options"]["navigation-sha256"].as_str().map(str::len),
        Some(64)
    );
    // The log edited between the shards: refused by the run, and by the merge where the record is gone.
    std::fs::write(a.join("nav.csv"), log(1)).unwrap();
    let o = shard(&a, "nav.csv", "2/2", &[]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("the content (SHA-256) of --navigation"),
        "{}",
        stderr(&o)
    );
    std::fs::remove_file(out.join("_abysslight/options.json")).unwrap();
    let o = shard(&a, "nav.csv", "2/2", &[]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let m = merge();
    assert!(!m.status.success(), "{}", stderr(&m));
    assert!(stderr(&m).contains("navigation-sha256"), "{}", stderr(&m));

    // A mask edited between the shards.
    let mask = d.path().join("mask.png");
    image::GrayImage::new(32, 24).save(&mask).unwrap();
    let out2 = d.path().join("out2");
    let masked = |k: &str| {
        run_within(
            &[
                "--survey",
                s(&survey),
                "--out",
                s(&out2),
                "--mask",
                "mask.png",
                "--shard",
                k,
            ],
            d.path(),
            300,
        )
    };
    let o = masked("1/2");
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    image::GrayImage::from_fn(32, 24, |x, _| image::Luma([if x < 3 { 255 } else { 0 }]))
        .save(&mask)
        .unwrap();
    let o = masked("2/2");
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("the content (SHA-256) of --mask"),
        "{}",
        stderr(&o)
    );
}

/// `merge-shards` reads the shards' reports whole: one that is a link to `/dev/zero` or a FIFO is refused by name,
/// not read until out of memory or waited on.
#[cfg(unix)]
#[test]
fn a_shard_report_that_is_a_device_or_a_fifo_is_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 6);
    let out = d.path().join("out");
    for k in ["1/2", "2/2"] {
        let args = [
            "--survey",
            s(&survey),
            "--out",
            s(&out),
            "--window",
            "3",
            "--shard",
            k,
        ];
        let o = run_within(&args, d.path(), 300);
        assert_eq!(code(&o), 0, "{}", stderr(&o));
    }
    let shard_report = out.join("_abysslight").join("report-shard-1-of-2.json");
    assert!(shard_report.is_file(), "the shard left its report");
    // Without its lock the shard counts as finished, so its report is read.
    let _ = std::fs::remove_file(out.join("_abysslight").join("lock-shard-1-of-2"));
    for (kind, make) in [
        (
            "a device",
            &(|p: &Path| std::os::unix::fs::symlink("/dev/zero", p).unwrap()) as &dyn Fn(&Path),
        ),
        ("a FIFO", &(|p: &Path| mkfifo(p)) as &dyn Fn(&Path)),
    ] {
        std::fs::remove_file(&shard_report).unwrap();
        make(&shard_report);
        let o = command_within(&["merge-shards", s(&out)], d.path(), 60);
        assert_ne!(code(&o), 0, "{kind}: {}", stderr(&o));
        assert!(
            stderr(&o).contains("report-shard-1-of-2.json") && stderr(&o).contains(kind),
            "{kind}: {}",
            stderr(&o)
        );
    }
}

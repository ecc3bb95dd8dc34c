//! Navigation logs as vehicles write them (`--navigation`): DVL dropouts, a units row, `;` with local offsets,
//! unusual column names, a clock offset, photos missing from the log, conflicting duplicate times, a million
//! rows. Each shape is read, or refused with a message that says what to do.

use crate::common::*;

use std::path::{Path, PathBuf};

use abysslight::io::navigation::{Navigation, ReadAs};

/// `n` JPEG photos (`IMG_0000.jpg`…) whose EXIF `DateTimeOriginal` is 2023-06-03 10:00:00 plus 2 s per photo
/// (no offset: UTC), in `root/survey`; returns the folder.
fn timed_mission(root: &Path, n: usize) -> PathBuf {
    use exif::{Field, In, Tag, Value};
    let survey = root.join("survey");
    std::fs::create_dir_all(&survey).unwrap();
    for i in 0..n {
        let s = 2 * i;
        let field = Field {
            tag: Tag::DateTimeOriginal,
            ifd_num: In::PRIMARY,
            value: Value::Ascii(vec![
                format!("2023:06:03 10:{:02}:{:02}", s / 60, s % 60).into_bytes()
            ]),
        };
        let mut w = exif::experimental::Writer::new();
        w.push_field(&field);
        let mut blob = std::io::Cursor::new(Vec::new());
        w.write(&mut blob, true).unwrap();
        let img = pattern(32, 24, i as u32);
        let mut out = Vec::new();
        let mut enc = jpeg_encoder::Encoder::new(&mut out, 95);
        enc.add_app_segment(1, [&b"Exif\0\0"[..], &blob.into_inner()].concat())
            .unwrap();
        enc.encode(img.as_raw(), 32, 24, jpeg_encoder::ColorType::Rgb)
            .unwrap();
        std::fs::write(survey.join(format!("IMG_{i:04}.jpg")), out).unwrap();
    }
    survey
}

/// 2023-06-03 10:00:00 UTC, seconds since 1970 (Python: calendar.timegm).
const T0: f64 = 1_685_786_400.0;

/// A log at 1 Hz from 2 s before the first photo of [`timed_mission`] to 2 s after its last, times as `time(t)`
/// writes them, with `row(k, t)` the rest of row `k`: the altitude 2 m plus 1 cm a second.
fn log_rows(n: usize, time: impl Fn(f64) -> String, sep: &str) -> String {
    let rows = 2 * n + 3;
    (0..rows)
        .map(|k| {
            let t = T0 - 2.0 + k as f64;
            format!("{}{sep}{:.2}\n", time(t), 2.0 + 0.01 * k as f64)
        })
        .collect()
}

fn correct(survey: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["correct", "--survey", s(survey), "--out", s(out)];
    args.extend_from_slice(extra);
    abysslight(&args)
}

fn altitudes(out: &Path) -> Vec<Option<f64>> {
    report(out)["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["altitude"].as_f64())
        .collect()
}

#[test]
fn dropout_rows_are_passed_over_counted_and_bridged() {
    let d = tempfile::tempdir().unwrap();
    let survey = timed_mission(d.path(), 6);
    // A DVL by time at 1 Hz: no bottom lock for four rows (0, NaN, empty, -1), between photos 1 and 2.
    let mut rows: Vec<String> = log_rows(6, |t| format!("{t:.1}"), ",")
        .lines()
        .map(str::to_string)
        .collect();
    for (k, bad) in [(5, "0"), (6, "NaN"), (7, ""), (8, "-1")] {
        let t = rows[k].split(',').next().unwrap().to_string();
        rows[k] = format!("{t},{bad}");
    }
    let nav = d.path().join("dvl.csv");
    std::fs::write(&nav, format!("time,altitude\n{}\n", rows.join("\n"))).unwrap();
    let out = d.path().join("out");
    let o = correct(&survey, &out, &["--navigation", s(&nav)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("4 of 15 rows give no altitude") && err.contains("line 7, 8, 9"),
        "{err}"
    );
    // Photo k at row 2 + 2k: 2 m + 1 cm a second; photo 2 (row 6, a dropout) interpolated over the 5 s gap
    // between rows 5 and 10, on the same line.
    let got = altitudes(&out);
    for (k, a) in got.iter().enumerate() {
        let want = 2.0 + 0.01 * (2 + 2 * k) as f64;
        assert!((a.unwrap() - want).abs() < 1e-4, "photo {k}: {a:?} {want}");
    }
    // Too few usable rows: refused, saying what to check.
    std::fs::write(&nav, "time,altitude\n1,0\n2,NaN\n3,7\n").unwrap();
    let o = correct(&survey, &d.path().join("o2"), &["--navigation", s(&nav)]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("1 of 3 rows give a usable altitude")
            && stderr(&o).contains("--navigation-columns altitude=NAME"),
        "{}",
        stderr(&o)
    );
    // Implausible values: refused at their line.
    for bad in ["9999", "1e30"] {
        std::fs::write(&nav, format!("time,altitude\n1,3\n2,{bad}\n")).unwrap();
        let o = correct(&survey, &d.path().join("o3"), &["--navigation", s(&nav)]);
        assert_eq!(o.status.code(), Some(2), "{bad}");
        assert!(
            stderr(&o).contains(s(&nav))
                && stderr(&o).contains("line 3")
                && stderr(&o).contains(bad),
            "{}",
            stderr(&o)
        );
    }
}

#[test]
fn a_units_row_semicolons_local_offsets_and_unusual_names() {
    let d = tempfile::tempdir().unwrap();
    let survey = timed_mission(d.path(), 6);
    // A sledge's log: `;`, a comment, a units row, dates in local time (UTC+2), and the names it chose.
    let local = |t: f64| {
        let s = (t - T0) as i64 + 2 * 3600;
        format!(
            "2023-06-03T{:02}:{:02}:{:02}+02:00",
            10 + s / 3600,
            (s / 60) % 60,
            s % 60
        )
    };
    let rows = log_rows(6, local, ";");
    let nav = d.path().join("sledge.csv");
    let text = format!("# sledge 7, dive 42\nDate Time;dvl_altitude_m\ns;m\n{rows}");
    std::fs::write(&nav, &text).unwrap();
    let out = d.path().join("out");
    let o = correct(&survey, &out, &["--navigation", s(&nav)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!((altitudes(&out)[1].unwrap() - 2.04).abs() < 1e-4);

    // Names no rule finds: refused with the way out, then read as the user names them.
    let renamed = text.replace("Date Time;dvl_altitude_m", "t_log;range");
    std::fs::write(&nav, &renamed).unwrap();
    let o = correct(&survey, &d.path().join("o2"), &["--navigation", s(&nav)]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("\"t_log;range\"") && stderr(&o).contains("--navigation-columns"),
        "{}",
        stderr(&o)
    );
    let named = d.path().join("o3");
    let o = correct(
        &survey,
        &named,
        &[
            "--navigation",
            s(&nav),
            "--navigation-columns",
            "time=T_LOG,altitude=range",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(altitudes(&named), altitudes(&out));
    // The same from a config file, as a table.
    let cfg = d.path().join("run.toml");
    std::fs::write(
        &cfg,
        "navigation = \"sledge.csv\"\n[navigation-columns]\ntime = \"t_log\"\naltitude = \"range\"\n",
    )
    .unwrap();
    let from_cfg = d.path().join("o4");
    let o = correct(&survey, &from_cfg, &["--config", s(&cfg)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(altitudes(&from_cfg), altitudes(&out));
    // A column named that the log lacks.
    std::fs::write(&nav, &text).unwrap();
    let o = correct(
        &survey,
        &d.path().join("o5"),
        &[
            "--navigation",
            s(&nav),
            "--navigation-columns",
            "altitude=alt",
        ],
    );
    assert!(
        stderr(&o).contains("no column named \"alt\""),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_log_on_another_clock_says_both_spans_and_takes_an_offset() {
    let d = tempfile::tempdir().unwrap();
    let survey = timed_mission(d.path(), 6);
    // The log's clock 2 h ahead of the camera's.
    let nav = d.path().join("auv.csv");
    let rows = log_rows(6, |t| format!("{:.1}", t + 7200.0), ",");
    std::fs::write(&nav, format!("timestamp,altitude\n{rows}")).unwrap();
    let o = correct(&survey, &d.path().join("o1"), &["--navigation", s(&nav)]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.contains("log 2023-06-03 11:59:58Z to 12:00:12Z")
            || err.contains("log 2023-06-03 11:59:58Z to 2023-06-03 12:00:12Z"),
        "{err}"
    );
    assert!(
        err.contains("photos 2023-06-03 10:00:00Z to 2023-06-03 10:00:10Z")
            && err.contains("2.0 h apart")
            && err.contains("--navigation-clock-offset -7200"),
        "{err}"
    );
    let out = d.path().join("o2");
    let o = correct(
        &survey,
        &out,
        &[
            "--navigation",
            s(&nav),
            "--navigation-clock-offset",
            "-7200",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!((altitudes(&out)[0].unwrap() - 2.02).abs() < 1e-4);
    // Clocks that agree, but rows too far apart around every photo: the gaps are named, not the clocks.
    std::fs::write(
        &nav,
        format!("time,altitude\n{},3\n{},3\n", T0 - 5.0, T0 + 15.0),
    )
    .unwrap();
    let o = correct(&survey, &d.path().join("o4"), &["--navigation", s(&nav)]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("the photos fall in its gaps (rows more than 10 s apart)"),
        "{}",
        stderr(&o)
    );
    std::fs::write(&nav, format!("timestamp,altitude\n{rows}")).unwrap();
    // A config key too.
    let cfg = d.path().join("run.toml");
    std::fs::write(
        &cfg,
        "navigation = \"auv.csv\"\nnavigation-clock-offset = -7200\n",
    )
    .unwrap();
    let o = correct(&survey, &d.path().join("o3"), &["--config", s(&cfg)]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn a_photo_missing_from_the_log_and_conflicting_times_are_said() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 12);
    // By name, photo 5 missing: the photos whose window holds it keep the window over time.
    let rows: String = (0..12)
        .filter(|&i| i != 5)
        .map(|i| format!("IMG_{i:04}.png,{:.1}\n", 2.0 + (i % 3) as f64))
        .collect();
    let nav = d.path().join("nav.csv");
    std::fs::write(&nav, format!("file,altitude\n{rows}")).unwrap();
    let o = correct(
        &survey,
        &d.path().join("o1"),
        &["--navigation", s(&nav), "--window", "5"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    // Centred windows of 5 over 12 photos hold photo 5 for photos 3 to 7.
    assert!(
        stderr(&o).contains("does not list 1 of the 12 survey photos (e.g. IMG_0005.png)")
            && stderr(&o).contains("5 photos lose windows by altitude (windows of 5 photos)"),
        "{}",
        stderr(&o)
    );
    // The dry run gives the altitudes' range.
    let o = correct(
        &survey,
        &d.path().join("o2"),
        &["--navigation", s(&nav), "--dry-run"],
    );
    assert!(
        stdout(&o).contains("gives the altitude of 11 of the 12 survey photos (2.00 to 4.00 m)"),
        "{}",
        stdout(&o)
    );
    // By time, a time listed twice with different altitudes: the first row is taken, with a warning.
    let survey = timed_mission(&d.path().join("timed"), 4);
    let rows = log_rows(4, |t| format!("{t:.1}"), ",");
    let nav = d.path().join("dup.csv");
    std::fs::write(&nav, format!("time,altitude\n{rows}{T0:.1},7.5\n")).unwrap();
    let out = d.path().join("o3");
    let o = correct(&survey, &out, &["--navigation", s(&nav)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o)
            .contains("1 time(s) are listed twice with different altitudes (e.g. lines 4 and 13")
            && stderr(&o).contains("the first row of each is taken"),
        "{}",
        stderr(&o)
    );
    assert!((altitudes(&out)[0].unwrap() - 2.02).abs() < 1e-4);
}

#[test]
fn a_million_rows_by_name_read_in_seconds() {
    let d = tempfile::tempdir().unwrap();
    let nav = d.path().join("big.csv");
    let mut text = String::from("Imagenumber,Depth [m],Altitude [m],relative_path\n");
    for i in 0..1_000_000u32 {
        text += &format!(
            "{i},4000.5,{:.3},image/PR_{i:07}_LC16.tif\n",
            2.0 + (i % 1000) as f64 / 1000.0
        );
    }
    std::fs::write(&nav, text).unwrap();
    let t = std::time::Instant::now();
    let log = Navigation::read(&nav, &ReadAs::default()).unwrap();
    let took = t.elapsed().as_secs_f64();
    assert_eq!(log.len(), 1_000_000);
    for i in [0u32, 1, 499_999, 999_999] {
        let want = 2.0 + (i % 1000) as f32 / 1000.0;
        let name = format!("PR_{i:07}_LC16.tif");
        assert_eq!(log.altitude_by_name(&name), Some(want), "{name}");
        // By the name without the extension.
        let png = format!("PR_{i:07}_LC16.png");
        assert_eq!(log.altitude_by_name(&png), Some(want), "{png}");
    }
    assert_eq!(log.altitude_by_name("PR_1000000_LC16.tif"), None);
    // 16 s before the log was read as a table (measured with the command: docs/guide.md); a loose bound for a
    // busy machine.
    assert!(took < 10.0, "{took} s");
}

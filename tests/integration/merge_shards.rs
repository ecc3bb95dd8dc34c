//! `merge-shards`: the report and pictures of a sharded mission, as one run writes them; and refusals that name
//! the shard that is missing, unfinished or ran with other options. Also `--cruise` through the library.

use crate::common;

use std::path::{Path, PathBuf};

use abysslight::merge_shards;
use abysslight::{correct_mission, Options, Photo, Shard, Silent};
use common::*;
use serde_json::Value;

fn opts(root: &Path, out: &str) -> Options {
    Options {
        survey: Some(root.join("survey")),
        out: Some(root.join(out)),
        window: Some(5),
        // Without the per-photo gain the overexposed photo is flagged (with it, its exposure is absorbed).
        photo_gain: false,
        ..Options::default()
    }
}

fn run_shard(root: &Path, out: &str, index: usize, count: usize, o: Options) {
    let o = Options {
        shard: Some(Shard { index, count }),
        ..o
    };
    correct_mission(&o, &Silent).unwrap();
    assert!(root
        .join(out)
        .join(format!("_abysslight/report-shard-{index}-of-{count}.json"))
        .is_file());
}

/// `photo` twice as bright: an exposure jump the monitor flags.
fn brighter(photo: &Photo) -> Photo {
    let mut p = photo.clone();
    if let abysslight::Samples::U8(v) = &mut p.samples {
        for s in v.iter_mut() {
            *s = s.saturating_mul(2);
        }
    }
    p
}

/// A dive of 24 photos, one corrupt (img9) and one overexposed (img17), written to `root/survey`.
fn mission(root: &Path) {
    let mut d = dive(48, 32, 24, 0, 0.2, false, 33);
    d.photos[16] = brighter(&d.photos[16]);
    write_all(&d.photos, &root.join("survey"), "img", "png");
    std::fs::write(root.join("survey/img9.png"), b"\x89PNG broken").unwrap();
}

#[test]
fn merged_report_and_pictures_equal_one_run() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    mission(root);
    let one = correct_mission(&opts(root, "one"), &Silent).unwrap();
    assert_eq!((one.corrected, one.failed), (23, 1));
    assert!(
        one.monitor.exposure_jump >= 1,
        "the overexposed photo is flagged: {:?}",
        one.monitor
    );
    let mut sheets_compared = 0;
    for count in [3usize, 4] {
        let out = format!("sharded{count}");
        for index in 1..=count {
            run_shard(root, &out, index, count, opts(root, &out));
        }
        let m = merge_shards(&root.join(&out)).unwrap();
        assert_eq!(
            (m.shards, m.frames, m.corrected, m.failed),
            (count, 23, 23, 1)
        );
        assert_eq!(outputs(&root.join("one")), outputs(&root.join(&out)));
        let (a, b) = (report(&root.join("one")), report(&root.join(&out)));
        // The same keys in the same order as one run's report.
        let keys = |v: &Value| v.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
        assert_eq!(keys(&a), keys(&b));
        for k in [
            "survey_photos",
            "corrected",
            "failed",
            "water_column_failed",
            "errors",
            "layout",
            "window",
        ] {
            assert_eq!(a[k], b[k], "{k} with {count} shards");
        }
        assert_eq!(b["options"]["shard"], Value::Null);
        assert_eq!(
            b["report_path"].as_str().map(PathBuf::from),
            Some(root.join(&out).join("_abysslight/report.json"))
        );
        // Every photo once, in mission order, at the position and with the window of one run.
        let frames = |v: &Value| -> Vec<(Value, Value, Value)> {
            v["frames"]
                .as_array()
                .unwrap()
                .iter()
                .map(|f| (f["input"].clone(), f["index"].clone(), f["window"].clone()))
                .collect()
        };
        assert_eq!(frames(&a), frames(&b), "{count} shards");
        // The overexposed photo (far from every shard's first photos) is flagged as in one run; the merged
        // sheet shows the photos one run shows.
        let flagged = |v: &Value| -> Vec<Value> {
            v["frames"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|f| {
                    f["health"]["flags"]
                        .as_array()
                        .is_some_and(|x| !x.is_empty())
                })
                .map(|f| f["input"].clone())
                .collect()
        };
        let one_flagged = flagged(&a);
        let img17 = Value::from(root.join("survey/img17.png").to_str().unwrap());
        assert!(one_flagged.contains(&img17) && flagged(&b).contains(&img17));
        if flagged(&b) == one_flagged {
            sheets_compared += 1;
            let sheet =
                |dir: &str| std::fs::read(root.join(dir).join("_abysslight/flagged.png")).unwrap();
            assert!(
                sheet("one") == sheet(&out),
                "flagged.png differs with {count} shards"
            );
        }
        assert!(root.join(&out).join("_abysslight/overview.png").is_file());
        assert_eq!(
            b["monitor"]["flagged"].as_u64(),
            Some(flagged(&b).len() as u64)
        );
    }
    assert!(
        sheets_compared > 0,
        "no sharding flagged the photos one run flagged"
    );
}

fn expect_error(out: &Path, needles: &[&str]) {
    let e = merge_shards(out).unwrap_err().to_string();
    for n in needles {
        assert!(e.contains(n), "{n:?} not in: {e}");
    }
    assert!(
        !out.join("_abysslight/report.json").exists(),
        "a report was written: {e}"
    );
}

#[test]
fn a_missing_or_unfinished_shard_is_named() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    mission(root);
    for k in [1, 2, 4] {
        run_shard(root, "out", k, 4, opts(root, "out"));
    }
    let work = root.join("out/_abysslight");
    expect_error(&root.join("out"), &["shard 3/4 is missing", "--shard 3/4"]);
    // A killed shard 3: it left its lock (the pid of a process that is gone) and no report.
    std::fs::write(
        work.join("lock-shard-3-of-4"),
        r#"{"pid": 4194300, "options": {}}"#,
    )
    .unwrap();
    expect_error(
        &root.join("out"),
        &["shard 3/4 has not finished", "lock-shard-3-of-4", "4194300"],
    );
    // A finished shard whose rerun was killed: its old report does not count while the lock is there.
    run_shard(root, "out", 2, 4, opts(root, "out"));
    std::fs::write(work.join("lock-shard-2-of-4"), r#"{"pid": 4194301}"#).unwrap();
    let e = merge_shards(&root.join("out")).unwrap_err().to_string();
    assert!(
        e.contains("shard 2/4 has not finished") && e.contains("shard 3/4 has not finished"),
        "{e}"
    );
    // The rerun takes the stale locks over; then the merge goes through.
    std::fs::remove_file(work.join("lock-shard-2-of-4")).unwrap();
    run_shard(root, "out", 3, 4, opts(root, "out"));
    // Its lock file stays (the lock is the operating system's, released when the run ended); its report is newer.
    assert!(work.join("lock-shard-3-of-4").exists());
    assert_eq!(merge_shards(&root.join("out")).unwrap().frames, 23);
    // Reports of another shard count in the same folder.
    std::fs::copy(
        work.join("report-shard-1-of-4.json"),
        work.join("report-shard-1-of-5.json"),
    )
    .unwrap();
    expect_error_keeping(&root.join("out"), &["different counts", "of-4", "of-5"]);
}

/// As [`expect_error`] where an earlier merge's report may be there.
fn expect_error_keeping(out: &Path, needles: &[&str]) {
    let e = merge_shards(out).unwrap_err().to_string();
    for n in needles {
        assert!(e.contains(n), "{n:?} not in: {e}");
    }
}

#[test]
fn shards_with_other_options_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    mission(root);
    for k in 1..=3 {
        run_shard(root, "out", k, 3, opts(root, "out"));
    }
    // Shard 2 again, with another window, into another folder (the folder's own guard refuses mixing), its
    // report then put beside the others.
    let other = Options {
        window: Some(7),
        ..opts(root, "other")
    };
    run_shard(root, "other", 2, 3, other);
    std::fs::copy(
        root.join("other/_abysslight/report-shard-2-of-3.json"),
        root.join("out/_abysslight/report-shard-2-of-3.json"),
    )
    .unwrap();
    expect_error(
        &root.join("out"),
        &["shard 2/3 ran with other options than shard 1/3", "window"],
    );
    // Only the options that decide the pixels count: another thread count merges.
    let threads = Options {
        threads: Some(1),
        ..opts(root, "out")
    };
    run_shard(root, "out", 2, 3, threads);
    assert_eq!(merge_shards(&root.join("out")).unwrap().frames, 23);
}

#[test]
fn not_a_sharded_folder() {
    let d = tempfile::tempdir().unwrap();
    let e = merge_shards(d.path()).unwrap_err().to_string();
    assert!(e.contains("no _abysslight folder"), "{e}");
    std::fs::create_dir(d.path().join("_abysslight")).unwrap();
    let e = merge_shards(d.path()).unwrap_err().to_string();
    assert!(e.contains("no shard reports"), "{e}");
}

#[test]
fn a_cruise_is_corrected_dive_by_dive() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    for (i, name) in ["dive2", "dive10"].iter().enumerate() {
        let dv = dive(40, 24, 9, 5, 0.2, false, 50 + i as u64);
        write_all(
            &dv.photos,
            &root.join("cruise").join(name).join("survey"),
            "img",
            "png",
        );
        write_all(
            &dv.water,
            &root.join("cruise").join(name).join("water-column"),
            "wc",
            "png",
        );
    }
    std::fs::create_dir_all(root.join("cruise/notes")).unwrap();
    let dives = abysslight::cruise::find_dives(&root.join("cruise")).unwrap();
    let names: Vec<&str> = dives.iter().map(|d| d.name.as_str()).collect();
    assert_eq!(
        names,
        ["dive2", "dive10"],
        "natural order, folders without survey/ passed over"
    );
    let base = Options {
        out: Some(root.join("out")),
        window: Some(5),
        ..Options::default()
    };
    let results = abysslight::cruise::correct_cruise(&base, &root.join("cruise"), &Silent).unwrap();
    for (dive, r) in results {
        let r = r.unwrap();
        assert_eq!((r.corrected, r.scatter.frames), (9, 5), "{}", dive.name);
        // The same as a run over the dive alone.
        let alone = Options {
            survey: Some(dive.survey.clone()),
            water_column: dive.water_column.clone(),
            out: Some(root.join("alone").join(&dive.name)),
            window: Some(5),
            ..Options::default()
        };
        correct_mission(&alone, &Silent).unwrap();
        assert_eq!(
            outputs(&root.join("out").join(&dive.name)),
            outputs(&root.join("alone").join(&dive.name))
        );
    }
    let e = abysslight::cruise::find_dives(&root.join("cruise/notes")).unwrap_err();
    assert!(e.to_string().contains("no dives"), "{e}");
}

#[test]
fn a_shard_that_left_photos_out_is_not_merged() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    mission(root);
    // Shard 2 of 4 (img7 to img12) timed with --limit 2: img7 and img8 only.
    for k in 1..=4 {
        let o = Options {
            limit: (k == 2).then_some(2),
            ..opts(root, "out")
        };
        run_shard(root, "out", k, 4, o);
    }
    expect_error(
        &root.join("out"),
        &[
            "shard 2/4: 4 of its 6 photos",
            "--limit 2",
            "img10.png",
            "img12.png",
        ],
    );
    let o = abysslight_in(&["merge-shards", "out"], root);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("img11.png"), "{}", stderr(&o));
    // Rerun without --limit: merged.
    run_shard(root, "out", 2, 4, opts(root, "out"));
    assert_eq!(merge_shards(&root.join("out")).unwrap().frames, 23);
}

#[test]
fn an_edited_shard_report_is_not_merged() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    mission(root);
    for k in 1..=3 {
        run_shard(root, "out", k, 3, opts(root, "out"));
    }
    let path = root.join("out/_abysslight/report-shard-3-of-3.json");
    let original = std::fs::read_to_string(&path).unwrap();
    let edit = |f: &dyn Fn(&mut Value)| {
        let mut v: Value = serde_json::from_str(&original).unwrap();
        f(&mut v);
        std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
    };
    // Two frames lost, the counts edited to match.
    edit(&|v| {
        let frames = v["frames"].as_array_mut().unwrap();
        frames.truncate(frames.len() - 2);
        v["corrected"] = (v["corrected"].as_u64().unwrap() - 2).into();
    });
    expect_error(
        &root.join("out"),
        &["shard 3/3: 2 of its 8 photos", "img23.png", "img24.png"],
    );
    // Two frames lost, the counts left as they were.
    edit(&|v| {
        let frames = v["frames"].as_array_mut().unwrap();
        frames.truncate(frames.len() - 2);
    });
    expect_error(&root.join("out"), &["shard 3/3", "counts", "edited"]);
    // A failed photo's error (img9, shard 2) removed, its count too.
    let first = root.join("out/_abysslight/report-shard-2-of-3.json");
    let one = std::fs::read_to_string(&first).unwrap();
    std::fs::write(&path, &original).unwrap();
    let mut v: Value = serde_json::from_str(&one).unwrap();
    v["errors"] = Value::Array(Vec::new());
    v["failed"] = 0.into();
    std::fs::write(&first, serde_json::to_string(&v).unwrap()).unwrap();
    expect_error(
        &root.join("out"),
        &["shard 2/3: 1 of its 8 photos", "img9.png"],
    );
    std::fs::write(&first, &one).unwrap();
    assert_eq!(merge_shards(&root.join("out")).unwrap().frames, 23);
}

/// A report written as JSON is read back as the same [`abysslight::Report`], and the merge of two shards of a dive
/// whose windows altitude chooses (a sledge swinging 1.2 m, with the simulator's navigation log) is, read back, the
/// report of one run over the whole survey, field by field: only the fields listed differ by nature.
#[test]
fn merged_shards_are_one_runs_report_field_by_field_with_windows_by_altitude() {
    use abysslight::Report;
    let d = tempfile::tempdir().unwrap();
    let dive = d.path().join("dive");
    let o = abysslight(&[
        "simulate",
        "--out",
        s(&dive),
        "--altitude-swing",
        "1.2",
        "--frames",
        "30",
        "--size",
        "160x120",
        "--encode",
        "srgb",
        "--seed",
        "4",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let opts = |out: &Path| Options {
        water_column: Some(dive.join("water")),
        survey: Some(dive.join("survey")),
        out: Some(out.to_path_buf()),
        navigation: Some(dive.join("navigation.csv")),
        ..Options::default()
    };
    let (one_out, sharded) = (d.path().join("one"), d.path().join("sharded"));
    let returned = correct_mission(&opts(&one_out), &Silent).unwrap();
    let read = |out: &Path| -> (String, Report) {
        let text = std::fs::read_to_string(out.join("_abysslight/report.json")).unwrap();
        let r = serde_json::from_str(&text).unwrap();
        (text, r)
    };

    // Report → JSON → report: the same report (compared as JSON, where a NaN is null), the same JSON.
    let (text, one) = read(&one_out);
    let (a, b) = (
        serde_json::to_value(&one).unwrap(),
        serde_json::to_value(&returned).unwrap(),
    );
    for (x, y) in a["frames"]
        .as_array()
        .unwrap()
        .iter()
        .zip(b["frames"].as_array().unwrap())
    {
        for (k, v) in x.as_object().unwrap() {
            assert_eq!(v, &y[k], "{k} of {}", x["input"]);
        }
    }
    for (k, v) in a.as_object().unwrap() {
        assert_eq!(v, &b[k], "{k}");
    }
    assert_eq!(serde_json::to_string_pretty(&one).unwrap(), text);
    let windows = |r: &Report| {
        r.frames
            .iter()
            .map(|f| f.window.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(windows(&one), windows(&returned));
    let chosen = one.frames.iter().filter(|f| f.window.by_altitude()).count();
    assert!(
        chosen > 0 && one.window.by_altitude == Some(chosen),
        "no window chosen by altitude: {:?}",
        one.window
    );
    assert!(one.frames.iter().all(|f| f.altitude.is_some()));

    for index in 1..=2 {
        run_shard(&sharded, "", index, 2, opts(&sharded));
    }
    let m = merge_shards(&sharded).unwrap();
    assert_eq!((m.shards, m.frames, m.corrected), (2, 30, 30));
    assert_eq!(outputs(&one_out), outputs(&sharded));
    let (_, merged) = read(&sharded);

    // The one counter of flags counted both reports' frames.
    let counted = |r: &Report| abysslight::report::Summary::of(r.frames.iter().map(|f| &f.health));
    assert_eq!(
        (counted(&one), counted(&merged)),
        (one.monitor, merged.monitor)
    );
    // What differs by nature: times, where the report and the photos went, the memory a shard held; and what
    // compares a photo with those before it, as each shard's monitor starts at its first photo (docs/cluster.md):
    // the change of F, the motion, the ground span, the colour shift, the flags resting on them and their counts.
    let before = ["factor-change", "colour-shift", "camera-still"];
    let same_but = |r: &Report, out: &Path| -> serde_json::Value {
        let mut r = r.clone();
        r.elapsed_s = 0.0;
        r.report_path = None;
        r.peak_photos_in_memory = 0;
        r.options.out = None;
        let m = &mut r.monitor;
        (m.flagged, m.factor_change, m.colour_shift, m.camera_still) = (0, 0, 0, 0);
        for f in &mut r.frames {
            (f.decode_ms, f.estimate_ms, f.correct_ms, f.encode_ms) = (0.0, 0.0, 0.0, 0.0);
            f.output = f.output.strip_prefix(out).unwrap().to_path_buf();
            let h = &mut f.health;
            (h.factor_change, h.colour_shift) = (0.0, 0.0);
            (h.motion, h.motion_ncc, h.window_span) = (None, None, None);
            h.flags.retain(|g| !before.contains(&g.kind()));
        }
        serde_json::to_value(&r).unwrap()
    };
    let (a, b) = (same_but(&one, &one_out), same_but(&merged, &sharded));
    let fields = a.as_object().unwrap();
    assert_eq!(fields.len(), b.as_object().unwrap().len());
    for (x, y) in a["frames"]
        .as_array()
        .unwrap()
        .iter()
        .zip(b["frames"].as_array().unwrap())
    {
        for (k, v) in x.as_object().unwrap() {
            assert_eq!(v, &y[k], "{k} of {}", x["input"]);
        }
    }
    for (k, v) in fields {
        assert_eq!(v, &b[k], "{k}");
    }
    // The typed frames too: every photo at its place with the window one run gave it.
    for (x, y) in one.frames.iter().zip(&merged.frames) {
        assert_eq!(
            (&x.input, x.index, &x.window),
            (&y.input, y.index, &y.window)
        );
    }
    let windows = |r: &Report| (r.window.shortest, r.window.longest, r.window.by_altitude);
    assert_eq!(windows(&merged), windows(&one));
}

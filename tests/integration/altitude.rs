//! A navigation log (`--navigation`): where the altitude swings, windows are chosen among the photos lit from the
//! nearest heights, and the correction is better for it; where it does not, nothing changes. The engine, shards and
//! the command take the same windows; bad logs are refused with the file named.

use crate::common::*;

use std::path::Path;

use abysslight::eval::evaluate::{albedo_error, residual_pattern};
use abysslight::eval::matrix;
use abysslight::eval::simulate::{Dive, Simulation};
use abysslight::io::{decode, find_photos};
use abysslight::{correct_mission, Engine, Options, Photo, Shard, Silent, Use};

/// Dive `name` of the matrix at `size`, written under `root` (`water/`, `survey/`, `navigation.csv`).
fn dive(name: &str, size: (usize, usize), root: &Path) -> (Simulation, Dive) {
    let (spec, seed) = matrix::dive_and_seed(name, 0).unwrap();
    let sim = spec.simulation(seed, size);
    let dive = sim.render_with_lighting().unwrap();
    dive.write(root).unwrap();
    (sim, dive)
}

fn options(sim: &Simulation, root: &Path, out: &Path, navigation: bool) -> Options {
    Options {
        water_column: Some(root.join("water")),
        survey: Some(root.join("survey")),
        out: Some(out.to_path_buf()),
        transfer: Some(sim.encode),
        navigation: navigation.then(|| root.join("navigation.csv")),
        ..Options::default()
    }
}

#[test]
fn windows_chosen_by_altitude_correct_a_swinging_sledge_better() {
    // t02 (held out): two lights, altitude 4 ± 1.6 m, 40 % nodules. At 320×240 (PNG) the log lowered the albedo
    // error 16 %, the residual pattern 32 % and the overlap difference 19 %.
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    let (sim, dive) = dive("t02", (320, 240), &root);
    let signal = matrix::signal_mask(&dive, sim.encode, 8);
    let names: Vec<String> = dive.truth.poses.iter().map(|p| p.file.clone()).collect();
    let score = |navigation: bool, out: &str| {
        let out = d.path().join(out);
        let report = correct_mission(&options(&sim, &root, &out, navigation), &Silent).unwrap();
        assert_eq!(report.corrected, sim.frames);
        let photos = matrix::load_set(&out, &names, sim.encode);
        (
            albedo_error(&photos, &dive.albedo, Some(&signal)),
            residual_pattern(&photos, &dive.albedo, (8, 6), Some(&signal)),
        )
    };
    let (time, by_altitude) = (score(false, "time"), score(true, "altitude"));
    assert!(
        by_altitude.0 < 0.93 * time.0 && by_altitude.1 < time.1,
        "albedo error and pattern: {by_altitude:?} by altitude, {time:?} over time"
    );

    // The report says what each window took: the photo's altitude from the log, and for the photos whose window
    // was chosen by altitude the photos it took, each nearer in altitude than a photo of the pool it left out.
    let r = report(&d.path().join("altitude"));
    let frames = r["frames"].as_array().unwrap();
    let altitude = |i: usize| frames[i]["altitude"].as_f64().unwrap();
    let mut chosen = 0;
    for (i, f) in frames.iter().enumerate() {
        let logged = dive.truth.poses[i].position[2];
        assert!((altitude(i) - logged).abs() < 2e-3, "photo {i}");
        let Some(took) = f["window_by_altitude"].as_array() else {
            continue;
        };
        chosen += 1;
        let took: Vec<usize> = took.iter().map(|v| v.as_u64().unwrap() as usize).collect();
        assert!(took.contains(&i) && took.windows(2).all(|p| p[0] < p[1]));
        let n = f["window_auto"]["window"].as_u64().unwrap() as usize;
        assert_eq!(took.len(), n, "photo {i}: the window's length");
        let window = f["window"].as_array().unwrap();
        assert_eq!(window[0].as_u64().unwrap() as usize, took[0]);
        assert_eq!(window[1].as_u64().unwrap() as usize, took[took.len() - 1]);
        // Before the photo: every photo left out between the pool's start and the photo is no nearer in altitude
        // than the farthest taken before it.
        let before: Vec<usize> = took.iter().copied().filter(|&j| j < i).collect();
        if let Some(farthest) = before
            .iter()
            .map(|&j| (altitude(j) - altitude(i)).abs())
            .reduce(f64::max)
        {
            for j in i.saturating_sub(n)..i {
                if !took.contains(&j) {
                    assert!(
                        (altitude(j) - altitude(i)).abs() >= farthest - 1e-3,
                        "photo {i}: {j}"
                    );
                }
            }
        }
    }
    assert!(
        chosen > sim.frames / 2,
        "{chosen} windows chosen by altitude"
    );
    // The window summary: the lengths the photos used, and how many took theirs by altitude.
    let lengths: Vec<u64> = frames
        .iter()
        .map(|f| f["window_auto"]["window"].as_u64().unwrap())
        .collect();
    assert_eq!(
        r["window"]["longest"].as_u64(),
        lengths.iter().max().copied()
    );
    assert_eq!(
        r["window"]["shortest"].as_u64(),
        lengths.iter().min().copied()
    );
    assert_eq!(r["window"]["by_altitude"].as_u64(), Some(chosen as u64));
}

#[test]
fn a_level_track_with_a_log_is_corrected_as_without() {
    // a01: a level dive (altitude within 5 %): every window stays over time, and the outputs are byte-identical.
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    let (sim, _) = dive("a01", (160, 120), &root);
    for (nav, out) in [(false, "time"), (true, "log")] {
        correct_mission(&options(&sim, &root, &d.path().join(out), nav), &Silent).unwrap();
    }
    assert_eq!(
        outputs(&d.path().join("time")),
        outputs(&d.path().join("log"))
    );
    let r = report(&d.path().join("log"));
    for f in r["frames"].as_array().unwrap() {
        assert!(f["altitude"].as_f64().unwrap() > 0.0);
        assert!(f.get("window_by_altitude").is_none());
    }
}

#[test]
fn the_engine_and_shards_take_the_commands_windows_by_altitude() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    let (sim, dive) = dive("s02", (160, 120), &root);
    let batch = d.path().join("batch");
    let opts = options(&sim, &root, &batch, true);
    correct_mission(&opts, &Silent).unwrap();
    let r = report(&batch);
    let frames = r["frames"].as_array().unwrap();
    assert!(
        frames.iter().any(|f| f.get("window_by_altitude").is_some()),
        "no window chosen by altitude"
    );

    // The engine, each photo pushed with its altitude.
    let mut engine = engine_over(&root.join("water"), opts.params().unwrap());
    let mut out = Vec::new();
    for ((name, photo), pose) in decoded_photos(&root.join("survey"))
        .into_iter()
        .zip(&dive.truth.poses)
    {
        let altitude = Some((pose.position[2] * 1000.0).round() as f32 / 1000.0);
        out.extend(engine.push((photo, name, Use::Correct, altitude)).unwrap());
    }
    out.extend(engine.finish());
    assert_eq!(out.len(), sim.frames);
    for c in out {
        let f = &frames[c.index];
        let took: Option<Vec<usize>> = f.get("window_by_altitude").map(|w| {
            w.as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_u64().unwrap() as usize)
                .collect()
        });
        assert_eq!(
            c.window.chosen_by_altitude().map(<[usize]>::to_vec),
            took,
            "photo {}",
            c.index
        );
        let written = decode(&batch.join(&c.tag)).unwrap();
        assert!(
            c.photo.unwrap().samples == written.samples,
            "{}",
            c.tag.display()
        );
    }

    // Two shards, merged: the same pixels and windows.
    let sharded = d.path().join("sharded");
    for index in 1..=2 {
        let o = Options {
            shard: Some(Shard { index, count: 2 }),
            ..options(&sim, &root, &sharded, true)
        };
        correct_mission(&o, &Silent).unwrap();
    }
    abysslight::merge_shards(&sharded).unwrap();
    assert_eq!(outputs(&batch), outputs(&sharded));
    let merged = report(&sharded);
    assert_eq!(merged["window"], r["window"], "the window summary");
    let chosen = frames
        .iter()
        .filter(|f| f.get("window_by_altitude").is_some())
        .count();
    assert_eq!(r["window"]["by_altitude"].as_u64(), Some(chosen as u64));
    for (a, b) in frames.iter().zip(merged["frames"].as_array().unwrap()) {
        assert_eq!(a["window_by_altitude"], b["window_by_altitude"]);
        assert_eq!(a["window"], b["window"]);
    }
}

#[test]
fn bad_logs_and_runs_that_cannot_use_one_are_refused_by_name() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = tiny_mission(d.path(), 6);
    let nav = d.path().join("nav.csv");
    let run = |extra: &[&str]| {
        let out = d.path().join("out");
        let _ = std::fs::remove_dir_all(&out);
        let mut args = vec![
            "correct",
            "--survey",
            s(&survey),
            "--out",
            s(&out),
            "--quiet",
        ];
        args.extend_from_slice(extra);
        abysslight(&args)
    };
    // No photo of the survey listed: the wrong log.
    std::fs::write(&nav, "file,altitude\nother.png,3\n").unwrap();
    let o = run(&["--navigation", s(&nav)]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains(s(&nav)) && stderr(&o).contains("lists none of the 6 survey photos"),
        "{}",
        stderr(&o)
    );
    // A value no camera is flown at: the line and the value.
    std::fs::write(&nav, "file,altitude\nx.png,3\ny.png,9999\n").unwrap();
    let o = run(&["--navigation", s(&nav)]);
    assert!(
        stderr(&o).contains("line 3") && stderr(&o).contains("9999"),
        "{}",
        stderr(&o)
    );
    // Missing.
    let o = run(&["--navigation", s(&d.path().join("none.csv"))]);
    assert!(
        !o.status.success() && stderr(&o).contains("--navigation"),
        "{}",
        stderr(&o)
    );
    // Some photos listed: corrected, with a warning that counts the others.
    let listed: Vec<String> = find_photos(&survey)
        .unwrap()
        .photos
        .iter()
        .take(4)
        .map(|e| format!("{},3.0\n", e.path.file_name().unwrap().to_string_lossy()))
        .collect();
    std::fs::write(&nav, format!("file,altitude\n{}", listed.concat())).unwrap();
    let out = d.path().join("out");
    let o = abysslight(&[
        "correct",
        "--survey",
        s(&survey),
        "--out",
        s(&out),
        "--navigation",
        s(&nav),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("does not list 2 of the 6 survey photos"),
        "{}",
        stderr(&o)
    );
    // A dry run says what the log gives.
    let o = run(&["--navigation", s(&nav), "--dry-run"]);
    assert!(
        stdout(&o).contains("gives the altitude of 4 of the 6 survey photos"),
        "{}",
        stdout(&o)
    );
    // The same log from a config file, relative to the file's folder.
    let cfg = d.path().join("run.toml");
    std::fs::write(&cfg, "navigation = \"nav.csv\"\n").unwrap();
    let o = abysslight(&[
        "correct",
        "--config",
        s(&cfg),
        "--survey",
        s(&survey),
        "--out",
        s(&d.path().join("o4")),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("does not list 2 of the 6 survey photos"),
        "{}",
        stderr(&o)
    );
    let r = report(&d.path().join("o4"));
    assert_eq!(r["frames"][0]["altitude"].as_f64(), Some(3.0));
    // Frames on standard input have no names; the paper's method has no windows by altitude.
    let o = run(&["--navigation", s(&nav), "--method", "paper"]);
    assert!(stderr(&o).contains("--method abyss"), "{}", stderr(&o));
    let o = abysslight(&[
        "correct",
        "--survey",
        "-",
        "--out",
        s(&d.path().join("o2")),
        "--navigation",
        s(&nav),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("stdin"),
        "{}",
        stderr(&o)
    );
    // The log is an input: no output may overwrite it.
    let o = abysslight(&[
        "correct",
        "--survey",
        s(&survey),
        "--out",
        s(&d.path().join("o3")),
        "--navigation",
        s(&nav),
        "--report",
        s(&nav),
    ]);
    assert!(!o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(&nav).unwrap(),
        format!("file,altitude\n{}", listed.concat())
    );
    // The engine refuses an altitude that is not a positive number.
    let mut engine: Engine<usize> = Engine::new(Default::default(), None, None).unwrap();
    let photo = decode(&find_photos(&survey).unwrap().photos[0].path).unwrap();
    assert!(engine.push((photo, 0, Some(-1.0))).is_err());
}

#[test]
fn a_cruise_dive_reads_its_own_log() {
    // Two dives of a cruise, each as the simulator writes it; only the first keeps its navigation.csv.
    let d = tempfile::tempdir().unwrap();
    let cruise = d.path().join("cruise");
    for name in ["d1", "d2"] {
        let root = cruise.join(name);
        dive("s02", (96, 64), &root);
        std::fs::rename(root.join("water"), root.join("water-column")).unwrap();
    }
    std::fs::remove_file(cruise.join("d2").join("navigation.csv")).unwrap();
    let out = d.path().join("out");
    let o = abysslight(&[
        "correct",
        "--cruise",
        s(&cruise),
        "--out",
        s(&out),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames = |dive: &str| {
        report(&out.join(dive))["frames"]
            .as_array()
            .unwrap()
            .clone()
    };
    assert!(frames("d1")
        .iter()
        .all(|f| f["altitude"].as_f64().is_some()));
    assert!(frames("d1")
        .iter()
        .any(|f| f.get("window_by_altitude").is_some()));
    assert!(frames("d2").iter().all(|f| f.get("altitude").is_none()));
    // One log for every dive is refused: each has its own.
    let o = abysslight(&[
        "correct",
        "--cruise",
        s(&cruise),
        "--out",
        s(&d.path().join("out2")),
        "--navigation",
        s(&cruise.join("d1").join("navigation.csv")),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("navigation.csv"),
        "{}",
        stderr(&o)
    );
    // The library's cruise: the same options per dive.
    let dives = abysslight::cruise::find_dives(&cruise).unwrap();
    assert_eq!(
        dives[0].navigation,
        Some(cruise.join("d1").join("navigation.csv"))
    );
    assert_eq!(dives[1].navigation, None);
    let o = dives[0].options(&Options::default(), &out);
    assert_eq!(o.navigation, dives[0].navigation);
}

/// `--watch` with a log takes the batch command's windows by altitude and writes its pixels.
#[test]
fn watch_with_a_log_writes_the_batch_commands_pixels() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    let (sim, _) = dive("s02", (96, 64), &root);
    let batch = d.path().join("batch");
    correct_mission(&options(&sim, &root, &batch, true), &Silent).unwrap();
    let watched = d.path().join("watched");
    let transfer = sim.encode.to_string();
    let o = abysslight(&[
        "correct",
        "--survey",
        s(&root.join("survey")),
        "--out",
        s(&watched),
        "--water-column",
        s(&root.join("water")),
        "--transfer",
        &transfer,
        "--navigation",
        s(&root.join("navigation.csv")),
        "--watch",
        "--idle-timeout",
        "1",
        "--poll-interval",
        "40",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(outputs(&batch), outputs(&watched));
    let took = |r: serde_json::Value| -> Vec<serde_json::Value> {
        r["frames"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f["window_by_altitude"].clone())
            .collect()
    };
    let batch_took = took(report(&batch));
    assert!(batch_took.iter().any(|w| !w.is_null()));
    assert_eq!(took(report(&watched)), batch_took);
}

/// Over a mission longer than the engine holds (150 photos), with the engine's own survey and with a window given,
/// each photo's window is the best balanced choice by altitude among the photos around it, knowing the whole
/// mission: the engine kept every photo a window chose among.
#[test]
fn a_long_mission_keeps_every_photo_a_window_chooses_among() {
    use abysslight::{Layout, Params, Samples, Window};
    let (w, h, total) = (48usize, 32usize, 150usize);
    // A swing of ±40 % with a period of 9 photos.
    let altitude = |i: usize| 4.0 + 1.6 * (i as f32 * std::f32::consts::TAU / 9.0).sin();
    let photo = |i: usize| {
        let mut rng = Rng::new(i as u64 + 1);
        let a = altitude(i);
        let samples = (0..w * h * 3)
            .map(|k| {
                let (x, y) = ((k / 3) % w, (k / 3) / w);
                let lit = light(x, y, k % 3, w, h) * 16.0 / (a * a);
                ((0.3 + 0.2 * rng.f32()) * lit * 255.0).clamp(0.0, 255.0) as u8
            })
            .collect();
        Photo {
            layout: Layout {
                width: w,
                height: h,
                channels: 3,
            },
            samples: Samples::U8(samples),
            alpha: None,
        }
    };
    // The photos `[start, end)` of `n` around photo `i`, shifted back at the mission's ends.
    let around = |i: usize, n: usize| {
        let s = i.saturating_sub(n / 2).min(total - n);
        s..s + n
    };
    for params in [
        Params::default(),
        Params {
            window: Window::Fixed(9),
            ..Params::default()
        },
    ] {
        let mut engine = Engine::new(params, None, None).unwrap();
        let mut out = Vec::new();
        for i in 0..total {
            out.extend(engine.push((photo(i), i, Some(altitude(i)))).unwrap());
        }
        out.extend(engine.finish());
        assert_eq!(out.len(), total);
        for c in &out {
            let i = c.index;
            let n = c.choice.map_or(9, |ch| ch.window);
            let by_time = around(i, n);
            let Some(took) = c.window.chosen_by_altitude() else {
                panic!("photo {i}: the window over time, where the altitude spans 80 %");
            };
            let pool = around(i, 2 * n + 1);
            assert_eq!(took.len(), n, "photo {i}");
            assert!(
                took.contains(&i) && took.iter().all(|j| pool.contains(j)),
                "photo {i}: {took:?}"
            );
            assert_eq!(c.window.span(), took[0]..took[n - 1] + 1);
            // As many before it as the window over time has, each side the nearest in altitude of its side.
            let side = |before: bool| move |j: &usize| if before { *j < i } else { *j > i };
            assert_eq!(
                took.iter().filter(|j| side(true)(j)).count(),
                by_time.clone().filter(side(true)).count(),
                "photo {i}"
            );
            for before in [true, false] {
                let far = took
                    .iter()
                    .filter(|j| side(before)(j))
                    .map(|&j| (altitude(j) - altitude(i)).abs())
                    .fold(0.0f32, f32::max);
                for j in pool
                    .clone()
                    .filter(side(before))
                    .filter(|j| !took.contains(j))
                {
                    assert!(
                        (altitude(j) - altitude(i)).abs() >= far,
                        "photo {i}: {j} left out, {took:?}"
                    );
                }
            }
        }
    }
}

/// A log by time, as a vehicle writes it (no file column, rows at its own rate, times in UTC): each photo's altitude
/// is read at the time its EXIF gives (`DateTimeOriginal`, `SubSecTimeOriginal`, `OffsetTimeOriginal`), and the
/// run takes the windows a log by file name gives.
#[test]
fn a_log_by_time_reads_each_photo_at_its_exif_time() {
    use exif::{Field, In, Tag, Value};
    use std::io::Cursor;
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    let (sim, dive) = dive("s02", (96, 64), &root);
    // The photos as a camera on local time (UTC+2) writes them: JPEGs taken 2 s apart, the last without EXIF.
    let survey = d.path().join("jpeg");
    std::fs::create_dir_all(&survey).unwrap();
    let names: Vec<String> = dive
        .truth
        .poses
        .iter()
        .map(|p| p.file.replace(".png", ".jpg"))
        .collect();
    let ascii = |s: &str| Value::Ascii(vec![s.as_bytes().to_vec()]);
    for (i, pose) in dive.truth.poses.iter().enumerate() {
        let photo = decode(&root.join("survey").join(&pose.file)).unwrap();
        let abysslight::Samples::U8(rgb) = photo.samples else {
            panic!("8-bit")
        };
        let (s, cs) = (2 * i, 25);
        let fields = [
            (
                Tag::DateTimeOriginal,
                ascii(&format!("2023:06:03 18:{:02}:{:02}", 27 + s / 60, s % 60)),
            ),
            (Tag::SubSecTimeOriginal, ascii(&cs.to_string())),
            (Tag::OffsetTimeOriginal, ascii("+02:00")),
        ];
        let mut w = exif::experimental::Writer::new();
        let fields: Vec<Field> = fields
            .into_iter()
            .map(|(tag, value)| Field {
                tag,
                ifd_num: In::PRIMARY,
                value,
            })
            .collect();
        for f in &fields {
            w.push_field(f);
        }
        let mut blob = Cursor::new(Vec::new());
        w.write(&mut blob, true).unwrap();
        let mut out = Vec::new();
        let mut enc = jpeg_encoder::Encoder::new(&mut out, 95);
        if i + 1 < names.len() {
            enc.add_app_segment(1, [&b"Exif\0\0"[..], &blob.into_inner()].concat())
                .unwrap();
        }
        let l = photo.layout;
        enc.encode(
            &rgb,
            l.width as u16,
            l.height as u16,
            jpeg_encoder::ColorType::Rgb,
        )
        .unwrap();
        std::fs::write(survey.join(&names[i]), out).unwrap();
    }
    // The vehicle's log: UTC, a row half a second before and after each photo at its altitude, newest first.
    let mut rows = Vec::new();
    for (i, pose) in dive.truth.poses.iter().enumerate() {
        for dt in [-0.5, 0.5] {
            let t = 1_685_809_620.0 + 2.0 * i as f64 + 0.25 + dt;
            rows.push(format!("{t:.2},4012.5,{:.3}\n", pose.position[2]));
        }
    }
    rows.reverse();
    let by_time = d.path().join("vehicle.csv");
    std::fs::write(&by_time, format!("time,depth,altitude\n{}", rows.concat())).unwrap();
    // The same altitudes by file name, without the photo that has no time.
    let listed: Vec<String> = names
        .iter()
        .zip(&dive.truth.poses)
        .take(names.len() - 1)
        .map(|(n, p)| format!("{n},{:.3}\n", p.position[2]))
        .collect();
    let by_name = d.path().join("names.csv");
    std::fs::write(&by_name, format!("file,altitude\n{}", listed.concat())).unwrap();

    let run = |nav: &Path, out: &str| {
        let out = d.path().join(out);
        let o = abysslight(&[
            "correct",
            "--survey",
            s(&survey),
            "--water-column",
            s(&root.join("water")),
            "--transfer",
            &sim.encode.to_string(),
            "--navigation",
            s(nav),
            "--out",
            s(&out),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        (report(&out), stderr(&o), out)
    };
    let (time_report, time_err, time_out) = run(&by_time, "time");
    let (name_report, _, name_out) = run(&by_name, "name");
    assert!(
        time_err.contains("gives no altitude at the time of 1 of the 40 survey photos"),
        "{time_err}"
    );
    assert_eq!(outputs(&time_out), outputs(&name_out));
    let frames = |r: &serde_json::Value| r["frames"].as_array().unwrap().clone();
    let (t, n) = (frames(&time_report), frames(&name_report));
    assert!(t.iter().any(|f| f.get("window_by_altitude").is_some()));
    for (i, (a, b)) in t.iter().zip(&n).enumerate() {
        assert_eq!(
            a["window_by_altitude"], b["window_by_altitude"],
            "photo {i}"
        );
        match (a["altitude"].as_f64(), b["altitude"].as_f64()) {
            (Some(x), Some(y)) => assert!((x - y).abs() < 1e-3, "photo {i}: {x} {y}"),
            (x, y) => assert_eq!(x, y, "photo {i}"),
        }
    }
    assert!(t[names.len() - 1].get("altitude").is_none());
}

/// With a log, a jump of `F` is said with the altitudes it came with, as the log gives them.
#[test]
fn a_jump_of_f_names_the_altitudes_the_log_gives() {
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
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let log = std::fs::read_to_string(dive.join("navigation.csv")).unwrap();
    let altitude: Vec<f64> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    let out = d.path().join("out");
    let o = correct_dive(
        &dive,
        s(&out),
        &["--navigation", s(&dive.join("navigation.csv"))],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let mut said = 0;
    for f in report(&out)["frames"].as_array().unwrap() {
        let i = f["index"].as_u64().unwrap() as usize;
        for flag in f["health"]["flags"].as_array().unwrap() {
            if flag["kind"] != "factor-change" {
                continue;
            }
            let m = flag["message"].as_str().unwrap();
            let want = format!(
                "puts it at {:.2} m, the previous at {:.2} m",
                altitude[i],
                altitude[i - 1]
            );
            assert!(m.contains(&want), "photo {i}: {m} ({want})");
            said += 1;
        }
    }
    assert!(said > 0, "no jump of F on a swinging dive");
}

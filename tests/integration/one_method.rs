//! One method whichever way the photos come in: on nodule fields where the survey chooses windows other than 7, the
//! in-memory `Engine` (what Python runs), `--watch` on the folder and photos on standard input write the pixels of
//! the batch command, byte for byte; and what the report says of the windows is what the photos used.

use crate::common::*;

use std::path::Path;
use std::process::{Command, Stdio};

use abysslight::eval::matrix;
use abysslight::eval::simulate::Simulation;
use abysslight::io::{decode, find_photos};
use abysslight::{correct_mission, Options, Params, Silent};

/// A nodule field of the matrix at 160×120 (40 photos), written under `root` (`water/`, `survey/`).
fn field(name: &str, root: &Path) -> Simulation {
    let (spec, seed) = matrix::dive_and_seed(name, 0).unwrap();
    assert!(!spec.jpeg, "{name}: a PNG dive");
    let sim = spec.simulation(seed, (160, 120));
    sim.write(root).unwrap();
    sim
}

/// The batch command's options for the field under `root`, into `out`, at default options but the curve the
/// simulator wrote (declared by the files as well; given so that every way in takes the same).
fn options(sim: &Simulation, root: &Path, out: &Path) -> Options {
    Options {
        water_column: Some(root.join("water")),
        survey: Some(root.join("survey")),
        out: Some(out.to_path_buf()),
        transfer: Some(sim.encode),
        ..Options::default()
    }
}

/// The in-memory engine at the command's defaults (`Options::params`), photos pushed one by one: the same pixels as
/// `abysslight correct` on the folder, windows chosen by the engine's own survey as the photos come; on each field
/// the survey chose windows longer than 7 for some photos, and every photo's window fits the mission.
#[test]
fn the_engine_writes_the_batch_commands_pixels_on_nodule_fields() {
    // Dense (45 %, 16-bit linear), 30 % (8-bit sRGB), patchy along the track (2 → 45 → 15 %, 8-bit sRGB).
    for name in ["g02", "n01", "n06"] {
        let d = tempfile::tempdir().unwrap();
        let root = d.path().join("dive");
        let sim = field(name, &root);
        let opts = options(&sim, &root, &d.path().join("batch"));
        let report = correct_mission(&opts, &Silent).unwrap();
        assert_eq!(report.corrected, sim.frames, "{name}");

        let params = opts.params().unwrap();
        assert_eq!(
            Params {
                transfer: None,
                ..params
            },
            Params::default(),
            "the command's defaults are the engine's"
        );
        let out = engine_corrects(&root, params);
        assert_eq!(out.len(), sim.frames, "{name}");
        let windows: Vec<usize> = out.iter().map(|c| c.choice.unwrap().window).collect();
        assert!(
            windows.iter().any(|&w| w > 7),
            "{name}: the survey chose no window longer than 7: {windows:?}"
        );
        for c in out {
            let choice = c.choice.unwrap();
            assert_eq!(c.window.len(), choice.window, "{name}: photo {}", c.index);
            assert!(choice.window <= sim.frames);
            let written = decode(&d.path().join("batch").join(&c.tag)).unwrap();
            assert!(
                c.photo.unwrap().samples == written.samples,
                "{name}: {} differs from the batch command's",
                c.tag.display()
            );
        }
    }
}

/// `--watch` on the field's folder and the same photos on standard input (`--survey -`) write the batch command's
/// pixels, and their reports state the windows the batch run used.
#[test]
fn watch_and_standard_input_write_the_batch_commands_pixels_on_a_nodule_field() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    let sim = field("n06", &root);
    let batch = d.path().join("batch");
    correct_mission(&options(&sim, &root, &batch), &Silent).unwrap();
    let transfer = sim.encode.to_string();
    let water = root.join("water");
    let common = ["--water-column", s(&water), "--transfer", &transfer, "-q"];

    let watched = d.path().join("watched");
    let o = Command::new(BIN)
        .args([
            "correct",
            "--survey",
            s(&root.join("survey")),
            "--out",
            s(&watched),
        ])
        .args(["--watch", "--idle-timeout", "1", "--poll-interval", "40"])
        .args(common)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));

    let piped = d.path().join("piped");
    let names: Vec<_> = decoded_photos(&root.join("survey"))
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    let mut input = Vec::new();
    for n in &names {
        input.extend(std::fs::read(root.join("survey").join(n)).unwrap());
    }
    let mut child = Command::new(BIN)
        .args(["correct", "--survey", "-", "--out", s(&piped)])
        .args(common)
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let feeder = std::thread::spawn(move || std::io::Write::write_all(&mut stdin, &input));
    let o = child.wait_with_output().unwrap();
    feeder.join().unwrap().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));

    let batch_report = report(&batch);
    let frames = |r: &serde_json::Value| -> Vec<serde_json::Value> {
        r["frames"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f["window"].clone())
            .collect()
    };
    let piped_out = decoded_photos(&piped);
    assert_eq!(piped_out.len(), names.len());
    for (i, n) in names.iter().enumerate() {
        let want = decode(&batch.join(n)).unwrap().samples;
        assert!(
            decode(&watched.join(n)).unwrap().samples == want,
            "--watch: {}",
            n.display()
        );
        assert!(
            piped_out[i].1.samples == want,
            "--survey -: {}",
            n.display()
        );
    }
    for r in [report(&watched), report(&piped)] {
        assert_eq!(frames(&r), frames(&batch_report), "the windows used");
        assert_eq!(
            r["window"], batch_report["window"],
            "the mission's window summary"
        );
    }
}

/// `report.json` states the windows the photos used: under auto, that they were chosen per stretch and their
/// range, each within the mission; a mission shorter than the window the survey asks uses all of it it can and is
/// flagged for too few samples, with no advice of a window it does not hold.
#[test]
fn the_report_states_the_windows_the_photos_used() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    let sim = field("g02", &root);
    let out = d.path().join("out");
    correct_mission(&options(&sim, &root, &out), &Silent).unwrap();
    let r = report(&out);
    let used: Vec<usize> = r["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let w = f["window"].as_array().unwrap();
            let n = (w[1].as_u64().unwrap() + 1 - w[0].as_u64().unwrap()) as usize;
            assert_eq!(f["window_auto"]["window"].as_u64(), Some(n as u64), "{f}");
            n
        })
        .collect();
    let (lo, hi) = (*used.iter().min().unwrap(), *used.iter().max().unwrap());
    assert!(hi > 7, "{used:?}");
    assert_eq!(r["window"]["rule"], "auto", "{}", r["window"]);
    assert_eq!(r["window"]["shortest"].as_u64(), Some(lo as u64));
    assert_eq!(r["window"]["longest"].as_u64(), Some(hi as u64));

    // Twelve photos of the same field: no window longer than the mission.
    let short = d.path().join("short");
    std::fs::create_dir_all(short.join("survey")).unwrap();
    for e in find_photos(&root.join("survey"))
        .unwrap()
        .photos
        .iter()
        .take(12)
    {
        std::fs::copy(&e.path, short.join("survey").join(&e.relative)).unwrap();
    }
    let out = d.path().join("short-out");
    let o = Command::new(BIN)
        .args([
            "correct",
            "--survey",
            s(&short.join("survey")),
            "--out",
            s(&out),
        ])
        .args([
            "--water-column",
            s(&root.join("water")),
            "--transfer",
            &sim.encode.to_string(),
        ])
        .output()
        .unwrap();
    let text = format!("{}{}", stdout(&o), stderr(&o));
    assert!(o.status.success(), "{text}");
    let r = report(&out);
    for f in r["frames"].as_array().unwrap() {
        let w = f["window"].as_array().unwrap();
        assert!(w[1].as_u64().unwrap() < 12, "{f}");
        assert!(f["window_auto"]["window"].as_u64().unwrap() <= 11, "{f}");
        for flag in f["health"]["flags"].as_array().unwrap() {
            let m = flag["message"].as_str().unwrap();
            assert!(
                !m.contains("--window"),
                "advice that cannot be followed: {m}"
            );
        }
    }
    assert!(r["window"]["longest"].as_u64().unwrap() <= 11);
    assert!(!text.contains("n = 7"), "{text}");
}

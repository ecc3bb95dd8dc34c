//! Live and video input: `--watch` on a folder written while abysslight runs, and frames through a pipe
//! (`--survey - --out -`). No ffmpeg needed: the tests make their own frames.

use crate::common;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use abysslight::io::decode;
use abysslight::io::{decode_frame, FrameSplitter};
use abysslight::{Layout, Photo, Samples};
use common::*;

fn bin() -> Command {
    Command::new(BIN)
}

fn run(args: &[&str], cwd: &Path, stdin: &[u8]) -> Output {
    let mut child = bin()
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run abysslight");
    let mut input = child.stdin.take().unwrap();
    let data = stdin.to_vec();
    let feeder = std::thread::spawn(move || {
        let _ = input.write_all(&data);
    });
    let out = child.wait_with_output().unwrap();
    feeder.join().unwrap();
    out
}

/// A binary PPM/PGM frame written by hand (with a comment in the header), independent of abysslight's writer.
fn pnm(p: &Photo) -> Vec<u8> {
    let l = p.layout;
    let magic = if l.channels == 1 { "P5" } else { "P6" };
    let (maxval, data) = match &p.samples {
        Samples::U8(v) => (255, v.clone()),
        Samples::U16(v) => (65535, v.iter().flat_map(|s| s.to_be_bytes()).collect()),
    };
    let mut out = format!(
        "{magic}\n# frame from a test\n{} {}\n{maxval}\n",
        l.width, l.height
    )
    .into_bytes();
    out.extend_from_slice(&data);
    out
}

fn grey(p: &Photo) -> Photo {
    let samples = match &p.samples {
        Samples::U8(v) => Samples::U8(v.iter().step_by(3).copied().collect()),
        Samples::U16(v) => Samples::U16(v.iter().step_by(3).copied().collect()),
    };
    Photo {
        layout: Layout {
            channels: 1,
            ..p.layout
        },
        samples,
        alpha: None,
    }
}

fn frames_of(stdout: &[u8]) -> Vec<Photo> {
    let mut s = FrameSplitter::new(stdout);
    std::iter::from_fn(|| s.next_frame())
        .map(|f| decode_frame(&f.expect("whole frame on stdout")).unwrap())
        .collect()
}

/// Correct `photos` once as a folder of PNGs and once as a stream of `stream(photo)` frames; both must give the
/// same pixels, frame for frame.
fn pipe_equals_folder(photos: &[Photo], water: &[Photo], stream: impl Fn(&Photo) -> Vec<u8>) {
    let d = tempfile::tempdir().unwrap();
    write_all(water, &d.path().join("water"), "w", "png");
    write_all(photos, &d.path().join("survey"), "img", "png");
    let common = ["--water-column", "water", "--window", "3", "-q"];
    let o = run(
        &[
            &["correct", "--survey", "survey", "--out", "out"],
            &common[..],
        ]
        .concat(),
        d.path(),
        b"",
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let input: Vec<u8> = photos.iter().flat_map(&stream).collect();
    let o = run(
        &[&["correct", "--survey", "-", "--out", "-"], &common[..]].concat(),
        d.path(),
        &input,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let got = frames_of(&o.stdout);
    assert_eq!(got.len(), photos.len(), "frame count");
    for (i, g) in got.iter().enumerate() {
        let want = decode(&d.path().join(format!("out/img{}.png", i + 1))).unwrap();
        assert_eq!(g.layout, want.layout, "frame {i}");
        assert_eq!(
            g.samples, want.samples,
            "frame {i}: pixels differ from folder mode"
        );
    }
    // Not a copy of the input: the lighting was corrected.
    assert_ne!(got[0].samples, photos[0].samples);
}

#[test]
fn ppm_stream_8_bit_gives_the_folder_result() {
    let dive = dive(32, 24, 8, 3, 0.1, false, 11);
    pipe_equals_folder(&dive.photos, &dive.water, pnm);
}

#[test]
fn ppm_and_pgm_streams_16_bit_give_the_folder_result() {
    let dive = dive(32, 24, 7, 3, 0.1, true, 12);
    pipe_equals_folder(&dive.photos, &dive.water, pnm);
    let g: Vec<Photo> = dive.photos.iter().map(grey).collect();
    let gw: Vec<Photo> = dive.water.iter().map(grey).collect();
    pipe_equals_folder(&g, &gw, pnm);
}

fn png_bytes(p: &Photo) -> Vec<u8> {
    let mut v = Vec::new();
    abysslight::io::encode_to(p, image::ImageFormat::Png, Default::default(), &mut v).unwrap();
    v
}

#[test]
fn png_stream_8_and_16_bit_gives_the_folder_result() {
    let d8 = dive(32, 24, 6, 3, 0.1, false, 13);
    pipe_equals_folder(&d8.photos, &d8.water, png_bytes);
    let d16 = dive(32, 24, 6, 3, 0.1, true, 14);
    pipe_equals_folder(&d16.photos, &d16.water, png_bytes);
    // PNG in, PNG out.
    let d = tempfile::tempdir().unwrap();
    let input: Vec<u8> = d8.photos.iter().flat_map(png_bytes).collect();
    let o = run(
        &["correct", "--survey", "-", "--out", "-"],
        d.path(),
        &input,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(&o.stdout[..4], b"\x89PNG");
}

#[test]
fn truncated_last_frame_is_an_error_naming_it_and_earlier_frames_are_written() {
    let dive = dive(32, 24, 7, 0, 0.1, false, 15);
    let d = tempfile::tempdir().unwrap();
    let mut input: Vec<u8> = dive.photos.iter().flat_map(pnm).collect();
    input.truncate(input.len() - 100);
    let o = run(
        &[
            "correct", "--survey", "-", "--out", "-", "--window", "3", "--report", "run.json",
        ],
        d.path(),
        &input,
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("stdin frame 6") && err.contains("truncated"),
        "{err}"
    );
    assert_eq!(frames_of(&o.stdout).len(), 6);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.path().join("run.json")).unwrap()).unwrap();
    assert_eq!(report["corrected"], 6);
    assert_eq!(report["failed"], 1);
    assert_eq!(report["survey_photos"], 7);
    assert!(report["errors"][0]["message"]
        .as_str()
        .unwrap()
        .contains("stdin frame 6"));
}

#[test]
fn stream_into_an_output_folder_names_frames() {
    let dive = dive(16, 16, 4, 0, 0.1, false, 16);
    let d = tempfile::tempdir().unwrap();
    let input: Vec<u8> = dive.photos.iter().flat_map(pnm).collect();
    let o = run(
        &["correct", "--survey", "-", "--out", "out", "-q"],
        d.path(),
        &input,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(o.stdout.is_empty());
    for i in 0..4 {
        let p = d.path().join(format!("out/frame-{i:06}.ppm"));
        assert_eq!(decode(&p).unwrap().layout, dive.photos[i].layout);
    }
    assert!(d.path().join("out/_abysslight/report.json").exists());
}

// --- watch -------------------------------------------------------------------------------------------------

fn wait_for(path: &Path, within: Duration) -> bool {
    let t = Instant::now();
    while t.elapsed() < within {
        if path.exists() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

/// Copy a file into the watched folder the way a careful writer does: temp name, then rename.
fn drop_in(src: &Path, dir: &Path) {
    let name = src.file_name().unwrap().to_string_lossy().into_owned();
    let tmp = dir.join(format!(".{name}.part"));
    std::fs::copy(src, &tmp).unwrap();
    std::fs::rename(&tmp, dir.join(name)).unwrap();
}

/// Write a file in place, slowly, in chunks: half-written for several polls.
fn write_slowly(src: &Path, dir: &Path) {
    let bytes = std::fs::read(src).unwrap();
    let mut f = std::fs::File::create(dir.join(src.file_name().unwrap())).unwrap();
    for chunk in bytes.chunks(bytes.len().div_ceil(4)) {
        f.write_all(chunk).unwrap();
        f.flush().unwrap();
        std::thread::sleep(Duration::from_millis(150));
    }
}

fn watch(d: &Path, extra: &[&str]) -> Child {
    bin()
        .args([
            "correct",
            "--survey",
            "live",
            "--out",
            "out",
            "--window",
            "3",
            "--watch",
            "--poll-interval",
            "40",
        ])
        .args(extra)
        .current_dir(d)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn batch_outputs_equal(d: &Path, names: &[PathBuf]) {
    let o = run(
        &[
            "correct", "--survey", "live", "--out", "batch", "--window", "3", "-q",
        ],
        d,
        b"",
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for n in names {
        let name = n.file_name().unwrap();
        let live = std::fs::read(d.join("out").join(name)).unwrap();
        let batch = std::fs::read(d.join("batch").join(name)).unwrap();
        assert!(
            live == batch,
            "{name:?}: watch output differs from batch output"
        );
    }
}

fn wait_exit(child: Child, within: Duration) -> Output {
    let id = child.id();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(within) {
        Ok(o) => o.unwrap(),
        Err(_) => {
            let _ = Command::new("kill").arg(id.to_string()).status();
            panic!("abysslight --watch did not stop within {within:?}");
        }
    }
}

#[test]
fn watch_picks_up_photos_as_they_arrive_and_equals_batch() {
    let dive = dive(32, 24, 7, 0, 0.1, false, 21);
    let d = tempfile::tempdir().unwrap();
    let src = write_all(&dive.photos, &d.path().join("src"), "img", "png");
    let live = d.path().join("live");
    std::fs::create_dir_all(&live).unwrap();
    let child = watch(d.path(), &["--idle-timeout", "1.5"]);
    let out = d.path().join("out");
    for (i, s) in src.iter().enumerate() {
        if i == 3 {
            write_slowly(s, &live);
        } else {
            drop_in(s, &live);
        }
        // Window 3: photo i is corrected once photo i + 1 is in (photo 0 needs photos 1 and 2).
        if i >= 2 {
            assert!(
                wait_for(&out.join(format!("img{i}.png")), Duration::from_secs(10)),
                "img{i} not corrected after img{} arrived",
                i + 1
            );
            assert!(
                !out.join(format!("img{}.png", i + 1)).exists(),
                "img{} corrected before its window was complete",
                i + 1
            );
        }
    }
    let t = Instant::now();
    let o = wait_exit(child, Duration::from_secs(20));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        t.elapsed() >= Duration::from_millis(1000),
        "stopped before the idle timeout"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("_abysslight/report.json")).unwrap())
            .unwrap();
    assert_eq!(report["corrected"], 7);
    assert_eq!(report["failed"], 0, "{report}");
    batch_outputs_equal(d.path(), &src);
}

#[test]
fn watch_stops_cleanly_on_sigterm_and_finishes_the_last_photos() {
    let dive = dive(32, 24, 4, 0, 0.1, false, 22);
    let d = tempfile::tempdir().unwrap();
    let src = write_all(&dive.photos, &d.path().join("src"), "img", "png");
    let live = d.path().join("live");
    std::fs::create_dir_all(&live).unwrap();
    // One photo is there before the watch starts.
    drop_in(&src[0], &live);
    let child = watch(d.path(), &[]);
    for s in &src[1..] {
        drop_in(s, &live);
    }
    let out = d.path().join("out");
    assert!(wait_for(&out.join("img3.png"), Duration::from_secs(10)));
    assert!(!out.join("img4.png").exists());
    // Still running: no idle timeout.
    std::thread::sleep(Duration::from_millis(300));
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let o = wait_exit(child, Duration::from_secs(20));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        out.join("img4.png").exists(),
        "last photo not finished on SIGTERM"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("_abysslight/report.json")).unwrap())
            .unwrap();
    assert_eq!(report["corrected"], 4);
    batch_outputs_equal(d.path(), &src);
}

#[test]
fn watch_refuses_what_needs_the_whole_mission() {
    let d = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(d.path().join("live")).unwrap();
    for extra in [&["--mask-auto"][..], &["--shard", "1/2"], &["--resume"]] {
        let o = run(
            &[
                &["correct", "--survey", "live", "--out", "out", "--watch"],
                extra,
            ]
            .concat(),
            d.path(),
            b"",
        );
        assert_eq!(o.status.code(), Some(2), "{extra:?}");
        assert!(stderr(&o).contains("--watch"), "{}", stderr(&o));
    }
    let o = run(
        &[
            "correct",
            "--survey",
            "live",
            "--out",
            "out",
            "--idle-timeout",
            "3",
        ],
        d.path(),
        b"",
    );
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn closed_stdout_stops_the_run() {
    let dive = dive(64, 48, 40, 0, 0.1, false, 17);
    let d = tempfile::tempdir().unwrap();
    let input: Vec<u8> = dive.photos.iter().flat_map(pnm).collect();
    let mut child = bin()
        .args(["correct", "--survey", "-", "--out", "-", "--window", "3"])
        .current_dir(d.path())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let mut stdin = child.stdin.take().unwrap();
    let feeder = std::thread::spawn(move || {
        let _ = stdin.write_all(&input);
    });
    let o = wait_exit(child, Duration::from_secs(30));
    feeder.join().unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("stdout was closed"), "{err}");
    assert!(
        err.matches("error:").count() <= 3,
        "one error per frame: {err}"
    );
}

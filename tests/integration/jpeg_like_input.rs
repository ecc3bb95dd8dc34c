//! Issue 14: a JPEG output is written with its JPEG input's chroma subsampling and (estimated) quality, unless
//! `--jpeg-quality` / `--jpeg-subsampling` say otherwise; what is read back from the output files is checked.

use crate::common::abysslight_in;

use std::path::Path;
use std::process::Command;

use abysslight::eval::synthetic_photo;
use abysslight::io::{jpeg_coding as parse, JpegCoding};
use abysslight::io::{write_atomic, EncodeSettings, Subsampling};
use abysslight::{correct_mission, Options, Silent};

/// Water-column PNGs and survey JPEGs written at `quality` with `sub`.
fn mission(dir: &Path, quality: u8, sub: Subsampling) {
    for j in 0..3 {
        let p = synthetic_photo(96, 64, j, true);
        write_atomic(
            &p,
            &dir.join(format!("wc/w{j}.png")),
            EncodeSettings::default(),
        )
        .unwrap();
    }
    let settings = EncodeSettings {
        jpeg_quality: quality,
        jpeg_subsampling: sub,
        ..EncodeSettings::default()
    };
    for j in 0..5 {
        let p = synthetic_photo(96, 64, j, false);
        write_atomic(&p, &dir.join(format!("survey/img{j}.jpg")), settings).unwrap();
    }
}

fn codings(dir: &Path) -> Vec<JpegCoding> {
    let mut names: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .collect();
    names.sort();
    names
        .iter()
        .map(|p| parse(&std::fs::read(p).unwrap()).expect("a JPEG"))
        .collect()
}

fn run(dir: &Path, out: &str, quality: Option<u8>, sub: Option<Subsampling>) -> Vec<JpegCoding> {
    let opts = Options {
        water_column: Some(dir.join("wc")),
        survey: Some(dir.join("survey")),
        out: Some(dir.join(out)),
        window: Some(3),
        threads: Some(2),
        jpeg_quality: quality,
        jpeg_subsampling: sub,
        ..Options::default()
    };
    let r = correct_mission(&opts, &Silent).unwrap();
    assert_eq!(r.corrected, 5);
    codings(&dir.join(out))
}

#[test]
fn outputs_take_the_inputs_subsampling_and_quality() {
    for (q, sub) in [
        (90, Subsampling::S420),
        (82, Subsampling::S422),
        (97, Subsampling::S444),
    ] {
        let d = tempfile::tempdir().unwrap();
        mission(d.path(), q, sub);
        let inputs = codings(&d.path().join("survey"));
        assert_eq!(inputs[0].subsampling, Some(sub));
        let outputs = run(d.path(), "out", None, None);
        assert_eq!(outputs.len(), 5);
        for o in &outputs {
            assert_eq!(o.subsampling, Some(sub), "input {q} {sub}");
            assert_eq!(o.quality, Some(q), "input {q} {sub}");
            assert_eq!(o.components, 3);
        }
    }
}

#[test]
fn explicit_quality_and_subsampling_win() {
    let d = tempfile::tempdir().unwrap();
    mission(d.path(), 90, Subsampling::S420);
    for o in run(d.path(), "q", Some(70), None) {
        assert_eq!(
            (o.quality, o.subsampling),
            (Some(70), Some(Subsampling::S420))
        );
    }
    for o in run(d.path(), "s", None, Some(Subsampling::S444)) {
        assert_eq!(
            (o.quality, o.subsampling),
            (Some(90), Some(Subsampling::S444))
        );
    }
    // The same through the command line.
    let o = abysslight_in(
        &[
            "correct",
            "--water-column",
            "wc",
            "--survey",
            "survey",
            "--out",
            "cli",
            "--window",
            "3",
            "--jpeg-quality",
            "60",
            "--jpeg-subsampling",
            "422",
        ],
        d.path(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let outs = codings(&d.path().join("cli"));
    assert_eq!(outs.len(), 5);
    for c in outs {
        assert_eq!(
            (c.quality, c.subsampling),
            (Some(60), Some(Subsampling::S422))
        );
    }
    let bad = abysslight_in(
        &[
            "correct",
            "--survey",
            "survey",
            "--out",
            "x",
            "--jpeg-subsampling",
            "411",
        ],
        d.path(),
    );
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("444, 422 or 420"));
}

/// The estimator against ImageMagick's (`identify -format %Q`) on the real camera JPEGs beside the project, when
/// ImageMagick is there (without it the test says so and checks nothing).
#[test]
#[ignore = "needs ../shared/data/real beside the project (real photos are not shipped); .ci/run runs it where they are"]
fn real_jpegs_agree_with_imagemagick() {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real");
    assert!(root.is_dir(), "{} is absent", root.display());
    let mut files = Vec::new();
    let mut stack = vec![root];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("jpg")) {
                files.push(p);
            }
        }
    }
    files.sort();
    let mut checked = 0;
    for p in files.iter().step_by(7) {
        let Ok(o) = Command::new("identify")
            .args(["-format", "%Q %[jpeg:sampling-factor]"])
            .arg(p)
            .output()
        else {
            eprintln!("skipped: ImageMagick's identify is not installed");
            return;
        };
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        let (q, factors) = text.trim().split_once(' ').unwrap();
        let im: u8 = q.parse().unwrap();
        let ours = parse(&std::fs::read(p).unwrap()).unwrap();
        let got = ours.quality.unwrap();
        assert!(
            got.abs_diff(im) <= 1,
            "{}: {got} vs ImageMagick {im}",
            p.display()
        );
        let expected = match factors {
            "2x2,1x1,1x1" => Some(Subsampling::S420),
            "2x1,1x1,1x1" => Some(Subsampling::S422),
            "1x1,1x1,1x1" => Some(Subsampling::S444),
            _ => None,
        };
        if factors.contains(',') {
            assert_eq!(ours.subsampling, expected, "{}", p.display());
        }
        checked += 1;
    }
    eprintln!("{checked} real JPEGs: quality and subsampling as ImageMagick reads them");
    assert!(checked > 0);
}

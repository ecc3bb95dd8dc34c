//! One gate for every file abysslight writes (docs/threat-model.md): every subcommand, with every path option
//! pointed at an input, a link to an input, a FIFO, a device node and a folder, is refused before it writes, and
//! every input is byte-identical afterwards.

#![cfg(unix)]

use crate::common;

use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{abysslight, s, snapshot};

/// A small mission and one corrected folder, plus the odd things a path can point at.
struct Site {
    _d: tempfile::TempDir,
    root: PathBuf,
    survey: PathBuf,
    water: PathBuf,
    corrected: PathBuf,
    photo: PathBuf,
    fifo: PathBuf,
    link_photo: PathBuf,
    link_survey: PathBuf,
    folder: PathBuf,
}

impl Site {
    fn new() -> Site {
        let d = tempfile::tempdir().unwrap();
        let root = d.path().canonicalize().unwrap();
        let (survey, water) = common::tiny_mission(&root, 6);
        let corrected = root.join("corrected");
        let o = abysslight(&[
            "correct",
            "-q",
            "--survey",
            s(&survey),
            "--water-column",
            s(&water),
            "--out",
            s(&corrected),
            "--window",
            "3",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let fifo = root.join("fifo");
        assert!(Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let photo = survey.join("IMG_0000.png");
        let link_photo = root.join("link-photo.png");
        let link_survey = root.join("link-survey");
        std::os::unix::fs::symlink(&photo, &link_photo).unwrap();
        std::os::unix::fs::symlink(&survey, &link_survey).unwrap();
        let folder = root.join("a-folder");
        std::fs::create_dir_all(&folder).unwrap();
        Site {
            _d: d,
            root,
            survey,
            water,
            corrected,
            photo,
            fifo,
            link_photo,
            link_survey,
            folder,
        }
    }

    /// Where a file option is pointed.
    fn file_targets(&self) -> Vec<PathBuf> {
        vec![
            self.photo.clone(),
            self.link_photo.clone(),
            self.fifo.clone(),
            PathBuf::from("/dev/null"),
            self.folder.clone(),
            self.survey.join("new.png"),
        ]
    }

    /// Where a folder option is pointed.
    fn folder_targets(&self) -> Vec<PathBuf> {
        vec![
            self.photo.clone(),
            self.link_photo.clone(),
            self.fifo.clone(),
            PathBuf::from("/dev/null"),
        ]
    }

    /// Run `args`, expect a refusal (exit 2) naming the option, and nothing changed.
    fn refused(&self, args: &[&str], flag: &str) {
        let inputs = [
            self.survey.as_path(),
            self.water.as_path(),
            self.corrected.as_path(),
        ];
        let before = snapshot(&inputs);
        let folder_before = snapshot(&[&self.folder]);
        let o = abysslight(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(flag), "{args:?} should name {flag}: {err}");
        assert_eq!(snapshot(&inputs), before, "{args:?} modified an input");
        assert_eq!(snapshot(&[&self.folder]), folder_before, "{args:?}");
        assert!(std::fs::symlink_metadata(&self.fifo)
            .unwrap()
            .file_type()
            .is_fifo());
        assert!(std::fs::symlink_metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device());
        assert!(std::fs::symlink_metadata(&self.link_photo)
            .unwrap()
            .file_type()
            .is_symlink());
    }
}

#[test]
fn every_file_option_of_every_subcommand_is_gated() {
    let site = Site::new();
    let out = site.root.join("out");
    let (sv, wc, co) = (s(&site.survey), s(&site.water), s(&site.corrected));
    // `scatter` reads the water column only.
    let frame = site.water.join("wc0.png");
    let link_frame = site.root.join("link-frame.png");
    std::os::unix::fs::symlink(&frame, &link_frame).unwrap();
    for t in [
        &frame,
        &link_frame,
        &site.fifo,
        Path::new("/dev/null"),
        &site.folder,
        &site.water.join("n.png"),
    ] {
        site.refused(&["scatter", "--water-column", wc, "--out", s(t)], "--out");
    }
    for t in site.file_targets() {
        let t = s(&t);
        #[rustfmt::skip]
        let cases: Vec<(Vec<&str>, &str)> = vec![
            (vec!["correct", "-q", "--survey", sv, "--water-column", wc, "--out", s(&out), "--window", "3",
                  "--report", t], "--report"),
            (vec!["sheet", sv, co, t], "--sheet"),
            (vec!["evaluate", sv, co, "--json", t], "--json"),
            (vec!["evaluate", sv, co, "--register", sv, "--save-placements", t], "--save-placements"),
        ];
        for (args, flag) in cases {
            site.refused(&args, flag);
        }
        // Refused before the first photo is read or written: no corrected photo.
        assert!(
            !out.join("IMG_0000.png").exists(),
            "correct --report {t}: photos written before the refusal"
        );
    }
}

#[test]
fn every_folder_option_of_every_subcommand_is_gated() {
    let site = Site::new();
    let (sv, wc) = (s(&site.survey), s(&site.water));
    let mut targets = site.folder_targets();
    targets.push(site.link_survey.clone());
    targets.push(site.survey.clone());
    for t in &targets {
        let t = s(t);
        site.refused(
            &[
                "correct",
                "-q",
                "--survey",
                sv,
                "--water-column",
                wc,
                "--out",
                t,
            ],
            "--out",
        );
    }
    for t in site.folder_targets() {
        let t = s(&t);
        site.refused(
            &["simulate", "--frames", "4", "--size", "32x24", "--out", t],
            "--out",
        );
        site.refused(&["demo", "--out", t], "--out");
        site.refused(
            &["bench", "--size", "64x48", "--photos", "2", "--dir", t],
            "--dir",
        );
    }
}

/// A link inside `--out/_abysslight` to the survey (`factors`, `factors-preview`) is refused up front: before,
/// `--save-factors` wrote an F·C image over every survey photo through it.
#[test]
fn save_factors_does_not_write_through_a_link_into_the_survey() {
    let site = Site::new();
    for name in ["factors", "factors-preview"] {
        let out = site.root.join(format!("out-{name}"));
        std::fs::create_dir_all(out.join("_abysslight")).unwrap();
        std::os::unix::fs::symlink(&site.survey, out.join("_abysslight").join(name)).unwrap();
        #[rustfmt::skip]
        site.refused(
            &["correct", "-q", "--survey", s(&site.survey), "--water-column", s(&site.water), "--out", s(&out),
              "--window", "3", "--save-factors", "--save-scatter"],
            "symbolic link",
        );
        assert!(!out.join("IMG_0000.png").exists());
    }
}

/// `--report DIR` and a report in a folder that cannot be written are found before the photos are corrected.
#[test]
fn an_unwritable_report_is_found_up_front() {
    let site = Site::new();
    let out = site.root.join("out");
    let ro = site.root.join("read-only");
    std::fs::create_dir_all(&ro).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    let writable = tempfile::tempfile_in(&ro).is_ok();
    let mut targets = vec![site.folder.clone()];
    if !writable {
        targets.push(ro.join("report.json"));
    } else {
        eprintln!("running as root: a read-only folder is writable, that case is not tested here");
    }
    for t in targets {
        #[rustfmt::skip]
        site.refused(
            &["correct", "-q", "--survey", s(&site.survey), "--water-column", s(&site.water), "--out", s(&out),
              "--window", "3", "--report", s(&t)],
            "--report",
        );
        assert!(!out.join("IMG_0000.png").exists());
    }
}

/// `--watch` skips a survey link into `--out`, as a batch run does (before: outputs fed back as photos, nested
/// ever deeper).
#[test]
fn watch_skips_a_survey_link_into_the_output_folder() {
    let site = Site::new();
    let out = site.root.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::symlink(&out, site.survey.join("loop")).unwrap();
    #[rustfmt::skip]
    let o = abysslight(&[
        "correct", "-q", "--survey", s(&site.survey), "--water-column", s(&site.water), "--out", s(&out),
        "--window", "3", "--watch", "--poll-interval", "50", "--idle-timeout", "1.5",
    ]);
    std::fs::remove_file(site.survey.join("loop")).unwrap();
    let written: Vec<_> = walkdir::WalkDir::new(&out)
        .into_iter()
        .flatten()
        .filter(|e| e.file_type().is_file() && e.path().extension().is_some_and(|x| x == "png"))
        .filter(|e| !e.path().starts_with(out.join("_abysslight")))
        .map(|e| e.path().strip_prefix(&out).unwrap().to_owned())
        .collect();
    assert_eq!(
        written.len(),
        6,
        "{written:?}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        written.iter().all(|p| p.components().count() == 1),
        "{written:?}"
    );
}

//! Never lose a photo on the cluster surfaces: a cruise never writes into a dive's inputs, a sharded cruise's
//! merge names a dive no task wrote a report for, a mask that hides every pixel is refused with or without a
//! water column, and photos of any legal size (thinner than a block, one pixel wide) are corrected or fail one by
//! one with a message, never a panic.

use crate::common;

use std::path::Path;

use common::*;

/// A cruise in `root/cruise`: dive1 with survey and water column, dive2 with a survey only (9 photos each).
fn cruise(root: &Path) {
    for (i, name) in ["dive1", "dive2"].iter().enumerate() {
        let dv = dive(40, 24, 9, 5, 0.2, false, 70 + i as u64);
        let dir = root.join("cruise").join(name);
        write_all(&dv.photos, &dir.join("survey"), "img", "png");
        if i == 0 {
            write_all(&dv.water, &dir.join("water-column"), "wc", "png");
        }
    }
}

#[test]
fn a_cruise_never_writes_into_a_dives_inputs() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    cruise(root);
    let before = snapshot(&[&root.join("cruise")]);
    for (out, input) in [
        ("cruise/dive2/survey/corrected", "survey of dive dive2"),
        // dive2 has no water-column folder yet: outputs there would be its water column on the next run.
        ("cruise/dive2/water-column", "water column of dive dive2"),
        (
            "cruise/dive1/water-column/out",
            "water column of dive dive1",
        ),
        ("cruise", "contains the survey of dive dive1"),
    ] {
        let o = abysslight_in(
            &["correct", "--cruise", "cruise", "--out", out, "--quiet"],
            root,
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "--out {out}: {e}");
        assert!(e.contains(input) && e.contains(out), "--out {out}: {e}");
        assert_eq!(
            snapshot(&[&root.join("cruise")]),
            before,
            "--out {out} wrote into the cruise"
        );
        assert!(!root.join("cruise/dive2/water-column").exists(), "{out}");
        // The library's cruise refuses it as well, before any dive runs.
        let base = abysslight::Options {
            out: Some(root.join(out)),
            window: Some(5),
            ..abysslight::Options::default()
        };
        let r =
            abysslight::cruise::correct_cruise(&base, &root.join("cruise"), &abysslight::Silent);
        assert!(r.is_err(), "library, --out {out}");
        assert_eq!(snapshot(&[&root.join("cruise")]), before, "library, {out}");
    }
    // Beside the cruise: both dives run.
    let o = abysslight_in(
        &["correct", "--cruise", "cruise", "--out", "out", "--quiet"],
        root,
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(outputs(&root.join("out/dive1")).len(), 9);
    assert_eq!(outputs(&root.join("out/dive2")).len(), 9);
}

#[test]
fn a_sharded_cruise_names_the_dive_no_task_reported() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    cruise(root);
    // dive3's survey is still being copied: empty.
    std::fs::create_dir_all(root.join("cruise/dive3/survey")).unwrap();
    // A dry run writes nothing, not even the record of the dives.
    let o = abysslight_in(
        &[
            "correct",
            "--cruise",
            "cruise",
            "--out",
            "out",
            "--shard",
            "1/2",
            "--dry-run",
        ],
        root,
    );
    assert!(!root.join("out").exists(), "{}", stderr(&o));
    for k in ["1/2", "2/2"] {
        let o = abysslight_in(
            &[
                "correct", "--cruise", "cruise", "--out", "out", "--shard", k, "--quiet",
            ],
            root,
        );
        assert_eq!(o.status.code(), Some(2), "task {k}: {}", stderr(&o));
    }
    let o = abysslight_in(&["merge-shards", "out"], root);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("dive dive3") && e.contains("no"), "{e}");
    // The dives that ran are merged all the same.
    assert!(
        root.join("out/dive1/_abysslight/report.json").is_file(),
        "{e}"
    );
    assert!(
        root.join("out/dive2/_abysslight/report.json").is_file(),
        "{e}"
    );
    // The library's merge names it too.
    let merged = abysslight::cruise::merge_cruise(&root.join("out")).unwrap();
    let names: Vec<(&str, bool)> = merged
        .iter()
        .map(|(n, r)| (n.as_str(), r.is_ok()))
        .collect();
    assert_eq!(names, [("dive1", true), ("dive2", true), ("dive3", false)]);
}

#[test]
fn a_mask_hiding_every_pixel_is_refused_without_a_water_column() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    tiny_mission(root, 9);
    image::GrayImage::from_pixel(32, 24, image::Luma([255]))
        .save(root.join("white.png"))
        .unwrap();
    for (water, out) in [(false, "out1"), (true, "out2")] {
        let mut args = vec![
            "correct",
            "--survey",
            "survey",
            "--out",
            out,
            "--mask",
            "white.png",
        ];
        if water {
            args.extend(["--water-column", "water"]);
        }
        let o = abysslight_in(&args, root);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "water column {water}: {e}");
        assert!(
            e.contains("white.png") && e.contains("ignores every pixel"),
            "water column {water}: {e}"
        );
        assert!(
            !root.join(out).exists() || outputs(&root.join(out)).is_empty(),
            "water column {water}: photos written"
        );
    }
}

#[test]
fn photos_of_any_legal_size_are_corrected_or_fail_one_by_one() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    for (w, h) in [
        (4000, 7),
        (7, 4000),
        (1, 40),
        (40, 1),
        (2, 2),
        (1, 1),
        (9, 9),
        (3, 700),
    ] {
        let survey = root.join(format!("s{w}x{h}"));
        std::fs::create_dir_all(&survey).unwrap();
        for i in 0..9 {
            pattern(w, h, i)
                .save(survey.join(format!("img{i}.png")))
                .unwrap();
        }
        let out = root.join(format!("o{w}x{h}"));
        let o = abysslight_in(&["correct", "--survey", s(&survey), "--out", s(&out)], root);
        let e = stderr(&o);
        assert!(
            matches!(o.status.code(), Some(0 | 1)),
            "{w}x{h}: exit {:?}: {e}",
            o.status.code()
        );
        assert!(!e.contains("panicked"), "{w}x{h}: {e}");
        let r = report(&out);
        let frames = r["frames"].as_array().unwrap().len();
        let errors = r["errors"].as_array().unwrap();
        assert_eq!(frames + errors.len(), 9, "{w}x{h}: {r}");
        for err in errors {
            let m = err["message"].as_str().unwrap();
            assert!(
                m.contains("img"),
                "{w}x{h}: an error not naming its photo: {m}"
            );
        }
        assert_eq!(outputs(&out).len(), frames, "{w}x{h}");
    }
}

/// Copy `from` (a file or a folder, recursively) to `to`.
fn copy_tree(from: &Path, to: &Path) {
    if from.is_dir() {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap().flatten() {
            copy_tree(&e.path(), &to.join(e.file_name()));
        }
    } else {
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(from, to).unwrap_or_else(|e| panic!("{}: {e}", from.display()));
    }
}

/// The build stage's context as deploy/container/Containerfile's `COPY` lines assemble it below its `WORKDIR`
/// (no container engine runs here): each `COPY SRC... DEST` of the first stage, `--from` copies left out.
fn container_build_context(repo: &Path, into: &Path) -> usize {
    let text = std::fs::read_to_string(repo.join("deploy/container/Containerfile")).unwrap();
    // Continuation lines joined, comments left out.
    let joined = text
        .lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n")
        .replace("\\\n", " ");
    let (mut stages, mut workdir, mut copies) = (0, into.to_path_buf(), 0);
    for line in joined.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.first().map(|w| w.to_ascii_uppercase()).as_deref() {
            Some("FROM") => stages += 1,
            Some("WORKDIR") if stages == 1 => {
                workdir = into.join(words[1].trim_start_matches('/'));
                std::fs::create_dir_all(&workdir).unwrap();
            }
            Some("COPY") if stages == 1 => {
                let args: Vec<&str> = words[1..]
                    .iter()
                    .copied()
                    .filter(|w| !w.starts_with("--"))
                    .collect();
                assert!(
                    !words[1..].iter().any(|w| w.starts_with("--from")),
                    "{line}"
                );
                let (dest, sources) = args.split_last().unwrap();
                let dest = workdir.join(dest);
                for src in sources {
                    let target = if sources.len() > 1 || dest.to_string_lossy().ends_with('/') {
                        dest.join(Path::new(src).file_name().unwrap())
                    } else {
                        dest.clone()
                    };
                    copy_tree(&repo.join(src), &target);
                    copies += 1;
                }
            }
            _ => {}
        }
    }
    assert!(stages >= 2, "a build stage and a runtime stage: {text}");
    copies
}

#[test]
fn the_container_build_context_holds_the_whole_workspace() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let d = tempfile::tempdir().unwrap();
    let copies = container_build_context(repo, d.path());
    assert!(copies >= 4, "{copies} sources copied");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let o = std::process::Command::new(cargo)
        // `--no-deps`: the members are what the context must hold, and a
        // resolve would need every platform's crates in the local registry.
        .args([
            "metadata",
            "--offline",
            "--no-deps",
            "--format-version",
            "1",
        ])
        .current_dir(d.path().join("src"))
        .env("CARGO_TARGET_DIR", d.path().join("target"))
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "cargo metadata in the container's build context: {}",
        stderr(&o)
    );
    let meta: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let names: Vec<&str> = meta["packages"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["source"].is_null())
        .filter_map(|p| p["name"].as_str())
        .collect();
    assert!(
        names.contains(&"abysslight") && names.contains(&"abysslight-python"),
        "{names:?}"
    );
    // The run examples write as the calling user.
    let text = std::fs::read_to_string(repo.join("deploy/container/Containerfile")).unwrap();
    assert!(text.contains("--user \"$(id -u):$(id -g)\""), "{text}");
}

#[test]
fn a_cruise_keeps_every_dives_report_and_its_own_water_column() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    cruise(root);
    // A config naming a water column (dive1's): dive2, which has none, must not take it.
    std::fs::write(
        root.join("cruise.toml"),
        "water-column = \"cruise/dive1/water-column\"\nwindow = 5\n",
    )
    .unwrap();
    let o = abysslight_in(
        &[
            "correct",
            "--cruise",
            "cruise",
            "--out",
            "out",
            "--config",
            "cruise.toml",
            "--report",
            "cruise.json",
            "--quiet",
        ],
        root,
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // --report FILE: one per dive (the report goes there instead of OUT/<dive>/_abysslight/).
    let dive = |name: &str| json(&root.join(format!("cruise-{name}.json")));
    let (dive1, dive2) = (dive("dive1"), dive("dive2"));
    assert_eq!(
        dive1["scatter"]["frames"].as_u64(),
        Some(5),
        "{}",
        dive1["scatter"]
    );
    assert_eq!(
        dive2["scatter"]["frames"].as_u64().unwrap_or(0),
        0,
        "dive2 took another dive's water column: {}",
        dive2["scatter"]
    );
    for name in ["dive1", "dive2"] {
        let r = json(&root.join(format!("cruise-{name}.json")));
        assert_eq!(r["corrected"].as_u64(), Some(9), "{name}");
        assert!(
            r["options"]["survey"].as_str().unwrap().contains(name),
            "{name}"
        );
    }
}

/// `merge-shards.sbatch` given the array's arguments where `--out` is only in the `--config` file (before: "give
/// OUT", exit 2): it merges the shards the config's out holds. Run with bash, as SLURM runs the script on a node.
#[test]
fn the_merge_script_takes_out_from_the_config_file() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    let dv = dive(40, 24, 10, 5, 0.2, false, 81);
    write_all(&dv.photos, &root.join("survey"), "img", "png");
    write_all(&dv.water, &root.join("water"), "wc", "png");
    std::fs::write(
        root.join("dive.toml"),
        "survey = \"survey\"\nwater-column = \"water\"\nout = \"corrected\"\nwindow = 5\n",
    )
    .unwrap();
    for k in 1..=2 {
        let shard = format!("{k}/2");
        let o = abysslight_in(
            &["correct", "--config", "dive.toml", "--shard", &shard, "-q"],
            root,
        );
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/slurm/merge-shards.sbatch");
    let merge = |args: &[&str]| {
        std::process::Command::new("bash")
            .arg(&script)
            .args(args)
            .env("ABYSSLIGHT", BIN)
            .current_dir(root)
            .output()
            .unwrap()
    };
    // The array's own arguments: --config, and --shard as each task had it (the script ignores it).
    let o = merge(&["--config", "dive.toml", "--shard", "1/2"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r = json(&root.join("corrected/_abysslight/report.json"));
    assert_eq!(r["corrected"], 10, "{r}");
    // --config=FILE too, and an --out flag over the file's.
    std::fs::remove_file(root.join("corrected/_abysslight/report.json")).unwrap();
    let o = merge(&["--config=dive.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(root.join("corrected/_abysslight/report.json").is_file());
    let o = merge(&["--config", "dive.toml", "--out", "elsewhere"]);
    assert_eq!(o.status.code(), Some(2), "the flag wins: {}", stderr(&o));
    assert!(stderr(&o).contains("elsewhere"), "{}", stderr(&o));
    // A config without out is named.
    std::fs::write(root.join("no-out.toml"), "survey = \"survey\"\n").unwrap();
    let o = merge(&["--config", "no-out.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("no-out.toml"), "{}", stderr(&o));
}

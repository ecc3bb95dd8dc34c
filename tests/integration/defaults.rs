//! One set of defaults: `abysslight correct` without options, `Options::default()` through `correct_mission`, and
//! `Params::default()` through the in-memory `Engine` run the same method and give the same pixels; the mapping from
//! `Options` to `Params` carries every setting of the method.

use std::path::Path;

use abysslight::Engine;
use abysslight::Transfer;
use abysslight::{Method, Options};
use abysslight::{Params, Steps};
use abysslight::{Photo, Samples};
use abysslight::{Scatter, SeafloorColour};

fn run(args: &[&str], cwd: &Path) {
    let o = crate::common::abysslight_in(args, cwd);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn photos(dir: &Path) -> Vec<(String, Photo)> {
    abysslight::io::find_photos(dir)
        .unwrap()
        .photos
        .into_iter()
        .map(|e| {
            let name = e.relative.to_string_lossy().into_owned();
            (name, abysslight::io::decode(&e.path).unwrap())
        })
        .collect()
}

fn samples(p: &Photo) -> Vec<u16> {
    match &p.samples {
        Samples::U8(v) => v.iter().map(|&x| x as u16).collect(),
        Samples::U16(v) => v.clone(),
    }
}

#[test]
fn the_command_line_options_and_params_defaults_give_the_same_pixels() {
    let d = tempfile::tempdir().unwrap();
    let dive = d.path().join("dive");
    let dive_s = dive.to_str().unwrap();
    // 12 photos of 160×120: blocks auto (4) and the near window auto (5 inside 7) both take effect.
    run(
        &[
            "simulate",
            "--out",
            dive_s,
            "--frames",
            "12",
            "--water-column",
            "5",
            "--size",
            "160x120",
            "--encode",
            "linear",
        ],
        d.path(),
    );
    let (water, survey) = (dive.join("water"), dive.join("survey"));
    let cli_out = d.path().join("cli");
    run(
        &[
            "correct",
            "--water-column",
            water.to_str().unwrap(),
            "--survey",
            survey.to_str().unwrap(),
            "--out",
            cli_out.to_str().unwrap(),
            "-q",
        ],
        d.path(),
    );
    let lib_out = d.path().join("lib");
    let opts = Options {
        water_column: Some(water.clone()),
        survey: Some(survey.clone()),
        out: Some(lib_out.clone()),
        ..Options::default()
    };
    abysslight::correct_mission(&opts, &abysslight::Silent).unwrap();

    let frames: Vec<Photo> = photos(&water).into_iter().map(|(_, p)| p).collect();
    let scatter = Scatter::from_frames(&frames).unwrap();
    let mut engine = Engine::new(Params::default(), scatter.as_ref(), None).unwrap();
    let mut mem = Vec::new();
    for (name, p) in photos(&survey) {
        mem.extend(engine.push((p, name)).unwrap());
    }
    mem.extend(engine.finish());
    assert_eq!(
        engine.params().steps.near_window,
        Some(5),
        "auto near window"
    );
    assert_eq!(engine.params().downsample, 4, "auto blocks");

    let cli = photos(&cli_out);
    let lib = photos(&lib_out);
    assert_eq!(cli.len(), 12);
    assert_eq!(mem.len(), 12);
    for ((c, l), m) in cli.iter().zip(&lib).zip(&mem) {
        assert_eq!(c.0, l.0);
        assert_eq!(c.0, m.tag);
        let m = samples(m.photo.as_ref().unwrap());
        assert!(
            samples(&c.1) == samples(&l.1),
            "{}: CLI and Options differ",
            c.0
        );
        assert!(samples(&c.1) == m, "{}: CLI and Params differ", c.0);
    }
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(cli_out.join("_abysslight/report.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["options"]["transfer"], "linear");
    assert_eq!(report["options"]["near-window"], 5);
    assert_eq!(report["options"]["downsample"], 4);
}

#[test]
fn options_default_is_params_default_and_every_method_setting_reaches_params() {
    let base = Options::default();
    assert_eq!(base.params().unwrap(), Params::default());
    // Each of the method's settings, changed on its own, changes Params (and only what it should).
    let changed: Vec<(&str, Options)> = vec![
        (
            "method",
            Options {
                method: Method::Paper,
                ..base.clone()
            },
        ),
        (
            "window",
            Options {
                window: Some(9),
                ..base.clone()
            },
        ),
        (
            "contamination",
            Options {
                contamination: Some(0.2),
                ..base.clone()
            },
        ),
        (
            "downsample",
            Options {
                downsample: Some(6),
                ..base.clone()
            },
        ),
        (
            "near_window",
            Options {
                near_window: Some(3),
                ..base.clone()
            },
        ),
        (
            "seafloor_colour",
            Options {
                seafloor_colour: SeafloorColour([0.5, 0.4, 0.3]),
                ..base.clone()
            },
        ),
        (
            "factor_floor",
            Options {
                factor_floor: 0.1,
                ..base.clone()
            },
        ),
        (
            "transfer",
            Options {
                transfer: Some(Transfer::Srgb),
                ..base.clone()
            },
        ),
        (
            "degree",
            Options {
                degree: 3,
                ..base.clone()
            },
        ),
        (
            "relative_floor",
            Options {
                relative_floor: 0.01,
                ..base.clone()
            },
        ),
        (
            "level_exposures",
            Options {
                level_exposures: false,
                ..base.clone()
            },
        ),
        (
            "photo_gain",
            Options {
                photo_gain: false,
                ..base.clone()
            },
        ),
        (
            "backscatter_scale",
            Options {
                backscatter_scale: None,
                ..base.clone()
            },
        ),
        (
            "denoise",
            Options {
                denoise: false,
                ..base.clone()
            },
        ),
        (
            "level_by_light",
            Options {
                level_by_light: false,
                ..base.clone()
            },
        ),
        (
            "bright_spots",
            Options {
                bright_spots: true,
                ..base.clone()
            },
        ),
        (
            "overlaps",
            Options {
                overlaps: true,
                ..base.clone()
            },
        ),
    ];
    for (name, o) in &changed {
        assert_ne!(
            o.params().unwrap(),
            Params::default(),
            "{name} did not reach Params"
        );
    }
    let c = Options {
        contamination: Some(0.2),
        ..base.clone()
    }
    .params()
    .unwrap();
    assert_eq!(
        c.window_length(),
        13,
        "--contamination 0.2 chooses the 1 % window"
    );
    assert_eq!(c.window_quantile(), 0.6);
    assert_eq!(c.near_window(), Some(7));
    let s = Options {
        bright_spots: true,
        level_exposures: false,
        photo_gain: false,
        overlaps: true,
        ..base.clone()
    }
    .params()
    .unwrap();
    assert_eq!(
        s.steps,
        Steps {
            bright_spots: true,
            level_exposures: false,
            photo_gain: false,
            overlaps: true,
            ..Steps::default()
        }
    );
    // The run's own settings do not touch the method.
    let run_only = Options {
        threads: Some(1),
        resume: true,
        save_factors: true,
        limit: Some(3),
        jpeg_quality: Some(80),
        ..base.clone()
    };
    assert_eq!(run_only.params().unwrap(), Params::default());
}

#[test]
fn auto_settings_resolve_in_one_place() {
    use abysslight::{BlockRule, Facts};
    let p = Params::default();
    let facts = |size, masked| Facts {
        size,
        masked,
        transfer: None,
    };
    assert_eq!(
        p.auto_block(&facts(Some((320, 240)), false)),
        (4, BlockRule::Size)
    );
    assert_eq!(
        p.auto_block(&facts(Some((4000, 3000)), false)),
        (8, BlockRule::Size)
    );
    assert_eq!(
        p.auto_block(&facts(Some((320, 240)), true)),
        (8, BlockRule::Masked)
    );
    assert_eq!(p.auto_block(&facts(None, false)), (0, BlockRule::Unknown));
    let paper = Params {
        method: Method::Paper,
        ..p
    };
    assert_eq!(
        paper.auto_block(&facts(Some((320, 240)), false)),
        (8, BlockRule::Paper)
    );
    let given = Params { downsample: 5, ..p };
    assert_eq!(
        given.auto_block(&facts(Some((320, 240)), true)),
        (5, BlockRule::Given)
    );
    // The curve: what the files declare, else linear; a given curve wins.
    let declared = Facts {
        transfer: Some(Transfer::Srgb),
        ..facts(None, false)
    };
    assert_eq!(p.resolved(&declared).transfer, Some(Transfer::Srgb));
    assert_eq!(
        p.resolved(&facts(None, false)).transfer,
        Some(Transfer::Linear)
    );
    let told = Params {
        transfer: Some(Transfer::Gamma(2.2)),
        ..p
    };
    assert_eq!(
        told.resolved(&declared).transfer,
        Some(Transfer::Gamma(2.2))
    );
    // Resolving twice changes nothing; the near window is off for the paper and when not shorter.
    let r = p.resolved(&facts(Some((320, 240)), false));
    assert_eq!(r.resolved(&facts(Some((320, 240)), false)), r);
    assert_eq!(r.steps.near_window, Some(5));
    assert_eq!(
        paper.resolved(&facts(None, false)).steps.near_window,
        Some(0)
    );
    let short = Params {
        window: abysslight::Window::Fixed(5),
        ..p
    };
    assert_eq!(short.near_window(), None);
    // The engine resolves the mask rule too: a masked mission in memory keeps the paper's 8.
    let mask = abysslight::Mask {
        width: 320,
        height: 240,
        ignore: vec![false; 320 * 240],
    };
    let e: Engine<usize> = Engine::new(p, None, Some(mask)).unwrap();
    assert_eq!(e.params().downsample, 8);
}

/// `correct --help` prints the method's defaults of `Params::default()` (and `Options::default()`, made from it):
/// each `[default: …]` of the method's options is the value a run takes without the option.
#[test]
fn help_prints_the_defaults_params_default_holds() {
    let o = crate::common::abysslight(&["correct", "--help"]);
    let help = crate::common::stdout(&o)
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    let default_of = |flag: &str| -> String {
        let at = help
            .find(&format!("{flag} <"))
            .or_else(|| help.find(&format!("{flag} ")))
            .unwrap_or_else(|| panic!("{flag} not in --help"));
        let rest = &help[at..];
        let d = rest
            .find("[default: ")
            .unwrap_or_else(|| panic!("{flag}: no default"));
        let v = &rest[d + 10..];
        v[..v.find(']').unwrap()].to_string()
    };
    let p = Params::default();
    let o = Options::default();
    assert_eq!(default_of("--method"), p.method.to_string());
    assert_eq!(
        default_of("--relative-floor").parse::<f32>().unwrap(),
        p.steps.relative_floor
    );
    assert_eq!(
        default_of("--factor-floor").parse::<f32>().unwrap(),
        p.factor_floor
    );
    assert_eq!(default_of("--degree").parse::<usize>().unwrap(), p.degree);
    assert_eq!(default_of("--risk").parse::<f64>().unwrap(), o.risk);
    assert_eq!(
        Some(default_of("--backscatter-scale").parse::<f32>().unwrap()),
        p.steps.backscatter_scale
    );
    assert_eq!(default_of("--window"), "auto");
    assert_eq!(p.window, abysslight::Window::Auto);
    assert_eq!(default_of("--near-window"), "auto");
    assert_eq!(p.steps.near_window, None);
    assert_eq!(default_of("--downsample"), "auto");
    assert_eq!(p.downsample, 0);
    assert_eq!(o.params().unwrap(), p);
}

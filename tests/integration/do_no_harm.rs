//! Do no harm: the survey's window is a hypothesis checked against the paper's window 7 on what the photos show
//! (docs/method.md). Block images made here: a swinging sledge over bare sediment and over a dense nodule field,
//! and the same field flown level.

use abysslight::eval::simulate::Simulation;
use abysslight::{correct_mission, Options, Raster, Silent, Survey};

const W: usize = 40;
const H: usize = 30;

/// Altitude of photo `t` of `n`: 4 m, swinging by `swing` metres 1.3 cycles over the mission.
fn altitude(t: usize, n: usize, swing: f32) -> f32 {
    4.0 + swing * (std::f32::consts::TAU * 1.3 * t as f32 / n as f32).sin()
}

/// The seafloor under block `(x, y)` of photo `t`, the camera moving `step` blocks a photo: sediment of level 1 with
/// a little texture, and dark nodules (0.15) covering a share `cover` in patches of 2×2 blocks.
fn albedo(x: usize, y: usize, t: usize, step: usize, cover: f64) -> f32 {
    let gx = x + t * step;
    let hash = |a: u64, b: u64, k: u64| {
        let v = (a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F) ^ k)
            .wrapping_mul(0x1656_67B1_9E37_79F9);
        (v >> 11) as f64 / (1u64 << 53) as f64
    };
    let texture = 1.0 + 0.1 * (hash(gx as u64, y as u64, 1) as f32 - 0.5);
    let dark = hash((gx / 2) as u64, (y / 2) as u64, 2) < cover;
    texture * if dark { 0.15 } else { 1.0 }
}

/// The block images (grey, linear) of a mission of `n` photos under a side light that moves and widens with the
/// altitude and dims with its square, over the water-column backscatter's share that reaches the floor from that
/// height; and the backscatter the water column gives (all of it: more than reaches the floor).
fn mission(n: usize, swing: f32, step: usize, cover: f64) -> (Vec<Raster>, Raster) {
    let s_water = |x: usize| 0.15 * (1.0 - x as f32 / W as f32);
    let lows = (0..n)
        .map(|t| {
            let a = altitude(t, n, swing);
            let (cx, sigma) = (0.65 * W as f32 + 3.0 * (a - 4.0), 0.3 * W as f32 * a / 4.0);
            Raster::from_fn(W, H, 1, |x, y, _| {
                let d = ((x as f32 - cx) / sigma).powi(2)
                    + ((y as f32 - 0.5 * H as f32) / (1.2 * sigma)).powi(2);
                let light = (4.0 / a).powi(2) * 0.8 * (-d).exp();
                light * albedo(x, y, t, step, cover) + s_water(x) * (a / 6.0).min(1.0)
            })
        })
        .collect();
    (lows, Raster::from_fn(W, H, 1, |x, _, _| s_water(x)))
}

fn survey(lows: &[Raster], s: &Raster) -> Survey {
    let mut survey = Survey::new(Some(s));
    lows.iter().for_each(|l| survey.push(l));
    survey.finish();
    survey
}

/// What report.json says of a choice: its `won` (which choice won the check against the paper's window).
fn won(c: &impl serde::Serialize) -> String {
    serde_json::to_value(c).expect("choice as JSON")["won"]
        .as_str()
        .unwrap_or("")
        .to_string()
}

/// Bare sediment under a swinging sledge (4 ± 1.6 m), the backscatter given the water column's (larger than what
/// reaches the floor): the survey reads at most 10 % dark on every photo, whatever the swing. Measured against one
/// level for the whole frame, the dim side of the lights' shape at the top of a swing read as dark: up to a third
/// of the photo.
#[test]
fn bare_sediment_with_swings_reads_no_cover() {
    for swing in [0.0, 0.8, 1.6] {
        let (lows, s) = mission(60, swing, 5, 0.0);
        let s = survey(&lows, &s);
        let most = s
            .choices()
            .iter()
            .map(|c| c.coverage)
            .fold(0.0f32, f32::max);
        assert!(most <= 0.10, "swing {swing} m: the survey read {most} dark");
    }
}

/// A dense nodule field (40 %) flown level: the survey's longer window and quantile win (the lights' shape is the
/// same along the window). Flown with a swing of 1.6 m, the lights' shape changes along that window more than
/// within the paper's window: a third of the photos or more (those at the swing's steep parts) take the window 7 and
/// the median, and say so (`won: short`, rule `unsteady`).
#[test]
fn the_survey_s_window_falls_back_to_the_short_one_where_the_lighting_changes_along_it() {
    let (lows, s) = mission(60, 0.0, 3, 0.4);
    let level = survey(&lows, &s);
    let longer: Vec<_> = level.choices().iter().filter(|c| c.window > 7).collect();
    assert!(
        longer.len() >= 40,
        "a dense field: the survey asks for longer windows ({} photos)",
        longer.len()
    );
    assert!(
        longer
            .iter()
            .all(|c| won(*c) == "survey" && c.quantile > 0.5),
        "level: the survey's choice is kept: {:?}",
        longer.iter().find(|c| won(*c) != "survey")
    );
    let (lows, s) = mission(60, 1.6, 3, 0.4);
    let swung = survey(&lows, &s);
    let mut short = 0;
    for c in swung.choices() {
        match won(c).as_str() {
            "short" => {
                short += 1;
                assert_eq!((c.window, c.quantile, c.near), (7, 0.5, None), "{c:?}");
                assert!(c.drift > 1.3, "{c:?}");
                let why = serde_json::to_value(c).expect("JSON")["rule"].clone();
                assert_eq!(why, "unsteady", "{c:?}");
            }
            "survey" => assert!(c.window > 7 || c.quantile > 0.5, "{c:?}"),
            other => assert_eq!(other, "paper", "{c:?}"),
        }
    }
    assert!(
        short >= 20,
        "swinging: {short} of 60 photos fell back to the short window"
    );
}

/// report.json says, for every photo, which choice won and on what evidence (`won`, `drift`, `why`).
#[test]
fn report_json_says_which_window_won_and_why() {
    let dir = tempfile::tempdir().expect("temp dir");
    let sim = Simulation {
        frames: 24,
        water_column: 6,
        width: 160,
        height: 120,
        contamination: 0.4,
        altitude_swing: Some(1.2),
        seed: 5,
        ..Simulation::default()
    };
    sim.render_with_lighting()
        .expect("render")
        .write(dir.path())
        .expect("write the dive");
    let out = dir.path().join("out");
    correct_mission(
        &Options {
            water_column: Some(dir.path().join("water")),
            survey: Some(dir.path().join("survey")),
            out: Some(out.clone()),
            ..Options::default()
        },
        &Silent,
    )
    .expect("correct");
    let text = std::fs::read_to_string(out.join("_abysslight/report.json")).expect("report.json");
    let report: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let frames = report["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 24);
    for f in frames {
        let w = &f["window_auto"];
        let won = w["won"].as_str().expect("won");
        assert!(["paper", "survey", "short"].contains(&won), "{w}");
        assert!(w["why"].as_str().is_some_and(|s| !s.is_empty()), "{w}");
        assert!(w.get("drift").is_some(), "{w}");
        if won == "short" {
            assert_eq!(w["window"], 7, "{w}");
            assert!(w["why"].as_str().unwrap().contains("changed"), "{w}");
        }
    }
}

//! Do no harm: the survey's longer window is a hypothesis checked against the paper's window 7 on the lights' shape
//! in the photos themselves (docs/method.md), and where the window 7 fits better it is taken, in every way in, and
//! report.json says so and why. A dense field (40 %) under a swinging vehicle (4 ± 1.6 m) whose side light moves
//! and widens with the altitude, where the check acts.

use std::path::Path;

use crate::common::*;

use abysslight::{correct_mission, Options, Silent, Transfer};

/// 40 photos of 160×120 (16-bit linear RGB) and 6 water-column frames: sediment of level 1 with a little texture and
/// dark nodules (0.15) covering 40 % in patches of 8×8 pixels, the camera moving 12 pixels a photo, under a side
/// light whose centre moves by 12 pixels and whose width grows with each metre of altitude, dimming with its square
/// (4 ± 1.6 m, 1.3 cycles), over a backscatter that falls off across the frame.
fn swinging_field(root: &Path) {
    let (w, h, n) = (160u32, 120u32, 40usize);
    let hash = |a: u64, b: u64, k: u64| {
        let v = (a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F) ^ k)
            .wrapping_mul(0x1656_67B1_9E37_79F9);
        (v >> 11) as f64 / (1u64 << 53) as f64
    };
    let s = |x: u32| 0.05 * (1.0 - x as f32 / w as f32);
    let code = |v: f32| image::Rgb([(v.clamp(0.0, 1.0) * 65535.0).round() as u16; 3]);
    std::fs::create_dir_all(root.join("survey")).unwrap();
    std::fs::create_dir_all(root.join("water")).unwrap();
    for t in 0..n {
        let a = 4.0 + 1.6 * (std::f32::consts::TAU * 1.3 * t as f32 / n as f32).sin();
        let (cx, sigma) = (0.65 * w as f32 + 12.0 * (a - 4.0), 0.3 * w as f32 * a / 4.0);
        let photo = image::ImageBuffer::from_fn(w, h, |x, y| {
            let gx = x as u64 + 12 * t as u64;
            let texture = 1.0 + 0.1 * (hash(gx, y as u64, 1) as f32 - 0.5);
            let nodule = hash(gx / 8, y as u64 / 8, 2) < 0.4;
            let albedo = texture * if nodule { 0.15 } else { 1.0 };
            let d = ((x as f32 - cx) / sigma).powi(2)
                + ((y as f32 - 0.5 * h as f32) / (1.2 * sigma)).powi(2);
            code(0.5 * (4.0 / a).powi(2) * (-d).exp() * albedo + s(x))
        });
        photo
            .save(root.join(format!("survey/s{t:04}.png")))
            .unwrap();
    }
    for i in 0..6 {
        image::ImageBuffer::from_fn(w, h, |x, _| code(s(x)))
            .save(root.join(format!("water/w{i}.png")))
            .unwrap();
    }
}

#[test]
fn where_the_lights_change_along_the_survey_s_window_the_window_7_is_taken_and_said() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path().join("dive");
    swinging_field(&root);
    let out = d.path().join("batch");
    let opts = Options {
        water_column: Some(root.join("water")),
        survey: Some(root.join("survey")),
        out: Some(out.clone()),
        transfer: Some(Transfer::Linear),
        ..Options::default()
    };
    let report = correct_mission(&opts, &Silent).unwrap();
    assert_eq!(report.corrected, 40);

    // report.json: every photo's rule and why; where the window 7 won, the misfits that decided it.
    let text = std::fs::read_to_string(out.join("_abysslight/report.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let frames = json["frames"].as_array().unwrap();
    let (mut unsteady, mut kept) = (0, 0);
    for f in frames {
        let w = &f["window_auto"];
        let rule = w["rule"].as_str().unwrap();
        assert!(w["why"].as_str().is_some_and(|s| !s.is_empty()), "{w}");
        match rule {
            "unsteady" => {
                unsteady += 1;
                assert_eq!(
                    (w["window"].as_u64(), w["quantile"].as_f64()),
                    (Some(7), Some(0.5)),
                    "{w}"
                );
                let m = w["misfit"].as_array().expect("the misfits that decided");
                let (long, short) = (m[0].as_f64().unwrap(), m[1].as_f64().unwrap());
                assert!(long > short, "{w}");
                assert!(w["why"].as_str().unwrap().contains("changed"), "{w}");
                // The photo's window in the report is the one it used: 7 photos.
                let used = f["window"].as_array().unwrap();
                let span = used[1].as_u64().unwrap() - used[0].as_u64().unwrap() + 1;
                assert_eq!(span, 7, "{f}");
                // Its count of views is the window 7's against the 3 among which no view must fill more than
                // half of it, and the monitor flags `few-samples` exactly where it holds fewer.
                let (samples, needed) = (w["samples"].as_u64().unwrap(), w["needed"].as_u64());
                assert_eq!(needed, Some(3), "{w}");
                let few = f["health"]["flags"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|g| g["kind"] == "few-samples");
                assert_eq!(few, samples < 3, "{f}");
            }
            "quantile" | "capped" | "short" => {
                kept += 1;
                let m = w["misfit"].as_array().expect("checked");
                assert!(m.len() == 2, "{w}");
            }
            "sparse" => assert!(w["misfit"].is_null(), "{w}"),
            other => panic!("unknown rule {other}"),
        }
    }
    assert!(
        unsteady >= 4,
        "the check acts on this dive: {unsteady} photos took the window 7"
    );
    assert!(
        kept >= 4,
        "and keeps the survey's window elsewhere: {kept} photos"
    );

    // The in-memory engine (what Python and --watch run) makes the same choices and writes the same pixels.
    let mut engine = engine_over(&root.join("water"), opts.params().unwrap());
    let mut got = Vec::new();
    for (name, photo) in decoded_photos(&root.join("survey")) {
        got.extend(engine.push((photo, name)).unwrap());
    }
    got.extend(engine.finish());
    assert_eq!(got.len(), 40);
    let engine_unsteady = got
        .iter()
        .filter(|c| c.choice.unwrap().why().contains("changed"))
        .count();
    assert_eq!(
        engine_unsteady, unsteady,
        "the engine's survey checks as the batch run's"
    );
    for c in got {
        let written = abysslight::io::decode(&out.join(&c.tag)).unwrap();
        assert!(
            c.photo.unwrap().samples == written.samples,
            "{} differs from the batch command's",
            c.tag.display()
        );
    }
}

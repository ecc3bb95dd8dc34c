//! `correct` end to end on small synthetic dives with known albedo, light pattern and backscatter.

use crate::common;

use abysslight::io::decode;
use abysslight::{correct_mission, Options, Silent};
use abysslight::{BitDepth, Samples};
use common::*;

fn run(opts: &Options) -> abysslight::Report {
    correct_mission(opts, &Silent).expect("correct_mission")
}

#[test]
fn corrected_photos_match_albedo_up_to_a_per_channel_scale() {
    let d = tempfile::tempdir().unwrap();
    let frames = 20;
    let dive = dive(128, 96, frames, 9, 0.2, false, 7);
    let inputs = write_dive(&dive, d.path(), "png");
    // The user states the contamination; the window follows from it (n = 13 for c = 0.2 at 1 % risk).
    let opts = Options {
        water_column: Some(d.path().join("water")),
        survey: Some(d.path().join("survey")),
        out: Some(d.path().join("out")),
        contamination: Some(0.2),
        ..Options::default()
    };
    let report = run(&opts);
    assert_eq!(report.window.n, Some(13));
    assert_eq!(report.window.rule, "contamination");
    assert_eq!((report.window.shortest, report.window.longest), (13, 13));
    assert_eq!(report.corrected, frames);
    assert_eq!(report.failed, 0);
    assert_eq!(report.scatter.frames, 9);

    let corrected: Vec<Vec<f32>> = (1..=frames)
        .map(|i| normalised(&decode(&d.path().join(format!("out/img{i}.png"))).unwrap()))
        .collect();
    let raw: Vec<Vec<f32>> = dive.photos.iter().map(normalised).collect();
    let err_corrected = scaled_error(&corrected, &dive.albedo);
    let err_raw = scaled_error(&raw, &dive.albedo);
    eprintln!("relative albedo error: corrected {err_corrected:.4}, uncorrected {err_raw:.4}");
    // For reference, dividing by the true F and S gives about 0.007 here (8-bit quantisation and noise).
    assert!(
        err_corrected < 0.05,
        "corrected photos off by {err_corrected}"
    );
    assert!(
        err_corrected < err_raw / 5.0,
        "corrected {err_corrected} vs raw {err_raw}"
    );

    // The seafloor comes out in the seafloor colour C (default grey): the median corrected pixel of each
    // channel is within a few percent of C.
    for c in 0..3 {
        let mut v: Vec<f32> = corrected
            .iter()
            .flat_map(|p| p.iter().skip(c).step_by(3).copied())
            .collect();
        v.sort_by(f32::total_cmp);
        let med = v[v.len() / 2];
        assert!((med - 0.4).abs() < 0.03, "channel {c}: median {med}");
    }
    // Inputs untouched.
    for (p, photo) in inputs.iter().zip(&dive.photos) {
        assert_eq!(&decode(p).unwrap(), photo);
    }
}

#[test]
fn without_water_column_backscatter_remains_but_lighting_is_flattened() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(96, 64, 9, 0, 0.2, false, 3);
    write_all(&dive.photos, &d.path().join("survey"), "img", "png");
    let opts = Options {
        survey: Some(d.path().join("survey")),
        out: Some(d.path().join("out")),
        ..Options::default()
    };
    let report = run(&opts);
    assert_eq!(report.corrected, 9);
    assert_eq!(report.scatter.source, "none");
    assert!(
        report.warnings.iter().any(|w| w.contains("S = 0")),
        "{:?}",
        report.warnings
    );
    let corrected: Vec<Vec<f32>> = (1..=9)
        .map(|i| normalised(&decode(&d.path().join(format!("out/img{i}.png"))).unwrap()))
        .collect();
    let raw: Vec<Vec<f32>> = dive.photos.iter().map(normalised).collect();
    assert!(scaled_error(&corrected, &dive.albedo) < scaled_error(&raw, &dive.albedo) / 2.0);
}

#[test]
fn sixteen_bit_tree_is_mirrored_in_natural_order() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(40, 24, 12, 3, 0.1, true, 11);
    let survey = d.path().join("survey");
    // Two sub-folders; unpadded numbers so that natural order differs from byte order.
    write_all(&dive.photos[..10], &survey.join("leg1"), "img", "png");
    write_all(&dive.photos[10..], &survey.join("leg2"), "img", "tif");
    write_all(&dive.water, &d.path().join("water"), "w", "png");
    let opts = Options {
        water_column: Some(d.path().join("water")),
        survey: Some(survey.clone()),
        out: Some(d.path().join("out")),
        window: Some(5),
        save_scatter: true,
        save_factors: true,
        ..Options::default()
    };
    let report = run(&opts);
    assert_eq!(report.corrected, 12);
    let order: Vec<String> = report
        .frames
        .iter()
        .map(|f| {
            f.input
                .strip_prefix(&survey)
                .unwrap()
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let expected: Vec<String> = (1..=10)
        .map(|i| format!("leg1/img{i}.png"))
        .chain((1..=2).map(|i| format!("leg2/img{i}.tif")))
        .collect();
    assert_eq!(order, expected);
    for rel in &expected {
        let out = decode(&d.path().join("out").join(rel)).unwrap();
        assert_eq!(out.depth(), BitDepth::Sixteen, "{rel}");
        assert_eq!(out.layout, dive.photos[0].layout);
        // 16-bit output really uses 16-bit precision (not 8-bit values scaled up).
        if let Samples::U16(v) = &out.samples {
            assert!(
                v.iter().any(|s| s % 257 != 0),
                "{rel} looks like 8-bit data"
            );
        }
    }
    let work = d.path().join("out/_abysslight");
    assert!(work.join("scatter.png").is_file());
    assert!(work.join("report.json").is_file());
    assert!(work.join("factors/leg1/img10.png").is_file());
    let f = decode(&work.join("factors/leg2/img2.png")).unwrap();
    assert_eq!(
        (f.layout.width, f.layout.height),
        (10, 6),
        "factors are stored one pixel per block (4x4 for photos this small: --downsample auto)"
    );
    // Windows: shifted at the ends, centred in the middle.
    assert_eq!(report.frames[0].window.span(), 0..5);
    assert_eq!(report.frames[5].window.span(), 3..8);
    assert_eq!(report.frames[11].window.span(), 7..12);
}

#[test]
fn saved_scatter_reused_gives_identical_output() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(48, 32, 7, 5, 0.2, false, 5);
    write_dive(&dive, d.path(), "jpg");
    let first = Options {
        water_column: Some(d.path().join("water")),
        survey: Some(d.path().join("survey")),
        out: Some(d.path().join("a")),
        save_scatter: true,
        ..Options::default()
    };
    run(&first);
    let second = Options {
        water_column: None,
        scatter: Some(d.path().join("a/_abysslight/scatter.png")),
        out: Some(d.path().join("b")),
        ..first.clone()
    };
    let r = run(&second);
    assert_eq!(r.scatter.source, "file");
    for i in 1..=7 {
        let a = std::fs::read(d.path().join(format!("a/img{i}.jpg"))).unwrap();
        let b = std::fs::read(d.path().join(format!("b/img{i}.jpg"))).unwrap();
        assert_eq!(a, b, "img{i}.jpg differs");
    }
}

#[test]
fn short_mission_uses_all_photos_and_warns() {
    let d = tempfile::tempdir().unwrap();
    let dive = dive(32, 16, 3, 0, 0.0, false, 9);
    write_all(&dive.photos, &d.path().join("survey"), "img", "png");
    let opts = Options {
        survey: Some(d.path().join("survey")),
        out: Some(d.path().join("out")),
        window: Some(7),
        ..Options::default()
    };
    let r = run(&opts);
    assert_eq!(r.corrected, 3);
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("fewer than the window")),
        "{:?}",
        r.warnings
    );
    assert!(r.frames.iter().all(|f| f.window.span() == (0..3)));
}

/// `--downsample auto` (the default): blocks from the photos' size for `--method abyss` (about 160 across, 4 to 8
/// pixels), the paper's 8 for the paper as published; a given size is kept. The report records what was used.
#[test]
fn automatic_block_size_follows_the_photo_size_and_the_method() {
    use abysslight::Method;
    let cases: [(usize, usize, Method, Option<usize>, usize); 8] = [
        (96, 24, Method::Abyss, None, 4),
        (97, 24, Method::Abyss, None, 8), // with --mask-auto (below)
        (968, 16, Method::Abyss, None, 6),
        (1300, 16, Method::Abyss, None, 8),
        (968, 16, Method::Paper, None, 8),
        (96, 24, Method::Polynomial, None, 8),
        (96, 24, Method::Abyss, Some(3), 3),
        (96, 24, Method::Abyss, Some(5), 5),
    ];
    for (w, h, method, given, want) in cases {
        let d = tempfile::tempdir().unwrap();
        let dive = dive(w, h, 5, 3, 0.1, false, 11);
        write_dive(&dive, d.path(), "png");
        let report = run(&Options {
            water_column: Some(d.path().join("water")),
            survey: Some(d.path().join("survey")),
            out: Some(d.path().join("out")),
            window: Some(3),
            method,
            downsample: given,
            mask_auto: w == 97,
            save_factors: true,
            ..Options::default()
        });
        assert_eq!(report.failed, 0, "{w}x{h} {method}");
        assert_eq!(
            report.options.downsample,
            Some(want),
            "{w}x{h} {method} --downsample {given:?}"
        );
        // The photo's detail survives (odd blocks used to turn every --method abyss photo flat grey).
        let out = normalised(&decode(&d.path().join("out/img3.png")).unwrap());
        let mean = out.iter().sum::<f32>() / out.len() as f32;
        let var = out.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / out.len() as f32;
        assert!(
            var > 1e-4,
            "{w}x{h} {method} K {want}: flat output (variance {var})"
        );
        // The factor images have one sample per block of that size.
        let factors = d.path().join("out/_abysslight/factors");
        let first = std::fs::read_dir(&factors)
            .unwrap()
            .map(|e| e.unwrap().path())
            .min()
            .unwrap();
        let f = decode(&first).unwrap();
        assert_eq!(
            (f.layout.width, f.layout.height),
            (w.div_ceil(want), h.div_ceil(want)),
            "{w}x{h} {method}: {}",
            first.display()
        );
    }
}

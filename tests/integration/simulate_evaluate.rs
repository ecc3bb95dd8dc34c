//! The simulator, the metrics of `evaluate` (each against a hand-computed case) and the comparison of the
//! correction methods on small simulated dives.

use abysslight::eval::evaluate::{
    albedo_error, consistency, evaluate, residual_pattern, EvalSettings,
};
use abysslight::eval::simulate::Simulation;
use abysslight::Method;
use abysslight::Raster;
use abysslight::{correct_mission, Options, Silent};

fn translation(tx: f64, ty: f64) -> [f64; 9] {
    [1.0, 0.0, tx, 0.0, 1.0, ty, 0.0, 0.0, 1.0]
}

fn textured(w: usize, h: usize) -> Raster {
    Raster::from_fn(w, h, 3, |x, y, c| {
        0.2 + 0.1 * c as f32 + 0.3 * (((x * 7 + y * 13) % 11) as f32 / 11.0)
    })
}

#[test]
fn albedo_error_is_zero_for_a_per_channel_scale_and_hand_computed_otherwise() {
    let t = textured(20, 10);
    let mut g = t.clone();
    for (i, v) in g.data.iter_mut().enumerate() {
        *v *= [2.0, 0.5, 1.3][i % 3];
    }
    assert!(albedo_error(&[g], std::slice::from_ref(&t), None) < 1e-6);

    // One grey channel: truth [1, 1], got [1, 3]: s = (1 + 3) / 2 = 2, error = (|1−2| + |3−2|) / (2 + 2) = 0.5.
    let truth = Raster {
        width: 2,
        height: 1,
        channels: 1,
        data: vec![1.0, 1.0],
    };
    let got = Raster {
        data: vec![1.0, 3.0],
        ..truth.clone()
    };
    assert!((albedo_error(&[got], &[truth], None) - 0.5).abs() < 1e-9);
}

#[test]
fn residual_pattern_by_hand() {
    // A perfect correction up to a scale has no pattern.
    let t = textured(16, 8);
    let scaled = Raster {
        data: t.data.iter().map(|v| 0.7 * v).collect(),
        ..t.clone()
    };
    assert!(residual_pattern(&[scaled], std::slice::from_ref(&t), (4, 2), None) < 1e-6);

    // Grey 4×1 photo, truth 1 everywhere, got [1, 1, 1, 2] on a 4×1 grid: s = 7/4, cell ratios
    // [4/7, 4/7, 4/7, 8/7]; median 4/7, absolute deviations [0, 0, 0, 4/7], MAD 0: no robust spread
    // (one outlying cell of four). With got [1, 1, 2, 2]: s = 6/4, ratios [2/3, 2/3, 4/3, 4/3], median 1,
    // deviations all 1/3, spread = 1.4826 · (1/3) / 1.
    let truth = Raster {
        width: 4,
        height: 1,
        channels: 1,
        data: vec![1.0; 4],
    };
    let one = Raster {
        data: vec![1.0, 1.0, 1.0, 2.0],
        ..truth.clone()
    };
    assert!(residual_pattern(&[one], std::slice::from_ref(&truth), (4, 1), None) < 1e-9);
    let two = Raster {
        data: vec![1.0, 1.0, 2.0, 2.0],
        ..truth.clone()
    };
    let r = residual_pattern(&[two], &[truth], (4, 1), None);
    assert!((r - 1.4826 / 3.0).abs() < 1e-6, "{r}");
}

#[test]
fn consistency_of_identical_overlapping_photos_is_zero() {
    // Two photos cut from one mosaic at an offset of 16 pixels: they agree wherever they overlap.
    let mosaic = Raster::from_fn(64, 32, 3, |x, y, c| {
        0.1 + 0.8 * (((x * 5 + y * 3 + c) % 17) as f32 / 17.0)
    });
    let cut = |x0: usize| Raster::from_fn(32, 32, 3, |x, y, c| mosaic.get(x + x0, y, c));
    let photos = [cut(0), cut(16)];
    let c = consistency(
        &photos,
        &[translation(0.0, 0.0), translation(16.0, 0.0)],
        8.0,
    )
    .unwrap();
    assert!(c < 1e-9, "{c}");
    // No overlap: nothing to compare.
    assert!(consistency(
        &photos,
        &[translation(0.0, 0.0), translation(100.0, 0.0)],
        8.0
    )
    .is_none());
}

#[test]
fn consistency_by_hand() {
    // Two constant photos on the same place: cell values 0.2 and 0.4, per-cell mean 0.3, RMS difference 0.1;
    // all observed pixels: half 0.2, half 0.4, standard deviation 0.1. Ratio 1 in each channel.
    let a = Raster::filled(16, 16, 3, 0.2);
    let b = Raster::filled(16, 16, 3, 0.4);
    let c = consistency(&[a, b], &[translation(0.0, 0.0); 2], 4.0).unwrap();
    assert!((c - 1.0).abs() < 1e-6, "{c}");
}

fn small(seed: u64) -> Simulation {
    Simulation {
        frames: 20,
        water_column: 9,
        width: 160,
        height: 120,
        seed,
        ..Simulation::default()
    }
}

#[test]
fn simulator_is_deterministic_by_seed() {
    let s = Simulation {
        frames: 3,
        water_column: 2,
        width: 48,
        height: 32,
        ..Simulation::default()
    };
    let a = s.render().unwrap();
    let b = s.render().unwrap();
    assert_eq!(a.survey, b.survey);
    assert_eq!(a.water, b.water);
    assert_eq!(a.albedo, b.albedo);
    let c = Simulation { seed: 2, ..s }.render().unwrap();
    assert_ne!(a.survey, c.survey);
    // Consecutive photos overlap: the homographies put photo 2's top edge inside photo 1's footprint.
    let h = &a.truth.poses;
    let (_, y1_bottom) = abysslight::eval::simulate::apply_h(&h[0].homography, 24.0, 32.0);
    let (_, y2_top) = abysslight::eval::simulate::apply_h(&h[1].homography, 24.0, 0.0);
    let (_, y1_top) = abysslight::eval::simulate::apply_h(&h[0].homography, 24.0, 0.0);
    assert!(
        y2_top < y1_top && y1_top < y1_bottom,
        "{y2_top} {y1_top} {y1_bottom}"
    );
}

/// A simulated dive of six 96×72 photos (no water column) written to a temporary folder.
fn six_photo_dive() -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    let sim = Simulation {
        frames: 6,
        water_column: 0,
        width: 96,
        height: 72,
        ..Simulation::default()
    };
    sim.write(d.path()).unwrap();
    d
}

#[test]
fn simulated_truth_placements_give_consistent_albedo() {
    // The true albedo of overlapping photos, placed with the simulator's homographies, is almost consistent
    // (only resampling differences), while the raw photos are not.
    let d = six_photo_dive();
    let ev = evaluate(
        &[
            ("truth".into(), d.path().join("truth/albedo")),
            ("raw".into(), d.path().join("survey")),
        ],
        None,
        Some(&d.path().join("truth/placements.txt")),
        &EvalSettings::default(),
    )
    .unwrap();
    let (t, r) = (
        ev.sets[0].consistency.unwrap(),
        ev.sets[1].consistency.unwrap(),
    );
    eprintln!("consistency: truth {t:.4}, raw {r:.4}");
    assert!(t < 0.15 && t < r / 3.0, "truth {t}, raw {r}");
}

/// `evaluate --mask`: with a truth the albedo scores ignore the mask and the consistency leaves its pixels out (a
/// mask over the left half of the frame changes it); without a truth, the same consistency as with one; a mask that
/// ignores every pixel, or of another size, is an error naming it.
#[test]
fn an_evaluation_mask_leaves_pixels_out_of_the_consistency_only() {
    use abysslight::Mask;
    let d = six_photo_dive();
    let mut half = Mask::empty(96, 72);
    for (i, m) in half.ignore.iter_mut().enumerate() {
        *m = i % 96 < 48;
    }
    half.save(&d.path().join("half.png")).unwrap();
    let run = |truth: bool, mask: Option<&str>| {
        evaluate(
            &[("raw".into(), d.path().join("survey"))],
            truth.then(|| d.path()),
            Some(&d.path().join("truth/placements.txt")),
            &EvalSettings {
                mask: mask.map(|m| d.path().join(m)),
                ..EvalSettings::default()
            },
        )
    };
    let plain = run(true, None).unwrap().sets.remove(0);
    let masked = run(true, Some("half.png")).unwrap().sets.remove(0);
    assert_eq!(plain.albedo_error, masked.albedo_error);
    assert_eq!(plain.residual_pattern, masked.residual_pattern);
    let (a, b) = (plain.consistency.unwrap(), masked.consistency.unwrap());
    assert!((a - b).abs() > 1e-3 * a, "{a} {b}");
    let no_truth = run(false, Some("half.png")).unwrap().sets.remove(0);
    // The same up to the order of the sums (the cells are kept in a hash map).
    assert!(
        (no_truth.consistency.unwrap() - b).abs() < 1e-12,
        "{no_truth:?} {b}"
    );
    let mut all = Mask::empty(96, 72);
    all.ignore.fill(true);
    all.save(&d.path().join("all.png")).unwrap();
    Mask::empty(40, 30)
        .save(&d.path().join("small.png"))
        .unwrap();
    for m in ["all.png", "small.png"] {
        let e = run(false, Some(m)).unwrap_err().to_string();
        assert!(e.contains(m), "{e}");
    }
}

type Score = (f64, f64);

/// Albedo error and residual pattern of raw, mean, polynomial and paper on a simulated dive.
fn scores(sim: &Simulation) -> [Score; 4] {
    let d = tempfile::tempdir().unwrap();
    let dive = d.path().join("dive");
    sim.write(&dive).unwrap();
    let mut sets = vec![("raw".to_string(), dive.join("survey"))];
    for m in [Method::Mean, Method::Polynomial, Method::Paper] {
        let out = d.path().join(m.to_string());
        let opts = Options {
            water_column: Some(dive.join("water")),
            survey: Some(dive.join("survey")),
            out: Some(out.clone()),
            contamination: Some(0.2),
            method: m,
            ..Options::default()
        };
        correct_mission(&opts, &Silent).unwrap();
        sets.push((m.to_string(), out));
    }
    let ev = evaluate(&sets, Some(&dive), None, &EvalSettings::default()).unwrap();
    eprintln!("seed {} beam {}\n{}", sim.seed, sim.beam_deg, ev.table());
    ["raw", "mean", "polynomial", "paper"].map(|label| {
        let s = ev.sets.iter().find(|s| s.label == label).unwrap();
        (s.albedo_error.unwrap(), s.residual_pattern.unwrap())
    })
}

#[test]
fn paper_beats_the_baselines_on_simulated_dives_with_20_percent_contamination() {
    for seed in [11u64, 12] {
        let [raw, mean, poly, paper] = scores(&small(seed));
        assert!(
            paper.0 < raw.0 / 4.0 && paper.1 < raw.1 / 10.0,
            "paper {paper:?} raw {raw:?}"
        );
        assert!(
            paper.0 < mean.0 && paper.1 < mean.1,
            "paper {paper:?} mean {mean:?}"
        );
        // With the default wide beams (36°) the light is smooth over the whole frame and the robust polynomial
        // fit is as good as the paper's method (within ~10 %, either way depending on the seed and metric; see
        // docs/evaluation.md), so paper < polynomial is asserted below for beams whose edges are in the frame.
        assert!(poly.0 < mean.0, "polynomial {poly:?} mean {mean:?}");
    }
}

#[test]
fn paper_beats_the_polynomial_when_the_light_cones_have_edges_in_the_frame() {
    for seed in [11u64, 12] {
        // 25°: the cone edges cross the frame, as on many real rigs; a degree-4 polynomial in log space cannot
        // follow them, the temporal median can.
        let [_, _, poly, paper] = scores(&Simulation {
            beam_deg: 25.0,
            ..small(seed)
        });
        assert!(
            paper.1 < 0.7 * poly.1,
            "paper {paper:?} polynomial {poly:?}"
        );
        assert!(
            paper.0 < 1.02 * poly.0,
            "paper {paper:?} polynomial {poly:?}"
        );
    }
}

/// The residual pattern of one photo against its truth, on the flagged samples (all without flags).
fn pattern_of(
    got: &Raster,
    truth: &Raster,
    grid: (usize, usize),
    signal: Option<Vec<bool>>,
) -> f64 {
    let (got, truth) = (std::slice::from_ref(got), std::slice::from_ref(truth));
    match signal {
        Some(m) => residual_pattern(got, truth, grid, Some(&[m])),
        None => residual_pattern(got, truth, grid, None),
    }
}

#[test]
fn residual_pattern_of_a_black_channel_is_one_not_zero() {
    // Two channels, truth 1 everywhere. Channel 0 is corrected perfectly; channel 1 is left black (a starved
    // channel a correction clamped to zero). Black is the whole signal lost, spread 1, not a perfect flatness.
    let truth = Raster {
        width: 4,
        height: 2,
        channels: 2,
        data: vec![1.0; 16],
    };
    let got = Raster {
        data: (0..16)
            .map(|i| if i % 2 == 0 { 0.8 } else { 0.0 })
            .collect(),
        ..truth.clone()
    };
    let r = pattern_of(&got, &truth, (4, 2), None);
    assert!((r - 0.5).abs() < 1e-9, "{r}");
    // Black in only the right half of the cells: median of the cell medians is still positive, and the
    // deviations of the black cells count in full.
    let half = Raster {
        data: (0..16)
            .map(|i| {
                if i % 2 == 1 && (i / 2) % 4 >= 2 {
                    0.0
                } else {
                    1.0
                }
            })
            .collect(),
        ..truth.clone()
    };
    let r = pattern_of(&half, &truth, (4, 2), None);
    // Channel 1: scale 1/2, cell ratios [2, 2, 0, 0] per row → median 1, deviations all 1 → 1.4826.
    assert!((r - 1.4826 / 2.0).abs() < 1e-6, "{r}");
}

#[test]
fn residual_pattern_scores_only_the_flagged_samples() {
    // Grey 4×1, truth 1; got [1, 1, 2, 2] has a pattern (see residual_pattern_by_hand), but scored only where
    // the photo carries signal (the first two samples) it has none. With no sample flagged the score is NaN.
    let truth = Raster {
        width: 4,
        height: 1,
        channels: 1,
        data: vec![1.0; 4],
    };
    let got = Raster {
        data: vec![1.0, 1.0, 2.0, 2.0],
        ..truth.clone()
    };
    let all = pattern_of(&got, &truth, (4, 1), Some(vec![true; 4]));
    assert!((all - 1.4826 / 3.0).abs() < 1e-6, "{all}");
    let left = pattern_of(&got, &truth, (4, 1), Some(vec![true, true, false, false]));
    assert!(left < 1e-9, "{left}");
    let none = pattern_of(&got, &truth, (4, 1), Some(vec![false; 4]));
    assert!(none.is_nan());
}

//! Issue 12: abyssal dives in the simulator (their truth checked against the image model) and the orderings of
//! the default method (`abyss`) against the paper as published on small dives of the dive matrix
//! (examples/dive_matrix.rs, docs/evaluation.md).

use abysslight::eval::evaluate::{albedo_error, evaluate, residual_pattern, EvalSettings};
use abysslight::eval::matrix;
use abysslight::eval::simulate::{Exposure, Rig, Simulation, Water};
use abysslight::Method;
use abysslight::Transfer;
use abysslight::{correct_mission, Options, Raster, Silent};

/// A small abyssal dive like a02 of the matrix: aft lights, clear ocean water (red ~0.4/m), 6 m ± 0.6 m,
/// white balance ×6 on red, exposure from the brightest sediment, 16-bit linear.
fn abyssal(seed: u64) -> Simulation {
    Simulation {
        frames: 16,
        water_column: 5,
        width: 160,
        height: 120,
        seed,
        contamination: 0.2,
        bit_depth: 16,
        rig: Rig::Aft,
        altitude: 6.0,
        fov_deg: 80.0,
        water: Water::preset("oceanic-i").unwrap(),
        altitude_swing: Some(0.6),
        white_balance: [6.0, 1.0, 0.7],
        exposure: Exposure::Brightest,
        ..Simulation::default()
    }
}

#[test]
fn abyssal_truth_follows_the_image_model() {
    // Without noise, each survey pixel is A·F + S with the simulator's own true F and S (particles aside, a few
    // pixels): checked on the median pixel error, channel by channel, independently of the renderer's code path.
    let sim = Simulation {
        frames: 2,
        water_column: 0,
        width: 64,
        height: 48,
        noise: 0.0,
        bit_depth: 16,
        ..abyssal(5)
    };
    let dive = sim.render_with_lighting().unwrap();
    assert_eq!(dive.factor.len(), 2);
    for i in 0..2 {
        let img = Raster::from_photo(&dive.survey[i]);
        let (a, f, s) = (&dive.albedo[i], &dive.factor[i], &dive.backscatter[i]);
        for ch in 0..3 {
            let mut err: Vec<f32> = (ch..img.data.len())
                .step_by(3)
                .filter(|&j| img.data[j] < 0.99)
                .map(|j| (img.data[j] - (a.data[j] * f.data[j] + s.data[j])).abs())
                .collect();
            err.sort_by(f32::total_cmp);
            assert!(
                err[err.len() / 2] < 1e-4,
                "photo {i} channel {ch}: {}",
                err[err.len() / 2]
            );
        }
        // Red-starved: the red F is far below the green one in the median pixel, despite the ×6 gain.
        let med = |ch: usize| {
            let mut v: Vec<f32> = f.data.iter().skip(ch).step_by(3).copied().collect();
            v.sort_by(f32::total_cmp);
            v[v.len() / 2]
        };
        assert!(med(0) < 0.5 * med(1), "red {} green {}", med(0), med(1));
    }
    // Brightest exposure: no sediment pixel of a level photo is clipped in any channel (objects may be).
    let img = Raster::from_photo(&dive.survey[0]);
    let clipped = img.data.iter().filter(|&&v| v >= 1.0).count();
    assert!(clipped * 200 < img.data.len(), "{clipped} clipped samples");
}

#[test]
fn water_presets_and_coefficients_parse() {
    let w: Water = "oceanic-i".parse().unwrap();
    assert_eq!(w, Water::preset("oceanic-i").unwrap());
    let c: Water = "0.4, 0.07, 0.03".parse().unwrap();
    assert_eq!(c.attenuation, [0.4, 0.07, 0.03]);
    assert_eq!(c.scattering, Water::MILD.scattering);
    for bad in ["sea", "0.4,0.07", "-1,0,0"] {
        assert!(bad.parse::<Water>().is_err(), "{bad}");
    }
    // The defaults render the dive of the first versions (demo and older tests stay comparable).
    let d = Simulation::default();
    assert_eq!(d.water, Water::MILD);
    assert_eq!((d.altitude_swing, d.white_balance), (None, [1.0; 3]));
    assert_eq!(d.exposure, Exposure::Centre);
}

/// Correct the simulated dive written at `dive` into `out` with `opts` (inputs, output, contamination and transfer
/// filled in from the dive).
fn correct_dive(sim: &Simulation, dive: &std::path::Path, out: &std::path::Path, opts: Options) {
    correct_mission(
        &Options {
            water_column: Some(dive.join("water")),
            survey: Some(dive.join("survey")),
            out: Some(out.to_path_buf()),
            contamination: Some(sim.contamination),
            transfer: Some(sim.encode),
            ..opts
        },
        &Silent,
    )
    .unwrap();
}

/// A dive of the matrix rendered with its lighting truth at 320×240 into a temporary folder (saved as JPEGs where
/// the matrix's camera writes JPEGs), for scoring as the matrix scores (on the samples with signal).
struct MatrixDive {
    sim: Simulation,
    dive: abysslight::eval::simulate::Dive,
    dir: tempfile::TempDir,
    names: Vec<String>,
    signal: Vec<Vec<bool>>,
}

impl MatrixDive {
    fn render(name: &str, seed_set: u64) -> MatrixDive {
        // A dive of the matrix, or a held-out one (with the held-out seeds).
        let (spec, seed) = matrix::dive_and_seed(name, seed_set).unwrap();
        let sim = spec.simulation(seed, (320, 240));
        let dive = sim.render_with_lighting().unwrap();
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("dive");
        dive.write(&root).unwrap();
        let mut names: Vec<String> = dive.truth.poses.iter().map(|p| p.file.clone()).collect();
        if spec.jpeg {
            // The camera wrote JPEGs, as in the matrix: the dive's folders hold those instead.
            for sub in ["survey", "water"] {
                let png = dir.path().join(format!("{sub}-png"));
                std::fs::rename(root.join(sub), &png).unwrap();
                matrix::save_as_jpeg(&png, &root.join(sub)).unwrap();
            }
            for n in &mut names {
                *n = std::path::Path::new(n)
                    .with_extension("jpg")
                    .to_string_lossy()
                    .into_owned();
            }
        }
        let signal = matrix::signal_mask(&dive, sim.encode, spec.bits);
        MatrixDive {
            sim,
            dive,
            dir,
            names,
            signal,
        }
    }

    /// Albedo error of each channel (on its samples with signal) of the dive corrected with `opts` into `label`.
    fn channel_errors(&self, label: &str, opts: Options) -> Vec<f64> {
        let out = self.dir.path().join(label);
        correct_dive(&self.sim, &self.dir.path().join("dive"), &out, opts);
        let photos = matrix::load_set(&out, &self.names, self.sim.encode);
        (0..3)
            .map(|ch| {
                let only: Vec<Vec<bool>> = self
                    .signal
                    .iter()
                    .map(|m| {
                        m.iter()
                            .enumerate()
                            .map(|(i, &b)| b && i % 3 == ch)
                            .collect()
                    })
                    .collect();
                albedo_error(&photos, &self.dive.albedo, Some(&only))
            })
            .collect()
    }

    /// (albedo error, residual pattern) of the dive corrected with `opts` into `label`.
    fn score(&self, label: &str, opts: Options) -> (f64, f64) {
        let out = self.dir.path().join(label);
        correct_dive(&self.sim, &self.dir.path().join("dive"), &out, opts);
        let photos = matrix::load_set(&out, &self.names, self.sim.encode);
        (
            albedo_error(&photos, &self.dive.albedo, Some(&self.signal)),
            residual_pattern(&photos, &self.dive.albedo, (8, 6), Some(&self.signal)),
        )
    }
}

/// The paper as published, otherwise the defaults.
fn paper() -> Options {
    Options {
        method: Method::Paper,
        ..Options::default()
    }
}

/// (albedo error, residual pattern) of raw, paper as published and the default on `sim`.
fn scores(sim: &Simulation) -> [(f64, f64); 3] {
    let d = tempfile::tempdir().unwrap();
    let dive = d.path().join("dive");
    sim.write(&dive).unwrap();
    let mut sets = vec![("raw".to_string(), dive.join("survey"))];
    for (label, method) in [("paper", Method::Paper), ("default", Method::default())] {
        let out = d.path().join(label);
        correct_dive(
            sim,
            &dive,
            &out,
            Options {
                method,
                ..Options::default()
            },
        );
        sets.push((label.to_string(), out));
    }
    let ev = evaluate(&sets, Some(&dive), None, &EvalSettings::default()).unwrap();
    eprintln!("seed {}\n{}", sim.seed, ev.table());
    ["raw", "paper", "default"].map(|l| {
        let s = ev.sets.iter().find(|s| s.label == l).unwrap();
        (s.albedo_error.unwrap(), s.residual_pattern.unwrap())
    })
}

#[test]
fn default_is_abyss_and_beats_the_paper_on_the_residual_pattern_of_an_abyssal_dive() {
    assert_eq!(Method::default(), Method::Abyss);
    for seed in [21u64, 22] {
        let [raw, paper, abyss] = scores(&abyssal(seed));
        // The paper's absolute floor leaves the dim leading edge of an aft-lit frame dark: a strong pattern.
        assert!(abyss.1 < 0.5 * paper.1, "abyss {abyss:?} paper {paper:?}");
        assert!(
            abyss.0 < 0.8 * raw.0 && abyss.1 < 0.2 * raw.1,
            "abyss {abyss:?} raw {raw:?}"
        );
        // Albedo error: at least 10 % below the paper's (the noise-aware blend of dim regions, where the paper's
        // clamp leaves them dark and a plain division amplifies red noise; docs/evaluation.md).
        assert!(abyss.0 < 0.9 * paper.0, "abyss {abyss:?} paper {paper:?}");
    }
}

#[test]
fn the_noise_aware_blend_lowers_the_albedo_error_and_keeps_nodules_dark() {
    // The same abyssal dive corrected with and without --no-denoise: the blend must lower the albedo error by at
    // least a fifth, and dark nodules must stay dark in red too (the red-starved channel takes its detail from the
    // well-lit ones instead of being lifted towards the sediment's level).
    let sim = abyssal(24);
    let d = tempfile::tempdir().unwrap();
    let dive = d.path().join("dive");
    sim.write(&dive).unwrap();
    let mut sets = Vec::new();
    for (label, denoise) in [("blend", true), ("plain", false)] {
        let out = d.path().join(label);
        correct_dive(
            &sim,
            &dive,
            &out,
            Options {
                denoise,
                ..Options::default()
            },
        );
        sets.push((label.to_string(), out));
    }
    let ev = evaluate(&sets, Some(&dive), None, &EvalSettings::default()).unwrap();
    eprintln!("{}", ev.table());
    let err = |l: &str| {
        ev.sets
            .iter()
            .find(|s| s.label == l)
            .unwrap()
            .albedo_error
            .unwrap()
    };
    assert!(
        err("blend") < 0.8 * err("plain"),
        "{} vs {}",
        err("blend"),
        err("plain")
    );
    // Nodule pixels (true albedo below 0.1 in every channel) against sediment pixels (above 0.3), per channel, in
    // the blended photos: the median nodule stays below half the median sediment in red as in green.
    let truth = abysslight::io::decode(&dive.join("truth/albedo/0008.png")).unwrap();
    let got = abysslight::io::decode(&d.path().join("blend/0008.png")).unwrap();
    let (t, g) = (Raster::from_photo(&truth), Raster::from_photo(&got));
    for ch in [0usize, 1] {
        let pick = |dark: bool| {
            let mut v: Vec<f32> = (0..t.data.len() / 3)
                .filter(|&p| {
                    let a = &t.data[p * 3..p * 3 + 3];
                    if dark {
                        a.iter().all(|&x| x < 0.1)
                    } else {
                        a.iter().all(|&x| x > 0.3)
                    }
                })
                .map(|p| g.data[p * 3 + ch])
                .collect();
            v.sort_by(f32::total_cmp);
            v[v.len() / 2]
        };
        let (nodule, sediment) = (pick(true), pick(false));
        assert!(
            nodule < 0.5 * sediment,
            "channel {ch}: nodules {nodule}, sediment {sediment}"
        );
    }
}

#[test]
fn default_stays_well_below_raw_on_an_srgb_jpeg_like_dive() {
    let sim = Simulation {
        bit_depth: 8,
        encode: Transfer::Srgb,
        rig: Rig::Two,
        altitude: 4.0,
        altitude_swing: Some(0.2),
        contamination: 0.35,
        water: Water::preset("oceanic-iii").unwrap(),
        ..abyssal(23)
    };
    let [raw, paper, abyss] = scores(&sim);
    assert!(
        abyss.0 < 0.8 * raw.0 && abyss.1 < 0.3 * raw.1,
        "abyss {abyss:?} raw {raw:?}"
    );
    // Here (two lights beside the camera, no large dim region, 35 % nodules) the paper's clamp costs little: the
    // default has the lower albedo error (at least 10 % lower) but not the lower pattern — within 30 % of the
    // paper's (docs/evaluation.md, dive a03: the blend lifts nodules in dim regions towards the sediment).
    assert!(
        abyss.1 < 1.3 * paper.1 && abyss.0 < 0.9 * paper.0,
        "abyss {abyss:?} paper {paper:?}"
    );
}

/// The monitor's flags on sound dives of the matrix, where the method works (albedo error half the paper's):
/// a starved red channel (a04, coastal water: red carries signal in 1 % of its samples) used to read as
/// "contamination" on 25 photos and "colour shift" on 19, a slow altitude drift (a02, seed set 1) as a growing
/// "colour shift" on 17, and the fine structure a correction removes from a dim, nodule-dotted photo (a01) as
/// "scene in F" on every photo.
#[test]
fn sound_abyssal_dives_raise_no_flags() {
    // (dive, seed set): a04 and a01 from the tuning set, a02 from seed set 1.
    for (name, set) in [("a04", 0), ("a02", 1), ("a01", 0)] {
        let (spec, seed) = matrix::dive_and_seed(name, set).unwrap();
        let sim = spec.simulation(seed, (320, 240));
        let d = tempfile::tempdir().unwrap();
        let dive = d.path().join("dive");
        sim.write(&dive).unwrap();
        let out = d.path().join("out");
        let report = correct_mission(
            &Options {
                water_column: Some(dive.join("water")),
                survey: Some(dive.join("survey")),
                out: Some(out),
                contamination: Some(sim.contamination),
                transfer: Some(sim.encode),
                ..Options::default()
            },
            &Silent,
        )
        .unwrap();
        let mut kinds = std::collections::BTreeMap::<&str, usize>::new();
        for f in &report.frames {
            for flag in &f.health.flags {
                *kinds.entry(flag.kind()).or_default() += 1;
            }
        }
        eprintln!("{name} seed {seed}: {kinds:?}");
        for kind in ["contamination", "colour-shift", "scene-in-factor"] {
            assert!(
                !kinds.contains_key(kind),
                "{name} seed {seed}: {kinds:?} on a sound dive"
            );
        }
        // At most one exposure jump (a04: one photo at level 0.72 of its window's, where the whole frame is dim).
        assert!(
            kinds.get("exposure-jump").copied().unwrap_or(0) <= 1,
            "{name}: {kinds:?}"
        );
    }
}

/// The blend's levels evened out across light levels (`level_by_light`, on by default): on dim, nodule-dotted
/// dives of the matrix the rim used to come out 6–18 % darker than the lit centre (noise pulls a dim block's
/// median towards its mean, the water-column `S` takes a larger share of a small signal). Two dives of seed set 1
/// (not the set the method was tuned on), scored as the matrix scores them (on the samples with signal): the
/// residual pattern at least 10 % lower than without it, the albedo error no more than 2 % higher. (The dives
/// were once a07 and a11; since the noise is modelled as growing with the level, a07's rim is
/// no longer darkened by it (its pattern 0.033 → 0.023) and the levels leave a07 as it is: 1.05×; a06 0.56×,
/// a11 0.77×, a12 0.64×.)
#[test]
fn levels_evened_out_across_light_lower_the_residual_pattern_of_dim_dives() {
    for name in ["a06", "a11"] {
        let d = MatrixDive::render(name, 1);
        let with = d.score("with", Options::default());
        let without = d.score(
            "without",
            Options {
                level_by_light: false,
                ..Options::default()
            },
        );
        eprintln!("{name}: (albedo error, residual pattern) with {with:?}, without {without:?}");
        assert!(
            with.1 < 0.9 * without.1 && with.0 < 1.02 * without.0,
            "{name}: with {with:?}, without {without:?}"
        );
    }
}

/// `--downsample auto` (blocks of 4 for 320×240 photos) against the paper's blocks of 8, on a04 of the tuning set:
/// four narrow-ish lights from 4.5 m, whose centre is clipped (the dive whose pattern stayed 0.78× the paper's with
/// blocks of 8). Scored as the matrix scores. Fails with blocks of 8 as the default. The two block sizes are
/// compared without the near window (the near window, which lowers the albedo error of blocks of 8 on
/// this dive, 0.33 → 0.32, and not that of blocks of 4: docs/evaluation.md).
#[test]
fn blocks_from_the_photo_size_lower_the_residual_pattern_below_the_papers() {
    let d = MatrixDive::render("a04", 0);
    let auto = d.score("default", Options::default());
    let alone = |downsample| Options {
        downsample,
        near_window: Some(0),
        ..Options::default()
    };
    let four = d.score("blocks-auto-alone", alone(None));
    let eight = d.score("blocks-8-alone", alone(Some(8)));
    let paper = d.score("paper", paper());
    eprintln!(
        "a04 (albedo error, residual pattern): default {auto:?}; without the near window, blocks from the photo \
         size {four:?}, blocks of 8 {eight:?}; paper {paper:?}"
    );
    assert!(
        four.1 < 0.9 * eight.1 && four.0 < 1.02 * eight.0,
        "blocks from the photo size {four:?} against blocks of 8 {eight:?}"
    );
    assert!(
        auto.1 <= 0.75 * paper.1 && auto.0 <= 0.9 * paper.0,
        "default {auto:?} against the paper {paper:?}"
    );
}

/// The near window (on by default) against the window alone, on a12 of the tuning set: four 28° lights from 5 ± 0.4
/// m, 8-bit sRGB JPEG, the dive whose residual pattern stayed 0.79× the paper's. Over its window of 9 photos the
/// lights' footprint moves with the vehicle's altitude and roll; the near window's 5 photos follow it. Scored as
/// the matrix scores. Fails without the near window (`near_window: Some(0)`) as the default.
#[test]
fn the_near_window_follows_the_lights_on_a_swinging_dive() {
    let d = MatrixDive::render("a12", 0);
    let default = d.score("default", Options::default());
    let without = d.score(
        "no-near",
        Options {
            near_window: Some(0),
            ..Options::default()
        },
    );
    let paper = d.score("paper", paper());
    eprintln!(
        "a12 (albedo error, residual pattern): default {default:?}, without the near window {without:?}, paper \
         {paper:?}"
    );
    assert!(
        default.1 <= 0.75 * paper.1 && default.0 <= 0.9 * paper.0,
        "default {default:?} against the paper {paper:?}"
    );
    assert!(
        default.1 < 0.8 * without.1 && default.0 < 1.02 * without.0,
        "near window {default:?} against none {without:?}"
    );
}

#[test]
fn a_starved_channels_noise_is_not_taken_for_seafloor_texture() {
    // a08: four lights from 6.5 m in clear ocean water, 8-bit linear: red reaches the floor weakly (signal in
    // 46 % of its samples) and its noise differs between dim and bright blocks. Read as texture, that noise made
    // the blend keep it: red's albedo error was 2.0× green's (0.185 against 0.090); with each channel's relative
    // texture held within three times the median channel's, red takes its detail from green and blue.
    let d = MatrixDive::render("a08", 0);
    let default = d.channel_errors("default", Options::default());
    let paper = d.channel_errors("paper", paper());
    eprintln!("a08 albedo error per channel (R, G, B): default {default:?}, paper {paper:?}");
    assert!(
        default[0] < 1.5 * default[1].max(default[2]),
        "red {default:?} against green and blue"
    );
    for ch in 0..3 {
        assert!(
            default[ch] < 0.6 * paper[ch],
            "channel {ch}: {default:?} against {paper:?}"
        );
    }
}

/// The held-out dive an earlier default failed on (h07: four lights from 8 m in clear ocean water, red
/// signal in 18 % of its samples, JPEG), on a seed set the change was not found on: albedo error ≥ 10 % below the
/// paper's (0.94× before the texture cap and the level-dependent noise, 0.76× after) and residual pattern ≥ 25 %
/// below.
#[test]
fn a_far_red_starved_held_out_dive_beats_the_paper() {
    let d = MatrixDive::render("h07", 1);
    let default = d.score("default", Options::default());
    let paper = d.score("paper", paper());
    eprintln!("h07 (albedo error, residual pattern): default {default:?}, paper {paper:?}");
    assert!(
        default.0 <= 0.9 * paper.0 && default.1 <= 0.75 * paper.1,
        "default {default:?} against the paper {paper:?}"
    );
}

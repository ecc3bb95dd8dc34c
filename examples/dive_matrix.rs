//! The dive matrix of docs/evaluation.md: simulated abyssal dives (rigs × water × altitude swing × contamination ×
//! 8/16-bit × linear/sRGB × PNG/JPEG), each corrected with every method and scored against the simulator's truth.
//!
//! ```sh
//! cargo run --release --example dive_matrix -- [--out DIR] [--seed-offset K] [--only NAME[,NAME]] [--ablation | --ablation-only COLUMN[,COLUMN]] [--size WxH] [--held-out] [--nodules [--told] | --swings] [--untold]
//! ```
//! Methods: `raw` (as recorded), `mean` and `polynomial` (baselines), `paper` (the paper as published,
//! `--method paper`, absolute floor 0.05 — abysslight's default before the abyss method), `paper-f0.001` (the same
//! with `--factor-floor 0.001`), `default` (`Options::default()`, i.e. `--method abyss`), `navigation` (the default
//! given the simulator's `navigation.csv`, `--navigation`: windows chosen by altitude), `oracle` (`(I − S)/F` with
//! the simulator's true `F` and `S`), `window-floor` (the window's `M` made from the true albedo alone:
//! what a window over a straight track takes into `F` from the seafloor itself, whatever the lights do —
//! `matrix::window_floor`), and `numpy` (the numpy peer of the paper, `PEER_PYTHON` or `../peer-venv` and
//! `../shared/peers/paper_numpy.py`, when present). `--ablation` adds the abyss method with each lever off.
//! `--columns NAME[,NAME]` keeps only those of the columns above (the oracle and the window's floor are always
//! scored; `numpy` runs only when listed). `--nodules` scores the nodule fields (`matrix::NODULES`, with
//! `--held-out` `matrix::NODULES_HELD_OUT`; docs/nodules.md) at default options instead (`--told`: with their
//! true coverage, as the twelve are scored). `--swings` scores the altitude-swing dives (`matrix::SWINGS`, with
//! `--held-out` `matrix::SWINGS_HELD_OUT`) at default options. `--untold` corrects every dive, the twelve and the
//! held-out ones too, at default options without its coverage (`--window auto` chooses, as for a user).
//! `--seed-offset K` renders the same matrix with other seeds (data the method was not tuned on). `--size WxH`
//! renders other photo sizes (default 320x240: the 8-pixel blocks are then 1/40 of the frame's width, where a 12 MP
//! camera's are 1/500; larger photos show how much of a score comes from that). `--held-out` scores the eight
//! held-out dives (`matrix::HELD_OUT`, h01 … h08: outside the twelve's ranges, never used to choose a default)
//! instead of the twelve.
//!
//! The monitor as a classifier: per dive, which of the default's photos it flagged and which are wrong (the photo's
//! own albedo error or residual pattern above 1.5× the dive's with the true lighting, or above 1.5× the larger of
//! that and the window floor's); precision, recall and each flag's precision over the dives at the end of the table.
//!
//! Scores (lower is better): albedo error and residual pattern of `evaluate`, and the consistency and overlap
//! difference over overlapping photos (placements from the simulator's poses), on every pixel and where the lights
//! reach (`matrix::lit_mask`). Written to `DIR/matrix.md` (default `target/dive-matrix/`) and
//! printed. With `DM_KEEP=1` in the environment each dive's folder (the dive with its truth, every method's output)
//! is kept under `DIR/NAME/` for a closer look, e.g. `abysslight correct` with other options on the same photos.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use abysslight::eval::evaluate::{albedo_error, consistency_parts, residual_pattern};
use abysslight::eval::matrix::{
    self, lit_mask, load_set, only_lit, oracle, signal_mask, window_floor, DIVES, HELD_OUT,
    NODULES, NODULES_HELD_OUT,
};
use abysslight::eval::simulate::Dive;
use abysslight::kernels::auto_block;
use abysslight::Raster;
use abysslight::Transfer;
use abysslight::{correct_mission, Silent};
use abysslight::{Method, Options};

/// The seed of a set's `index`-th dive in seed set `offset`.
type SeedOf = fn(usize, u64) -> u64;

/// Options of one column, made from the options every column shares.
type MakeOptions = Box<dyn Fn(Options) -> Options>;

/// Scores of one method on one dive.
#[derive(Clone, Copy)]
struct Score {
    /// Albedo error on the samples with signal ([`signal_mask`]).
    albedo: f64,
    /// Albedo error on every sample (as `evaluate` scores it without the lighting truth).
    albedo_all: f64,
    /// Residual pattern on the samples with signal.
    pattern: f64,
    /// Residual pattern on every sample.
    pattern_all: f64,
    consistency: f64,
    overlap: f64,
    /// Consistency on the pixels the lights reach ([`lit_mask`]).
    consistency_lit: f64,
    /// Overlap difference on the pixels the lights reach.
    overlap_lit: f64,
}

fn score(photos: &[Raster], dive: &Dive, signal: &[Vec<bool>], lit: &[Vec<bool>]) -> Score {
    let hs: Vec<[f64; 9]> = dive.truth.poses.iter().map(|p| p.homography).collect();
    let (consistency, overlap) =
        consistency_parts(photos, &hs, 8.0).unwrap_or((f64::NAN, f64::NAN));
    let (consistency_lit, overlap_lit) =
        consistency_parts(&only_lit(photos, lit), &hs, 8.0).unwrap_or((f64::NAN, f64::NAN));
    Score {
        albedo: albedo_error(photos, &dive.albedo, Some(signal)),
        albedo_all: albedo_error(photos, &dive.albedo, None),
        pattern: residual_pattern(photos, &dive.albedo, (8, 6), Some(signal)),
        pattern_all: residual_pattern(photos, &dive.albedo, (8, 6), None),
        consistency,
        overlap,
        consistency_lit,
        overlap_lit,
    }
}

/// The survey's true backscatter over the water-column median, per channel (ratio of the means over all pixels).
fn true_scale(dive: &Dive, t: Transfer) -> Vec<f64> {
    let frames: Vec<Raster> = dive
        .water
        .iter()
        .map(|p| Raster::from_photo_linear(p, t))
        .collect();
    let (Some(first), false) = (frames.first(), dive.backscatter.is_empty()) else {
        return Vec::new();
    };
    let c = first.channels;
    let mut wc = vec![0.0f64; c];
    let mut col = vec![0.0f32; frames.len()];
    for i in 0..first.data.len() {
        for (v, f) in col.iter_mut().zip(&frames) {
            *v = f.data[i];
        }
        col.sort_by(f32::total_cmp);
        wc[i % c] += col[col.len() / 2] as f64;
    }
    let mut sv = vec![0.0f64; c];
    for s in &dive.backscatter {
        for (i, v) in s.data.iter().enumerate() {
            sv[i % c] += *v as f64 / dive.backscatter.len() as f64;
        }
    }
    (0..c).map(|ch| sv[ch] / wc[ch]).collect()
}

/// What `--help` prints: the options of the module's docs.
const USAGE: &str = "usage: cargo run --release --example dive_matrix -- [--out DIR] [--seed-offset K] \
[--only NAME[,NAME]] [--columns NAME[,NAME]] [--ablation | --ablation-only COLUMN[,COLUMN]] [--size WxH] \
[--held-out] [--nodules [--told] | --swings] [--untold]
Scores every method on simulated dives against their truth (the overlaps on every pixel and where the lights
reach); DM_KEEP=1 keeps each dive's folder.
Columns: raw, mean, polynomial, paper, paper-f0.001, default, numpy (the oracle and the window's floor always).
The whole description: the docs at the top of examples/dive_matrix.rs, and docs/evaluation.md.";

fn main() {
    let mut out =
        PathBuf::from(std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| "target".into()))
            .join("dive-matrix");
    let mut seed_offset = 0u64;
    let mut only: Option<Vec<String>> = None;
    let mut ablation = false;
    let mut ablation_only: Option<Vec<String>> = None;
    let mut size = (320usize, 240usize);
    let mut held_out = false;
    let mut nodules = false;
    let mut swings = false;
    let mut told_all = false;
    let mut untold = false;
    let mut columns: Option<Vec<String>> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = PathBuf::from(args.next().expect("--out DIR")),
            "--seed-offset" => {
                seed_offset = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .expect("--seed-offset K")
            }
            "--only" => {
                only = Some(
                    args.next()
                        .expect("--only NAME[,NAME]")
                        .split(',')
                        .map(str::to_owned)
                        .collect(),
                )
            }
            "--ablation" => ablation = true,
            "--held-out" => held_out = true,
            "--nodules" => nodules = true,
            "--swings" => swings = true,
            "--told" => told_all = true,
            "--untold" => untold = true,
            "--columns" => {
                columns = Some(
                    args.next()
                        .expect("--columns NAME[,NAME]")
                        .split(',')
                        .map(str::to_owned)
                        .collect(),
                )
            }
            "--ablation-only" => {
                ablation = true;
                ablation_only = Some(
                    args.next()
                        .expect("--ablation-only COLUMN[,COLUMN]")
                        .split(',')
                        .map(str::to_owned)
                        .collect(),
                )
            }
            "--size" => {
                size = args
                    .next()
                    .and_then(|v| {
                        let (w, h) = v.split_once('x')?;
                        Some((w.parse().ok()?, h.parse().ok()?))
                    })
                    .expect("--size WxH")
            }
            "--help" | "-h" => {
                println!("{USAGE}");
                return;
            }
            _ => {
                eprintln!("dive_matrix: unknown argument {a:?}\n{USAGE}");
                std::process::exit(2);
            }
        }
    }
    let peers = abysslight::eval::matrix::peers();
    if peers.is_none() {
        eprintln!(
            "dive_matrix: numpy peer not found (PEER_PYTHON or ../peer-venv, ../shared/peers/paper_numpy.py): no numpy column"
        );
    }
    let peer_python = peers.as_ref().map(|(p, _)| p.clone()).unwrap_or_default();
    let peer = peers.map(|(_, d)| d.join("paper_numpy.py"));
    // (label, options relative to the paper-as-published baseline)
    let mut methods: Vec<(String, MakeOptions)> = vec![
        (
            "mean".into(),
            Box::new(|o| Options {
                method: Method::Mean,
                ..o
            }),
        ),
        (
            "polynomial".into(),
            Box::new(|o| Options {
                method: Method::Polynomial,
                ..o
            }),
        ),
        (
            "paper".into(),
            Box::new(|o| Options {
                method: Method::Paper,
                factor_floor: 0.05,
                ..o
            }),
        ),
        (
            "paper-f0.001".into(),
            Box::new(|o| Options {
                method: Method::Paper,
                factor_floor: 0.001,
                ..o
            }),
        ),
        ("default".into(), Box::new(|o| o)),
        // The default given the vehicle's log (`correct --navigation`): windows chosen by altitude.
        (
            "navigation".into(),
            Box::new(|o| Options {
                navigation: o
                    .survey
                    .as_ref()
                    .and_then(|s| s.parent())
                    .map(|d| d.join("navigation.csv")),
                ..o
            }),
        ),
    ];
    if ablation {
        for (label, f) in ablations() {
            if ablation_only
                .as_ref()
                .is_some_and(|o| !o.iter().any(|n| n == label))
            {
                continue;
            }
            methods.push((label.to_string(), Box::new(f)));
        }
    }
    if let Some(c) = &columns {
        methods.retain(|(l, _)| c.contains(l));
    }
    let peer = peer.filter(|_| {
        columns
            .as_ref()
            .is_none_or(|c| c.iter().any(|l| l == "numpy"))
    });
    let mut rows: Vec<(String, Vec<(String, Score)>)> = Vec::new();
    let mut monitors = [Monitor::default(), Monitor::default()];
    let started = Instant::now();
    let (dives, seed): (&[matrix::DiveSpec], SeedOf) = match (nodules, held_out) {
        (false, false) => (DIVES, matrix::seed),
        (false, true) => (HELD_OUT, matrix::held_out_seed),
        (true, false) => (NODULES, matrix::nodule_seed),
        (true, true) => (NODULES_HELD_OUT, matrix::nodule_held_out_seed),
    };
    let (dives, seed): (&[matrix::DiveSpec], SeedOf) = match (swings, held_out) {
        (false, _) => (dives, seed),
        (true, false) => (matrix::SWINGS, matrix::swing_seed),
        (true, true) => (matrix::SWINGS_HELD_OUT, matrix::swing_held_out_seed),
    };
    // The coverage each column is told: the twelve's, or none (a nodule field corrected as a user would).
    // `--told`: every dive's true coverage, the nodule fields' too.
    // `--untold`: no dive's coverage, not even the twelve's (every dive at default options, `--window auto` choosing).
    let told = |spec: &matrix::DiveSpec| {
        (!untold && (spec.told || told_all)).then_some(spec.contamination)
    };
    for (i, spec) in dives.iter().enumerate() {
        if only
            .as_ref()
            .is_some_and(|o| !o.iter().any(|n| n == spec.name))
        {
            continue;
        }
        let t = Instant::now();
        let sim = spec.simulation(seed(i, seed_offset), size);
        let dive = sim.render_with_lighting().expect("render");
        let dir = out.join(spec.name);
        let _ = std::fs::remove_dir_all(&dir);
        let root = dir.join("dive");
        dive.write(&root).expect("write dive");
        // JPEG dives: the camera wrote JPEGs (quality 92) instead of PNGs.
        let ext = if spec.jpeg { "jpg" } else { "png" };
        if spec.jpeg {
            for sub in ["survey", "water"] {
                matrix::save_as_jpeg(&root.join(sub), &dir.join(format!("{sub}-jpeg")))
                    .expect("save the dive as JPEG");
            }
            // The log beside the JPEGs (it names the PNGs: photos are matched by name without the extension).
            std::fs::copy(root.join("navigation.csv"), dir.join("navigation.csv"))
                .expect("copy the navigation log");
        }
        let (survey, water) = if spec.jpeg {
            (dir.join("survey-jpeg"), dir.join("water-jpeg"))
        } else {
            (root.join("survey"), root.join("water"))
        };
        let names: Vec<String> = dive
            .truth
            .poses
            .iter()
            .map(|p| {
                Path::new(&p.file)
                    .with_extension(ext)
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        let t_enc = sim.encode;
        let signal = signal_mask(&dive, t_enc, spec.bits);
        let lit = lit_mask(&dive);
        let raw = load_set(&survey, &names, t_enc);
        let mut scores = vec![("raw".to_string(), score(&raw, &dive, &signal, &lit))];
        let (mut default_flags, mut default_photos) = (None, None);
        for (label, make) in &methods {
            let o = make(Options {
                water_column: Some(water.clone()),
                survey: Some(survey.clone()),
                out: Some(dir.join(label)),
                contamination: told(spec),
                transfer: Some(t_enc),
                ..Options::default()
            });
            let report = correct_mission(&o, &Silent)
                .unwrap_or_else(|e| panic!("{} {label}: {e}", spec.name));
            if label == "default" {
                eprintln!(
                    "dive_matrix: {} default: {}",
                    spec.name,
                    flag_summary(&report)
                );
                default_flags = Some(flags_by_name(&report, &names));
            }
            if label == "abyss-scale-auto" {
                // The backscatter scale the default estimated (median over photos, per channel).
                let k: Vec<String> = (0..3)
                    .map(|c| {
                        let mut v: Vec<f32> = report
                            .frames
                            .iter()
                            .filter_map(|f| f.backscatter_scale.get(c).copied())
                            .collect();
                        v.sort_by(f32::total_cmp);
                        v.get(v.len() / 2).map_or("-".into(), |x| format!("{x:.3}"))
                    })
                    .collect();
                eprintln!(
                    "dive_matrix: {} --backscatter-scale auto estimated {}",
                    spec.name,
                    k.join(", ")
                );
            }
            let photos = load_set(&dir.join(label), &names, t_enc);
            scores.push((label.clone(), score(&photos, &dive, &signal, &lit)));
            if label == "default" {
                default_photos = Some(photos);
            }
            if std::env::var_os("DM_KEEP").is_none() {
                let _ = std::fs::remove_dir_all(dir.join(label));
            }
        }
        let truth_lit = score(&oracle(&raw, &dive), &dive, &signal, &lit);
        scores.push(("oracle".into(), truth_lit));
        // The default's window and quantile (the paper's column and the numpy peer take the same window).
        let default = Options {
            contamination: told(spec),
            ..Options::default()
        };
        let window = default.window_choice().map_or(7, |w| w.n);
        let floor = window_floor(
            &dive.albedo,
            window,
            default.window_quantile(),
            auto_block(sim.width, sim.height),
        );
        let floor_score = score(&floor, &dive, &signal, &lit);
        scores.push(("window-floor".into(), floor_score));
        if let (Some(flags), Some(photos)) = (&default_flags, &default_photos) {
            // Wrong against the true lighting's figures, and against the larger of those and the window floor's
            // (what a window over this track can reach).
            let bars = [
                (truth_lit.albedo, truth_lit.pattern),
                (
                    truth_lit.albedo.max(floor_score.albedo),
                    truth_lit.pattern.max(floor_score.pattern),
                ),
            ];
            for (m, bar) in monitors.iter_mut().zip(bars) {
                let judged = judge(photos, flags, &dive, &signal, bar);
                eprintln!("dive_matrix: {} monitor: {}", spec.name, judged.line());
                m.add(&judged);
            }
        }
        if let Some(script) = &peer {
            let o = dir.join("numpy");
            let ok = Command::new(&peer_python)
                .arg(script)
                .arg("paper")
                .arg(&water)
                .arg(&survey)
                .arg(&o)
                .args(["--window", &window.to_string()])
                .status()
                .is_ok_and(|s| s.success());
            if ok {
                scores.push((
                    "numpy".into(),
                    score(&load_set(&o, &names, t_enc), &dive, &signal, &lit),
                ));
            }
        }
        let share: Vec<String> = (0..3)
            .map(|ch| {
                let (n, k) = signal.iter().fold((0usize, 0usize), |(n, k), m| {
                    let on = m.iter().skip(ch).step_by(3).filter(|&&b| b).count();
                    (n + m.len() / 3, k + on)
                });
                format!("{:.0} %", 100.0 * k as f64 / n.max(1) as f64)
            })
            .collect();
        eprintln!(
            "dive_matrix: {} done in {:.1} s; true backscatter scale {:.3?}; samples with signal (R, G, B) {}",
            spec.name,
            t.elapsed().as_secs_f64(),
            true_scale(&dive, t_enc),
            share.join(", ")
        );
        let desc = format!(
            "{} | {:?}{} | {} | {}±{} m | {:.2} | {}-bit {} {}",
            spec.name,
            spec.rig,
            if spec.beam < 36.0 {
                format!(" {}°", spec.beam)
            } else {
                String::new()
            },
            spec.water,
            spec.altitude,
            spec.swing,
            spec.contamination,
            spec.bits,
            if spec.srgb { "sRGB" } else { "linear" },
            if spec.jpeg { "JPEG" } else { "PNG" },
        );
        rows.push((desc, scores));
        if std::env::var_os("DM_KEEP").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
    let mut md = table(&rows);
    if monitors[0].photos > 0 {
        md.push_str(&monitors[0].table("the true lighting's"));
        md.push_str(&monitors[1].table("the larger of the true lighting's and the window floor's"));
    }
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("matrix.md"), &md).unwrap();
    println!("{md}");
    eprintln!(
        "dive_matrix: {} dives in {:.0} s, table in {}",
        rows.len(),
        started.elapsed().as_secs_f64(),
        out.join("matrix.md").display()
    );
}

/// Each photo's flags (their kinds) in the order of `names`, matched by the output's file name.
fn flags_by_name(report: &abysslight::Report, names: &[String]) -> Vec<Vec<String>> {
    names
        .iter()
        .map(|n| {
            report
                .frames
                .iter()
                .find(|f| {
                    f.output
                        .file_name()
                        .is_some_and(|o| o.to_string_lossy() == *n)
                })
                .map_or_else(Vec::new, |f| {
                    f.health.flags.iter().map(|k| k.kind.clone()).collect()
                })
        })
        .collect()
}

/// The monitor as a classifier on one dive: a photo is wrong where its own albedo error or residual pattern is
/// above 1.5× a bar of its dive (the true lighting's figures, or the larger of those and the window floor's);
/// flagged where the monitor raised any flag.
#[derive(Default)]
struct Monitor {
    photos: usize,
    wrong: usize,
    flagged: usize,
    /// Flagged and wrong.
    caught: usize,
    /// Per flag kind: photos flagged with it, and of those the wrong ones.
    kinds: std::collections::BTreeMap<String, (usize, usize)>,
}

impl Monitor {
    fn add(&mut self, o: &Monitor) {
        self.photos += o.photos;
        self.wrong += o.wrong;
        self.flagged += o.flagged;
        self.caught += o.caught;
        for (k, (n, w)) in &o.kinds {
            let e = self.kinds.entry(k.clone()).or_default();
            e.0 += n;
            e.1 += w;
        }
    }

    fn line(&self) -> String {
        format!(
            "{} wrong, {} flagged, {} of them wrong (of {} photos); {:?}",
            self.wrong, self.flagged, self.caught, self.photos, self.kinds
        )
    }

    /// Precision, recall and the share of good photos flagged, then each kind's precision.
    fn table(&self, bar: &str) -> String {
        let ratio = |a: usize, b: usize| {
            if b == 0 {
                "-".to_string()
            } else {
                format!("{:.2}", a as f64 / b as f64)
            }
        };
        let good = self.photos - self.wrong;
        let mut md = format!(
            "\n**the monitor as a classifier** (wrong: the photo's albedo error or residual pattern above 1.5x \
             {bar} on its dive)\n\n| photos | wrong | flagged | precision | recall | good photos flagged |\n\
             |---:|---:|---:|---:|---:|---:|\n| {} | {} | {} | {} | {} | {} |\n\n| flag | photos | of them wrong | precision |\n|---|---:|---:|---:|\n",
            self.photos,
            self.wrong,
            self.flagged,
            ratio(self.caught, self.flagged),
            ratio(self.caught, self.wrong),
            ratio(self.flagged - self.caught, good),
        );
        for (k, (n, w)) in &self.kinds {
            md.push_str(&format!("| {k} | {n} | {w} | {} |\n", ratio(*w, *n)));
        }
        md
    }
}

/// [`Monitor`] of one dive's default output.
fn judge(
    photos: &[Raster],
    flags: &[Vec<String>],
    dive: &Dive,
    signal: &[Vec<bool>],
    (bar_albedo, bar_pattern): (f64, f64),
) -> Monitor {
    let mut m = Monitor::default();
    for (i, (p, f)) in photos.iter().zip(flags).enumerate() {
        let one = std::slice::from_ref(p);
        let albedo = std::slice::from_ref(&dive.albedo[i]);
        let mask = std::slice::from_ref(&signal[i]);
        let a = albedo_error(one, albedo, Some(mask));
        let r = residual_pattern(one, albedo, (8, 6), Some(mask));
        let wrong = a > 1.5 * bar_albedo || r > 1.5 * bar_pattern;
        m.photos += 1;
        m.wrong += usize::from(wrong);
        m.flagged += usize::from(!f.is_empty());
        m.caught += usize::from(wrong && !f.is_empty());
        let mut kinds = f.clone();
        kinds.sort_unstable();
        kinds.dedup();
        for k in kinds {
            let e = m.kinds.entry(k).or_default();
            e.0 += 1;
            e.1 += usize::from(wrong);
        }
    }
    m
}

/// Photos flagged by the monitor (share and the count of each kind) and the windows used.
fn flag_summary(report: &abysslight::Report) -> String {
    let mut kinds: std::collections::BTreeMap<&str, usize> = Default::default();
    let mut flagged = 0;
    for f in &report.frames {
        flagged += usize::from(!f.health.flags.is_empty());
        for k in &f.health.flags {
            *kinds.entry(k.kind()).or_default() += 1;
        }
    }
    let lens: Vec<usize> = report.frames.iter().map(|f| f.window.len()).collect();
    format!(
        "flagged {} of {} photos {:?}; windows {}..{} photos",
        flagged,
        report.frames.len(),
        kinds,
        lens.iter().min().unwrap_or(&0),
        lens.iter().max().unwrap_or(&0)
    )
}

fn table(rows: &[(String, Vec<(String, Score)>)]) -> String {
    let Some((_, first)) = rows.first() else {
        return String::new();
    };
    let labels: Vec<&str> = first.iter().map(|(l, _)| l.as_str()).collect();
    let mut s = String::new();
    for (metric, get) in [
        ("albedo error", (|x: &Score| x.albedo) as fn(&Score) -> f64),
        ("residual pattern", |x: &Score| x.pattern),
        ("consistency", |x: &Score| x.consistency),
        ("overlap difference", |x: &Score| x.overlap),
        ("consistency where lit", |x: &Score| x.consistency_lit),
        ("overlap difference where lit", |x: &Score| x.overlap_lit),
        ("albedo error, every sample", |x: &Score| x.albedo_all),
        ("residual pattern, every sample", |x: &Score| x.pattern_all),
    ] {
        s.push_str(&format!(
            "\n**{metric}** (lower is better)\n\n| dive | rig | water | altitude | c | format | {} | default/paper | default/oracle | default/window-floor |\n|---|---|---|---|---:|---|{}---:|---:|---:|\n",
            labels.join(" | "),
            "---:|".repeat(labels.len())
        ));
        for (desc, scores) in rows {
            let v = |l: &str| scores.iter().find(|(x, _)| x == l).map(|(_, s)| get(s));
            let cells: Vec<String> = labels
                .iter()
                .map(|l| v(l).map_or("-".into(), |x| format!("{x:.4}")))
                .collect();
            let ratio = |a: &str, b: &str| match (v(a), v(b)) {
                (Some(a), Some(b)) => format!("{:.2}", a / b),
                _ => "-".into(),
            };
            s.push_str(&format!(
                "| {desc} | {} | {} | {} | {} |\n",
                cells.join(" | "),
                ratio("default", "paper"),
                ratio("default", "oracle"),
                ratio("default", "window-floor")
            ));
        }
    }
    s
}

/// The abyss method with one lever at a time turned off or changed, for the ablation of the dive matrix
/// (`examples/dive_matrix.rs --ablation`).
#[allow(clippy::type_complexity)]
fn ablations() -> Vec<(&'static str, fn(Options) -> Options)> {
    vec![
        ("abyss-no-levelling", |o| Options {
            method: Method::Abyss,
            level_exposures: false,
            ..o
        }),
        ("abyss-no-gain", |o| Options {
            method: Method::Abyss,
            photo_gain: false,
            ..o
        }),
        ("abyss-floor-0.01", |o| Options {
            method: Method::Abyss,
            relative_floor: 0.01,
            ..o
        }),
        ("abyss-floor-0.003", |o| Options {
            method: Method::Abyss,
            relative_floor: 0.003,
            ..o
        }),
        ("abyss-floor-0.03", |o| Options {
            method: Method::Abyss,
            relative_floor: 0.03,
            ..o
        }),
        ("abyss-floor-0.1", |o| Options {
            method: Method::Abyss,
            relative_floor: 0.1,
            ..o
        }),
        ("abyss-no-denoise", |o| Options {
            method: Method::Abyss,
            denoise: false,
            ..o
        }),
        ("abyss-blocks-8", |o| Options {
            method: Method::Abyss,
            downsample: Some(8),
            ..o
        }),
        ("abyss-blocks-3", |o| Options {
            method: Method::Abyss,
            downsample: Some(3),
            ..o
        }),
        ("abyss-blocks-6", |o| Options {
            method: Method::Abyss,
            downsample: Some(6),
            ..o
        }),
        ("abyss-blocks-4", |o| Options {
            method: Method::Abyss,
            downsample: Some(4),
            ..o
        }),
        ("abyss-no-near-window", |o| Options {
            method: Method::Abyss,
            near_window: Some(0),
            ..o
        }),
        // Without --contamination (the window 7, its median, the near window 5), with and without the near window.
        ("abyss-window-7", |o| Options {
            method: Method::Abyss,
            contamination: None,
            window: Some(7),
            ..o
        }),
        ("abyss-window-7-no-near", |o| Options {
            method: Method::Abyss,
            contamination: None,
            window: Some(7),
            near_window: Some(0),
            ..o
        }),
        ("abyss-overlaps", |o| Options {
            method: Method::Abyss,
            overlaps: true,
            ..o
        }),
        ("abyss-bright-spots", |o| Options {
            method: Method::Abyss,
            bright_spots: true,
            ..o
        }),
        ("abyss-no-level-by-light", |o| Options {
            method: Method::Abyss,
            level_by_light: false,
            ..o
        }),
        ("abyss-scale-auto", |o| Options {
            method: Method::Abyss,
            backscatter_scale: None,
            ..o
        }),
        ("abyss-before", |o| Options {
            method: Method::Abyss,
            backscatter_scale: Some(1.0),
            denoise: false,
            ..o
        }),
    ]
}

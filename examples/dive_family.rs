//! The randomized dive family of docs/results.md: many dives of two simulators written apart — `abysslight
//! simulate` (the crate's own, [`Simulation`](abysslight::eval::simulate::Simulation)) and the independent
//! `simdive.py` beside the numpy peer — drawn at random over rig, nodule cover (0–50 %, one cover or patchy along the
//! track), altitude (2.5–8 m), altitude swing (0–40 % of the altitude), overlap (0.5–0.9), sRGB or linear, 8 or 16
//! bits, PNG or JPEG. Each dive is corrected with the default (`Options::default()`), with `--window 7` and with the
//! numpy peer of the paper (window 7), and scored: albedo error and residual pattern on the samples that carry the
//! albedo unclipped (the crate's `evaluate`; on `simdive.py`'s dives also its own `evaluate_dive.py`, on every
//! sediment pixel). Dive `k` has seed `FAMILY_SEED + k`; even `k` is the tuning half, odd `k` the held-out half.
//!
//! ```sh
//! cargo run --release --example dive_family -- [--out DIR] [--count N] [--frames N] [--size WxH] [--sim ours|simdive|both] [--from K] [--summary]
//! ```
//! `--count N` dives of each simulator (default 60), `--from K` starts at dive `K` (runs in parts). `--others-from
//! DIR` scores only the default and takes the `--window 7` and peer columns from `DIR/family.tsv`, an earlier run of
//! the same family (another build's default: neither column depends on it), and `simdive.py`'s renders from `DIR`
//! (linked, not rendered again). Each dive's
//! scores are appended to `DIR/family.tsv` (default `target/dive-family/`) as it finishes; dives already there are
//! not run again; each photo of the default's output is appended to `DIR/photos.tsv` with its albedo error and
//! residual pattern beside the true lighting's on the same photo and the flags the run raised on it. `--summary`
//! only prints, from those files, the distribution (median, 90th percentile, worst) of default ÷ peer and default ÷
//! `--window 7` per score, per simulator and half, and the monitor as a classifier (precision, recall, good photos
//! flagged, per flag) by the definition of docs/results.md. The default's `report.json` of each dive is kept as
//! `DIR/reports/DIVE.json` (each photo's health figures and window, to study the monitor). Needs the peers' Python (`../peer-venv`, or
//! `PEER_PYTHON`; numpy, OpenCV, SciPy) and `../shared/peers/{simdive,paper_numpy,evaluate_dive}.py`; without them only the crate's
//! dives and columns are run.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use abysslight::eval::evaluate::{albedo_error, residual_pattern};
use abysslight::eval::matrix::{self, load_set, signal_mask, DiveSpec};
use abysslight::eval::simulate::Rig;
use abysslight::{correct_mission, Silent};
use abysslight::{Options, Raster, Report, Transfer};

/// Seed of dive 0; dive `k` has `FAMILY_SEED + k`.
const FAMILY_SEED: u64 = 56_000;

/// A small deterministic generator (splitmix64) for the draws.
struct Draw(u64);

impl Draw {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next() >> 11) as f64 / (1u64 << 53) as f64)
    }
    fn chance(&mut self, p: f64) -> bool {
        self.uniform(0.0, 1.0) < p
    }
    fn pick<T: Copy>(&mut self, v: &[T]) -> T {
        v[(self.next() % v.len() as u64) as usize]
    }
}

/// One dive of the family, as drawn.
#[derive(Clone, Debug)]
struct Drawn {
    sim: &'static str,
    k: usize,
    seed: u64,
    rig: &'static str,
    cover: f64,
    patchy: bool,
    altitude: f64,
    swing: f64,
    overlap: f64,
    srgb: bool,
    bits: u32,
    jpeg: bool,
}

impl Drawn {
    fn half(&self) -> &'static str {
        if self.k.is_multiple_of(2) {
            "tuning"
        } else {
            "held-out"
        }
    }
    fn name(&self) -> String {
        format!("{}-{:03}", self.sim, self.k)
    }
}

/// Dive `k` of simulator `sim` (`ours` or `simdive`).
fn draw(sim: &'static str, k: usize) -> Drawn {
    let seed = FAMILY_SEED + k as u64;
    let mut d = Draw(seed ^ if sim == "ours" { 0x0A } else { 0x5D00 });
    let rig = match sim {
        "ours" => d.pick(&["two", "three", "four", "aft"]),
        _ => d.pick(&["twin", "ring", "side"]),
    };
    // A quarter of bare sediment: the case the survey must read as such.
    let cover = if d.chance(0.25) {
        0.0
    } else {
        d.uniform(0.02, 0.5)
    };
    let patchy = cover > 0.0 && d.chance(0.3);
    let altitude = d.uniform(2.5, 8.0);
    let swing = altitude * d.uniform(0.0, 0.4);
    let overlap = d.uniform(0.5, 0.9);
    let srgb = d.chance(0.5);
    let jpeg = d.chance(0.35);
    let bits = if !jpeg && d.chance(0.4) { 16 } else { 8 };
    Drawn {
        sim,
        k,
        seed,
        rig,
        cover,
        patchy,
        altitude,
        swing,
        overlap,
        srgb,
        bits,
        jpeg,
    }
}

/// Scores of one correction (lower is better); NaN where not measured.
#[derive(Clone, Copy, Default)]
struct Score {
    albedo: f64,
    pattern: f64,
    /// `evaluate_dive.py`'s `nmae` and `pattern` (simdive dives only).
    nmae: f64,
    peer_pattern: f64,
}

const COLUMNS: [&str; 3] = ["default", "window7", "numpy"];

struct Peers {
    python: PathBuf,
    dir: PathBuf,
}

fn peers() -> Option<Peers> {
    let (python, dir) = matrix::peers().filter(|(_, d)| d.join("simdive.py").exists())?;
    Some(Peers { python, dir })
}

/// A dive ready to correct: its photos, the names to score, the truth and the samples to score.
struct Rendered {
    survey: PathBuf,
    water: PathBuf,
    names: Vec<String>,
    transfer: Transfer,
    albedo: Vec<Raster>,
    signal: Vec<Vec<bool>>,
    /// Each photo corrected with the true lighting (`F` and `S`), scored as the methods are.
    oracle: Vec<Raster>,
    /// The samples each photo is scored on alone (for the monitor): `signal`, and on `simdive.py`'s dives only where
    /// the raw sample is at least 2 % of the sensor's range (its true lighting is not given; in the corners the
    /// lights miss the oracle divides noise by almost nothing).
    lit: Vec<Vec<bool>>,
}

fn render_ours(d: &Drawn, dir: &Path, size: (usize, usize), frames: usize) -> Rendered {
    let rig = match d.rig {
        "two" => Rig::Two,
        "three" => Rig::Three,
        "four" => Rig::Four,
        _ => Rig::Aft,
    };
    let c = d.cover;
    let spec = DiveSpec {
        name: "family",
        rig,
        beam: 36.0,
        water: "mild",
        altitude: d.altitude as f32,
        swing: d.swing as f32,
        contamination: c,
        bits: d.bits,
        srgb: d.srgb,
        jpeg: d.jpeg,
        fov: 75.0,
        overlap: d.overlap as f32,
        frames,
        along: d.patchy.then_some([0.05 * c, c, 0.4 * c]),
        told: false,
    };
    let sim = spec.simulation(d.seed, size);
    let dive = sim.render_with_lighting().expect("render");
    let root = dir.join("dive");
    dive.write(&root).expect("write dive");
    let ext = if d.jpeg { "jpg" } else { "png" };
    let (survey, water) = if d.jpeg {
        for sub in ["survey", "water"] {
            matrix::save_as_jpeg(&root.join(sub), &dir.join(format!("{sub}-jpeg")))
                .expect("save the dive as JPEG");
        }
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
    let oracle = matrix::oracle(&load_set(&survey, &names, sim.encode), &dive);
    Rendered {
        survey,
        water,
        names,
        transfer: sim.encode,
        lit: signal_mask(&dive, sim.encode, d.bits),
        signal: signal_mask(&dive, sim.encode, d.bits),
        albedo: dive.albedo,
        oracle,
    }
}

/// A `.npy` array of little-endian f16, f32 or f64 as f32 values (C order).
fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&b[..6], b"\x93NUMPY", "{}: not a .npy", path.display());
    let (hlen, start) = match b[6] {
        1 => (u16::from_le_bytes([b[8], b[9]]) as usize, 10),
        _ => (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12),
    };
    let header = String::from_utf8_lossy(&b[start..start + hlen]).into_owned();
    let shape: Vec<usize> = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_default();
    let data = &b[start + hlen..];
    let values = if header.contains("'<f2'") {
        data.chunks_exact(2)
            .map(|c| f16_to_f32(u16::from_le_bytes([c[0], c[1]])))
            .collect()
    } else if header.contains("'<f4'") {
        data.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    } else if header.contains("'<f8'") {
        data.chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
            .collect()
    } else {
        panic!("{}: unsupported dtype in {header}", path.display())
    };
    (shape, values)
}

fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let frac = (h & 0x3ff) as f32;
    sign * match exp {
        0 => frac * 2f32.powi(-24),
        31 => f32::INFINITY,
        e => (1.0 + frac / 1024.0) * 2f32.powi(e - 15),
    }
}

fn render_simdive(
    d: &Drawn,
    p: &Peers,
    dir: &Path,
    (size, frames): ((usize, usize), usize),
    cached: bool,
) -> Rendered {
    let root = dir.join("dive");
    let mut cmd = Command::new(&p.python);
    cmd.arg(p.dir.join("simdive.py"))
        .arg(&root)
        .args(["--frames", &frames.to_string(), "--water", "9"])
        .args([
            "--width",
            &size.0.to_string(),
            "--height",
            &size.1.to_string(),
        ])
        .args(["--contamination", &format!("{:.3}", d.cover)])
        .args(["--rig", d.rig])
        .args(["--alt", &format!("{:.2}", d.altitude)])
        .args(["--alt-swing", &format!("{:.2}", d.swing)])
        .args(["--overlap", &format!("{:.2}", d.overlap)])
        .args(["--bits", &d.bits.to_string()])
        .args(["--format", if d.jpeg { "jpg" } else { "png" }])
        .args(["--seed", &d.seed.to_string()]);
    if d.patchy {
        cmd.arg("--patchy");
    }
    if d.srgb {
        cmd.arg("--gamma");
    }
    let ok = cached
        || cmd
            .env("OMP_NUM_THREADS", "1")
            .env("OPENBLAS_NUM_THREADS", "1")
            .stdout(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
    assert!(ok, "simdive.py failed for {}", d.name());
    let ext = if d.jpeg { "jpg" } else { "png" };
    let names: Vec<String> = (0..frames).map(|i| format!("s{i:04}.{ext}")).collect();
    let transfer = if d.srgb {
        Transfer::Srgb
    } else {
        Transfer::Linear
    };
    let survey = root.join("survey");
    let raw = load_set(&survey, &names, transfer);
    let albedo: Vec<Raster> = (0..frames)
        .map(|i| {
            let (shape, v) = read_npy(&root.join("truth").join(format!("a{i:04}.npy")));
            let (h, w, c) = (shape[0], shape[1], shape.get(2).copied().unwrap_or(1));
            Raster::from_fn(w, h, c, |x, y, ch| v[(y * w + x) * c + ch])
        })
        .collect();
    // The samples that carry the albedo unclipped: the raw sample below the sensor's top (a third of a photo clips
    // at low altitude) and above its floor.
    let signal = raw
        .iter()
        .map(|r| {
            let c = r.channels;
            r.data
                .chunks_exact(c)
                .flat_map(|px| {
                    let ok = px.iter().all(|&v| v < 0.98) && px.iter().all(|&v| v > 0.002);
                    std::iter::repeat_n(ok, c)
                })
                .collect()
        })
        .collect();
    let pngs: Vec<String> = (0..frames).map(|i| format!("s{i:04}.png")).collect();
    let lit = raw
        .iter()
        .zip(&signal)
        .map(|(r, s): (&Raster, &Vec<bool>)| {
            let c = r.channels;
            r.data
                .chunks_exact(c)
                .zip(s.chunks_exact(c))
                .flat_map(|(px, s)| {
                    let ok = s[0] && px.iter().all(|&v| v >= 0.02);
                    std::iter::repeat_n(ok, c)
                })
                .collect()
        })
        .collect();
    Rendered {
        survey,
        water: root.join("water"),
        names,
        transfer,
        albedo,
        signal,
        lit,
        oracle: load_set(&root.join("oracle"), &pngs, transfer),
    }
}

/// `evaluate_dive.py`'s `nmae` and `pattern` of a corrected folder.
fn evaluate_dive(p: &Peers, dive: &Path, corrected: &Path) -> (f64, f64) {
    let out = Command::new(&p.python)
        .arg(p.dir.join("evaluate_dive.py"))
        .arg(dive)
        .arg(corrected)
        .output();
    let text = out.map(|o| String::from_utf8_lossy(&o.stdout).into_owned());
    let field = |t: &str, k: &str| {
        t.split_whitespace()
            .find_map(|f| f.strip_prefix(k)?.parse().ok())
            .unwrap_or(f64::NAN)
    };
    match text {
        Ok(t) => (field(&t, "nmae="), field(&t, "pattern=")),
        Err(_) => (f64::NAN, f64::NAN),
    }
}

/// What the default's survey chose: the median of its photos' stretch coverage, the share of photos whose window
/// is longer than 7, and how many photos each rule chose (`unsteady`: the survey asked for more, the window 7 won).
fn survey_summary(r: &Report) -> (f64, f64, String) {
    let mut c: Vec<f64> = r
        .frames
        .iter()
        .filter_map(|f| f.window_auto.as_ref().map(|w| w.choice.coverage as f64))
        .collect();
    c.sort_by(f64::total_cmp);
    let long = r
        .frames
        .iter()
        .filter(|f| f.window_auto.as_ref().is_some_and(|w| w.choice.window > 7))
        .count();
    let mut kept = std::collections::BTreeMap::<String, usize>::new();
    for f in &r.frames {
        if let Some(w) = &f.window_auto {
            let v = serde_json::to_value(w.choice).unwrap_or_default();
            let key = v
                .get("rule")
                .and_then(|k| k.as_str())
                .unwrap_or("-")
                .to_string();
            *kept.entry(key).or_default() += 1;
        }
    }
    let kept = kept
        .iter()
        .map(|(k, n)| format!("{k}:{n}"))
        .collect::<Vec<_>>()
        .join(",");
    (
        c.get(c.len() / 2).copied().unwrap_or(f64::NAN),
        long as f64 / r.frames.len().max(1) as f64,
        kept,
    )
}

/// The columns other than the default's of dive `name` in an earlier run's `family.tsv` (its 4 scores each).
fn earlier_scores(earlier: &str, name: &str) -> Option<Vec<Score>> {
    let line = earlier
        .lines()
        .find(|l| l.split('\t').next() == Some(name))?;
    // The columns' scores start at the default's first, in HEADER's order.
    let first = HEADER.split('\t').position(|h| h == "default_albedo")?;
    let v: Vec<f64> = line
        .split('\t')
        .skip(first)
        .take(4 * COLUMNS.len())
        .map(|f| f.parse().unwrap_or(f64::NAN))
        .collect();
    (v.len() == 4 * COLUMNS.len()).then(|| {
        v.chunks_exact(4)
            .map(|c| Score {
                albedo: c[0],
                pattern: c[1],
                nmae: c[2],
                peer_pattern: c[3],
            })
            .collect()
    })
}

fn run_one(
    d: &Drawn,
    peers: Option<&Peers>,
    out: &Path,
    (size, frames): ((usize, usize), usize),
    earlier: Option<(&Path, &str)>,
) -> (String, Vec<String>) {
    let dir = out.join(d.name());
    let reused = earlier.and_then(|(_, tsv)| earlier_scores(tsv, &d.name()));
    if let (Some((from, _)), "simdive", false) = (earlier, d.sim, dir.exists()) {
        let target = std::fs::canonicalize(from.join(d.name())).expect("the earlier run's dive");
        std::os::unix::fs::symlink(target, &dir).expect("link the earlier render");
    }
    for col in COLUMNS {
        let _ = std::fs::remove_dir_all(dir.join(col));
    }
    let t = Instant::now();
    let rendered = dir.join("rendered");
    if !rendered.exists() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    let r = match d.sim {
        "ours" => render_ours(d, &dir, size, frames),
        _ => render_simdive(
            d,
            peers.expect("simdive needs the peers"),
            &dir,
            (size, frames),
            rendered.exists(),
        ),
    };
    let render_s = t.elapsed().as_secs_f64();
    let _ = std::fs::write(&rendered, "");
    let mut scores: Vec<Score> = Vec::new();
    let mut survey = (f64::NAN, f64::NAN, String::new());
    let mut times = Vec::new();
    let mut photo_lines = Vec::new();
    for (c, col) in COLUMNS.into_iter().enumerate() {
        let t = Instant::now();
        let o = dir.join(col);
        if let Some(r) = reused.as_ref().filter(|_| col != "default") {
            scores.push(r[c]);
            times.push(0.0);
            continue;
        }
        if col == "numpy" {
            let Some(p) = peers else {
                scores.push(Score {
                    albedo: f64::NAN,
                    pattern: f64::NAN,
                    nmae: f64::NAN,
                    peer_pattern: f64::NAN,
                });
                continue;
            };
            let ok = Command::new(&p.python)
                .arg(p.dir.join("paper_numpy.py"))
                .arg("paper")
                .arg(&r.water)
                .arg(&r.survey)
                .arg(&o)
                .args(["--window", "7"])
                .stdout(std::process::Stdio::null())
                .status()
                .is_ok_and(|s| s.success());
            assert!(ok, "{}: the numpy peer failed", d.name());
        } else {
            let opts = Options {
                water_column: Some(r.water.clone()),
                survey: Some(r.survey.clone()),
                out: Some(o.clone()),
                transfer: Some(r.transfer),
                window: (col == "window7").then_some(7),
                ..Options::default()
            };
            let report = correct_mission(&opts, &Silent)
                .unwrap_or_else(|e| panic!("{} {col}: {e}", d.name()));
            if col == "default" {
                survey = survey_summary(&report);
                let photos = load_set(&o, &r.names, r.transfer);
                photo_lines = per_photo(d, &r, &photos, &report);
                // Every photo's health figures and window, kept for the monitor's analysis.
                if let Some(json) = &report.report_path {
                    let kept = out.join("reports");
                    let _ = std::fs::create_dir_all(&kept);
                    let _ = std::fs::copy(json, kept.join(format!("{}.json", d.name())));
                }
            }
        }
        let photos = load_set(&o, &r.names, r.transfer);
        let (nmae, peer_pattern) = match (d.sim, peers) {
            ("simdive", Some(p)) => evaluate_dive(p, &dir.join("dive"), &o),
            _ => (f64::NAN, f64::NAN),
        };
        scores.push(Score {
            albedo: albedo_error(&photos, &r.albedo, Some(&r.signal)),
            pattern: residual_pattern(&photos, &r.albedo, (8, 6), Some(&r.signal)),
            nmae,
            peer_pattern,
        });
        times.push(t.elapsed().as_secs_f64());
    }
    for col in COLUMNS {
        let _ = std::fs::remove_dir_all(dir.join(col));
    }
    let mut line = format!(
        "{}\t{}\t{}\t{}\t{}\t{:.3}\t{}\t{:.2}\t{:.2}\t{:.2}\t{}\t{}\t{}\t{:.3}\t{:.2}\t{}",
        d.name(),
        d.sim,
        d.half(),
        d.seed,
        d.rig,
        d.cover,
        d.patchy,
        d.altitude,
        d.swing,
        d.overlap,
        if d.srgb { "srgb" } else { "linear" },
        d.bits,
        if d.jpeg { "jpg" } else { "png" },
        survey.0,
        survey.1,
        if survey.2.is_empty() { "-" } else { &survey.2 },
    );
    for s in &scores {
        let _ = write!(
            line,
            "\t{:.4}\t{:.4}\t{:.4}\t{:.4}",
            s.albedo, s.pattern, s.nmae, s.peer_pattern
        );
    }
    let _ = write!(
        line,
        "\t{render_s:.1}\t{}",
        times
            .iter()
            .map(|t| format!("{t:.1}"))
            .collect::<Vec<_>>()
            .join(",")
    );
    (line, photo_lines)
}

/// The default's photos one by one, for the monitor as a classifier: each photo's albedo error and residual pattern
/// beside the true lighting's on the same photo, and the flags the run raised on it.
fn per_photo(d: &Drawn, r: &Rendered, photos: &[Raster], report: &Report) -> Vec<String> {
    (0..photos.len())
        .map(|i| {
            let one = |p: &Raster| {
                let (p, a) = (std::slice::from_ref(p), std::slice::from_ref(&r.albedo[i]));
                let m = Some(std::slice::from_ref(&r.lit[i]));
                (albedo_error(p, a, m), residual_pattern(p, a, (8, 6), m))
            };
            let (da, dp) = one(&photos[i]);
            let (oa, op) = one(&r.oracle[i]);
            let flags = report
                .frames
                .iter()
                .find(|f| f.index == i)
                .map(|f| {
                    f.health
                        .flags
                        .iter()
                        .map(|n| n.kind.clone())
                        .collect::<Vec<_>>()
                        .join(",")
                })
                .unwrap_or_default();
            format!(
                "{}\t{}\t{}\t{i}\t{da:.4}\t{dp:.4}\t{oa:.4}\t{op:.4}\t{}",
                d.name(),
                d.sim,
                d.half(),
                if flags.is_empty() { "-" } else { &flags }
            )
        })
        .collect()
}

const PHOTO_HEADER: &str =
    "dive\tsim\thalf\tphoto\tdefault_albedo\tdefault_pattern\toracle_albedo\toracle_pattern\tflags";

const HEADER: &str =
    "dive\tsim\thalf\tseed\trig\tcover\tpatchy\taltitude\tswing\toverlap\tcurve\tbits\tformat\
\tsurvey_cover\tlong_windows\trules\
\tdefault_albedo\tdefault_pattern\tdefault_nmae\tdefault_peer_pattern\
\twindow7_albedo\twindow7_pattern\twindow7_nmae\twindow7_peer_pattern\
\tnumpy_albedo\tnumpy_pattern\tnumpy_nmae\tnumpy_peer_pattern\trender_s\tcolumn_s";

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The rows of each simulator and half that has any (`sim` in column 1, `half` in column 2; rows of at least
/// `columns` fields), in the order the tables print them.
fn groups<'r, 'a>(
    rows: &'r [Vec<&'a str>],
    columns: usize,
) -> Vec<(&'static str, &'static str, Vec<&'r Vec<&'a str>>)> {
    let mut out = Vec::new();
    for sim in ["ours", "simdive"] {
        for half in ["tuning", "held-out"] {
            let here: Vec<&Vec<&str>> = rows
                .iter()
                .filter(|r| r.len() >= columns && r[1] == sim && r[2] == half)
                .collect();
            if !here.is_empty() {
                out.push((sim, half, here));
            }
        }
    }
    out
}

/// The distribution of default ÷ peer and default ÷ `--window 7` per score, per simulator and half, in Markdown.
fn summary(tsv: &Path) -> String {
    let text = std::fs::read_to_string(tsv).unwrap_or_default();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split('\t').collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split('\t').collect()).collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let mut md = String::from(
        "| simulator | half | dives | score | default ÷ numpy: median / p90 / worst (dive) | default ÷ `--window 7`: median / p90 / worst (dive) | bare sediment: survey cover max |\n|---|---|---|---|---|---|---|\n",
    );
    for (sim, half, here) in groups(&rows, 3) {
        let bare = here
            .iter()
            .filter(|r| r[5].parse::<f64>().is_ok_and(|c| c == 0.0))
            .filter_map(|r| col("survey_cover").and_then(|i| r[i].parse::<f64>().ok()))
            .fold(f64::NAN, f64::max);
        let mut scores = vec![("albedo", "albedo error"), ("pattern", "residual pattern")];
        if sim == "simdive" {
            scores.push(("nmae", "evaluate_dive nmae"));
            scores.push(("peer_pattern", "evaluate_dive pattern"));
        }
        for (key, label) in scores {
            let ratio = |other: &str| {
                let (Some(a), Some(b)) = (
                    col(&format!("default_{key}")),
                    col(&format!("{other}_{key}")),
                ) else {
                    return "-".to_string();
                };
                let mut v: Vec<(f64, &str)> = here
                    .iter()
                    .filter_map(|r| {
                        let (x, y) = (r[a].parse::<f64>().ok()?, r[b].parse::<f64>().ok()?);
                        (x.is_finite() && y.is_finite() && y > 0.0).then_some((x / y, r[0]))
                    })
                    .collect();
                if v.is_empty() {
                    return "-".to_string();
                }
                v.sort_by(|p, q| p.0.total_cmp(&q.0));
                let mut r: Vec<f64> = v.iter().map(|p| p.0).collect();
                let worst = v.last().expect("not empty");
                format!(
                    "{:.2} / {:.2} / **{:.2}** ({})",
                    quantile(&mut r, 0.5),
                    quantile(&mut r, 0.9),
                    worst.0,
                    worst.1
                )
            };
            let _ = writeln!(
                md,
                "| {sim} | {half} | {} | {label} | {} | {} | {} |",
                here.len(),
                ratio("numpy"),
                ratio("window7"),
                if bare.is_finite() {
                    format!("{bare:.2}")
                } else {
                    "-".into()
                }
            );
        }
    }
    md
}

/// The monitor as a classifier on the held-out half (and the tuning half), by the definition a user signs: a photo
/// is wrong where its albedo error is above max(1.5 × the true lighting's on that photo, the true lighting's + 0.03),
/// or its residual pattern above max(2 × the true lighting's, 0.05); flagged where the run raised any flag on it.
/// Precision, recall and the share of good photos flagged, overall and per flag, per simulator.
fn monitor_summary(tsv: &Path) -> String {
    let text = std::fs::read_to_string(tsv).unwrap_or_default();
    let rows: Vec<Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| l.split('\t').collect())
        .collect();
    let mut md = String::from(
        "| simulator | half | photos | wrong | flagged | precision | recall | good photos flagged | per flag: flagged (of them wrong) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for (sim, half, here) in groups(&rows, 9) {
        let num = |r: &Vec<&str>, i: usize| r[i].parse::<f64>().unwrap_or(f64::NAN);
        let wrong = |r: &Vec<&str>| {
            let (da, dp, oa, op) = (num(r, 4), num(r, 5), num(r, 6), num(r, 7));
            da > (1.5 * oa).max(oa + 0.03) || dp > (2.0 * op).max(0.05)
        };
        let flagged = |r: &Vec<&str>| r[8] != "-";
        let n = here.len();
        let w = here.iter().filter(|r| wrong(r)).count();
        let f = here.iter().filter(|r| flagged(r)).count();
        let tp = here.iter().filter(|r| wrong(r) && flagged(r)).count();
        let good_flagged = here.iter().filter(|r| !wrong(r) && flagged(r)).count();
        let mut per = std::collections::BTreeMap::<&str, (usize, usize)>::new();
        for r in &here {
            for k in r[8].split(',').filter(|k| *k != "-") {
                let e = per.entry(k).or_default();
                e.0 += 1;
                e.1 += usize::from(wrong(r));
            }
        }
        let per = per
            .iter()
            .map(|(k, (a, b))| format!("{k} {a} ({b})"))
            .collect::<Vec<_>>()
            .join(", ");
        let ratio = |a: usize, b: usize| {
            if b == 0 {
                "-".to_string()
            } else {
                format!("{:.2}", a as f64 / b as f64)
            }
        };
        let _ = writeln!(
            md,
            "| {sim} | {half} | {n} | {w} | {f} | {} | {} | {} | {per} |",
            ratio(tp, f),
            ratio(tp, w),
            ratio(good_flagged, n - w)
        );
    }
    md
}

fn main() {
    let mut out =
        PathBuf::from(std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| "target".into()))
            .join("dive-family");
    let (mut count, mut frames, mut size, mut from) = (60usize, 40usize, (320usize, 240usize), 0);
    let mut sims = vec!["ours", "simdive"];
    let mut only_summary = false;
    let mut others_from: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().unwrap_or_else(|| panic!("{a} needs a value"));
        match a.as_str() {
            "--out" => out = PathBuf::from(value()),
            "--count" => count = value().parse().expect("--count N"),
            "--frames" => frames = value().parse().expect("--frames N"),
            "--from" => from = value().parse().expect("--from K"),
            "--size" => {
                size = value()
                    .split_once('x')
                    .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                    .expect("--size WxH")
            }
            "--sim" => {
                sims = match value().as_str() {
                    "ours" => vec!["ours"],
                    "simdive" => vec!["simdive"],
                    _ => vec!["ours", "simdive"],
                }
            }
            "--summary" => only_summary = true,
            "--others-from" => others_from = Some(PathBuf::from(value())),
            _ => {
                eprintln!("dive_family: unknown argument {a:?} (see the docs at the top of examples/dive_family.rs)");
                std::process::exit(2);
            }
        }
    }
    std::fs::create_dir_all(&out).expect("output folder");
    let tsv = out.join("family.tsv");
    if !only_summary {
        let peers = peers();
        if peers.is_none() {
            eprintln!("dive_family: peers not found (../peer-venv or PEER_PYTHON, ../shared/peers): the crate's dives only");
            sims.retain(|s| *s == "ours");
        }
        let done = std::fs::read_to_string(&tsv).unwrap_or_default();
        if done.is_empty() {
            std::fs::write(&tsv, format!("{HEADER}\n")).expect("write family.tsv");
        }
        let earlier_tsv = others_from
            .as_ref()
            .map(|d| {
                std::fs::read_to_string(d.join("family.tsv")).expect("--others-from DIR/family.tsv")
            })
            .unwrap_or_default();
        // Alternate the simulators so that a run cut short holds both.
        for k in from..count {
            for sim in &sims {
                let d = draw(sim, k);
                if done
                    .lines()
                    .any(|l| l.split('\t').next() == Some(&d.name()))
                {
                    continue;
                }
                let t = Instant::now();
                let earlier = others_from
                    .as_deref()
                    .map(|dir| (dir, earlier_tsv.as_str()));
                let (line, photo_lines) =
                    run_one(&d, peers.as_ref(), &out, (size, frames), earlier);
                let photos_tsv = out.join("photos.tsv");
                let mut p = std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(&photos_tsv)
                    .expect("open photos.tsv");
                if p.metadata().is_ok_and(|m| m.len() == 0) {
                    writeln!(p, "{PHOTO_HEADER}").expect("append to photos.tsv");
                }
                for l in photo_lines {
                    writeln!(p, "{l}").expect("append to photos.tsv");
                }
                eprintln!(
                    "dive_family: {} {:.0} s: {line}",
                    d.name(),
                    t.elapsed().as_secs_f64()
                );
                let mut f = std::fs::OpenOptions::new()
                    .append(true)
                    .open(&tsv)
                    .expect("open family.tsv");
                writeln!(f, "{line}").expect("append to family.tsv");
            }
        }
    }
    let mut md = summary(&tsv);
    md.push('\n');
    md.push_str(&monitor_summary(&out.join("photos.tsv")));
    println!("{md}");
    let _ = std::fs::write(out.join("family.md"), md);
}

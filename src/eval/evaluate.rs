//! `abysslight evaluate`: score corrected photos.
//!
//! - With ground truth (a simulated dive): the **albedo error** after one global per-channel scale `s_c` (least
//!   squares, since white balance is a free choice of each method): `Σ|g − s_c·t| / Σ s_c·t` over all samples of all
//!   photos, in linear light; and the **residual lighting pattern**: the image frame is cut into a coarse grid, the
//!   median of `g / (s_c·t)` is taken per cell over all photos, and the robust spread of those cell medians
//!   (1.4826·median absolute deviation divided by the median, i.e. a robust coefficient of variation) is reported, averaged over channels. A perfect correction scores 0 on both.
//! - Without ground truth: the **consistency** metric of Köser et al. over overlapping photos, given their
//!   placement in a mosaic: each photo's mean value per mosaic cell (cells it covers completely), the RMS
//!   difference of those to the per-cell mean over cells seen by at least two photos, divided by the standard
//!   deviation of all observed pixels; per channel, then averaged.
//!
//! Placement file (`placements.txt`): one photo per line, `#` starts a comment, fields separated by white space:
//! `NAME TX TY` (the photo's pixel `(u, v)` lies at mosaic `(u + TX, v + TY)`) or `NAME H11 H12 H13 H21 H22 H23
//! H31 H32 H33` (a homography from photo pixels to mosaic coordinates, row-major). Pixel coordinates: the
//! top-left corner of the photo is `(0, 0)`, pixel centres are at `+0.5`. NAME is the photo's path relative to the
//! photo folder.

use std::io::Write;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::eval::simulate::{apply_h, invert3, load_truth, Truth};
use crate::io::decode;
use crate::method::mask::Mask;
use crate::method::raster::Raster;
use crate::method::transfer::Transfer;

/// Placement of one photo in the mosaic.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Placement {
    /// File name of the photo (as listed in the placement file).
    pub name: String,
    /// Photo pixel → mosaic, row-major.
    pub h: [f64; 9],
}

/// Parse a placement file's text (see the module docs). `path` is only used in error messages.
pub(crate) fn parse_placements(text: &str, path: &Path) -> Result<Vec<Placement>> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let bad = |reason: String| Error::Config {
            path: path.to_owned(),
            reason: format!("line {}: {reason}", i + 1),
        };
        let fields: Vec<&str> = line.split_whitespace().collect();
        let nums: Vec<f64> = fields[1..]
            .iter()
            .map(|f| f.parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad(format!("not a number in {line:?}")))?;
        let h = match nums.as_slice() {
            [tx, ty] => [1.0, 0.0, *tx, 0.0, 1.0, *ty, 0.0, 0.0, 1.0],
            [..] if nums.len() == 9 => {
                let mut h = [0.0; 9];
                h.copy_from_slice(&nums);
                h
            }
            _ => {
                return Err(bad(format!(
                    "expected NAME TX TY or NAME and 9 homography entries, got {} numbers",
                    nums.len()
                )))
            }
        };
        if nums.iter().any(|v| !v.is_finite()) || invert3(&h).is_none() {
            return Err(bad("placement is not finite or not invertible".into()));
        }
        out.push(Placement {
            name: fields[0].to_owned(),
            h,
        });
    }
    if out.is_empty() {
        return Err(Error::Config {
            path: path.to_owned(),
            reason: "no placements in the file".into(),
        });
    }
    Ok(out)
}

/// The text of a placement file with one homography per photo.
pub(crate) fn placements_text<'a>(rows: impl Iterator<Item = (&'a str, &'a [f64; 9])>) -> String {
    let mut s = String::from(
        "# abysslight placements: NAME and the homography photo pixel -> mosaic (row-major), or NAME TX TY\n",
    );
    for (name, h) in rows {
        s.push_str(name);
        for v in h {
            s.push_str(&format!(" {v:.9e}"));
        }
        s.push('\n');
    }
    s
}

/// Per-channel least-squares scale `s_c` minimising `Σ (g − s_c·t)²` (over the samples `signal` flags, if given).
fn channel_scales(got: &[Raster], truth: &[Raster], signal: Option<&[Vec<bool>]>) -> Vec<f64> {
    let c = truth[0].channels;
    let (mut num, mut den) = (vec![0.0f64; c], vec![0.0f64; c]);
    for (k, (g, t)) in got.iter().zip(truth).enumerate() {
        for (i, (&gv, &tv)) in g.data.iter().zip(&t.data).enumerate() {
            if signal.is_none_or(|m| m[k][i]) {
                num[i % c] += gv as f64 * tv as f64;
                den[i % c] += tv as f64 * tv as f64;
            }
        }
    }
    num.iter()
        .zip(&den)
        .map(|(n, d)| n / d.max(1e-30))
        .collect()
}

fn check_pairs(got: &[Raster], truth: &[Raster]) {
    assert_eq!(got.len(), truth.len(), "one truth per photo");
    assert!(!truth.is_empty(), "no photos");
    for (g, t) in got.iter().zip(truth) {
        assert_eq!(g.layout(), t.layout(), "photo and truth differ in size");
    }
}

/// Albedo error after the best global per-channel scale: `Σ|g − s_c·t| / Σ s_c·t`, over every sample (`signal:
/// None`) or over the samples `signal` flags (see [`residual_pattern`]).
pub fn albedo_error(got: &[Raster], truth: &[Raster], signal: Option<&[Vec<bool>]>) -> f64 {
    check_pairs(got, truth);
    check_signal(truth, signal);
    let s = channel_scales(got, truth, signal);
    let c = s.len();
    let (mut err, mut mag) = (0.0f64, 0.0f64);
    for (k, (g, t)) in got.iter().zip(truth).enumerate() {
        for (i, (&gv, &tv)) in g.data.iter().zip(&t.data).enumerate() {
            if signal.is_none_or(|m| m[k][i]) {
                let e = s[i % c] * tv as f64;
                err += (gv as f64 - e).abs();
                mag += e;
            }
        }
    }
    err / mag.max(1e-30)
}

fn check_signal(truth: &[Raster], signal: Option<&[Vec<bool>]>) {
    if let Some(m) = signal {
        assert_eq!(m.len(), truth.len(), "one signal mask per photo");
        for (m, t) in m.iter().zip(truth) {
            assert_eq!(m.len(), t.data.len(), "one signal flag per sample");
        }
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Residual lighting pattern: robust spread (1.4826·MAD / median) of the per-cell medians of `g / (s_c·t)` over a `gx`×`gy` grid
/// of the image frame (pooled over photos), averaged over channels. Samples with `t` below 0.02 are skipped.
/// A channel left black (its scale `s_c` or the median of its cell medians 0) scores 1, the whole signal lost.
/// (It used to score 0, a perfect flatness, which rewarded a correction that blacks out a starved channel.)
///
/// With `signal: None` every sample is scored; with flags (one per sample of each photo, in the rasters' order) only
/// those set: e.g. where the photo carries the albedo at all, its true lit signal `F·A` at least one code step of the
/// camera's encoding. The flags come from the data, not from a method's output, so every method is scored on the
/// same samples. A channel with no scored sample is left out of the average (NaN when none is left).
pub fn residual_pattern(
    got: &[Raster],
    truth: &[Raster],
    grid: (usize, usize),
    signal: Option<&[Vec<bool>]>,
) -> f64 {
    check_pairs(got, truth);
    check_signal(truth, signal);
    let s = channel_scales(got, truth, signal);
    let c = s.len();
    let (w, h) = (truth[0].width, truth[0].height);
    let (gx, gy) = (grid.0.clamp(1, w), grid.1.clamp(1, h));
    let (mut total, mut scored) = (0.0, 0usize);
    for (ch, &sc) in s.iter().enumerate() {
        let mut cells: Vec<Vec<f64>> = vec![Vec::new(); gx * gy];
        for (k, (g, t)) in got.iter().zip(truth).enumerate() {
            for y in 0..h {
                for x in 0..w {
                    let i = (y * w + x) * c + ch;
                    let tv = t.data[i] as f64;
                    if tv >= 0.02 && signal.is_none_or(|m| m[k][i]) {
                        cells[(y * gy / h) * gx + x * gx / w].push(g.data[i] as f64 / (sc * tv));
                    }
                }
            }
        }
        let mut meds: Vec<f64> = cells
            .iter_mut()
            .filter(|v| !v.is_empty())
            .map(|v| median(v))
            .collect();
        if meds.is_empty() {
            continue;
        }
        scored += 1;
        // A black channel: scale 0 (or NaN), or most cells at 0.
        let black = |v: f64| v.is_nan() || v <= 0.0 || v.is_infinite();
        if black(sc) {
            total += 1.0;
            continue;
        }
        let mid = median(&mut meds);
        if black(mid) {
            total += 1.0;
            continue;
        }
        let mut dev: Vec<f64> = meds.iter().map(|m| (m - mid).abs()).collect();
        total += 1.4826 * median(&mut dev) / mid;
    }
    if scored == 0 {
        return f64::NAN;
    }
    total / scored as f64
}

/// Bilinear sample at continuous pixel coordinates (pixel centres at `+0.5`), clamped at the border.
fn sample(r: &Raster, u: f64, v: f64, ch: usize) -> f64 {
    let x = (u - 0.5).clamp(0.0, (r.width - 1) as f64);
    let y = (v - 0.5).clamp(0.0, (r.height - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(r.width - 1), (y0 + 1).min(r.height - 1));
    let (tx, ty) = (x - x0 as f64, y - y0 as f64);
    let g = |xx: usize, yy: usize| r.get(xx, yy, ch) as f64;
    let a = g(x0, y0) + (g(x1, y0) - g(x0, y0)) * tx;
    let b = g(x0, y1) + (g(x1, y1) - g(x0, y1)) * tx;
    a + (b - a) * ty
}

/// A photo's mean over one mosaic cell: (cell index, per-channel mean).
type CellObservation = ((i64, i64), Vec<f64>);
/// Per mosaic cell: photos seen, per-channel sum and sum of squares of their cell means.
type CellSums = (usize, Vec<f64>, Vec<f64>);

/// Sample points per cell side when a photo's mean over a mosaic cell is taken.
const CELL_SAMPLES: usize = 4;

/// The consistency metric (see the module docs); `cell` is the mosaic cell size in mosaic units. `None` when no
/// cell is seen by two photos.
pub fn consistency(photos: &[Raster], h: &[[f64; 9]], cell: f64) -> Option<f64> {
    consistency_parts(photos, h, cell).map(|c| c.0)
}

/// [`consistency`] and the overlap difference: the same RMS difference divided by the mean of all pixels instead
/// of their standard deviation (a correction flattens the photos, which lowers the standard deviation and so
/// raises the consistency figure even when the overlaps agree better; the mean is not moved by that).
///
/// Public for the dive matrix (examples/dive_matrix.rs), which scores the signal-masked sets with it; not part of
/// the documented surface.
#[doc(hidden)]
pub fn consistency_parts(photos: &[Raster], h: &[[f64; 9]], cell: f64) -> Option<(f64, f64)> {
    assert_eq!(photos.len(), h.len(), "one placement per photo");
    let c = photos.first()?.channels;
    // Per photo: (cell, per-channel mean) of the cells it covers completely.
    let per_photo: Vec<Vec<CellObservation>> = photos
        .par_iter()
        .zip(h)
        .map(|(p, h)| cell_means(p, h, cell, c))
        .collect();
    let (ss, n) = overlap_squares(&per_photo, c)?;
    let (s1, s2, m) = pixel_sums(photos, c);
    let (mut total, mut relative) = (0.0, 0.0);
    for ch in 0..c {
        let rms = (ss[ch] / n as f64).sqrt();
        let mean = s1[ch] / m as f64;
        let sd = (s2[ch] / m as f64 - mean * mean).max(0.0).sqrt();
        total += rms / sd.max(1e-30);
        relative += rms / mean.abs().max(1e-30);
    }
    Some((total / c as f64, relative / c as f64))
}

/// The mosaic cells photo `p` (placed by `h`) may touch: the inclusive cell ranges `(x, y)` spanned by the
/// bounding box of its placed corners.
fn cell_span(p: &Raster, h: &[f64; 9], cell: f64) -> (RangeInclusive<i64>, RangeInclusive<i64>) {
    let (w, hh) = (p.width as f64, p.height as f64);
    let corners = [(0.0, 0.0), (w, 0.0), (0.0, hh), (w, hh)].map(|(u, v)| apply_h(h, u, v));
    let lo_x = corners.iter().map(|c| c.0).fold(f64::INFINITY, f64::min);
    let hi_x = corners
        .iter()
        .map(|c| c.0)
        .fold(f64::NEG_INFINITY, f64::max);
    let lo_y = corners.iter().map(|c| c.1).fold(f64::INFINITY, f64::min);
    let hi_y = corners
        .iter()
        .map(|c| c.1)
        .fold(f64::NEG_INFINITY, f64::max);
    (
        (lo_x / cell).floor() as i64..=(hi_x / cell).floor() as i64,
        (lo_y / cell).floor() as i64..=(hi_y / cell).floor() as i64,
    )
}

/// Photo `p`'s mean over each of its first `c` channels in every mosaic cell it covers completely (placement
/// `h`), sampled on a [`CELL_SAMPLES`]² grid; a cell touching a masked pixel (NaN) is left out.
fn cell_means(p: &Raster, h: &[f64; 9], cell: f64, c: usize) -> Vec<CellObservation> {
    let inv = invert3(h).expect("placement homography is invertible");
    let (w, hh) = (p.width as f64, p.height as f64);
    let inside = |(u, v): (f64, f64)| u >= 0.0 && v >= 0.0 && u <= w && v <= hh;
    let (xs, ys) = cell_span(p, h, cell);
    let mut out = Vec::new();
    for cy in ys {
        for cx in xs.clone() {
            let (x0, y0) = (cx as f64 * cell, cy as f64 * cell);
            let covered = [
                (x0, y0),
                (x0 + cell, y0),
                (x0, y0 + cell),
                (x0 + cell, y0 + cell),
            ]
            .into_iter()
            .all(|(x, y)| inside(apply_h(&inv, x, y)));
            if !covered {
                continue;
            }
            let mut mean = vec![0.0f64; c];
            for sy in 0..CELL_SAMPLES {
                for sx in 0..CELL_SAMPLES {
                    let x = x0 + (sx as f64 + 0.5) / CELL_SAMPLES as f64 * cell;
                    let y = y0 + (sy as f64 + 0.5) / CELL_SAMPLES as f64 * cell;
                    let (u, v) = apply_h(&inv, x, y);
                    for (ch, m) in mean.iter_mut().enumerate() {
                        *m += sample(p, u, v, ch);
                    }
                }
            }
            for m in &mut mean {
                *m /= (CELL_SAMPLES * CELL_SAMPLES) as f64;
            }
            // A cell touching a masked pixel (NaN) is not observed.
            if mean.iter().all(|m| m.is_finite()) {
                out.push(((cx, cy), mean));
            }
        }
    }
    out
}

/// Over the cells seen by two photos or more: per channel, the sum of squared differences of the photos' cell
/// means from their cell's average, and the number of observations in those cells. `None` when no cell is seen
/// twice.
fn overlap_squares(per_photo: &[Vec<CellObservation>], c: usize) -> Option<(Vec<f64>, usize)> {
    // Sorted by cell, so that the sums below add up in the same order on every run (a hash map's order varies,
    // and with it the last bits of the score).
    let mut cells: std::collections::BTreeMap<(i64, i64), CellSums> =
        std::collections::BTreeMap::new();
    for obs in per_photo.iter().flatten() {
        let e = cells
            .entry(obs.0)
            .or_insert_with(|| (0, vec![0.0; c], vec![0.0; c]));
        e.0 += 1;
        for ch in 0..c {
            e.1[ch] += obs.1[ch];
            e.2[ch] += obs.1[ch] * obs.1[ch];
        }
    }
    let (mut ss, mut n) = (vec![0.0f64; c], 0usize);
    for (count, sum, sumsq) in cells.values().filter(|e| e.0 >= 2) {
        n += count;
        for ch in 0..c {
            ss[ch] += (sumsq[ch] - sum[ch] * sum[ch] / *count as f64).max(0.0);
        }
    }
    if n == 0 {
        return None;
    }
    Some((ss, n))
}

/// Per channel, the sum and sum of squares of all observed (finite) pixels of all photos, and their count: the
/// standard deviation and mean the overlap differences are divided by.
fn pixel_sums(photos: &[Raster], c: usize) -> (Vec<f64>, Vec<f64>, usize) {
    let (mut s1, mut s2, mut m) = (vec![0.0f64; c], vec![0.0f64; c], 0usize);
    for p in photos {
        for px in p
            .data
            .chunks_exact(c)
            .filter(|px| px.iter().all(|v| v.is_finite()))
        {
            for ch in 0..c {
                s1[ch] += px[ch] as f64;
                s2[ch] += (px[ch] as f64).powi(2);
            }
            m += 1;
        }
    }
    (s1, s2, m)
}

/// Settings of [`evaluate`].
#[derive(Debug, Clone, Serialize)]
pub struct EvalSettings {
    /// Mosaic cell size for the consistency metric, in mosaic units. Default: 8.
    pub cell: f64,
    /// Grid of the residual pattern (columns, rows). Default: 8×6.
    pub grid: (usize, usize),
    /// Transfer curve of the photos (all sets). Default: the simulated dive's encoding, else linear.
    pub transfer: Option<Transfer>,
    /// Register the photos of this folder (the raw photos) and use the placements found for the consistency
    /// metric of every set (see `register`).
    pub register: Option<PathBuf>,
    /// Write the placements found by `register` here (the placement file format).
    pub save_placements: Option<PathBuf>,
    /// Box-average photos by this factor before the consistency metric (memory: every photo of a set is held);
    /// placements stay in full-resolution units. Default: 1.
    pub downsample: usize,
    /// A mask the size of the photos (white = not seafloor: overlays, laser dots, e.g. a run's `mask-auto.png`):
    /// its pixels are left out of the consistency metric in every photo. Default: none.
    pub mask: Option<PathBuf>,
}

impl EvalSettings {
    /// The ranges of `abysslight evaluate`'s flags, each message naming the flag: a cell below one unit would
    /// grow the mosaic grid without bound.
    pub fn validate(&self) -> Result<()> {
        crate::eval::within("--cell", self.cell, 1.0, 1e6)?;
        crate::eval::within("--eval-downsample", self.downsample, 1, 64)?;
        Ok(())
    }
}

impl Default for EvalSettings {
    fn default() -> Self {
        EvalSettings {
            cell: 8.0,
            grid: (8, 6),
            transfer: None,
            register: None,
            save_placements: None,
            downsample: 1,
            mask: None,
        }
    }
}

/// Scores of one set of photos.
#[derive(Debug, Clone, Serialize)]
pub struct Scores {
    /// Name of the set in the table (e.g. the method).
    pub label: String,
    /// Folder the photos were read from.
    pub folder: PathBuf,
    /// Photos scored.
    pub photos: usize,
    /// `Σ|g − s_c·t| / Σ s_c·t` against the true albedo (see [`albedo_error`]); `None` without truth.
    pub albedo_error: Option<f64>,
    /// Robust spread of per-cell `g / (s_c·t)` medians: lighting left in the photos; `None` without truth.
    pub residual_pattern: Option<f64>,
    /// RMS difference over overlaps divided by the standard deviation of all pixels; `None` without placements.
    pub consistency: Option<f64>,
    /// RMS difference over overlaps divided by the mean of all pixels (see `consistency_parts`).
    pub overlap_difference: Option<f64>,
    /// Share of the samples at black or at the top code. Two overlapping photos clipped at the same place agree
    /// whatever lies there: a set with many clipped samples scores a better consistency than it earns.
    pub clipped: f64,
}

/// How the registration of `--register` went.
#[derive(Debug, Clone, Serialize)]
pub struct RegistrationSummary {
    /// Photos registered.
    pub photos: usize,
    /// Consecutive pairs whose match passed the confidence test.
    pub accepted_pairs: usize,
    /// Consecutive pairs tried.
    pub pairs: usize,
    /// Median normalised cross-correlation of the accepted matches.
    pub median_ncc: Option<f64>,
}

impl RegistrationSummary {
    fn of(reg: &crate::eval::register::Registration) -> Self {
        let (accepted_pairs, pairs) = reg.accepted();
        let mut ncc: Vec<f64> = reg
            .matches
            .iter()
            .flatten()
            .filter(|m| m.accepted)
            .map(|m| m.ncc)
            .collect();
        RegistrationSummary {
            photos: reg.placements.len(),
            accepted_pairs,
            pairs,
            median_ncc: (!ncc.is_empty()).then(|| median(&mut ncc)),
        }
    }
}

/// What `abysslight evaluate` writes as JSON.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluation {
    /// The truth file (`truth/dive.json`) scored against, if any.
    pub truth: Option<PathBuf>,
    /// The placement file given with `--placements`, or the one `--save-placements` wrote, if any.
    pub placements: Option<PathBuf>,
    /// With `--register`: how many consecutive pairs were matched.
    pub registration: Option<RegistrationSummary>,
    /// Transfer curve assumed between photo values and linear light.
    pub transfer: Transfer,
    /// The settings of the run.
    pub settings: EvalSettings,
    /// Scores per set of photos, in the order given.
    pub sets: Vec<Scores>,
    /// What the user should know about the scores: a set its `correct` run wrote with another curve than
    /// `transfer` (`transfer_warnings`).
    pub warnings: Vec<String>,
}

/// The curve the `correct` run that wrote `folder` took, from its `<folder>/_abysslight/report.json`
/// (`options.transfer`, which a run records with `auto` resolved; for an `auto` there, the curve
/// `transfer_assumed` names). `None` when the folder holds no readable report.
pub(crate) fn run_transfer(folder: &Path) -> Option<Transfer> {
    let text =
        std::fs::read_to_string(folder.join(crate::io::WORK_DIR).join("report.json")).ok()?;
    let report: serde_json::Value = serde_json::from_str(&text).ok()?;
    let given = report.get("options")?.get("transfer")?.as_str()?;
    let assumed = report.get("transfer_assumed").and_then(|a| a.as_str());
    let curve = match (given.trim().eq_ignore_ascii_case("auto"), assumed) {
        (false, _) => given,
        // "<curve>: <why>" (a curve never holds ": ", gamma:2.2 no space).
        (true, Some(a)) => a.split_once(": ").map_or(a, |(t, _)| t),
        (true, None) => return None,
    };
    curve.parse().ok()
}

/// A warning for each set whose `correct` run ([`run_transfer`]) took another curve than `transfer`, the one the
/// scores assume: its photos would be read into linear light with another curve than they were written with, and
/// its scores would not be those of the run.
pub(crate) fn transfer_warnings(sets: &[(String, PathBuf)], transfer: Transfer) -> Vec<String> {
    sets.iter()
        .filter_map(|(label, folder)| {
            let run = run_transfer(folder).filter(|t| *t != transfer)?;
            Some(format!(
                "{label}: the correct run that wrote {} took the camera curve {run} (its {}/report.json), but these \
                 scores assume {transfer}; give --transfer {run} to score the photos as they were corrected",
                folder.display(),
                crate::io::WORK_DIR
            ))
        })
        .collect()
}

/// `truth/dive.json` below a dive folder, or the file itself.
fn truth_file(p: &Path) -> PathBuf {
    if p.is_dir() {
        if p.join("truth").join("dive.json").is_file() {
            p.join("truth").join("dive.json")
        } else {
            p.join("dive.json")
        }
    } else {
        p.to_owned()
    }
}

/// Set the pixels `mask` ignores to NaN in every channel: the consistency metric leaves out every mosaic cell
/// observation that touches one, and them from the photos' mean and standard deviation. A mask of another size than
/// the photo, or one that ignores every pixel, is an error naming the mask (`path`), as for `correct --mask`.
pub(crate) fn leave_out(r: &mut Raster, mask: &Mask, path: &Path) -> Result<()> {
    mask.check(r.layout(), path)?;
    let c = r.channels;
    for (px, &ignore) in r.data.chunks_exact_mut(c).zip(&mask.ignore) {
        if ignore {
            px.fill(f32::NAN);
        }
    }
    Ok(())
}

/// Decode a photo and undo its transfer curve.
pub(crate) fn load_linear(path: &Path, transfer: Transfer) -> Result<Raster> {
    Ok(Raster::from_photo_linear(&decode(path)?, transfer))
}

/// Box average by `k` (the right and bottom remainders dropped); `k = 1` returns a copy.
pub(crate) fn reduce(r: &Raster, k: usize) -> Raster {
    if k <= 1 {
        return r.clone();
    }
    let c = r.channels;
    Raster::from_fn(r.width / k, r.height / k, c, |x, y, ch| {
        let mut s = 0.0f32;
        for yy in y * k..(y + 1) * k {
            for xx in x * k..(x + 1) * k {
                s += r.get(xx, yy, ch);
            }
        }
        s / (k * k) as f32
    })
}

/// A placement of full-resolution pixels turned into one of pixels of a photo reduced by `k`: reduced pixel
/// coordinates (pixel centres at `+0.5`) times `k` are full-resolution coordinates, so `H·diag(k, k, 1)`.
fn scale_h(h: &[f64; 9], k: usize) -> [f64; 9] {
    let k = k as f64;
    [
        h[0] * k,
        h[1] * k,
        h[2],
        h[3] * k,
        h[4] * k,
        h[5],
        h[6] * k,
        h[7] * k,
        h[8],
    ]
}

/// The placements to score consistency with: `--register`ed from the raw photos (also saved with
/// `--save-placements`), read from `--placements`, or the simulator's from the truth; with the registration's
/// summary when registered.
fn resolve_placements(
    placements: Option<&Path>,
    settings: &EvalSettings,
    truth: Option<&Truth>,
) -> Result<(Option<Vec<Placement>>, Option<RegistrationSummary>)> {
    let mut registration = None;
    let placed = match (placements, &settings.register) {
        (Some(_), Some(_)) => {
            return Err(Error::Usage(
                "give either --placements or --register, not both".into(),
            ))
        }
        (None, Some(raw)) => {
            let transfer = settings.transfer.unwrap_or_default();
            let reg = crate::eval::register::register_folder(raw, transfer)?;
            if let Some(out) = &settings.save_placements {
                let text = placements_text(reg.placements.iter().map(|p| (p.name.as_str(), &p.h)));
                crate::io::write_with(out, |w| {
                    w.write_all(text.as_bytes()).map_err(|e| Error::io(out, e))
                })?;
            }
            let placed = reg.placements.clone();
            registration = Some(RegistrationSummary::of(&reg));
            Some(placed)
        }
        (Some(p), None) => {
            let text = std::fs::read_to_string(p).map_err(|e| Error::io(p, e))?;
            Some(parse_placements(&text, p)?)
        }
        (None, None) => truth.map(|t| {
            t.poses
                .iter()
                .map(|p| Placement {
                    name: p.file.clone(),
                    h: p.homography,
                })
                .collect()
        }),
    };
    Ok((placed, registration))
}

/// What every set of photos is scored against.
struct ScoreSet<'a> {
    /// File names of the photos, in order (each set holds the same names).
    names: &'a [String],
    /// True albedo of each photo, if scored against a simulated truth.
    albedo: Option<&'a [Raster]>,
    /// Placements for the consistency metric, if any.
    placed: Option<&'a [Placement]>,
    /// Curve from photo values to linear light.
    transfer: Transfer,
    /// Pixels left out of the consistency metric, with the mask's path (for errors).
    mask: Option<(&'a Mask, &'a Path)>,
}

impl ScoreSet<'_> {
    /// Load the set's photos from `folder` and score them.
    fn score(&self, label: &str, folder: &Path, settings: &EvalSettings) -> Result<Scores> {
        let (names, albedo, placed, transfer, mask) = (
            self.names,
            self.albedo,
            self.placed,
            self.transfer,
            self.mask,
        );
        let k = if albedo.is_some() {
            1
        } else {
            settings.downsample.max(1)
        };
        // Without a truth the photos serve the consistency metric only, and are masked as they load.
        let (photos, clipped): (Vec<Raster>, Vec<(usize, usize)>) = names
            .par_iter()
            .map(|n| {
                let mut r = load_linear(&folder.join(n), transfer)?;
                let clipped = clipped_samples(&r);
                if let (Some((m, path)), None) = (mask, albedo) {
                    leave_out(&mut r, m, path)?;
                }
                Ok((reduce(&r, k), clipped))
            })
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .unzip();
        let (at_limit, samples) = clipped.iter().fold((0, 0), |(a, n), (c, t)| (a + c, n + t));
        if let Some(a) = &albedo {
            for (p, (t, n)) in photos.iter().zip(a.iter().zip(names)) {
                if p.layout() != t.layout() {
                    return Err(Error::Mismatch {
                        path: folder.join(n),
                        reason: format!(
                            "photo is {}, its true albedo is {}",
                            p.layout(),
                            t.layout()
                        ),
                    });
                }
            }
        }
        let masked: Option<Vec<Raster>> = match (mask, albedo, placed) {
            (Some((m, path)), Some(_), Some(_)) => Some(
                photos
                    .iter()
                    .map(|p| {
                        let mut p = p.clone();
                        leave_out(&mut p, m, path).map(|()| p)
                    })
                    .collect::<Result<_>>()?,
            ),
            _ => None,
        };
        let parts = placed.as_ref().and_then(|pl| {
            let hs: Vec<[f64; 9]> = names
                .iter()
                .map(|n| pl.iter().find(|p| &p.name == n).map(|p| scale_h(&p.h, k)))
                .collect::<Option<_>>()?;
            consistency_parts(masked.as_deref().unwrap_or(&photos), &hs, settings.cell)
        });
        Ok(Scores {
            label: label.to_string(),
            folder: folder.to_owned(),
            photos: photos.len(),
            albedo_error: albedo.map(|a| albedo_error(&photos, a, None)),
            residual_pattern: albedo.map(|a| residual_pattern(&photos, a, settings.grid, None)),
            consistency: parts.map(|p| p.0),
            overlap_difference: parts.map(|p| p.1),
            clipped: at_limit as f64 / samples.max(1) as f64,
        })
    }
}

/// Samples of a photo in linear light at black or at the top (0 and 1: the codes 0 and the largest), and all its
/// samples.
fn clipped_samples(r: &Raster) -> (usize, usize) {
    let at_limit = r.data.iter().filter(|&&v| v <= 0.0 || v >= 1.0).count();
    (at_limit, r.data.len())
}

/// Score each `(label, folder)` of photos. `truth` is a simulated dive folder (or its `truth/dive.json`);
/// `placements` a placement file (default with a truth: the simulator's poses).
pub fn evaluate(
    sets: &[(String, PathBuf)],
    truth: Option<&Path>,
    placements: Option<&Path>,
    settings: &EvalSettings,
) -> Result<Evaluation> {
    settings.validate()?;
    if sets.is_empty() {
        return Err(Error::Usage(
            "give at least one folder of photos to evaluate".into(),
        ));
    }
    let truth_path = truth.map(truth_file);
    let truth = truth_path.as_deref().map(load_truth).transpose()?;
    let (placed, registration) = resolve_placements(placements, settings, truth.as_ref())?;
    if truth.is_none() && placed.is_none() {
        return Err(Error::Usage(
            "nothing to score against: give --truth (a simulated dive), --placements FILE or --register RAW_DIR"
                .into(),
        ));
    }
    let transfer = settings
        .transfer
        .or(truth.as_ref().map(|t| t.settings.encode))
        .unwrap_or_default();
    let names: Vec<String> = match (&truth, &placed) {
        (Some(t), _) => t.poses.iter().map(|p| p.file.clone()).collect(),
        (None, Some(p)) => p.iter().map(|p| p.name.clone()).collect(),
        (None, None) => unreachable!(),
    };
    let albedo: Option<Vec<Raster>> = match (&truth, &truth_path) {
        (Some(_), Some(tp)) => {
            let dir = tp.parent().unwrap_or(Path::new(".")).join("albedo");
            Some(
                names
                    .par_iter()
                    .map(|n| load_linear(&dir.join(n), Transfer::Linear))
                    .collect::<Result<_>>()?,
            )
        }
        _ => None,
    };
    let mask = settings.mask.as_deref().map(Mask::load).transpose()?;
    let set = ScoreSet {
        names: &names,
        albedo: albedo.as_deref(),
        placed: placed.as_deref(),
        transfer,
        mask: mask.as_ref().zip(settings.mask.as_deref()),
    };
    let mut scores = Vec::new();
    for (label, folder) in sets {
        scores.push(set.score(label, folder, settings)?);
    }
    Ok(Evaluation {
        truth: truth_path,
        placements: placements
            .map(Path::to_owned)
            .or(settings.save_placements.clone()),
        transfer,
        registration,
        settings: settings.clone(),
        sets: scores,
        warnings: transfer_warnings(sets, transfer),
    })
}

impl Evaluation {
    /// A Markdown table of the scores (lower is better everywhere).
    pub fn table(&self) -> String {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
        let mut s = String::from(
            "| method | photos | albedo error | residual pattern | consistency | overlap difference | clipped |\n\
             |---|---:|---:|---:|---:|---:|---:|\n",
        );
        for r in &self.sets {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {:.1} % |\n",
                r.label,
                r.photos,
                f(r.albedo_error),
                f(r.residual_pattern),
                f(r.consistency),
                f(r.overlap_difference),
                100.0 * r.clipped
            ));
        }
        s
    }

    /// What each score of [`Evaluation::table`] means, one line each, for the columns that have values.
    pub fn legend(&self) -> Vec<String> {
        type Column = (fn(&Scores) -> Option<f64>, &'static str);
        let columns: [Column; 4] = [
            (
                |s| s.albedo_error,
                "albedo error: mean difference from the true seafloor after one scale per \
                colour channel, as a share of it (0.05: 5 %)",
            ),
            (
                |s| s.residual_pattern,
                "residual pattern: lighting left in the photos, the spread of corrected / \
                true over an 8x6 grid of the frame (0.05: 5 % brighter or darker in places)",
            ),
            (
                |s| s.consistency,
                "consistency: RMS difference where photos overlap in the mosaic, as a share of \
                the photos' contrast (their standard deviation)",
            ),
            (
                |s| s.overlap_difference,
                "overlap difference: the same RMS difference as a share of the photos' \
                mean level (0.10: 10 % of the seafloor's brightness)",
            ),
        ];
        let has = |f: fn(&Scores) -> Option<f64>| self.sets.iter().any(|s| f(s).is_some());
        let mut lines = vec!["lower is better for every score; 0 is perfect".to_string()];
        lines.extend(
            columns
                .iter()
                .filter(|(f, _)| has(*f))
                .map(|(_, m)| m.to_string()),
        );
        lines.push(
            "clipped: samples at black or white; photos clipped at the same place agree whatever \
            lies there, which flatters the consistency and the overlap difference"
                .to_string(),
        );
        lines
    }

    /// Write the evaluation as JSON (atomically).
    pub fn save_json(&self, path: &Path) -> Result<()> {
        crate::io::write_with(path, |w| {
            serde_json::to_writer_pretty(w, self).map_err(|e| Error::Encode {
                path: path.to_owned(),
                reason: e.to_string(),
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ID: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

    /// A folder with a run report whose `options.transfer` is `given` and `transfer_assumed` is `assumed`.
    fn run_folder(root: &Path, name: &str, given: &str, assumed: Option<&str>) -> PathBuf {
        let dir = root.join(name);
        std::fs::create_dir_all(dir.join(crate::io::WORK_DIR)).unwrap();
        let report = serde_json::json!({
            "options": { "transfer": given },
            "transfer_assumed": assumed,
        });
        std::fs::write(
            dir.join(crate::io::WORK_DIR).join("report.json"),
            report.to_string(),
        )
        .unwrap();
        dir
    }

    #[test]
    fn the_curve_of_a_run_is_read_from_its_report_and_another_one_warned_of() {
        let d = tempfile::tempdir().unwrap();
        let srgb = run_folder(d.path(), "a", "srgb", None);
        let gamma = run_folder(d.path(), "b", "auto", Some("gamma:2.2: what the file says"));
        let unknown = run_folder(d.path(), "c", "auto", None);
        assert_eq!(run_transfer(&srgb), Some(Transfer::Srgb));
        assert_eq!(run_transfer(&gamma), Some(Transfer::Gamma(2.2)));
        assert_eq!(run_transfer(&unknown), None);
        assert_eq!(run_transfer(d.path()), None, "no report");
        let sets: Vec<(String, PathBuf)> = [("a", &srgb), ("b", &gamma), ("c", &unknown)]
            .iter()
            .map(|(l, p)| (l.to_string(), p.to_path_buf()))
            .collect();
        let w = transfer_warnings(&sets, Transfer::Srgb);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with("b: ") && w[0].contains("--transfer gamma:2.2"),
            "{w:?}"
        );
        assert_eq!(transfer_warnings(&sets, Transfer::Linear).len(), 2);
    }

    #[test]
    fn the_legend_explains_the_columns_that_have_scores() {
        let scores = |consistency: Option<f64>, albedo: Option<f64>| Scores {
            label: "x".into(),
            folder: PathBuf::new(),
            photos: 1,
            albedo_error: albedo,
            residual_pattern: albedo,
            consistency,
            overlap_difference: consistency,
            clipped: 0.0,
        };
        let ev = |sets| Evaluation {
            truth: None,
            placements: None,
            registration: None,
            transfer: Transfer::Linear,
            settings: EvalSettings::default(),
            sets,
            warnings: Vec::new(),
        };
        let only_overlaps = ev(vec![scores(Some(0.1), None)]).legend();
        assert_eq!(only_overlaps.len(), 4, "{only_overlaps:?}");
        assert!(only_overlaps[1].starts_with("consistency: "));
        assert!(only_overlaps[2].starts_with("overlap difference: "));
        assert!(only_overlaps[3].starts_with("clipped: "));
        let all = ev(vec![scores(None, Some(0.1)), scores(Some(0.1), None)]).legend();
        let names: Vec<&str> = all[1..]
            .iter()
            .filter_map(|l| l.split(':').next())
            .collect();
        assert_eq!(
            names,
            [
                "albedo error",
                "residual pattern",
                "consistency",
                "overlap difference",
                "clipped"
            ]
        );
    }

    #[test]
    fn clipped_samples_are_those_at_black_or_white() {
        // Codes 0, 1, 254 and 255 of an 8-bit photo in each curve: the first and the last are clipped.
        for transfer in [Transfer::Linear, Transfer::Srgb] {
            let photo = crate::method::raster::Photo {
                layout: crate::method::raster::Layout {
                    width: 4,
                    height: 1,
                    channels: 1,
                },
                samples: crate::method::raster::Samples::U8(vec![0, 1, 254, 255]),
                alpha: None,
            };
            let r = Raster::from_photo_linear(&photo, transfer);
            assert_eq!(clipped_samples(&r), (2, 4), "{transfer:?}: {:?}", r.data);
        }
    }

    #[test]
    fn placement_file_formats_and_errors() {
        let p = std::path::Path::new("placements.txt");
        let v = parse_placements(
            "# comment\nimg1.png 10 -5\n\nimg2.png 1 0 3 0 1 4 0 0 1  # homography\n",
            p,
        )
        .unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!(v[0].h, [1.0, 0.0, 10.0, 0.0, 1.0, -5.0, 0.0, 0.0, 1.0]);
        assert_eq!(v[1].h, [1.0, 0.0, 3.0, 0.0, 1.0, 4.0, 0.0, 0.0, 1.0]);
        for bad in ["img 1 2 3", "img a b", "img 0 0 0 0 0 0 0 0 0", ""] {
            let e = parse_placements(bad, p).unwrap_err().to_string();
            assert!(e.contains("placements.txt"), "{bad:?}: {e}");
        }
    }

    #[test]
    fn overlap_difference_by_hand() {
        // Two constant photos on the same place: RMS difference 0.1, standard deviation 0.1, mean 0.3.
        let a = Raster::filled(16, 16, 3, 0.2);
        let b = Raster::filled(16, 16, 3, 0.4);
        let (c, d) = consistency_parts(&[a, b], &[ID; 2], 4.0).unwrap();
        assert!((c - 1.0).abs() < 1e-6, "{c}");
        assert!((d - 0.1 / 0.3).abs() < 1e-6, "{d}");
    }

    /// Two photos of the same seafloor 8 pixels apart, one with a laser dot: the dot alone makes them differ; with
    /// the dot's pixels left out (`--mask`) they agree exactly, and the score equals that of the photos without
    /// the dot and without the masked pixels' cells, computed directly.
    #[test]
    fn masked_pixels_are_left_out_of_the_overlap_difference() {
        let floor = |x: usize, y: usize| 0.3 + 0.1 * (((x * 7 + y * 3) % 11) as f32 / 11.0);
        let a = Raster::from_fn(40, 24, 3, |x, y, _| floor(x, y));
        let mut b = Raster::from_fn(40, 24, 3, |x, y, _| floor(x + 8, y));
        let dot = |x: usize, y: usize| x.abs_diff(20) <= 2 && y.abs_diff(12) <= 2;
        for y in 0..24 {
            for x in 0..40 {
                if dot(x, y) {
                    b.data[(y * 40 + x) * 3] = 1.0;
                }
            }
        }
        let h = [ID, [1.0, 0.0, 8.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]];
        let (_, with_dot) = consistency_parts(&[a.clone(), b.clone()], &h, 4.0).unwrap();
        assert!(with_dot > 0.01, "{with_dot}");
        let mut mask = Mask::empty(40, 24);
        for y in 0..24 {
            for x in 0..40 {
                mask.ignore[y * 40 + x] = dot(x, y);
            }
        }
        let (mut ma, mut mb) = (a.clone(), b.clone());
        leave_out(&mut ma, &mask, Path::new("m.png")).unwrap();
        leave_out(&mut mb, &mask, Path::new("m.png")).unwrap();
        let (_, masked) = consistency_parts(&[ma, mb], &h, 4.0).unwrap();
        assert!(masked.abs() < 1e-9, "{masked}");
        // The cells left are still compared: the second photo made 10 % brighter outside the dot differs again.
        let mut brighter = b.clone();
        for v in &mut brighter.data {
            *v *= 1.1;
        }
        leave_out(&mut brighter, &mask, Path::new("m.png")).unwrap();
        let mut ma = a.clone();
        leave_out(&mut ma, &mask, Path::new("m.png")).unwrap();
        assert!(consistency_parts(&[ma, brighter], &h, 4.0).unwrap().1 > 0.02);
        // A mask of another size names itself.
        let err = leave_out(&mut a.clone(), &Mask::empty(8, 8), Path::new("m.png")).unwrap_err();
        assert!(err.to_string().contains("m.png"), "{err}");
    }

    /// The sums over the cells add up in one order on every call, so the scores are the same to the last bit
    /// (before, the cells were summed in a hash map's order, which changes from map to map, and the last bits
    /// with it).
    #[test]
    fn consistency_is_the_same_to_the_last_bit_on_every_call() {
        // Three textured photos 5 pixels apart, of other brightness: hundreds of overlapping cells whose squared
        // differences differ in size, so that another order of the sum rounds differently.
        let photo = |x0: usize, k: f32| {
            Raster::from_fn(64, 48, 3, move |x, y, c| {
                0.1 + k * (((x + x0) * 7 + y * 13 + c * 5) % 23) as f32 / 23.0
            })
        };
        let photos = [photo(0, 1.0), photo(5, 1.07), photo(10, 0.93)];
        let shift = |dx: f64| [1.0, 0.0, dx, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let h = [ID, shift(5.0), shift(10.0)];
        let bits = |(c, d): (f64, f64)| (c.to_bits(), d.to_bits());
        let first = bits(consistency_parts(&photos, &h, 2.0).unwrap());
        for _ in 0..20 {
            assert_eq!(bits(consistency_parts(&photos, &h, 2.0).unwrap()), first);
        }
    }

    #[test]
    fn reduced_photos_with_scaled_placements_score_like_full_ones() {
        // A horizontal ramp seen by two photos 8 pixels apart, one of them 10 % brighter.
        let ramp =
            |x0: usize, k: f32| Raster::from_fn(32, 16, 1, move |x, _, _| k * (x + x0) as f32);
        let (a, b) = (ramp(0, 1.0), ramp(8, 1.1));
        let h = [ID, [1.0, 0.0, 8.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]];
        let full = consistency_parts(&[a.clone(), b.clone()], &h, 4.0).unwrap();
        let (ra, rb) = (reduce(&a, 2), reduce(&b, 2));
        assert_eq!((ra.width, ra.height), (16, 8));
        // Box average by hand: pixels 0 and 1 of row 0.
        assert_eq!(ra.get(0, 0, 0), 0.5);
        let hs = [scale_h(&h[0], 2), scale_h(&h[1], 2)];
        let small = consistency_parts(&[ra, rb], &hs, 4.0).unwrap();
        // A linear ramp is reproduced exactly by the box average and bilinear sampling inside the photo.
        assert!(
            (full.1 - small.1).abs() < 0.02 * full.1,
            "{full:?} {small:?}"
        );
    }
}

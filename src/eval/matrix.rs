//! The dive matrix of issue 12 (docs/evaluation.md, `examples/dive_matrix.rs`): twelve abyssal dives (light rigs,
//! beams, waters, altitudes, contamination, 8/16-bit, linear/sRGB, PNG/JPEG) that the example scores every method
//! on, and the tests and the demo render from the same table.

use std::path::Path;

use crate::eval::evaluate::{leave_out, load_linear};
use crate::eval::simulate::{Dive, Exposure, Rig, Simulation, Water};
use crate::io::{decode, find_photos, write_atomic, EncodeSettings};
use crate::method::factor::upsample;
use crate::method::mask::Mask;
use crate::method::median::{median_of_f32, stack_quantile};
use crate::method::raster::Raster;
use crate::method::transfer::Transfer;
use crate::method::window::window_range;

/// One dive of the matrix: its light rig, water, altitude, contamination and how the camera stores it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiveSpec {
    /// Its name in the tables (`a01` … `a12`).
    pub name: &'static str,
    /// Light rig.
    pub rig: Rig,
    /// Beam width of the lights, degrees.
    pub beam: f32,
    /// Water preset ([`Water::preset`]).
    pub water: &'static str,
    /// Mean altitude, metres.
    pub altitude: f32,
    /// Altitude swing, metres.
    pub swing: f32,
    /// Share of the seafloor covered by nodules.
    pub contamination: f64,
    /// Bits per stored sample (8 or 16).
    pub bits: u32,
    /// Stored sRGB-encoded (otherwise linear).
    pub srgb: bool,
    /// Saved as JPEG (quality 92) by the matrix.
    pub jpeg: bool,
    /// Horizontal field of view, degrees.
    pub fov: f32,
    /// Share of a photo's along-track extent the next photo sees (0.6 for the twelve; 0.9: a slow sledge).
    pub overlap: f32,
    /// Survey photos.
    pub frames: usize,
    /// Coverage at the first, middle and last photo instead of one ([`Simulation::contamination_along`]).
    pub along: Option<[f64; 3]>,
    /// The coverage is given to every method (`--contamination`, as for the twelve); `false` for the nodule
    /// fields, corrected as a user would, at default options.
    pub told: bool,
}

#[allow(clippy::too_many_arguments)]
const fn d(
    name: &'static str,
    rig: Rig,
    beam: f32,
    water: &'static str,
    altitude: f32,
    swing: f32,
    contamination: f64,
    bits: u32,
    srgb: bool,
    jpeg: bool,
    fov: f32,
) -> DiveSpec {
    DiveSpec {
        name,
        rig,
        beam,
        water,
        altitude,
        swing,
        contamination,
        bits,
        srgb,
        jpeg,
        fov,
        overlap: 0.6,
        frames: 30,
        along: None,
        told: true,
    }
}

/// A nodule field ([`NODULES`]): 40 photos at overlap `overlap`, coverage `c` (or `along` the track), not told.
#[allow(clippy::too_many_arguments)]
const fn n(
    name: &'static str,
    rig: Rig,
    beam: f32,
    water: &'static str,
    altitude: f32,
    swing: f32,
    c: f64,
    along: Option<[f64; 3]>,
    bits: u32,
    srgb: bool,
    jpeg: bool,
    overlap: f32,
) -> DiveSpec {
    DiveSpec {
        overlap,
        frames: 40,
        along,
        told: false,
        ..d(
            name, rig, beam, water, altitude, swing, c, bits, srgb, jpeg, 80.0,
        )
    }
}

/// Coverage along the patchy dives' tracks: bare sediment, a dense field, a sparse one.
const PATCHY: Option<[f64; 3]> = Some([0.02, 0.45, 0.15]);

#[rustfmt::skip]
/// Nodule fields (docs/nodules.md): 30–50 % of the seafloor covered, one dive per rig patchy along the track,
/// slow (overlap 0.9, a sledge) and fast (0.6) tracks, 40 photos each, corrected at default options (the coverage
/// is not given). `dive_matrix --nodules` scores them; the window's choice was tuned on these.
pub const NODULES: &[DiveSpec] = &[
    //  name     rig        beam  water          alt  swing  c     along   bits srgb   jpeg   overlap
    n("n01", Rig::Two,   36.0, "oceanic-i",   5.0, 0.3, 0.30, None,   8,  true,  false, 0.6),
    n("n02", Rig::Three, 30.0, "oceanic-iii", 4.5, 0.2, 0.40, None,   16, false, false, 0.9),
    n("n03", Rig::Four,  36.0, "oceanic-i",   6.0, 0.4, 0.50, None,   8,  true,  true,  0.6),
    n("n04", Rig::Aft,   36.0, "oceanic-i",   5.0, 0.3, 0.45, PATCHY, 8,  true,  false, 0.9),
    n("n05", Rig::Two,   30.0, "oceanic-iii", 5.5, 0.3, 0.50, None,   16, false, false, 0.9),
    n("n06", Rig::Three, 36.0, "oceanic-i",   5.0, 0.4, 0.45, PATCHY, 8,  true,  false, 0.6),
    n("n07", Rig::Four,  30.0, "oceanic-i",   4.5, 0.2, 0.30, None,   8,  true,  false, 0.9),
    n("n08", Rig::Aft,   36.0, "oceanic-iii", 6.0, 0.5, 0.40, None,   8,  true,  true,  0.6),
];

#[rustfmt::skip]
/// Held-out nodule fields: other coverages (33–48 %, another patchy profile; 50 % under the rigs the tuning fields
/// have at 30–45 % only), seeds and rig/track pairings than [`NODULES`], never used to choose anything
/// (`dive_matrix --nodules --held-out`).
pub const NODULES_HELD_OUT: &[DiveSpec] = &[
    //  name     rig        beam  water          alt  swing  c     along   bits srgb   jpeg   overlap
    n("g01", Rig::Three, 36.0, "oceanic-i",   5.0, 0.3, 0.35, None,   8,  true,  false, 0.9),
    n("g02", Rig::Aft,   30.0, "oceanic-iii", 5.5, 0.4, 0.45, None,   16, false, false, 0.6),
    n("g03", Rig::Two,   36.0, "oceanic-i",   4.5, 0.3, 0.48, Some([0.05, 0.48, 0.2]), 8, true, false, 0.9),
    n("g04", Rig::Four,  32.0, "oceanic-iii", 5.0, 0.2, 0.45, None,   8,  true,  true,  0.9),
    n("g05", Rig::Two,   36.0, "oceanic-i",   6.0, 0.5, 0.33, None,   8,  true,  false, 0.6),
    n("g06", Rig::Aft,   36.0, "oceanic-i",   4.5, 0.3, 0.38, None,   16, true,  false, 0.9),
    n("g07", Rig::Aft,   34.0, "oceanic-iii", 5.0, 0.4, 0.50, None,   8,  true,  true,  0.9),
    n("g08", Rig::Three, 32.0, "oceanic-i",   5.5, 0.3, 0.50, None,   16, false, false, 0.6),
];

#[rustfmt::skip]
/// Dives whose altitude swings (a towed sledge, an ROV over rough ground): ± 20–40 % of the altitude, 0–50 % nodule
/// cover, every rig, 40 photos each at default options (the coverage not given). `dive_matrix --swings` scores
/// them; with `--held-out` [`SWINGS_HELD_OUT`]. Measured, not tuned on (docs/results.md).
pub const SWINGS: &[DiveSpec] = &[
    //  name     rig        beam  water          alt  swing  c     along   bits srgb   jpeg   overlap
    n("s01", Rig::Two,   36.0, "oceanic-i",   4.0, 1.6, 0.25, None,   8,  true,  false, 0.6),
    n("s02", Rig::Three, 30.0, "oceanic-iii", 5.0, 1.5, 0.00, None,   8,  true,  true,  0.6),
    n("s03", Rig::Four,  36.0, "oceanic-i",   4.5, 1.0, 0.45, None,   16, false, false, 0.9),
    n("s04", Rig::Aft,   36.0, "coastal",     5.0, 2.0, 0.15, None,   8,  true,  false, 0.6),
    n("s05", Rig::Two,   28.0, "oceanic-i",   6.0, 1.8, 0.35, None,   8,  true,  true,  0.9),
    n("s06", Rig::Three, 36.0, "oceanic-i",   4.0, 1.2, 0.50, None,   8,  true,  false, 0.6),
];

#[rustfmt::skip]
/// Held-out altitude-swing dives: other rigs, covers and swings than [`SWINGS`], their own seeds.
pub const SWINGS_HELD_OUT: &[DiveSpec] = &[
    //  name     rig        beam  water          alt  swing  c     along   bits srgb   jpeg   overlap
    n("t01", Rig::Four,  30.0, "oceanic-iii", 5.5, 2.2, 0.20, None,   8,  true,  false, 0.6),
    n("t02", Rig::Aft,   32.0, "oceanic-i",   4.0, 1.4, 0.40, None,   16, true,  false, 0.9),
    n("t03", Rig::Two,   36.0, "oceanic-i",   5.0, 1.0, 0.05, None,   8,  true,  true,  0.6),
    n("t04", Rig::Three, 25.0, "coastal",     4.5, 1.8, 0.30, PATCHY, 8,  true,  false, 0.6),
];

/// The seed of the `index`-th altitude-swing dive ([`SWINGS`]) in seed set `offset`.
pub fn swing_seed(index: usize, offset: u64) -> u64 {
    9000 + offset * 100 + index as u64
}

/// The seed of the `index`-th held-out altitude-swing dive ([`SWINGS_HELD_OUT`]) in seed set `offset`.
pub fn swing_held_out_seed(index: usize, offset: u64) -> u64 {
    9500 + offset * 100 + index as u64
}

#[rustfmt::skip]
/// The twelve dives (docs/evaluation.md, "The dive matrix").
pub const DIVES: &[DiveSpec] = &[
    //  name     rig        beam  water          alt  swing  c     bits srgb   jpeg   fov
    d("a01", Rig::Three, 36.0, "oceanic-i",   5.0, 0.3, 0.10, 8,  true,  false, 90.0),
    d("a02", Rig::Aft,   36.0, "oceanic-i",   6.0, 0.6, 0.20, 16, false, false, 80.0),
    d("a03", Rig::Two,   36.0, "oceanic-iii", 4.0, 0.2, 0.35, 8,  true,  true,  75.0),
    d("a04", Rig::Four,  36.0, "coastal",     4.5, 0.5, 0.25, 16, false, false, 85.0),
    d("a05", Rig::Three, 25.0, "oceanic-i",   5.0, 0.4, 0.15, 8,  true,  false, 80.0),
    d("a06", Rig::Aft,   36.0, "oceanic-iii", 7.0, 0.6, 0.30, 8,  true,  true,  90.0),
    d("a07", Rig::Two,   25.0, "coastal",     5.5, 0.3, 0.20, 16, true,  false, 75.0),
    d("a08", Rig::Four,  36.0, "oceanic-i",   6.5, 0.0, 0.10, 8,  false, false, 90.0),
    d("a09", Rig::Three, 36.0, "oceanic-iii", 4.0, 0.6, 0.35, 8,  true,  true,  80.0),
    d("a10", Rig::Aft,   30.0, "oceanic-i",   5.0, 0.5, 0.25, 16, false, false, 85.0),
    d("a11", Rig::Two,   36.0, "oceanic-i",   7.0, 0.2, 0.30, 8,  true,  false, 90.0),
    d("a12", Rig::Four,  28.0, "oceanic-iii", 5.0, 0.4, 0.15, 8,  true,  true,  80.0),
];

#[rustfmt::skip]
/// Eight held-out dives (docs/evaluation.md, "Held-out dives"): outside the twelve's ranges on purpose — narrower
/// beams (20–25°), farther (7.5–8 m) or lower (3.5 m), larger swings (0.8 m), narrower fields of view (60–70°), 8-bit
/// linear coastal photos — and never used to choose a default. `dive_matrix --held-out` scores them.
pub const HELD_OUT: &[DiveSpec] = &[
    //  name     rig        beam  water          alt  swing  c     bits srgb   jpeg   fov
    d("h01", Rig::Three, 20.0, "oceanic-i",   6.0, 0.4, 0.20, 8,  true,  true,  80.0),
    d("h02", Rig::Two,   30.0, "oceanic-iii", 8.0, 0.5, 0.25, 16, false, false, 90.0),
    d("h03", Rig::Four,  25.0, "coastal",     3.5, 0.3, 0.30, 8,  true,  false, 70.0),
    d("h04", Rig::Aft,   22.0, "oceanic-i",   7.5, 0.8, 0.15, 8,  true,  true,  85.0),
    d("h05", Rig::Three, 36.0, "oceanic-iii", 5.0, 0.2, 0.33, 16, true,  false, 60.0),
    d("h06", Rig::Two,   20.0, "coastal",     6.0, 0.6, 0.10, 8,  false, false, 90.0),
    d("h07", Rig::Four,  32.0, "oceanic-i",   8.0, 0.3, 0.20, 8,  true,  true,  90.0),
    d("h08", Rig::Aft,   28.0, "coastal",     4.0, 0.5, 0.30, 16, false, false, 75.0),
];

impl DiveSpec {
    /// The dive rendered with `seed` at `size` (width, height): its photos (30; 40 for a nodule field) at its overlap
    /// and 15 water-column frames, the camera's
    /// white balance from the two-way path (red capped at ×6) and the exposure from the brightest sediment;
    /// `jpeg` is left to the caller (the matrix saves the rendered PNGs as JPEGs).
    pub fn simulation(&self, seed: u64, size: (usize, usize)) -> Simulation {
        let water = Water::preset(self.water).expect("known water preset");
        // The camera's white balance makes the sediment grey at the centre: gains from the two-way path.
        let path = 2.0 * self.altitude;
        let eta = water.attenuation;
        let gain = |c: usize| ((eta[c] - eta[1]) * path).exp().clamp(0.2, 6.0);
        Simulation {
            frames: self.frames,
            overlap: self.overlap,
            contamination_along: self.along,
            water_column: 15,
            width: size.0,
            height: size.1,
            seed,
            contamination: self.contamination,
            bit_depth: self.bits,
            encode: if self.srgb {
                Transfer::Srgb
            } else {
                Transfer::Linear
            },
            rig: self.rig,
            altitude: self.altitude,
            fov_deg: self.fov,
            beam_deg: self.beam,
            water,
            altitude_swing: Some(self.swing),
            white_balance: [gain(0), 1.0, gain(2)],
            exposure: Exposure::Brightest,
            ..Simulation::default()
        }
    }
}

/// JPEG quality of the matrix's JPEG dives (the camera's own files).
pub const JPEG_QUALITY: u8 = 92;

/// The photos of `from` (a rendered dive's `survey` or `water` folder) saved as the camera of a JPEG dive would
/// have saved them: quality [`JPEG_QUALITY`], the same names with `.jpg`, into `to`.
pub fn save_as_jpeg(from: &Path, to: &Path) -> crate::Result<()> {
    let settings = EncodeSettings {
        jpeg_quality: JPEG_QUALITY,
        ..EncodeSettings::default()
    };
    for e in find_photos(from)?.photos {
        write_atomic(
            &decode(&e.path)?,
            &to.join(e.relative.with_extension("jpg")),
            settings,
        )?;
    }
    Ok(())
}

/// The dive of the matrix called `name` (`a01` … `a12`, or a held-out `h01` … `h08`).
pub fn dive(name: &str) -> Option<&'static DiveSpec> {
    dive_and_seed(name, 0).map(|(d, _)| d)
}

/// The dive called `name` and its seed in seed set `offset` ([`seed`] for the twelve, [`held_out_seed`] for the
/// held-out dives).
pub fn dive_and_seed(name: &str, offset: u64) -> Option<(&'static DiveSpec, u64)> {
    let find = |dives: &'static [DiveSpec]| dives.iter().enumerate().find(|(_, d)| d.name == name);
    find(DIVES)
        .map(|(i, d)| (d, seed(i, offset)))
        .or_else(|| find(HELD_OUT).map(|(i, d)| (d, held_out_seed(i, offset))))
        .or_else(|| find(NODULES).map(|(i, d)| (d, nodule_seed(i, offset))))
        .or_else(|| find(NODULES_HELD_OUT).map(|(i, d)| (d, nodule_held_out_seed(i, offset))))
        .or_else(|| find(SWINGS).map(|(i, d)| (d, swing_seed(i, offset))))
        .or_else(|| find(SWINGS_HELD_OUT).map(|(i, d)| (d, swing_held_out_seed(i, offset))))
}

/// The seed of the `index`-th nodule field ([`NODULES`]) in seed set `offset`.
pub fn nodule_seed(index: usize, offset: u64) -> u64 {
    7000 + offset * 100 + index as u64
}

/// The seed of the `index`-th held-out nodule field ([`NODULES_HELD_OUT`]) in seed set `offset`.
pub fn nodule_held_out_seed(index: usize, offset: u64) -> u64 {
    8000 + offset * 100 + index as u64
}

/// The seed of the matrix's `index`-th dive in seed set `offset` (0: the set the method was tuned on).
pub fn seed(index: usize, offset: u64) -> u64 {
    1000 + offset * 100 + index as u64
}

/// The seed of the `index`-th held-out dive in seed set `offset`: never one of [`seed`]'s.
pub fn held_out_seed(index: usize, offset: u64) -> u64 {
    5000 + offset * 100 + index as u64
}

/// The peers beside the project, as `../shared/peers/README.md` sets them up: the Python with numpy and OpenCV
/// (`PEER_PYTHON`, else `../peer-venv/bin/python`) and the folder of `paper_numpy.py`, `simdive.py` and
/// `evaluate_dive.py` (`../shared/peers`); `None` where either is missing.
pub fn peers() -> Option<(std::path::PathBuf, std::path::PathBuf)> {
    let python = std::env::var_os("PEER_PYTHON")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| "../peer-venv/bin/python".into());
    let dir = std::path::PathBuf::from("../shared/peers");
    (python.exists() && dir.join("paper_numpy.py").exists()).then_some((python, dir))
}

/// The photos `names` of `dir`, each in linear light; panics on a file that does not decode (the matrix wrote it).
pub fn load_set(dir: &Path, names: &[String], t: Transfer) -> Vec<Raster> {
    names
        .iter()
        .map(|n| {
            let p = dir.join(n);
            load_linear(&p, t).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        })
        .collect()
}

/// The oracle: `(I − S)/F` with the true lighting, in linear light (albedo units, clipped to `[0, 2.5]`), of the
/// photos every method was given (`raw`: on a JPEG dive the camera's JPEGs, not the rendering before it), of a dive rendered with
/// [`Simulation::render_with_lighting`] (its true `F` and `S`).
pub fn oracle(raw: &[Raster], dive: &Dive) -> Vec<Raster> {
    raw.iter()
        .zip(dive.factor.iter().zip(&dive.backscatter))
        .map(|(p, (f, s))| {
            let mut r = p.clone();
            for ((v, &f), &s) in r.data.iter_mut().zip(&f.data).zip(&s.data) {
                *v = ((*v - s) / f.max(1e-4)).clamp(0.0, 2.5);
            }
            r
        })
        .collect()
}

/// Where each survey photo carries the albedo at all: the true lit signal `F·A` is at least one code step of the
/// camera's encoding (`bits`, curve `t`) at the sample's level `F·A + S`, and that level is below clipping. The
/// residual pattern is scored on these samples only, for every method alike: where a starved channel (red over
/// metres of coastal water) is below one code step, no method can recover it and none should be scored on it.
pub fn signal_mask(dive: &Dive, t: Transfer, bits: u32) -> Vec<Vec<bool>> {
    let q = 1.0 / ((1u32 << bits) - 1) as f32;
    dive.albedo
        .iter()
        .zip(dive.factor.iter().zip(&dive.backscatter))
        .map(|(a, (f, s))| {
            a.data
                .iter()
                .zip(f.data.iter().zip(&s.data))
                .map(|(&a, (&f, &s))| {
                    let lit = a * f;
                    let v = t.from_linear((lit + s).min(1.0));
                    let step = t.to_linear((v + q).min(1.0)) - t.to_linear(v);
                    lit + s < 1.0 && lit >= step
                })
                .collect()
        })
        .collect()
}

/// Share of a photo's brightest light (the true `F`, mean over the channels) below which a pixel is unlit for
/// [`lit_mask`].
pub const LIT_SHARE: f32 = 0.02;

/// Where each survey photo is lit at all: its true `F`, the mean over the channels, at least [`LIT_SHARE`] of that
/// photo's largest. Outside it (the corners a narrow beam misses, the side an aft rig's backscatter fills) the
/// photos hold noise and backscatter only: every method fills or clips them, and overlapping photos disagree
/// there whatever the method did where the lights reach. The dive matrix scores the overlaps on these pixels too
/// (`where lit`), beside every pixel.
pub fn lit_mask(dive: &Dive) -> Vec<Vec<bool>> {
    dive.factor
        .iter()
        .map(|f| {
            let c = f.channels;
            let light: Vec<f32> = f
                .data
                .chunks_exact(c)
                .map(|px| px.iter().sum::<f32>() / c as f32)
                .collect();
            let top = light.iter().copied().fold(0.0f32, f32::max);
            light.iter().map(|&l| l >= LIT_SHARE * top).collect()
        })
        .collect()
}

/// `photos` with the pixels `lit` leaves out set to NaN in every channel (one mask per photo, one flag per
/// pixel), as `evaluate --mask` leaves a mask's pixels out: the consistency metric leaves out every cell
/// observation that touches one.
pub fn only_lit(photos: &[Raster], lit: &[Vec<bool>]) -> Vec<Raster> {
    assert_eq!(photos.len(), lit.len(), "one lit mask per photo");
    photos
        .iter()
        .zip(lit)
        .map(|(p, on)| {
            let mask = Mask {
                width: p.width,
                height: p.height,
                ignore: on.iter().map(|&b| !b).collect(),
            };
            let mut p = p.clone();
            leave_out(&mut p, &mask, Path::new("the lit mask"))
                .expect("a lit mask of the photo's size");
            p
        })
        .collect()
}

/// The window method's floor on a dive (the `window-floor` column of `examples/dive_matrix.rs`): its `M` made from
/// the photos' true albedo alone (no lights, water or noise) — the
/// per-block medians of each photo's albedo, the `(1 + c)/2` quantile over the photos of its window, upsampled
/// as the correction upsamples `F` — and each photo's albedo divided by it. What this leaves is the part of the
/// seafloor that a window over a straight track takes into `F`, whatever the lights do: the mean albedo of the
/// strip each image column sees (the paper's stated limit, "a seafloor colour change is absorbed into F"), the
/// nodule field's density along it, and the blocks' coarseness. A method that estimates `F` from the photos has
/// this in its residual pattern as well; the oracle, which is given `F`, does not.
pub fn window_floor(albedo: &[Raster], window: usize, q: f64, block: usize) -> Vec<Raster> {
    let lows: Vec<Raster> = albedo.iter().map(|a| block_median_f32(a, block)).collect();
    let total = lows.len();
    albedo
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let stack: Vec<&Raster> = lows[window_range(i, window, total)].iter().collect();
            let m = upsample(&stack_quantile(&stack, q), block, a.width, a.height);
            let mut r = a.clone();
            for (v, &m) in r.data.iter_mut().zip(&m.data) {
                *v = (*v / m.max(1e-4)).clamp(0.0, 2.5);
            }
            r
        })
        .collect()
}

/// Per-channel median of every `k`×`k` block of a float raster (partial blocks at the border included), as the
/// method's block median does on photo codes.
pub fn block_median_f32(r: &Raster, k: usize) -> Raster {
    let (bw, bh, c) = (r.width.div_ceil(k), r.height.div_ceil(k), r.channels);
    let mut v = Vec::with_capacity(k * k);
    Raster::from_fn(bw, bh, c, |bx, by, ch| {
        v.clear();
        for y in by * k..((by + 1) * k).min(r.height) {
            for x in bx * k..((bx + 1) * k).min(r.width) {
                v.push(r.get(x, y, ch));
            }
        }
        median_of_f32(&mut v)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` photos of `w`×`h` whose albedo is `f(photo, x, y)` in every channel.
    fn photos(n: usize, w: usize, h: usize, f: impl Fn(usize, usize, usize) -> f32) -> Vec<Raster> {
        (0..n)
            .map(|i| Raster::from_fn(w, h, 3, |x, y, _| f(i, x, y)))
            .collect()
    }

    #[test]
    fn block_median_f32_matches_brute_force() {
        // 10×7 with blocks of 3: partial blocks at the right and the bottom.
        let r = Raster::from_fn(10, 7, 3, |x, y, c| {
            ((x * 37 + y * 11 + c * 5) % 17) as f32 / 16.0
        });
        let low = block_median_f32(&r, 3);
        let samples: Vec<f64> = r.data.iter().map(|&v| v as f64).collect();
        let want = crate::method::median::reference::block_median(&samples, 10, 7, 3, 3, 1.0);
        assert_eq!((low.width, low.height), (4, 3));
        for (a, b) in low.data.iter().zip(&want) {
            assert!((*a as f64 - b).abs() < 1e-6, "{a} vs {b}");
        }
    }

    #[test]
    fn window_floor_is_one_on_a_uniform_seafloor_and_outvotes_a_nodule() {
        // A nodule (albedo 0.05 on 0.3) over one block of photo 1 only: in the windows of the other photos it is
        // one sample of five and the median outvotes it; photo 1 itself keeps it, darker by the nodule's contrast.
        let nodule = |i: usize, x: usize, y: usize| {
            if i == 1 && (8..12).contains(&x) && (4..8).contains(&y) {
                0.05
            } else {
                0.3
            }
        };
        let a = photos(9, 20, 16, nodule);
        let out = window_floor(&a, 5, 0.5, 4);
        for (i, o) in out.iter().enumerate() {
            for y in 0..16 {
                for x in 0..20 {
                    let want = nodule(i, x, y) / 0.3;
                    assert!((o.get(x, y, 1) - want).abs() < 1e-5, "photo {i} ({x}, {y})");
                }
            }
        }
        // The window and its quantile count: at q = 0 the nodule is the window's `M` wherever the window holds
        // photo 1 (photos 0 to 3: windows 0..5, 0..5, 0..5, 1..6) and the seafloor around comes out bright; photo
        // 4's window is 2..7, without it.
        let low = window_floor(&a, 5, 0.0, 4);
        for i in [0, 2, 3] {
            assert!(
                low[i].get(9, 5, 0) > 2.0,
                "photo {i}: {}",
                low[i].get(9, 5, 0)
            );
        }
        assert!(
            low[1].get(9, 5, 0) < 1.0,
            "photo 1's own nodule stays darker than its window"
        );
        assert!((low[4].get(9, 5, 0) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn window_floor_takes_a_strip_seen_in_every_photo_into_f() {
        // The seafloor brightens from left to right in every photo (a straight track over a strip): the window's
        // `M` holds the same ramp, so the floor's output is flat — the ramp is gone from the "corrected" photo and
        // is left as residual pattern against the truth, which is what the column measures.
        let ramp = |_: usize, x: usize, _: usize| 0.2 + 0.01 * x as f32;
        let a = photos(9, 32, 16, ramp);
        let out = window_floor(&a, 7, 0.6, 4);
        // Between the first and the last block centre (x = 1.5 … 29.5) bilinear interpolation of the block
        // medians (each the ramp at its block's centre) is the ramp itself.
        for o in &out {
            for y in 0..16 {
                for x in 2..30 {
                    assert!(
                        (o.get(x, y, 2) - 1.0).abs() < 1e-4,
                        "({x}, {y}): {}",
                        o.get(x, y, 2)
                    );
                }
            }
        }
        let pattern = crate::eval::evaluate::residual_pattern(&out, &a, (8, 2), None);
        assert!(pattern > 0.1, "the strip is left as pattern: {pattern}");
    }

    #[test]
    fn held_out_dives_are_not_the_matrix_and_use_other_seeds() {
        for h in HELD_OUT {
            assert!(DIVES.iter().all(|d| d.name != h.name), "{}", h.name);
            assert_eq!(dive(h.name), Some(h));
            let i = HELD_OUT.iter().position(|d| d == h).unwrap();
            assert_eq!(dive_and_seed(h.name, 2), Some((h, held_out_seed(i, 2))));
            // Not a copy of a matrix dive under another name.
            assert!(DIVES.iter().all(|d| DiveSpec { name: h.name, ..*d } != *h));
        }
        // Nodule fields: their own names and seeds, the held-out ones never a tuned one's.
        for (i, d) in NODULES.iter().enumerate() {
            assert_eq!(dive_and_seed(d.name, 1), Some((d, nodule_seed(i, 1))));
            assert!(!d.told && d.frames == 40);
        }
        for (i, d) in NODULES_HELD_OUT.iter().enumerate() {
            assert_eq!(
                dive_and_seed(d.name, 0),
                Some((d, nodule_held_out_seed(i, 0)))
            );
            assert!(NODULES.iter().all(|t| t.name != d.name));
            for o in 0..10 {
                assert!((0..NODULES.len()).all(|j| nodule_seed(j, o) != nodule_held_out_seed(i, o)));
            }
        }
        // Altitude swings: their own names and seeds.
        for (i, d) in SWINGS.iter().enumerate() {
            assert_eq!(dive_and_seed(d.name, 1), Some((d, swing_seed(i, 1))));
        }
        for (i, d) in SWINGS_HELD_OUT.iter().enumerate() {
            assert_eq!(
                dive_and_seed(d.name, 0),
                Some((d, swing_held_out_seed(i, 0)))
            );
            assert!(SWINGS.iter().all(|t| t.name != d.name));
        }
        assert_eq!(dive_and_seed("a03", 1), Some((&DIVES[2], seed(2, 1))));
        assert_eq!(dive_and_seed("x01", 0), None);
        let tuned: Vec<u64> = (0..10)
            .flat_map(|o| (0..DIVES.len()).map(move |i| seed(i, o)))
            .collect();
        for o in 0..10 {
            for i in 0..HELD_OUT.len() {
                assert!(!tuned.contains(&held_out_seed(i, o)));
            }
        }
    }

    /// A narrow cone lights the centre of a simulated dive and not its corners: the lit mask holds the centre and
    /// leaves the corners out, and the pixels it leaves out are NaN after `only_lit`, the others untouched.
    #[test]
    fn the_lit_mask_follows_the_true_light() {
        let (spec, seed) = dive_and_seed("g02", 0).unwrap();
        let sim = spec.simulation(seed, (160, 120));
        let dive = sim.render_with_lighting().unwrap();
        let lit = lit_mask(&dive);
        let f = &dive.factor[0];
        let light = |x: usize, y: usize| (0..3).map(|ch| f.get(x, y, ch)).sum::<f32>() / 3.0;
        let top = (0..120)
            .flat_map(|y| (0..160).map(move |x| (x, y)))
            .map(|(x, y)| light(x, y))
            .fold(0.0f32, f32::max);
        for (x, y) in [(80, 60), (0, 0), (159, 119), (40, 100), (150, 10)] {
            assert_eq!(
                lit[0][y * 160 + x],
                light(x, y) >= LIT_SHARE * top,
                "({x}, {y})"
            );
        }
        assert!(lit[0][60 * 160 + 80], "the centre is lit");
        let share = lit[0].iter().filter(|&&b| b).count() as f64 / lit[0].len() as f64;
        assert!(share > 0.5 && share < 0.98, "lit share {share}");
        let masked = only_lit(&dive.albedo, &lit);
        for (i, &on) in lit[0].iter().enumerate() {
            for ch in 0..3 {
                let v = masked[0].data[i * 3 + ch];
                assert_eq!(v.is_nan(), !on);
                if on {
                    assert_eq!(v, dive.albedo[0].data[i * 3 + ch]);
                }
            }
        }
    }
}

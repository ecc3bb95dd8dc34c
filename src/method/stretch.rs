//! The window chosen per stretch of the mission (`--window auto`, the default of [`Method::Abyss`]): how much of
//! the seafloor is dark (nodules, burrows, shadows) and how far the camera moves between photos, measured on the
//! mission's block images before the correction ([`Surveyor`]), give each photo its window, the quantile its `M`
//! and per-photo gain take, and its near window ([`choose`]).
//!
//! The paper's window rule counts photos as independent samples. They are not when the camera moves less than an
//! object's extent between photos: a slow sledge sees the same burrow at the same place of the frame in most photos
//! of a short window, and the window's `M` takes it into `F`. So the rule here counts ground covered, measured
//! where it matters: each photo's scene at block resolution (its block image over the reference of its neighbours,
//! the lights' smooth pattern and what is fixed in the frame taken out) is correlated with the scene of the photos
//! after it at the same blocks; the photos one independent sample takes are the lag at which that correlation
//! falls below [`SAME_SCENE`]. The window then holds [`BASE_WINDOW`] independent samples, and more by
//! [`crate::method::window::quantile_window`] where the stretch is dark.
//!
//! [`Method::Abyss`]: crate::method::baseline::Method::Abyss

use std::collections::VecDeque;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::method::matching::box_blur;
use crate::method::median::quantile;
use crate::method::raster::Raster;
use crate::method::running::RunningQuantile;
use crate::method::window::{near_range, quantile_window, window_range, NEAR_MIN, NEAR_RISK};

/// Photos on each side of a photo whose block images make the reference its dark share is measured against.
pub const REFERENCE_HALF: usize = 10;
/// The reference's quantile over those photos, per block: the seafloor's bright side, above what dark patches
/// covering up to half of the photos at a block pull down.
pub const REFERENCE_QUANTILE: f64 = 0.8;
/// A block is dark when its level against the reference is below this share of the photo's seafloor level.
pub const DARK_RATIO: f32 = 0.6;
/// Photos on each side of a photo over which its stretch's coverage and photos per sample are taken.
pub const STRETCH_HALF: usize = 10;
/// The stretch's coverage: this quantile of its photos' dark shares (a stretch is as dense as its denser photos).
pub const STRETCH_QUANTILE: f64 = 0.75;
/// Coverage below which a stretch on which the camera moves on keeps the default window and its median.
pub const ACT_COVERAGE: f32 = 0.2;
/// The longest window chosen (the engine's ring holds it; `n/2 + 1` full photos wait for it).
pub const MAX_AUTO_WINDOW: usize = 31;
/// The window of a stretch where nothing calls for more: the paper's 7.
pub use crate::method::params::BASE_WINDOW;
/// Breakdown risk of the window's quantile ([`quantile_window`]).
pub const RISK: f64 = 0.01;
/// Correlation of two photos' scenes at the same blocks above which they are not independent samples.
pub const SAME_SCENE: f32 = 0.45;
/// Longest lag, in photos, at which the scenes are correlated (photos per sample beyond it: capped).
pub const MAX_LAG: usize = 16;
/// The correlation a scene keeps at every lag before the one where [`SAME_SCENE`] finds it again
/// ([`independent`]).
pub const PERSISTS: f32 = 0.2;

/// The correlation at which a scene that was gone is found again: the lights' pattern, not the ground
/// ([`lit_again`]).
pub const LIT_AGAIN: f32 = 0.3;

/// Independent views a window 7 taken by the do-no-harm check ([`Rule::Unsteady`]) must hold not to be flagged
/// `few-samples`: the fewest among which no view has to fill more than half of it (with 2, one view is in at least
/// 4 of its 7 photos, and the median takes it). It asks fewer than the survey's 7, which the independence test,
/// under a swing, cannot always tell from the lights.
pub const UNSTEADY_VIEWS: usize = BASE_WINDOW.div_ceil(BASE_WINDOW / 2);

/// The parts of the frame (columns, rows) over which the lights' low-frequency shape is read ([`PhotoSurvey::shape`]).
pub const SHAPE_GRID: (usize, usize) = (8, 6);
/// Parts of [`SHAPE_GRID`].
pub const SHAPE_PARTS: usize = SHAPE_GRID.0 * SHAPE_GRID.1;
/// The quantile of a part's blocks that stands for its lit seafloor (above what nodules covering up to half of the
/// part pull down).
pub const SHAPE_QUANTILE: f64 = 0.9;
/// Photos on each side of a photo whose shapes are compared with a window's ([`shape_misfit`]).
pub const STEADY_HALF: usize = 1;
/// Where the survey asked for more than the window 7 and its median on sparse ground (a slow camera): the longer
/// window is kept where its [`shape_misfit`] is at most `.0` times the short window's plus `.1` (log units: 1 % of
/// the light).
pub const STEADY_SPARSE: (f32, f32) = (1.5, 0.01);
/// The same on a dense stretch, where both windows are compared without the photos they are fitted to: a short
/// window's `M` holds their nodules, which the parts' upper quantile does not wholly leave out, and fits them by
/// holding them, so more is asked before the short window wins.
pub const STEADY_DENSE: (f32, f32) = (2.0, 0.02);

/// What the survey measured on one photo.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PhotoSurvey {
    /// Share of the photo's blocks darker than [`DARK_RATIO`] of its seafloor level, against the reference of its
    /// neighbours' bright side.
    pub coverage: f32,
    /// Correlation of its scene with the scene of the photo `k` after it at the same blocks, `k = 1..=`
    /// [`MAX_LAG`] (NaN past the mission's end).
    pub same_scene: [f32; MAX_LAG],
    /// The lights' low-frequency shape and level in the photo: per part of [`SHAPE_GRID`] (row by row), the log of
    /// the [`SHAPE_QUANTILE`] of its blocks' grey level above `S`; NaN where the part is masked or unlit (below 5 %
    /// of the photo's brightest parts).
    #[serde(skip)]
    pub shape: [f32; SHAPE_PARTS],
}

/// The streaming pass over a mission's block images (bounded memory: `2·`[`REFERENCE_HALF`]` + 1` grey block
/// images). Push each photo's block medians (linear light) in mission order, then [`Surveyor::finish`].
pub struct Surveyor {
    s_low: Option<Raster>,
    /// The grey level of `S` per block (mean over channels), for the blocks the dark share judges.
    s_grey: Option<Vec<f32>>,
    /// Grey `M − S`-like levels of the last photos, with their first photo's number.
    greys: VecDeque<Vec<f32>>,
    /// The levels of `greys`, per block, for their reference ([`REFERENCE_QUANTILE`]).
    held: Option<RunningQuantile>,
    size: (usize, usize),
    pushed: usize,
    /// The scenes of the last photos measured (at most [`MAX_LAG`] + 1).
    scenes: VecDeque<Vec<f32>>,
    /// Photos whose reference is known, waiting to be measured together: their grey levels and reference.
    pending: Vec<(Vec<f32>, Vec<f32>)>,
    done: Vec<PhotoSurvey>,
}

/// Photos measured at once, on all workers: the reference is kept in mission order, each photo's measures against it
/// are its own.
const MEASURED_TOGETHER: usize = 8;

/// The grey level above `S` of each block (mean over channels; NaN where masked).
fn grey_above(low: &Raster, s: Option<&Raster>) -> Vec<f32> {
    let c = low.channels;
    (0..low.width * low.height)
        .map(|b| {
            let mut g = 0.0;
            for ch in 0..c {
                let i = b * c + ch;
                g += low.data[i] - s.map_or(0.0, |s| s.data.get(i).copied().unwrap_or(0.0));
            }
            g / c as f32
        })
        .collect()
}

impl Surveyor {
    /// A survey against the backscatter `s_low` (block resolution, linear; `None`: no `S`).
    pub fn new(s_low: Option<&Raster>) -> Self {
        Surveyor {
            s_low: s_low.cloned(),
            s_grey: s_low.map(|s| grey_above(s, None)),
            greys: VecDeque::new(),
            held: None,
            size: (0, 0),
            pushed: 0,
            scenes: VecDeque::new(),
            pending: Vec::new(),
            done: Vec::new(),
        }
    }

    /// The next photo's block medians. Block images of another size than the first are taken as missing.
    pub fn push(&mut self, low: &Raster) {
        if self.pushed == 0 {
            self.size = (low.width, low.height);
        }
        let fits = (low.width, low.height) == self.size
            && self
                .s_low
                .as_ref()
                .is_none_or(|s| s.layout() == low.layout());
        let grey = if fits {
            grey_above(low, self.s_low.as_ref())
        } else {
            vec![f32::NAN; self.size.0 * self.size.1]
        };
        let n = 2 * REFERENCE_HALF + 1;
        let held = self
            .held
            .get_or_insert_with(|| RunningQuantile::new(grey.len(), n));
        if self.greys.len() == n {
            held.remove(&self.greys.pop_front().expect("n photos held"));
        }
        held.add(&grey);
        self.greys.push_back(grey);
        self.pushed += 1;
        if self.greys.len() == n {
            // Every photo whose reference is these photos: the first `REFERENCE_HALF + 1` at once, then one each.
            while self.queued() + REFERENCE_HALF < self.pushed {
                self.queue(self.queued(), self.pushed - n);
            }
            if self.pending.len() >= MEASURED_TOGETHER {
                self.measure_pending();
            }
        }
    }

    /// Photos measured or waiting to be.
    fn queued(&self) -> usize {
        self.done.len() + self.pending.len()
    }

    /// Photo `j` to be measured against the reference of the photos held (the first of them is photo `first`).
    fn queue(&mut self, j: usize, first: usize) {
        let reference = self
            .held
            .as_ref()
            .map_or_else(Vec::new, |h| h.quantile(REFERENCE_QUANTILE));
        self.pending
            .push((self.greys[j - first].clone(), reference));
    }

    /// The photos waiting: each one's dark share and scene against its reference (on all workers), then in mission
    /// order its scene's correlation with the scenes of the photos before it.
    fn measure_pending(&mut self) {
        let (size, s_grey) = (self.size, self.s_grey.as_deref());
        let measured: Vec<(f32, Vec<f32>, [f32; SHAPE_PARTS])> = self
            .pending
            .par_iter()
            .map(|(own, reference)| {
                let ratio = lit_ratios(own, reference);
                (
                    dark_share(&judged_ratios(&ratio, own, reference, s_grey, size), size),
                    scene(&ratio, size),
                    shape(own, size),
                )
            })
            .collect();
        self.pending.clear();
        for (coverage, scene, shape) in measured {
            let j = self.done.len();
            // This photo's scene against the photos before it: their correlation at lag k.
            let earlier: Vec<&Vec<f32>> = self.scenes.iter().rev().collect();
            let lags: Vec<f32> = earlier.par_iter().map(|e| correlation(e, &scene)).collect();
            for (k, c) in lags.into_iter().enumerate() {
                self.done[j - 1 - k].same_scene[k] = c;
            }
            self.scenes.push_back(scene);
            if self.scenes.len() > MAX_LAG {
                self.scenes.pop_front();
            }
            self.done.push(PhotoSurvey {
                coverage,
                same_scene: [f32::NAN; MAX_LAG],
                shape,
            });
        }
    }

    /// The photos measured so far, in order (those whose reference is known: all but the last
    /// [`REFERENCE_HALF`] pushed, once the reference is full). The lags of the last [`MAX_LAG`] of them reach
    /// photos not measured yet (NaN).
    pub fn measured(&mut self) -> &[PhotoSurvey] {
        if !self.pending.is_empty() {
            self.measure_pending();
        }
        &self.done
    }

    /// The survey of every photo pushed (shorter missions than the reference: against all their photos).
    pub fn finish(mut self) -> Vec<PhotoSurvey> {
        let first = self.pushed - self.greys.len();
        while self.queued() < self.pushed {
            self.queue(self.queued(), first);
        }
        self.measure_pending();
        self.done
    }
}

/// Photos of a mission whose JPEGs the survey reads by their DC coefficients (block means) that it also decodes
/// (block medians) to check that the two see the same dark blocks: one in this many.
pub const MEANS_CHECKED_EVERY: usize = 8;
/// Largest difference of dark shares ([`dark_share`]) between a photo's block means and its block medians at which
/// the means stand for the medians. Where clutter is as fine as the blocks, a block half covered has a mean halfway
/// to the clutter's level and a median at one of the two: the means' dark share falls far below the medians'.
pub const MEANS_AGREE: f32 = 0.05;

/// Whether block means `means` of a photo see the dark blocks its block medians `medians` see (same size and
/// channels; linear light; `s`: the backscatter at block resolution): their dark shares against one smooth
/// reference, the medians' grey levels above `S` box-averaged over an eighth of the frame, differ by at most
/// [`MEANS_AGREE`].
pub fn means_stand_for_medians(means: &Raster, medians: &Raster, s: Option<&Raster>) -> bool {
    if means.layout() != medians.layout() {
        return false;
    }
    let (w, h) = (medians.width, medians.height);
    let (a, b) = (grey_above(means, s), grey_above(medians, s));
    let reference = box_average_finite(&b, (w, h), (w.max(h) / 8).max(2), f32::NAN);
    // One level for the frame: both are measured against the same smooth reference.
    let share = |g: &[f32]| {
        let mut judged: Vec<f32> = lit_ratios(g, &reference)
            .into_iter()
            .filter(|v| v.is_finite())
            .collect();
        dark_count(&mut judged) as f32 / judged.len().max(1) as f32
    };
    (share(&a) - share(&b)).abs() <= MEANS_AGREE
}

/// `own / reference` per block where the reference is lit (at least 5 % of its 95th percentile: corners the lights
/// miss are not judged), `NaN` elsewhere and where either is not finite (masked).
fn lit_ratios(own: &[f32], reference: &[f32]) -> Vec<f32> {
    let mut lit: Vec<f32> = reference
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let top = quantile(&mut lit, 0.95);
    own.iter()
        .zip(reference)
        .map(|(&o, &r)| {
            if r.is_finite() && o.is_finite() && r > 0.05 * top && top > 0.0 {
                o / r
            } else {
                f32::NAN
            }
        })
        .collect()
}

/// Share of the photo's own light, smoothed over an eighth of the frame, below which its blocks are not judged dark
/// or not: where the vehicle comes low the cones narrow, and blocks its neighbours lit fall dark in the photo itself.
pub const OWN_LIT: f32 = 0.25;

/// The [`lit_ratios`] `ratio` of the blocks the dark share judges (NaN elsewhere): the photo's own grey levels `own`
/// (`w`×`h`), smoothed over an eighth of the frame, at least [`OWN_LIT`] of their 95th percentile; and the reference
/// at least the backscatter `s` subtracted there — where `S` is most of the light, the water column's `S` (taken
/// over the whole descent) can exceed what reaches the floor from low down, and the seafloor left above it reads
/// dark where it is not.
fn judged_ratios(
    ratio: &[f32],
    own: &[f32],
    reference: &[f32],
    s: Option<&[f32]>,
    (w, h): (usize, usize),
) -> Vec<f32> {
    if ratio.len() != w * h || own.len() != w * h {
        return ratio.to_vec();
    }
    let smooth = box_average_finite(own, (w, h), (w.max(h) / 8).max(2), f32::NAN);
    let mut finite: Vec<f32> = smooth.iter().copied().filter(|v| v.is_finite()).collect();
    let top = quantile(&mut finite, 0.95);
    let s = s.filter(|s| s.len() == ratio.len());
    (0..ratio.len())
        .map(|b| {
            let lit = smooth[b] >= OWN_LIT * top && s.is_none_or(|s| reference[b] >= s[b]);
            if lit {
                ratio[b]
            } else {
                f32::NAN
            }
        })
        .collect()
}

/// The dark share of a photo's blocks (`w`×`h`), from their [`lit_ratios`] against the reference (NaN: not judged),
/// each block against the seafloor's level around it: the ratios' box average over an eighth of the frame, then the
/// box average of the blocks that first guess did not find dark. The neighbours' reference is taken at other
/// altitudes where the vehicle swings, and the lights' cones move and widen with the altitude: against one level for
/// the whole frame, the cones' edges read as dark.
fn dark_share(ratio: &[f32], (w, h): (usize, usize)) -> f32 {
    if ratio.len() != w * h || ratio.is_empty() {
        return 0.0;
    }
    let r = (w.max(h) / 8).max(2);
    let first = box_average_finite(ratio, (w, h), r, f32::NAN);
    let bright: Vec<f32> = ratio
        .iter()
        .zip(&first)
        .map(|(&q, &l)| if q >= DARK_RATIO * l { q } else { f32::NAN })
        .collect();
    let level = box_average_finite(&bright, (w, h), r, f32::NAN);
    let (mut dark, mut judged) = (0usize, 0usize);
    for ((&q, &l), &l0) in ratio.iter().zip(&level).zip(&first) {
        if q.is_finite() {
            judged += 1;
            let l = if l.is_finite() { l } else { l0 };
            dark += usize::from(q < DARK_RATIO * l);
        }
    }
    if judged == 0 {
        0.0
    } else {
        dark as f32 / judged as f32
    }
}

/// The blocks of `judged` (their ratios) darker than [`DARK_RATIO`] of their seafloor level: a first guess at the
/// median, then twice the `(1 + c)/2` quantile of the share `c` found dark.
fn dark_count(judged: &mut [f32]) -> usize {
    let n = judged.len();
    if n == 0 {
        return 0;
    }
    let mut level = quantile(judged, 0.5);
    for _ in 0..2 {
        let dark_n = judged.iter().filter(|&&r| r < DARK_RATIO * level).count();
        let c = dark_n as f64 / n as f64;
        level = quantile(judged, ((1.0 + c) / 2.0).min(0.95));
    }
    judged.iter().filter(|&&r| r < DARK_RATIO * level).count()
}

/// The part of [`SHAPE_GRID`] (row by row) that block `b` of a `w`×`h` block image lies in.
fn part_of(b: usize, (w, h): (usize, usize)) -> usize {
    let (gx, gy) = SHAPE_GRID;
    ((b / w) * gy / h) * gx + (b % w) * gx / w
}

/// The lights' shape in a photo from its blocks' grey levels above `S` (`w`×`h`): [`PhotoSurvey::shape`].
fn shape(grey: &[f32], (w, h): (usize, usize)) -> [f32; SHAPE_PARTS] {
    let mut parts: Vec<Vec<f32>> = vec![Vec::new(); SHAPE_PARTS];
    let mut blocks = [0usize; SHAPE_PARTS];
    for (b, &v) in grey.iter().enumerate().take(w * h) {
        let k = part_of(b, (w, h));
        blocks[k] += 1;
        if v.is_finite() {
            parts[k].push(v);
        }
    }
    let mut level = [f32::NAN; SHAPE_PARTS];
    for (k, part) in parts.iter_mut().enumerate() {
        if !part.is_empty() && 2 * part.len() >= blocks[k] {
            level[k] = quantile(part, SHAPE_QUANTILE);
        }
    }
    let mut lit: Vec<f32> = level.iter().copied().filter(|v| v.is_finite()).collect();
    let top = quantile(&mut lit, 0.95);
    level.map(|l| {
        if l.is_finite() && top > 0.0 && l > 0.05 * top {
            l.ln()
        } else {
            f32::NAN
        }
    })
}

/// How far the lights' shape in the photos around `i` (`i − `[`STEADY_HALF`]` ..= i + `[`STEADY_HALF`]) is from the
/// shape the rest of the window `range` gives them at its quantile `q`: per part of [`SHAPE_GRID`], the `q` quantile
/// of the shapes of the window's other photos (the window's `M`, at this scale, without the photos it is compared
/// with: a short window would otherwise fit them by holding them) against the median of the photos' own, less the
/// median over the parts (the level: the per-photo gain takes it), as the mean absolute difference (log units). NaN
/// where fewer than 2 other photos or 4 lit parts are left.
pub fn shape_misfit(
    photos: &[PhotoSurvey],
    i: usize,
    range: std::ops::Range<usize>,
    q: f64,
    leave_out: bool,
) -> f32 {
    let near = i.saturating_sub(STEADY_HALF)..(i + STEADY_HALF + 1).min(photos.len());
    let others: Vec<&PhotoSurvey> = range
        .filter(|j| !leave_out || !near.contains(j))
        .map(|j| &photos[j])
        .collect();
    if others.len() < 2 {
        return f32::NAN;
    }
    let r: Vec<f32> = (0..SHAPE_PARTS)
        .filter_map(|k| {
            let mut m: Vec<f32> = others
                .iter()
                .map(|p| p.shape[k])
                .filter(|v| v.is_finite())
                .collect();
            if 2 * m.len() < others.len() {
                return None;
            }
            let m = quantile(&mut m, q);
            let mut d: Vec<f32> = photos[near.clone()]
                .iter()
                .map(|p| p.shape[k] - m)
                .filter(|v| v.is_finite())
                .collect();
            let d = quantile(&mut d, 0.5);
            d.is_finite().then_some(d)
        })
        .collect();
    spread(&r)
}

/// The spread of per-part differences of the lights' shape ([`shape`]) over the parts of [`SHAPE_GRID`]: their mean
/// absolute difference from their median over the parts (the level: the per-photo gain takes it). NaN where fewer
/// than 4 parts are left.
fn spread(d: &[f32]) -> f32 {
    if d.len() < 4 {
        return f32::NAN;
    }
    let level = quantile(&mut d.to_vec(), 0.5);
    d.iter().map(|v| (v - level).abs()).sum::<f32>() / d.len() as f32
}

/// The upper quantile of a part's block ratios photo / window that [`lights_misfit`] reads: above the dark objects
/// of a dense part (up to nine tenths of its blocks), on the seafloor's side.
pub const LIGHTS_QUANTILE: f64 = 0.9;

/// How far the lights in a photo are from its window's (see [`Health::lights_misfit`]): per part of [`SHAPE_GRID`],
/// a quantile of the log ratios of its blocks' grey level above `s_low` (`own`) to its window's `M − S`
/// (`m_minus_s`) at the same blocks, lit to at least 5 % of the window's brightest; their [`spread`] over the parts
/// (log units), read at two quantiles and the lesser taken: [`LIGHTS_QUANTILE`] and the window's own `q`. Block by
/// block, so that a part's own gradient of light cancels wherever its seafloor lies. Each reading has its own false
/// alarm — noise lifts the upper quantile most in the dim parts (a sound 12 MP mission of noisy JPEGs read 0.07–0.11
/// there), a part mostly covered by nodules pulls the window's quantile down (a sound level 40 % field read up to
/// 0.2) — while the lights' pattern moves every quantile of a part alike and so both readings. It is what the
/// correction leaves of the lights' pattern at the grid the residual pattern is scored on, plus what the seafloor's
/// texture puts in. NaN where the two are not the same size or fewer than 4 parts have half their blocks lit.
///
/// [`Health::lights_misfit`]: crate::method::monitor::Health::lights_misfit
pub fn lights_misfit(own: &Raster, m_minus_s: &Raster, s_low: Option<&Raster>, q: f64) -> f32 {
    let (w, h) = (own.width, own.height);
    if (m_minus_s.width, m_minus_s.height) != (w, h) {
        return f32::NAN;
    }
    let (a, b) = (grey_above(own, s_low), grey_above(m_minus_s, None));
    let mut lit: Vec<f32> = b.iter().copied().filter(|v| v.is_finite()).collect();
    let floor = 0.05 * quantile(&mut lit, 0.95);
    let mut parts: Vec<Vec<f32>> = vec![Vec::new(); SHAPE_PARTS];
    let mut blocks = [0usize; SHAPE_PARTS];
    for (p, (&x, &y)) in a.iter().zip(&b).enumerate() {
        let k = part_of(p, (w, h));
        blocks[k] += 1;
        if x > 0.0 && y > floor {
            parts[k].push((x / y).ln());
        }
    }
    let mut lit_parts: Vec<&mut Vec<f32>> = parts
        .iter_mut()
        .zip(blocks)
        .filter(|(part, n)| !part.is_empty() && 2 * part.len() >= *n)
        .map(|(part, _)| part)
        .collect();
    let mut at = |q: f64| -> f32 {
        let d: Vec<f32> = lit_parts.iter_mut().map(|part| quantile(part, q)).collect();
        spread(&d)
    };
    at(LIGHTS_QUANTILE).min(at(q))
}

/// A photo's scene at block resolution, from its [`lit_ratios`] `own / reference`: their log less its box average
/// (a sixteenth of the frame: the lights' changing shape and the photo's exposure go), 0 where not judged (dim or
/// masked blocks).
fn scene(ratio: &[f32], (w, h): (usize, usize)) -> Vec<f32> {
    let log: Vec<f32> = ratio
        .iter()
        .map(|&q| if q > 0.0 { q.ln() } else { f32::NAN })
        .collect();
    // A band: objects of a few blocks to an eighth of the frame (a burrow, a nodule patch), not the sediment's
    // fine texture (which a small shift decorrelates) nor the lights' shape.
    let band = |r: usize| box_average_finite(&log, (w, h), r, 0.0);
    let (fine, coarse) = (band((w.max(h) / 60).max(1)), band((w.max(h) / 8).max(2)));
    log.iter()
        .zip(fine.iter().zip(&coarse))
        .map(|(&v, (&f, &c))| if v.is_finite() { f - c } else { 0.0 })
        .collect()
}

/// The box average of radius `r` of the finite values of `v` (`w`×`h`, row by row), `empty` where a box holds
/// almost none.
fn box_average_finite(v: &[f32], (w, h): (usize, usize), r: usize, empty: f32) -> Vec<f32> {
    let zeroed: Vec<f32> = v
        .iter()
        .map(|&x| if x.is_finite() { x } else { 0.0 })
        .collect();
    let valid: Vec<f32> = v
        .iter()
        .map(|x| f32::from(u8::from(x.is_finite())))
        .collect();
    let (num, den) = (box_blur(&zeroed, w, h, r), box_blur(&valid, w, h, r));
    num.iter()
        .zip(&den)
        .map(|(&n, &d)| if d > 1e-3 { n / d } else { empty })
        .collect()
}

/// Pearson correlation of two scenes (0 when either is flat).
fn correlation(a: &[f32], b: &[f32]) -> f32 {
    let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (x as f64, y as f64);
        sa += x;
        sb += y;
        saa += x * x;
        sbb += y * y;
        sab += x * y;
    }
    let n = a.len().max(1) as f64;
    let (va, vb) = (saa - sa * sa / n, sbb - sb * sb / n);
    if va <= 1e-12 || vb <= 1e-12 {
        return 0.0;
    }
    ((sab - sa * sb / n) / (va * vb).sqrt()) as f32
}

/// Why a photo has the window it has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rule {
    /// Little dark seafloor and a camera that moves on: the default window 7 and its median.
    Sparse,
    /// A dense stretch (the `(1 + c)/2` quantile and the samples [`quantile_window`] asks) or photos that see the
    /// same scene (a longer window until it holds enough independent samples).
    Quantile,
    /// As [`Rule::Quantile`], but [`MAX_AUTO_WINDOW`] photos did not hold the samples asked.
    Capped,
    /// As [`Rule::Quantile`], but the whole mission, shorter than [`MAX_AUTO_WINDOW`], did not hold the samples
    /// asked: the window is as long as the mission allows.
    Short,
    /// The survey asked for a longer window or a higher quantile, but the lights' shape changed along it (a swing
    /// of the altitude, a turn): the window [`BASE_WINDOW`] fitted the photos' own shape better
    /// ([`shape_misfit`]), and it is taken with its median, as [`Rule::Sparse`].
    Unsteady,
}

/// What `--window auto` chose for one photo.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Choice {
    /// Photos in its window (odd).
    pub window: usize,
    /// The quantile its window's `M` and its per-photo gain take.
    #[serde(deserialize_with = "crate::method::members::null_is_nan")]
    pub quantile: f32,
    /// Its near window (`None`: off).
    pub near: Option<usize>,
    /// Its stretch's coverage by dark patches.
    #[serde(deserialize_with = "crate::method::members::null_is_nan")]
    pub coverage: f32,
    /// Photos per independent sample in its window.
    #[serde(deserialize_with = "crate::method::members::null_is_nan")]
    pub photos_per_sample: f32,
    /// Independent samples its window holds.
    pub samples: usize,
    /// Independent samples the window needs (at most [`MAX_AUTO_WINDOW`] photos are taken to find them).
    pub needed: usize,
    /// Why.
    pub rule: Rule,
    /// Where the survey asked for more than the window [`BASE_WINDOW`] and its median: the [`shape_misfit`] of what
    /// it asked and of the short window, which decided between them (`None`: not checked).
    #[serde(default)]
    pub misfit: Option<[f32; 2]>,
}

impl Choice {
    /// In words, for the console and the report.
    pub fn why(&self) -> String {
        let c = 100.0 * self.coverage;
        match self.rule {
            Rule::Sparse => format!(
                "{c:.0} % dark, {:.1} photo(s) per independent sample: the window {BASE_WINDOW} and its median",
                self.photos_per_sample
            ),
            Rule::Unsteady => {
                let [long, short] = self.misfit.unwrap_or([f32::NAN; 2]);
                format!(
                    "{c:.0} % dark, {:.1} photo(s) per independent sample, but the lights' shape changed along the \
                     longer window (misfit {long:.3} against {short:.3}): the window {BASE_WINDOW} and its median",
                    self.photos_per_sample
                )
            }
            Rule::Quantile | Rule::Capped | Rule::Short => format!(
                "{c:.0} % dark, {:.1} photo(s) per independent sample: the {:.2} quantile of {} photos{}",
                self.photos_per_sample,
                self.quantile,
                self.window,
                match self.rule {
                    Rule::Capped => format!(
                        " (capped: {} of the {} independent samples asked)",
                        self.samples, self.needed
                    ),
                    Rule::Short => format!(
                        " (the whole mission: {} of the {} independent samples asked)",
                        self.samples, self.needed
                    ),
                    _ => String::new(),
                }
            ),
        }
    }
}

/// Each photo's window, quantile and near window from the mission's survey ([`choose_one`] of each photo).
pub fn choose(photos: &[PhotoSurvey]) -> Vec<Choice> {
    (0..photos.len()).map(|i| choose_one(photos, i)).collect()
}

/// The longest window a mission of `total` photos allows: [`MAX_AUTO_WINDOW`], or the largest odd number of photos
/// the mission holds (at least 1).
pub fn longest_window(total: usize) -> usize {
    let odd = if total.is_multiple_of(2) {
        total.saturating_sub(1)
    } else {
        total
    };
    MAX_AUTO_WINDOW.min(odd).max(1)
}

/// Photos of the survey that photo `i`'s choice reads: the photos of its longest possible window (the stretch's and
/// the near window's lie inside it). Once the survey measured these, [`choose_one`] of `i` over the photos measured
/// so far is its choice over the whole mission (what a survey streamed with the photos waits for).
pub fn photos_read(i: usize) -> usize {
    window_range(i, MAX_AUTO_WINDOW, usize::MAX).end
}

/// Photo `i`'s window, quantile and near window from the survey of the mission's photos `photos` (see the module
/// documentation): the stretch's coverage `c` is [`STRETCH_QUANTILE`] of its photos' dark shares; the window needs
/// [`BASE_WINDOW`] independent samples below [`ACT_COVERAGE`] (its median), else the samples [`quantile_window`]
/// asks of the `(1 + c)/2` quantile, and grows from [`BASE_WINDOW`] photos until it holds them ([`independent`]),
/// never past [`longest_window`] of the mission.
pub fn choose_one(photos: &[PhotoSurvey], i: usize) -> Choice {
    let asked = survey_choice(photos, i);
    if asked.rule == Rule::Sparse {
        return asked;
    }
    // Do no harm: what the survey asked against the window 7 and its median, on how well each fits the lights'
    // shape in the photos around this one.
    let total = photos.len();
    let short = BASE_WINDOW.min(longest_window(total));
    let dense = asked.coverage >= ACT_COVERAGE;
    let long = shape_misfit(
        photos,
        i,
        window_range(i, asked.window, total),
        asked.quantile as f64,
        dense,
    );
    let plain = shape_misfit(photos, i, window_range(i, short, total), 0.5, dense);
    if !(long.is_finite() && plain.is_finite()) {
        return asked;
    }
    let misfit = Some([long, plain]);
    let (ratio, slack) = if dense { STEADY_DENSE } else { STEADY_SPARSE };
    if long <= ratio * plain + slack {
        return Choice { misfit, ..asked };
    }
    let range = window_range(i, short, total);
    let read = read_by(photos, i);
    let (near, _) = grow(read, NEAR_MIN.min(short), short, NEAR_MIN, |k| {
        near_range(i, k, &range)
    });
    let found = independent(read, range.clone());
    Choice {
        window: short,
        quantile: 0.5,
        near: (near < short).then_some(near),
        coverage: asked.coverage,
        photos_per_sample: range.len() as f32 / found.max(1) as f32,
        samples: found,
        // A slow camera's photos stay few samples (the monitor says so), whichever window fits the lights better.
        needed: UNSTEADY_VIEWS,
        rule: Rule::Unsteady,
        misfit,
    }
}

/// The photos photo `i`'s choice reads ([`photos_read`]) of those surveyed: its lit-again test reads no further, so
/// a survey streamed with the photos decides as one over the whole mission.
fn read_by(photos: &[PhotoSurvey], i: usize) -> &[PhotoSurvey] {
    &photos[..photos_read(i).min(photos.len())]
}

/// What the survey asks for photo `i` before [`choose_one`] checks it against the short window.
fn survey_choice(photos: &[PhotoSurvey], i: usize) -> Choice {
    let total = photos.len();
    let stretch = &photos[i.saturating_sub(STRETCH_HALF)..(i + STRETCH_HALF + 1).min(total)];
    let mut c: Vec<f32> = stretch.iter().map(|p| p.coverage).collect();
    let c = quantile(&mut c, STRETCH_QUANTILE);
    let c = if c.is_finite() {
        c.clamp(0.0, 0.6)
    } else {
        0.0
    };
    let dense = c >= ACT_COVERAGE;
    let q = if dense { (1.0 + c as f64) / 2.0 } else { 0.5 };
    let samples = |risk: f64, least: usize| match dense {
        true => quantile_window(c as f64, q, risk, 1)
            .unwrap_or(MAX_AUTO_WINDOW)
            .max(least),
        false => least,
    };
    let longest = longest_window(total);
    let need = samples(RISK, BASE_WINDOW);
    let read = read_by(photos, i);
    let (window, found) = grow(read, BASE_WINDOW.min(longest), longest, need, |n| {
        window_range(i, n, total)
    });
    let range = window_range(i, window, total);
    let need_near = samples(NEAR_RISK, NEAR_MIN);
    let (near, _) = grow(read, NEAR_MIN.min(window), window, need_near, |k| {
        near_range(i, k, &range)
    });
    let rule = match (found >= need, dense || window > BASE_WINDOW) {
        (false, _) if window < MAX_AUTO_WINDOW => Rule::Short,
        (false, _) => Rule::Capped,
        (true, false) => Rule::Sparse,
        (true, true) => Rule::Quantile,
    };
    Choice {
        window,
        quantile: q as f32,
        near: (near < window).then_some(near),
        coverage: c,
        photos_per_sample: range.len() as f32 / found.max(1) as f32,
        samples: found,
        needed: need,
        rule,
        misfit: None,
    }
}

/// The shortest odd length from `from` up to `most` whose photos (`range_of(length)`) hold `need` independent
/// samples, and how many they hold (`most` and its count when none does).
fn grow(
    photos: &[PhotoSurvey],
    from: usize,
    most: usize,
    need: usize,
    range_of: impl Fn(usize) -> std::ops::Range<usize>,
) -> (usize, usize) {
    let mut n = from | 1;
    loop {
        let found = independent(photos, range_of(n));
        if found >= need || n + 2 > most || range_of(n + 2).len() == range_of(n).len() {
            return (n, found);
        }
        n += 2;
    }
}

/// Independent samples among `photos[range]`: the photos whose scene is not the scene of an earlier photo of the
/// range ([`seen_again`], within [`MAX_LAG`] photos), unless that photo is lit again ([`lit_again`], over the
/// photos up to the end of `photos`: a choice passes the photos it reads).
pub fn independent(photos: &[PhotoSurvey], range: std::ops::Range<usize>) -> usize {
    let lit = |e: usize| lit_again(&photos[e], photos.len() - e - 1);
    range
        .clone()
        .filter(|&j| {
            !(range.start.max(j.saturating_sub(MAX_LAG))..j)
                .any(|e| seen_again(&photos[e], j - e) && !lit(e))
        })
        .count()
}

/// Whether a photo's scene is seen again `lag` photos later: its correlation there at least [`SAME_SCENE`], and at
/// every shorter lag at least [`PERSISTS`]. A scene that stays in view of a slow camera is seen in every photo
/// between; a lighting pattern that comes back with the altitude (a swinging sledge: the light cone's edge where it
/// was a swing ago) is not, and the photos between, lit from another height, correlate little or negatively.
fn seen_again(p: &PhotoSurvey, lag: usize) -> bool {
    p.same_scene[lag - 1] >= SAME_SCENE && p.same_scene[..lag - 1].iter().all(|&c| c >= PERSISTS)
}

/// Whether a photo's scene, once gone (its correlation with a later photo below 0), comes back to [`LIT_AGAIN`]
/// within the `horizon` photos after it: then what it shares with the photos around is the lights', at every lag.
/// A view of the ground fades as a slow camera moves on and does not return; a pattern fixed in the frame (the
/// cones' edges, the backscatter the water column's `S` leaves) follows the altitude and changes sign with it, so
/// under a swing the photos lit alike correlate as one scene. Only the photos [`photos_read`] by the choice are
/// read, which a survey streamed with the photos has measured when it decides.
fn lit_again(p: &PhotoSurvey, horizon: usize) -> bool {
    let lags = &p.same_scene[..horizon.min(MAX_LAG)];
    lags.iter()
        .position(|&c| c < 0.0)
        .is_some_and(|gone| lags[gone..].iter().any(|&c| c >= LIT_AGAIN))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mission of `frames` block images (`w`×`h`, grey): a smooth light over a seafloor of level 1 with a share
    /// `c` of dark (0.1) square patches of `size` blocks, the camera moving `step` blocks a photo along x.
    fn mission(frames: usize, c: f64, size: usize, step: usize) -> Vec<Raster> {
        let (w, h) = (60usize, 40usize);
        let ground_w = w + step * frames + size;
        // Patches on a grid of cells, each dark with probability c (a hash of the cell): the dark share is c.
        let dark = |x: usize, y: usize| {
            let (cx, cy) = ((x / size) as u64, (y / size) as u64);
            let hsh = (cx.wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ cy.wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
            .wrapping_mul(0x1656_67B1_9E37_79F9);
            ((hsh >> 11) as f64 / (1u64 << 53) as f64) < c
        };
        assert!(ground_w > w);
        (0..frames)
            .map(|i| {
                Raster::from_fn(w, h, 1, |x, y, _| {
                    let light = 0.2
                        + 0.8
                            * (-(((x as f32 - 30.0) / 25.0).powi(2)
                                + ((y as f32 - 20.0) / 18.0).powi(2)))
                            .exp();
                    let albedo = if dark(x + i * step, y) { 0.1 } else { 1.0 };
                    light * albedo * 0.5
                })
            })
            .collect()
    }

    fn survey(frames: &[Raster]) -> Vec<PhotoSurvey> {
        let mut s = Surveyor::new(None);
        for f in frames {
            s.push(f);
        }
        s.finish()
    }

    /// Altitude of photo `t` of `n`: 4 m, swinging by `swing` metres 1.3 cycles over the mission.
    fn swing_altitude(t: usize, n: usize, swing: f32) -> f32 {
        4.0 + swing * (std::f32::consts::TAU * 1.3 * t as f32 / n as f32).sin()
    }

    /// The block images (grey, linear, 40×30) of a mission of `n` photos under a side light that moves and widens
    /// with the altitude and dims with its square, the camera moving `step` blocks a photo over sediment of level 1
    /// with a little texture and dark nodules (0.15) covering a share `cover` in patches of 2×2 blocks; and the
    /// water column's backscatter (more than reaches the floor from low down).
    fn swinging(n: usize, swing: f32, step: usize, cover: f64) -> (Vec<Raster>, Raster) {
        let (w, h) = (40usize, 30usize);
        let hash = |a: u64, b: u64, k: u64| {
            let v =
                (a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F) ^ k)
                    .wrapping_mul(0x1656_67B1_9E37_79F9);
            (v >> 11) as f64 / (1u64 << 53) as f64
        };
        let albedo = |x: usize, y: usize, t: usize| {
            let gx = x + t * step;
            let texture = 1.0 + 0.1 * (hash(gx as u64, y as u64, 1) as f32 - 0.5);
            let dark = hash((gx / 2) as u64, (y / 2) as u64, 2) < cover;
            texture * if dark { 0.15 } else { 1.0 }
        };
        let s_water = |x: usize| 0.15 * (1.0 - x as f32 / w as f32);
        let lows = (0..n)
            .map(|t| {
                let a = swing_altitude(t, n, swing);
                let (cx, sigma) = (0.65 * w as f32 + 3.0 * (a - 4.0), 0.3 * w as f32 * a / 4.0);
                Raster::from_fn(w, h, 1, |x, y, _| {
                    let d = ((x as f32 - cx) / sigma).powi(2)
                        + ((y as f32 - 0.5 * h as f32) / (1.2 * sigma)).powi(2);
                    let light = (4.0 / a).powi(2) * 0.8 * (-d).exp();
                    light * albedo(x, y, t) + s_water(x) * (a / 6.0).min(1.0)
                })
            })
            .collect();
        (lows, Raster::from_fn(w, h, 1, |x, _, _| s_water(x)))
    }

    fn survey_against(lows: &[Raster], s: &Raster) -> Vec<PhotoSurvey> {
        let mut surveyor = Surveyor::new(Some(s));
        lows.iter().for_each(|l| surveyor.push(l));
        surveyor.finish()
    }

    /// Bare sediment under a swinging sledge (4 ± 0.8 and ± 1.6 m): the survey reads at most 10 % dark on every
    /// photo. Against one level for the whole frame, the lights' shape at the top of a swing, other than the
    /// neighbours' reference, read as dark: more than a tenth of the photo at 1.6 m.
    #[test]
    fn bare_sediment_with_swings_reads_no_cover() {
        for swing in [0.0, 0.8, 1.6] {
            let (lows, s) = swinging(60, swing, 5, 0.0);
            let most = survey_against(&lows, &s)
                .iter()
                .map(|p| p.coverage)
                .fold(0.0f32, f32::max);
            assert!(most <= 0.10, "swing {swing} m: the survey read {most} dark");
        }
        // The same photos judged with one level for the frame (the rule before).
        let (lows, s) = swinging(60, 1.6, 5, 0.0);
        let greys: Vec<Vec<f32>> = lows.iter().map(|l| grey_above(l, Some(&s))).collect();
        let whole = (0..60usize)
            .map(|j| {
                let around =
                    &greys[j.saturating_sub(10).min(39)..(j.saturating_sub(10).min(39) + 21)];
                let reference: Vec<f32> = (0..greys[j].len())
                    .map(|b| {
                        let mut v: Vec<f32> = around.iter().map(|g| g[b]).collect();
                        quantile(&mut v, REFERENCE_QUANTILE)
                    })
                    .collect();
                let mut judged: Vec<f32> = lit_ratios(&greys[j], &reference)
                    .into_iter()
                    .filter(|v| v.is_finite())
                    .collect();
                dark_count(&mut judged) as f32 / judged.len() as f32
            })
            .fold(0.0f32, f32::max);
        assert!(whole > 0.10, "one level for the frame read {whole}");
        // Nodules are still read: a 40 % field, level or swinging.
        for swing in [0.0, 1.6] {
            let (lows, s) = swinging(60, swing, 3, 0.4);
            let mut c: Vec<f32> = survey_against(&lows, &s)
                .iter()
                .map(|p| p.coverage)
                .collect();
            let median = quantile(&mut c, 0.5);
            assert!(median > 0.25 && median < 0.55, "swing {swing}: {median}");
        }
    }

    /// A dense nodule field (40 %) flown level: the survey's longer window and quantile are kept, with the misfits
    /// that decided it. Flown with a swing of 1.6 m, the lights' shape changes along that window: photos where the
    /// window 7 fits their shape better take it and its median (rule `unsteady`), and say so.
    #[test]
    fn the_survey_s_window_falls_back_to_the_short_one_where_the_lighting_changes_along_it() {
        let (lows, s) = swinging(60, 0.0, 3, 0.4);
        let level = choose(&survey_against(&lows, &s));
        let longer = level.iter().filter(|c| c.window > BASE_WINDOW).count();
        assert!(
            longer >= 40,
            "a dense field asks for longer windows: {longer}"
        );
        assert!(
            level.iter().all(|c| c.rule != Rule::Unsteady),
            "level: {:?}",
            level.iter().find(|c| c.rule == Rule::Unsteady)
        );
        assert!(level
            .iter()
            .filter(|c| c.rule != Rule::Sparse)
            .all(|c| c.misfit.is_some()));
        let (lows, s) = swinging(60, 1.6, 3, 0.4);
        let swung = choose(&survey_against(&lows, &s));
        let mut short = 0;
        for c in &swung {
            if c.rule == Rule::Unsteady {
                short += 1;
                assert_eq!((c.window, c.quantile), (BASE_WINDOW, 0.5), "{c:?}");
                assert_eq!(c.needed, 3, "{c:?}");
                assert!(c.samples <= BASE_WINDOW, "{c:?}");
                let [long, plain] = c.misfit.expect("the misfits that decided");
                assert!(long > STEADY_DENSE.0 * plain + STEADY_DENSE.1, "{c:?}");
                assert!(c.why().contains("changed"), "{}", c.why());
            }
        }
        assert!(
            short >= 10,
            "swinging: {short} of 60 photos took the short window"
        );
    }

    /// [`shape_misfit`] against a brute-force reading of its definition, with and without the photos it is compared
    /// with left out of the window, on shapes with unlit (NaN) parts.
    #[test]
    fn the_shape_misfit_is_its_definition() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let photos: Vec<PhotoSurvey> = (0..20)
            .map(|_| {
                let mut shape = [0.0; SHAPE_PARTS];
                for v in shape.iter_mut() {
                    *v = if next() < 0.1 { f32::NAN } else { next() - 0.5 };
                }
                PhotoSurvey {
                    coverage: 0.0,
                    same_scene: [0.0; MAX_LAG],
                    shape,
                }
            })
            .collect();
        let sorted_at = |mut v: Vec<f32>, q: f64| {
            v.sort_by(f32::total_cmp);
            v[((v.len() - 1) as f64 * q).round() as usize]
        };
        for (i, range, q, leave_out) in [
            (9, 3..16, 0.7, true),
            (9, 6..13, 0.5, false),
            (0, 0..7, 0.5, true),
        ] {
            let near: Vec<usize> = (i.max(STEADY_HALF) - STEADY_HALF..=i + STEADY_HALF).collect();
            let others: Vec<usize> = range
                .clone()
                .filter(|j| !leave_out || !near.contains(j))
                .collect();
            let mut r = Vec::new();
            for k in 0..SHAPE_PARTS {
                let m: Vec<f32> = others
                    .iter()
                    .map(|&j| photos[j].shape[k])
                    .filter(|v| v.is_finite())
                    .collect();
                if 2 * m.len() < others.len() {
                    continue;
                }
                let m = sorted_at(m, q);
                let d: Vec<f32> = near
                    .iter()
                    .map(|&j| photos[j].shape[k] - m)
                    .filter(|v| v.is_finite())
                    .collect();
                if !d.is_empty() {
                    r.push(sorted_at(d, 0.5));
                }
            }
            let level = sorted_at(r.clone(), 0.5);
            let want = r.iter().map(|v| (v - level).abs()).sum::<f32>() / r.len() as f32;
            let got = shape_misfit(&photos, i, range.clone(), q, leave_out);
            assert!((got - want).abs() < 1e-6, "{i} {range:?}: {got} vs {want}");
        }
    }

    /// [`lights_misfit`] against its definition worked by hand: a photo lit as its window's `M − S` (a cone steep
    /// across each part) times a pattern constant over each part of the grid (and an overall gain, which it must
    /// not see), above a backscatter `S`, with one unlit corner part; the spread of the pattern over the lit parts,
    /// its median taken out.
    #[test]
    fn the_lights_misfit_is_the_spread_of_the_lights_pattern_left() {
        let (w, h) = (64usize, 48usize);
        let (gx, gy) = SHAPE_GRID;
        let part = |x: usize, y: usize| (y * gy / h) * gx + x * gx / w;
        let pattern: Vec<f32> = (0..SHAPE_PARTS)
            .map(|k| 0.2 * (((k * 37) % 11) as f32 / 10.0 - 0.5))
            .collect();
        // The window's lights: a smooth cone, the corner part 0 unlit (below 5 % of the brightest parts).
        let lit = |x: usize, y: usize, c: usize| {
            if part(x, y) == 0 {
                return 1e-4;
            }
            let d = ((x as f32 - 32.0) / 40.0).powi(2) + ((y as f32 - 24.0) / 30.0).powi(2);
            (0.2 + 0.6 * (-d).exp()) * [1.0, 0.8, 0.6][c]
        };
        let m = Raster::from_fn(w, h, 3, lit);
        let s = Raster::from_fn(w, h, 3, |x, _, c| {
            0.01 * (1 + c) as f32 * x as f32 / w as f32
        });
        let own = Raster::from_fn(w, h, 3, |x, y, c| {
            1.7 * lit(x, y, c) * pattern[part(x, y)].exp() + s.data[(y * w + x) * 3 + c]
        });
        // By hand: block by block the photo over `M` is the part's pattern times the gain, so every quantile of a
        // part's log ratios is the pattern plus the gain's log.
        let d: Vec<f32> = (1..SHAPE_PARTS).map(|k| pattern[k] + 1.7f32.ln()).collect();
        let mut sorted = d.clone();
        sorted.sort_by(f32::total_cmp);
        let level = sorted[((sorted.len() - 1) as f64 * 0.5).round() as usize];
        let want = d.iter().map(|v| (v - level).abs()).sum::<f32>() / d.len() as f32;
        let got = lights_misfit(&own, &m, Some(&s), 0.5);
        assert!((got - want).abs() < 1e-4, "{got} vs {want}");
        assert!(want > 0.03, "the pattern is there to see: {want}");
        // The same lights, only brighter: nothing left to see; a window of another size: not measured.
        let brighter = Raster::from_fn(w, h, 3, |x, y, c| 1.3 * lit(x, y, c));
        assert!(lights_misfit(&brighter, &m, None, 0.5).abs() < 1e-5);
        let other = Raster::from_fn(w / 2, h, 3, lit);
        assert!(lights_misfit(&own, &other, Some(&s), 0.5).is_nan());
    }

    /// The streaming survey (a running reference, photos measured in batches on all workers) gives bit for bit what
    /// each photo gives measured on its own: its reference the 0.8 quantile of the finite levels of the 21 photos
    /// around it (the mission's first or last 21 at its ends; all of a shorter mission) selected afresh, its scene correlated with
    /// the scene of each of the 16 photos after it; for missions shorter and longer than the reference and than a
    /// batch, with masked (NaN) blocks.
    #[test]
    fn the_streaming_survey_is_each_photo_measured_on_its_own() {
        for frames in [1usize, 5, 21, 22, 40, 57] {
            let mut mission = mission(frames, 0.3, 4, 3);
            for (i, m) in mission.iter_mut().enumerate() {
                let at = (i * 7) % m.data.len();
                m.data[at] = f32::NAN;
            }
            let got = survey(&mission);
            let greys: Vec<Vec<f32>> = mission.iter().map(|m| grey_above(m, None)).collect();
            let n = 2 * REFERENCE_HALF + 1;
            let size = (mission[0].width, mission[0].height);
            let scenes: Vec<(f32, Vec<f32>)> = (0..frames)
                .map(|j| {
                    let first = j
                        .saturating_sub(REFERENCE_HALF)
                        .min(frames.saturating_sub(n));
                    let around = &greys[first..(first + n).min(frames)];
                    let reference: Vec<f32> = (0..greys[j].len())
                        .map(|b| {
                            let mut v: Vec<f32> = around
                                .iter()
                                .map(|g| g[b])
                                .filter(|v| v.is_finite())
                                .collect();
                            quantile(&mut v, REFERENCE_QUANTILE)
                        })
                        .collect();
                    let ratio = lit_ratios(&greys[j], &reference);
                    (
                        dark_share(
                            &judged_ratios(&ratio, &greys[j], &reference, None, size),
                            size,
                        ),
                        scene(&ratio, size),
                    )
                })
                .collect();
            assert_eq!(got.len(), frames);
            for j in 0..frames {
                assert_eq!(
                    got[j].coverage.to_bits(),
                    scenes[j].0.to_bits(),
                    "{frames} photos: photo {j}"
                );
                let want = shape(&greys[j], size);
                assert!(
                    got[j]
                        .shape
                        .iter()
                        .zip(&want)
                        .all(|(g, w)| g.to_bits() == w.to_bits()),
                    "{frames} photos: photo {j}'s shape"
                );
                for k in 0..MAX_LAG {
                    let want = scenes
                        .get(j + 1 + k)
                        .map_or(f32::NAN, |later| correlation(&scenes[j].1, &later.1));
                    let g = got[j].same_scene[k];
                    assert!(
                        g.to_bits() == want.to_bits() || (g.is_nan() && want.is_nan()),
                        "{frames} photos: photo {j} lag {k}: {g} vs {want}"
                    );
                }
            }
        }
    }

    /// A photo of `w`×`h` pixels (grey, linear) under a smooth light: sediment of level 1 and dark nodules (0.1)
    /// of radius `r` on a jittered grid covering about 40 % of it, reduced to 8×8 blocks by their means and by their
    /// medians (brute force).
    fn means_and_medians(w: usize, h: usize, r: f32) -> (Raster, Raster) {
        let cell = 2.6 * r;
        let dark = |x: f32, y: f32| {
            let (cx, cy) = ((x / cell).floor(), (y / cell).floor());
            let jitter = |a: f32, b: f32| {
                ((a * 12.9898 + b * 78.233).sin() * 43_758.547)
                    .fract()
                    .abs()
            };
            let (ox, oy) = (
                (cx + 0.3 + 0.4 * jitter(cx, cy)) * cell,
                (cy + 0.3 + 0.4 * jitter(cy, cx)) * cell,
            );
            (x - ox).powi(2) + (y - oy).powi(2) < r * r
        };
        let light = |x: f32, y: f32| {
            0.2 + 0.8 * (-((x / w as f32 - 0.5).powi(2) + (y / h as f32 - 0.5).powi(2)) * 4.0).exp()
        };
        let (bw, bh) = (w / 8, h / 8);
        let mut means = Raster::filled(bw, bh, 1, 0.0);
        let mut medians = Raster::filled(bw, bh, 1, 0.0);
        for by in 0..bh {
            for bx in 0..bw {
                let mut v: Vec<f32> = (0..64)
                    .map(|i| {
                        let (x, y) = ((bx * 8 + i % 8) as f32, (by * 8 + i / 8) as f32);
                        light(x, y) * if dark(x, y) { 0.1 } else { 1.0 }
                    })
                    .collect();
                means.data[by * bw + bx] = v.iter().sum::<f32>() / 64.0;
                v.sort_by(f32::total_cmp);
                medians.data[by * bw + bx] = 0.5 * (v[31] + v[32]);
            }
        }
        (means, medians)
    }

    /// Block means stand for block medians where the nodules are many blocks wide, and are refused where they are
    /// as fine as the blocks (the means' dark share far below the medians').
    #[test]
    fn block_means_stand_for_medians_only_where_clutter_is_coarse() {
        let (means, medians) = means_and_medians(640, 480, 24.0);
        assert!(means_stand_for_medians(&means, &medians, None));
        let (means, medians) = means_and_medians(640, 480, 4.0);
        assert!(!means_stand_for_medians(&means, &medians, None));
        // Itself, always; another size, never.
        assert!(means_stand_for_medians(&medians, &medians, None));
        let small = Raster::filled(3, 2, 1, 0.5);
        assert!(!means_stand_for_medians(&small, &medians, None));
    }

    #[test]
    fn the_dark_share_is_measured_against_the_neighbours_bright_side() {
        for c in [0.0, 0.15, 0.4] {
            let got = survey(&mission(30, c, 3, 4));
            let mut v: Vec<f32> = got.iter().map(|p| p.coverage).collect();
            let med = quantile(&mut v, 0.5);
            assert!(
                (med - c as f32).abs() < 0.08,
                "coverage {c}: measured {med}"
            );
        }
    }

    #[test]
    fn a_slow_camera_takes_more_photos_per_independent_sample() {
        // Patches of 6 blocks: moving 8 blocks a photo, consecutive photos see other ground at each block; moving
        // 1 block a photo, the same patch stays several photos: the window grows until it holds 7 samples.
        let fast = choose(&survey(&mission(60, 0.12, 6, 8)));
        let slow = choose(&survey(&mission(60, 0.12, 6, 1)));
        let (f, s) = (fast[30], slow[30]);
        assert_eq!(
            (f.window, f.quantile, f.rule),
            (BASE_WINDOW, 0.5, Rule::Sparse),
            "{f:?}"
        );
        assert!(f.photos_per_sample < 1.2, "{f:?}");
        assert!(
            s.window > BASE_WINDOW && s.photos_per_sample >= 2.0,
            "{s:?}"
        );
        assert_eq!(s.quantile, 0.5);
    }

    /// Scenes whose correlation comes back with a swing of the altitude every 5 photos (0.6 at lags 5, 10 and 15,
    /// negative between: the light cone's edge where it was a swing ago, as measured on the swing dive s02) are not
    /// a slow camera: the window stays 7 (with any correlation at any lag counted, photos 5 apart were one sample
    /// and the window grew to 31, capped). A slow camera's scene, whose correlation decays from 0.9 lag by lag,
    /// still grows the window.
    #[test]
    fn a_light_that_swings_with_the_altitude_is_not_a_slow_camera() {
        let with_lags = |corr: &dyn Fn(usize) -> f32| {
            let mut same_scene = [0.0; MAX_LAG];
            for (k, c) in same_scene.iter_mut().enumerate() {
                *c = corr(k + 1);
            }
            vec![
                PhotoSurvey {
                    coverage: 0.01,
                    same_scene,
                    shape: [0.0; SHAPE_PARTS],
                };
                60
            ]
        };
        let swing = with_lags(&|lag| 0.6 * (std::f32::consts::TAU * lag as f32 / 5.0).cos());
        assert!(swing[0].same_scene[4] >= SAME_SCENE && swing[0].same_scene[0] < PERSISTS);
        let c = choose_one(&swing, 30);
        assert_eq!(
            (c.window, c.samples, c.rule),
            (BASE_WINDOW, 7, Rule::Sparse),
            "{c:?}"
        );
        let slow = with_lags(&|lag| (0.9 - 0.1 * lag as f32).max(0.0));
        let c = choose_one(&slow, 30);
        assert!(
            c.window > BASE_WINDOW && c.photos_per_sample >= 2.0,
            "{c:?}"
        );
    }

    #[test]
    fn independent_samples_are_counted_by_brute_force() {
        // Photos 0..10; photo 3 repeats 2 and photo 4 repeats 3 (a chain: one scene), photo 9 repeats 5 (its scene
        // kept through photos 6–8). Photo 8 correlates with photo 1 but not through photos 2–7: no repeat.
        let mut photos = vec![
            PhotoSurvey {
                coverage: 0.0,
                same_scene: [0.0; MAX_LAG],
                shape: [0.0; SHAPE_PARTS],
            };
            10
        ];
        photos[2].same_scene[0] = 0.9;
        photos[3].same_scene[0] = 0.9;
        photos[5].same_scene[..4].copy_from_slice(&[0.4, 0.3, 0.25, 0.9]);
        photos[1].same_scene[6] = 0.9;
        assert_eq!(independent(&photos, 0..10), 7);
        // Broken persistence anywhere before the lag: no repeat.
        let mut broken = photos.clone();
        broken[5].same_scene[1] = 0.1;
        assert_eq!(independent(&broken, 0..10), 8);
        assert_eq!(
            independent(&photos, 3..10),
            5,
            "photo 3 starts the range: its own sample"
        );
        assert_eq!(independent(&photos, 6..10), 4);
        // The longer window that holds 7 samples around photo 4.
        let (n, found) = grow(&photos, 7, 31, 7, |n| window_range(4, n, 10));
        assert_eq!((n, found), (9, 7));
    }

    #[test]
    fn a_scene_that_comes_back_after_it_was_gone_is_the_lights() {
        let photo = |lags: &[f32]| {
            let mut p = PhotoSurvey {
                coverage: 0.0,
                same_scene: [0.0; MAX_LAG],
                shape: [0.0; SHAPE_PARTS],
            };
            p.same_scene[..lags.len()].copy_from_slice(lags);
            p
        };
        // A slow camera's view fades and goes below 0 (the band's ring), and does not return.
        let fades = photo(&[0.9, 0.75, 0.55, 0.35, 0.15, -0.1, -0.3, -0.2, -0.05, 0.1]);
        assert!(!lit_again(&fades, MAX_LAG));
        // Photos a swing apart: seen as one scene at lags 1–3, gone at 4, back at 7.
        let swing = photo(&[0.75, 0.7, 0.85, -0.2, -0.3, -0.2, 0.85, 0.6]);
        assert!(lit_again(&swing, MAX_LAG));
        assert!(
            !lit_again(&swing, 6),
            "the return lies beyond the photos read"
        );
        assert!(lit_again(&swing, 7));
        // Back only to below LIT_AGAIN: a view, not the lights.
        let faint = photo(&[0.8, 0.6, -0.1, 0.29]);
        assert!(!lit_again(&faint, MAX_LAG));
        // By brute force over a mission of 9: photo 0 is lit again, so photos 1–3 are samples of their own; with
        // photo 0 a fading view, only photo 0 and photos 4–8 are.
        let mut photos = vec![photo(&[]); 9];
        photos[0] = swing;
        assert_eq!(independent(&photos, 0..9), 9);
        photos[0] = fades;
        assert!(seen_again(&photos[0], 3) && !seen_again(&photos[0], 4));
        assert_eq!(independent(&photos, 0..9), 6);
        // Read only up to photo 6: the return at lag 7 is not seen, photo 0 is a view again.
        photos[0] = swing;
        assert_eq!(independent(&photos[..7], 0..7), 4);
    }

    #[test]
    fn a_dense_stretch_takes_the_quantile_and_its_window() {
        let dense = choose(&survey(&mission(40, 0.4, 3, 8)));
        let d = dense[20];
        assert!(d.coverage > 0.3 && d.coverage < 0.5, "{d:?}");
        assert!((d.quantile - (1.0 + d.coverage) / 2.0).abs() < 1e-6);
        let need = quantile_window(d.coverage as f64, d.quantile as f64, RISK, 1).unwrap();
        assert_eq!(d.window, need.min(MAX_AUTO_WINDOW));
        assert!(d.near.is_some_and(|k| k < d.window));
    }
}

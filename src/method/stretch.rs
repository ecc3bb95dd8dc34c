//! The window chosen per stretch of the mission (`--window auto`, the default of [`Method::Abyss`]): how much of
//! the seafloor is dark (nodules, burrows, shadows) and how far the camera moves between photos, measured on the
//! mission's block images before the correction ([`Surveyor`]), give each photo its window, the quantile its `M`
//! and per-photo gain take, and its near window ([`choose`]).
//!
//! The paper's window rule counts photos as independent samples. They are not when the camera moves less than a
//! dark object's extent between photos: a slow sledge sees the same burrow in most photos of a short window. So the
//! rule here counts ground covered: [`crate::method::window::quantile_window`] with the photos one independent
//! sample takes (the dark patches' extent along the motion over the step between photos).
//!
//! [`Method::Abyss`]: crate::method::baseline::Method::Abyss

use std::collections::VecDeque;

use serde::Serialize;

use crate::method::matching::{match_pair, reduction_to, texture, Texture};
use crate::method::raster::Raster;
use crate::method::refine::quantile;
use crate::method::window::{quantile_window, NEAR_MIN, NEAR_RISK};

/// Photos on each side of a photo whose block images make the reference its dark share is measured against.
pub const REFERENCE_HALF: usize = 10;
/// The reference's quantile over those photos, per block: the seafloor's bright side, above what dark patches
/// covering up to half of the photos at a block pull down.
pub const REFERENCE_QUANTILE: f64 = 0.8;
/// A block is dark when its level against the reference is below this share of the photo's seafloor level.
pub const DARK_RATIO: f32 = 0.6;
/// Photos on each side of a photo over which its stretch's coverage, step and dark extent are taken.
pub const STRETCH_HALF: usize = 10;
/// The stretch's coverage: this quantile of its photos' dark shares (a stretch is as dense as its denser photos).
pub const STRETCH_QUANTILE: f64 = 0.75;
/// Coverage below which a stretch on which the camera moves on keeps the default window and its median.
pub const ACT_COVERAGE: f32 = 0.25;
/// The longest window chosen (the engine's ring holds it; `n/2 + 1` full photos wait for it).
pub const MAX_AUTO_WINDOW: usize = 31;
/// The window of a stretch where nothing calls for more: the paper's 7 (today's default).
pub const BASE_WINDOW: usize = 7;
/// Breakdown risk of the window's quantile ([`quantile_window`]).
pub const RISK: f64 = 0.01;
/// Long side (block pixels) up to which block images are matched for the motion without reduction.
const MATCH_SIDE: usize = 192;

/// What the survey measured on one photo.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PhotoSurvey {
    /// Share of the photo's blocks darker than [`DARK_RATIO`] of its seafloor level, against the reference of its
    /// neighbours' bright side.
    pub coverage: f32,
    /// Shift from the previous photo, in blocks (`None`: first photo, or no trusted match).
    pub step: Option<f32>,
    /// Mean length, in blocks, of the runs of dark blocks along the motion (along the longer side without one).
    pub dark_extent: f32,
}

/// The streaming pass over a mission's block images (bounded memory: `2·`[`REFERENCE_HALF`]` + 1` grey block
/// images). Push each photo's block medians (linear light) in mission order, then [`Surveyor::finish`].
pub struct Surveyor {
    s_low: Option<Raster>,
    /// Grey `M − S`-like levels of the last photos, with their first photo's number.
    greys: VecDeque<Vec<f32>>,
    size: (usize, usize),
    pushed: usize,
    previous: Option<Texture>,
    /// Per photo: the shift from the previous one (blocks, both axes), when trusted.
    shifts: Vec<Option<(f32, f32)>>,
    done: Vec<PhotoSurvey>,
}

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
            greys: VecDeque::new(),
            size: (0, 0),
            pushed: 0,
            previous: None,
            shifts: Vec::new(),
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
        let shift = fits.then(|| self.motion(low)).flatten();
        self.shifts.push(shift);
        self.greys.push_back(grey);
        self.pushed += 1;
        let n = 2 * REFERENCE_HALF + 1;
        if self.greys.len() > n {
            self.greys.pop_front();
        }
        if self.greys.len() == n {
            // Every photo whose reference is these photos: the first `REFERENCE_HALF + 1` at once, then one each.
            while self.done.len() + REFERENCE_HALF < self.pushed {
                self.measure(self.done.len(), self.pushed - n);
            }
        }
    }

    /// The shift of this photo's texture from the previous photo's, when the match is trusted.
    fn motion(&mut self, low: &Raster) -> Option<(f32, f32)> {
        let scale = reduction_to(low.width, low.height, MATCH_SIDE);
        let t = texture(low, scale);
        let prev = self.previous.replace(t);
        let (prev, t) = (prev?, self.previous.as_ref()?);
        if (prev.width, prev.height) != (t.width, t.height) || t.width < 16 || t.height < 12 {
            return None;
        }
        let m = match_pair(&prev, t);
        m.accepted.then_some((m.shift.0 as f32, m.shift.1 as f32))
    }

    /// Photo `j`'s dark share against the reference of the photos held (the first of them is photo `first`).
    fn measure(&mut self, j: usize, first: usize) {
        let own = &self.greys[j - first];
        let reference = reference(&self.greys);
        let (coverage, dark) = dark_blocks(own, &reference);
        let axis_x = match self.shifts.get(j).copied().flatten() {
            Some((dx, dy)) => dx.abs() >= dy.abs(),
            None => self.size.0 >= self.size.1,
        };
        let dark_extent = mean_run(&dark, self.size, axis_x);
        let step = self.shifts[j].map(|(dx, dy)| dx.hypot(dy));
        self.done.push(PhotoSurvey {
            coverage,
            step,
            dark_extent,
        });
    }

    /// The survey of every photo pushed (shorter missions than the reference: against all their photos).
    pub fn finish(mut self) -> Vec<PhotoSurvey> {
        let first = self.pushed - self.greys.len();
        while self.done.len() < self.pushed {
            self.measure(self.done.len(), first);
        }
        self.done
    }
}

/// Per block, [`REFERENCE_QUANTILE`] of the photos' grey levels (NaN ones left out).
fn reference(greys: &VecDeque<Vec<f32>>) -> Vec<f32> {
    let len = greys.front().map_or(0, Vec::len);
    let mut col = Vec::with_capacity(greys.len());
    (0..len)
        .map(|b| {
            col.clear();
            col.extend(greys.iter().map(|g| g[b]).filter(|v| v.is_finite()));
            quantile(&mut col, REFERENCE_QUANTILE)
        })
        .collect()
}

/// The dark share of a photo's grey levels `own` against `reference`, and which blocks are dark. Blocks where the
/// reference is dim (under 5 % of its 95th percentile: corners the lights miss) are not judged.
fn dark_blocks(own: &[f32], reference: &[f32]) -> (f32, Vec<bool>) {
    let mut lit: Vec<f32> = reference
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let top = quantile(&mut lit, 0.95);
    let ratio: Vec<f32> = own
        .iter()
        .zip(reference)
        .map(|(&o, &r)| {
            if r.is_finite() && o.is_finite() && r > 0.05 * top && top > 0.0 {
                o / r
            } else {
                f32::NAN
            }
        })
        .collect();
    let mut judged: Vec<f32> = ratio.iter().copied().filter(|v| v.is_finite()).collect();
    if judged.is_empty() {
        return (0.0, vec![false; own.len()]);
    }
    let n = judged.len();
    // The seafloor's level: a first guess at the median, then at the median of the blocks not dark.
    let mut level = quantile(&mut judged, 0.5);
    for _ in 0..2 {
        let dark_n = judged.iter().filter(|&&r| r < DARK_RATIO * level).count();
        let c = dark_n as f64 / n as f64;
        level = quantile(&mut judged, ((1.0 + c) / 2.0).min(0.95));
    }
    let dark: Vec<bool> = ratio
        .iter()
        .map(|&r| r.is_finite() && r < DARK_RATIO * level)
        .collect();
    let dark_n = dark.iter().filter(|&&d| d).count();
    (dark_n as f32 / n as f32, dark)
}

/// Mean length of the runs of `true` along x (`axis_x`) or y in a `size` grid; 0 without any.
fn mean_run(dark: &[bool], (w, h): (usize, usize), axis_x: bool) -> f32 {
    let (outer, inner) = if axis_x { (h, w) } else { (w, h) };
    let (mut runs, mut total) = (0usize, 0usize);
    for o in 0..outer {
        let mut len = 0;
        for i in 0..=inner {
            let d = i < inner && dark[if axis_x { o * w + i } else { i * w + o }];
            if d {
                len += 1;
            } else if len > 0 {
                runs += 1;
                total += len;
                len = 0;
            }
        }
    }
    if runs == 0 {
        0.0
    } else {
        total as f32 / runs as f32
    }
}

/// Why a photo has the window it has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rule {
    /// No survey of the mission before the correction (photos as they come, in memory): the default window 7 and
    /// its median.
    NoSurvey,
    /// Little dark seafloor and a camera that moves on: the default window 7 and its median.
    Sparse,
    /// The window by the quantile's rule ([`quantile_window`]) for the stretch's coverage and independent samples.
    Quantile,
    /// As [`Rule::Quantile`], but the rule asked for more than [`MAX_AUTO_WINDOW`] photos.
    Capped,
}

/// What `--window auto` chose for one photo.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Choice {
    /// Photos in its window (odd).
    pub window: usize,
    /// The quantile its window's `M` and its per-photo gain take.
    pub quantile: f32,
    /// Its near window (`None`: off).
    pub near: Option<usize>,
    /// Its stretch's coverage by dark patches.
    pub coverage: f32,
    /// Photos per independent sample on its stretch.
    pub photos_per_sample: usize,
    /// Why.
    pub rule: Rule,
}

impl Choice {
    /// The default window and median, for a mission without a survey.
    pub fn without_survey() -> Self {
        Choice {
            window: BASE_WINDOW,
            quantile: 0.5,
            near: crate::method::window::near_window(BASE_WINDOW, None),
            coverage: f32::NAN,
            photos_per_sample: 1,
            rule: Rule::NoSurvey,
        }
    }

    /// In words, for the console and the report.
    pub fn why(&self) -> String {
        let c = 100.0 * self.coverage;
        match self.rule {
            Rule::NoSurvey => "no survey of the mission before the correction: the window 7 and its median".into(),
            Rule::Sparse => format!(
                "{c:.0} % dark, {} photo(s) per independent sample: the window 7 and its median",
                self.photos_per_sample
            ),
            Rule::Quantile | Rule::Capped => format!(
                "{c:.0} % dark, {} photo(s) per independent sample: the {:.2} quantile of {} photos{}",
                self.photos_per_sample,
                self.quantile,
                self.window,
                if self.rule == Rule::Capped { " (capped)" } else { "" }
            ),
        }
    }
}

/// The values of `photos[range]` that `pick` gives, at quantile `q` (NaN without any).
fn stretch_quantile(
    photos: &[PhotoSurvey],
    range: std::ops::Range<usize>,
    q: f64,
    pick: impl Fn(&PhotoSurvey) -> Option<f32>,
) -> f32 {
    let mut v: Vec<f32> = photos[range].iter().filter_map(pick).collect();
    quantile(&mut v, q)
}

/// Each photo's window, quantile and near window from the mission's survey (see the module documentation).
pub fn choose(photos: &[PhotoSurvey]) -> Vec<Choice> {
    (0..photos.len())
        .map(|i| {
            let range = i.saturating_sub(STRETCH_HALF)..(i + STRETCH_HALF + 1).min(photos.len());
            let c = stretch_quantile(photos, range.clone(), STRETCH_QUANTILE, |p| {
                Some(p.coverage)
            });
            let step = stretch_quantile(photos, range.clone(), 0.5, |p| p.step);
            let extent = stretch_quantile(photos, range, 0.5, |p| Some(p.dark_extent));
            let pps = if step.is_finite() && step > 0.0 && extent.is_finite() {
                ((extent / step).round() as usize).max(1)
            } else {
                1
            };
            choice_for(if c.is_finite() { c } else { 0.0 }, pps)
        })
        .collect()
}

/// The window, quantile and near window for coverage `c` and `pps` photos per independent sample.
pub fn choice_for(c: f32, pps: usize) -> Choice {
    let c = c.clamp(0.0, 0.6);
    if c < ACT_COVERAGE && pps <= 1 {
        return Choice {
            coverage: c,
            photos_per_sample: pps,
            rule: Rule::Sparse,
            ..Choice::without_survey()
        };
    }
    let q = (1.0 + c as f64) / 2.0;
    let (window, rule) = match quantile_window(c as f64, q, RISK, pps) {
        Some(n) if n <= MAX_AUTO_WINDOW => (n.max(BASE_WINDOW), Rule::Quantile),
        _ => (MAX_AUTO_WINDOW, Rule::Capped),
    };
    let near = quantile_window(c as f64, q, NEAR_RISK, pps)
        .unwrap_or(window)
        .max(NEAR_MIN);
    Choice {
        window,
        quantile: q as f32,
        near: (near < window).then_some(near),
        coverage: c,
        photos_per_sample: pps,
        rule,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_are_counted_along_the_axis() {
        // 4×2: row 0 has a run of 3, row 1 a run of 1 — along x mean 2; along y runs of 1, 2 and 1.
        let d = [true, true, true, false, false, true, false, false];
        assert_eq!(mean_run(&d, (4, 2), true), 2.0);
        assert_eq!(mean_run(&d, (4, 2), false), 4.0 / 3.0);
        assert_eq!(mean_run(&[false; 8], (4, 2), true), 0.0);
    }
}

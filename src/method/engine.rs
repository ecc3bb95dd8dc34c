//! The whole method over a stream of photos in memory: photos go in one at a time, in mission order, and come out
//! corrected once the window around them is complete.
//!
//! ```
//! use abysslight::{Engine, Params, Window};
//! use abysslight::{Layout, Photo, Samples};
//!
//! let layout = Layout { width: 32, height: 24, channels: 3 };
//! let photo = |level: u8| Photo { layout, samples: Samples::U8(vec![level; 32 * 24 * 3]), alpha: None };
//! let mut engine = Engine::new(Params { window: Window::Fixed(3), ..Params::default() }, None, None)?;
//! let mut out = Vec::new();
//! for (i, level) in [100u8, 110, 120, 130].into_iter().enumerate() {
//!     out.extend(engine.push(photo(level), i)?); // photos come out once their window is complete
//! }
//! out.extend(engine.finish());
//! assert_eq!(out.iter().map(|c| c.tag).collect::<Vec<_>>(), vec![0, 1, 2, 3]);
//! # Ok::<(), abysslight::Error>(())
//! ```
//!
//! Memory: at most `n` low-resolution images in the ring buffer and at most `n/2 + 1` full-resolution photos
//! waiting for the photos after them (`n` at the start of a mission), whatever the mission's length.

use std::ops::Range;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::method::baseline::{polynomial_m, Method};
use crate::method::correct::{correct_with_offset, Blend, CorrectStats, NEGLIGIBLE_BLEND};
use crate::method::factor::{factor, lit_seafloor, upsample};
use crate::method::mask::{block_median_masked, fill_missing, Mask};
use crate::method::median::{block_median, stack_median, stack_quantile};
use crate::method::monitor::{pool_factor, pooled, Flag, Health, Monitor, Thresholds};
use crate::method::noise::{block_stats, level_by_light, Blended, NoiseModel};
use crate::method::outliers::bright_spots;
use crate::method::overlap::{chained_pairs, overlap_correction};
use crate::method::params::Facts;
pub use crate::method::params::Params;
use crate::method::raster::{Layout, Photo, Raster, Sample, Samples};
use crate::method::refine::{
    backscatter_scale, levelled_stack, near_shape, refine_factor, scaled, LEVEL_MIN_WINDOW,
};
use crate::method::ring::Ring;
use crate::method::scatter::{Prepared, Scatter};
use crate::method::stretch::Choice;
use crate::method::survey::{Survey, FIRST_DECIDED};
use crate::method::transfer::{Curve, Transfer};
use crate::method::window::near_range;

/// What the engine does with a photo it is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Use {
    /// Estimate its `F` and health, and correct it.
    Correct,
    /// Estimate its `F` and health, but do not correct it (an output that exists already, `--resume`): it comes
    /// out with `photo: None`.
    Estimate,
    /// Only a neighbour for the windows of other photos (a shard's halo): it never comes out.
    Context,
}

/// One photo out of the [`Engine`].
#[derive(Debug)]
pub struct Corrected<T> {
    /// What the caller pushed with the photo.
    pub tag: T,
    /// Position among the photos the engine accepted (0-based).
    pub index: usize,
    /// Photos (by `index`) whose median gave this photo's `F`.
    pub window: Range<usize>,
    /// The corrected photo (`None` for photos pushed with [`Use::Estimate`]).
    pub photo: Option<Photo>,
    /// `F` at block resolution, in linear light.
    pub factor: Raster,
    /// `F·C = M − S` of the window's own `M` (before the near window's shape and the per-photo refinements, as the
    /// monitor judged it): the seafloor as the lights show it, without backscatter (what `--save-factors` writes).
    pub lit: Raster,
    /// Health figures and flags of the estimate.
    pub health: Health,
    /// Floored pixels and clipped samples of the correction.
    pub stats: CorrectStats,
    /// Milliseconds spent on this photo's block median, temporal median and `F`.
    pub estimate_ms: f64,
    /// Milliseconds spent correcting it.
    pub correct_ms: f64,
    /// [`Method::Abyss`]: the scale applied to the water-column `S` per channel (empty for the other methods or
    /// without `S`).
    pub backscatter_scale: Vec<f32>,
    /// [`Method::Abyss`] with `denoise`: the noise and texture measured on the photo.
    pub noise: Option<NoiseModel>,
    /// With the window chosen per stretch ([`Params::auto_window`]): what the survey chose for this photo and why.
    pub choice: Option<Choice>,
}

struct Waiting<T> {
    tag: T,
    photo: Option<Photo>,
    use_: Use,
    downsample_ms: f64,
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1000.0
}

/// The method of Köser et al. on a stream of photos (see the module documentation).
pub struct Engine<T> {
    params: Params,
    /// `S` at full resolution, prepared for the correction pass.
    scatter: Option<Prepared>,
    /// `S` at block resolution, linear light.
    scatter_low: Option<Raster>,
    mask: Option<Mask>,
    /// One flag per block: the block holds a masked pixel (no noise-aware blend there).
    masked_blocks: Option<Vec<bool>>,
    /// `M` of [`Method::Mean`] (block resolution, linear light).
    mission_mean: Option<Raster>,
    /// Transfer tables for 8- and 16-bit photos.
    curves: (Curve, Curve),
    /// Linear light of every value an 8-bit block median can take (`s/2 · 1/255`, `s = 0..=510`), as
    /// `(value, linear)`: the block medians of an sRGB mission are converted by look-up instead of a `powf` each
    /// (half a million per 12 MP photo). Empty for a linear curve.
    median_linear_8: Vec<(f32, f32)>,
    /// `C` in linear light, for the mission's channel count (set by the first photo).
    colour: Vec<f32>,
    layout: Option<Layout>,
    monitor: Monitor,
    /// The window's block images and the photos waiting for theirs.
    ring: Ring<RingEntry, Waiting<T>>,
    /// `S` and the mission's mean at block resolution pooled like the ring's images for the monitor, made the first
    /// time they are needed (both stay the same for the whole mission).
    judged_fixed: Option<(Option<Raster>, Option<Raster>)>,
    /// With [`Params::auto_window`]: the survey that chooses each photo's window, quantile and near window, fed
    /// the engine's own block images as photos come ([`Survey`]) or given whole ([`Engine::set_survey`]).
    survey: Option<Survey>,
    /// [`Engine::finish`] was called: the mission is over.
    finished: bool,
    /// With `steps.overlaps`: the texture of the last photo's block medians, to match the next one against.
    previous_texture: Option<crate::method::matching::Texture>,
}

/// The table of `Engine::median_linear_8`: every value an 8-bit block median takes, computed as `block_median`
/// computes it (`(a + b)·0.5·(1/255)`), with its linear light. Empty for a linear curve.
pub(crate) fn median_linear_table(transfer: Transfer) -> Vec<(f32, f32)> {
    if transfer.is_linear() {
        return Vec::new();
    }
    let scale = 1.0 / <u8 as Sample>::MAX;
    (0..=510u16)
        .map(|s| {
            let v = s as f32 * 0.5 * scale;
            (v, transfer.to_linear(v))
        })
        .collect()
}

/// `transfer.to_linear(v)`, looked up in `table` (see `Engine::median_linear_8`) when `v` is one of its values.
fn median_to_linear(table: &[(f32, f32)], transfer: Transfer, v: f32) -> f32 {
    let j = (v * 510.0).round();
    match table.get(j as usize) {
        Some(&(key, lin)) if key.to_bits() == v.to_bits() => lin,
        _ => transfer.to_linear(v),
    }
}

/// A photo's `k`×`k` block medians in linear light, the pixels `mask` ignores left out (NaN where a whole block
/// is); `table` is [`median_linear_table`]`(transfer)`.
pub(crate) fn linear_block_medians(
    photo: &Photo,
    k: usize,
    mask: Option<&Mask>,
    transfer: Transfer,
    table: &[(f32, f32)],
) -> Raster {
    let l = photo.layout;
    let mut low = match (&photo.samples, mask) {
        (Samples::U8(v), None) => block_median(v, l.width, l.height, l.channels, k),
        (Samples::U16(v), None) => block_median(v, l.width, l.height, l.channels, k),
        (Samples::U8(v), Some(m)) => block_median_masked(v, l, k, m),
        (Samples::U16(v), Some(m)) => block_median_masked(v, l, k, m),
    };
    if !transfer.is_linear() {
        // The value computed exactly as the block median computes it is looked up; any other (16-bit samples, NaN
        // under a mask) is converted directly: the same result either way.
        for v in &mut low.data {
            *v = median_to_linear(table, transfer, *v);
        }
    }
    low
}

impl<T> Engine<T> {
    /// An engine for one mission. `scatter` is `S` (`None`: no backscatter removal); `mask` marks static pixels
    /// (overlays, vehicle parts), left out of every median, with `F` and `S` filled in smoothly beneath them.
    pub fn new(params: Params, scatter: Option<&Scatter>, mask: Option<Mask>) -> Result<Engine<T>> {
        params.validate()?;
        let n = params.window_length();
        // `auto` resolved (src/method/params.rs): the blocks from the photos' size where S or the mask knows it,
        // else at the first photo (`accept`); photos in memory declare no curve.
        let params = params.resolved(&Facts {
            size: scatter
                .map(|s| (s.layout.width, s.layout.height))
                .or(mask.as_ref().map(|m| (m.width, m.height))),
            masked: mask.is_some(),
            transfer: None,
        });
        let k = params.downsample.max(1);
        let transfer = params.curve();
        if let (Some(m), Some(s)) = (&mask, scatter) {
            if (m.width, m.height) != (s.layout.width, s.layout.height) {
                return Err(Error::Usage(format!(
                    "the mask is {}x{} but the scatter image is {}",
                    m.width, m.height, s.layout
                )));
            }
        }
        let scatter_low_codes = scatter.map(|s| {
            let mut low = match &mask {
                Some(m) => block_median_masked(&s.q, s.layout, k, m),
                None => s.downsampled(k),
            };
            fill_missing(&mut low);
            low
        });
        let prepared = scatter.map(|s| match (&mask, &scatter_low_codes) {
            // Under the mask, S holds whatever is burned into the water-column frames too: use the smooth fill.
            (Some(m), Some(low)) => {
                let smooth = upsample(low, k, s.layout.width, s.layout.height);
                s.with_pixels_from(&smooth, &m.ignore).prepare(transfer)
            }
            _ => s.prepare(transfer),
        });
        let scatter_low = scatter_low_codes.map(|mut low| {
            for v in &mut low.data {
                *v = transfer.to_linear(*v);
            }
            low
        });
        Ok(Engine {
            params,
            scatter: prepared,
            scatter_low,
            masked_blocks: mask.as_ref().map(|m| masked_blocks(m, k)),
            mask,
            mission_mean: None,
            curves: (Curve::new(transfer, 256), Curve::new(transfer, 65536)),
            median_linear_8: median_linear_table(transfer),
            colour: Vec::new(),
            layout: None,
            monitor: Monitor::new(Thresholds::default())
                .with_window(n)
                .with_gain(params.method == Method::Abyss && params.steps.photo_gain),
            ring: Ring::new(n),
            judged_fixed: None,
            survey: None,
            finished: false,
            previous_texture: None,
        }
        .with_own_survey())
    }

    /// With [`Params::auto_window`], the engine's own survey of the photos as they come: photo `i` waits for its
    /// decision ([`crate::method::survey::LOOK_AHEAD`] photos after it), so the ring holds the block images from the
    /// start of the oldest waiting photo's longest window to the newest.
    fn with_own_survey(mut self) -> Self {
        if self.params.window_is_auto() {
            self.survey = Some(Survey::new(self.scatter_low.as_ref()));
            self.ring = Ring::new(FIRST_DECIDED + 1);
        }
        self
    }

    /// The survey of the whole mission, made before its photos are pushed (a run over a folder surveys it first,
    /// from its JPEGs' block means where it can): its choices instead of the engine's own survey as photos come, so
    /// that no photo waits for the decision and the ring holds only the longest window chosen. Only with
    /// [`Params::auto_window`] and [`Method::Abyss`] (otherwise ignored); refused once photos were pushed, or
    /// when the survey is not finished ([`Survey::finish`]).
    pub fn set_survey(&mut self, survey: Survey) -> Result<()> {
        if self.ring.pushed() > 0 {
            return Err(Error::Usage(
                "the survey of a mission is set before its first photo".into(),
            ));
        }
        if !self.params.window_is_auto() {
            return Ok(());
        }
        if !survey.finished() || survey.decided() == 0 {
            return Err(Error::Usage(
                "a survey given to the engine is finished and holds at least one photo".into(),
            ));
        }
        let longest = survey.choices().iter().map(|c| c.window).max().unwrap_or(1);
        self.ring = Ring::new(longest);
        self.survey = Some(survey);
        Ok(())
    }

    /// `S` at block resolution in linear light, as the engine and its survey take it (`None`: no `S`).
    pub fn scatter_low(&self) -> Option<&Raster> {
        self.scatter_low.as_ref()
    }

    /// The block medians the engine takes of `photo` (its blocks, mask and curve, linear light); `None` while the
    /// block size is not known (no size before the first photo) or when the photo does not fit the mask.
    pub fn block_image(&self, photo: &Photo) -> Option<Raster> {
        let l = photo.layout;
        let fits = self
            .mask
            .as_ref()
            .is_none_or(|m| (m.width, m.height) == (l.width, l.height));
        (self.params.downsample > 0 && fits).then(|| self.block_medians(photo))
    }

    /// The survey's block image from a JPEG's 8×8 block means (sRGB levels as shares of 255, `blocks` across and
    /// down, `channels` interleaved; [`crate::io::survey_block_means`]) instead of [`Engine::block_image`]'s block
    /// medians of the decoded photo: each `K`×`K` block the mean of the 8×8 means it covers, in linear light.
    /// `None` where the means cannot stand for the blocks: `K` not a multiple of 8, or a mask (its pixels are left
    /// out of the blocks).
    pub fn block_image_from_means(
        &self,
        means: &[f32],
        blocks: (usize, usize),
        channels: usize,
    ) -> Option<Raster> {
        if !self.takes_block_means() || means.len() != blocks.0 * blocks.1 * channels {
            return None;
        }
        let k = self.params.downsample;
        let m = k / 8;
        let (bw, bh) = (blocks.0.div_ceil(m), blocks.1.div_ceil(m));
        let curve = self.params.curve();
        let mut out = Raster::filled(bw, bh, channels, 0.0);
        for by in 0..bh {
            for bx in 0..bw {
                for c in 0..channels {
                    let (mut sum, mut n) = (0.0f32, 0.0f32);
                    for y in by * m..((by + 1) * m).min(blocks.1) {
                        for x in bx * m..((bx + 1) * m).min(blocks.0) {
                            sum += means[(y * blocks.0 + x) * channels + c];
                            n += 1.0;
                        }
                    }
                    out.data[(by * bw + bx) * channels + c] = curve.to_linear(sum / n);
                }
            }
        }
        Some(out)
    }

    /// Whether a photo's block image from block means sees the dark blocks its block image from block medians sees
    /// ([`crate::method::stretch::means_stand_for_medians`], against this engine's `S`).
    pub fn means_stand_for_medians(&self, means: &Raster, medians: &Raster) -> bool {
        crate::method::stretch::means_stand_for_medians(means, medians, self.scatter_low.as_ref())
    }

    /// Whether [`Engine::block_image_from_means`] takes 8×8 block means: `K` a multiple of 8, no mask.
    pub fn takes_block_means(&self) -> bool {
        let k = self.params.downsample;
        k > 0 && k.is_multiple_of(8) && self.mask.is_none()
    }

    /// Photo `i`'s choice, when the window is chosen per stretch (once the survey decided it).
    fn choice(&self, i: usize) -> Option<&Choice> {
        self.survey.as_ref()?.choice(i)
    }

    /// Photo `i`'s window length.
    fn window_of(&self, i: usize) -> usize {
        self.choice(i)
            .map_or(self.params.window_length(), |c| c.window)
    }

    /// The quantile photo `i`'s window takes as `M`.
    fn quantile_of(&self, i: usize) -> f32 {
        self.choice(i)
            .map_or(self.params.window_quantile(), |c| c.quantile)
    }

    /// Photo `i`'s near window (`None`: off); `--near-window 0` turns it off for chosen windows too.
    fn near_of(&self, i: usize) -> Option<usize> {
        match self.choice(i) {
            Some(_) if self.params.steps.near_window == Some(0) => None,
            Some(c) => c.near,
            None => self.params.near_window(),
        }
    }

    /// `M` of [`Method::Mean`]: the mission's mean image at block resolution, in linear light.
    pub fn set_mission_mean(&mut self, mean: Raster) {
        self.mission_mean = Some(mean);
    }

    /// The method's parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Size of the mission's photos, once the first was accepted.
    pub fn layout(&self) -> Option<Layout> {
        self.layout
    }

    /// Photos accepted so far.
    pub fn accepted(&self) -> usize {
        self.ring.pushed()
    }

    /// Photos accepted but not yet out (waiting for the photos after them).
    pub fn waiting(&self) -> usize {
        self.ring.waiting()
    }

    /// Give the next photo of the mission, to be corrected. Returns the photos whose window became complete, in
    /// order. A photo of another size than the first is refused with [`Error::Mismatch`] (its path empty: the
    /// caller knows it) and leaves the engine as it was; a first photo that does not fit `S` or the mask is
    /// refused with [`Error::Usage`].
    pub fn push(&mut self, photo: Photo, tag: T) -> Result<Vec<Corrected<T>>> {
        self.push_as(photo, tag, Use::Correct)
    }

    /// [`push`](Self::push), saying what to do with the photo.
    pub fn push_as(&mut self, photo: Photo, tag: T, use_: Use) -> Result<Vec<Corrected<T>>> {
        if self.finished {
            return Err(Error::Usage(
                "this engine's mission is over (finish() was called): an engine corrects one mission; make a new \
                 engine for the next"
                    .into(),
            ));
        }
        self.accept(&photo)?;
        let t = Instant::now();
        let low = self.block_medians(&photo);
        if let Some(s) = self.survey.as_mut().filter(|s| !s.finished()) {
            s.push(&low);
        }
        let judged = match pool_factor(self.params.downsample) {
            1 => None,
            p => Some(pooled(&low, p)),
        };
        // With `--bright-spots`: this photo's blocks of bright spots that move (laser dots, highlights).
        let spots = (self.params.method == Method::Abyss && self.params.steps.bright_spots)
            .then(|| bright_spots(&low))
            .filter(|s| !s.is_empty());
        let step = self.step_from_previous(&low);
        let waiting = Waiting {
            tag,
            photo: (use_ == Use::Correct).then_some(photo),
            use_,
            downsample_ms: ms(t),
        };
        self.ring.push(
            RingEntry {
                low,
                judged,
                spots,
                step,
            },
            waiting,
        );
        Ok(self.flush(false))
    }

    /// The end of the mission: every photo still waiting, corrected with the window shifted back from the end.
    pub fn finish(&mut self) -> Vec<Corrected<T>> {
        if let Some(s) = self.survey.as_mut() {
            s.finish();
        }
        self.finished = true;
        self.flush(true)
    }

    /// With `steps.overlaps`: the shift of the ground from the last photo to this one, in blocks, by phase
    /// correlation of the block medians' textures (`None`: no match, or the step is off).
    fn step_from_previous(&mut self, low: &Raster) -> Option<(f64, f64)> {
        use crate::method::matching::{match_pair, reduction, texture};
        if self.params.method != Method::Abyss || !self.params.steps.overlaps {
            return None;
        }
        let t = texture(low, reduction(low.width, low.height));
        let m = self.previous_texture.as_ref().map(|p| match_pair(p, &t));
        self.previous_texture = Some(t);
        m.filter(|m| m.accepted).map(|m| m.shift)
    }

    /// Check a photo against the mission's size (the first photo sets it).
    fn accept(&mut self, photo: &Photo) -> Result<()> {
        photo.check()?;
        match self.layout {
            Some(l) if l != photo.layout => Err(Error::Mismatch {
                path: Default::default(),
                reason: format!(
                    "photo is {}, the mission's photos are {}; skipped (split mixed missions into one folder per \
                     camera setting)",
                    photo.layout, l
                ),
            }),
            Some(_) => Ok(()),
            None => {
                if let Some(s) = &self.scatter {
                    if s.layout != photo.layout {
                        return Err(Error::Usage(format!(
                            "scatter estimate is {}, but the survey photos are {}: water-column frames and \
                             survey photos must come from the same camera",
                            s.layout, photo.layout
                        )));
                    }
                }
                if let Some(m) = &self.mask {
                    if (m.width, m.height) != (photo.layout.width, photo.layout.height) {
                        return Err(Error::Usage(format!(
                            "the mask is {}x{} but the photos are {}",
                            m.width, m.height, photo.layout
                        )));
                    }
                }
                self.layout = Some(photo.layout);
                let (w, h) = (photo.layout.width, photo.layout.height);
                self.params = self.params.resolved(&Facts {
                    size: Some((w, h)),
                    masked: self.mask.is_some(),
                    transfer: None,
                });
                let transfer = self.params.curve();
                self.colour = self
                    .params
                    .seafloor_colour
                    .for_channels(photo.layout.channels)
                    .into_iter()
                    .map(|c| transfer.to_linear(c))
                    .collect();
                Ok(())
            }
        }
    }

    /// `M` of the photo whose block medians are `own`, from its window's `stack` (the mission's mean for
    /// [`Method::Mean`], the photo's own polynomial fit for [`Method::Polynomial`]), and whether its photos were
    /// levelled to one exposure first: with [`Method::Abyss`], where `may_level` and its exposure jumps
    /// ([`levelled_stack`]).
    fn window_m(
        &self,
        own: &Raster,
        stack: &[&Raster],
        s_low: Option<&Raster>,
        mission_mean: Option<&Raster>,
        q: f32,
        may_level: bool,
    ) -> (Raster, bool) {
        match (self.params.method, mission_mean) {
            (Method::Mean, Some(mean)) if mean.layout() == own.layout() => (mean.clone(), false),
            (Method::Polynomial, _) => (polynomial_m(own, s_low, self.params.degree), false),
            (Method::Abyss, _) => {
                let m = quantile_or_median(stack, q);
                if !(self.params.steps.level_exposures && may_level) {
                    return (m, false);
                }
                match levelled_stack(stack, &m, s_low, q as f64) {
                    Some(levelled) => (
                        quantile_or_median(&levelled.iter().collect::<Vec<_>>(), q),
                        true,
                    ),
                    None => (m, false),
                }
            }
            _ => (stack_median(stack), false),
        }
    }

    /// `m` (the window's `M` over the photos in `range`) with the blocks where bright spots held more than half
    /// of the window ([`crate::method::outliers`]) filled from the blocks
    /// around them, as under a mask. Elsewhere `m` stands: the quantile outvoted the spots. (Two ways that also
    /// changed the blocks where spots were fewer were measured and dropped: leaving them out of the quantile's
    /// count moved the `(1 + c)/2` quantile down wherever the simulator's bright particles were frequent, and
    /// ranking them above every value moved it up; both raised the residual pattern of high-contamination matrix
    /// dives, a09 by 1.15–1.75×: docs/evaluation.md, "Bright spots that move".)
    fn without_spots(&self, m: &mut Raster, range: &Range<usize>) {
        if !self.params.steps.bright_spots {
            return;
        }
        let entries: Vec<&RingEntry> = self.ring.in_range(range.clone()).collect();
        if entries.iter().all(|e| e.spots.is_none()) {
            return;
        }
        let (n, c) = (entries.len(), m.channels);
        let mut holes = false;
        // Counted once per block: a block's samples are NaN in every channel or in none (a mask leaves a block
        // without pixels in all of them).
        for (b, px) in m.data.chunks_exact_mut(c).enumerate() {
            let out = entries
                .iter()
                .filter(|e| e.spots.as_ref().is_some_and(|s| s[b]) && !e.low.data[b * c].is_nan())
                .count();
            if 2 * out > n {
                px.fill(f32::NAN);
                holes = true;
            }
        }
        if holes {
            fill_missing(m);
        }
    }

    /// `F = (M − S)/C`, with the blocks a mask left without samples filled from their neighbours.
    fn factor_of(&self, m: &Raster, s_low: Option<&Raster>) -> Raster {
        let mut f = factor(m, s_low, &self.colour);
        if self.mask.is_some() {
            fill_missing(&mut f);
        }
        f
    }

    /// The photo's `K`×`K` block medians, in linear light (masked pixels left out).
    fn block_medians(&self, photo: &Photo) -> Raster {
        linear_block_medians(
            photo,
            self.params.downsample,
            self.mask.as_ref(),
            self.params.curve(),
            &self.median_linear_8,
        )
    }

    /// Every waiting photo whose window is complete (all of them at the end of the mission).
    fn flush(&mut self, eof: bool) -> Vec<Corrected<T>> {
        let mut out = Vec::new();
        loop {
            // With the engine's own survey, a photo waits for its decision as well as for its window.
            let undecided = match (&self.survey, self.ring.front()) {
                (Some(s), Some(i)) => s.choice(i).is_none(),
                _ => false,
            };
            if undecided {
                break;
            }
            let (survey, window) = (&self.survey, self.params.window_length());
            let ready = self.ring.next_ready_by(eof, |i| {
                survey
                    .as_ref()
                    .and_then(|s| s.choice(i))
                    .map_or(window, |c| c.window)
            });
            let Some((i, w, range)) = ready else { break };
            if w.use_ != Use::Context {
                out.push(self.estimate_and_correct(i, w, range, eof));
            }
        }
        out
    }

    /// One photo's estimate and correction, the method as a chain of steps:
    ///
    /// 1. the paper: the window's `M` (with `--bright-spots` filled where spots held it) and `F = (M − S)/C`
    ///    ([`Engine::window_estimate`]);
    /// 2. the monitor's health figures on that `F` ([`Engine::judged`]), on another worker thread while the next
    ///    steps run (nothing of them depends on it);
    /// 3. with [`Method::Abyss`], the steps it adds, in order ([`Engine::abyss_steps`]);
    /// 4. the correction `A = (I − S)/F` of the photo ([`Engine::correct`]).
    fn estimate_and_correct(
        &mut self,
        i: usize,
        w: Waiting<T>,
        range: Range<usize>,
        eof: bool,
    ) -> Corrected<T> {
        let t = Instant::now();
        let WindowEstimate {
            m,
            f,
            lit,
            levelled,
        } = self.window_estimate(i, &range);
        let pooled = self.pooled_estimate(i, &range);
        let mut monitor = std::mem::take(&mut self.monitor);
        monitor.set_window(self.window_of(i), self.quantile_of(i));
        let mut health = Health::default();
        let mut photo = w.photo;
        let (estimate, estimate_ms, stats, correct_ms) = rayon::in_place_scope(|scope| {
            let judged = self.judged(i, (&lit, &f), pooled.as_ref());
            let (monitor, health) = (&mut monitor, &mut health);
            scope.spawn(move |_| {
                *health = monitor.observe_photo(judged.0, judged.1, judged.2, judged.3)
            });
            let estimate = match self.params.method {
                Method::Abyss => self.abyss_steps(i, &range, m, levelled, photo.as_ref()),
                _ => Estimate::of_window(f.clone(), self.params.factor_floor),
            };
            let estimate_ms = w.downsample_ms + ms(t);
            let t = Instant::now();
            let stats = photo
                .as_mut()
                .map_or_else(CorrectStats::default, |p| self.correct(p, &estimate));
            (estimate, estimate_ms, stats, ms(t))
        });
        self.monitor = monitor;
        let (photos, n) = (self.ring.pushed(), self.window_of(i));
        // No advice of a window longer than the photos the mission is known to hold.
        let holds = if photos.is_multiple_of(2) {
            photos.saturating_sub(1)
        } else {
            photos
        };
        for f in &mut health.flags {
            if let Flag::StructureAdded { longer, .. } = f {
                *longer = longer.filter(|&m| m <= holds);
            }
        }
        match self.choice(i) {
            Some(c) if c.samples < c.needed => health.flags.push(Flag::FewSamples {
                samples: c.samples,
                needed: c.needed,
                window: c.window,
                whole_mission: c.rule == crate::method::stretch::Rule::Short,
            }),
            None if eof && photos < n => {
                health.flags.push(Flag::ShortMission { photos, window: n })
            }
            _ => {}
        }
        let Estimate {
            f,
            mut scale,
            noise,
            ..
        } = estimate;
        if self.scatter_low.is_none() {
            scale.clear();
        }
        Corrected {
            tag: w.tag,
            index: i,
            window: range,
            photo,
            factor: f,
            lit,
            health,
            stats,
            estimate_ms,
            correct_ms,
            backscatter_scale: scale,
            noise,
            choice: self.choice(i).copied(),
        }
    }

    /// The block medians of the photos in `range`, in order.
    fn stack(&self, range: &Range<usize>) -> Vec<&Raster> {
        let stack: Vec<&Raster> = self.ring.in_range(range.clone()).map(|e| &e.low).collect();
        debug_assert_eq!(stack.len(), range.len(), "ring lost a photo of the window");
        stack
    }

    /// Photo `i`'s entry in the ring (it is in its own window).
    fn own(&self, i: usize) -> &RingEntry {
        self.ring
            .get(i)
            .expect("a photo's own block medians are in its window")
    }

    /// Step 1, the paper's: the window's `M` of photo `i` over the photos in `range` (with `--bright-spots` filled
    /// where spots held the window), `F = (M − S)/C` and `F·C = M − S`.
    fn window_estimate(&self, i: usize, range: &Range<usize>) -> WindowEstimate {
        let stack = self.stack(range);
        let s_low = self.scatter_low.as_ref();
        let q = self.quantile_of(i);
        let (mut m, levelled) = self.window_m(
            &self.own(i).low,
            &stack,
            s_low,
            self.mission_mean.as_ref(),
            q,
            stack.len() >= LEVEL_MIN_WINDOW,
        );
        self.without_spots(&mut m, range);
        let f = self.factor_of(&m, s_low);
        let lit = lit_seafloor(&f, &self.colour);
        WindowEstimate {
            m,
            f,
            lit,
            levelled,
        }
    }

    /// Step 2's `F` and `F·C` of photo `i` when the monitor judges pooled blocks (`None` when it judges the
    /// window's own): the monitor judges blocks of about 8 pixels whatever the block size (its thresholds were set
    /// there), so with smaller blocks it sees its own `M` and `F` from the window's block medians pooled to that
    /// size.
    fn pooled_estimate(&mut self, i: usize, range: &Range<usize>) -> Option<(Raster, Raster)> {
        let p = pool_factor(self.params.downsample);
        if p > 1 && self.judged_fixed.is_none() {
            self.judged_fixed = Some((
                self.scatter_low.as_ref().map(|s| pooled(s, p)),
                self.mission_mean.as_ref().map(|m| pooled(m, p)),
            ));
        }
        let own_j = self.own(i).judged.as_ref()?;
        let stack_j: Vec<&Raster> = self
            .ring
            .in_range(range.clone())
            .filter_map(|e| e.judged.as_ref())
            .collect();
        let (s_j, mean_j) = self
            .judged_fixed
            .as_ref()
            .expect("made above when the ring holds pooled images");
        let (m_j, _) = self.window_m(
            own_j,
            &stack_j,
            s_j.as_ref(),
            mean_j.as_ref(),
            self.quantile_of(i),
            stack_j.len() >= LEVEL_MIN_WINDOW,
        );
        let f_j = self.factor_of(&m_j, s_j.as_ref());
        let lit_j = lit_seafloor(&f_j, &self.colour);
        Some((f_j, lit_j))
    }

    /// Step 2's rasters for [`Monitor::observe_photo`] of photo `i`: its block medians, `F·C`, `S` and `F`, the
    /// window's own or, with `pooled` ([`Engine::pooled_estimate`]), pooled.
    fn judged<'a>(
        &'a self,
        i: usize,
        (lit, f): (&'a Raster, &'a Raster),
        pooled: Option<&'a (Raster, Raster)>,
    ) -> (&'a Raster, &'a Raster, Option<&'a Raster>, &'a Raster) {
        let own = self.own(i);
        match (own.judged.as_ref(), pooled) {
            (Some(own_j), Some((f_j, lit_j))) => {
                let s_j = self.judged_fixed.as_ref().and_then(|(s, _)| s.as_ref());
                (own_j, lit_j, s_j, f_j)
            }
            _ => (&own.low, lit, self.scatter_low.as_ref(), f),
        }
    }

    /// Step 3, what [`Method::Abyss`] adds to the paper, in order, on the window's `M` of photo `i` (`levelled`:
    /// its photos were levelled to one exposure): the near window's shape, the scale of `S`, `F` of both, the
    /// per-photo gain and the soft floor, then the noise model and its blend.
    fn abyss_steps(
        &self,
        i: usize,
        range: &Range<usize>,
        m: Raster,
        levelled: bool,
        photo: Option<&Photo>,
    ) -> Estimate {
        let stack = self.stack(range);
        let own = &self.own(i).low;
        let s_low = self.scatter_low.as_ref();
        let m = self.near_window_shape(i, range, own, m, levelled);
        let m = self.overlap_shape(range, m);
        let scale = match (self.params.steps.backscatter_scale, s_low) {
            (Some(v), Some(_)) => vec![v; m.channels],
            (None, Some(s)) => backscatter_scale(&stack, &m, s),
            _ => vec![1.0; m.channels],
        };
        let s_k = s_low.map(|s| scaled(s, &scale));
        let rescaled = scale.iter().any(|&v| v != 1.0);
        let mut f = self.factor_of(&m, if rescaled { s_k.as_ref() } else { s_low });
        // The per-photo gain at the window's quantile where the window is chosen per stretch (the median
        // elsewhere: docs/nodules.md).
        let gain_q = self.choice(i).map_or(0.5, |c| c.quantile as f64);
        refine_factor(&mut f, own, &m, s_k.as_ref(), &self.params.steps, gain_q);
        let noise = self.noise_model(photo, &f);
        let blended = noise
            .as_ref()
            .and_then(|model| self.blend(model, &f, own, s_k.as_ref(), gain_q > 0.5));
        Estimate {
            use_blend: blended.is_some() || rescaled,
            f,
            // The soft floor is in `F`: the kernel's floor only guards against 0.
            floor: 1e-6,
            scale,
            noise,
            blended,
        }
    }

    /// The window's `M` bent to the smooth shape of the near window's around the same photo
    /// ([`near_shape`]), when the near window is on and shorter than this photo's window. The near window is
    /// levelled where its own exposure jumps only when the window was (`levelled`): the ghosts levelling keeps
    /// out are a photo's scene, which the window's `M` gives and the smooth shape leaves out, while a window whose
    /// near window alone sees a jump is one where the light's swing turns, which the shape is there to follow
    /// (docs/method.md, step 8).
    fn near_window_shape(
        &self,
        i: usize,
        range: &Range<usize>,
        own: &Raster,
        m: Raster,
        levelled: bool,
    ) -> Raster {
        let Some(near) = self.near_of(i).filter(|&k| k < range.len()) else {
            return m;
        };
        let s_low = self.scatter_low.as_ref();
        let near_r = near_range(i, near, range);
        let (mut m_near, _) = self.window_m(
            own,
            &self.stack(&near_r),
            s_low,
            None,
            self.quantile_of(i),
            levelled,
        );
        self.without_spots(&mut m_near, &near_r);
        near_shape(&m, &m_near, s_low)
    }

    /// With `steps.overlaps`: `M − S` bent to the `F` that the overlaps of the window's photos give
    /// ([`crate::method::overlap`]), with the window's `M` as the prior for what they leave undetermined.
    fn overlap_shape(&self, range: &Range<usize>, mut m: Raster) -> Raster {
        if !self.params.steps.overlaps {
            return m;
        }
        let entries: Vec<&RingEntry> = self.ring.in_range(range.clone()).collect();
        let steps: Vec<Option<(f64, f64)>> = entries
            .iter()
            .enumerate()
            .map(|(j, e)| e.step.filter(|_| j > 0))
            .collect();
        let pairs = chained_pairs(&steps, m.width, m.height);
        let s_low = self.scatter_low.as_ref();
        let lit: Vec<Raster> = entries
            .iter()
            .map(|e| less_scatter(&e.low, s_low))
            .collect();
        let refs: Vec<&Raster> = lit.iter().collect();
        let prior = less_scatter(&m, s_low);
        // The overlaps' gains (`Overlaps::gains`) are not used: the per-photo gain stays the median's (taking theirs
        // instead measured worse on the nodule dives: docs/overlaps.md).
        let Some(overlaps) = overlap_correction(&refs, &pairs, &prior) else {
            return m;
        };
        let delta = &overlaps.delta;
        for ((v, p), d) in m.data.iter_mut().zip(&prior.data).zip(&delta.data) {
            if *p > 0.0 {
                *v += p * (d.exp() - 1.0);
            }
        }
        m
    }

    /// The noise and texture measured on the photo (with `denoise`), against its `F`.
    fn noise_model(&self, photo: Option<&Photo>, f: &Raster) -> Option<NoiseModel> {
        let k = self.params.downsample;
        let blocks = match (photo, self.params.steps.denoise) {
            (Some(p), true) => {
                // Every second block in both directions, fewer on large photos (about 2000 blocks sampled: plenty
                // for two medians, and the pass stays a small share of a 12 MP photo's time).
                let blocks = p.layout.width.div_ceil(k) * p.layout.height.div_ceil(k);
                let stride = ((blocks as f64 / 2000.0).sqrt() as usize).max(2);
                block_stats(p, k, stride, (&self.curves.0, &self.curves.1))
            }
            _ => Vec::new(),
        };
        NoiseModel::fit(&blocks, f).map(|m| m.with_texture_capped(&self.colour))
    }

    /// The blend of dim regions towards their local level (held more firmly to the channels' shared level where
    /// `dense`: the window was chosen for a dense field), with its levels evened out by light (`level_by_light`, by
    /// bins' trimmed means where `dense`); `None` where it changes nothing (no noise measured: most camera JPEGs),
    /// so the photo takes the plain path.
    fn blend(
        &self,
        model: &NoiseModel,
        f: &Raster,
        own: &Raster,
        s_k: Option<&Raster>,
        dense: bool,
    ) -> Option<Blended> {
        let keep = self.masked_blocks.as_deref();
        let k = self.params.downsample;
        let mut b = model.blend(f, own, s_k, &self.colour, k, keep, dense);
        if !b.weight.data.iter().any(|&w| w < 1.0 - NEGLIGIBLE_BLEND) {
            return None;
        }
        if self.params.steps.level_by_light {
            level_by_light(&mut b.level, f, &self.colour, keep, dense);
        }
        Some(b)
    }

    /// Step 4: `A = (I − S)/F` of the photo, in place, with the blend and the scale of `S` of the estimate.
    fn correct(&self, p: &mut Photo, e: &Estimate) -> CorrectStats {
        let (l, k) = (p.layout, self.params.downsample);
        let s = self.scatter.as_ref();
        let blend = e.use_blend.then_some(Blend {
            fields: e.blended.as_ref(),
            scatter_scale: &e.scale,
        });
        match &mut p.samples {
            Samples::U8(v) => correct_with_offset(v, l, s, &e.f, blend, k, e.floor, &self.curves.0),
            Samples::U16(v) => {
                correct_with_offset(v, l, s, &e.f, blend, k, e.floor, &self.curves.1)
            }
        }
    }
}

/// The paper's estimate of one photo ([`Engine::window_estimate`]).
struct WindowEstimate {
    /// The window's `M`.
    m: Raster,
    /// `F = (M − S)/C`.
    f: Raster,
    /// `F·C = M − S`.
    lit: Raster,
    /// The window's photos were levelled to one exposure before its `M` ([`levelled_stack`]).
    levelled: bool,
}

/// What corrects one photo: `F` and how it is applied.
struct Estimate {
    /// `F` at block resolution.
    f: Raster,
    /// The smallest `F` a pixel is divided by.
    floor: f32,
    /// The scale of `S` per channel (empty: none).
    scale: Vec<f32>,
    /// The noise and texture measured on the photo.
    noise: Option<NoiseModel>,
    /// The blend of dim regions.
    blended: Option<Blended>,
    /// Correct with the blend and the scale of `S` (else the plain `(I − S)/F`).
    use_blend: bool,
}

impl Estimate {
    /// The window's own `F`, applied plainly with the absolute floor (every method but [`Method::Abyss`]).
    fn of_window(f: Raster, floor: f32) -> Self {
        Estimate {
            f,
            floor,
            scale: Vec::new(),
            noise: None,
            blended: None,
            use_blend: false,
        }
    }
}

/// `r − S` (`r` itself without `S`).
fn less_scatter(r: &Raster, s: Option<&Raster>) -> Raster {
    let mut out = r.clone();
    if let Some(s) = s {
        for (v, s) in out.data.iter_mut().zip(&s.data) {
            *v -= s;
        }
    }
    out
}

/// One flag per `k`×`k` block: does the block, or one of its 8 neighbours, hold a masked pixel? (The margin
/// keeps the noise-aware blend off overlay pixels an automatic mask missed at its edge.)
fn masked_blocks(m: &Mask, k: usize) -> Vec<bool> {
    let (bw, bh) = (m.width.div_ceil(k), m.height.div_ceil(k));
    let mut hit = vec![false; bw * bh];
    for (i, &ignored) in m.ignore.iter().enumerate() {
        if ignored {
            hit[(i / m.width / k) * bw + (i % m.width) / k] = true;
        }
    }
    let mut out = vec![false; bw * bh];
    for by in 0..bh {
        for bx in 0..bw {
            out[by * bw + bx] = (by.saturating_sub(1)..(by + 2).min(bh))
                .any(|y| (bx.saturating_sub(1)..(bx + 2).min(bw)).any(|x| hit[y * bw + x]));
        }
    }
    out
}

/// One photo in the ring: its block medians (linear light), the same pooled for the monitor (when the blocks are
/// smaller than 8 pixels) and, with `--bright-spots` when it had any, its blocks of bright spots
/// ([`crate::method::outliers::bright_spots`]).
struct RingEntry {
    low: Raster,
    judged: Option<Raster>,
    spots: Option<Vec<bool>>,
    /// With `steps.overlaps`: the shift of the ground from the photo before, in blocks (`None`: no match).
    step: Option<(f64, f64)>,
}

/// The window's `M` at quantile `q` (the median at 0.5).
fn quantile_or_median(stack: &[&Raster], q: f32) -> Raster {
    if q != 0.5 {
        stack_quantile(stack, q as f64)
    } else {
        stack_median(stack)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The look-up gives `to_linear` bit for bit: on every value the block median makes (including the
    /// neighbouring floats, which miss the table and are converted directly) and on NaN.
    #[test]
    fn median_to_linear_is_to_linear() {
        for t in [Transfer::Srgb, Transfer::Gamma(2.2)] {
            let table = median_linear_table(t);
            assert_eq!(table.len(), 511);
            for (a, b) in (0..=255u16).flat_map(|a| [(a, a), (a, a.saturating_add(1).min(255))]) {
                let v = (a as f32 + b as f32) * 0.5 * (1.0 / 255.0f32);
                for w in [v, f32::from_bits(v.to_bits() + 1), v * 0.999] {
                    assert_eq!(
                        median_to_linear(&table, t, w).to_bits(),
                        t.to_linear(w).to_bits(),
                        "{t:?} {w}"
                    );
                }
            }
            assert!(median_to_linear(&table, t, f32::NAN).is_nan());
        }
        assert!(median_linear_table(Transfer::Linear).is_empty());
    }

    /// The survey's block image from 8×8 block means: each `K`×`K` block the mean of the 8×8 means it covers (fewer
    /// at the right and bottom border), in linear light, against a brute-force sum; none for `K` not a multiple
    /// of 8 or means of another size.
    #[test]
    fn block_image_from_means_averages_the_means_it_covers() {
        let (bw, bh) = (5usize, 3usize);
        let means: Vec<f32> = (0..bw * bh * 3)
            .map(|i| 0.1 + ((i * 37) % 200) as f32 / 255.0)
            .collect();
        for k in [8usize, 16, 24, 4, 12] {
            let params = Params {
                downsample: k,
                transfer: Some(Transfer::Srgb),
                ..Params::default()
            };
            let engine = Engine::<usize>::new(params, None, None).unwrap();
            let got = engine.block_image_from_means(&means, (bw, bh), 3);
            assert_eq!(engine.takes_block_means(), k % 8 == 0, "K = {k}");
            let Some(got) = got else {
                assert!(k % 8 != 0, "K = {k}");
                continue;
            };
            let m = k / 8;
            assert_eq!(
                (got.width, got.height, got.channels),
                (bw.div_ceil(m), bh.div_ceil(m), 3)
            );
            for y in 0..got.height {
                for x in 0..got.width {
                    for c in 0..3 {
                        let covered: Vec<f32> = (0..bh)
                            .flat_map(|by| (0..bw).map(move |bx| (bx, by)))
                            .filter(|&(bx, by)| bx / m == x && by / m == y)
                            .map(|(bx, by)| means[(by * bw + bx) * 3 + c])
                            .collect();
                        let want = Transfer::Srgb
                            .to_linear(covered.iter().sum::<f32>() / covered.len() as f32);
                        let v = got.data[(y * got.width + x) * 3 + c];
                        assert!(
                            (v - want).abs() < 1e-6,
                            "K = {k} ({x}, {y}) {c}: {v} vs {want}"
                        );
                    }
                }
            }
            assert!(engine
                .block_image_from_means(&means[1..], (bw, bh), 3)
                .is_none());
        }
    }
}

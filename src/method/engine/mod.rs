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
//! waiting for the photos after them (`n` at the start of a mission), whatever the mission's length. With windows
//! chosen by altitude ([`Engine::push_at`]) the ring holds the `2n + 1` photos each window is chosen among, and up
//! to `n + 1` photos wait.

use std::time::Instant;

mod estimate;
mod lasers;

use lasers::Lasers;
pub(crate) use lasers::LASER_PHOTOS;

use crate::error::{Error, Result};
use crate::method::altitude::waits_for;
use crate::method::baseline::Method;
use crate::method::blocks::{linear_block_medians, masked_blocks, median_linear_table};
use crate::method::chain::Seen;
use crate::method::correct::CorrectStats;
use crate::method::mask::Mask;
use crate::method::monitor::{pool_factor, pooled, Health, Monitor, Thresholds};
use crate::method::noise::NoiseModel;
use crate::method::outliers::{bright_spots, SpotPath};
use crate::method::params::Facts;
pub use crate::method::params::Params;
use crate::method::raster::{Layout, Photo, Raster};
use crate::method::ring::Ring;
use crate::method::scatter::{for_the_engine, Prepared, Scatter};
use crate::method::stretch::Choice;
use crate::method::survey::{Survey, FIRST_DECIDED};
use crate::method::transfer::Curve;

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
    /// The photos (by `index`) whose median gave this photo's `F`, and whether altitude chose them
    /// ([`crate::method::altitude`]).
    pub window: crate::method::members::Members,
    /// The altitude the photo was pushed with ([`Engine::push_at`]).
    pub altitude: Option<f32>,
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
    /// With the window chosen per stretch ([`Window::Auto`](crate::Window::Auto)): what the survey chose for this photo
    /// and why.
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
    ring: Ring<Seen, Waiting<T>>,
    /// `S` and the mission's mean at block resolution pooled like the ring's images for the monitor, made the first
    /// time they are needed (both stay the same for the whole mission).
    judged_fixed: Option<(Option<Raster>, Option<Raster>)>,
    /// With [`Window::Auto`](crate::Window::Auto): the survey that chooses each photo's window, quantile and near window, fed
    /// the engine's own block images as photos come ([`Survey`]) or given whole ([`Engine::set_survey`]).
    survey: Option<Survey>,
    /// [`Engine::finish`] was called: the mission is over.
    finished: bool,
    /// With `steps.overlaps`: the texture of the last photo's block medians, to match the next one against.
    previous_texture: Option<crate::method::matching::Texture>,
    /// The paths of laser dots left out of every window's `M` ([`Steps::laser_paths`](crate::Steps::laser_paths)).
    lasers: Lasers,
    /// Windows are chosen by altitude ([`Engine::expect_altitudes`], or the first photo came with one): a photo
    /// waits for the pool of photos its window is chosen among.
    by_altitude: bool,
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
        let (prepared, scatter_low) = for_the_engine(scatter, mask.as_ref(), k, transfer)?;
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
                .with_gain(params.method == Method::Abyss && params.steps.photo_gain)
                .with_levelling(params.method == Method::Abyss && params.steps.level_exposures),
            ring: Ring::new(n),
            judged_fixed: None,
            survey: None,
            finished: false,
            previous_texture: None,
            lasers: Lasers::Off,
            by_altitude: false,
        }
        .with_own_survey())
    }

    /// With [`Params::auto_window`], the engine's own survey of the photos as they come: photo `i` waits for its
    /// decision ([`crate::method::survey::LOOK_AHEAD`] photos after it), so the ring holds the block images from the
    /// start of the oldest waiting photo's longest window to the newest.
    fn with_own_survey(mut self) -> Self {
        if self.params.window_is_auto() {
            self.survey = Some(Survey::new(self.scatter_low.as_ref()));
            self.ring = Ring::new(self.ring_length());
            if self.params.steps.laser_paths {
                self.lasers = Lasers::Looking(SpotPath::new());
            }
        }
        self
    }

    /// What the window keeps of a photo's block image: the image, pooled for the monitor, its bright spots and the
    /// step from the photo before.
    fn seen(&mut self, low: Raster, altitude: Option<f32>) -> Seen {
        let judged = match pool_factor(self.params.downsample) {
            1 => None,
            p => Some(pooled(&low, p)),
        };
        // With `--bright-spots`: this photo's blocks of bright spots that move (laser dots, highlights).
        let spots = (self.params.method == Method::Abyss && self.params.steps.bright_spots)
            .then(|| bright_spots(&low))
            .filter(|s| !s.is_empty());
        let step = self.step_from_previous(&low);
        Seen {
            low,
            judged,
            spots,
            step,
            altitude,
        }
    }

    /// The survey of the whole mission, made before its photos are pushed (a run over a folder surveys it first,
    /// from its JPEGs' block means where it can): its choices instead of the engine's own survey as photos come, so
    /// that no photo waits for the decision and the ring holds only the longest window chosen. Only with
    /// [`Window::Auto`](crate::Window::Auto) and [`Method::Abyss`] (otherwise ignored); refused once photos were pushed, or
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
        self.survey = Some(survey);
        self.ring = Ring::new(self.ring_length());
        Ok(())
    }

    /// Choose windows by altitude ([`Engine::push_at`]) from the mission's first photo on, whether or not it has an
    /// altitude (a navigation log that starts late). Only with [`Method::Abyss`] (otherwise ignored); refused once
    /// photos were pushed.
    pub fn expect_altitudes(&mut self) -> Result<()> {
        if self.ring.pushed() > 0 {
            return Err(Error::Usage(
                "windows by altitude are chosen from the mission's first photo on".into(),
            ));
        }
        if self.params.method == Method::Abyss && !self.by_altitude {
            self.by_altitude = true;
            self.ring = Ring::new(self.ring_length());
        }
        Ok(())
    }

    /// The block images the ring holds: the longest window's (with windows by altitude, the pool it is chosen
    /// among), and with the engine's own survey those of the photos waiting for its decision.
    fn ring_length(&self) -> usize {
        let longest = match (&self.survey, self.params.window_is_auto()) {
            (Some(s), _) if s.finished() => s.choices().iter().map(|c| c.window).max().unwrap_or(1),
            (_, true) => crate::method::stretch::MAX_AUTO_WINDOW,
            _ => self.params.window_length(),
        };
        let longest = waits_for(longest, self.by_altitude);
        match &self.survey {
            Some(s) if !s.finished() => longest.max(FIRST_DECIDED + 1),
            _ => longest,
        }
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
        if !self.takes_block_means() {
            return None;
        }
        crate::method::blocks::from_means(
            means,
            blocks,
            channels,
            self.params.downsample,
            self.params.curve(),
        )
    }

    /// Whether a photo's block image from block means sees the dark blocks its block image from block medians sees
    /// (the survey's test, against this engine's `S`).
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
        self.push_at(photo, tag, use_, None)
    }

    /// [`push_as`](Self::push_as), with the photo's altitude above the seafloor in metres where it is known (a
    /// navigation log). With [`Method::Abyss`], where the altitude swings along the track, a photo's window is then
    /// chosen among the photos around it lit from the nearest heights ([`crate::method::altitude`]); a photo then
    /// waits for its window's length of photos after it, not half. Windows are chosen by altitude when the
    /// mission's first photo comes with an altitude, or after [`Engine::expect_altitudes`]; photos without one
    /// keep the window over time and are not chosen into others'. An altitude that is not a positive number is
    /// refused with [`Error::Usage`].
    pub fn push_at(
        &mut self,
        photo: Photo,
        tag: T,
        use_: Use,
        altitude: Option<f32>,
    ) -> Result<Vec<Corrected<T>>> {
        if let Some(a) = altitude.filter(|a| !(a.is_finite() && *a > 0.0)) {
            return Err(Error::Usage(format!(
                "a photo's altitude is a positive number of metres, got {a}"
            )));
        }
        if self.ring.pushed() == 0 && altitude.is_some() {
            self.expect_altitudes()?;
        }
        if self.finished {
            return Err(Error::Usage(
                "this engine's mission is over (finish() was called): an engine corrects one mission; make a new \
                 engine for the next"
                    .into(),
            ));
        }
        self.accept(&photo)?;
        let t = Instant::now();
        let mut low = self.block_medians(&photo);
        if let Some(s) = self.survey.as_mut().filter(|s| !s.finished()) {
            s.push(&low);
        }
        // The survey sees the photo whole; the windows without the paths of laser dots.
        self.look_for_lasers(Some(&low), false);
        if let Some(p) = self.laser_paths() {
            p.clear(&mut low);
        }
        let seen = self.seen(low, altitude);
        let waiting = Waiting {
            tag,
            photo: (use_ == Use::Correct).then_some(photo),
            use_,
            downsample_ms: ms(t),
        };
        self.ring.push(seen, waiting);
        Ok(self.flush(false))
    }

    /// The end of the mission: every photo still waiting, corrected with the window shifted back from the end.
    pub fn finish(&mut self) -> Vec<Corrected<T>> {
        self.look_for_lasers(None, true);
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
            let by_altitude = self.by_altitude;
            let ready = self.ring.next_ready_by(eof, |i| {
                waits_for(
                    survey
                        .as_ref()
                        .and_then(|s| s.choice(i))
                        .map_or(window, |c| c.window),
                    by_altitude,
                )
            });
            let Some((i, w, range)) = ready else { break };
            if w.use_ != Use::Context {
                out.push(self.estimate_and_correct(i, w, range, eof));
            }
        }
        out
    }
}

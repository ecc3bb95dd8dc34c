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
//!     out.extend(engine.push((photo(level), i))?); // photos come out once their window is complete
//! }
//! out.extend(engine.finish());
//! assert_eq!(out.iter().map(|c| c.tag).collect::<Vec<_>>(), vec![0, 1, 2, 3]);
//! # Ok::<(), abysslight::Error>(())
//! ```
//!
//! Memory: at most `n` low-resolution images in the ring buffer and at most `n/2 + 1` full-resolution photos
//! waiting for the photos after them (`n` at the start of a mission), whatever the mission's length. With windows
//! chosen by altitude (photos pushed with an altitude, [`PhotoIn::altitude`]) the ring holds the `2n + 1` photos
//! each window is chosen among, and up to `n + 1` photos wait (`2n + 1` at the start). With the window chosen per
//! stretch ([`Window::Auto`](crate::Window::Auto)) as photos come, a photo also waits for the survey's decision:
//! up to 41 photos at the start of a mission (until [`Engine::FIRST_DECIDED`] is pushed) and 26 after, or
//! with altitudes up to 63 at the start and 32 after (the longest window, 31, chosen by altitude).

use std::time::Instant;

mod estimate;
mod first_pass;
mod lasers;
mod photo_in;

pub(crate) use crate::method::steps::lasers::{too_few_warning, Found, LASER_PHOTOS};
pub(crate) use first_pass::FirstPass;
pub use photo_in::{PhotoIn, Use};

use crate::error::{Error, Result};
use crate::method::altitude::waits_for;
use crate::method::baseline::Method;
use crate::method::blocks::{linear_block_medians, masked_blocks, median_linear_table};
use crate::method::correct::CorrectStats;
use crate::method::mask::Mask;
use crate::method::monitor::{pool_factor, pooled, Health, Monitor, Thresholds};
use crate::method::params::Facts;
pub use crate::method::params::Params;
use crate::method::raster::{Layout, Photo, Raster};
use crate::method::ring::Ring;
use crate::method::scatter::{for_the_engine, Prepared, Scatter};
use crate::method::seen::Seen;
use crate::method::steps::blend::NoiseModel;
use crate::method::steps::lasers::{Lasers, Look};
use crate::method::steps::{bright_spots, overlaps::Registration};
use crate::method::stretch::Choice;
use crate::method::survey::{Survey, FIRST_DECIDED};
use crate::method::transfer::Curve;

/// One photo out of the [`Engine`].
#[derive(Debug)]
pub struct Corrected<T> {
    /// What the caller pushed with the photo.
    pub tag: T,
    /// Position among the photos the engine accepted (0-based).
    pub index: usize,
    /// The photos (by `index`) whose median gave this photo's `F`, and whether altitude chose them
    /// (docs/method.md, "Windows by altitude").
    pub window: crate::method::members::Members,
    /// The altitude the photo was pushed with ([`PhotoIn::altitude`]).
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
    /// With `steps.overlaps`: each photo registered against the one before ([`Registration`]).
    registration: Registration,
    /// The paths of laser dots left out of every window's `M` ([`Steps::laser_paths`](crate::Steps::laser_paths)).
    lasers: Lasers,
    /// Windows are chosen by altitude ([`Engine::expect_altitudes`], or the first photo came with one): a photo
    /// waits for the pool of photos its window is chosen among.
    by_altitude: bool,
}

impl<T> Engine<T> {
    /// Photos a stream waits for after a photo before the survey decides its window: the photos after it that its
    /// longest window holds, and the 10 photos after those that their measures need (25). The first photos wait
    /// longer, for the longest window from the mission's start: they are decided once photo
    /// [`Engine::FIRST_DECIDED`] is pushed.
    pub const LOOK_AHEAD: usize = crate::method::survey::LOOK_AHEAD;
    /// The photo whose push decides the mission's first photos, those whose longest window starts at the first
    /// photo (40: the 41st photo).
    pub const FIRST_DECIDED: usize = crate::method::survey::FIRST_DECIDED;

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
            registration: Registration::default(),
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
                self.lasers = Lasers::Looking(Look::new());
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
        let abyss = self.params.method == Method::Abyss;
        let spots = bright_spots::spots(&low, abyss && self.params.steps.bright_spots);
        let step = self
            .registration
            .step(&low, abyss && self.params.steps.overlaps);
        Seen {
            low,
            judged,
            spots,
            step,
            altitude,
        }
    }

    /// Choose windows by altitude ([`PhotoIn::altitude`]) from the mission's first photo on, whether or not it has an
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

    /// Give the next photo of the mission ([`PhotoIn`]: from `(photo, tag)` to be corrected, or with what to do
    /// with it and its altitude). Returns the photos whose window became complete, in order. A photo of another
    /// layout than the first is refused with [`Error::Mismatch`] (its path empty: the caller knows it) and leaves the
    /// engine as it was; a first photo that does not fit `S` or the mask, or an altitude that is not a positive
    /// number, is refused with [`Error::Usage`].
    pub fn push(&mut self, photo: impl Into<PhotoIn<T>>) -> Result<Vec<Corrected<T>>> {
        let PhotoIn {
            photo,
            tag,
            use_,
            altitude,
        } = photo.into();
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

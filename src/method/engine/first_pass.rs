//! What a run over a folder does before its photos are pushed, through the engine it prepares ([`FirstPass`]): the
//! engine's block images of photos (by block medians, or from a JPEG's block means) for the survey and for the
//! paths of laser dots, and what that pass found: the survey, the paths, the mission's mean.

use rayon::prelude::*;

use super::Engine;
use crate::error::{Error, Result};
use crate::method::raster::{Layout, Photo, Raster};
use crate::method::ring::Ring;
use crate::method::steps::lasers::{Found, Look, LASER_PHOTOS};
use crate::method::survey::Survey;

/// An engine lent to the first pass over a folder, before its photos are pushed ([`Engine::first_pass`]).
pub(crate) struct FirstPass<'a, T> {
    engine: &'a mut Engine<T>,
}

impl<T> Engine<T> {
    /// The engine lent to the first pass over a folder, before the photos are pushed.
    pub(crate) fn first_pass(&mut self) -> FirstPass<'_, T> {
        FirstPass { engine: self }
    }
}

impl<T> FirstPass<'_, T> {
    /// `S` at block resolution in linear light, as the engine and its survey take it (`None`: no `S`).
    pub(crate) fn scatter_low(&self) -> Option<&Raster> {
        self.engine.scatter_low.as_ref()
    }

    /// The block medians the engine takes of `photo` (its blocks, mask and curve, linear light); `None` while the
    /// block size is not known (no size before the first photo) or when the photo does not fit the mask.
    pub(crate) fn block_image(&self, photo: &Photo) -> Option<Raster> {
        let e = &self.engine;
        let l = photo.layout;
        let fits = e
            .mask
            .as_ref()
            .is_none_or(|m| (m.width, m.height) == (l.width, l.height));
        (e.params.downsample > 0 && fits).then(|| e.block_medians(photo))
    }

    /// The survey's block image from a JPEG's 8×8 block means (sRGB levels as shares of 255, `blocks` across and
    /// down, `channels` interleaved; [`crate::io::survey_block_means`]) instead of [`FirstPass::block_image`]'s
    /// block medians of the decoded photo: each `K`×`K` block the mean of the 8×8 means it covers, in linear light.
    /// `None` where the means cannot stand for the blocks: `K` not a multiple of 8, or a mask (its pixels are left
    /// out of the blocks).
    pub(crate) fn block_image_from_means(
        &self,
        means: &[f32],
        blocks: (usize, usize),
        channels: usize,
    ) -> Option<Raster> {
        if !self.takes_block_means() {
            return None;
        }
        let p = &self.engine.params;
        crate::method::blocks::from_means(means, blocks, channels, p.downsample, p.curve())
    }

    /// Whether a photo's block image from block means sees the dark blocks its block image from block medians sees
    /// (the survey's test, against this engine's `S`).
    pub(crate) fn means_stand_for_medians(&self, means: &Raster, medians: &Raster) -> bool {
        crate::method::stretch::means_stand_for_medians(means, medians, self.scatter_low())
    }

    /// Whether [`FirstPass::block_image_from_means`] takes 8×8 block means: `K` a multiple of 8, no mask.
    pub(crate) fn takes_block_means(&self) -> bool {
        let k = self.engine.params.downsample;
        k > 0 && k.is_multiple_of(8) && self.engine.mask.is_none()
    }

    /// The survey of the whole mission, made before its photos are pushed (from its JPEGs' block means where it
    /// can): its choices instead of the engine's own survey as photos come, so that no photo waits for the decision
    /// and the ring holds only the longest window chosen. Only with [`Window::Auto`](crate::Window::Auto) (otherwise
    /// ignored); refused once photos were pushed, or when the survey is not finished ([`Survey::finish`]).
    pub(crate) fn set_survey(&mut self, survey: Survey) -> Result<()> {
        let e = &mut *self.engine;
        if e.ring.pushed() > 0 {
            return Err(Error::Usage(
                "the survey of a mission is set before its first photo".into(),
            ));
        }
        if !e.params.window_is_auto() {
            return Ok(());
        }
        if !survey.finished() || survey.decided() == 0 {
            return Err(Error::Usage(
                "a survey given to the engine is finished and holds at least one photo".into(),
            ));
        }
        e.survey = Some(survey);
        e.ring = Ring::new(e.ring_length());
        Ok(())
    }

    /// `M` of [`Method::Mean`](crate::Method::Mean): the mission's mean image at block resolution, in linear light.
    pub(crate) fn set_mission_mean(&mut self, mean: Raster) {
        self.engine.mission_mean = Some(mean);
    }

    /// The paths of laser dots in the mission's first [`LASER_PHOTOS`] photos the engine accepts, looked for as the
    /// engine looks for them when it is given the photos as they come (one [`Look`], fed the same block images), and
    /// given to the engine instead of its own look ([`Engine::set_lasers`]). `low(self, i)` is the `i`-th of the
    /// mission's `count` photos' layout and block image (`None`: it does not decode, or does not fit), read a batch
    /// at a time in parallel and counted in order. Refused once photos were pushed.
    pub(crate) fn find_laser_paths(
        &mut self,
        count: usize,
        low: impl Fn(&Self, usize) -> Option<(Layout, Raster)> + Sync,
    ) -> Result<Found>
    where
        T: Sync,
    {
        let mut look = Look::new();
        let mut next = 0;
        while !look.full() && next < count {
            let end = (next + LASER_PHOTOS - look.photos()).min(count);
            let this = &*self;
            let lows: Vec<Option<(Layout, Raster)>> =
                (next..end).into_par_iter().map(|i| low(this, i)).collect();
            for (layout, low) in lows.iter().flatten() {
                if !look.full() {
                    look.add(*layout, low);
                }
            }
            next = end;
        }
        let found = look.decide();
        self.engine.set_lasers(found.clone())?;
        Ok(found)
    }
}

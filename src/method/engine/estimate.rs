//! One photo's estimate and correction, once its window is complete: the [`chain`] of the method on its window,
//! the monitor's judgement of the window's `M`, and `A = (I − S)/F`.

use std::ops::Range;
use std::time::Instant;

use super::{ms, Corrected, Engine, Waiting};
use crate::method::altitude::choose;
use crate::method::baseline::Method;
use crate::method::chain;
use crate::method::correct::{correct_with_offset, Blend, CorrectStats};
use crate::method::estimate::Estimate;
use crate::method::factor::{factor_filled, lit_seafloor};
use crate::method::members::Members;
use crate::method::monitor::{pool_factor, pooled, Flag, Health};
use crate::method::raster::{Photo, Raster, Samples};
use crate::method::seen::{Seen, Window};
use crate::method::window::window_range;

impl<T> Engine<T> {
    /// One photo's estimate and correction: its window's estimate ([`chain`]: the paper's, a baseline's or the
    /// default's steps in the order they run), then the correction `A = (I − S)/F` of the photo ([`Engine::correct`])
    /// while another worker thread has the monitor judge the window's `M` (nothing of the correction depends on it).
    pub(super) fn estimate_and_correct(
        &mut self,
        i: usize,
        w: Waiting<T>,
        range: Range<usize>,
        eof: bool,
    ) -> Corrected<T> {
        let t = Instant::now();
        let mut photo = w.photo;
        let members = self.members(i, &range);
        let estimate = {
            let window = self.window(i, &members);
            match self.params.method {
                Method::Abyss => chain::abyss(&window, photo.as_ref()),
                Method::Paper => chain::paper(&window),
                _ => chain::baseline(&window),
            }
        };
        let window_f = match self.params.method {
            Method::Abyss => self.factor_of(&estimate.window_m, self.scatter_low.as_ref()),
            _ => estimate.f.clone(),
        };
        let lit = lit_seafloor(&window_f, &self.colour);
        let estimate_ms = w.downsample_ms + ms(t);
        let pooled = self.pooled_estimate(i, &members);
        let mut monitor = std::mem::take(&mut self.monitor);
        monitor.set_window(self.window_of(i), self.quantile_of(i));
        monitor.set_views(self.choice(i).map(|c| c.photos_per_sample));
        let mut health = Health::default();
        let (stats, correct_ms) = rayon::in_place_scope(|scope| {
            let judged = self.judged(i, (&lit, &window_f), pooled.as_ref());
            let (monitor, health) = (&mut monitor, &mut health);
            scope.spawn(move |_| {
                *health = monitor.observe_photo(judged.0, judged.1, judged.2, judged.3)
            });
            let t = Instant::now();
            let stats = photo
                .as_mut()
                .map_or_else(CorrectStats::default, |p| self.correct(p, &estimate));
            (stats, ms(t))
        });
        self.monitor = monitor;
        self.flags_of_the_stream(i, eof, &mut health);
        let Estimate {
            f,
            mut scale,
            noise,
            ..
        } = estimate;
        if self.scatter_low.is_none() {
            scale.clear();
        }
        let chosen = self.by_altitude && !members.iter().copied().eq(self.by_time(i));
        Corrected {
            tag: w.tag,
            index: i,
            window: Members::new(members, chosen),
            altitude: self.own(i).altitude,
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

    /// The flags only the stream knows: a window short of independent samples, a mission shorter than the window
    /// given; no advice of a window longer than the photos the mission is known to hold; and with altitudes, those
    /// a jump of `F` came with.
    fn flags_of_the_stream(&self, i: usize, eof: bool, health: &mut Health) {
        let (photos, n) = (self.ring.pushed(), self.window_of(i));
        let holds = if photos.is_multiple_of(2) {
            photos.saturating_sub(1)
        } else {
            photos
        };
        let altitude_of = |j: usize| self.ring.get(j).and_then(|e| e.altitude);
        for f in &mut health.flags {
            match f {
                Flag::StructureAdded { longer, .. } => *longer = longer.filter(|&m| m <= holds),
                // With a navigation log, the altitudes the jump of `F` came with.
                Flag::FactorChange { altitude, .. } => {
                    *altitude = i.checked_sub(1).and_then(altitude_of).zip(altitude_of(i))
                }
                _ => {}
            }
        }
        // Where the do-no-harm check fell back to the window 7, the survey's count of views needs the photo's
        // support (`Monitor::supports_few_views`).
        let supported = |c: &crate::method::stretch::Choice| {
            c.rule != crate::method::stretch::Rule::Unsteady
                || self.monitor.supports_few_views(health)
        };
        match self.choice(i) {
            Some(c) if c.samples < c.needed && supported(c) => {
                health.flags.push(Flag::FewSamples {
                    samples: c.samples,
                    needed: c.needed,
                    window: c.window,
                    whole_mission: c.rule == crate::method::stretch::Rule::Short,
                })
            }
            None if eof && photos < n => {
                health.flags.push(Flag::ShortMission { photos, window: n })
            }
            _ => {}
        }
    }

    /// The photos of photo `i`'s window, once `range` is complete: its window, or where windows are chosen by
    /// altitude, the pool it is chosen among ([`crate::method::altitude::choose`]).
    fn members(&self, i: usize, range: &Range<usize>) -> Vec<usize> {
        if !self.by_altitude {
            return range.clone().collect();
        }
        choose(i, self.window_of(i), range.clone(), self.by_time(i), |j| {
            self.ring.get(j).and_then(|e| e.altitude)
        })
    }

    /// Photo `i`'s window over time, once it is complete: the photos nearest to it in time.
    fn by_time(&self, i: usize) -> Range<usize> {
        window_range(i, self.window_of(i), self.ring.pushed())
    }

    /// Photo `i`'s window over the photos `members` ([`Engine::members`]), as the chain's steps read it.
    fn window<'a>(&'a self, i: usize, members: &'a [usize]) -> Window<'a> {
        let seen: Vec<&Seen> = members
            .iter()
            .map(|&j| {
                self.ring
                    .get(j)
                    .expect("the ring holds the photos of a window")
            })
            .collect();
        Window {
            i,
            members,
            seen,
            own: self.own(i),
            s_low: self.scatter_low.as_ref(),
            colour: &self.colour,
            params: &self.params,
            quantile: self.quantile_of(i),
            near: self.near_of(i),
            // The per-photo gain at the window's quantile where the window is chosen per stretch (the median
            // elsewhere: docs/nodules.md).
            gain_quantile: self.choice(i).map_or(0.5, |c| c.quantile as f64),
            masked: self.mask.is_some() || self.laser_paths().is_some(),
            masked_blocks: self.masked_blocks.as_deref(),
            mission_mean: self.mission_mean.as_ref(),
            curves: (&self.curves.0, &self.curves.1),
        }
    }

    /// `F = (M − S)/C`, with the blocks a mask left without samples filled from their neighbours.
    fn factor_of(&self, m: &Raster, s_low: Option<&Raster>) -> Raster {
        factor_filled(
            m,
            s_low,
            &self.colour,
            self.mask.is_some() || self.laser_paths().is_some(),
        )
    }

    /// Photo `i`'s entry in the ring (it is in its own window).
    fn own(&self, i: usize) -> &Seen {
        self.ring
            .get(i)
            .expect("a photo's own block medians are in its window")
    }

    /// The monitor's `F` and `F·C` of photo `i` when it judges pooled blocks ([`chain::pooled`]; `None` when it
    /// judges the window's own), with `S` and the mission's mean pooled once for the mission.
    fn pooled_estimate(&mut self, i: usize, members: &[usize]) -> Option<(Raster, Raster)> {
        let p = pool_factor(self.params.downsample);
        if p > 1 && self.judged_fixed.is_none() {
            self.judged_fixed = Some((
                self.scatter_low.as_ref().map(|s| pooled(s, p)),
                self.mission_mean.as_ref().map(|m| pooled(m, p)),
            ));
        }
        chain::pooled(&self.window(i, members), self.judged_fixed.as_ref()?)
    }

    /// The rasters for [`Monitor::observe_photo`] of photo `i`: its block medians, `F·C`, `S` and `F`, the
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

    /// `A = (I − S)/F` of the photo, in place, with the blend and the scale of `S` of the estimate.
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

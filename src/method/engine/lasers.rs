//! The paths of laser dots: looked for in the mission's first photos (or given), then left out of every window's
//! `M`, with no noise-aware blend beside them.

use super::Engine;
use crate::error::{Error, Result};
use crate::method::outliers::{LaserPaths, SpotPath};
use crate::method::raster::Raster;
use crate::method::ring::Ring;
use crate::method::survey::FIRST_DECIDED;

/// Where an engine stands on the paths of laser dots.
pub(super) enum Lasers {
    /// Not looked for: off, or the window is not chosen per stretch.
    Off,
    /// The engine's own survey: counting the laser spots of the mission's first [`LASER_PHOTOS`] photos.
    Looking(SpotPath),
    /// Found (`None`: none), or given ([`Engine::set_laser_paths`]).
    Decided(Option<LaserPaths>),
}

/// The photos whose laser spots decide the paths of laser dots: those the engine's own survey holds when it makes
/// its first decision ([`Survey::FIRST_DECIDED`]), so that no photo waits longer for them (41).
pub const LASER_PHOTOS: usize = FIRST_DECIDED + 1;

impl<T> Engine<T> {
    /// The share of the frame's blocks on the paths of laser dots found in the mission's first 41 photos (a run
    /// over a folder finds them before the photos are pushed), once decided; `None` before, and when there are
    /// none. Their blocks are left out of every window's `M` and `F` is filled beneath them, as beneath a mask.
    pub fn laser_paths_share(&self) -> Option<f64> {
        self.laser_paths().map(LaserPaths::share)
    }

    /// The paths of laser dots, once decided ([`Engine::laser_paths_share`]).
    pub(crate) fn laser_paths(&self) -> Option<&LaserPaths> {
        match &self.lasers {
            Lasers::Decided(p) => p.as_ref(),
            _ => None,
        }
    }

    /// Whether the paths of laser dots are decided (found, found to be none, or given): always true when the
    /// engine does not look for them.
    pub fn laser_paths_decided(&self) -> bool {
        !matches!(self.lasers, Lasers::Looking(_))
    }

    /// The paths of laser dots found before the photos are pushed (a run over a folder finds them in the mission's
    /// first [`LASER_PHOTOS`] photos, as the engine would): instead of the engine's own look at its first photos.
    /// Only with [`Window::Auto`](crate::Window::Auto), [`Method::Abyss`](crate::Method::Abyss) and
    /// [`Steps::laser_paths`](crate::Steps::laser_paths) (otherwise ignored); `None`: no paths. Refused once photos
    /// were pushed.
    pub(crate) fn set_laser_paths(&mut self, paths: Option<LaserPaths>) -> Result<()> {
        if self.ring.pushed() > 0 {
            return Err(Error::Usage(
                "the paths of laser dots are set before the mission's first photo".into(),
            ));
        }
        if self.params.window_is_auto() && self.params.steps.laser_paths {
            if let Some(p) = &paths {
                self.blend_off_near(p);
            }
            self.lasers = Lasers::Decided(paths);
        }
        Ok(())
    }

    /// Count `low`'s laser spots while looking for the paths; decide at the last of [`LASER_PHOTOS`] (or with
    /// `end`, at the end of a shorter mission), and then leave the paths out of the block images already held.
    pub(super) fn look_for_lasers(&mut self, low: Option<&Raster>, end: bool) {
        let Lasers::Looking(path) = &mut self.lasers else {
            return;
        };
        if let Some(low) = low {
            path.add(low);
        }
        if !end && path.photos() < LASER_PHOTOS {
            return;
        }
        let paths = LaserPaths::of(path);
        if let Some(p) = &paths {
            self.blend_off_near(p);
            // Photos held are seen again without the paths, in order (the overlaps' steps chain them).
            self.previous_texture = None;
            let mut held = std::mem::replace(&mut self.ring, Ring::new(0));
            held.map_entries(|seen| {
                let mut low = seen.low;
                p.clear(&mut low);
                self.seen(low, seen.altitude)
            });
            self.ring = held;
        }
        self.lasers = Lasers::Decided(paths);
    }

    /// No noise-aware blend on the paths of laser dots and next to them, as next to a mask.
    pub(super) fn blend_off_near(&mut self, p: &LaserPaths) {
        self.masked_blocks = Some(match self.masked_blocks.take() {
            Some(m) => m.iter().zip(p.near()).map(|(&a, b)| a || b).collect(),
            None => p.near(),
        });
    }
}

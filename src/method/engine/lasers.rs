//! The engine's side of the paths of laser dots ([`crate::method::steps::lasers`]): its own look at the mission's
//! first photos (or the paths given), then the paths left out of every window's `M`, with no noise-aware blend
//! beside them.

use super::Engine;
use crate::error::{Error, Result};
use crate::method::outliers::LaserPaths;
use crate::method::raster::Raster;
use crate::method::ring::Ring;
use crate::method::steps::lasers::{Found, Lasers};

impl<T> Engine<T> {
    /// The share of the frame's blocks on the paths of laser dots found in the mission's first 41 photos (a run
    /// over a folder finds them before the photos are pushed), once decided; `None` before, and when there are
    /// none. Their blocks are left out of every window's `M` and `F` is filled beneath them, as beneath a mask.
    pub fn laser_paths_share(&self) -> Option<f64> {
        self.laser_paths().map(LaserPaths::share)
    }

    /// Whether the paths of laser dots are decided (found, found to be none, or given): always true when the
    /// engine does not look for them.
    pub fn laser_paths_decided(&self) -> bool {
        !matches!(self.lasers, Lasers::Looking(_))
    }

    /// The paths of laser dots, once decided ([`Engine::laser_paths_share`]).
    pub(crate) fn laser_paths(&self) -> Option<&LaserPaths> {
        self.lasers.paths()
    }

    /// What the look for the paths of laser dots decided, once it did (`None` before, and when not looking).
    pub(crate) fn lasers_found(&self) -> Option<&Found> {
        match &self.lasers {
            Lasers::Decided(found) => Some(found),
            _ => None,
        }
    }

    /// The paths of laser dots found before the photos are pushed ([`super::FirstPass::find_laser_paths`]): instead
    /// of the engine's own look at its first photos. Only with [`Window::Auto`](crate::Window::Auto),
    /// [`Method::Abyss`](crate::Method::Abyss) and [`Steps::laser_paths`](crate::Steps::laser_paths) (otherwise
    /// ignored). Refused once photos were pushed.
    pub(super) fn set_lasers(&mut self, found: Found) -> Result<()> {
        if self.ring.pushed() > 0 {
            return Err(Error::Usage(
                "the paths of laser dots are set before the mission's first photo".into(),
            ));
        }
        if self.params.window_is_auto() && self.params.steps.laser_paths {
            if let Found::Paths(p) = &found {
                self.blend_off_near(p);
            }
            self.lasers = Lasers::Decided(found);
        }
        Ok(())
    }

    /// With the engine's own look: count `low` (the accepted photo's block image); once decided (at the last of the
    /// photos looked at, or with `end` at the end of a shorter mission), leave the paths out of the block images
    /// already held.
    pub(super) fn look_for_lasers(&mut self, low: Option<&Raster>, end: bool) {
        let low = self.layout.zip(low);
        let Some(found) = self.lasers.look(low, end) else {
            return;
        };
        if let Found::Paths(p) = found.clone() {
            self.blend_off_near(&p);
            // Photos held are seen again without the paths, in order (the overlaps' steps chain them).
            self.registration.restart();
            let mut held = std::mem::replace(&mut self.ring, Ring::new(0));
            held.map_entries(|seen| {
                let mut low = seen.low;
                p.clear(&mut low);
                self.seen(low, seen.altitude)
            });
            self.ring = held;
        }
    }

    /// No noise-aware blend on the paths of laser dots and next to them, as next to a mask.
    fn blend_off_near(&mut self, p: &LaserPaths) {
        self.masked_blocks = Some(match self.masked_blocks.take() {
            Some(m) => m.iter().zip(p.near()).map(|(&a, b)| a || b).collect(),
            None => p.near(),
        });
    }
}

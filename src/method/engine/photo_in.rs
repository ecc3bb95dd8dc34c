//! What goes into the [`Engine`]: one photo at a time ([`PhotoIn`]), and what to do with it ([`Use`]).

use super::Engine;
use crate::error::{Error, Result};
use crate::method::params::Facts;
use crate::method::raster::Photo;

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

/// One photo given to the [`Engine`] ([`Engine::push`]): the photo, what comes back with it, what to do with it,
/// and its altitude. Made from `(photo, tag)` (to be corrected, no altitude), `(photo, tag, use)`,
/// `(photo, tag, altitude)` or `(photo, tag, use, altitude)`.
#[derive(Debug)]
pub struct PhotoIn<T> {
    /// The photo, of the mission's layout (the first photo sets it).
    pub photo: Photo,
    /// What the caller gets back with it ([`Corrected::tag`](crate::Corrected::tag)).
    pub tag: T,
    /// What the engine does with it.
    pub use_: Use,
    /// Its altitude above the seafloor in metres, where known (a navigation log). With [`Method::Abyss`](crate::Method::Abyss), where the
    /// altitude swings along the track, a photo's window is then chosen among the photos around it lit from the
    /// nearest heights (docs/method.md, "Windows by altitude"); a photo then waits for its window's length of photos after
    /// it, not half. Windows are chosen by altitude when the mission's first photo comes with an altitude, or after
    /// [`Engine::expect_altitudes`]; photos without one keep the window over time and are not chosen into others'.
    /// An altitude that is not a positive number is refused with [`Error::Usage`].
    pub altitude: Option<f32>,
}

impl<T> From<(Photo, T)> for PhotoIn<T> {
    fn from((photo, tag): (Photo, T)) -> Self {
        (photo, tag, Use::Correct, None).into()
    }
}

impl<T> From<(Photo, T, Use)> for PhotoIn<T> {
    fn from((photo, tag, use_): (Photo, T, Use)) -> Self {
        (photo, tag, use_, None).into()
    }
}

impl<T> From<(Photo, T, Option<f32>)> for PhotoIn<T> {
    fn from((photo, tag, altitude): (Photo, T, Option<f32>)) -> Self {
        (photo, tag, Use::Correct, altitude).into()
    }
}

impl<T> From<(Photo, T, Use, Option<f32>)> for PhotoIn<T> {
    fn from((photo, tag, use_, altitude): (Photo, T, Use, Option<f32>)) -> Self {
        PhotoIn {
            photo,
            tag,
            use_,
            altitude,
        }
    }
}

impl<T> Engine<T> {
    /// Check a photo against the mission's size (the first photo sets it).
    pub(super) fn accept(&mut self, photo: &Photo) -> Result<()> {
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
}

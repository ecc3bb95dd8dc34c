//! The paths of laser dots (`Steps::laser_paths`): looked for in the mission's first [`LASER_PHOTOS`] photos, then
//! left out of every window's `M`, with no noise-aware blend beside them ([`crate::method::outliers::LaserPaths`]).
//!
//! One look, whoever feeds it: the engine its own block images as photos come, a run over a folder the block
//! images of the mission's first photos before the photos are pushed. Either way it counts exactly the photos the
//! engine accepts, in mission order: a photo of another layout than the first (another size, or grey among colour
//! photos) is passed over, as the engine refuses it.

use rayon::prelude::*;

use crate::method::blocks::{linear_block_medians, median_linear_table};
use crate::method::mask::Mask;
use crate::method::outliers::{LaserPaths, SpotPath, LASER_MIN_BLOCKS, LASER_MIN_PHOTOS};
use crate::method::raster::{Layout, Photo, Raster};
use crate::method::survey::FIRST_DECIDED;
use crate::method::transfer::Transfer;

/// The photos whose laser spots decide the paths of laser dots: those the engine's own survey holds when it makes
/// its first decision ([`Engine::FIRST_DECIDED`](crate::Engine::FIRST_DECIDED)), so that no photo waits longer for them (41).
pub const LASER_PHOTOS: usize = FIRST_DECIDED + 1;

/// The look for the paths of laser dots in a mission's first [`LASER_PHOTOS`] photos.
#[derive(Debug, Clone, Default)]
pub(crate) struct Look {
    path: SpotPath,
    /// The mission's layout: the first photo's.
    layout: Option<Layout>,
}

/// What a look decided.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Found {
    /// The paths of laser dots.
    Paths(LaserPaths),
    /// None (no laser-coloured spots came back to the same blocks).
    None,
    /// Laser-coloured spots came back to the same blocks, but in a mission of `photos`, fewer than
    /// [`LASER_MIN_PHOTOS`]: too few to tell the paths of laser dots from something red on the seafloor, so no
    /// paths are left out of `F`.
    TooFew {
        /// The photos looked at.
        photos: usize,
    },
}

impl Look {
    /// Nothing counted yet.
    pub(crate) fn new() -> Look {
        Look::default()
    }

    /// Count the laser spots of the block image `low` of the mission's next photo, of `layout`; a photo of another
    /// layout than the first counted is passed over (returns `false`), as the engine refuses it.
    pub(crate) fn add(&mut self, layout: Layout, low: &Raster) -> bool {
        if *self.layout.get_or_insert(layout) != layout {
            return false;
        }
        self.path.add(low)
    }

    /// The photos counted.
    pub(crate) fn photos(&self) -> usize {
        self.path.photos()
    }

    /// Whether [`LASER_PHOTOS`] photos were counted: the look decides.
    pub(crate) fn full(&self) -> bool {
        self.photos() >= LASER_PHOTOS
    }

    /// The decision on the photos counted (all of a mission shorter than [`LASER_PHOTOS`]).
    pub(crate) fn decide(&self) -> Found {
        match LaserPaths::of(&self.path) {
            Some(p) => Found::Paths(p),
            None if self.photos() < LASER_MIN_PHOTOS && self.path.laser_blocks().is_some() => {
                Found::TooFew {
                    photos: self.photos(),
                }
            }
            None => Found::None,
        }
    }
}

/// The words on a mission too short for the paths of laser dots ([`Found::TooFew`]).
pub(crate) fn too_few_warning(photos: usize) -> String {
    format!(
        "laser dots: red or green bright spots came back to the same blocks in the {photos} photos of this \
         mission, but fewer than {LASER_MIN_PHOTOS} photos are too few to tell the paths of laser dots from \
         something coloured on the seafloor: they are not left out of F, and where most photos of a window had a \
         dot, F takes it (a stain where it is not); give --mask-auto to look for them as static content, or --mask \
         with their paths"
    )
}

/// The warning for the paths of laser dots the survey found ([`SpotPath`]) when they are not left out of `F`
/// (`--no-laser-paths`), if it found at least [`LASER_MIN_BLOCKS`].
pub(crate) fn kept_warning(path: &SpotPath) -> Option<String> {
    let (on, share) = path.on_path();
    (on >= LASER_MIN_BLOCKS).then(|| {
        format!(
            "laser dots: red or green bright spots came back to the same blocks ({:.1} % of the frame) in the {} \
             photos looked at, the paths of laser dots (or of something coloured that stays in view); where most \
             photos of a window had a dot, F takes it, and photos whose own dot is elsewhere get a stain there \
             (teal beside a red laser): leave out --no-laser-paths, or give --mask-auto, to keep those paths out of F \
             (docs/guide.md)",
            100.0 * share,
            path.photos()
        )
    })
}

/// `--mask-auto`'s look over the whole mission: the blocks where laser-coloured bright spots came back over `photos`
/// (spread over the mission, of `fixed`'s size; [`SpotPath`]: laser dots that wander with the altitude), as a pixel
/// mask; `None` when there are none. Block medians of `k` pixels, leaving out what `fixed` (the static pixels)
/// ignores, in linear light.
pub(crate) fn paths_over_the_mission(
    photos: impl ParallelIterator<Item = Photo>,
    fixed: &Mask,
    k: usize,
    transfer: Transfer,
) -> Option<Mask> {
    let table = median_linear_table(transfer);
    // Counted as the photos come (a count per block and thread), not kept: 400 block images of 12 MP photos would
    // take 0.9 GB.
    let path = photos
        .fold(SpotPath::new, |mut path, p| {
            path.add(&linear_block_medians(&p, k, Some(fixed), transfer, &table));
            path
        })
        .reduce(SpotPath::new, SpotPath::merge);
    let blocks = path.blocks();
    blocks
        .contains(&true)
        .then(|| Mask::from_blocks(&blocks, k, fixed.width, fixed.height))
}

/// Where an engine stands on the paths of laser dots.
#[derive(Debug, Clone)]
pub(crate) enum Lasers {
    /// Not looked for: off, or the window is not chosen per stretch.
    Off,
    /// The engine's own look at the mission's first [`LASER_PHOTOS`] photos.
    Looking(Look),
    /// Decided by the engine's look, or given (found by a run over a folder).
    Decided(Found),
}

impl Lasers {
    /// The paths of laser dots, once decided.
    pub(crate) fn paths(&self) -> Option<&LaserPaths> {
        match self {
            Lasers::Decided(Found::Paths(p)) => Some(p),
            _ => None,
        }
    }

    /// With the engine's own look: count `low` (the accepted photo's block image, of `layout`; `None` at the end of
    /// the mission) and return the decision once it is made (at the last of [`LASER_PHOTOS`], or with `end` at the
    /// end of a shorter mission). `None` while still looking, and when not looking.
    pub(crate) fn look(&mut self, low: Option<(Layout, &Raster)>, end: bool) -> Option<&Found> {
        let Lasers::Looking(look) = self else {
            return None;
        };
        if let Some((layout, low)) = low {
            look.add(layout, low);
        }
        if !end && !look.full() {
            return None;
        }
        *self = Lasers::Decided(look.decide());
        match self {
            Lasers::Decided(found) => Some(found),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block image of 40×30 blocks of grey ground, with a red spot on the block `(x, y)` (grown by
    /// [`crate::method::outliers::SPOT_GROW`] into the 25 blocks of one dot with its glare).
    fn with_spot(channels: usize, x: usize, y: usize) -> (Layout, Raster) {
        let (w, h) = (40, 30);
        let mut r = Raster::filled(w, h, channels, 0.2);
        if channels == 3 {
            r.data[(y * w + x) * 3] = 0.9;
        }
        let layout = Layout {
            width: w * 8,
            height: h * 8,
            channels,
        };
        (layout, r)
    }

    /// A grey photo among colour ones is passed over, as the engine refuses it: the look counts the same photos
    /// with it as without it, and decides the same.
    #[test]
    fn a_photo_of_another_layout_is_passed_over() {
        let spots = |i: usize| with_spot(3, 10 + i % 2, 12);
        let (mut with, mut without) = (Look::new(), Look::new());
        for i in 0..LASER_PHOTOS + 5 {
            if i == 5 {
                let (l, grey) = with_spot(1, 10, 12);
                assert!(!with.add(l, &grey), "a grey photo is not counted");
            }
            let (l, r) = spots(i);
            if !with.full() {
                assert!(with.add(l, &r));
            }
            if !without.full() {
                assert!(without.add(l, &r));
            }
        }
        assert_eq!(with.photos(), LASER_PHOTOS);
        assert_eq!(with.decide(), without.decide());
        assert!(matches!(with.decide(), Found::Paths(_)));
    }

    /// A mission of fewer than `LASER_MIN_PHOTOS` photos whose spots come back says so ([`Found::TooFew`]); one
    /// without spots finds none.
    #[test]
    fn a_short_mission_is_too_few_for_paths() {
        let mut look = Look::new();
        for i in 0..12 {
            let (l, r) = with_spot(3, 10 + i % 2, 12);
            look.add(l, &r);
        }
        assert_eq!(look.decide(), Found::TooFew { photos: 12 });
        let mut plain = Look::new();
        for _ in 0..12 {
            let (l, mut r) = with_spot(3, 10, 12);
            r.data.fill(0.2);
            plain.add(l, &r);
        }
        assert_eq!(plain.decide(), Found::None);
    }
}

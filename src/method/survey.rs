//! The method's first pass (the default of [`Method::Abyss`]): a survey of the mission's block images that gives each
//! photo its window, the quantile its `M` takes and its near window ([`crate::method::stretch`] says how).
//!
//! [`Survey`] takes the block images in mission order, as the [`Engine`](crate::method::engine::Engine) takes the
//! photos, and decides photo `i` once it has measured the photos its choice reads ([`photos_read`]`(i)`: up to
//! `i + 16`, whose measures wait for the [`REFERENCE_HALF`] photos after them) or once the mission is over. A choice
//! made that way is the choice the survey of the whole mission makes, so a stream of photos (the `Engine`, `--watch`,
//! photos on standard input, Python) and a run over a folder (which may survey the mission before its correction,
//! from the cheaper block means of its JPEGs) choose the same windows.
//!
//! [`Method::Abyss`]: crate::method::baseline::Method::Abyss

use crate::method::raster::Raster;
use crate::method::stretch::{
    choose, choose_one, photos_read, Choice, PhotoSurvey, Surveyor, REFERENCE_HALF,
};

/// Photos a stream waits for after a photo before the survey decides it ([`Engine::LOOK_AHEAD`](crate::Engine::LOOK_AHEAD)).
pub(crate) const LOOK_AHEAD: usize = crate::method::stretch::MAX_AUTO_WINDOW / 2 + REFERENCE_HALF;
/// The photo whose push decides the mission's first photos
/// ([`Engine::FIRST_DECIDED`](crate::Engine::FIRST_DECIDED)).
pub(crate) const FIRST_DECIDED: usize =
    crate::method::stretch::MAX_AUTO_WINDOW - 1 + REFERENCE_HALF;

/// Each photo's window from a survey of the mission's block images (see the module documentation).
pub(crate) struct Survey {
    surveyor: Option<Surveyor>,
    choices: Vec<Choice>,
}

impl Survey {
    /// A survey against the backscatter `s_low` (block resolution, linear light; `None`: no `S`).
    pub fn new(s_low: Option<&Raster>) -> Self {
        Survey {
            surveyor: Some(Surveyor::new(s_low)),
            choices: Vec::new(),
        }
    }

    /// The finished survey of a mission whose photos were all measured first (a run over a
    /// folder measures them before the correction, in batches on every worker): the choices [`Survey::push`] and
    /// [`Survey::finish`] make of the same block images.
    pub fn of_mission(photos: &[PhotoSurvey]) -> Self {
        Survey {
            surveyor: None,
            choices: choose(photos),
        }
    }

    /// The next photo's block medians (linear light, the blocks the engine takes). A block image of another size than
    /// the first is taken as a photo the survey cannot see.
    pub fn push(&mut self, low: &Raster) {
        let Some(surveyor) = self.surveyor.as_mut() else {
            return;
        };
        surveyor.push(low);
        let measured = surveyor.measured();
        while self.choices.len() < measured.len()
            && photos_read(self.choices.len()) <= measured.len()
        {
            self.choices.push(choose_one(measured, self.choices.len()));
        }
    }

    /// The end of the mission: every photo pushed is decided.
    pub fn finish(&mut self) {
        if let Some(surveyor) = self.surveyor.take() {
            let photos = surveyor.finish();
            for i in self.choices.len()..photos.len() {
                self.choices.push(choose_one(&photos, i));
            }
        }
    }

    /// Whether the mission is over ([`Survey::finish`]).
    pub fn finished(&self) -> bool {
        self.surveyor.is_none()
    }

    /// Photos decided so far (photos `0..decided()`).
    pub fn decided(&self) -> usize {
        self.choices.len()
    }

    /// Photo `i`'s choice, once decided; after the end of the mission, photos past it take the last photo's.
    pub fn choice(&self, i: usize) -> Option<&Choice> {
        match self.finished() {
            true => self.choices.get(i).or(self.choices.last()),
            false => self.choices.get(i),
        }
    }

    /// Every choice made, by photo.
    pub fn choices(&self) -> &[Choice] {
        &self.choices
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grey block images of a mission whose dark share and camera speed change along the track: a smooth light over
    /// patches of dark ground, sparse and fast at first, dense and slow later.
    fn mission(frames: usize) -> Vec<Raster> {
        let (w, h) = (48usize, 32usize);
        let mut x0 = 0usize;
        (0..frames)
            .map(|i| {
                let (c, step) = if (i / 25) % 2 == 0 {
                    (0.1, 7)
                } else {
                    (0.45, 1)
                };
                x0 += step;
                Raster::from_fn(w, h, 1, |x, y, _| {
                    let (gx, gy) = ((x + x0) / 3, y / 3);
                    let hash = (gx as u64)
                        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                        .wrapping_add((gy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
                        .wrapping_mul(0x1656_67B1_9E37_79F9);
                    let dark = ((hash >> 11) as f64 / (1u64 << 53) as f64) < c;
                    let light = 0.3 + 0.7 * (-((x as f32 - 24.0) / 20.0).powi(2)).exp();
                    light * if dark { 0.1 } else { 0.8 }
                })
            })
            .collect()
    }

    /// Streamed, photo `i` is decided when photo `max(i + LOOK_AHEAD, FIRST_DECIDED)` is pushed (or at the end), and its
    /// choice is the one [`choose`] makes over the survey of the whole mission, for missions shorter than a window,
    /// than the look-ahead, and several stretches long.
    #[test]
    fn a_streamed_survey_chooses_what_the_whole_mission_survey_chooses() {
        for frames in [1usize, 6, 12, 30, 41, 80, 131] {
            let lows = mission(frames);
            let mut whole = Surveyor::new(None);
            lows.iter().for_each(|l| whole.push(l));
            let want = choose(&whole.finish());
            let mut s = Survey::new(None);
            for (k, low) in lows.iter().enumerate() {
                s.push(low);
                let want_decided = match k >= FIRST_DECIDED {
                    true => k - LOOK_AHEAD + 1,
                    false => 0,
                };
                assert_eq!(
                    s.decided(),
                    want_decided,
                    "{frames} photos, after photo {k}"
                );
                for (i, want) in want.iter().enumerate().take(s.decided()) {
                    assert_eq!(
                        s.choice(i),
                        Some(want),
                        "{frames} photos: photo {i} after {k}"
                    );
                }
            }
            s.finish();
            assert_eq!(s.choices(), &want[..], "{frames} photos");
            let mut whole = Surveyor::new(None);
            lows.iter().for_each(|l| whole.push(l));
            assert_eq!(Survey::of_mission(&whole.finish()).choices(), &want[..]);
            assert!(want
                .iter()
                .all(|c| c.window <= frames.max(1) && c.window % 2 == 1));
            if frames >= 80 {
                assert!(
                    want.iter().any(|c| c.window > 7),
                    "the dense, slow stretches take longer windows"
                );
            }
        }
    }
}

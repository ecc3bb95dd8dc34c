//! Bright spots that move from photo to photo — laser dots whose place in the frame changes with the altitude,
//! specular highlights, glints — and the window's `M` where they held it (`--bright-spots`, off by default).
//!
//! The window's `M` is a median (or the `(1 + c)/2` quantile) over photos, so it outvotes objects that are at
//! another place in most photos of the window. A laser dot may not be: its place in the frame changes only with the
//! altitude, so over a window it can sit on the same few blocks in most photos, and the window's `M` takes it into
//! `F` there — on the real Nephrops runs a red blob in `F` beside each dot, and the corrected photos show a teal
//! stain (red divided by too much) wherever the dot is not. `--mask-auto` finds only what never moves.
//!
//! [`bright_spots`] marks, per photo, the blocks of its block-median image that stand far above the seafloor
//! around them in some channel (twice the local level, and by a tenth of the brightest channel's lit level, so noise
//! in dark regions never qualifies), in compact groups (a long bright edge of a narrow beam is lighting, not a
//! spot), and the blocks around them (glare). The engine fills `M` from the blocks around wherever such blocks held
//! more than half of the window, and leaves it alone elsewhere. The dots themselves then keep their full brightness
//! (before, `F` held part of them and dimmed them), which raises the overlap difference of the Nephrops runs; that
//! is why it is not the default (docs/evaluation.md, "Bright spots that move").
//!
//! [`SpotPath`] finds, before the run (`--mask-auto`), the blocks where red or green bright spots ([`laser_spots`])
//! come back to more often than chance over photos spread across the mission: the path a laser dot wanders along.
//! They join the mask of static pixels, so no photo's median holds them (docs/evaluation.md, "The paths of laser
//! dots").

use crate::method::median::quantile;
use crate::method::raster::Raster;
use crate::method::steps::nodes::{between_nodes, near_nodes, node_medians};
use crate::method::window::binomial_tail;

/// A block is bright when one of its channels is at least this many times the channel's local level.
pub const SPOT_RATIO: f32 = 2.0;

/// … and above the local level by at least this share of the brightest channel's lit level (its 99th percentile
/// over the frame): sensor noise in a dark corner, or in a channel starved of light, can double a block's value,
/// never by a tenth of that.
pub const SPOT_MARGIN: f32 = 0.1;

/// A group of bright blocks (8-connected) larger than this share of the frame's blocks is left alone: not a spot.
pub const SPOT_MAX_SHARE: f32 = 0.005;

/// Blocks around a spot marked with it (the glare).
pub const SPOT_GROW: usize = 2;

/// The blocks of `low` (a photo's block medians, linear light) that are bright spots, with the blocks within
/// [`SPOT_GROW`] of them; an empty vector when there are none. The local level is the median over a square of blocks a sixteenth of the
/// longer side across around grid nodes that far apart, interpolated bilinearly (as
/// [`crate::method::steps::near_window::near_shape`] does); NaN blocks (a mask) are never spots and do not vote.
pub fn bright_spots(low: &Raster) -> Vec<bool> {
    spots_where(low, |_, _| true)
}

/// [`bright_spots`] whose blocks pass `keep(block, local level of its channels)` before the glare is added.
fn spots_where(low: &Raster, keep: impl Fn(usize, &[f32]) -> bool) -> Vec<bool> {
    let (w, h, c) = (low.width, low.height, low.channels);
    if w < 8 || h < 8 {
        return Vec::new();
    }
    let r = ((w.max(h) as f64 / 32.0).round() as usize).max(2);
    let local = local_level(low, r);
    let bright = bright_blocks(low, &local);
    if !bright.contains(&true) {
        return Vec::new();
    }
    let spots = compact_groups(&bright, w, h, |b| keep(b, &local[b * c..(b + 1) * c]));
    if !spots.contains(&true) {
        return Vec::new();
    }
    // With the blocks around them: the glare around a dot lifts them by less than the ratio.
    grow(&spots, w, h, SPOT_GROW)
}

/// Per channel, the lit level of `low`: the 99th percentile of its finite blocks (0 when there are none).
fn lit_levels(low: &Raster) -> Vec<f32> {
    let c = low.channels;
    (0..c)
        .map(|ch| {
            let mut v: Vec<f32> = low.data[ch..]
                .iter()
                .step_by(c)
                .copied()
                .filter(|v| v.is_finite())
                .collect();
            if v.is_empty() {
                0.0
            } else {
                quantile(&mut v, 0.99)
            }
        })
        .collect()
}

/// The blocks of `low` that are bright in some channel: at least [`SPOT_RATIO`] times the `local` level, and above
/// it by [`SPOT_MARGIN`] of the brightest channel's lit level.
fn bright_blocks(low: &Raster, local: &[f32]) -> Vec<bool> {
    let c = low.channels;
    let lit = lit_levels(low);
    // The margin against the brightest channel's lit level: a channel starved of light (red at depth) has noise
    // that doubles its dim blocks and rises by a tenth of its own small lit level.
    let top = lit.iter().copied().fold(0.0f32, f32::max);
    (0..low.width * low.height)
        .map(|b| {
            (0..c).any(|ch| {
                let (v, l) = (low.data[b * c + ch], local[b * c + ch]);
                v.is_finite() && l.is_finite() && v >= SPOT_RATIO * l && v - l >= SPOT_MARGIN * top
            })
        })
        .collect()
}

/// The `bright` blocks (of a `w`×`h` grid) in compact 8-connected groups — at most [`SPOT_MAX_SHARE`] of the
/// blocks — that pass `keep(block)`; larger groups are lighting, not spots.
fn compact_groups(bright: &[bool], w: usize, h: usize, keep: impl Fn(usize) -> bool) -> Vec<bool> {
    let max_blocks = ((w * h) as f32 * SPOT_MAX_SHARE).ceil() as usize;
    let mut seen = vec![false; w * h];
    let mut spots = vec![false; w * h];
    let mut stack = Vec::new();
    let mut members = Vec::new();
    for start in 0..w * h {
        if !bright[start] || seen[start] {
            continue;
        }
        members.clear();
        stack.push(start);
        seen[start] = true;
        while let Some(b) = stack.pop() {
            members.push(b);
            let (x, y) = (b % w, b / w);
            for ny in y.saturating_sub(1)..(y + 2).min(h) {
                for nx in x.saturating_sub(1)..(x + 2).min(w) {
                    let n = ny * w + nx;
                    if bright[n] && !seen[n] {
                        seen[n] = true;
                        stack.push(n);
                    }
                }
            }
        }
        if members.len() <= max_blocks {
            for &b in &members {
                spots[b] = keep(b);
            }
        }
    }
    spots
}

/// The `spots` (of a `w`×`h` grid) with every block within `g` of them (a square).
pub(crate) fn grow(spots: &[bool], w: usize, h: usize, g: usize) -> Vec<bool> {
    let mut out = vec![false; w * h];
    for b in (0..w * h).filter(|&b| spots[b]) {
        let (x, y) = (b % w, b / w);
        for ny in y.saturating_sub(g)..(y + g + 1).min(h) {
            for nx in x.saturating_sub(g)..(x + g + 1).min(w) {
                out[ny * w + nx] = true;
            }
        }
    }
    out
}

/// A bright spot counts for a spot path only when a channel's share of its colour is at least this many times that
/// channel's share of the seafloor's around it: lasers are red or green; bright stones, shells and glints are the
/// colour of the light. Grey photos have no colour to tell them by, and no spot paths: on the AQUALOC frames (grey,
/// a camera drifting slowly over amphorae) the bright amphorae came back to the same blocks in every third of the
/// clip, 7 % of the frame.
pub const LASER_CHROMA: f32 = 1.5;

/// [`bright_spots`] that have a laser's colour ([`LASER_CHROMA`]); none in a photo of fewer than 3 channels.
pub fn laser_spots(low: &Raster) -> Vec<bool> {
    let c = low.channels;
    if c < 3 {
        return Vec::new();
    }
    spots_where(low, |b, local| {
        let v = &low.data[b * c..(b + 1) * c];
        let (sv, sl) = (v.iter().sum::<f32>(), local.iter().sum::<f32>());
        sv > 0.0
            && sl > 0.0
            && v.iter()
                .zip(local)
                .any(|(&v, &l)| v / sv >= LASER_CHROMA * l / sl)
    })
}

/// A block is on a spot path when it was a bright spot in more of the photos counted than chance would give any
/// block of the frame with this probability: with `q` the share of all blocks of all photos that were spots and `B`
/// blocks, the smallest count `t` (at least 2) with `B · P(Binom(photos, q) ≥ t) ≤ PATH_CHANCE`. Objects on the
/// seafloor pass through the frame, so a block holds them in a photo now and then, by chance; a laser dot moves
/// only with the altitude and comes back to the same few blocks all mission long.
pub const PATH_CHANCE: f64 = 0.01;

/// The fewest blocks on spot paths ([`SpotPath::blocks`]) that are taken for the paths of laser dots: one spot with
/// its glare, `(2·SPOT_GROW + 1)²`. Fewer blocks held more often than chance are a coincidence of neighbouring spots
/// (a simulated nodule field without lasers: 1–2 blocks of 4800).
pub const LASER_MIN_BLOCKS: usize = (2 * SPOT_GROW + 1) * (2 * SPOT_GROW + 1);

/// The fewest photos [`LaserPaths::of`] decides on: in fewer, a block needs to hold a spot in only 2 or 3 of them to
/// beat chance, and a slow camera over one red animal does that (MBARI's 12 benthic frames: 0.2 % of the frame).
pub const LASER_MIN_PHOTOS: usize = 20;

/// Where bright spots come back to through a mission: the path of laser dots that wander with the altitude
/// (`--mask-auto`). Counts, per block, the photos whose [`laser_spots`] held it; [`SpotPath::blocks`] keeps the
/// blocks held in more of them than chance explains ([`PATH_CHANCE`]). Left out of every median like a fixed
/// overlay, they leave no stain where the dot is not, however few photos of a window it held there
/// (`--bright-spots` handles only the blocks it held in more than half of the window). A camera hovering over a red
/// sponge finds it too: the window's median would have taken it into `F` there, and `F` filled from around it is
/// better.
#[derive(Debug, Clone, Default)]
pub struct SpotPath {
    width: usize,
    height: usize,
    photos: usize,
    count: Vec<u32>,
}

impl SpotPath {
    /// Nothing counted yet.
    pub fn new() -> SpotPath {
        SpotPath::default()
    }

    /// Count the laser-coloured bright spots of one photo's block medians (linear light). A raster of another size
    /// than the first one counted is passed over (returns `false`).
    pub fn add(&mut self, low: &Raster) -> bool {
        self.add_spots((low.width, low.height), &laser_spots(low))
    }

    /// Count one photo's [`laser_spots`], found beforehand on its `width`×`height` block image (empty: none). A
    /// photo of another size than the first one counted is passed over (returns `false`).
    pub fn add_spots(&mut self, (width, height): (usize, usize), spots: &[bool]) -> bool {
        if self.photos == 0 {
            (self.width, self.height) = (width, height);
            self.count = vec![0; width * height];
        } else if (width, height) != (self.width, self.height) {
            return false;
        }
        self.photos += 1;
        for (n, &spot) in self.count.iter_mut().zip(spots) {
            *n += u32::from(spot);
        }
        true
    }

    /// The blocks on a spot path ([`SpotPath::blocks`]), and their share of the frame's (0 before any photo was
    /// counted).
    pub fn on_path(&self) -> (usize, f64) {
        let on = self.blocks().iter().filter(|&&b| b).count();
        (on, on as f64 / self.count.len().max(1) as f64)
    }

    /// The counts of `self` and `other` together (counted from photos of one size; an empty one takes the other's).
    pub fn merge(mut self, other: SpotPath) -> SpotPath {
        if self.photos == 0 {
            return other;
        }
        if other.photos > 0 {
            assert_eq!(
                (self.width, self.height),
                (other.width, other.height),
                "spot counts of photos of different sizes"
            );
            self.photos += other.photos;
            for (a, b) in self.count.iter_mut().zip(other.count) {
                *a += b;
            }
        }
        self
    }

    /// Photos counted.
    pub fn photos(&self) -> usize {
        self.photos
    }

    /// The fewest photos a block must have been a spot in to be on a path ([`PATH_CHANCE`]).
    pub fn least(&self) -> usize {
        let spots: u64 = self.count.iter().map(|&n| u64::from(n)).sum();
        let cells = (self.count.len() * self.photos).max(1);
        let q = spots as f64 / cells as f64;
        let blocks = self.count.len() as f64;
        (2..=self.photos)
            .find(|&t| blocks * binomial_tail(self.photos, t, q) <= PATH_CHANCE)
            .unwrap_or(self.photos + 1)
    }

    /// The blocks on a spot path (row by row; empty before any photo was counted).
    pub fn blocks(&self) -> Vec<bool> {
        let least = self.least();
        self.count.iter().map(|&n| n as usize >= least).collect()
    }

    /// The blocks on a spot path when there are at least [`LASER_MIN_BLOCKS`] of them: the paths of laser dots
    /// (`None`: fewer, or none).
    pub fn laser_blocks(&self) -> Option<Vec<bool>> {
        let blocks = self.blocks();
        (blocks.iter().filter(|&&b| b).count() >= LASER_MIN_BLOCKS).then_some(blocks)
    }
}

/// The paths of laser dots an [`Engine`](crate::method::engine::Engine) leaves out of every window's `M`
/// ([`Steps::laser_paths`](crate::method::params::Steps::laser_paths)): the blocks a [`SpotPath`] counted over the
/// mission's first photos holds ([`SpotPath::laser_blocks`]), on the grid of the engine's block images.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LaserPaths {
    /// Blocks across.
    pub width: usize,
    /// Blocks down.
    pub height: usize,
    /// One flag per block, row by row: on a path.
    pub blocks: Vec<bool>,
    /// The photos they were found in.
    pub photos: usize,
}

impl LaserPaths {
    /// The paths `path` found, if it found laser paths ([`SpotPath::laser_blocks`]) in at least
    /// [`LASER_MIN_PHOTOS`] photos.
    pub fn of(path: &SpotPath) -> Option<LaserPaths> {
        if path.photos < LASER_MIN_PHOTOS {
            return None;
        }
        Some(LaserPaths {
            width: path.width,
            height: path.height,
            blocks: path.laser_blocks()?,
            photos: path.photos,
        })
    }

    /// The share of the frame's blocks on a path.
    pub fn share(&self) -> f64 {
        self.blocks.iter().filter(|&&b| b).count() as f64 / self.blocks.len().max(1) as f64
    }

    /// Leave the blocks on a path out of `low`, a block image of the same grid (NaN in every channel, as a mask
    /// that covers the whole block leaves it); one of another size is left as it is.
    pub fn clear(&self, low: &mut Raster) {
        if (low.width, low.height) != (self.width, self.height) {
            return;
        }
        let c = low.channels;
        for (b, _) in self.blocks.iter().enumerate().filter(|(_, &on)| on) {
            low.data[b * c..(b + 1) * c].fill(f32::NAN);
        }
    }

    /// The blocks on a path or next to one (8-connected): as [`crate::method::blocks`]' flags of blocks near a
    /// masked pixel, where the blend stays off.
    pub fn near(&self) -> Vec<bool> {
        grow(&self.blocks, self.width, self.height, 1)
    }

    /// The paths as a pixel mask of a `width`×`height` photo cut into blocks of `k` (white on a path).
    pub fn to_mask(&self, k: usize, width: usize, height: usize) -> crate::method::mask::Mask {
        crate::method::mask::Mask::from_blocks(&self.blocks, k, width, height)
    }
}

/// The local level of each block and channel: the median over the `(2r + 1)`² square around grid nodes `r` blocks
/// apart (and the last row and column), interpolated bilinearly between the nodes.
fn local_level(low: &Raster, r: usize) -> Vec<f32> {
    let (w, h, c) = (low.width, low.height, low.channels);
    let (gx, gy) = (near_nodes(w, r), near_nodes(h, r));
    let nodes: Vec<Vec<f32>> = (0..c)
        .map(|ch| {
            node_medians(&gx, &gy, r, (w, h), |x, y| {
                Some(low.data[(y * w + x) * c + ch]).filter(|v| v.is_finite())
            })
        })
        .collect();
    let mut out = vec![f32::NAN; w * h * c];
    for y in 0..h {
        for x in 0..w {
            for (ch, node) in nodes.iter().enumerate() {
                if let Some(v) = between_nodes(|j, k| node[j * gx.len() + k], &gx, &gy, x, y) {
                    out[(y * w + x) * c + ch] = v;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A light cone over grey seafloor (block medians), with: a 2×2 red dot (4× the red around it), a long bright
    /// band down the right edge (a narrow beam's lit edge: 2.5× the level, far more blocks than a spot), and blocks
    /// tripled by noise in the dark corner (a tenth of the lit level is more than they rise).
    fn scene() -> Raster {
        let (w, h) = (64, 48);
        Raster::from_fn(w, h, 3, |x, y, ch| {
            let (fx, fy) = (x as f32 - 32.0, y as f32 - 24.0);
            let mut v = 0.4 * (-(fx * fx + fy * fy) / (2.0 * 12.0f32.powi(2))).exp();
            if x >= 56 {
                v *= 2.5;
            }
            if (20..22).contains(&x) && (20..22).contains(&y) && ch == 0 {
                v *= 4.0;
            }
            if x < 4 && y < 4 && (x + y) % 2 == 0 {
                v *= 3.0;
            }
            v
        })
    }

    #[test]
    fn a_dot_is_found_with_the_blocks_around_it_a_lit_band_and_dark_noise_are_not() {
        let low = scene();
        let spots = bright_spots(&low);
        assert_eq!(spots.len(), 64 * 48);
        for y in 0..48 {
            for x in 0..64 {
                let around = 20 - SPOT_GROW..22 + SPOT_GROW;
                let want = around.contains(&x) && around.contains(&y);
                assert_eq!(spots[y * 64 + x], want, "block ({x}, {y})");
            }
        }
    }

    /// 30 photos of the cone of [`scene`] (without its dot), with: a red laser dot at A in two photos of every three
    /// and at B in the third; a white spot four times the light at one place in every photo (a glint: the light's
    /// colour); a red spot at a new place in every photo (a red animal passing through); a red spot at one place in
    /// the first two photos only.
    #[test]
    fn a_spot_path_is_where_a_laser_comes_back_all_mission_long() {
        let (w, h, n) = (64usize, 48usize, 30usize);
        let (a, b, glint, twice) = ((20usize, 30usize), (30, 30), (44, 14), (12, 12));
        let photos: Vec<Raster> = (0..n)
            .map(|i| {
                let passing = (8 + (i * 7) % 48, 6 + (i * 5) % 36);
                let dot = if i % 3 == 2 { b } else { a };
                Raster::from_fn(w, h, 3, |x, y, ch| {
                    let (fx, fy) = (x as f32 - 32.0, y as f32 - 24.0);
                    let v = 0.4 * (-(fx * fx + fy * fy) / (2.0 * 12.0f32.powi(2))).exp() + 0.05;
                    let red = [(dot, true), (passing, true), (twice, i < 2)]
                        .iter()
                        .any(|&((px, py), on)| on && (px, py) == (x, y));
                    if red && ch == 0 {
                        6.0 * v
                    } else if (x, y) == glint {
                        4.0 * v
                    } else {
                        v
                    }
                })
            })
            .collect();
        let mut path = SpotPath::new();
        for p in &photos {
            assert!(path.add(p));
        }
        assert_eq!(path.photos(), n);
        // Counted in two parts and merged: the same.
        let (mut first, mut second) = (SpotPath::new(), SpotPath::new());
        for (i, p) in photos.iter().enumerate() {
            assert!(if i < 11 { first.add(p) } else { second.add(p) });
        }
        let merged = SpotPath::new().merge(first).merge(second);
        assert_eq!((merged.photos(), &merged.count), (n, &path.count));
        let blocks = path.blocks();
        let at = |(x, y): (usize, usize)| blocks[y * w + x];
        assert!(at(a) && at(b), "the laser's places");
        assert!(!at(glint), "a glint the colour of the light");
        assert!(!at(twice), "a red spot in two photos");
        // The passing spots are never on a path, and nothing else is far from the laser.
        for y in 0..h {
            for x in 0..w {
                if at((x, y)) {
                    assert!(
                        y.abs_diff(30) <= SPOT_GROW && (18..=32).contains(&x),
                        "({x}, {y}) on a path"
                    );
                }
            }
        }
        // The threshold, directly: the smallest t ≥ 2 with B · P(Binom(n, q) ≥ t) ≤ PATH_CHANCE.
        let spots: u32 = photos
            .iter()
            .map(|p| laser_spots(p).iter().filter(|&&s| s).count() as u32)
            .sum();
        let q = spots as f64 / (w * h * n) as f64;
        let tail = |t: usize| -> f64 {
            let mut sum = 0.0;
            for u in t..=n {
                let mut ln_choose = 0.0f64;
                for j in 0..u {
                    ln_choose += ((n - j) as f64).ln() - ((j + 1) as f64).ln();
                }
                sum += (ln_choose + u as f64 * q.ln() + (n - u) as f64 * (1.0 - q).ln()).exp();
            }
            sum
        };
        let want = (2..=n)
            .find(|&t| (w * h) as f64 * tail(t) <= PATH_CHANCE)
            .unwrap();
        assert_eq!(path.least(), want);
        assert!(want > 2 && want <= 10, "{want}");
        // A raster of another size is passed over; grey photos have no laser colour.
        assert!(!path.add(&Raster::filled(8, 8, 3, 0.5)));
        assert!(
            laser_spots(&Raster::from_fn(w, h, 1, |x, y, _| photos[0].get(x, y, 0))).is_empty()
        );
    }

    #[test]
    fn nothing_bright_gives_an_empty_vector() {
        let low = Raster::from_fn(40, 30, 3, |x, y, _| 0.2 + 0.001 * (x + y) as f32);
        assert!(bright_spots(&low).is_empty());
        // Too small to tell a spot from the scene.
        assert!(bright_spots(&Raster::filled(7, 7, 3, 0.5)).is_empty());
    }

    #[test]
    fn a_spot_in_a_masked_frame_is_found_and_nan_blocks_are_never_spots() {
        let mut low = scene();
        for x in 0..10 {
            for ch in 0..3 {
                low.data[(40 * 64 + x) * 3 + ch] = f32::NAN;
            }
        }
        let spots = bright_spots(&low);
        assert!(spots[20 * 64 + 20]);
        assert!((0..10).all(|x| !spots[40 * 64 + x]));
    }
}

//! Exposure levelling (`Steps::level_exposures`): where the exposure jumps from photo to photo within the window, its
//! photos levelled to one exposure, each by its gain against the window's `M`, before `M` is taken again; the
//! quantile otherwise takes the middle-exposure photo's scene whole (ghosts). A window shorter than
//! [`LEVEL_MIN_WINDOW`] is left alone, and a near window is levelled only with its window (docs/method.md).

use crate::method::raster::Raster;
use crate::method::steps::gain::{Against, GAIN_MIN_LIT};
use crate::method::steps::quantile;

/// `m`, the `q` quantile of `stack`, taken again over the photos levelled to one exposure where `on` (the step is
/// on and the window may be levelled) and its exposure jumps ([`levelled_stack`]); and whether it was.
pub(crate) fn level(
    stack: &[&Raster],
    m: Raster,
    s_low: Option<&Raster>,
    q: f32,
    on: bool,
) -> (Raster, bool) {
    if !on {
        return (m, false);
    }
    match levelled_stack(stack, &m, s_low, q as f64) {
        Some(levelled) => (quantile::of(&levelled.iter().collect::<Vec<_>>(), q), true),
        None => (m, false),
    }
}

/// A photo whose gain departs more than this share from the median of its own and its two neighbours' in every
/// channel is an exposure jump; a window with one is levelled ([`levelled_stack`]).
pub const EXPOSURE_JUMP: f32 = 0.1;

/// Blocks per channel that [`levelled_stack`]'s gains are taken on, at most (every `k`-th block of larger block
/// images: a 12 MP photo's 187 500 blocks give the same median within a thousandth at a tenth of the work).
pub const LEVEL_SAMPLES: usize = 16_384;

/// Windows shorter than this are not levelled ([`levelled_stack`]): four of a window of 5's photos are judged
/// against the three photos at one of its ends, where an altitude swing that turns looks like a jump (the dive
/// matrix's a01, a window of 5: residual pattern +3.2 % from levelling). The paper's window, and the shortest the
/// survey chooses, is 7; shorter ones come from a `--window` or a low `--contamination` given.
pub const LEVEL_MIN_WINDOW: usize = 7;

/// The longest window whose first and last photos are judged for a jump ([`levelled_stack`]). An end photo is
/// judged against the two photos on its one side, where an altitude swing that turns looks like a jump: in the
/// longer windows of the dive matrix every jump found was at an end (a10's windows of 19, h08's of 30, the whole
/// mission), and levelling them raised their residual pattern by 4.6 % and 7.9 %; there one end photo of so many does not
/// set the median's order, and inner jumps still count. Up to this length the ends stay judged: on the slow
/// sledge of Nephrops run 1627 (windows of 7–11) a quarter of the windows levelled jump at an end alone, and left
/// unlevelled they brought the burrow ghosts back.
pub const EDGE_JUMP_MAX_WINDOW: usize = 11;

/// Blocks per channel of [`levelled_stack`]'s first look for an exposure jump, at most.
pub const GLANCE_SAMPLES: usize = 1_024;

/// The window's photos levelled to one exposure before its `M` is taken, where the exposure jumps along the
/// window: each photo's `own − S` divided by its [`photo_gain`] against `m` (the window's `M` as first taken, at
/// quantile `q`), per channel, on at most [`LEVEL_SAMPLES`] blocks. `None` when no photo of the window (in mission
/// order; not its first and last of more than [`EDGE_JUMP_MAX_WINDOW`]) is an exposure jump ([`EXPOSURE_JUMP`] in
/// every channel against its neighbours): a smooth drift
/// (altitude) is left to the window as before, and so is noise in one starved channel. A first look on at most
/// [`GLANCE_SAMPLES`] blocks spares the windows without a jump the full gains.
///
/// The window's samples at a block are only exchangeable when the photos share one exposure. Where the exposure
/// jumps from photo to photo (a sledge that lifts and drops, an automatic exposure), the photos' levels differ by
/// more than the seafloor's texture, so at most blocks the median is the same photo — the one whose level is the
/// middle one — and `M` (and `F`) takes that photo's burrows and nodules whole: the ghosts of a slow sledge.
pub fn levelled_stack(
    stack: &[&Raster],
    m: &Raster,
    s: Option<&Raster>,
    q: f64,
) -> Option<Vec<Raster>> {
    let blocks = m.width * m.height;
    let stride = blocks.div_ceil(LEVEL_SAMPLES).max(1);
    let against = Against::new(m, s, stride);
    // A long window's end photos are not judged ([`EDGE_JUMP_MAX_WINDOW`]).
    let n = stack.len();
    let judged = |j: usize| n <= EDGE_JUMP_MAX_WINDOW || (j > 0 && j + 1 < n);
    let jumped = |gains: &[Vec<f32>], by: f32| {
        jumps(gains)
            .iter()
            .enumerate()
            .any(|(k, g)| judged(k) && g.iter().all(|j| (j - 1.0).abs() > by))
    };
    // Most windows have no jump: a first look on a few blocks (gains within a few thousandths of the full ones)
    // with half the threshold spares them the full gains.
    let glance = blocks.div_ceil(GLANCE_SAMPLES).max(stride);
    let rough: Vec<Vec<f32>> = stack
        .iter()
        .map(|p| against.gain(p, GAIN_MIN_LIT, q, glance))
        .collect();
    if !jumped(&rough, EXPOSURE_JUMP / 2.0) {
        return None;
    }
    let gains: Vec<Vec<f32>> = stack
        .iter()
        .map(|p| against.gain(p, GAIN_MIN_LIT, q, stride))
        .collect();
    if !jumped(&gains, EXPOSURE_JUMP) {
        return None;
    }
    let levelled = stack
        .iter()
        .zip(&gains)
        .map(|(p, g)| {
            let c = p.channels;
            let mut out = (*p).clone();
            for (i, v) in out.data.iter_mut().enumerate() {
                let sv = s.map_or(0.0, |s| s.data[i]);
                *v = sv + (*v - sv) / g[i % c];
            }
            out
        })
        .collect();
    Some(levelled)
}

/// The jumps of a sequence of gains (photos in mission order, per channel): each gain over the median of it and its
/// two neighbours (at the ends: of the three nearest). A smooth drift (altitude) gives jumps of 1; a photo whose
/// exposure jumps away from its neighbours keeps its jump.
fn jumps(gains: &[Vec<f32>]) -> Vec<Vec<f32>> {
    let n = gains.len();
    if n < 3 {
        return gains.to_vec();
    }
    (0..n)
        .map(|j| {
            let from = j.saturating_sub(1).min(n - 3);
            gains[j]
                .iter()
                .enumerate()
                .map(|(ch, &g)| {
                    let mut three = [gains[from][ch], gains[from + 1][ch], gains[from + 2][ch]];
                    three.sort_by(f32::total_cmp);
                    g / three[1]
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::steps::lit_level::LIT_PERCENTILE;

    /// A window whose exposure jumps photo to photo (more than its seafloor's texture): the plain median at every
    /// block is the middle-exposure photo, scene and all; levelled, `M` follows the light and no photo's scene.
    /// Checked against gains and a median taken by sorting, and `None` when the exposure does not change.
    #[test]
    fn levelled_stack_takes_no_photo_s_scene_whole() {
        use crate::method::median::stack_median;
        let (w, h, c) = (40, 30, 3);
        let light = |x: usize, y: usize| 0.2 + 0.01 * x as f32 + 0.005 * y as f32;
        let texture = |j: usize, x: usize, y: usize| {
            let k = (x * 73 + y * 151 + j * 997) * 2654435761 % 1000;
            1.0 + 0.03 * (k as f32 / 500.0 - 1.0)
        };
        let exposures = [1.0f32, 0.8, 1.25, 0.7, 1.4, 0.9, 1.1];
        let s = Raster::filled(w, h, c, 0.03);
        let photos: Vec<Raster> = exposures
            .iter()
            .enumerate()
            .map(|(j, e)| {
                Raster::from_fn(w, h, c, |x, y, _| 0.03 + e * light(x, y) * texture(j, x, y))
            })
            .collect();
        let stack: Vec<&Raster> = photos.iter().collect();
        let m = stack_median(&stack);
        let levelled = levelled_stack(&stack, &m, Some(&s), 0.5).expect("the exposures differ");
        let m_levelled = stack_median(&levelled.iter().collect::<Vec<_>>());
        // By hand: each photo's gain the median ratio over the blocks lit at least 0.3 of the 95th percentile.
        let lit: Vec<f32> = m.data.iter().map(|v| v - 0.03).collect();
        let mut sorted = lit.clone();
        sorted.sort_by(f32::total_cmp);
        let top = sorted[((sorted.len() - 1) as f64 * LIT_PERCENTILE).round() as usize];
        for (i, want) in m_levelled.data.iter().enumerate() {
            let mut column: Vec<f32> = photos
                .iter()
                .map(|p| {
                    let mut r: Vec<f32> = (i % c..p.data.len())
                        .step_by(c)
                        .filter(|&k| lit[k] >= 0.3 * top)
                        .map(|k| (p.data[k] - 0.03) / lit[k])
                        .collect();
                    r.sort_by(f32::total_cmp);
                    let nearest_rank = ((r.len() - 1) as f64 * 0.5).round() as usize;
                    0.03 + (p.data[i] - 0.03) / r[nearest_rank]
                })
                .collect();
            column.sort_by(f32::total_cmp);
            assert!(
                (column[3] - want).abs() < 1e-6,
                "{i}: {} vs {want}",
                column[3]
            );
        }
        // The scene of the middle-exposure photo (exposure 1.0): the plain M is it, the levelled M is not.
        let scene_share = |m: &Raster| {
            let (mut same, mut n) = (0, 0);
            for y in 0..h {
                for x in 0..w {
                    let rel = (m.get(x, y, 0) - 0.03) / light(x, y);
                    same += usize::from((rel - texture(0, x, y)).abs() < 1e-4);
                    n += 1;
                }
            }
            same as f64 / n as f64
        };
        assert!(scene_share(&m) > 0.95, "plain: {}", scene_share(&m));
        assert!(
            scene_share(&m_levelled) < 0.5,
            "levelled: {}",
            scene_share(&m_levelled)
        );
        // One exposure, or a smooth drift (altitude): nothing to level.
        let same: Vec<&Raster> = vec![&photos[0]; 5];
        assert!(levelled_stack(&same, &photos[0], Some(&s), 0.5).is_none());
        let drift: Vec<Raster> = (0..7)
            .map(|j| {
                let e = 0.85 + 0.05 * j as f32;
                Raster::from_fn(w, h, c, |x, y, _| 0.03 + e * light(x, y) * texture(j, x, y))
            })
            .collect();
        let drift: Vec<&Raster> = drift.iter().collect();
        assert!(levelled_stack(&drift, &stack_median(&drift), Some(&s), 0.5).is_none());
    }

    /// The gains of a 12 MP photo's block image (500×375 blocks) on every `k`-th block are its gains on all of
    /// them, within a thousandth.
    #[test]
    fn levelling_gains_on_a_sample_of_blocks_are_the_gains_on_all() {
        let (w, h) = (500, 375);
        let m = Raster::from_fn(w, h, 3, |x, y, _| {
            0.05 + 0.3 * (1.0 - (x as f32 / w as f32 - 0.5).powi(2)) + 0.0002 * y as f32
        });
        let own = Raster::from_fn(w, h, 3, |x, y, c| {
            let k = ((x * 73 + y * 151 + c * 31) * 2654435761usize % 1000) as f32 / 1000.0;
            let nodule = (x / 7 + y / 5) % 4 == 0;
            m.get(x, y, c) * if nodule { 0.3 } else { 1.1 + 0.2 * (k - 0.5) }
        });
        let against = Against::new(&m, None, 1);
        let stride = (w * h).div_ceil(LEVEL_SAMPLES);
        assert!(stride > 8);
        let (all, sampled) = (
            against.gain(&own, 0.3, 0.5, 1),
            against.gain(&own, 0.3, 0.5, stride),
        );
        for c in 0..3 {
            assert!(
                (all[c] - sampled[c]).abs() < 1e-3,
                "{c}: {} vs {}",
                all[c],
                sampled[c]
            );
            // A quarter nodules: the median is the seafloor's 1/3 quantile, 1.0 + 0.2/3.
            assert!((all[c] - (1.0 + 0.2 / 3.0)).abs() < 0.01, "{c}: {}", all[c]);
        }
    }
}

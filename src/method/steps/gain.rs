//! The per-photo gain (`Steps::photo_gain`): one robust gain per photo and channel, fitted on the photo's own
//! seafloor against its window's `M`, at the window's quantile where the survey chose it (the median elsewhere:
//! docs/nodules.md). It absorbs the altitude bounce and exposure jumps that the window's quantile averages away.

use crate::method::median::quantile;
use crate::method::raster::Raster;
use crate::method::seen::Window;
use crate::method::steps::lit_level::lit_level_every;

/// `f` times the photo's gain against `m` (`s`: the `S` in effect), where the step is on.
pub(crate) fn apply(w: &Window, f: &mut Raster, m: &Raster, s: Option<&Raster>) {
    if w.params.steps.photo_gain {
        // The engine gives the median unless the window is chosen per stretch: the window's quantile here wins on
        // dense nodule fields but moved the twelve dives of the matrix by up to 8 % either way (docs/nodules.md).
        let g = photo_gain(&w.own.low, m, s, GAIN_MIN_LIT, w.gain_quantile);
        apply_gain(f, &g);
    }
}

/// The share of a channel's lit level below which a block of `M − S` does not count in the per-photo gain (nor in
/// the levelling's gains, which are the same estimator).
pub const GAIN_MIN_LIT: f32 = 0.3;

/// One robust gain per channel of a photo against its window: the `q` quantile over the photo's lit blocks of
/// `(own − S) / (M − S)`, where lit means `M − S` at least `min_lit` of the channel's lit level. With `q = 0.5`
/// (the median) blocks of the photo that are not seafloor (nodules, objects) are outvoted as long as they are
/// fewer than half; the window's own quantile `(1 + c)/2` ([`Params::window_quantile`]) takes the seafloor's
/// median under a share `c` of dark blocks, as the window's `M` does (with the median and `M` at that quantile, a
/// dense nodule field's gain followed each photo's own nodule cover: photos with more nodules came out brighter,
/// and overlapping photos disagreed — docs/nodules.md).
/// Gains are clamped to `[0.25, 4]`; a channel with fewer than 8 lit blocks keeps gain 1.
pub fn photo_gain(own: &Raster, m: &Raster, s: Option<&Raster>, min_lit: f32, q: f64) -> Vec<f32> {
    Against::new(m, s, 1).gain(own, min_lit, q, 1)
}

/// A window's `M − S` and its lit level per channel, for the gains of many photos against it.
pub(crate) struct Against<'a> {
    m: &'a Raster,
    s: Option<&'a Raster>,
    lit: Vec<f32>,
    level: Vec<f32>,
}

impl<'a> Against<'a> {
    /// The window `m` over `s`, its lit level ([`lit_level`]) taken on every `stride`-th block.
    pub(crate) fn new(m: &'a Raster, s: Option<&'a Raster>, stride: usize) -> Self {
        let lit: Vec<f32> = m
            .data
            .iter()
            .enumerate()
            .map(|(i, &v)| v - s.map_or(0.0, |s| s.data[i]))
            .collect();
        let level = lit_level_every(&lit, m.channels, stride);
        Against { m, s, lit, level }
    }

    /// [`photo_gain`] of `own` against this window, on every `stride`-th block.
    pub(crate) fn gain(&self, own: &Raster, min_lit: f32, q: f64, stride: usize) -> Vec<f32> {
        assert_eq!(
            own.layout(),
            self.m.layout(),
            "photo and window differ in size"
        );
        let c = own.channels;
        let sv = |i: usize| self.s.map_or(0.0, |s| s.data[i]);
        (0..c)
            .map(|ch| {
                let mut r: Vec<f32> = (ch..own.data.len())
                    .step_by(c * stride)
                    .filter(|&i| self.lit[i] >= min_lit * self.level[ch] && self.lit[i] > 0.0)
                    .map(|i| (own.data[i] - sv(i)) / self.lit[i])
                    .filter(|x| x.is_finite())
                    .collect();
                if r.len() < 8 {
                    1.0
                } else {
                    quantile(&mut r, q).clamp(0.25, 4.0)
                }
            })
            .collect()
    }
}

/// Multiply each channel of `f` by its gain.
pub fn apply_gain(f: &mut Raster, gain: &[f32]) {
    let c = f.channels;
    for (i, v) in f.data.iter_mut().enumerate() {
        *v *= gain[i % c];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photo_gain_recovers_a_known_gain_despite_outliers() {
        // M − S a smooth ramp, the photo 1.3× brighter (red), 0.8× (green), 1× (blue) on its seafloor, with 30 %
        // of its blocks dark nodules (ratio 0.1) and S = 0.05 everywhere.
        let (w, h) = (20, 10);
        let s = Raster::filled(w, h, 3, 0.05);
        let m = Raster::from_fn(w, h, 3, |x, y, _| {
            0.05 + 0.2 + 0.02 * x as f32 + 0.01 * y as f32
        });
        let gains = [1.3f32, 0.8, 1.0];
        let own = Raster::from_fn(w, h, 3, |x, y, c| {
            let lit = 0.2 + 0.02 * x as f32 + 0.01 * y as f32;
            let nodule = (x * 7 + y * 3) % 10 < 3;
            0.05 + lit * if nodule { 0.1 } else { gains[c] }
        });
        let g = photo_gain(&own, &m, Some(&s), 0.3, 0.5);
        for c in 0..3 {
            assert!((g[c] - gains[c]).abs() < 1e-5, "{c}: {}", g[c]);
        }
        // Too few lit blocks: gain 1.
        let tiny = Raster::filled(2, 2, 3, 0.5);
        assert_eq!(photo_gain(&tiny, &tiny, None, 0.3, 0.5), vec![1.0; 3]);
    }

    #[test]
    fn photo_gain_at_the_windows_quantile_holds_under_a_dense_nodule_field() {
        // 60 % of the blocks nodules (ratio 0.1): the median lands on a nodule, the (1 + 0.6)/2 = 0.8 quantile on
        // the seafloor's gain.
        let (w, h) = (20, 10);
        let m = Raster::from_fn(w, h, 3, |x, _, _| 0.2 + 0.02 * x as f32);
        let nodule = |x: usize, y: usize| (x * 7 + y * 3) % 10 < 6;
        let own = Raster::from_fn(w, h, 3, |x, y, _| {
            (0.2 + 0.02 * x as f32) * if nodule(x, y) { 0.1 } else { 1.2 }
        });
        let by_median = photo_gain(&own, &m, None, 0.3, 0.5);
        let by_quantile = photo_gain(&own, &m, None, 0.3, 0.8);
        for c in 0..3 {
            assert!(
                (by_median[c] - 0.25).abs() < 1e-6,
                "clamped nodule ratio: {}",
                by_median[c]
            );
            assert!((by_quantile[c] - 1.2).abs() < 1e-5, "{}", by_quantile[c]);
        }
    }
}

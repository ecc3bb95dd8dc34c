//! Static regions: pixels that move with the camera and are not seafloor (burned-in overlays, laser dots, vehicle
//! parts). They are left out of every median, so they do not bend `F` and `S` around them (no halos); `F` and `S`
//! under them are filled smoothly from the surrounding estimate, and the masked pixels are corrected with that
//! fill like any other. Overlays keep their shape and colour (bright text may clip to white), and a safety margin
//! drawn around them blends into the corrected seafloor.

use std::path::Path;

use crate::error::{Error, Result};
use crate::method::factor::upsample;
use crate::method::median::{blocks, median_of_samples};
use crate::method::raster::{Layout, Raster, Sample};

/// Which pixels to ignore (`true`), one per pixel, row by row.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mask {
    /// Width in pixels (the photos').
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// One flag per pixel, row by row: `true` = not seafloor, left out of every median.
    pub ignore: Vec<bool>,
}

impl Mask {
    /// A mask that ignores nothing.
    pub fn empty(width: usize, height: usize) -> Mask {
        Mask {
            width,
            height,
            ignore: vec![false; width * height],
        }
    }

    /// Pixels ignored.
    pub fn count(&self) -> usize {
        self.ignore.iter().filter(|&&m| m).count()
    }

    /// Union with another mask of the same size.
    pub fn union(&mut self, other: &Mask) {
        for (a, b) in self.ignore.iter_mut().zip(&other.ignore) {
            *a |= *b;
        }
    }

    /// The pixels of the `k`×`k` blocks flagged in `blocks` (row by row, `blocks(width, k)` per row; the last
    /// row and column of blocks cut at the frame) in a `width`×`height` frame.
    pub fn from_blocks(blocks: &[bool], k: usize, width: usize, height: usize) -> Mask {
        let bw = crate::method::median::blocks(width, k);
        assert_eq!(blocks.len(), bw * crate::method::median::blocks(height, k));
        let ignore = (0..width * height)
            .map(|i| blocks[(i / width / k) * bw + (i % width) / k])
            .collect();
        Mask {
            width,
            height,
            ignore,
        }
    }

    /// Grow the ignored region by `r` pixels (square neighbourhood).
    pub fn dilate(&self, r: usize) -> Mask {
        let (w, h) = (self.width, self.height);
        // Separable: rows, then columns.
        let mut rows = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                if self.ignore[y * w + x] {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        rows[y * w + xx] = true;
                    }
                }
            }
        }
        let mut out = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                if rows[y * w + x] {
                    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                        out[yy * w + x] = true;
                    }
                }
            }
        }
        Mask {
            width: w,
            height: h,
            ignore: out,
        }
    }

    /// Check the mask fits photos of `layout`.
    pub fn check(&self, layout: Layout, path: &Path) -> Result<()> {
        if (self.width, self.height) != (layout.width, layout.height) {
            return Err(Error::Mismatch {
                path: path.to_owned(),
                reason: format!(
                    "mask is {}x{}, the photos are {}x{}",
                    self.width, self.height, layout.width, layout.height
                ),
            });
        }
        if self.count() == self.ignore.len() {
            return Err(Error::Mismatch {
                path: path.to_owned(),
                reason: "mask ignores every pixel: nothing is left to estimate the lighting from"
                    .into(),
            });
        }
        Ok(())
    }
}

/// Block median over the pixels the mask does not ignore; `NaN` where a whole block is ignored.
pub fn block_median_masked<T: Sample>(
    samples: &[T],
    layout: Layout,
    k: usize,
    mask: &Mask,
) -> Raster {
    use rayon::prelude::*;
    let Layout {
        width,
        height,
        channels,
    } = layout;
    assert_eq!(samples.len(), width * height * channels);
    assert_eq!((mask.width, mask.height), (width, height));
    let (bw, bh) = (blocks(width, k), blocks(height, k));
    let mut out = Raster::filled(bw, bh, channels, f32::NAN);
    if bw == 0 || bh == 0 {
        return out;
    }
    let scale = 1.0 / T::MAX;
    out.data
        .par_chunks_mut(bw * channels)
        .enumerate()
        .for_each(|(by, out_row)| {
            let (y0, y1) = (by * k, ((by + 1) * k).min(height));
            let mut scratch: Vec<T> = Vec::with_capacity(k * k);
            for bx in 0..bw {
                let (x0, x1) = (bx * k, ((bx + 1) * k).min(width));
                for c in 0..channels {
                    scratch.clear();
                    for y in y0..y1 {
                        for x in x0..x1 {
                            if !mask.ignore[y * width + x] {
                                scratch.push(samples[(y * width + x) * channels + c]);
                            }
                        }
                    }
                    if !scratch.is_empty() {
                        out_row[bx * channels + c] = median_of_samples(&mut scratch) * scale;
                    }
                }
            }
        });
    out
}

/// Replace `NaN` samples by a smooth (harmonic) fill from the known ones: each missing sample becomes the mean of
/// its four neighbours, iterated to convergence, known samples fixed. Returns the number of samples filled.
pub fn fill_missing(r: &mut Raster) -> usize {
    let (w, h, c) = (r.width, r.height, r.channels);
    let missing: Vec<usize> = (0..r.data.len()).filter(|&i| r.data[i].is_nan()).collect();
    if missing.is_empty() {
        return 0;
    }
    for ch in 0..c {
        // Start from the channel mean of the known samples.
        let known: Vec<f32> = (0..w * h)
            .map(|p| r.data[p * c + ch])
            .filter(|v| !v.is_nan())
            .collect();
        let start = if known.is_empty() {
            1.0
        } else {
            known.iter().sum::<f32>() / known.len() as f32
        };
        let holes: Vec<usize> = missing
            .iter()
            .filter(|&&i| i % c == ch)
            .map(|&i| i / c)
            .collect();
        for &p in &holes {
            r.data[p * c + ch] = start;
        }
        // Gauss-Seidel with over-relaxation on the holes only.
        for _ in 0..2000 {
            let mut change = 0.0f32;
            for &p in &holes {
                let (x, y) = (p % w, p / w);
                let mut sum = 0.0;
                let mut n = 0.0;
                for (nx, ny) in [
                    (x.wrapping_sub(1), y),
                    (x + 1, y),
                    (x, y.wrapping_sub(1)),
                    (x, y + 1),
                ] {
                    if nx < w && ny < h {
                        sum += r.data[(ny * w + nx) * c + ch];
                        n += 1.0;
                    }
                }
                let old = r.data[p * c + ch];
                let new = old + 1.6 * (sum / n - old);
                change = change.max((new - old).abs());
                r.data[p * c + ch] = new;
            }
            if change < 1e-6 {
                break;
            }
        }
    }
    missing.len()
}

/// Settings of [`detect_static`].
#[derive(Debug, Clone, Copy)]
pub struct DetectSettings {
    /// A pixel is static when its temporal median differs from the smooth lighting by more than this share of
    /// the lighting...
    pub relative: f32,
    /// ...and by more than this absolute amount (normalised units).
    pub absolute: f32,
    /// Pixels added around what was found.
    pub grow: usize,
}

impl Default for DetectSettings {
    fn default() -> Self {
        DetectSettings {
            relative: 0.2,
            absolute: 0.05,
            grow: 2,
        }
    }
}

/// Find static pixels (overlays, laser dots, vehicle parts) from per-pixel temporal medians of photos taken from
/// different parts of the mission (e.g. its three thirds). Seafloor moves through the frame and blurs out in such a
/// median, leaving the smooth lighting; whatever moves with the camera stays sharp. A pixel is static when it is
/// far from a smooth fit in *every* median: dark nodules that happen to sit at one place in many photos of one part
/// of the mission do not repeat in the others.
pub fn detect_static(medians: &[Raster], settings: DetectSettings) -> Mask {
    assert!(!medians.is_empty(), "no medians to detect static pixels in");
    let (w, h) = (medians[0].width, medians[0].height);
    let mut all = Mask {
        width: w,
        height: h,
        ignore: vec![true; w * h],
    };
    for m in medians {
        let found = sharp_structure(m, settings);
        for (a, f) in all.ignore.iter_mut().zip(&found.ignore) {
            *a &= *f;
        }
    }
    all.dilate(settings.grow)
}

/// Pixels of one median far from a smooth fit of it (not grown).
fn sharp_structure(median: &Raster, settings: DetectSettings) -> Mask {
    let (w, h, c) = (median.width, median.height, median.channels);
    let block = (w.min(h) / 16).max(16);
    let codes: Vec<u16> = median.to_u16();
    let layout = median.layout();
    let mut ignore = Mask::empty(w, h);
    let mut found = Mask::empty(w, h);
    // Twice: the second smooth fit leaves out what the first found, so large overlays do not bend it.
    for _ in 0..2 {
        let mut low = block_median_masked(&codes, layout, block, &ignore);
        fill_missing(&mut low);
        let smooth = upsample(&low, block, w, h);
        for p in 0..w * h {
            found.ignore[p] = (0..c).any(|ch| {
                let m = median.data[p * c + ch];
                let s = smooth.data[p * c + ch];
                let d = (m - s).abs();
                d > settings.absolute && d > settings.relative * s.max(0.0)
            });
        }
        ignore = found.dilate(settings.grow);
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::median::{block_median, reference};

    #[test]
    fn a_mask_from_blocks_covers_their_pixels_and_nothing_else() {
        // 21×13 pixels in blocks of 4: 6×4 blocks, the last column and row cut at the frame.
        let flagged = [(0usize, 0usize), (5, 1), (2, 3), (5, 3)];
        let mut blocks = vec![false; 6 * 4];
        for &(bx, by) in &flagged {
            blocks[by * 6 + bx] = true;
        }
        let m = Mask::from_blocks(&blocks, 4, 21, 13);
        assert_eq!((m.width, m.height), (21, 13));
        for y in 0..13 {
            for x in 0..21 {
                let want = flagged.iter().any(|&(bx, by)| {
                    (bx * 4..bx * 4 + 4).contains(&x) && (by * 4..by * 4 + 4).contains(&y)
                });
                assert_eq!(m.ignore[y * 21 + x], want, "({x}, {y})");
            }
        }
        // 16 + 4·4 (block (5, 1): one column) + 4·1 (block (2, 3): one row) + 1·1 (block (5, 3)).
        assert_eq!(m.count(), 16 + 4 + 4 + 1);
    }

    #[test]
    fn masked_block_median_matches_brute_force() {
        let (w, h, c, k) = (13usize, 9usize, 3usize, 4usize);
        let samples: Vec<u8> = (0..w * h * c)
            .map(|i| ((i * 37 + 11) % 251) as u8)
            .collect();
        let mut mask = Mask::empty(w, h);
        for p in 0..w * h {
            mask.ignore[p] = (p * 7) % 5 == 0 || (p % w < 4 && p / w < 4);
        }
        let got = block_median_masked(
            &samples,
            Layout {
                width: w,
                height: h,
                channels: c,
            },
            k,
            &mask,
        );
        for by in 0..h.div_ceil(k) {
            for bx in 0..w.div_ceil(k) {
                for ch in 0..c {
                    let vals: Vec<f64> = (0..w * h)
                        .filter(|&p| p % w / k == bx && p / w / k == by && !mask.ignore[p])
                        .map(|p| samples[p * c + ch] as f64)
                        .collect();
                    let g = got.get(bx, by, ch);
                    if vals.is_empty() {
                        assert!(g.is_nan());
                    } else {
                        assert!((g as f64 - reference::median(&vals) / 255.0).abs() < 1e-6);
                    }
                }
            }
        }
        // An empty mask gives the plain block median.
        let plain = block_median(&samples, w, h, c, k);
        let unmasked = block_median_masked(
            &samples,
            Layout {
                width: w,
                height: h,
                channels: c,
            },
            k,
            &Mask::empty(w, h),
        );
        assert_eq!(plain, unmasked);
    }

    #[test]
    fn fill_reproduces_a_plane_through_a_hole() {
        // A harmonic fill is exact for linear functions.
        let plane = |x: usize, y: usize| 0.3 + 0.02 * x as f32 - 0.01 * y as f32;
        let mut r = Raster::from_fn(20, 12, 1, |x, y, _| plane(x, y));
        for y in 3..8 {
            for x in 5..14 {
                r.data[y * 20 + x] = f32::NAN;
            }
        }
        assert_eq!(fill_missing(&mut r), 45);
        for y in 0..12 {
            for x in 0..20 {
                assert!((r.get(x, y, 0) - plane(x, y)).abs() < 1e-4, "({x},{y})");
            }
        }
    }

    #[test]
    fn detects_a_burned_in_box_and_a_dot_but_not_smooth_light() {
        let (w, h) = (160usize, 120usize);
        let light = |x: usize, y: usize| {
            let d = ((x as f32 - 80.0) / 70.0).powi(2) + ((y as f32 - 60.0) / 60.0).powi(2);
            0.1 + 0.5 * (-d).exp()
        };
        let is_box = |x: usize, y: usize| (4..60).contains(&x) && (3..12).contains(&y);
        let is_dot = |x: usize, y: usize| (x as i32 - 110).pow(2) + (y as i32 - 70).pow(2) <= 4;
        let median = Raster::from_fn(w, h, 3, |x, y, c| {
            if is_box(x, y) {
                if (x / 3 + y) % 2 == 0 {
                    1.0
                } else {
                    0.0
                }
            } else if is_dot(x, y) {
                [1.0, 0.1, 0.1][c]
            } else {
                light(x, y)
            }
        });
        let m = detect_static(&[median], DetectSettings::default());
        let truth = |x: usize, y: usize| is_box(x, y) || is_dot(x, y);
        let (mut hit, mut truth_n, mut false_pos) = (0, 0, 0);
        for y in 0..h {
            for x in 0..w {
                let t = truth(x, y);
                truth_n += t as usize;
                hit += (t && m.ignore[y * w + x]) as usize;
                // More than `grow` pixels away from any true static pixel counts as a false positive.
                let near = (y.saturating_sub(3)..(y + 4).min(h))
                    .any(|yy| (x.saturating_sub(3)..(x + 4).min(w)).any(|xx| truth(xx, yy)));
                false_pos += (m.ignore[y * w + x] && !near) as usize;
            }
        }
        assert!(
            hit as f32 >= 0.9 * truth_n as f32,
            "found {hit} of {truth_n}"
        );
        assert_eq!(false_pos, 0);
    }
}

//! Matching two photos of overlapping ground by phase correlation of texture images: the monitor uses it to see
//! whether the camera moves over the ground (a window of photos of the same ground cannot separate the scene from
//! the lighting), and [`crate::eval::register`] chains it over a sequence for the consistency metric.
//!
//! Each photo is reduced to a texture image at about [`TARGET_SIDE`] pixels on its long side: the log of its grey
//! level, box-averaged down, minus a local box average (the lights' smooth pattern goes, the texture stays).
//! Texture images are matched by phase correlation (FFT of a Hann-windowed copy, normalised cross-power spectrum,
//! peak refined to sub-pixel by a parabola through its neighbours). A match is accepted only when the photos
//! overlap over at least [`MIN_OVERLAP`] of their area and the texture images correlate there (normalised
//! cross-correlation at least [`MIN_NCC`]).
//!
//! The FFT is rustfft's, on the power-of-two sizes the texture images are padded to.

use crate::method::raster::Raster;

/// Long side, in pixels, of the texture images photos are matched on (at least; the reduction is an integer).
pub const TARGET_SIDE: usize = 256;
/// Smallest overlap (share of the photo's area) of an accepted match.
pub const MIN_OVERLAP: f64 = 0.2;
/// Smallest normalised cross-correlation of the texture images over the overlap of an accepted match.
pub const MIN_NCC: f64 = 0.25;
/// A texture image prepared for matching.
#[derive(Debug, Clone)]
pub struct Texture {
    /// Width in texture pixels.
    pub width: usize,
    /// Height in texture pixels.
    pub height: usize,
    /// Pixels of the reduced photo per pixel of the texture image.
    pub scale: usize,
    /// Row-major log grey level minus its local box mean (local contrast), `width × height` values.
    pub data: Vec<f32>,
}

/// Result of matching one photo against the previous one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Match {
    /// Shift `(dx, dy)` in full-resolution pixels: a point at `(u, v)` in the first photo is at `(u + dx, v + dy)`
    /// in the second.
    pub shift: (f64, f64),
    /// Normalised cross-correlation of the texture images over the overlap.
    pub ncc: f64,
    /// Overlap, as a share of the photo's area.
    pub overlap: f64,
    /// Whether the match passed the confidence test.
    pub accepted: bool,
}

/// Reduction factor giving a long side of at least [`TARGET_SIDE`] (1 for small photos).
pub fn reduction(width: usize, height: usize) -> usize {
    reduction_to(width, height, TARGET_SIDE)
}

/// Reduction factor giving a long side of at least `side` (and under `2·side`; 1 for images up to that size).
pub fn reduction_to(width: usize, height: usize, side: usize) -> usize {
    (width.max(height) / side).max(1)
}

/// The texture image of a photo (any channels, linear or not: only the log of its grey level's local contrast
/// counts), reduced by `scale`.
pub fn texture(photo: &Raster, scale: usize) -> Texture {
    let (w, h) = (photo.width / scale, photo.height / scale);
    let c = photo.channels;
    let mut grey = vec![0.0f32; w * h];
    for (y, row) in grey.chunks_exact_mut(w.max(1)).enumerate().take(h) {
        for (x, g) in row.iter_mut().enumerate() {
            let mut s = 0.0f32;
            for yy in y * scale..(y + 1) * scale {
                let line = photo.row(yy);
                for v in &line[x * scale * c..(x + 1) * scale * c] {
                    s += v;
                }
            }
            *g = s / (scale * scale * c) as f32;
        }
    }
    // Masked (NaN) pixels take the mean grey level for the floor below, and no texture.
    let valid: Vec<bool> = grey.iter().map(|v| v.is_finite()).collect();
    let masked = valid.contains(&false);
    let (sum, count) = grey
        .iter()
        .filter(|v| v.is_finite())
        .fold((0.0f64, 0usize), |(s, n), &v| (s + v as f64, n + 1));
    let fill = if count > 0 {
        (sum / count as f64) as f32
    } else {
        0.0
    };
    for g in &mut grey {
        if !g.is_finite() {
            *g = fill;
        }
    }
    let mut sorted: Vec<f32> = grey.clone();
    let floor = if sorted.is_empty() {
        1e-6
    } else {
        let at = (sorted.len() - 1) * 99 / 100;
        (0.02 * *sorted.select_nth_unstable_by(at, f32::total_cmp).1).max(1e-6)
    };
    let log: Vec<f32> = grey.iter().map(|&v| v.max(floor).ln()).collect();
    let r = (w.max(h) / 32).max(2);
    let smooth = if masked {
        // The local level from the unmasked pixels alone (a normalised box average): a fill level that differs from
        // the seafloor around it would leave a ring at the mask's edge, fixed in the frame like the mask, and the
        // match would lock onto it (laser dots' paths on Nephrops: camera-still flags on a moving sledge).
        let weight: Vec<f32> = valid.iter().map(|&ok| f32::from(u8::from(ok))).collect();
        let weighted: Vec<f32> = log.iter().zip(&weight).map(|(l, k)| l * k).collect();
        let (num, den) = (box_blur(&weighted, w, h, r), box_blur(&weight, w, h, r));
        num.iter()
            .zip(&den)
            .map(|(n, d)| if *d > 1e-3 { n / d } else { 0.0 })
            .collect()
    } else {
        box_blur(&log, w, h, r)
    };
    Texture {
        width: w,
        height: h,
        scale,
        data: log
            .iter()
            .zip(&smooth)
            .zip(&valid)
            .map(|((a, b), &ok)| if ok { a - b } else { 0.0 })
            .collect(),
    }
}

/// Mean over the clamped `(2r + 1)²` square (separable running sums).
pub(crate) fn box_blur(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    // No rows or no columns (a photo thinner than a block, reduced): nothing to blur, nothing to index.
    if w == 0 || h == 0 {
        return v.to_vec();
    }
    let pass = |src: &[f32], len: usize, stride: usize, count: usize, step: usize| -> Vec<f32> {
        let mut out = vec![0.0f32; src.len()];
        let last = len.saturating_sub(1);
        let n = (2 * r + 1) as f64;
        for k in 0..count {
            let (src, out) = (&src[k * step..], &mut out[k * step..]);
            let at = |i: usize| src[i * stride] as f64;
            let mut acc: f64 = (-(r as isize)..=r as isize)
                .map(|i| at(i.clamp(0, last as isize) as usize))
                .sum();
            // The samples entering and leaving the running sum, clamped to the edges as one index each.
            for i in 0..len {
                out[i * stride] = (acc / n) as f32;
                acc += at((i + r + 1).min(last)) - at(i.saturating_sub(r));
            }
        }
        out
    };
    let rows = pass(v, w, 1, h, w);
    pass(&rows, h, w, w, 1)
}

/// Photos a sequence needs before its fixed pattern is removed: the median of fewer, overlapping texture images
/// still holds their texture, and subtracting it puts a common component into every image (a false peak at zero
/// shift; seen on a synthetic five-photo sequence).
pub const FIXED_PATTERN_PHOTOS: usize = 15;

/// Subtract the per-pixel median over the sequence (what stays in the frame), when it has at least
/// [`FIXED_PATTERN_PHOTOS`] images of one size.
pub fn remove_fixed_pattern(textures: &mut [Texture]) {
    if textures.len() < FIXED_PATTERN_PHOTOS
        || textures
            .iter()
            .any(|t| t.data.len() != textures[0].data.len())
    {
        return;
    }
    let n = textures[0].data.len();
    let mut column = Vec::with_capacity(textures.len());
    let median: Vec<f32> = (0..n)
        .map(|i| {
            column.clear();
            column.extend(textures.iter().map(|t| t.data[i]));
            let mid = column.len() / 2;
            *column.select_nth_unstable_by(mid, f32::total_cmp).1
        })
        .collect();
    for t in textures {
        for (v, m) in t.data.iter_mut().zip(&median) {
            *v -= m;
        }
    }
}

/// In-place FFT of `re`/`im` (one row); `inverse` without the `1/n` factor.
#[cfg(test)]
pub(crate) fn fft(re: &mut [f64], im: &mut [f64], inverse: bool) {
    let n = re.len();
    fft2(re, im, n, 1, inverse);
}

/// 2-D FFT of a row-major `w`×`h` complex image (rows, then columns; rustfft's plans, any size); `inverse` without
/// the `1/(w·h)` factor.
pub(crate) fn fft2(re: &mut [f64], im: &mut [f64], w: usize, h: usize, inverse: bool) {
    use rustfft::{num_complex::Complex, FftDirection, FftPlanner};
    let direction = if inverse {
        FftDirection::Inverse
    } else {
        FftDirection::Forward
    };
    let mut planner = FftPlanner::<f64>::new();
    let mut buf: Vec<Complex<f64>> = re
        .iter()
        .zip(im.iter())
        .map(|(&r, &i)| Complex::new(r, i))
        .collect();
    planner.plan_fft(w, direction).process(&mut buf);
    let mut column = vec![Complex::new(0.0, 0.0); h];
    let plan = planner.plan_fft(h, direction);
    for x in 0..w {
        for (y, c) in column.iter_mut().enumerate() {
            *c = buf[y * w + x];
        }
        plan.process(&mut column);
        for (y, c) in column.iter().enumerate() {
            buf[y * w + x] = *c;
        }
    }
    for ((r, i), c) in re.iter_mut().zip(im.iter_mut()).zip(&buf) {
        *r = c.re;
        *i = c.im;
    }
}

/// Spectrum of a texture image, Hann-windowed and zero-padded to `(pw, ph)`.
pub(crate) fn spectrum(t: &Texture, pw: usize, ph: usize) -> (Vec<f64>, Vec<f64>) {
    let (mut re, mut im) = (vec![0.0; pw * ph], vec![0.0; pw * ph]);
    let mean = t.data.iter().map(|&v| v as f64).sum::<f64>() / t.data.len().max(1) as f64;
    let hann = |i: usize, n: usize| {
        0.5 - 0.5 * (std::f64::consts::TAU * (i as f64 + 0.5) / n as f64).cos()
    };
    for y in 0..t.height {
        for x in 0..t.width {
            re[y * pw + x] =
                (t.data[y * t.width + x] as f64 - mean) * hann(x, t.width) * hann(y, t.height);
        }
    }
    fft2(&mut re, &mut im, pw, ph, false);
    let _ = &mut im;
    (re, im)
}

/// Normalised cross-correlation of `a` and `b` over their overlap when `b` is `a` shifted by `(dx, dy)` texture
/// pixels (`b(x + dx, y + dy) ≈ a(x, y)`), and the overlap's share of the area.
pub fn overlap_ncc(a: &Texture, b: &Texture, dx: isize, dy: isize) -> (f64, f64) {
    let (w, h) = (a.width as isize, a.height as isize);
    let (x0, x1) = (0.max(-dx), w.min(w - dx));
    let (y0, y1) = (0.max(-dy), h.min(h - dy));
    if x1 <= x0 || y1 <= y0 {
        return (0.0, 0.0);
    }
    let (mut sa, mut sb, mut saa, mut sbb, mut sab, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0f64);
    for y in y0..y1 {
        for x in x0..x1 {
            let va = a.data[(y * w + x) as usize] as f64;
            let vb = b.data[((y + dy) * w + x + dx) as usize] as f64;
            sa += va;
            sb += vb;
            saa += va * va;
            sbb += vb * vb;
            sab += va * vb;
            n += 1.0;
        }
    }
    let cov = sab - sa * sb / n;
    let va = (saa - sa * sa / n).max(0.0);
    let vb = (sbb - sb * sb / n).max(0.0);
    let ncc = if va > 0.0 && vb > 0.0 {
        cov / (va * vb).sqrt()
    } else {
        0.0
    };
    (ncc, n / (w * h) as f64)
}

/// The spectrum of a texture image as [`match_pair`] takes it (Hann-windowed, zero-padded to powers of two): a
/// sequence matched photo by photo computes each photo's once ([`match_spectra`]).
pub(crate) type Spectrum = (Vec<f64>, Vec<f64>);

/// The [`Spectrum`] of `t`.
pub(crate) fn texture_spectrum(t: &Texture) -> Spectrum {
    spectrum(t, t.width.next_power_of_two(), t.height.next_power_of_two())
}

/// Match texture image `b` against `a` (same size) by phase correlation; see [`Match`].
pub fn match_pair(a: &Texture, b: &Texture) -> Match {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "texture sizes differ"
    );
    match_spectra(a, b, &texture_spectrum(a), &texture_spectrum(b))
}

/// [`match_pair`] of `a` and `b` given their [`texture_spectrum`]s.
pub(crate) fn match_spectra(
    a: &Texture,
    b: &Texture,
    (ar, ai): &Spectrum,
    (br, bi): &Spectrum,
) -> Match {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "texture sizes differ"
    );
    let (pw, ph) = (a.width.next_power_of_two(), a.height.next_power_of_two());
    assert_eq!(ar.len(), pw * ph, "a spectrum of another size");
    // conj(A)·B / |A·B|: its inverse peaks at the shift of b against a.
    let (mut re, mut im) = (vec![0.0; pw * ph], vec![0.0; pw * ph]);
    for i in 0..pw * ph {
        let (r, m) = (ar[i] * br[i] + ai[i] * bi[i], ar[i] * bi[i] - ai[i] * br[i]);
        let mag = (r * r + m * m).sqrt();
        if mag > 1e-20 {
            re[i] = r / mag;
            im[i] = m / mag;
        }
    }
    fft2(&mut re, &mut im, pw, ph, true);
    let best = (0..pw * ph)
        .max_by(|&i, &j| re[i].total_cmp(&re[j]))
        .unwrap_or(0);
    let (px, py) = (best % pw, best / pw);
    let at = |x: isize, y: isize| {
        re[(y.rem_euclid(ph as isize) as usize) * pw + x.rem_euclid(pw as isize) as usize]
    };
    let refine = |l: f64, c: f64, r: f64| {
        let d = l - 2.0 * c + r;
        if d < 0.0 {
            (0.5 * (l - r) / d).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    };
    let (xi, yi) = (px as isize, py as isize);
    let fx = refine(at(xi - 1, yi), at(xi, yi), at(xi + 1, yi));
    let fy = refine(at(xi, yi - 1), at(xi, yi), at(xi, yi + 1));
    let wrap = |p: isize, n: usize| {
        if p > n as isize / 2 {
            p - n as isize
        } else {
            p
        }
    };
    let (dx, dy) = (wrap(xi, pw), wrap(yi, ph));
    let (ncc, overlap) = overlap_ncc(a, b, dx, dy);
    let s = a.scale as f64;
    Match {
        shift: ((dx as f64 + fx) * s, (dy as f64 + fy) * s),
        ncc,
        overlap,
        accepted: overlap >= MIN_OVERLAP && ncc >= MIN_NCC,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A texture image of a smooth random pattern seen at offset `(ox, oy)`.
    fn shifted(ox: usize, oy: usize) -> Texture {
        let (w, h) = (70, 50);
        let v = |x: usize, y: usize| {
            let (x, y) = ((x + ox) as f32, (y + oy) as f32);
            (0.37 * x).sin() * (0.23 * y).cos()
                + (0.11 * x + 0.31 * y).sin()
                + 0.5 * (0.05 * x * y).sin()
        };
        Texture {
            width: w,
            height: h,
            scale: 3,
            data: (0..w * h).map(|i| v(i % w, i / w)).collect(),
        }
    }

    /// The running sums of [`box_blur`] with each index clamped in the sum (the form before the edges were
    /// clamped once per index): the reference the kernel must equal bit for bit.
    fn box_blur_clamped(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
        let pass = |src: &[f32], len: usize, stride: usize, count: usize, step: usize| {
            let mut out = vec![0.0f32; src.len()];
            for k in 0..count {
                let at = |i: isize| src[k * step + i.clamp(0, len as isize - 1) as usize * stride];
                let mut acc: f64 = (-(r as isize)..=r as isize).map(|i| at(i) as f64).sum();
                for i in 0..len as isize {
                    out[k * step + i as usize * stride] = (acc / (2 * r + 1) as f64) as f32;
                    acc += at(i + r as isize + 1) as f64 - at(i - r as isize) as f64;
                }
            }
            out
        };
        let rows = pass(v, w, 1, h, w);
        pass(&rows, h, w, w, 1)
    }

    #[test]
    fn box_blur_is_the_clamped_running_sum_and_near_the_square_mean() {
        for (w, h, r) in [(1, 1, 1), (7, 3, 2), (40, 25, 5), (13, 31, 20), (64, 2, 1)] {
            let v: Vec<f32> = (0..w * h)
                .map(|i| ((i * 2654435761usize) % 1000) as f32 / 37.0 - 9.0)
                .collect();
            let got = box_blur(&v, w, h, r);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&got),
                bits(&box_blur_clamped(&v, w, h, r)),
                "{w}x{h} r {r}"
            );
            // Brute force: the mean over the square, samples past an edge taken from the edge.
            let c = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let mut sum = 0.0f64;
                    for dy in -(r as isize)..=r as isize {
                        for dx in -(r as isize)..=r as isize {
                            sum += v[c(y + dy, h) * w + c(x + dx, w)] as f64;
                        }
                    }
                    let want = sum / ((2 * r + 1) * (2 * r + 1)) as f64;
                    let g = got[y as usize * w + x as usize] as f64;
                    assert!(
                        (g - want).abs() < 1e-4,
                        "{w}x{h} r {r} at ({x}, {y}): {g} {want}"
                    );
                }
            }
        }
    }

    /// A sequence matched with each texture's spectrum computed once gives what matching each pair afresh gives,
    /// bit for bit.
    #[test]
    fn spectra_computed_once_match_as_pairs_do() {
        let textures: Vec<Texture> = [(0, 0), (4, 1), (9, 3), (9, 3), (15, 2)]
            .iter()
            .map(|&(x, y)| shifted(x, y))
            .collect();
        let spectra: Vec<Spectrum> = textures.iter().map(texture_spectrum).collect();
        for i in 1..textures.len() {
            let (a, b) = (&textures[i - 1], &textures[i]);
            let once = match_spectra(a, b, &spectra[i - 1], &spectra[i]);
            assert_eq!(once, match_pair(a, b), "pair {i}");
            assert!(once.accepted, "pair {i}: {once:?}");
        }
    }
}

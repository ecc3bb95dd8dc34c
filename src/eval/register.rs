//! Registration of consecutive overlapping photos, for the consistency metric on real dives without navigation
//! (`abysslight evaluate --register RAW_DIR`).
//!
//! Model: a translation between consecutive photos (a downward camera over flat ground at a steady altitude).
//! Each photo is reduced to a texture image at about [`TARGET_SIDE`](crate::method::matching::TARGET_SIDE) pixels on its long side: the log of its grey
//! level, box-averaged down, minus a local box average (the lights' smooth pattern goes, the texture stays). The
//! per-pixel median of those images over the sequence, the part that stays in the frame (vignetting residue,
//! overlays, laser dots), is subtracted when the sequence has at least 15 photos, so it cannot pull the match
//! to zero shift. Consecutive texture images are matched by phase correlation (FFT of a Hann-windowed copy,
//! normalised cross-power spectrum, peak refined to sub-pixel by a parabola through its neighbours). A match is
//! accepted only when the photos overlap over at least [`MIN_OVERLAP`](crate::method::matching::MIN_OVERLAP) of their area and the texture images
//! correlate there (normalised cross-correlation at least [`MIN_NCC`](crate::method::matching::MIN_NCC)); unrelated photos fail that test. The
//! placements are chained along the sequence; after a rejected pair a new chain starts far away, so photos of
//! different chains never share a mosaic cell.
//!
//! The FFT is written out (radix 2, on power-of-two sizes the texture images are padded to): at 256–512 pixels a
//! side it is a few dozen lines and fast enough (milliseconds a pair), so no FFT crate is added.

use std::path::Path;

use rayon::prelude::*;

use crate::error::Result;
use crate::eval::evaluate::Placement;
use crate::method::matching::{
    match_pair, reduction, remove_fixed_pattern, texture, Match, Texture,
};
#[cfg(test)]
use crate::method::raster::Raster;

/// Vertical distance, in photo heights, between chains of placements that could not be joined.
const CHAIN_GAP: f64 = 100.0;

/// What [`register_folder`] found: one placement per photo (translations, in full-resolution pixels) and the match of
/// each photo against the previous one (`None` for the first).
#[derive(Debug, Clone)]
pub struct Registration {
    /// One placement per photo, in input order.
    pub placements: Vec<Placement>,
    /// Match of each photo against the previous one; `None` for the first.
    pub matches: Vec<Option<Match>>,
}

impl Registration {
    /// Pairs accepted, of pairs tried.
    pub fn accepted(&self) -> (usize, usize) {
        let tried = self.matches.iter().flatten().count();
        let ok = self.matches.iter().flatten().filter(|m| m.accepted).count();
        (ok, tried)
    }
}

/// Register a sequence of photos (in order; all of one size): chain the accepted consecutive matches into
/// placements. `names` label the placements.
#[cfg(test)]
pub fn register_rasters(names: &[String], photos: &[Raster]) -> Registration {
    assert_eq!(names.len(), photos.len(), "one name per photo");
    let Some(first) = photos.first() else {
        return Registration {
            placements: Vec::new(),
            matches: Vec::new(),
        };
    };
    let scale = reduction(first.width, first.height);
    let mut textures: Vec<Texture> = photos.par_iter().map(|p| texture(p, scale)).collect();
    remove_fixed_pattern(&mut textures);
    chain(names, &textures, first.height as f64)
}

/// Register the photos of a folder (found as `correct` finds them), decoded in order, `transfer` undone. Photos
/// of another size than the first are left out with a warning on stderr.
pub fn register_folder(
    dir: &Path,
    transfer: crate::method::transfer::Transfer,
) -> Result<Registration> {
    let found = crate::io::find_photos(dir)?;
    let names: Vec<String> = found
        .photos
        .iter()
        .map(|e| e.relative.to_string_lossy().replace('\\', "/"))
        .collect();
    // Decode and reduce one photo at a time (in parallel), keeping only the small texture images.
    let loaded: Vec<Result<(usize, usize, Texture)>> = found
        .photos
        .par_iter()
        .map(|e| {
            let r = crate::eval::evaluate::load_linear(&e.path, transfer)?;
            let scale = reduction(r.width, r.height);
            Ok((r.width, r.height, texture(&r, scale)))
        })
        .collect();
    let mut kept_names = Vec::new();
    let mut textures = Vec::new();
    let mut size = None;
    for (name, l) in names.into_iter().zip(loaded) {
        let (w, h, t) = l?;
        match size {
            None => size = Some((w, h)),
            Some(s) if s != (w, h) => {
                eprintln!(
                    "abysslight: {name} is {w}x{h}, not {}x{}: left out of the registration",
                    s.0, s.1
                );
                continue;
            }
            _ => {}
        }
        kept_names.push(name);
        textures.push(t);
    }
    remove_fixed_pattern(&mut textures);
    Ok(chain(
        &kept_names,
        &textures,
        size.map_or(1.0, |s| s.1 as f64),
    ))
}

fn chain(names: &[String], textures: &[Texture], height: f64) -> Registration {
    let matches: Vec<Option<Match>> = (0..textures.len())
        .into_par_iter()
        .map(|i| (i > 0).then(|| match_pair(&textures[i - 1], &textures[i])))
        .collect();
    let mut placements = Vec::with_capacity(names.len());
    let (mut tx, mut ty, mut chains) = (0.0f64, 0.0f64, 0usize);
    for (name, m) in names.iter().zip(&matches) {
        match m {
            Some(m) if m.accepted => {
                // Photo pixel (u, v) of the previous photo is at (u + dx, v + dy) here; both at one mosaic point.
                tx -= m.shift.0;
                ty -= m.shift.1;
            }
            Some(_) => {
                chains += 1;
                tx = 0.0;
                ty = chains as f64 * CHAIN_GAP * height;
            }
            None => {}
        }
        placements.push(Placement {
            name: name.clone(),
            h: [1.0, 0.0, tx, 0.0, 1.0, ty, 0.0, 0.0, 1.0],
        });
    }
    Registration {
        placements,
        matches,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::matching::*;

    /// Deterministic pseudo-random texture: smooth blobs of several sizes (sums of hashed lattice values).
    fn terrain(seed: u64, x: f64, y: f64) -> f64 {
        let hash = |i: i64, j: i64, k: u64| {
            let mut v = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
                ^ k.wrapping_mul(0x1656_67B1_9E37_79F9)
                ^ seed;
            v ^= v >> 29;
            v = v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            v ^= v >> 32;
            (v % 10_000) as f64 / 10_000.0
        };
        let mut s = 0.0;
        for (k, cell) in [3.0f64, 7.0, 17.0].iter().enumerate() {
            let (gx, gy) = (x / cell, y / cell);
            let (i, j) = (gx.floor() as i64, gy.floor() as i64);
            let (fx, fy) = (gx - gx.floor(), gy - gy.floor());
            let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
            let k = k as u64;
            let a = hash(i, j, k) + (hash(i + 1, j, k) - hash(i, j, k)) * sx;
            let b = hash(i, j + 1, k) + (hash(i + 1, j + 1, k) - hash(i, j + 1, k)) * sx;
            s += a + (b - a) * sy;
        }
        s
    }

    /// A photo of the terrain seen from `(ox, oy)`, under a co-moving light cone.
    fn photo(seed: u64, ox: f64, oy: f64, w: usize, h: usize) -> Raster {
        Raster::from_fn(w, h, 3, |x, y, c| {
            let (dx, dy) = (x as f64 - w as f64 / 2.0, y as f64 - h as f64 / 2.0);
            let cone = 0.2 + (-(dx * dx + dy * dy) / (0.3 * (w * w) as f64)).exp();
            let a = 0.3 + 0.2 * terrain(seed, x as f64 + ox, y as f64 + oy);
            (cone * a * [1.0, 0.9, 0.7][c]) as f32
        })
    }

    /// Brute-force DFT of a short complex sequence.
    fn dft(re: &[f64], im: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let n = re.len();
        let mut out = (vec![0.0; n], vec![0.0; n]);
        for k in 0..n {
            for t in 0..n {
                let a = -std::f64::consts::TAU * (k * t) as f64 / n as f64;
                out.0[k] += re[t] * a.cos() - im[t] * a.sin();
                out.1[k] += re[t] * a.sin() + im[t] * a.cos();
            }
        }
        out
    }

    #[test]
    fn fft_matches_the_direct_sum_and_inverts() {
        let n = 16;
        let re: Vec<f64> = (0..n).map(|i| ((i * 7) % 5) as f64 - 1.3).collect();
        let im: Vec<f64> = (0..n).map(|i| ((i * 3) % 4) as f64 * 0.5).collect();
        let (wr, wi) = dft(&re, &im);
        let (mut r, mut m) = (re.clone(), im.clone());
        fft(&mut r, &mut m, false);
        for k in 0..n {
            assert!((r[k] - wr[k]).abs() < 1e-9 && (m[k] - wi[k]).abs() < 1e-9);
        }
        fft(&mut r, &mut m, true);
        for k in 0..n {
            assert!((r[k] / n as f64 - re[k]).abs() < 1e-9);
            assert!((m[k] / n as f64 - im[k]).abs() < 1e-9);
        }
    }

    #[test]
    fn box_blur_matches_brute_force() {
        let (w, h, r) = (11usize, 7usize, 2usize);
        let v: Vec<f32> = (0..w * h).map(|i| ((i * 13) % 7) as f32).collect();
        let got = box_blur(&v, w, h, r);
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for dy in -(r as isize)..=r as isize {
                    for dx in -(r as isize)..=r as isize {
                        let sx = (x as isize + dx).clamp(0, w as isize - 1) as usize;
                        let sy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                        s += v[sy * w + sx];
                    }
                }
                let want = s / ((2 * r + 1) * (2 * r + 1)) as f32;
                assert!((got[y * w + x] - want).abs() < 1e-4);
            }
        }
    }

    /// Masked blocks (NaN: laser dots' paths under `--mask-auto`) sit at the same place in every photo. The texture
    /// image takes the local level around them from the unmasked pixels and gives them no texture; filled with the
    /// photo's mean grey level instead, the bright cone around them left a ring fixed in the frame, and the match
    /// locked onto it (checked: no shift found).
    #[test]
    fn masked_pixels_fixed_in_the_frame_do_not_hold_the_match() {
        let (w, h) = (320, 200);
        let (mx, my) = (23.0, -41.0);
        let blank = |mut r: Raster| {
            for y in 0..h {
                for x in 0..w {
                    for (cx, cy) in [(120.0, 100.0), (200.0, 100.0), (160.0, 70.0)] {
                        if (x as f64 - cx).hypot(y as f64 - cy) < 14.0 {
                            for c in 0..3 {
                                r.data[(y * w + x) * 3 + c] = f32::NAN;
                            }
                        }
                    }
                }
            }
            r
        };
        let (a, b) = (
            blank(photo(7, 0.0, 0.0, w, h)),
            blank(photo(7, mx, my, w, h)),
        );
        let (ta, tb) = (texture(&a, 1), texture(&b, 1));
        assert!(ta.data.iter().all(|v| v.is_finite()));
        let m = match_pair(&ta, &tb);
        assert!(m.accepted, "{m:?}");
        assert!(
            (m.shift.0 + mx).abs() < 0.6 && (m.shift.1 + my).abs() < 0.6,
            "{m:?}"
        );
    }

    #[test]
    fn recovers_a_known_shift_and_rejects_unrelated_photos() {
        let (w, h) = (320, 200);
        // The camera moves by (23, -41) pixels: a ground point at (u, v) in the first photo is at (u − 23, v + 41)
        // in the second.
        let (mx, my) = (23.0, -41.0);
        let a = photo(7, 0.0, 0.0, w, h);
        let b = photo(7, mx, my, w, h);
        let scale = reduction(w, h);
        assert_eq!(scale, 1);
        let m = match_pair(&texture(&a, scale), &texture(&b, scale));
        assert!(m.accepted, "{m:?}");
        assert!(
            (m.shift.0 + mx).abs() < 0.6 && (m.shift.1 + my).abs() < 0.6,
            "{m:?}"
        );
        // Another stretch of ground: no overlap, the test rejects it.
        let c = photo(99, 5000.0, 3000.0, w, h);
        let m = match_pair(&texture(&a, scale), &texture(&c, scale));
        assert!(!m.accepted, "{m:?}");
        // Chained over a sequence: placements agree with the truth up to the
        // first photo's position, and a break in the sequence starts a new chain far away.
        let offsets = [(0.0, 0.0), (10.0, 35.0), (25.0, 70.0), (31.0, 112.0)];
        let mut photos: Vec<Raster> = offsets.iter().map(|&(x, y)| photo(3, x, y, w, h)).collect();
        photos.push(photo(11, 9000.0, 0.0, w, h));
        let names: Vec<String> = (0..photos.len()).map(|i| format!("{i}.png")).collect();
        let reg = register_rasters(&names, &photos);
        assert_eq!(reg.accepted(), (3, 4), "{:?}", reg.matches);
        for (p, &(x, y)) in reg.placements.iter().zip(&offsets) {
            assert!(
                (p.h[2] - x).abs() < 1.0 && (p.h[5] - y).abs() < 1.0,
                "{p:?}"
            );
        }
        assert!(reg.placements[4].h[5] > 50.0 * h as f64);
    }

    #[test]
    fn recovers_a_shift_at_reduced_resolution() {
        let (w, h) = (600, 420);
        let a = photo(5, 0.0, 0.0, w, h);
        let b = photo(5, -60.0, 34.0, w, h);
        let scale = reduction(w, h);
        assert_eq!(scale, 2);
        let m = match_pair(&texture(&a, scale), &texture(&b, scale));
        assert!(m.accepted, "{m:?}");
        assert!(
            (m.shift.0 - 60.0).abs() < 1.5 && (m.shift.1 + 34.0).abs() < 1.5,
            "{m:?}"
        );
    }
}

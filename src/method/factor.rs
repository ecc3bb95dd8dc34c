//! `F`, the multiplicative factor image (light cones, attenuation, vehicle pose).
//!
//! Each survey photo is downsampled by a `K`×`K` spatial median; the per-pixel temporal median of those over the
//! sliding window is `M`, a virtual "all-seafloor" photo. Then `F = (M − S) / C`, with `C` the assumed seafloor
//! colour. `F` lives at the low resolution and is upsampled bilinearly, with samples at the block centres.

use crate::method::median::blocks;
use crate::method::raster::Raster;

/// Blocks across the photo's longer side that `--downsample auto` aims for. `F` is estimated per block and
/// upsampled between block centres, and the blend's level is a block's, so a block that is large against the
/// frame smooths the light cones' edges and the seafloor's detail: on the dive matrix (three seed sets), blocks
/// of 4 against 8 lowered the residual pattern's median by 4–10 % at 320×240 and 8–20 % at 640×480, and the
/// albedo error's and overlap difference's medians too (docs/evaluation.md).
pub const AUTO_BLOCKS_ACROSS: usize = 160;

/// Largest block `--downsample auto` chooses: the paper's 8 (12–24 MP photos have 500 and more blocks across).
pub const AUTO_MAX_BLOCK: usize = 8;

/// Smallest block `--downsample auto` chooses: a median of 16 samples (blocks of 2 raised the albedo error on the
/// dive matrix at 320×240 and at 640×480).
pub const AUTO_MIN_BLOCK: usize = 4;

/// The block size `K` that `--downsample auto` takes for photos of `width`×`height`: about
/// `AUTO_BLOCKS_ACROSS` blocks across the longer side, from `AUTO_MIN_BLOCK` to `AUTO_MAX_BLOCK` pixels.
pub fn auto_block(width: usize, height: usize) -> usize {
    (width.max(height) / AUTO_BLOCKS_ACROSS).clamp(AUTO_MIN_BLOCK, AUTO_MAX_BLOCK)
}

/// `F = (M − S_low) / C` per channel (`S_low = 0` when there is no scatter estimate). Not floored: the floor is
/// applied per full-resolution pixel in `correct`.
pub fn factor(m: &Raster, s_low: Option<&Raster>, colour: &[f32]) -> Raster {
    let c = m.channels;
    assert_eq!(colour.len(), c, "one seafloor colour component per channel");
    if let Some(s) = s_low {
        assert_eq!(
            s.layout(),
            m.layout(),
            "scatter and factor image differ in size"
        );
    }
    let mut f = m.clone();
    for (i, v) in f.data.iter_mut().enumerate() {
        let s = s_low.map_or(0.0, |s| s.data[i]);
        *v = (*v - s) / colour[i % c];
    }
    f
}

/// [`factor`], with the blocks a mask left without samples (`masked`) filled from their neighbours.
pub(crate) fn factor_filled(
    m: &Raster,
    s_low: Option<&Raster>,
    colour: &[f32],
    masked: bool,
) -> Raster {
    let mut f = factor(m, s_low, colour);
    if masked {
        crate::method::mask::fill_missing(&mut f);
    }
    f
}

/// The product `F·C = M − S` that `--save-factors` writes: what the seafloor would look like under the lights,
/// without backscatter. Viewable as an image, and `F` is it divided by `C`.
pub fn lit_seafloor(f: &Raster, colour: &[f32]) -> Raster {
    let mut out = f.clone();
    let c = f.channels;
    for (i, v) in out.data.iter_mut().enumerate() {
        *v *= colour[i % c];
    }
    out
}

/// One bilinear interpolation tap along an axis: the two low-resolution samples and the weight of the second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tap {
    /// The low-resolution sample before the coordinate.
    pub i0: u32,
    /// The low-resolution sample after it (`i0` at the edges).
    pub i1: u32,
    /// Weight of `i1`.
    pub t: f32,
}

/// Centre (in full-resolution pixel coordinates) of block `b` along an axis of `len` pixels; the last block may
/// be partial, and its centre is that of the pixels it really covers.
pub fn block_centre(b: usize, k: usize, len: usize) -> f32 {
    let start = b * k;
    let end = ((b + 1) * k).min(len);
    (start + end - 1) as f32 * 0.5
}

/// Interpolation taps for every full-resolution coordinate along an axis of `len` pixels cut into `k`-blocks.
/// Outside the first and last block centre the edge value is held.
pub fn taps(len: usize, k: usize) -> Vec<Tap> {
    let nb = blocks(len, k);
    let mut out = Vec::with_capacity(len);
    let mut b = 0usize;
    for x in 0..len {
        let xf = x as f32;
        while b + 1 < nb && block_centre(b + 1, k, len) <= xf {
            b += 1;
        }
        let c0 = block_centre(b, k, len);
        if b + 1 >= nb || xf <= c0 {
            out.push(Tap {
                i0: b as u32,
                i1: b as u32,
                t: 0.0,
            });
        } else {
            let c1 = block_centre(b + 1, k, len);
            out.push(Tap {
                i0: b as u32,
                i1: (b + 1) as u32,
                t: (xf - c0) / (c1 - c0),
            });
        }
    }
    out
}

/// Bilinear upsampling of a low-resolution raster to `width`×`height` (used to save or inspect a full-size `F`;
/// the correction fuses this into its own pass and never builds the full-size image).
pub fn upsample(low: &Raster, k: usize, width: usize, height: usize) -> Raster {
    let (tx, ty) = (taps(width, k), taps(height, k));
    let c = low.channels;
    let mut out = Raster::filled(width, height, c, 0.0);
    let mut row = vec![0.0f32; low.width * c];
    for (y, t) in ty.iter().enumerate() {
        lerp_rows(
            low.row(t.i0 as usize),
            low.row(t.i1 as usize),
            t.t,
            &mut row,
        );
        let dst = &mut out.data[y * width * c..(y + 1) * width * c];
        for (x, tp) in tx.iter().enumerate() {
            for ch in 0..c {
                let a = row[tp.i0 as usize * c + ch];
                let b = row[tp.i1 as usize * c + ch];
                dst[x * c + ch] = a + (b - a) * tp.t;
            }
        }
    }
    out
}

/// `out = a + (b − a)·t`, element-wise.
#[inline]
pub fn lerp_rows(a: &[f32], b: &[f32], t: f32, out: &mut [f32]) {
    for ((o, &a), &b) in out.iter_mut().zip(a).zip(b) {
        *o = a + (b - a) * t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centres_and_partial_blocks() {
        assert_eq!(block_centre(0, 8, 20), 3.5);
        assert_eq!(block_centre(1, 8, 20), 11.5);
        // Last block covers 16..20 only.
        assert_eq!(block_centre(2, 8, 20), 17.5);
    }

    #[test]
    fn upsampling_reproduces_a_plane_exactly_between_centres() {
        // Low-res samples of a linear function taken at the block centres; bilinear interpolation must give the
        // same linear function at every full-res pixel between the outermost centres.
        let (w, h, k) = (37usize, 21usize, 8usize);
        let plane = |x: f32, y: f32| 0.2 + 0.01 * x - 0.004 * y;
        let bw = w.div_ceil(k);
        let bh = h.div_ceil(k);
        let low = Raster::from_fn(bw, bh, 1, |bx, by, _| {
            plane(block_centre(bx, k, w), block_centre(by, k, h))
        });
        let up = upsample(&low, k, w, h);
        let (x_lo, x_hi) = (block_centre(0, k, w), block_centre(bw - 1, k, w));
        let (y_lo, y_hi) = (block_centre(0, k, h), block_centre(bh - 1, k, h));
        for y in 0..h {
            for x in 0..w {
                let (xf, yf) = (x as f32, y as f32);
                let expect = plane(xf.clamp(x_lo, x_hi), yf.clamp(y_lo, y_hi));
                assert!(
                    (up.get(x, y, 0) - expect).abs() < 1e-5,
                    "({x},{y}) {} vs {expect}",
                    up.get(x, y, 0)
                );
            }
        }
    }

    #[test]
    fn k1_upsampling_is_identity() {
        let low = Raster::from_fn(5, 4, 3, |x, y, c| (x * 7 + y * 3 + c) as f32);
        assert_eq!(upsample(&low, 1, 5, 4), low);
    }

    #[test]
    fn auto_block_is_about_160_blocks_across_within_four_to_eight() {
        for (w, h) in [
            (320, 240),
            (240, 320),
            (640, 480),
            (968, 608),
            (1229, 691),
            (1360, 1024),
            (4000, 3000),
            (100, 50),
        ] {
            let k = auto_block(w, h);
            assert!((4..=8).contains(&k), "{w}x{h}: {k}");
            let long = w.max(h);
            // Either at a bound, or the largest block that leaves at least 160 blocks across.
            if k > 4 && k < 8 {
                assert!(long / k >= 160 && long / (k + 1) < 160, "{w}x{h}: {k}");
            }
        }
        assert_eq!(auto_block(320, 240), 4);
        assert_eq!(auto_block(640, 480), 4);
        assert_eq!(auto_block(968, 608), 6);
        assert_eq!(auto_block(4000, 3000), 8);
    }

    #[test]
    fn factor_formula() {
        let m = Raster::from_fn(2, 1, 3, |x, _, c| 0.1 * (x + c + 1) as f32);
        let s = Raster::filled(2, 1, 3, 0.05);
        let f = factor(&m, Some(&s), &[0.5, 0.25, 0.1]);
        assert!((f.get(1, 0, 2) - (0.4 - 0.05) / 0.1).abs() < 1e-6);
        assert!((f.get(0, 0, 0) - (0.1 - 0.05) / 0.5).abs() < 1e-6);
        let lit = lit_seafloor(&f, &[0.5, 0.25, 0.1]);
        assert!((lit.get(1, 0, 2) - 0.35).abs() < 1e-6);
    }
}

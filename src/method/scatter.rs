//! `S`, the additive backscatter: the per-pixel, per-channel temporal median of the water-column frames taken on
//! the way down (camera far above the floor, so they hold only backscatter and floating particles; the median
//! rejects the particles).
//!
//! The full-resolution median needs every frame's value at a pixel at once. To keep memory bounded whatever the
//! number of frames, [`estimate_banded`] holds the frames as row bands: when `frames × frame size` exceeds the
//! memory budget, the image is processed in several bands and each frame is loaded once per band. Reading the
//! frames from files is [`crate::io`]'s part (`Scatter::from_files`, `Scatter::load`).

use std::path::PathBuf;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::method::median::{block_median, column_median};
use crate::method::raster::{BitDepth, Layout, Photo, Raster, Samples};
use crate::method::transfer::Transfer;

/// `S` and how it was made. `S` is kept once, as the index `q` of each sample on the 16-bit grid of stored values
/// (`S = q / 65535`, interleaved like the photos), so that a scatter image saved as 16-bit PNG and loaded again
/// (`--scatter`) gives exactly the same correction, in 2 bytes a sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Scatter {
    /// Size of `S`: the photos' size.
    pub layout: Layout,
    /// Grid index of each sample.
    pub q: Vec<u16>,
    /// Water-column frames that entered the median (0 when loaded from a file).
    pub frames: usize,
    /// Row bands the estimate took (each a loading pass over the frames).
    pub passes: usize,
}

impl Scatter {
    /// `S` from values in stored units (`[0, 1]`), rounded to the 16-bit grid.
    pub fn from_raster(full: &Raster) -> Scatter {
        Scatter {
            layout: full.layout(),
            q: full.data.iter().map(|&v| grid_index(v)).collect(),
            frames: 0,
            passes: 0,
        }
    }

    /// `S` in stored units (`[0, 1]`), e.g. to save or look at it.
    pub fn to_raster(&self) -> Raster {
        Raster {
            width: self.layout.width,
            height: self.layout.height,
            channels: self.layout.channels,
            data: self.q.iter().map(|&q| q as f32 / 65535.0).collect(),
        }
    }

    /// `S` from water-column frames in memory: the per-sample median. Every frame must have the first one's size
    /// and bit depth. `None` when `frames` is empty.
    pub fn from_frames(frames: &[Photo]) -> Result<Option<Scatter>> {
        for (i, p) in frames.iter().enumerate() {
            p.check().map_err(|e| Error::Mismatch {
                path: PathBuf::from(format!("water-column frame {i}")),
                reason: e.to_string(),
            })?;
        }
        if let Some(first) = frames.first() {
            if let Some((i, p)) = frames
                .iter()
                .enumerate()
                .find(|(_, p)| p.layout != first.layout || p.depth() != first.depth())
            {
                return Err(Error::Mismatch {
                    path: PathBuf::from(format!("water-column frame {i}")),
                    reason: format!(
                        "frame is {} {}-bit, the first is {} {}-bit",
                        p.layout,
                        p.depth().bits(),
                        first.layout,
                        first.depth().bits()
                    ),
                });
            }
        }
        let refs: Vec<&Photo> = frames.iter().collect();
        estimate_banded(
            &refs,
            usize::MAX,
            |p| Ok((*p).clone()),
            |_| PathBuf::new(),
            |_| {},
        )
    }

    /// `S` at the resolution of the factor images: the same `k`×`k` block median as the survey photos get.
    pub fn downsampled(&self, k: usize) -> Raster {
        let l = self.layout;
        block_median(&self.q, l.width, l.height, l.channels, k)
    }

    /// A copy with the pixels marked in `replace` taken from `values` (stored units, same size).
    pub fn with_pixels_from(&self, values: &Raster, replace: &[bool]) -> Scatter {
        let c = self.layout.channels;
        let mut out = self.clone();
        for (p, _) in replace.iter().enumerate().filter(|(_, &r)| r) {
            for i in p * c..(p + 1) * c {
                out.q[i] = grid_index(values.data[i]);
            }
        }
        out
    }

    /// `S` as the correction pass reads it, for photos whose codes follow `transfer`.
    pub fn prepare(&self, transfer: Transfer) -> Prepared {
        Prepared::new(self, transfer)
    }
}

/// `S` as the correction pass reads it: for every sample its index `q` on the 16-bit grid that [`Scatter`] keeps
/// (`S = q / 65535` in stored units), 2 bytes a sample instead of the 4 of an `f32`. The correction pass streams
/// all of `S` once per photo (72 MB instead of 144 MB at 12 MP), and with linear codes the numerator of
/// `(I − S) / F` becomes an exact integer (`257·code − q` for 8-bit photos, `code − q` for 16-bit ones).
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Size of `S`, the photos' size.
    pub layout: Layout,
    /// Grid index of each sample, interleaved like the photos.
    pub q: Vec<u16>,
    /// `S` in linear light by grid index, for a transfer that is not linear (empty for linear codes).
    linear: Vec<f32>,
}

impl Prepared {
    /// `S` for photos whose codes follow `transfer`.
    pub fn new(s: &Scatter, transfer: Transfer) -> Prepared {
        let linear = if transfer.is_linear() {
            Vec::new()
        } else {
            // The same expression as `transfer.to_linear` of the quantised value, so the same bits.
            (0..=65535u32)
                .map(|q| transfer.to_linear(q as f32 / 65535.0))
                .collect()
        };
        Prepared {
            layout: s.layout,
            q: s.q.clone(),
            linear,
        }
    }

    /// `S` given in stored units (`[0, 1]`, rounded to the 16-bit grid), for photos whose codes follow
    /// `transfer`.
    pub fn from_raster(full: &Raster, transfer: Transfer) -> Prepared {
        Prepared::new(&Scatter::from_raster(full), transfer)
    }

    /// One row of grid indices.
    pub fn row(&self, y: usize) -> &[u16] {
        let n = self.layout.width * self.layout.channels;
        &self.q[y * n..(y + 1) * n]
    }

    /// `S` in linear light by grid index (non-linear transfers), or `None` when `S = q / 65535` is linear already.
    pub fn linear_table(&self) -> Option<&[f32]> {
        (!self.linear.is_empty()).then_some(self.linear.as_slice())
    }
}

/// Index on the 16-bit grid of a value in `[0, 1]` (clamped; NaN gives 0).
fn grid_index(v: f32) -> u16 {
    (v.clamp(0.0, 1.0) * 65535.0).round() as u16
}

/// Samples `range` of a photo as `u16`, and the photo's largest code.
fn widen(samples: &Samples, range: std::ops::Range<usize>) -> (Vec<u16>, f32) {
    match samples {
        Samples::U8(v) => (v[range].iter().map(|&s| s as u16).collect(), 255.0),
        Samples::U16(v) => (v[range].to_vec(), 65535.0),
    }
}

/// Load `frames` a few at a time on the worker threads, handing each result to `each` in the frames' order;
/// at most as many loaded photos as there are threads are held at once.
fn load_in_order<'e, E: Sync>(
    frames: &[&'e E],
    load: &(dyn Fn(&E) -> Result<Photo> + Sync),
    mut each: impl FnMut(&'e E, Result<Photo>) -> Result<()>,
) -> Result<()> {
    for group in frames.chunks(rayon::current_num_threads().max(1)) {
        let loaded: Vec<Result<Photo>> = group.par_iter().map(|e| load(e)).collect();
        for (e, photo) in group.iter().zip(loaded) {
            each(e, photo)?;
        }
    }
    Ok(())
}

/// Estimate `S` from water-column frames that `load` produces (called once per row band for each usable frame).
/// Frames that cannot be loaded or do not match the first usable frame are passed to `on_error` (a mismatch
/// names the frame with `name`) and left out. Returns `None` when no frame could be used.
pub fn estimate_banded<E: Sync>(
    frames: &[E],
    memory_budget: usize,
    load: impl Fn(&E) -> Result<Photo> + Sync,
    name: impl Fn(&E) -> PathBuf,
    mut on_error: impl FnMut(Error),
) -> Result<Option<Scatter>> {
    // First pass: find the usable frames and the layout; keep the first band.
    let mut layout: Option<(Layout, BitDepth)> = None;
    let mut usable: Vec<&E> = Vec::new();
    let mut band: Vec<Vec<u16>> = Vec::new();
    let mut rows_per_band = 0usize;
    let mut max = 255.0f32;
    let all: Vec<&E> = frames.iter().collect();
    load_in_order(&all, &load, |e, photo| {
        let photo = match photo {
            Ok(p) => p,
            Err(err) => {
                on_error(err);
                return Ok(());
            }
        };
        let l = match layout {
            None => {
                let l = photo.layout;
                layout = Some((l, photo.depth()));
                let row_bytes = l.width * l.channels * 2;
                rows_per_band = (memory_budget / (frames.len().max(1) * row_bytes.max(1)))
                    .clamp(1, l.height.max(1));
                l
            }
            Some((l, d)) if l != photo.layout || d != photo.depth() => {
                on_error(mismatch(name(e), &photo, l, d));
                return Ok(());
            }
            Some((l, _)) => l,
        };
        let n = rows_per_band.min(l.height) * l.width * l.channels;
        let (wide, m) = widen(&photo.samples, 0..n);
        max = m;
        band.push(wide);
        usable.push(e);
        Ok(())
    })?;
    let Some((l, _)) = layout else {
        return Ok(None);
    };
    let mut q = vec![0u16; l.width * l.height * l.channels];
    let row_len = l.width * l.channels;
    let mut passes = 0;
    let mut y0 = 0;
    while y0 < l.height {
        let y1 = (y0 + rows_per_band).min(l.height);
        if passes > 0 {
            band.clear();
            load_in_order(&usable, &load, |_, photo| {
                band.push(widen(&photo?.samples, y0 * row_len..y1 * row_len).0);
                Ok(())
            })?;
        }
        let out = &mut q[y0 * row_len..y1 * row_len];
        band_median(out, &band, row_len, max);
        passes += 1;
        y0 = y1;
    }
    Ok(Some(Scatter {
        layout: l,
        q,
        frames: usable.len(),
        passes,
    }))
}

/// The error for a water-column frame whose layout or bit depth `photo` differs from the others' (`l`, `d`).
fn mismatch(path: PathBuf, photo: &Photo, l: Layout, d: BitDepth) -> Error {
    Error::Mismatch {
        path,
        reason: format!(
            "water-column frame is {} {}-bit, the others are {} {}-bit; left out of the scatter estimate",
            photo.layout,
            photo.depth().bits(),
            l,
            d.bits()
        ),
    }
}

/// Fill `out` (rows of `row_len`) with the grid index of each sample's median over the frames' `band`, over `max`.
fn band_median(out: &mut [u16], band: &[Vec<u16>], row_len: usize, max: f32) {
    let band_ref = band;
    out.par_chunks_mut(row_len).enumerate().for_each_init(
        || vec![0f32; row_len],
        |median, (r, out_row)| {
            let base = r * row_len;
            let cols: Vec<&[u16]> = band_ref.iter().map(|f| &f[base..base + row_len]).collect();
            column_median(&cols, median);
            for (o, m) in out_row.iter_mut().zip(median.iter()) {
                *o = grid_index(*m / max);
            }
        },
    );
}

/// `S` as the engine takes it: prepared for the correction at full resolution and at blocks of `k` in linear light
/// (`transfer`), the blocks a mask leaves without samples filled from their neighbours and, under the mask, the
/// smooth fill at full resolution too (the water-column frames hold whatever is burned in there).
pub(crate) fn for_the_engine(
    scatter: Option<&Scatter>,
    mask: Option<&crate::method::mask::Mask>,
    k: usize,
    transfer: crate::method::transfer::Transfer,
) -> crate::error::Result<(Option<Prepared>, Option<Raster>)> {
    use crate::method::mask::{block_median_masked, fill_missing};
    if let (Some(m), Some(s)) = (mask, scatter) {
        if (m.width, m.height) != (s.layout.width, s.layout.height) {
            return Err(crate::error::Error::Usage(format!(
                "the mask is {}x{} but the scatter image is {}",
                m.width, m.height, s.layout
            )));
        }
    }
    let scatter_low_codes = scatter.map(|s| {
        let mut low = match mask {
            Some(m) => block_median_masked(&s.q, s.layout, k, m),
            None => s.downsampled(k),
        };
        fill_missing(&mut low);
        low
    });
    let prepared = scatter.map(|s| match (mask, &scatter_low_codes) {
        // Under the mask, S holds whatever is burned into the water-column frames too: use the smooth fill.
        (Some(m), Some(low)) => {
            let smooth = crate::method::factor::upsample(low, k, s.layout.width, s.layout.height);
            s.with_pixels_from(&smooth, &m.ignore).prepare(transfer)
        }
        _ => s.prepare(transfer),
    });
    let scatter_low = scatter_low_codes.map(|mut low| {
        for v in &mut low.data {
            *v = transfer.to_linear(*v);
        }
        low
    });
    Ok((prepared, scatter_low))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::method::median::reference;

    /// A water-column frame of random 8-bit RGB samples (xorshift from `seed`).
    pub(crate) fn frame(seed: u64, w: usize, h: usize) -> Photo {
        let mut s = seed | 1;
        Photo {
            layout: Layout {
                width: w,
                height: h,
                channels: 3,
            },
            samples: Samples::U8(
                (0..w * h * 3)
                    .map(|_| {
                        s ^= s << 13;
                        s ^= s >> 7;
                        s ^= s << 17;
                        (s >> 40) as u8
                    })
                    .collect(),
            ),
            alpha: None,
        }
    }

    /// The median of every sample over the frames, brute force, in `[0, 1]`.
    fn brute_force(photos: &[Photo]) -> Vec<f64> {
        let n = photos[0].samples.len();
        (0..n)
            .map(|i| {
                let vals: Vec<f64> = photos
                    .iter()
                    .map(|p| match &p.samples {
                        Samples::U8(v) => v[i] as f64,
                        _ => unreachable!(),
                    })
                    .collect();
                reference::median(&vals) / 255.0
            })
            .collect()
    }

    #[test]
    fn median_matches_brute_force_in_one_or_many_bands() {
        let (w, h) = (13, 9);
        for b in [1usize, 4, 5] {
            let photos: Vec<Photo> = (0..b as u64).map(|i| frame(i + 11, w, h)).collect();
            let expected = brute_force(&photos);
            for budget in [1usize << 30, w * 3 * 2 * b * 2] {
                let s = estimate_banded(
                    &photos,
                    budget,
                    |p| Ok(p.clone()),
                    |_| PathBuf::new(),
                    |e| panic!("{e}"),
                )
                .unwrap()
                .unwrap();
                assert_eq!(s.frames, b);
                if budget < 1000 {
                    assert!(s.passes > 1, "small budget must band");
                }
                for (g, e) in s.to_raster().data.iter().zip(&expected) {
                    assert!(
                        (*g as f64 - e).abs() <= 0.5 / 65535.0 + 1e-7,
                        "b={b}: {g} vs {e}"
                    );
                }
            }
            let from_frames = Scatter::from_frames(&photos).unwrap().unwrap();
            assert_eq!(
                from_frames.q,
                estimate_banded(
                    &photos,
                    1 << 30,
                    |p| Ok(p.clone()),
                    |_| PathBuf::new(),
                    |_| {}
                )
                .unwrap()
                .unwrap()
                .q
            );
        }
    }

    #[test]
    fn from_frames_refuses_a_frame_of_another_size() {
        let e = Scatter::from_frames(&[frame(1, 6, 4), frame(2, 5, 4)]).unwrap_err();
        assert!(e.to_string().contains("5x4"), "{e}");
        assert!(Scatter::from_frames(&[]).unwrap().is_none());
    }

    #[test]
    fn raster_round_trip_is_exact_on_the_grid() {
        let s = Scatter::from_frames(&[frame(3, 7, 5), frame(4, 7, 5), frame(5, 7, 5)])
            .unwrap()
            .unwrap();
        assert_eq!(Scatter::from_raster(&s.to_raster()).q, s.q);
    }
}

//! `S`, the additive backscatter: the per-pixel, per-channel temporal median of the water-column frames taken on
//! the way down (camera far above the floor, so they hold only backscatter and floating particles; the median
//! rejects the particles).
//!
//! The full-resolution median needs every frame's value at a pixel at once. To keep memory bounded whatever the
//! number of frames, the frames are held as row bands: when `frames × frame size` exceeds the memory budget, the
//! image is processed in several bands and each frame is decoded once per band.

use std::path::Path;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::io::{decode, Entry};
use crate::median::{block_median, column_median};
use crate::raster::{Layout, Photo, Raster, Samples};
use crate::transfer::Transfer;

/// The scatter image and how it was made.
#[derive(Debug, Clone)]
pub struct Scatter {
    /// `S` at full resolution, normalised to `[0, 1]` and quantised to the 16-bit grid, so that a scatter image
    /// saved as 16-bit PNG and loaded again (`--scatter`) gives exactly the same correction.
    pub full: Raster,
    /// Water-column frames that entered the median (0 when loaded from a file).
    pub frames: usize,
    /// Row bands the estimate took (each a decoding pass over the frames).
    pub passes: usize,
}

impl Scatter {
    /// `S` at the resolution of the factor images: the same `k`×`k` block median as the survey photos get.
    pub fn downsampled(&self, k: usize) -> Raster {
        let s = &self.full;
        block_median(&s.to_u16(), s.width, s.height, s.channels, k)
    }

    /// A scatter image saved by an earlier run.
    pub fn load(path: &Path) -> Result<Scatter> {
        let mut full = crate::io::load_raster(path)?;
        quantise_16(&mut full.data);
        Ok(Scatter {
            full,
            frames: 0,
            passes: 0,
        })
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
    /// `S` given in stored units (`[0, 1]`, values already on the 16-bit grid stay exact; others are rounded to
    /// it), for photos whose codes follow `transfer`.
    pub fn new(full: &Raster, transfer: Transfer) -> Prepared {
        let q = full.data.iter().map(|&v| grid_index(v)).collect();
        let linear = if transfer.is_linear() {
            Vec::new()
        } else {
            // The same expression as `transfer.to_linear` of the quantised value, so the same bits.
            (0..=65535u32)
                .map(|q| transfer.to_linear(q as f32 / 65535.0))
                .collect()
        };
        Prepared {
            layout: full.layout(),
            q,
            linear,
        }
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

fn quantise_16(v: &mut [f32]) {
    for x in v {
        *x = (x.clamp(0.0, 1.0) * 65535.0).round() / 65535.0;
    }
}

/// Samples `range` of a photo as `u16`, and the photo's largest code.
fn widen(samples: &Samples, range: std::ops::Range<usize>) -> (Vec<u16>, f32) {
    match samples {
        Samples::U8(v) => (v[range].iter().map(|&s| s as u16).collect(), 255.0),
        Samples::U16(v) => (v[range].to_vec(), 65535.0),
    }
}

/// Decode `frames` a few at a time on the worker threads, handing each result to `each` in the frames' order;
/// at most as many decoded photos as there are threads are held at once.
fn decode_in_order<'e>(
    frames: &[&'e Entry],
    mut each: impl FnMut(&'e Entry, Result<Photo>) -> Result<()>,
) -> Result<()> {
    for group in frames.chunks(rayon::current_num_threads().max(1)) {
        let decoded: Vec<Result<Photo>> = group.par_iter().map(|e| decode(&e.path)).collect();
        for (e, photo) in group.iter().zip(decoded) {
            each(e, photo)?;
        }
    }
    Ok(())
}

/// Estimate `S` from water-column frames. Frames that cannot be read or do not match the first readable frame
/// are passed to `on_error` and left out. Returns `None` when no frame could be used.
pub fn estimate(
    frames: &[Entry],
    memory_budget: usize,
    mut on_error: impl FnMut(Error),
) -> Result<Option<Scatter>> {
    // First pass: find the usable frames and the layout; keep the first band.
    let mut layout: Option<(Layout, crate::raster::BitDepth)> = None;
    let mut usable: Vec<&Entry> = Vec::new();
    let mut band: Vec<Vec<u16>> = Vec::new();
    let mut rows_per_band = 0usize;
    let mut max = 255.0f32;
    let all: Vec<&Entry> = frames.iter().collect();
    decode_in_order(&all, |e, photo| {
        let photo = match photo {
            Ok(p) => p,
            Err(err) => {
                on_error(err);
                return Ok(());
            }
        };
        match layout {
            None => {
                let l = photo.layout;
                layout = Some((l, photo.depth()));
                let row_bytes = l.width * l.channels * 2;
                rows_per_band = (memory_budget / (frames.len().max(1) * row_bytes.max(1)))
                    .clamp(1, l.height.max(1));
            }
            Some((l, d)) if l != photo.layout || d != photo.depth() => {
                on_error(Error::Mismatch {
                    path: e.path.clone(),
                    reason: format!(
                        "water-column frame is {} {}-bit, the others are {} {}-bit; left out of the scatter estimate",
                        photo.layout,
                        photo.depth().bits(),
                        l,
                        d.bits()
                    ),
                });
                return Ok(());
            }
            _ => {}
        }
        let (l, _) = layout.unwrap();
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
    let mut full = Raster::filled(l.width, l.height, l.channels, 0.0);
    let row_len = l.width * l.channels;
    let mut passes = 0;
    let mut y0 = 0;
    while y0 < l.height {
        let y1 = (y0 + rows_per_band).min(l.height);
        if passes > 0 {
            band.clear();
            decode_in_order(&usable, |_, photo| {
                band.push(widen(&photo?.samples, y0 * row_len..y1 * row_len).0);
                Ok(())
            })?;
        }
        let out = &mut full.data[y0 * row_len..y1 * row_len];
        let band_ref = &band;
        out.par_chunks_mut(row_len)
            .enumerate()
            .for_each(|(r, out_row)| {
                let base = r * row_len;
                let cols: Vec<&[u16]> = band_ref.iter().map(|f| &f[base..base + row_len]).collect();
                column_median(&cols, out_row);
                for o in out_row.iter_mut() {
                    *o /= max;
                }
            });
        passes += 1;
        y0 = y1;
    }
    quantise_16(&mut full.data);
    Ok(Some(Scatter {
        full,
        frames: usable.len(),
        passes,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{write_atomic, EncodeSettings};
    use crate::median::reference;

    fn frame(seed: u64, w: usize, h: usize) -> Photo {
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

    #[test]
    fn median_matches_brute_force_in_one_or_many_bands() {
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (13, 9);
        for b in [1usize, 4, 5] {
            let photos: Vec<Photo> = (0..b as u64).map(|i| frame(i + 11, w, h)).collect();
            let entries: Vec<Entry> = photos
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let path = d.path().join(format!("b{b}_{i}.png"));
                    write_atomic(p, &path, EncodeSettings::default()).unwrap();
                    Entry {
                        relative: path.clone(),
                        path,
                    }
                })
                .collect();
            let expected: Vec<f64> = (0..w * h * 3)
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
                .collect();
            for budget in [1usize << 30, w * 3 * 2 * b * 2] {
                let s = estimate(&entries, budget, |e| panic!("{e}"))
                    .unwrap()
                    .unwrap();
                assert_eq!(s.frames, b);
                if budget < 1000 {
                    assert!(s.passes > 1, "small budget must band");
                }
                for (g, e) in s.full.data.iter().zip(&expected) {
                    assert!(
                        (*g as f64 - e).abs() <= 0.5 / 65535.0 + 1e-7,
                        "b={b}: {g} vs {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn bad_and_mismatched_frames_are_reported_and_left_out() {
        let d = tempfile::tempdir().unwrap();
        let mut entries = Vec::new();
        for (i, p) in [frame(1, 6, 4), frame(2, 5, 4), frame(3, 6, 4)]
            .iter()
            .enumerate()
        {
            let path = d.path().join(format!("{i}.png"));
            write_atomic(p, &path, EncodeSettings::default()).unwrap();
            entries.push(Entry {
                relative: path.clone(),
                path,
            });
        }
        let junk = d.path().join("junk.png");
        std::fs::write(&junk, b"nope").unwrap();
        entries.push(Entry {
            relative: junk.clone(),
            path: junk,
        });
        let mut errors = Vec::new();
        let s = estimate(&entries, 1 << 20, |e| errors.push(e.to_string()))
            .unwrap()
            .unwrap();
        assert_eq!(s.frames, 2);
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors
            .iter()
            .any(|e| e.contains("1.png") && e.contains("5x4")));
        assert!(errors.iter().any(|e| e.contains("junk.png")));
    }

    #[test]
    fn saved_scatter_reloads_identically() {
        let d = tempfile::tempdir().unwrap();
        let mut entries = Vec::new();
        for i in 0..4 {
            let path = d.path().join(format!("{i}.png"));
            write_atomic(&frame(i + 1, 7, 5), &path, EncodeSettings::default()).unwrap();
            entries.push(Entry {
                relative: path.clone(),
                path,
            });
        }
        let s = estimate(&entries, 1 << 20, |e| panic!("{e}"))
            .unwrap()
            .unwrap();
        let p = d.path().join("scatter.png");
        crate::io::save_raster_png16(&s.full, &p).unwrap();
        assert_eq!(Scatter::load(&p).unwrap().full, s.full);
    }
}

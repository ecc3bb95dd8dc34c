//! Median kernels: the robust statistic the whole method rests on (breakdown point 50 %).
//!
//! Convention everywhere: the median of an even number of values is the mean of the two middle ones.

use rayon::prelude::*;

use crate::raster::{Raster, Sample};

/// Median of integer samples, reordering `v`. Returns the value in sample units. `v` must not be empty.
pub fn median_of_samples<T: Sample>(v: &mut [T]) -> f32 {
    let n = v.len();
    debug_assert!(n > 0);
    let mid = n / 2;
    let (lower, upper_mid, _) = v.select_nth_unstable(mid);
    let upper = upper_mid.to_u16() as f32;
    if n % 2 == 1 {
        upper
    } else {
        let lower_max = lower.iter().copied().max().unwrap_or(*upper_mid);
        (lower_max.to_u16() as f32 + upper) * 0.5
    }
}

/// Median of `f32` values, reordering `v`. `v` must not be empty. NaN sorts last (`total_cmp`).
pub fn median_of_f32(v: &mut [f32]) -> f32 {
    let n = v.len();
    debug_assert!(n > 0);
    if n <= 32 {
        // Insertion sort: the temporal window is small, and this beats selection there.
        for i in 1..n {
            let x = v[i];
            let mut j = i;
            while j > 0 && v[j - 1].total_cmp(&x).is_gt() {
                v[j] = v[j - 1];
                j -= 1;
            }
            v[j] = x;
        }
        return if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
    }
    let mid = n / 2;
    let (lower, upper, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    let upper = *upper;
    if n % 2 == 1 {
        upper
    } else {
        let lower_max = lower.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        0.5 * (lower_max + upper)
    }
}

/// Number of blocks of size `k` covering `len` pixels (the last block may be partial).
#[inline]
pub fn blocks(len: usize, k: usize) -> usize {
    len.div_ceil(k)
}

/// Spatial median downsampling: every `k`×`k` block (partial blocks at the right and bottom border included) becomes
/// one pixel holding the per-channel median of the block, normalised to `[0, 1]`.
pub fn block_median<T: Sample>(
    samples: &[T],
    width: usize,
    height: usize,
    channels: usize,
    k: usize,
) -> Raster {
    assert!(k > 0, "block size must be positive");
    assert_eq!(samples.len(), width * height * channels);
    let bw = blocks(width, k);
    let bh = blocks(height, k);
    let mut out = Raster::filled(bw, bh, channels, 0.0);
    if bw == 0 || bh == 0 {
        return out;
    }
    let scale = 1.0 / T::MAX;
    let row_len = width * channels;
    out.data
        .par_chunks_mut(bw * channels)
        .enumerate()
        .for_each(|(by, out_row)| {
            let y0 = by * k;
            let y1 = (y0 + k).min(height);
            let mut scratch: Vec<T> = Vec::with_capacity(k * k);
            for bx in 0..bw {
                let x0 = bx * k;
                let x1 = (x0 + k).min(width);
                for c in 0..channels {
                    scratch.clear();
                    for y in y0..y1 {
                        let row = &samples[y * row_len..(y + 1) * row_len];
                        scratch.extend((x0..x1).map(|x| row[x * channels + c]));
                    }
                    out_row[bx * channels + c] = median_of_samples(&mut scratch) * scale;
                }
            }
        });
    out
}

/// Per-sample median over a stack of rasters of the same layout (the temporal median).
pub fn stack_median(frames: &[&Raster]) -> Raster {
    assert!(!frames.is_empty(), "median of an empty stack");
    let first = frames[0];
    for f in frames {
        assert_eq!(f.layout(), first.layout(), "stack of unequal rasters");
    }
    let mut out = Raster::filled(first.width, first.height, first.channels, 0.0);
    let row_len = first.width * first.channels;
    if row_len == 0 {
        return out;
    }
    out.data
        .par_chunks_mut(row_len)
        .enumerate()
        .for_each(|(y, out_row)| {
            let mut scratch = vec![0.0f32; frames.len()];
            let rows: Vec<&[f32]> = frames.iter().map(|f| f.row(y)).collect();
            for (i, o) in out_row.iter_mut().enumerate() {
                for (s, r) in scratch.iter_mut().zip(&rows) {
                    *s = r[i];
                }
                *o = median_of_f32(&mut scratch);
            }
        });
    out
}

#[cfg(test)]
pub(crate) mod reference {
    //! Brute-force twins of the kernels above, written to be obviously right.
    use crate::raster::Raster;

    /// Sort everything, take the middle (or the mean of the two middles).
    pub fn median(values: &[f64]) -> f64 {
        let mut v = values.to_vec();
        v.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            (v[n / 2 - 1] + v[n / 2]) / 2.0
        }
    }

    /// Block median by visiting every output pixel and gathering its block pixel by pixel.
    pub fn block_median(
        samples: &[f64],
        width: usize,
        height: usize,
        channels: usize,
        k: usize,
        max: f64,
    ) -> Vec<f64> {
        let bw = width.div_ceil(k);
        let bh = height.div_ceil(k);
        let mut out = Vec::new();
        for by in 0..bh {
            for bx in 0..bw {
                for c in 0..channels {
                    let mut block = Vec::new();
                    for y in 0..height {
                        for x in 0..width {
                            if x / k == bx && y / k == by {
                                block.push(samples[(y * width + x) * channels + c]);
                            }
                        }
                    }
                    out.push(median(&block) / max);
                }
            }
        }
        out
    }

    pub fn stack_median(frames: &[Raster]) -> Vec<f64> {
        (0..frames[0].data.len())
            .map(|i| median(&frames.iter().map(|f| f.data[i] as f64).collect::<Vec<_>>()))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn median_even_and_odd() {
        assert_eq!(median_of_samples(&mut [3u8, 1, 2]), 2.0);
        assert_eq!(median_of_samples(&mut [4u8, 1, 3, 2]), 2.5);
        assert_eq!(median_of_samples(&mut [7u16]), 7.0);
        assert_eq!(median_of_f32(&mut [0.5, 0.1]), 0.3);
        // A single outlier cannot move the median (breakdown point 50 %).
        assert_eq!(median_of_samples(&mut [10u8, 10, 255, 10, 0]), 10.0);
    }

    proptest! {
        #[test]
        fn sample_median_matches_sorting(v in proptest::collection::vec(any::<u16>(), 1..200)) {
            let expected = reference::median(&v.iter().map(|&x| x as f64).collect::<Vec<_>>());
            let got = median_of_samples(&mut v.clone());
            prop_assert!((got as f64 - expected).abs() <= 1e-9 * expected.max(1.0), "{got} vs {expected}");
        }

        #[test]
        fn f32_median_matches_sorting(v in proptest::collection::vec(-1000.0f32..1000.0, 1..100)) {
            let expected = reference::median(&v.iter().map(|&x| x as f64).collect::<Vec<_>>());
            let got = median_of_f32(&mut v.clone());
            prop_assert!((got as f64 - expected).abs() <= 1e-4, "{got} vs {expected}");
        }

        #[test]
        fn block_median_matches_brute_force(
            w in 0usize..20, h in 0usize..20, c in prop_oneof![Just(1usize), Just(3usize)],
            k in 1usize..9, seed in any::<u64>()
        ) {
            let mut state = seed | 1;
            let samples: Vec<u8> = (0..w * h * c).map(|_| {
                state ^= state << 13; state ^= state >> 7; state ^= state << 17;
                (state >> 24) as u8
            }).collect();
            let got = block_median(&samples, w, h, c, k);
            let expected = reference::block_median(
                &samples.iter().map(|&s| s as f64).collect::<Vec<_>>(), w, h, c, k, 255.0);
            prop_assert_eq!(got.width, w.div_ceil(k));
            prop_assert_eq!(got.height, h.div_ceil(k));
            prop_assert_eq!(got.data.len(), expected.len());
            for (g, e) in got.data.iter().zip(&expected) {
                prop_assert!((*g as f64 - e).abs() < 1e-6, "{g} vs {e}");
            }
        }

        #[test]
        fn stack_median_matches_brute_force(
            n in 1usize..12, w in 1usize..6, h in 1usize..6, seed in any::<u64>()
        ) {
            let mut state = seed | 1;
            let frames: Vec<Raster> = (0..n).map(|_| Raster::from_fn(w, h, 3, |_, _, _| {
                state ^= state << 13; state ^= state >> 7; state ^= state << 17;
                (state % 1000) as f32 / 1000.0
            })).collect();
            let refs: Vec<&Raster> = frames.iter().collect();
            let got = stack_median(&refs);
            let expected = reference::stack_median(&frames);
            for (g, e) in got.data.iter().zip(&expected) {
                prop_assert!((*g as f64 - e).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn block_median_16_bit_partial_blocks() {
        // 3x2 grey image, k = 2: blocks {0,1,3,4} and {2,5}.
        let s: Vec<u16> = vec![0, 100, 65535, 300, 400, 1];
        let r = block_median(&s, 3, 2, 1, 2);
        assert_eq!((r.width, r.height), (2, 1));
        assert!((r.data[0] - 200.0 / 65535.0).abs() < 1e-7);
        assert!((r.data[1] - 32768.0 / 65535.0).abs() < 1e-7);
    }
}

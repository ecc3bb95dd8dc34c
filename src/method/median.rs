//! Median kernels: the robust statistic the whole method rests on (breakdown point 50 %).
//!
//! Convention everywhere: the median of an even number of values is the mean of the two middle ones.

use rayon::prelude::*;

use crate::method::raster::{Raster, Sample};
#[cfg(target_arch = "x86_64")]
use crate::simd::Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod sse2;
mod unrolled;

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

/// Comparators `(i, j)`, `i < j`, of a sorting network for `n` values: Batcher's odd–even merge sort for the next
/// power of two, without the comparators that touch the missing (conceptually `+∞`) values. Applying them in
/// order with `(min, max)` sorts any input.
pub fn sorting_network(n: usize) -> Vec<(u16, u16)> {
    assert!(n <= u16::MAX as usize, "network too large");
    let p2 = n.next_power_of_two();
    let mut out = Vec::new();
    let mut p = 1;
    while p < p2 {
        let mut k = p;
        while k >= 1 {
            let mut j = k % p;
            while j + k < p2 {
                for i in 0..k.min(p2 - j - k) {
                    let (a, b) = (i + j, i + j + k);
                    if (a / (2 * p)) == (b / (2 * p)) && b < n {
                        out.push((a as u16, b as u16));
                    }
                }
                j += 2 * k;
            }
            k /= 2;
        }
        p *= 2;
    }
    out
}

/// The comparators of `net` that can change the values ending at `positions` (the others are dropped).
pub fn prune_network(net: &[(u16, u16)], positions: &[usize]) -> Vec<(u16, u16)> {
    let size = net
        .iter()
        .map(|&(_, b)| b as usize + 1)
        .chain(positions.iter().map(|&p| p + 1))
        .max()
        .unwrap_or(0);
    let mut needed = vec![false; size];
    for &p in positions {
        needed[p] = true;
    }
    let mut kept: Vec<(u16, u16)> = Vec::new();
    for &(a, b) in net.iter().rev() {
        if needed[a as usize] || needed[b as usize] {
            needed[a as usize] = true;
            needed[b as usize] = true;
            kept.push((a, b));
        }
    }
    kept.reverse();
    kept
}

/// Positions holding the median of `n` sorted values (one for odd `n`, two for even).
fn median_positions(n: usize) -> Vec<usize> {
    if n % 2 == 1 {
        vec![n / 2]
    } else {
        vec![n / 2 - 1, n / 2]
    }
}

/// Apply `net` to `lanes` independent columns stored as `v[e * lanes + lane]` (element `e` of column `lane`).
/// The inner loop runs over lanes with `min`/`max` only, which the compiler vectorises.
fn apply_network<T: Copy + PartialOrd>(net: &[(u16, u16)], v: &mut [T], lanes: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = Avx2::detect() {
        return avx2::apply_network(t, net, v, lanes);
    }
    apply_network_portable(net, v, lanes)
}

/// The portable body of [`apply_network`] (any CPU).
#[inline(always)]
fn apply_network_portable<T: Copy + PartialOrd>(net: &[(u16, u16)], v: &mut [T], lanes: usize) {
    for &(a, b) in net {
        let (a, b) = (a as usize * lanes, b as usize * lanes);
        let (lo, hi) = v.split_at_mut(b);
        let (ra, rb) = (&mut lo[a..a + lanes], &mut hi[..lanes]);
        for (x, y) in ra.iter_mut().zip(rb.iter_mut()) {
            let (p, q) = (*x, *y);
            let swap = q < p;
            *x = if swap { q } else { p };
            *y = if swap { p } else { q };
        }
    }
}

/// Per-column median of integer samples: `out[i]` = the median of `cols[j][i]` over `j` (in sample units, the
/// mean of the two middle ones for an even count), as [`median_of_samples`] would give it, through a sorting
/// network over many columns at once.
pub fn column_median<T: Sample>(cols: &[&[T]], out: &mut [f32]) {
    let n = cols.len();
    assert!(n > 0, "median of no columns");
    for c in cols {
        assert_eq!(c.len(), out.len());
    }
    if n > NETWORK_MAX {
        let mut scratch = vec![T::default(); n];
        for (i, o) in out.iter_mut().enumerate() {
            for (s, c) in scratch.iter_mut().zip(cols) {
                *s = c[i];
            }
            *o = median_of_samples(&mut scratch);
        }
        return;
    }
    let net = prune_network(&sorting_network(n), &median_positions(n));
    let mut v = vec![T::default(); n * LANES];
    for (chunk, o) in out.chunks_mut(LANES).enumerate() {
        let (lanes, s0) = (o.len(), chunk * LANES);
        let v = &mut v[..n * lanes];
        for (e, c) in cols.iter().enumerate() {
            v[e * lanes..(e + 1) * lanes].copy_from_slice(&c[s0..s0 + lanes]);
        }
        apply_network(&net, v, lanes);
        if n % 2 == 1 {
            for (o, &m) in o.iter_mut().zip(&v[(n / 2) * lanes..(n / 2 + 1) * lanes]) {
                *o = m.to_u16() as f32;
            }
        } else {
            let lo = &v[(n / 2 - 1) * lanes..(n / 2) * lanes];
            let hi = &v[(n / 2) * lanes..(n / 2 + 1) * lanes];
            for ((o, &a), &b) in o.iter_mut().zip(lo).zip(hi) {
                *o = (a.to_u16() as f32 + b.to_u16() as f32) * 0.5;
            }
        }
    }
}

/// Largest block (`k²` values) done with a sorting network; larger blocks use selection.
const NETWORK_MAX: usize = 256;
/// Columns sorted at once by a network (sized so that the working set stays in L1).
const LANES: usize = 128;

/// Spatial median downsampling: every `k`×`k` block (partial blocks at the right and bottom border included) becomes
/// one pixel holding the per-channel median of the block, normalised to `[0, 1]`.
///
/// Full blocks go through a pruned sorting network applied to many blocks at once (no per-block sort call;
/// unrolled at compile time for blocks of 4×4 to 8×8); partial blocks and huge `k` use selection. Both give the
/// same value: the middle sample, or the mean of the two middle ones.
pub fn block_median<T: Sample>(
    samples: &[T],
    width: usize,
    height: usize,
    channels: usize,
    k: usize,
) -> Raster {
    assert!(k > 0, "block size must be positive");
    assert_eq!(samples.len(), width * height * channels);
    let (bw, bh) = (blocks(width, k), blocks(height, k));
    let mut out = Raster::filled(bw, bh, channels, 0.0);
    if bw == 0 || bh == 0 {
        return out;
    }
    let (scale, kk) = (1.0 / T::MAX, k * k);
    let net = if kk <= NETWORK_MAX && !unrolled::handles(kk) {
        prune_network(&sorting_network(kk), &median_positions(kk))
    } else {
        Vec::new()
    };
    // Blocks of a row that are complete (k wide); in complete block rows these go through the network.
    let full_bx = if kk <= NETWORK_MAX { width / k } else { 0 };
    out.data
        .par_chunks_mut(bw * channels)
        .enumerate()
        .for_each(|(by, out_row)| {
            let y0 = by * k;
            let y1 = (y0 + k).min(height);
            let first_scalar = if y1 - y0 == k { full_bx } else { 0 };
            let band = Band {
                samples,
                width,
                channels,
                k,
                rows: y0..y1,
            };
            if first_scalar > 0 {
                let total = first_scalar * channels;
                // Whole blocks per chunk (lanes a multiple of the channel count), so the gather copies pixels, and
                // a multiple of 64 lanes, so the network's min/max loops have no scalar tail (126 lanes cost 3×
                // the time of 128). The grouping of lanes does not change any median.
                let chunk_lanes = if LANES.is_multiple_of(channels) {
                    LANES
                } else {
                    channels * 64
                };
                let mut v: Vec<T> = vec![T::default(); kk * chunk_lanes];
                let mut lane0 = 0;
                while lane0 < total {
                    let lanes = chunk_lanes.min(total - lane0);
                    let v = &mut v[..kk * lanes];
                    gather_lanes(&band, v, lanes, lane0);
                    if !unrolled::middle_values(v, kk, lanes) {
                        apply_network(&net, v, lanes);
                    }
                    write_medians(v, kk, lanes, scale, &mut out_row[lane0..lane0 + lanes]);
                    lane0 += lanes;
                }
            }
            selected_medians(&band, first_scalar..bw, scale, out_row);
        });
    out
}

/// The samples of `lanes` lanes of the complete blocks of `band` (a complete block row) from lane `lane0` on, into
/// `v`: element `e = dy·k + dx` of lane `(bx, ch)`.
fn gather_lanes<T: Sample>(band: &Band<T>, v: &mut [T], lanes: usize, lane0: usize) {
    let (samples, k, channels, y0) = (band.samples, band.k, band.channels, band.rows.start);
    let row_len = band.width * channels;
    let rows = (0..k).map(|dy| &samples[(y0 + dy) * row_len..(y0 + dy + 1) * row_len]);
    let rgb8 = (k == 8 && channels == 3)
        .then(|| T::as_bytes(samples).zip(T::as_bytes_mut(v)))
        .flatten();
    if let Some((bytes, vb)) = rgb8 {
        let rows: [&[u8]; 8] =
            std::array::from_fn(|dy| &bytes[(y0 + dy) * row_len..(y0 + dy + 1) * row_len]);
        gather_rgb8_k8(&rows, vb, lanes, lane0);
    } else {
        match channels {
            3 => gather_blocks::<T, 3, 4>(rows, v, k, lanes, lanes, lane0),
            1 => gather_blocks::<T, 1, 2>(rows, v, k, lanes, lanes, lane0),
            _ => gather_blocks_dyn(rows, v, k, lanes, lane0, channels),
        }
    }
}

/// A band of block rows `rows` of a photo of `width` pixels of `channels` samples, in blocks of `k`.
struct Band<'a, T> {
    samples: &'a [T],
    width: usize,
    channels: usize,
    k: usize,
    rows: std::ops::Range<usize>,
}

/// The medians of blocks `bxs` of a band by selection (partial blocks, huge `k`), scaled by `scale`, into the
/// band's output row.
fn selected_medians<T: Sample>(
    b: &Band<T>,
    bxs: std::ops::Range<usize>,
    scale: f32,
    out_row: &mut [f32],
) {
    let (k, c) = (b.k, b.channels);
    let row_len = b.width * c;
    let mut scratch: Vec<T> = Vec::with_capacity(k * k);
    for bx in bxs {
        let x0 = bx * k;
        let x1 = (x0 + k).min(b.width);
        for ch in 0..c {
            scratch.clear();
            for y in b.rows.clone() {
                let row = &b.samples[y * row_len..(y + 1) * row_len];
                scratch.extend((x0..x1).map(|x| row[x * c + ch]));
            }
            out_row[bx * c + ch] = median_of_samples(&mut scratch) * scale;
        }
    }
}

/// The medians of `lanes` columns of `kk` values sorted by the network (`v`, value `e` of lane `l` at
/// `e·lanes + l`), scaled by `scale`, into `out`: the middle value, or the mean of the two middle ones.
fn write_medians<T: Sample>(v: &[T], kk: usize, lanes: usize, scale: f32, out: &mut [f32]) {
    if kk % 2 == 1 {
        let m = &v[(kk / 2) * lanes..(kk / 2 + 1) * lanes];
        for (o, &m) in out.iter_mut().zip(m) {
            *o = m.to_u16() as f32 * scale;
        }
    } else {
        let lo = &v[(kk / 2 - 1) * lanes..(kk / 2) * lanes];
        let hi = &v[(kk / 2) * lanes..(kk / 2 + 1) * lanes];
        for ((o, &a), &b) in out.iter_mut().zip(lo).zip(hi) {
            *o = (a.to_u16() as f32 + b.to_u16() as f32) * 0.5 * scale;
        }
    }
}

/// Gather the rows of a band of blocks for the network: element `e = dy·k + dx` of lane `l` (lane `l` = sample
/// `lane0 + l` of the block row, i.e. block `bx`, channel `ch` with `lane0 + l = bx·C + ch`) is the sample of
/// pixel `(bx·k + dx, dy)`, channel `ch`. `lane0` and `lanes` are multiples of `C`. Element rows are `stride`
/// samples apart in `v` (`stride ≥ lanes`; `lanes` itself for a whole chunk).
///
/// Each pixel is moved as `C1 = C + 1` samples (one 4-byte move for 8-bit RGB instead of a 2 + 1): the extra
/// sample lands on the next block's first lane, which the next move overwrites; the last block of each
/// element row is moved exactly, so nothing outside the band is read or written.
#[inline(always)]
fn gather_blocks<'a, T: Sample, const C: usize, const C1: usize>(
    rows: impl Iterator<Item = &'a [T]>,
    v: &mut [T],
    k: usize,
    stride: usize,
    lanes: usize,
    lane0: usize,
) {
    debug_assert!(
        lane0.is_multiple_of(C) && lanes.is_multiple_of(C) && C1 == C + 1 && stride >= lanes
    );
    let (bx0, nb) = (lane0 / C, lanes / C);
    if nb == 0 {
        return;
    }
    for (dy, row) in rows.enumerate() {
        let band = &row[bx0 * k * C..(bx0 + nb) * k * C];
        for dx in 0..k {
            let e = &mut v[(dy * k + dx) * stride..(dy * k + dx) * stride + lanes];
            for b in 0..nb - 1 {
                let src: &[T; C1] = band[(b * k + dx) * C..(b * k + dx) * C + C1]
                    .try_into()
                    .unwrap();
                let dst: &mut [T; C1] = (&mut e[b * C..b * C + C1]).try_into().unwrap();
                *dst = *src;
            }
            let b = nb - 1;
            e[b * C..b * C + C].copy_from_slice(&band[(b * k + dx) * C..(b * k + dx) * C + C]);
        }
    }
}

/// [`gather_blocks`] for the common case of 8-bit RGB photos in 8×8 blocks: with AVX2, eight blocks at a time
/// as an 8×8 transpose of pixels held in 32-bit lanes (16 loads, 8 + 8 byte shuffles, 24 lane shuffles and 16
/// stores for 64 pixels, instead of 64 loads and 64 stores); the blocks left over, and CPUs without AVX2, take
/// [`gather_blocks`]. Same result (tested bit for bit).
fn gather_rgb8_k8(rows: &[&[u8]; 8], v: &mut [u8], lanes: usize, lane0: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = Avx2::detect() {
        return avx2::gather_rgb8_k8(t, rows, v, lanes, lane0);
    }
    gather_blocks::<u8, 3, 4>(rows.iter().copied(), v, 8, lanes, lanes, lane0)
}

/// [`gather_blocks`] for any channel count.
fn gather_blocks_dyn<'a, T: Sample>(
    rows: impl Iterator<Item = &'a [T]>,
    v: &mut [T],
    k: usize,
    lanes: usize,
    lane0: usize,
    c: usize,
) {
    let (bx0, nb) = (lane0 / c, lanes / c);
    for (dy, row) in rows.enumerate() {
        let band = &row[bx0 * k * c..(bx0 + nb) * k * c];
        for (b, block) in band.chunks_exact(k * c).enumerate() {
            for (dx, px) in block.chunks_exact(c).enumerate() {
                let at = (dy * k + dx) * lanes + b * c;
                v[at..at + c].copy_from_slice(px);
            }
        }
    }
}

/// Per-pixel quantile `q` of a stack of equal-sized rasters, interpolated linearly between the order statistics
/// (the sorted stack `v`, NaN last, read at the position `(n − 1)·q`: `v[k] + t·(v[k + 1] − v[k])`, numpy's and
/// R's default "type 7"). `q = 0.5` with an odd stack is [`stack_median`]'s value. Nearest rank would jump in
/// steps of `1/(n − 1)`: with 9 photos, 0.575 became 0.625, biased up by a share of the window's spread, which is
/// largest in the dim parts of the frame. Rows run in parallel.
pub fn stack_quantile(frames: &[&Raster], q: f64) -> Raster {
    assert!(!frames.is_empty(), "quantile of an empty stack");
    let first = frames[0];
    for f in frames {
        assert_eq!(f.layout(), first.layout(), "stack of unequal rasters");
    }
    let n = frames.len();
    let pos = (n - 1) as f64 * q.clamp(0.0, 1.0);
    let k = (pos.floor() as usize).min(n - 1);
    let t = (pos - k as f64) as f32;
    let mut out = Raster::filled(first.width, first.height, first.channels, 0.0);
    if network_fits(frames) {
        // The order statistics k and k + 1 through the pruned sorting network, many samples at once: the same
        // values as the selection below (min/max order equals `total_cmp` order without NaN and −0).
        let hi_at = (k + 1).min(n - 1);
        let net = prune_network(&sorting_network(n), &[k, hi_at]);
        per_lanes(frames, &mut out, &net, |v, lanes, o| {
            let lo = &v[k * lanes..(k + 1) * lanes];
            let hi = &v[hi_at * lanes..(hi_at + 1) * lanes];
            for ((o, &a), &b) in o.iter_mut().zip(lo).zip(hi) {
                *o = if t == 0.0 { a } else { a + t * (b - a) };
            }
        });
        return out;
    }
    per_sample(frames, &mut out, |v| {
        let (_, &mut lo, above) = v.select_nth_unstable_by(k, f32::total_cmp);
        if t == 0.0 {
            return lo;
        }
        let hi = above.iter().copied().min_by(f32::total_cmp).unwrap_or(lo);
        lo + t * (hi - lo)
    });
    out
}

/// Whether a stack can go through a sorting network: at most [`NETWORK_MAX`] frames, and no NaN or −0 (which
/// order differently under `total_cmp` than under `<`; those rare stacks take the scalar path).
fn network_fits(frames: &[&Raster]) -> bool {
    frames.len() <= NETWORK_MAX && !frames.par_iter().any(|f| any_nan_or_negative_zero(&f.data))
}

/// Whether `values` holds a NaN or a −0, read from the bits without a branch per value (so that it vectorises:
/// a scan of every window's block images per photo), a chunk at a time so that a hit stops it early.
fn any_nan_or_negative_zero(values: &[f32]) -> bool {
    values.chunks(4096).any(|chunk| {
        chunk.iter().fold(false, |odd, v| {
            let bits = v.to_bits();
            // NaN: exponent all ones and a mantissa; −0: the sign bit alone.
            odd | ((bits & 0x7FFF_FFFF) > 0x7F80_0000) | (bits == 0x8000_0000)
        })
    })
}

/// `net` applied to the stack's values at every position, [`LANES`] positions at a time (`v[e * lanes + lane]`:
/// frame `e`'s value at the lane's position); `take(v, lanes, out)` then writes the lanes' results. Chunks of
/// positions run in parallel.
fn per_lanes(
    frames: &[&Raster],
    out: &mut Raster,
    net: &[(u16, u16)],
    take: impl Fn(&[f32], usize, &mut [f32]) + Sync,
) {
    let n = frames.len();
    out.data
        .par_chunks_mut(LANES * 16)
        .enumerate()
        .for_each(|(chunk, out_chunk)| {
            let start = chunk * LANES * 16;
            let mut v = vec![0.0f32; n * LANES];
            for (sub, o) in out_chunk.chunks_mut(LANES).enumerate() {
                let lanes = o.len();
                let s0 = start + sub * LANES;
                let v = &mut v[..n * lanes];
                for (e, f) in frames.iter().enumerate() {
                    v[e * lanes..(e + 1) * lanes].copy_from_slice(&f.data[s0..s0 + lanes]);
                }
                apply_network(net, v, lanes);
                take(v, lanes, o);
            }
        });
}

/// `out` = `of(samples)` at every position, `samples` being the stack's values there (in a scratch buffer the
/// function may reorder). Rows run in parallel.
fn per_sample(frames: &[&Raster], out: &mut Raster, of: impl Fn(&mut [f32]) -> f32 + Sync) {
    let row_len = out.width * out.channels;
    if row_len == 0 {
        return;
    }
    let n = frames.len();
    out.data
        .par_chunks_mut(row_len)
        .enumerate()
        .for_each(|(y, out_row)| {
            let mut scratch = vec![0.0f32; n];
            for (i, o) in out_row.iter_mut().enumerate() {
                for (s, f) in scratch.iter_mut().zip(frames) {
                    *s = f.row(y)[i];
                }
                *o = of(&mut scratch);
            }
        });
}

/// Per-sample median over a stack of rasters of the same layout (the temporal median).
///
/// A sorting network over the frames, applied to many samples at once (no per-sample sort call). NaN is treated
/// as larger than every number, as in the median of a list of numbers.
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
    let n = frames.len();
    if !network_fits(frames) {
        per_sample(frames, &mut out, median_of_f32);
        return out;
    }
    let net = prune_network(&sorting_network(n), &median_positions(n));
    per_lanes(frames, &mut out, &net, |v, lanes, o| {
        if n % 2 == 1 {
            o.copy_from_slice(&v[(n / 2) * lanes..(n / 2 + 1) * lanes]);
        } else {
            let lo = &v[(n / 2 - 1) * lanes..(n / 2) * lanes];
            let hi = &v[(n / 2) * lanes..(n / 2 + 1) * lanes];
            for ((o, &a), &b) in o.iter_mut().zip(lo).zip(hi) {
                *o = 0.5 * (a + b);
            }
        }
    });
    out
}

/// The value at quantile `q` (0..=1, by nearest rank: no mean of two middle values here) of `v` (reordered in
/// place, by selection: linear time); NaN for an empty slice.
pub fn quantile(v: &mut [f32], q: f64) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    *v.select_nth_unstable_by(i, f32::total_cmp).1
}

#[cfg(test)]
pub(crate) mod reference {
    //! Brute-force twins of the kernels above, written to be obviously right.
    use crate::method::raster::Raster;

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
    fn quantile_nearest_rank() {
        let mut v = vec![5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(quantile(&mut v, 0.5), 3.0);
        assert_eq!(quantile(&mut v, 0.0), 1.0);
        assert_eq!(quantile(&mut v, 1.0), 5.0);
        // 21 values 0..=20: the 95th percentile by nearest rank is index round(20·0.95) = 19.
        let mut w: Vec<f32> = (0..=20).rev().map(|x| x as f32).collect();
        assert_eq!(quantile(&mut w, 0.95), 19.0);
        assert!(quantile(&mut [], 0.5).is_nan());
    }

    #[test]
    fn nan_and_negative_zero_are_found_as_by_their_predicates() {
        let specials = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            f32::NAN,
            -f32::NAN,
            f32::from_bits(0x7F80_0001),
            f32::from_bits(0xFFFF_FFFF),
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::from_bits(0x8000_0001),
        ];
        let odd = |v: &f32| v.is_nan() || (*v == 0.0 && v.is_sign_negative());
        for &special in &specials {
            // The value alone, and at the start, the middle and the end of a run longer than a chunk.
            for at in [None, Some(0), Some(4095), Some(4096), Some(9999)] {
                let mut values = vec![0.25f32; if at.is_some() { 10_000 } else { 1 }];
                *values.get_mut(at.unwrap_or(0)).unwrap() = special;
                assert_eq!(
                    any_nan_or_negative_zero(&values),
                    values.iter().any(odd),
                    "{special:?} at {at:?}"
                );
            }
        }
        assert!(!any_nan_or_negative_zero(&[]));
    }

    #[test]
    fn stack_quantile_against_sorting() {
        let mut rng = crate::method::xorshift32(0x1357_9BDF);
        let mut next = move || (rng() % 1000) as f32 / 999.0;
        // Up to 256 frames the sorting network's path, above it (and with NaN, below) the selection's.
        for n in [1usize, 2, 5, 7, 13, 300] {
            let frames: Vec<Raster> = (0..n)
                .map(|_| Raster::from_fn(7, 3, 3, |_, _, _| next()))
                .collect();
            let refs: Vec<&Raster> = frames.iter().collect();
            for q in [0.0, 0.3, 0.5, 0.675, 1.0] {
                let got = stack_quantile(&refs, q);
                // One NaN sends the whole stack down the selection's path: elsewhere the same bits.
                let mut with_nan = frames.clone();
                with_nan[0].data[0] = f32::NAN;
                let scalar = stack_quantile(&with_nan.iter().collect::<Vec<_>>(), q);
                for i in 1..got.data.len() {
                    assert_eq!(
                        got.data[i].to_bits(),
                        scalar.data[i].to_bits(),
                        "n {n} q {q} i {i}"
                    );
                }
                for i in 0..got.data.len() {
                    let mut v: Vec<f32> = frames.iter().map(|f| f.data[i]).collect();
                    v.sort_by(f32::total_cmp);
                    // numpy's default: the sorted values interpolated at (n − 1)·q, in f64.
                    let pos = (n - 1) as f64 * q;
                    let (k, t) = (pos.floor() as usize, pos - pos.floor());
                    let want = if t == 0.0 {
                        v[k] as f64
                    } else {
                        v[k] as f64 + t * (v[k + 1] as f64 - v[k] as f64)
                    };
                    assert!(
                        (got.data[i] as f64 - want).abs() <= 1e-6,
                        "n {n} q {q} i {i}: {} against {want}",
                        got.data[i]
                    );
                }
            }
            if n % 2 == 1 {
                assert_eq!(stack_quantile(&refs, 0.5), stack_median(&refs));
            }
        }
    }

    #[test]
    fn median_even_and_odd() {
        assert_eq!(median_of_samples(&mut [3u8, 1, 2]), 2.0);
        assert_eq!(median_of_samples(&mut [4u8, 1, 3, 2]), 2.5);
        assert_eq!(median_of_samples(&mut [7u16]), 7.0);
        assert_eq!(median_of_f32(&mut [0.5, 0.1]), 0.3);
        // A single outlier cannot move the median (breakdown point 50 %).
        assert_eq!(median_of_samples(&mut [10u8, 10, 255, 10, 0]), 10.0);
    }

    /// `n` pseudo-random bytes (xorshift64 from `state`).
    fn random_bytes(state: &mut u64, n: usize) -> Vec<u8> {
        (0..n)
            .map(|_| {
                *state ^= *state << 13;
                *state ^= *state >> 7;
                *state ^= *state << 17;
                (*state >> 40) as u8
            })
            .collect()
    }

    /// The AVX2 gather for 8-bit RGB in 8×8 blocks against the portable one, bit for bit: groups of eight blocks,
    /// blocks left over, chunks that start inside the row and bands that end at the row's end (where the
    /// 28-byte loads must fall back).
    #[test]
    fn rgb8_gather_matches_the_portable_gather() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        for width_blocks in [8usize, 9, 15, 16, 64, 70] {
            for extra_px in [0usize, 3, 7] {
                let row_len = (width_blocks * 8 + extra_px) * 3;
                let rows_data: Vec<Vec<u8>> =
                    (0..8).map(|_| random_bytes(&mut state, row_len)).collect();
                let rows: [&[u8]; 8] = std::array::from_fn(|i| rows_data[i].as_slice());
                for (lane0, nb) in [
                    (0, width_blocks),
                    (3 * 8, width_blocks - 8),
                    (3, width_blocks - 1),
                ] {
                    if nb == 0 {
                        continue;
                    }
                    let lanes = nb * 3;
                    let mut got = vec![0u8; 64 * lanes];
                    let mut want = vec![0u8; 64 * lanes];
                    gather_rgb8_k8(&rows, &mut got, lanes, lane0);
                    gather_blocks::<u8, 3, 4>(
                        rows.iter().copied(),
                        &mut want,
                        8,
                        lanes,
                        lanes,
                        lane0,
                    );
                    assert_eq!(
                        got, want,
                        "{width_blocks} blocks + {extra_px} px, lane0 {lane0}"
                    );
                }
            }
        }
    }

    #[test]
    fn wide_rgb8_block_median_matches_brute_force() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        for (w, h) in [
            (8 * 64, 16usize),
            (8 * 70 + 5, 19),
            (8 * 8 + 7, 8),
            (8 * 8, 9),
        ] {
            let samples = random_bytes(&mut state, w * h * 3);
            let got = block_median(&samples, w, h, 3, 8);
            let expected = reference::block_median(
                &samples.iter().map(|&s| s as f64).collect::<Vec<_>>(),
                w,
                h,
                3,
                8,
                255.0,
            );
            assert_eq!(got.data.len(), expected.len());
            for (i, (g, e)) in got.data.iter().zip(&expected).enumerate() {
                assert!(
                    (*g as f64 - e).abs() < 1e-6,
                    "{w}x{h} sample {i}: {g} vs {e}"
                );
            }
        }
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
    fn sorting_networks_sort_every_0_1_input() {
        // The 0-1 principle: a comparator network sorts every input iff it sorts every 0/1 input.
        for n in 1..=16usize {
            let net = sorting_network(n);
            for bits in 0u32..(1 << n) {
                let mut v: Vec<u8> = (0..n).map(|i| ((bits >> i) & 1) as u8).collect();
                apply_network(&net, &mut v, 1);
                assert!(
                    v.windows(2).all(|w| w[0] <= w[1]),
                    "n = {n}, input {bits:b}"
                );
            }
        }
    }

    proptest! {
        #[test]
        fn pruned_networks_find_the_median(n in 1usize..=100, seed in any::<u64>()) {
            let mut state = seed | 1;
            let v: Vec<u16> = (0..n).map(|_| {
                state ^= state << 13; state ^= state >> 7; state ^= state << 17;
                (state % 50) as u16
            }).collect();
            let net = prune_network(&sorting_network(n), &median_positions(n));
            let mut w = v.clone();
            apply_network(&net, &mut w, 1);
            let mut sorted = v.clone();
            sorted.sort();
            for p in median_positions(n) {
                prop_assert_eq!(w[p], sorted[p]);
            }
        }

        #[test]
        fn block_median_network_matches_selection_bitwise(
            w in 0usize..70, h in 0usize..30, c in 1usize..5,
            k in 1usize..11, seed in any::<u64>(), wide in any::<bool>()
        ) {
            // The network path (full blocks) against the per-block selection it replaced: identical bits.
            let mut state = seed | 1;
            let mut next = || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; state };
            let s8: Vec<u8> = (0..w * h * c).map(|_| (next() >> 24) as u8).collect();
            let s16: Vec<u16> = (0..w * h * c)
                .map(|_| if wide { (next() >> 20) as u16 } else { (next() % 7) as u16 })
                .collect();
            prop_assert_eq!(block_median(&s8, w, h, c, k), selection::block_median(&s8, w, h, c, k));
            prop_assert_eq!(block_median(&s16, w, h, c, k), selection::block_median(&s16, w, h, c, k));
        }

        #[test]
        fn stack_median_network_matches_selection_bitwise(
            n in 1usize..20, len in 1usize..3000, seed in any::<u64>()
        ) {
            let mut state = seed | 1;
            let frames: Vec<Raster> = (0..n).map(|_| Raster::from_fn(len, 1, 1, |_, _, _| {
                state ^= state << 13; state ^= state >> 7; state ^= state << 17;
                (state % 1000) as f32 / 999.0
            })).collect();
            let refs: Vec<&Raster> = frames.iter().collect();
            let got = stack_median(&refs);
            for (i, g) in got.data.iter().enumerate() {
                let mut col: Vec<f32> = frames.iter().map(|f| f.data[i]).collect();
                prop_assert_eq!(g.to_bits(), median_of_f32(&mut col).to_bits());
            }
        }
    }

    /// The per-block selection kernel the network replaced, kept as a bit-exact reference.
    mod selection {
        use super::super::*;
        pub fn block_median<T: Sample>(
            s: &[T],
            width: usize,
            height: usize,
            c: usize,
            k: usize,
        ) -> Raster {
            let (bw, bh) = (blocks(width, k), blocks(height, k));
            let mut out = Raster::filled(bw, bh, c, 0.0);
            let mut scratch = Vec::new();
            for by in 0..bh {
                for bx in 0..bw {
                    for ch in 0..c {
                        scratch.clear();
                        for y in by * k..((by + 1) * k).min(height) {
                            for x in bx * k..((bx + 1) * k).min(width) {
                                scratch.push(s[(y * width + x) * c + ch]);
                            }
                        }
                        out.data[(by * bw + bx) * c + ch] =
                            median_of_samples(&mut scratch) * (1.0 / T::MAX);
                    }
                }
            }
            out
        }
    }

    #[test]
    fn avx2_and_portable_networks_agree() {
        let net = sorting_network(64);
        let v = random_bytes(&mut 0x9e37_79b9_7f4a_7c15u64, 64 * 200);
        let (mut a, mut b) = (v.clone(), v.clone());
        apply_network(&net, &mut a, 200);
        apply_network_portable(&net, &mut b, 200);
        assert_eq!(a, b);
        let f: Vec<f32> = v.iter().map(|&x| x as f32 / 7.0).collect();
        let (mut a, mut b) = (f.clone(), f.clone());
        apply_network(&net, &mut a, 200);
        apply_network_portable(&net, &mut b, 200);
        assert_eq!(a, b);
    }

    proptest! {
        #[test]
        fn column_median_matches_sample_median(n in 1usize..20, len in 0usize..300, seed in any::<u64>()) {
            let mut state = seed | 1;
            let cols: Vec<Vec<u16>> = (0..n).map(|_| (0..len).map(|_| {
                state ^= state << 13; state ^= state >> 7; state ^= state << 17;
                (state >> 48) as u16
            }).collect()).collect();
            let refs: Vec<&[u16]> = cols.iter().map(|c| c.as_slice()).collect();
            let mut out = vec![0.0f32; len];
            column_median(&refs, &mut out);
            for (i, o) in out.iter().enumerate() {
                let mut col: Vec<u16> = cols.iter().map(|c| c[i]).collect();
                prop_assert_eq!(o.to_bits(), median_of_samples(&mut col).to_bits());
            }
        }
    }

    #[test]
    fn stack_median_with_nan_sorts_nan_last() {
        let a = Raster::filled(3, 1, 1, f32::NAN);
        let b = Raster::filled(3, 1, 1, 0.2);
        let c = Raster::filled(3, 1, 1, 0.4);
        assert_eq!(stack_median(&[&a, &b, &c]).data, vec![0.4; 3]);
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

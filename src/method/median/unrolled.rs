//! The block medians of the common block sizes (4×4 to 8×8, so 16 to 64 samples) by a sorting network unrolled
//! at compile time: each comparator a `min`/`max` of whole lane vectors held in local variables, so the compiler
//! keeps them in registers, with no loop over the comparator list and no bookkeeping per comparator. The
//! comparators are Batcher's odd–even merge sort in its recursive order (a sort of 8 finishes before the next
//! starts, which keeps few values live at once), pruned to those that can change the middle values, and of those
//! only the half (`min` or `max`) that is used.
//!
//! The lane vectors are a [`Vector`]: on x86-64 one register, its `min`/`max` one instruction (AVX2 in
//! `avx2.rs` where the CPU has it, SSE2, the baseline, in `sse2.rs` otherwise); elsewhere [`Lanes`], an array
//! the compiler vectorizes. The registers are written out rather than left to the vectorizer because the
//! vectorizer pays for every comparator of every network at each build: the unrolled networks over arrays made
//! up a quarter of the library's compile time.
//!
//! The values are integer samples, so any network that finds the middle values finds the same ones as the
//! generic network and as a selection: the medians are bit for bit the same (tested against sorting).

use crate::method::raster::Sample;

/// Room for the comparators of any network built here (Batcher's sort of 64 values has 543).
const MAX_COMPARATORS: usize = 576;
/// Most values a network here sorts.
const MAX_VALUES: usize = 64;

/// Which halves of a comparator `(a, b)` are used: `a ← min` (`LOW`), `b ← max` (`HIGH`), or both.
const BOTH: u8 = 0;
const LOW: u8 = 1;
const HIGH: u8 = 2;

/// A comparator list `list[..len]` of `(a, b, halves)`, `a < b`.
struct Net {
    list: [(u8, u8, u8); MAX_COMPARATORS],
    len: usize,
}

impl Net {
    const fn push(&mut self, a: usize, b: usize, count: usize) {
        if b < count {
            self.list[self.len] = (a as u8, b as u8, BOTH);
            self.len += 1;
        }
    }
}

/// Batcher's odd–even merge of the sorted halves of `lo..lo + n`, elements `r` apart (comparators touching
/// positions `≥ count`, the conceptually `+∞` padding, left out).
const fn merge(net: &mut Net, lo: usize, n: usize, r: usize, count: usize) {
    let m = r * 2;
    if m < n {
        merge(net, lo, n, m, count);
        merge(net, lo + r, n, m, count);
        let mut i = lo + r;
        while i + r < lo + n {
            net.push(i, i + r, count);
            i += m;
        }
    } else {
        net.push(lo, lo + r, count);
    }
}

/// Batcher's odd–even merge sort of `lo..lo + n` (`n` a power of two), recursively.
const fn sort(net: &mut Net, lo: usize, n: usize, count: usize) {
    if n > 1 {
        let m = n / 2;
        sort(net, lo, m, count);
        sort(net, lo + m, m, count);
        merge(net, lo, n, 1, count);
    }
}

/// The comparators that find the middle values of `count` values (positions `(count − 1)/2` and `count/2`),
/// each with the halves of it that are used.
const fn median_net(count: usize) -> Net {
    assert!(count >= 1 && count <= MAX_VALUES);
    let mut full = Net {
        list: [(0, 0, BOTH); MAX_COMPARATORS],
        len: 0,
    };
    sort(&mut full, 0, count.next_power_of_two(), count);
    // Backwards from the outputs: a comparator is kept if one of its outputs is live, and then both its inputs are.
    let mut live = [false; MAX_VALUES];
    live[(count - 1) / 2] = true;
    live[count / 2] = true;
    let mut kept = Net {
        list: [(0, 0, BOTH); MAX_COMPARATORS],
        len: 0,
    };
    let mut i = full.len;
    while i > 0 {
        i -= 1;
        let (a, b, _) = full.list[i];
        let (la, lb) = (live[a as usize], live[b as usize]);
        if la || lb {
            let halves = if la && lb {
                BOTH
            } else if la {
                LOW
            } else {
                HIGH
            };
            kept.list[kept.len] = (a, b, halves);
            kept.len += 1;
            live[a as usize] = true;
            live[b as usize] = true;
        }
    }
    // Back into the network's order.
    let mut j = 0;
    while j < kept.len / 2 {
        let t = kept.list[j];
        kept.list[j] = kept.list[kept.len - 1 - j];
        kept.list[kept.len - 1 - j] = t;
        j += 1;
    }
    kept
}

/// The network for `KK` values, built at compile time.
struct Network<const KK: usize>;

impl<const KK: usize> Network<KK> {
    const NET: Net = median_net(KK);
}

/// Most lanes a [`Vector`] holds (32 bytes of 8-bit samples).
pub(super) const MAX_LANES: usize = 32;

/// `W` samples of type `T`, one of each of `W` columns, with lane-by-lane `min` and `max`.
pub(super) trait Vector<T>: Copy {
    /// Lanes (at most [`MAX_LANES`]).
    const W: usize;
    /// The first `W` values of `v` (panics on fewer).
    fn load(v: &[T]) -> Self;
    /// Into the first `W` values of `out` (panics on fewer).
    fn store(self, out: &mut [T]);
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
}

/// `W` samples as an array, `min` and `max` lane by lane: the portable [`Vector`], which the compiler turns into
/// vector instructions where the target has them. Off x86-64 only (and in the tests, which hold it to the others).
#[cfg(any(test, not(target_arch = "x86_64")))]
#[derive(Clone, Copy)]
pub(super) struct Lanes<T, const W: usize>([T; W]);

#[cfg(any(test, not(target_arch = "x86_64")))]
impl<T: Copy + Ord, const W: usize> Vector<T> for Lanes<T, W> {
    const W: usize = W;
    #[inline(always)]
    fn load(v: &[T]) -> Self {
        Lanes(v[..W].try_into().unwrap())
    }
    #[inline(always)]
    fn store(self, out: &mut [T]) {
        out[..W].copy_from_slice(&self.0);
    }
    #[inline(always)]
    fn min(mut self, o: Self) -> Self {
        for i in 0..W {
            self.0[i] = self.0[i].min(o.0[i]);
        }
        self
    }
    #[inline(always)]
    fn max(mut self, o: Self) -> Self {
        for i in 0..W {
            self.0[i] = self.0[i].max(o.0[i]);
        }
        self
    }
}

/// Comparator `$i` of `Network::<$kk>` on `$v` (nothing past the list's end; each a constant once inlined).
macro_rules! step {
    ($v:ident, $kk:ident, $i:expr) => {
        if $i < Network::<$kk>::NET.len {
            let (a, b, halves) = Network::<$kk>::NET.list[$i];
            let (x, y) = ($v[a as usize], $v[b as usize]);
            if halves != HIGH {
                $v[a as usize] = x.min(y);
            }
            if halves != LOW {
                $v[b as usize] = x.max(y);
            }
        }
    };
}

macro_rules! step8 {
    ($v:ident, $kk:ident, $i:expr) => {
        step!($v, $kk, $i);
        step!($v, $kk, $i + 1);
        step!($v, $kk, $i + 2);
        step!($v, $kk, $i + 3);
        step!($v, $kk, $i + 4);
        step!($v, $kk, $i + 5);
        step!($v, $kk, $i + 6);
        step!($v, $kk, $i + 7);
    };
}

macro_rules! step64 {
    ($v:ident, $kk:ident, $i:expr) => {
        step8!($v, $kk, $i);
        step8!($v, $kk, $i + 8);
        step8!($v, $kk, $i + 16);
        step8!($v, $kk, $i + 24);
        step8!($v, $kk, $i + 32);
        step8!($v, $kk, $i + 40);
        step8!($v, $kk, $i + 48);
        step8!($v, $kk, $i + 56);
    };
}

/// The middle values (positions `(KK − 1)/2` and `KK/2` of the sorted values) of each lane of `v`.
#[inline(always)]
fn middle<T, V: Vector<T>, const KK: usize>(mut v: [V; KK]) -> (V, V) {
    // 9 × 64 = MAX_COMPARATORS steps, unrolled; those past the network's length vanish.
    step64!(v, KK, 0);
    step64!(v, KK, 64);
    step64!(v, KK, 128);
    step64!(v, KK, 192);
    step64!(v, KK, 256);
    step64!(v, KK, 320);
    step64!(v, KK, 384);
    step64!(v, KK, 448);
    step64!(v, KK, 512);
    (v[(KK - 1) / 2], v[KK / 2])
}

/// [`middle`] on every group of `V::W` columns of `v` (value `e` of column `l` at `e·lanes + l`, `KK` values a
/// column): the middle values land in value rows `(KK − 1)/2` and `KK/2`; the other rows are left as they were.
#[inline(always)]
fn columns<T: Copy + Default, V: Vector<T>, const KK: usize>(v: &mut [T], lanes: usize) {
    debug_assert_eq!(v.len(), KK * lanes);
    debug_assert!(V::W <= MAX_LANES);
    let (lo_row, hi_row) = ((KK - 1) / 2 * lanes, KK / 2 * lanes);
    let mut l0 = 0;
    // Whole groups: loads and stores straight from and to `v`.
    while l0 + V::W <= lanes {
        let rows: [V; KK] = std::array::from_fn(|e| V::load(&v[e * lanes + l0..]));
        let (lo, hi) = middle::<T, V, KK>(rows);
        lo.store(&mut v[lo_row + l0..]);
        hi.store(&mut v[hi_row + l0..]);
        l0 += V::W;
    }
    if l0 < lanes {
        // The columns left over, padded.
        let n = lanes - l0;
        let rows: [V; KK] = std::array::from_fn(|e| {
            let mut r = [T::default(); MAX_LANES];
            r[..n].copy_from_slice(&v[e * lanes + l0..e * lanes + lanes]);
            V::load(&r)
        });
        let (lo, hi) = middle::<T, V, KK>(rows);
        let mut r = [T::default(); MAX_LANES];
        lo.store(&mut r);
        v[lo_row + l0..lo_row + lanes].copy_from_slice(&r[..n]);
        hi.store(&mut r);
        v[hi_row + l0..hi_row + lanes].copy_from_slice(&r[..n]);
    }
}

/// [`columns`] for the `kk` the kernel has a network for (`false`: none, `v` untouched).
#[inline(always)]
pub(super) fn columns_of<T: Copy + Default, V: Vector<T>>(
    v: &mut [T],
    kk: usize,
    lanes: usize,
) -> bool {
    match kk {
        16 => columns::<T, V, 16>(v, lanes),
        25 => columns::<T, V, 25>(v, lanes),
        36 => columns::<T, V, 36>(v, lanes),
        49 => columns::<T, V, 49>(v, lanes),
        64 => columns::<T, V, 64>(v, lanes),
        _ => return false,
    }
    true
}

/// Whether [`middle_values`] has a kernel for blocks of `kk` samples.
pub(super) fn handles(kk: usize) -> bool {
    matches!(kk, 16 | 25 | 36 | 49 | 64)
}

/// The middle values of `lanes` columns of `kk` samples each (`v[e·lanes + l]`: value `e` of column `l`), into
/// value rows `(kk − 1)/2` and `kk/2` of `v`, as the generic network leaves them there. Returns `false` (and
/// leaves `v` as it is) where there is no kernel for `kk` ([`handles`]).
pub(super) fn middle_values<T: Sample>(v: &mut [T], kk: usize, lanes: usize) -> bool {
    if !handles(kk) {
        return false;
    }
    if let Some(bytes) = T::as_bytes_mut(v) {
        return dispatch(bytes, kk, lanes);
    }
    if std::any::TypeId::of::<T>() == std::any::TypeId::of::<u16>() {
        // SAFETY: `T` is `u16` (same type id), so the slice is one of `u16`.
        let words = unsafe { std::slice::from_raw_parts_mut(v.as_mut_ptr() as *mut u16, v.len()) };
        return dispatch(words, kk, lanes);
    }
    false
}

/// A sample type the networks run on, with its vectors.
pub(super) trait NetworkSample: Copy + Ord + Default {
    /// 16 bytes of lanes: one SSE2 register on x86-64, an array elsewhere.
    type Narrow: Vector<Self>;
    /// One AVX2 register (32 bytes), used only behind an [`crate::simd::Avx2`] token.
    #[cfg(target_arch = "x86_64")]
    type Wide: Vector<Self>;
}

#[cfg(target_arch = "x86_64")]
impl NetworkSample for u8 {
    type Narrow = super::sse2::U8x16;
    type Wide = super::avx2::U8x32;
}

#[cfg(target_arch = "x86_64")]
impl NetworkSample for u16 {
    type Narrow = super::sse2::U16x8;
    type Wide = super::avx2::U16x16;
}

#[cfg(not(target_arch = "x86_64"))]
impl NetworkSample for u8 {
    type Narrow = Lanes<u8, 16>;
}

#[cfg(not(target_arch = "x86_64"))]
impl NetworkSample for u16 {
    type Narrow = Lanes<u16, 8>;
}

/// [`columns_of`] on 32-byte registers where the CPU has AVX2, else on 16-byte vectors (`T::Narrow`).
fn dispatch<T: NetworkSample>(v: &mut [T], kk: usize, lanes: usize) -> bool {
    #[cfg(target_arch = "x86_64")]
    if let Some(t) = crate::simd::Avx2::detect() {
        return super::avx2::columns(t, v, kk, lanes);
    }
    columns_of::<T, T::Narrow>(v, kk, lanes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::median::{median_positions, prune_network, sorting_network};

    #[test]
    fn the_networks_are_the_pruned_batcher_networks() {
        // The same comparators as the generic kernel's pruned network (in another order: the recursive one).
        for kk in [16usize, 25, 36, 49, 64] {
            let net = median_net(kk);
            let mut ours: Vec<(u16, u16)> = net.list[..net.len]
                .iter()
                .map(|&(a, b, _)| (a as u16, b as u16))
                .collect();
            let mut theirs = prune_network(&sorting_network(kk), &median_positions(kk));
            ours.sort_unstable();
            theirs.sort_unstable();
            assert_eq!(ours, theirs, "{kk}");
        }
    }

    /// `n` pseudo-random values below `range` (xorshift64 from `state`).
    fn random(state: &mut u64, n: usize, range: u64) -> Vec<u64> {
        (0..n)
            .map(|_| {
                *state ^= *state << 13;
                *state ^= *state >> 7;
                *state ^= *state << 17;
                (*state >> 11) % range
            })
            .collect()
    }

    /// The middle values of every column against sorting the column, for both sample types, every vector a CPU
    /// may run (the CPU's own path: AVX2 where it has it; the 16-byte vectors; the portable arrays, here with 4
    /// and 2 lanes, whose code is the same for any width), every block size with a kernel, lane counts around the
    /// vector widths, and values with many ties (ranges 2 and 5) and few (the full range).
    #[test]
    fn middle_values_match_sorting() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        for kk in [16usize, 25, 36, 49, 64] {
            for lanes in [1usize, 3, 7, 8, 15, 16, 17, 31, 32, 33, 96, 192, 200] {
                for range in [2u64, 5, 256, 65536] {
                    let vals = random(&mut state, kk * lanes, range);
                    if range <= 256 {
                        let v: Vec<u8> = vals.iter().map(|&x| x as u8).collect();
                        check(&v, kk, lanes, |v| middle_values(v, kk, lanes));
                        check(&v, kk, lanes, |v| {
                            columns_of::<u8, <u8 as NetworkSample>::Narrow>(v, kk, lanes)
                        });
                        check(&v, kk, lanes, |v| {
                            columns_of::<u8, Lanes<u8, 4>>(v, kk, lanes)
                        });
                    }
                    let v: Vec<u16> = vals.iter().map(|&x| x as u16).collect();
                    check(&v, kk, lanes, |v| middle_values(v, kk, lanes));
                    check(&v, kk, lanes, |v| {
                        columns_of::<u16, <u16 as NetworkSample>::Narrow>(v, kk, lanes)
                    });
                    check(&v, kk, lanes, |v| {
                        columns_of::<u16, Lanes<u16, 2>>(v, kk, lanes)
                    });
                }
            }
        }
    }

    /// The 16-bit SSE2 `min`/`max` (built from a saturating subtraction) against the scalar ones, on the values
    /// where such tricks go wrong: 0, 1, the top of the range and its neighbours, and pairs across 32768.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn sixteen_bit_min_and_max_hold_over_the_whole_range() {
        let edges = [
            0u16, 1, 2, 32766, 32767, 32768, 32769, 65533, 65534, 65535, 12345, 54321,
        ];
        for &a in &edges {
            let b: Vec<u16> = edges.iter().copied().cycle().skip(3).take(8).collect();
            let x = <u16 as NetworkSample>::Narrow::load(&[a; 8]);
            let y = <u16 as NetworkSample>::Narrow::load(&b);
            let (mut lo, mut hi) = ([0u16; 8], [0u16; 8]);
            x.min(y).store(&mut lo);
            x.max(y).store(&mut hi);
            for i in 0..8 {
                assert_eq!((lo[i], hi[i]), (a.min(b[i]), a.max(b[i])), "{a} {}", b[i]);
            }
        }
    }

    fn check<T: Sample + std::fmt::Debug>(
        v: &[T],
        kk: usize,
        lanes: usize,
        kernel: impl Fn(&mut [T]) -> bool,
    ) {
        let mut got = v.to_vec();
        assert!(kernel(&mut got));
        for l in 0..lanes {
            let mut col: Vec<T> = (0..kk).map(|e| v[e * lanes + l]).collect();
            col.sort_unstable();
            for p in [(kk - 1) / 2, kk / 2] {
                assert_eq!(got[p * lanes + l], col[p], "kk {kk} lanes {lanes} lane {l}");
            }
        }
    }

    #[test]
    fn other_block_sizes_are_left_to_the_generic_kernel() {
        let mut v = vec![3u8, 1, 2, 9, 4, 8, 7, 6, 5];
        for kk in [1usize, 4, 9, 81, 100] {
            assert!(!handles(kk));
            assert!(!middle_values(&mut v[..kk.min(9)], kk, 1));
        }
        assert_eq!(v, [3, 1, 2, 9, 4, 8, 7, 6, 5]);
    }
}

//! A per-block quantile over a sliding window of block images, kept up to date as images enter and leave instead
//! of selected again from every image each time: each block holds its finite levels sorted (by [`f32::total_cmp`],
//! as integer keys), so entering and leaving cost a short shift and the quantile is an index. The value is the
//! one [`crate::method::median::quantile`] selects from the same levels, bit for bit.

/// The finite levels of the block images held, per block, sorted.
pub(crate) struct RunningQuantile {
    /// Most images held at once.
    cap: usize,
    /// How many finite levels each block holds.
    len: Vec<u8>,
    /// `cap` slots per block: the first `len` hold its levels' keys ([`key`]), ascending.
    keys: Vec<i32>,
}

/// The integer whose order is [`f32::total_cmp`]'s (the same transform the standard library uses); it is its own
/// inverse on the bits.
#[inline]
fn key(v: f32) -> i32 {
    let b = v.to_bits() as i32;
    b ^ ((((b >> 31) as u32) >> 1) as i32)
}

#[inline]
fn value(k: i32) -> f32 {
    f32::from_bits((k ^ ((((k >> 31) as u32) >> 1) as i32)) as u32)
}

impl RunningQuantile {
    /// Room for `blocks` blocks and at most `cap` images (at most 255) held at once.
    pub(crate) fn new(blocks: usize, cap: usize) -> Self {
        assert!(cap <= u8::MAX as usize, "at most 255 images");
        RunningQuantile {
            cap,
            len: vec![0; blocks],
            keys: vec![0; blocks * cap],
        }
    }

    /// An image enters: its finite levels join their blocks (NaN and infinite ones are left out).
    pub(crate) fn add(&mut self, levels: &[f32]) {
        assert_eq!(levels.len(), self.len.len(), "block image of another size");
        let cap = self.cap;
        for ((&v, n), slots) in levels
            .iter()
            .zip(self.len.iter_mut())
            .zip(self.keys.chunks_exact_mut(cap))
        {
            if !v.is_finite() {
                continue;
            }
            assert!((*n as usize) < cap, "more images than the room made");
            let k = key(v);
            let mut i = *n as usize;
            while i > 0 && slots[i - 1] > k {
                slots[i] = slots[i - 1];
                i -= 1;
            }
            slots[i] = k;
            *n += 1;
        }
    }

    /// An image held leaves (the same levels it entered with).
    pub(crate) fn remove(&mut self, levels: &[f32]) {
        assert_eq!(levels.len(), self.len.len(), "block image of another size");
        let cap = self.cap;
        for ((&v, n), slots) in levels
            .iter()
            .zip(self.len.iter_mut())
            .zip(self.keys.chunks_exact_mut(cap))
        {
            if !v.is_finite() {
                continue;
            }
            let k = key(v);
            let held = &mut slots[..*n as usize];
            let at = held
                .iter()
                .position(|&s| s == k)
                .expect("a level that never entered");
            held.copy_within(at + 1.., at);
            *n -= 1;
        }
    }

    /// Per block, the value at quantile `q` (nearest rank, as [`crate::method::median::quantile`]) of the levels
    /// held; NaN where a block holds none.
    pub(crate) fn quantile(&self, q: f64) -> Vec<f32> {
        let q = q.clamp(0.0, 1.0);
        self.len
            .iter()
            .zip(self.keys.chunks_exact(self.cap))
            .map(|(&n, slots)| match n {
                0 => f32::NAN,
                n => value(slots[((n - 1) as f64 * q).round() as usize]),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::median::quantile;
    use std::collections::VecDeque;

    /// Levels with ties, both zeros, NaN, infinities and negative values.
    fn levels(seed: u64, blocks: usize) -> Vec<f32> {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..blocks)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                match s % 23 {
                    0 => f32::NAN,
                    1 => 0.0,
                    2 => -0.0,
                    3 => f32::INFINITY,
                    4 => 0.25,
                    _ => ((s >> 20) % 2001) as f32 / 100.0 - 5.0,
                }
            })
            .collect()
    }

    #[test]
    fn a_sliding_window_gives_the_selected_quantile_bit_for_bit() {
        let (blocks, cap) = (300, 21);
        let mut run = RunningQuantile::new(blocks, cap);
        let mut held: VecDeque<Vec<f32>> = VecDeque::new();
        for t in 0..60u64 {
            // Windows that grow to the room, then slide, then shrink.
            if held.len() == cap {
                run.remove(&held.pop_front().unwrap());
            }
            let l = levels(t + 1, blocks);
            run.add(&l);
            held.push_back(l);
            while t >= 45 && held.len() > 3 {
                run.remove(&held.pop_front().unwrap());
            }
            for q in [0.0, 0.25, 0.5, 0.8, 0.95, 1.0] {
                let got = run.quantile(q);
                for (b, g) in got.iter().enumerate() {
                    let mut col: Vec<f32> = held
                        .iter()
                        .map(|h| h[b])
                        .filter(|v| v.is_finite())
                        .collect();
                    let want = quantile(&mut col, q);
                    assert_eq!(g.to_bits(), want.to_bits(), "t {t} block {b} q {q}");
                }
            }
        }
    }

    #[test]
    fn keys_order_as_total_cmp_and_come_back_unchanged() {
        let v = [
            f32::NEG_INFINITY,
            -3.5,
            -0.0,
            0.0,
            1e-40,
            2.0,
            f32::MAX,
            f32::INFINITY,
        ];
        for w in v.windows(2) {
            assert!(key(w[0]) < key(w[1]));
            assert_eq!(w[0].total_cmp(&w[1]), key(w[0]).cmp(&key(w[1])));
        }
        for x in v {
            assert_eq!(value(key(x)).to_bits(), x.to_bits());
        }
    }
}

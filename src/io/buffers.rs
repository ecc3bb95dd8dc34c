//! The sample buffers of decoded photos, kept for the next decode of the same size.
//!
//! A 12 MP RGB photo is a 36 MB buffer: more than the C allocator ever keeps for reuse, so every fresh one is a new
//! mapping whose pages the kernel faults in and zeroes as the decoder first writes them, and unmaps again when the
//! photo is dropped. Over a mission that is two such buffers a photo (the survey's decode and the correction's), and
//! about a tenth of a run's processor time went to the kernel for it. The run hands the buffers of photos it is
//! done with back here ([`recycle`]); the next JPEG decode of the same size writes into one of them instead
//! ([`take`]). At most [`HELD`] buffers wait here; the decoder overwrites every sample of the buffer it takes.

use std::sync::{Mutex, MutexGuard};

use crate::method::raster::{Photo, Samples};

/// Buffers kept at most (each is dropped beyond that).
pub const HELD: usize = 4;

/// Buffers smaller than this are left to the allocator, which reuses them well.
const SMALL: usize = 1 << 20;

static POOL: Pool = Pool::new();

/// Buffers waiting for a decode of their size (a struct, so that the tests have their own).
struct Pool(Mutex<Vec<Vec<u8>>>);

impl Pool {
    const fn new() -> Self {
        Pool(Mutex::new(Vec::new()))
    }

    fn held(&self) -> MutexGuard<'_, Vec<Vec<u8>>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn take(&self, len: usize) -> Vec<u8> {
        let kept = {
            let mut held = self.held();
            held.iter()
                .position(|b| b.len() == len)
                .map(|i| held.swap_remove(i))
        };
        kept.unwrap_or_else(|| vec![0; len])
    }

    fn give(&self, v: Vec<u8>) {
        if v.len() < SMALL {
            return;
        }
        let mut held = self.held();
        // Beyond HELD the oldest goes: sizes change rarely, and a mission's new size is the one to keep.
        let old = (held.len() >= HELD).then(|| held.remove(0));
        held.push(v);
        drop(held);
        drop(old);
    }
}

/// A buffer of `len` bytes: one handed back earlier (its old contents still in it), or a new zeroed one.
pub(crate) fn take(len: usize) -> Vec<u8> {
    POOL.take(len)
}

/// Hand back the samples of a photo the caller is done with, for a later decode of the same size.
pub fn recycle(photo: Photo) {
    if let Samples::U8(v) = photo.samples {
        POOL.give(v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_come_back_by_size_and_stay_bounded() {
        let pool = Pool::new();
        let len = SMALL * 3 + 7;
        for k in 1..=HELD + 3 {
            pool.give(vec![k as u8; len]);
        }
        assert_eq!(pool.held().len(), HELD, "never more than HELD buffers");
        let kept: Vec<u8> = pool.held().iter().map(|b| b[0]).collect();
        assert_eq!(kept, [4, 5, 6, 7], "the newest are kept");
        let b = pool.take(len);
        assert_eq!(b.len(), len);
        assert!(
            b.iter().all(|&v| v != 0),
            "a handed-back buffer is reused, not a new zeroed one"
        );
        assert_eq!(pool.held().len(), HELD - 1);
        let other = pool.take(len + 3);
        assert_eq!(other.len(), len + 3);
        assert!(
            other.iter().all(|&v| v == 0),
            "no buffer of that size: a new zeroed one"
        );
        pool.give(vec![9; SMALL / 2]);
        assert_eq!(
            pool.held().len(),
            HELD - 1,
            "small buffers are left to the allocator"
        );
    }
}

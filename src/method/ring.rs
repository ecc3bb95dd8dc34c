//! The sliding window's bookkeeping: the block images of the photos a window can still need (a ring buffer of
//! `n`), the photos waiting for the photos after them, and which photos each window spans.
//!
//! A photo comes out once its window is complete: centred on it where the mission allows (the `n/2` photos after
//! it are in), shifted back from the end once the mission is over
//! ([`crate::method::window::window_range`]). So at most `n` block images and, past the start of the mission,
//! `n/2 + 1` photos are held, whatever the mission's length.

use std::collections::VecDeque;
use std::ops::Range;

use crate::method::window::window_range;

/// The ring of one mission: block images `E` and waiting photos `W`, both numbered in the order they were pushed.
#[derive(Debug)]
pub(crate) struct Ring<E, W> {
    n: usize,
    entries: VecDeque<(usize, E)>,
    waiting: VecDeque<(usize, W)>,
    seq: usize,
}

impl<E, W> Ring<E, W> {
    /// A ring for a window of `n` photos.
    pub(crate) fn new(n: usize) -> Self {
        Ring {
            n,
            entries: VecDeque::with_capacity(n + 1),
            waiting: VecDeque::new(),
            seq: 0,
        }
    }

    /// Photos pushed so far.
    pub(crate) fn pushed(&self) -> usize {
        self.seq
    }

    /// The number of the oldest photo waiting.
    pub(crate) fn front(&self) -> Option<usize> {
        self.waiting.front().map(|&(i, _)| i)
    }

    /// Photos pushed and not yet out.
    pub(crate) fn waiting(&self) -> usize {
        self.waiting.len()
    }

    /// The next photo: its block image, and what waits for its window. Returns its number.
    pub(crate) fn push(&mut self, entry: E, waiting: W) -> usize {
        let seq = self.seq;
        self.entries.push_back((seq, entry));
        if self.entries.len() > self.n {
            self.entries.pop_front();
        }
        self.waiting.push_back((seq, waiting));
        self.seq += 1;
        seq
    }

    /// The first waiting photo whose window is complete (any, in order, once `eof`: the mission is over), with its
    /// number and its window.
    #[cfg(test)]
    pub(crate) fn next_ready(&mut self, eof: bool) -> Option<(usize, W, Range<usize>)> {
        let n = self.n;
        self.next_ready_by(eof, |_| n)
    }

    /// [`Ring::next_ready`] with a window of its own for each photo, `window_of(i)` photos (odd, at most the
    /// ring's `n`): photo `i` waits for the `window_of(i)/2` photos after it (and for the photos before it).
    pub(crate) fn next_ready_by(
        &mut self,
        eof: bool,
        window_of: impl Fn(usize) -> usize,
    ) -> Option<(usize, W, Range<usize>)> {
        let &(i, _) = self.waiting.front()?;
        let n = window_of(i).clamp(1, self.n);
        let range = if eof {
            window_range(i, n, self.seq)
        } else {
            let s = i.saturating_sub(n / 2);
            s..s + n
        };
        if !eof && self.seq < range.end {
            return None;
        }
        let (i, w) = self.waiting.pop_front()?;
        Some((i, w, range))
    }

    /// The block images of the photos in `range`, in order.
    #[cfg(test)]
    pub(crate) fn in_range(&self, range: Range<usize>) -> impl Iterator<Item = &E> {
        self.entries
            .iter()
            .filter(move |(s, _)| range.contains(s))
            .map(|(_, e)| e)
    }

    /// Every block image held, in order, replaced by `f` of it.
    pub(crate) fn map_entries(&mut self, mut f: impl FnMut(E) -> E) {
        self.entries = std::mem::take(&mut self.entries)
            .into_iter()
            .map(|(s, e)| (s, f(e)))
            .collect();
    }

    /// The block image of photo `seq`, while the ring holds it.
    pub(crate) fn get(&self, seq: usize) -> Option<&E> {
        self.entries.iter().find(|(s, _)| *s == seq).map(|(_, e)| e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::altitude::{choose, waits_for};
    use crate::method::window::{near_range, window_range};
    use proptest::prelude::*;

    proptest! {
        /// Over windows and near windows of many lengths and missions of every length up to a few windows: every
        /// photo comes out once, in order, with a window of `min(n, mission)` photos that holds it and that the
        /// ring still holds whole; its near window lies inside it and holds it; and the photos held stay bounded.
        #[test]
        fn every_photo_once_in_order_with_its_whole_window(
            half in 0usize..12,
            near_half in 0usize..12,
            total in 0usize..60,
        ) {
            let n = 2 * half + 1;
            let near = 2 * near_half + 1;
            let mut ring: Ring<usize, usize> = Ring::new(n);
            let mut out = Vec::new();
            let check = |ring: &Ring<usize, usize>, i: usize, w: usize, range: Range<usize>, eof: bool| {
                prop_assert_eq!(i, w);
                let mission = if eof { total } else { ring.pushed() };
                prop_assert!(range.contains(&i), "{:?} misses {}", range, i);
                prop_assert!(range.end <= mission);
                prop_assert_eq!(range.len(), n.min(if eof { total } else { range.end.max(n) }));
                let held: Vec<usize> = ring.in_range(range.clone()).copied().collect();
                prop_assert_eq!(held, range.clone().collect::<Vec<_>>(), "the ring lost a photo of the window");
                prop_assert_eq!(ring.get(i), Some(&i));
                let nr = near_range(i, near, &range);
                prop_assert!(nr.start >= range.start && nr.end <= range.end && nr.contains(&i));
                prop_assert_eq!(nr.len(), near.min(range.len()));
                Ok(())
            };
            for p in 0..total {
                ring.push(p, p);
                prop_assert!(ring.waiting() <= n);
                if p >= n {
                    prop_assert!(ring.waiting() <= n / 2 + 1);
                }
                while let Some((i, w, range)) = ring.next_ready(false) {
                    check(&ring, i, w, range, false)?;
                    out.push(i);
                }
            }
            while let Some((i, w, range)) = ring.next_ready(true) {
                check(&ring, i, w, range, true)?;
                out.push(i);
            }
            prop_assert_eq!(out, (0..total).collect::<Vec<_>>());
            prop_assert_eq!(ring.waiting(), 0);
        }
    }

    proptest! {
        /// The engine's readiness with a window of its own for each photo (any odd length up to 31, as the survey
        /// chooses them) and, with windows by altitude, the pool each is chosen among ([`waits_for`]), in a ring as
        /// long as the longest: every photo comes out exactly once, in order, and when it does the ring holds its
        /// whole pool, its window over time lies in it, and so does every photo its window by altitude chooses.
        #[test]
        fn per_photo_windows_and_altitude_pools_come_out_once_in_order_with_their_members_held(
            halves in proptest::collection::vec(0usize..16, 0..90),
            altitudes in proptest::collection::vec(proptest::option::weighted(0.9, 1.0f32..6.0), 90),
            by_altitude in any::<bool>(),
        ) {
            let total = halves.len();
            let window_of = |i: usize| 2 * halves[i] + 1;
            let longest = (0..total).map(window_of).max().unwrap_or(1);
            let mut ring: Ring<usize, usize> = Ring::new(waits_for(longest, by_altitude));
            let mut out = Vec::new();
            let check = |ring: &Ring<usize, usize>, i: usize, w: usize, pool: Range<usize>, eof: bool| {
                prop_assert_eq!(i, w);
                let mission = if eof { total } else { ring.pushed() };
                let (n, reach) = (window_of(i), waits_for(window_of(i), by_altitude));
                prop_assert!(pool.contains(&i) && pool.end <= mission, "{:?} for {}", pool, i);
                prop_assert_eq!(pool.len(), reach.min(mission));
                let held: Vec<usize> = ring.in_range(pool.clone()).copied().collect();
                prop_assert_eq!(held, pool.clone().collect::<Vec<_>>(), "the ring lost a photo of the pool");
                let by_time = window_range(i, n, ring.pushed());
                prop_assert!(by_time.start >= pool.start && by_time.end <= pool.end && by_time.contains(&i));
                let members = choose(i, n, pool.clone(), by_time, |j| altitudes[j]);
                prop_assert!(members.contains(&i));
                prop_assert!(members.windows(2).all(|m| m[0] < m[1]), "{:?}", members);
                for m in members {
                    prop_assert_eq!(ring.get(m), Some(&m), "member {} of photo {}", m, i);
                }
                Ok(())
            };
            let ready = |i: usize| waits_for(window_of(i), by_altitude);
            for p in 0..total {
                ring.push(p, p);
                while let Some((i, w, pool)) = ring.next_ready_by(false, ready) {
                    check(&ring, i, w, pool, false)?;
                    out.push(i);
                }
            }
            while let Some((i, w, pool)) = ring.next_ready_by(true, ready) {
                check(&ring, i, w, pool, true)?;
                out.push(i);
            }
            prop_assert_eq!(out, (0..total).collect::<Vec<_>>());
            prop_assert_eq!(ring.waiting(), 0);
        }
    }

    /// The windows of a mission of 10 with n = 5, written out: shifted at the start and end, centred between.
    #[test]
    fn windows_of_a_short_mission() {
        let mut ring: Ring<(), usize> = Ring::new(5);
        let mut got = Vec::new();
        for p in 0..10 {
            ring.push((), p);
            while let Some((i, _, r)) = ring.next_ready(false) {
                got.push((i, r));
            }
        }
        while let Some((i, _, r)) = ring.next_ready(true) {
            got.push((i, r));
        }
        let want: Vec<(usize, Range<usize>)> = vec![
            (0, 0..5),
            (1, 0..5),
            (2, 0..5),
            (3, 1..6),
            (4, 2..7),
            (5, 3..8),
            (6, 4..9),
            (7, 5..10),
            (8, 5..10),
            (9, 5..10),
        ];
        assert_eq!(got, want);
    }
}

//! Windows chosen by altitude: where the altitude of each photo is known (a navigation log) and it swings along the
//! track, a photo's window is taken among the photos around it that were lit from the heights nearest its own,
//! instead of the photos nearest in time.
//!
//! The lights' footprint on the seafloor — the cone's width, its fall-off, the attenuation of the way down and back
//! — is set by the altitude. A window over the photos nearest in time mixes photos lit from other heights where
//! the vehicle bounces (a towed sledge, an ROV over rough ground), and its `M` is a blend of footprints that fits
//! none of them. Like oplab's `correct_images` and MB-System's `mbgetphotocorrection`, which bin by altitude, the
//! window is chosen here among photos of a similar altitude; unlike them, only among the photos around the photo
//! ([`pool_length`]), so the water, the attitude and the exposure stay those of its stretch of the mission.
//!
//! The choice is balanced in time: half the window among the photos before the photo, half among those after (as
//! the window over time is), each half the photos nearest in altitude. On the dive matrix's altitude swings an
//! unbalanced choice left more of the lighting pattern (docs/results.md "Altitude swings").
//!
//! Where the altitude hardly changes over the window over time ([`ALTITUDE_SPAN`]), that window stays: on the dive
//! matrix's level dives (5 % altitude changes) a choice by altitude only lost samples' independence.

use std::ops::Range;

/// The window over time is kept where its photos' altitudes span less than this share of their mean altitude.
///
/// On the dive matrix the level dives' windows span 4.5–12 % (the twelve and the nodule fields), where choosing by
/// altitude raised their albedo error by up to 5 % and their residual pattern by up to 23 %; the altitude swings'
/// windows span 17–61 %, where it lowered their albedo error by up to 16 % (docs/results.md "Altitude swings").
pub const ALTITUDE_SPAN: f64 = 0.15;

/// The photos around a photo its window is chosen among, for a window of `n`: the `n` photos before it and the `n`
/// after it, and itself. A photo waits for the `n` photos after it (not `n/2`).
pub fn pool_length(n: usize) -> usize {
    2 * n + 1
}

/// The photos a window of `n` is chosen among, and so the reach a photo waits for and a shard reads: the window,
/// or where windows are chosen by altitude, its pool ([`pool_length`]).
pub fn waits_for(n: usize, by_altitude: bool) -> usize {
    match by_altitude {
        true => pool_length(n),
        false => n,
    }
}

/// The share of their mean altitude that `altitudes` span (`max − min` over the mean); `None` when one is unknown
/// or the mean is not positive.
pub fn span(altitudes: impl IntoIterator<Item = Option<f32>>) -> Option<f64> {
    let (mut lo, mut hi, mut sum, mut count) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
    for a in altitudes {
        let a = a? as f64;
        lo = lo.min(a);
        hi = hi.max(a);
        sum += a;
        count += 1;
    }
    let mean = sum / count as f64;
    (count > 0 && mean > 0.0).then(|| (hi - lo) / mean)
}

/// Photo `i`'s window of `n` photos chosen by altitude among `pool` (the photos around it, a range of photo
/// numbers that holds `i`), with `altitude(j)` the altitude of photo `j` (`None`: unknown). The window over time,
/// `by_time`, stays where photo `i`'s altitude or one of `by_time`'s is unknown, or where `by_time` spans less than
/// [`ALTITUDE_SPAN`] of its mean altitude.
///
/// Otherwise: photo `i`, and as many photos before it as the window over time has, those nearest to `i` in
/// altitude among the pool's photos before it with a known altitude (ties: the nearer in time); the same after it.
/// Where one side has too few, the other gives the rest. Returns the photo numbers in order.
pub fn choose(
    i: usize,
    n: usize,
    pool: Range<usize>,
    by_time: Range<usize>,
    altitude: impl Fn(usize) -> Option<f32>,
) -> Vec<usize> {
    let keep = || by_time.clone().collect();
    let Some(own) = altitude(i) else {
        return keep();
    };
    match span(by_time.clone().map(&altitude)) {
        Some(s) if s >= ALTITUDE_SPAN => {}
        _ => return keep(),
    }
    let nearest = |side: Vec<usize>| {
        let mut side: Vec<(f32, usize, usize)> = side
            .into_iter()
            .filter_map(|j| altitude(j).map(|a| ((a - own).abs(), j.abs_diff(i), j)))
            .collect();
        side.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        side.into_iter().map(|(_, _, j)| j).collect::<Vec<usize>>()
    };
    let before = nearest((pool.start..i).collect());
    let after = nearest((i + 1..pool.end).collect());
    let want_before = (i - by_time.start).min(n.saturating_sub(1));
    let want_after = n.saturating_sub(1) - want_before;
    let (mut nb, mut na) = (want_before.min(before.len()), want_after.min(after.len()));
    // One side short: the other gives the rest.
    let missing = n.saturating_sub(1) - nb - na;
    let more_after = missing.min(after.len() - na);
    na += more_after;
    nb += (missing - more_after).min(before.len() - nb);
    let mut out: Vec<usize> = before[..nb]
        .iter()
        .chain(&after[..na])
        .copied()
        .chain([i])
        .collect();
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: every window of `n` photos from the pool that holds `i`, balanced as `by_time` is, whose
    /// summed altitude distance is the least.
    fn least_distance(
        i: usize,
        n: usize,
        pool: Range<usize>,
        want_before: usize,
        alt: &[f32],
    ) -> f32 {
        let others: Vec<usize> = pool.clone().filter(|&j| j != i).collect();
        let mut best = f32::INFINITY;
        for mask in 0u32..(1 << others.len()) {
            if mask.count_ones() as usize != n - 1 {
                continue;
            }
            let chosen: Vec<usize> = (0..others.len())
                .filter(|b| mask & (1 << b) != 0)
                .map(|b| others[b])
                .collect();
            if chosen.iter().filter(|&&j| j < i).count() != want_before {
                continue;
            }
            best = best.min(chosen.iter().map(|&j| (alt[j] - alt[i]).abs()).sum());
        }
        best
    }

    #[test]
    fn a_swinging_track_takes_the_photos_lit_from_the_nearest_heights_half_on_each_side() {
        // Altitude swings of ±40 % with a period of 6 photos.
        let alt: Vec<f32> = (0..40)
            .map(|j| 4.0 + 1.6 * (j as f32 * std::f32::consts::TAU / 6.0).sin())
            .collect();
        let n = 5;
        for i in 5..35 {
            let by_time = i - 2..i + 3;
            let pool = i - n..i + n + 1;
            let w = choose(i, n, pool.clone(), by_time, |j| Some(alt[j]));
            assert_eq!(w.len(), n, "photo {i}: {w:?}");
            assert!(w.contains(&i));
            assert!(w.windows(2).all(|p| p[0] < p[1]), "in order: {w:?}");
            assert!(w.iter().all(|j| pool.contains(j)));
            assert_eq!(w.iter().filter(|&&j| j < i).count(), 2, "balanced: {w:?}");
            let got: f32 = w.iter().map(|&j| (alt[j] - alt[i]).abs()).sum();
            let best = least_distance(i, n, pool, 2, &alt);
            assert!((got - best).abs() < 1e-5, "photo {i}: {got} against {best}");
            // And nearer in altitude than the window over time.
            let by_time: f32 = (i - 2..i + 3).map(|j| (alt[j] - alt[i]).abs()).sum();
            assert!(got <= by_time + 1e-6, "photo {i}");
        }
    }

    #[test]
    fn a_level_track_or_an_unknown_altitude_keeps_the_window_over_time() {
        let level: Vec<f32> = (0..30).map(|j| 4.0 + 0.02 * (j % 5) as f32).collect();
        assert_eq!(
            choose(10, 7, 3..18, 7..14, |j| Some(level[j])),
            (7..14).collect::<Vec<_>>()
        );
        let swing = |j: usize| Some(if j.is_multiple_of(2) { 3.0 } else { 5.0 });
        assert_ne!(
            choose(10, 7, 3..18, 7..14, swing),
            (7..14).collect::<Vec<_>>()
        );
        // The photo's own altitude unknown, or one of the window's.
        let unknown_own = |j: usize| if j == 10 { None } else { swing(j) };
        assert_eq!(
            choose(10, 7, 3..18, 7..14, unknown_own),
            (7..14).collect::<Vec<_>>()
        );
        let unknown_other = |j: usize| if j == 12 { None } else { swing(j) };
        assert_eq!(
            choose(10, 7, 3..18, 7..14, unknown_other),
            (7..14).collect::<Vec<_>>()
        );
    }

    #[test]
    fn at_the_start_of_the_mission_the_photos_after_give_the_rest() {
        let swing = |j: usize| Some(if j.is_multiple_of(3) { 3.0 } else { 5.0 });
        // Photo 1 of a mission: its window over time is 0..7, one photo before it.
        let w = choose(1, 7, 0..16, 0..7, swing);
        assert_eq!(w.len(), 7);
        assert_eq!(w.iter().filter(|&&j| j < 1).count(), 1);
        // Photo 1's altitude is 5: the photos after it are those of altitude 5 first.
        assert!(
            w.iter().filter(|&&j| j > 1).all(|&j| swing(j) == Some(5.0)),
            "{w:?}"
        );
        // A pool with too few photos after: the window is the whole pool.
        assert_eq!(choose(5, 7, 0..7, 0..7, swing), (0..7).collect::<Vec<_>>());
        // Photos of unknown altitude in the pool are never chosen.
        let some_unknown = |j: usize| if j > 5 { None } else { swing(j) };
        let w = choose(3, 5, 0..12, 1..6, |j| {
            if (1..6).contains(&j) {
                swing(j)
            } else {
                some_unknown(j)
            }
        });
        assert!(w.iter().all(|&j| j <= 5), "{w:?}");
    }

    #[test]
    fn span_is_the_range_over_the_mean() {
        assert_eq!(span([Some(3.0), Some(5.0)]), Some(0.5));
        assert_eq!(span([Some(3.0), None]), None);
        assert_eq!(span(std::iter::empty()), None);
    }
}

//! The sliding temporal window: how many photos (`n`) the median over time needs, and which photos it spans.
//!
//! With contamination rate `c` (the chance that a given pixel of a given photo is not uniform seafloor), the
//! temporal median of `n` samples breaks down when at least half of them are contaminated:
//! `P_half = Σ_{u ≥ n/2} Binom(u; n, c)`. [`choose_window`] returns the smallest odd `n` with `P_half ≤ risk`.

use serde::Serialize;

use crate::method::params::InvalidConfig;

/// Largest window [`choose_window`] will propose.
pub const MAX_WINDOW: usize = crate::limits::WINDOW;

/// Probability that at least half of `n` samples are contaminated, each independently with probability `c`:
/// `Σ_{u = ⌈n/2⌉}^{n} C(n, u) c^u (1 − c)^(n − u)`.
pub fn p_half(n: usize, c: f64) -> f64 {
    if n == 0 {
        return 1.0;
    }
    binomial_tail(n, n.div_ceil(2), c)
}

/// Probability that at least `u_min` of `n` independent events of probability `c` happen:
/// `Σ_{u = u_min}^{n} C(n, u) c^u (1 − c)^(n − u)`.
pub fn binomial_tail(n: usize, u_min: usize, c: f64) -> f64 {
    if u_min == 0 {
        return 1.0;
    }
    if c <= 0.0 || u_min > n {
        return 0.0;
    }
    if c >= 1.0 {
        return 1.0;
    }
    let (ln_c, ln_q) = (c.ln(), (1.0 - c).ln());
    // ln C(n, u) built up incrementally; terms summed in linear space (they are all ≤ 1).
    let mut ln_binom = 0.0f64; // ln C(n, 0)
    let mut sum = 0.0;
    for u in 0..=n {
        if u > 0 {
            ln_binom += ((n - u + 1) as f64).ln() - (u as f64).ln();
        }
        if u >= u_min {
            sum += (ln_binom + u as f64 * ln_c + (n - u) as f64 * ln_q).exp();
        }
    }
    sum.min(1.0)
}

/// A window size and its breakdown probability.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WindowChoice {
    /// Photos in the window (odd).
    pub n: usize,
    /// Probability that half or more of the window is contaminated at a pixel (NaN when the contamination rate
    /// is not known).
    pub p_half: f64,
}

/// The smallest odd `n` whose breakdown probability `P_half(n, c)` is at most `risk`; `c` must be in `[0, 0.5)`,
/// `risk` in `(0, 1)`, and a window up to [`limits::WINDOW`](crate::limits::WINDOW) photos must do.
pub fn choose_window(contamination: f64, risk: f64) -> Result<WindowChoice, InvalidConfig> {
    if !(0.0..0.5).contains(&contamination) {
        return Err(InvalidConfig::Contamination(contamination));
    }
    if !(risk > 0.0 && risk < 1.0) {
        return Err(InvalidConfig::Risk(risk));
    }
    let mut n = 1;
    while n <= MAX_WINDOW {
        let p = p_half(n, contamination);
        if p <= risk {
            return Ok(WindowChoice { n, p_half: p });
        }
        n += 2;
    }
    Err(InvalidConfig::NoWindow {
        contamination,
        risk,
    })
}

/// Probability that the `q` quantile of `n` samples falls on a contaminated one, each sample contaminated
/// independently with probability `c` and darker than every seafloor sample (nodules, shadows, burrows): the
/// quantile sits at position `q·(n − 1)` of the sorted samples (interpolated), so it is dark once more than
/// `⌊q·(n − 1)⌋` of them are: `Σ_{u > ⌊q(n−1)⌋} Binom(u; n, c)`. At `q = 0.5` and odd `n`, [`p_half`].
pub fn p_quantile_dark(n: usize, q: f64, c: f64) -> f64 {
    if n == 0 {
        return 1.0;
    }
    let at = (q.clamp(0.0, 1.0) * (n - 1) as f64).floor() as usize;
    binomial_tail(n, at + 1, c)
}

/// The smallest odd window whose `q` quantile breaks down ([`p_quantile_dark`]) with probability at most `risk`
/// at contamination `c`, counting `photos_per_sample` photos for one independent sample (a camera that moves
/// less than a dark object's extent between photos sees it again: its photos are not independent samples).
/// `None` when no window up to `MAX_WINDOW` photos does.
///
/// With the `(1 + c)/2` quantile the window needs far fewer photos than the median's rule ([`choose_window`]):
/// at `c = 0.4`, 21 instead of 129 for a 1 % risk.
pub fn quantile_window(c: f64, q: f64, risk: f64, photos_per_sample: usize) -> Option<usize> {
    let step = photos_per_sample.max(1);
    let mut n = 1;
    while n * step <= MAX_WINDOW {
        if p_quantile_dark(n, q, c) <= risk {
            return Some((n * step) | 1);
        }
        n += 2;
    }
    None
}

/// First photo of the window of photo `i` in a mission of `total` photos: centred on `i` where possible, shifted
/// at the start and end so it still holds `n` photos. Missions shorter than `n` use all photos.
pub fn window_start(i: usize, n: usize, total: usize) -> usize {
    if total <= n {
        return 0;
    }
    i.saturating_sub(n / 2).min(total - n)
}

/// The photos `[start, end)` in the window of photo `i`.
pub fn window_range(i: usize, n: usize, total: usize) -> std::ops::Range<usize> {
    let s = window_start(i, n, total);
    s..(s + n).min(total)
}

/// Breakdown risk accepted for the near window: the paper's own example (`c = 0.2`, `n = 7`: `P_half` = 3.3 %).
pub const NEAR_RISK: f64 = 0.05;

/// Fewest photos in the near window (with 3, a dense nodule field broke it: a03's pattern 1.8× on the matrix).
pub const NEAR_MIN: usize = 5;

/// The near window of `--method abyss` for a mission whose window is `n`: with a contamination rate `c`, the
/// smallest odd window with `P_half ≤` `NEAR_RISK`, at least `NEAR_MIN`; without one, `NEAR_MIN`. `None`
/// when that is not shorter than `n` (nothing to follow that the window does not already follow).
///
/// The window's `n` is chosen so that its median almost never breaks; over that many photos the lights'
/// footprint moves with the vehicle's altitude and roll. The near window's `M` follows it, and only its smooth
/// shape is taken (`near_shape`), so its more frequent local breakdowns are outvoted.
pub fn near_window(n: usize, contamination: Option<f64>) -> Option<usize> {
    let near = match contamination {
        Some(c) => choose_window(c, NEAR_RISK).map_or(n, |w| w.n.max(NEAR_MIN)),
        None => NEAR_MIN,
    };
    (near < n).then_some(near)
}

/// The near window's photos `[start, end)` for photo `i`, inside its window `window` (as the engine ranges them:
/// centred where possible, shifted at the mission's ends).
pub fn near_range(
    i: usize,
    near: usize,
    window: &std::ops::Range<usize>,
) -> std::ops::Range<usize> {
    let s = i.saturating_sub(near / 2).clamp(
        window.start,
        window.end.saturating_sub(near).max(window.start),
    );
    s..(s + near).min(window.end)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_window_is_shorter_than_the_window_or_none() {
        // c = 0.2: the 1 % window is 13, the near one the 5 % window, 7 (P_half 3.3 %).
        assert_eq!(choose_window(0.2, 0.01).unwrap().n, 13);
        assert_eq!(near_window(13, Some(0.2)), Some(7));
        // c = 0.1: 5 % allows 3, the near window keeps 5; a window of 5 has no shorter one.
        assert_eq!(choose_window(0.1, NEAR_RISK).unwrap().n, 3);
        assert_eq!(near_window(9, Some(0.1)), Some(5));
        assert_eq!(near_window(5, Some(0.1)), None);
        // c = 0.35: 29 inside the 1 % window's 57.
        assert_eq!(near_window(57, Some(0.35)), Some(29));
        assert!(p_half(29, 0.35) <= NEAR_RISK && p_half(27, 0.35) > NEAR_RISK);
        // Without a contamination rate: 5 inside the default 7, none inside 3 or 5.
        assert_eq!(near_window(7, None), Some(5));
        assert_eq!(near_window(5, None), None);
        assert_eq!(near_window(3, None), None);
    }

    #[test]
    fn near_range_is_centred_and_inside_the_window() {
        for total in [3usize, 7, 9, 30] {
            for n in [5usize, 7, 9, 13] {
                for near in (3..n).step_by(2) {
                    for i in 0..total {
                        let w = window_range(i, n, total);
                        let r = near_range(i, near, &w);
                        assert!(
                            r.start >= w.start && r.end <= w.end,
                            "{i} {near} {w:?} {r:?}"
                        );
                        assert!(r.contains(&i), "photo {i} not in its near window {r:?}");
                        assert_eq!(r.len(), near.min(w.len()), "{i} {near} {w:?} {r:?}");
                        // Centred on i wherever the window leaves room.
                        if i >= near / 2 + w.start && i + near / 2 < w.end {
                            assert_eq!(r, i - near / 2..i + near / 2 + 1);
                        }
                    }
                }
            }
        }
    }

    /// Independent check: enumerate all 2^n contamination patterns and add up the probability of those in which
    /// at least half of the samples are contaminated.
    fn p_half_by_enumeration(n: usize, c: f64) -> f64 {
        let mut total = 0.0;
        for pattern in 0u32..(1 << n) {
            let u = pattern.count_ones() as usize;
            if 2 * u >= n {
                total += c.powi(u as i32) * (1.0 - c).powi((n - u) as i32);
            }
        }
        total
    }

    /// The `q` quantile's breakdown by enumerating every contamination pattern of `n` samples (dark = 0,
    /// seafloor = 1, the quantile by sorting and linear interpolation: dark when below 1).
    fn p_quantile_dark_by_enumeration(n: usize, q: f64, c: f64) -> f64 {
        let mut total = 0.0;
        for bits in 0u32..(1 << n) {
            let dark = bits.count_ones() as usize;
            let mut v: Vec<f64> = (0..n).map(|i| f64::from(i >= dark)).collect();
            v.sort_by(f64::total_cmp);
            let pos = q * (n - 1) as f64;
            let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
            let val = v[lo] + (v[hi] - v[lo]) * (pos - lo as f64);
            if val < 1.0 {
                total += c.powi(dark as i32) * (1.0 - c).powi((n - dark) as i32);
            }
        }
        total
    }

    #[test]
    fn p_quantile_dark_matches_enumeration_and_the_median() {
        for n in [1, 2, 3, 5, 8, 11] {
            for q in [0.5, 0.6, 0.65, 0.7, 0.75] {
                for c in [0.1, 0.3, 0.45] {
                    let (a, b) = (
                        p_quantile_dark(n, q, c),
                        p_quantile_dark_by_enumeration(n, q, c),
                    );
                    assert!((a - b).abs() < 1e-12, "n {n} q {q} c {c}: {a} vs {b}");
                }
            }
        }
        for n in [1, 7, 13, 31] {
            assert!((p_quantile_dark(n, 0.5, 0.3) - p_half(n, 0.3)).abs() < 1e-12);
        }
    }

    #[test]
    fn quantile_window_is_far_shorter_than_the_median_rule_and_counts_independent_samples() {
        let w = quantile_window(0.4, 0.7, 0.01, 1).unwrap();
        assert!(p_quantile_dark(w, 0.7, 0.4) <= 0.01);
        assert!((1..w)
            .step_by(2)
            .all(|n| p_quantile_dark(n, 0.7, 0.4) > 0.01));
        assert!(w < choose_window(0.4, 0.01).unwrap().n / 4, "{w}");
        // Three photos per independent sample: three times the photos (odd).
        let w3 = quantile_window(0.4, 0.7, 0.01, 3).unwrap();
        assert_eq!(w3, (3 * w) | 1);
        // The median's rule is the q = 0.5 case.
        assert_eq!(
            quantile_window(0.3, 0.5, 0.01, 1),
            Some(choose_window(0.3, 0.01).unwrap().n)
        );
        assert_eq!(quantile_window(0.49, 0.5, 1e-9, 1), None);
    }

    #[test]
    fn binomial_tail_matches_enumeration() {
        for n in 1..=14usize {
            for u_min in 0..=n + 1 {
                for &c in &[0.0f64, 0.02, 0.2, 0.5, 0.9, 1.0] {
                    let mut want = 0.0;
                    for pattern in 0u32..(1 << n) {
                        let u = pattern.count_ones() as usize;
                        if u >= u_min {
                            want += c.powi(u as i32) * (1.0 - c).powi((n - u) as i32);
                        }
                    }
                    let got = binomial_tail(n, u_min, c);
                    assert!(
                        (got - want).abs() < 1e-12,
                        "n={n} u_min={u_min} c={c}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn paper_example_c02_n7_is_about_3_percent() {
        // Exact: 35·.2⁴·.8³ + 21·.2⁵·.8² + 7·.2⁶·.8 + .2⁷ = 0.033344
        let p = p_half(7, 0.2);
        assert!((p - 0.033344).abs() < 1e-12, "{p}");
    }

    #[test]
    fn p_half_matches_enumeration() {
        for n in 1..=15 {
            for &c in &[0.01, 0.1, 0.2, 0.33, 0.45, 0.5, 0.7] {
                let a = p_half(n, c);
                let b = p_half_by_enumeration(n, c);
                assert!((a - b).abs() < 1e-12, "n={n} c={c}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn chosen_window_is_smallest_odd_meeting_risk() {
        for &c in &[0.0, 0.05, 0.2, 0.3, 0.4] {
            for &risk in &[0.05, 0.01, 0.001] {
                let w = choose_window(c, risk).unwrap();
                assert_eq!(w.n % 2, 1);
                assert!(p_half_by_enumeration(w.n.min(15), c) <= risk || w.n > 15);
                assert!(w.p_half <= risk);
                if w.n >= 3 {
                    assert!(p_half(w.n - 2, c) > risk, "c={c} risk={risk} n={}", w.n);
                }
            }
        }
        // c = 0.2: n = 7 gives 3.3 %, so a 5 % risk takes 7 and a 1 % risk needs more.
        assert_eq!(choose_window(0.2, 0.05).unwrap().n, 7);
        assert!(choose_window(0.2, 0.01).unwrap().n > 7);
    }

    #[test]
    fn contamination_at_or_above_half_is_refused() {
        assert!(choose_window(0.5, 0.01).is_err());
        assert!(choose_window(-0.1, 0.01).is_err());
        assert!(choose_window(0.2, 0.0).is_err());
        // A nodule field's coverage too dense for the median's rule: the error says what to run instead.
        for c in [0.48, 0.5] {
            let e = choose_window(c, 0.01).unwrap_err().to_string();
            assert!(
                e.contains("--window auto") && e.contains("no --contamination"),
                "{e}"
            );
        }
        assert!(choose_window(0.45, 0.01).is_ok());
    }

    #[test]
    fn window_shifts_at_the_ends_and_always_holds_n() {
        let (n, total) = (7, 20);
        for i in 0..total {
            let r = window_range(i, n, total);
            assert_eq!(r.len(), n);
            assert!(r.contains(&i));
            if i >= 3 && i + 3 < total {
                assert_eq!(r, i - 3..i + 4, "centred in the middle");
            }
        }
        assert_eq!(window_range(0, 7, 20), 0..7);
        assert_eq!(window_range(19, 7, 20), 13..20);
        assert_eq!(window_range(2, 7, 4), 0..4, "short mission uses all photos");
    }
}

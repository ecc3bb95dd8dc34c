//! Breakdown monitoring: the method's assumptions fail silently (more than half of a window contaminated, a
//! seafloor colour change absorbed into `F`), so every photo gets a few health figures and a flag with a reason
//! when its estimate is likely wrong. The paper: a seafloor colour change "can only be detected by monitoring the
//! multiplicative image".

use serde::Serialize;

use crate::raster::Raster;

/// Thresholds for the flags.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Thresholds {
    /// Contamination estimate above which a photo is flagged (the median breaks at 0.5).
    pub contamination: f32,
    /// Relative change of `F` from the previous photo above which a photo is flagged...
    pub factor_change: f32,
    /// ...when it is also this many times the typical (median) change so far.
    pub factor_change_ratio: f32,
    /// Relative change of `F`'s colour balance against the start of the mission above which a photo is flagged.
    pub colour_shift: f32,
    /// A block counts as contaminated when its corrected value is off the seafloor colour by this share.
    pub block_deviation: f32,
}

impl Default for Thresholds {
    fn default() -> Self {
        Thresholds {
            contamination: 0.4,
            factor_change: 0.15,
            factor_change_ratio: 4.0,
            colour_shift: 0.1,
            block_deviation: 0.5,
        }
    }
}

/// Health figures of one photo, in the run report.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Health {
    /// Share of blocks whose corrected value is far from the seafloor colour (not seafloor, or a broken `F`).
    pub contamination: f32,
    /// Mean relative change of `F` from the previous photo.
    pub factor_change: f32,
    /// Largest relative change of `F`'s channel ratios against the start of the mission.
    pub colour_shift: f32,
    /// Why this photo's correction is likely wrong (empty: no reason to doubt it).
    pub flags: Vec<String>,
}

/// Share of blocks of `low` (the photo's own block medians, linear) whose ratio to `M − S` (i.e. the corrected
/// value relative to `C`) is off by more than `deviation`. `NaN` (masked) blocks are not counted.
pub fn contamination(
    low: &Raster,
    m_minus_s: &Raster,
    s_low: Option<&Raster>,
    deviation: f32,
) -> f32 {
    let c = low.channels;
    let (mut bad, mut n) = (0usize, 0usize);
    for p in 0..low.width * low.height {
        let mut ratio = 0.0;
        let mut valid = true;
        for ch in 0..c {
            let i = p * c + ch;
            let s = s_low.map_or(0.0, |s| s.data[i]);
            let (v, m) = (low.data[i] - s, m_minus_s.data[i]);
            if v.is_nan() || m.is_nan() || m <= 1e-6 {
                valid = false;
                break;
            }
            ratio += v / m;
        }
        if valid {
            n += 1;
            bad += ((ratio / c as f32 - 1.0).abs() > deviation) as usize;
        }
    }
    if n == 0 {
        0.0
    } else {
        bad as f32 / n as f32
    }
}

/// Mean relative change between two factor images: `Σ|a − b| / Σ|b|`.
pub fn factor_change(a: &Raster, b: &Raster) -> f32 {
    let (mut d, mut s) = (0.0f64, 0.0f64);
    for (x, y) in a.data.iter().zip(&b.data) {
        if x.is_finite() && y.is_finite() {
            d += (x - y).abs() as f64;
            s += y.abs() as f64;
        }
    }
    if s > 0.0 {
        (d / s) as f32
    } else {
        0.0
    }
}

/// Colour balance of a factor image: each channel's mean divided by the mean over channels.
pub fn balance(f: &Raster) -> Vec<f32> {
    let means = f.channel_means();
    let all = means.iter().sum::<f64>() / means.len().max(1) as f64;
    means
        .iter()
        .map(|m| if all > 0.0 { (m / all) as f32 } else { 1.0 })
        .collect()
}

/// Follows the mission photo by photo and flags photos whose estimate is likely broken.
#[derive(Debug, Default)]
pub struct Monitor {
    pub thresholds: Thresholds,
    previous: Option<Raster>,
    changes: Vec<f32>,
    /// Balances of the first photos, whose median is the mission's reference balance.
    start: Vec<Vec<f32>>,
    reference: Option<Vec<f32>>,
}

/// Photos whose balance makes up the mission's reference.
const REFERENCE_PHOTOS: usize = 5;

impl Monitor {
    pub fn new(thresholds: Thresholds) -> Self {
        Monitor {
            thresholds,
            ..Monitor::default()
        }
    }

    /// Health of the next photo, from its factor image and contamination estimate.
    pub fn observe(&mut self, f: &Raster, contamination: f32) -> Health {
        let t = self.thresholds;
        let mut h = Health {
            contamination,
            ..Health::default()
        };
        if contamination > t.contamination {
            h.flags.push(format!(
                "contamination {:.0} % is near the 50 % at which the median breaks down",
                100.0 * contamination
            ));
        }
        if let Some(prev) = &self.previous {
            let change = factor_change(f, prev);
            h.factor_change = change;
            let mut sorted = self.changes.clone();
            sorted.sort_by(f32::total_cmp);
            let typical = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
            if change > t.factor_change && change > t.factor_change_ratio * typical {
                h.flags.push(format!(
                    "F changed {:.0} % from the previous photo (altitude or attitude jump, or a seafloor change)",
                    100.0 * change
                ));
            }
            self.changes.push(change);
        }
        let b = balance(f);
        if self.reference.is_none() {
            self.start.push(b.clone());
            if self.start.len() == REFERENCE_PHOTOS {
                self.reference = Some(median_balance(&self.start));
            }
        }
        let reference = self
            .reference
            .clone()
            .unwrap_or_else(|| median_balance(&self.start));
        h.colour_shift = b
            .iter()
            .zip(&reference)
            .map(|(x, r)| ((x - r) / r).abs())
            .fold(0.0, f32::max);
        if h.colour_shift > t.colour_shift {
            h.flags.push(format!(
                "F's colour balance differs {:.0} % from the mission start (seafloor or water colour change: \
                 it is absorbed into F and removed from the photos)",
                100.0 * h.colour_shift
            ));
        }
        self.previous = Some(f.clone());
        h
    }
}

fn median_balance(v: &[Vec<f32>]) -> Vec<f32> {
    let c = v.first().map_or(0, Vec::len);
    (0..c)
        .map(|ch| {
            let mut x: Vec<f32> = v.iter().map(|b| b[ch]).collect();
            x.sort_by(f32::total_cmp);
            x[x.len() / 2]
        })
        .collect()
}

/// Count of flagged photos per kind of reason, for the end-of-run summary.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Summary {
    pub flagged: usize,
    pub contamination: usize,
    pub factor_change: usize,
    pub colour_shift: usize,
    pub short_mission: usize,
}

impl Summary {
    pub fn add(&mut self, flags: &[String]) {
        if flags.is_empty() {
            return;
        }
        self.flagged += 1;
        for f in flags {
            if f.starts_with("contamination") {
                self.contamination += 1;
            } else if f.starts_with("F changed") {
                self.factor_change += 1;
            } else if f.starts_with("F's colour") {
                self.colour_shift += 1;
            } else {
                self.short_mission += 1;
            }
        }
    }

    /// One line for the user.
    pub fn line(&self, photos: usize) -> String {
        if self.flagged == 0 {
            return format!("no photo of {photos} flagged: the estimates look sound");
        }
        let mut parts = Vec::new();
        for (n, what) in [
            (self.contamination, "contamination near 50 %"),
            (self.factor_change, "sudden change of F"),
            (self.colour_shift, "colour change of F"),
            (self.short_mission, "too few photos for the window"),
        ] {
            if n > 0 {
                parts.push(format!("{n} {what}"));
            }
        }
        format!(
            "{} of {photos} photos flagged as likely wrong ({}); see the report and _abysslight/overview.png",
            self.flagged,
            parts.join(", ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contamination_counts_blocks_off_the_seafloor() {
        let m = Raster::filled(10, 10, 3, 0.5);
        let mut low = m.clone();
        for p in 0..30 {
            for c in 0..3 {
                low.data[p * 3 + c] = 0.1; // dark nodule: ratio 0.2
            }
        }
        for c in 0..3 {
            low.data[50 * 3 + c] = 0.6; // ratio 1.2: texture, not contamination
            low.data[60 * 3 + c] = f32::NAN; // masked
        }
        let got = contamination(&low, &m, None, 0.5);
        assert!((got - 30.0 / 99.0).abs() < 1e-6, "{got}");
        // S is subtracted from the photo's blocks before the ratio.
        let s = Raster::filled(10, 10, 3, 0.1);
        let lifted = Raster::from_fn(10, 10, 3, |x, y, c| m.get(x, y, c) + 0.1);
        assert_eq!(contamination(&lifted, &m, Some(&s), 0.5), 0.0);
    }

    #[test]
    fn factor_change_and_balance_by_hand() {
        let a = Raster::filled(2, 1, 3, 1.0);
        let b = Raster::from_fn(2, 1, 3, |x, _, _| if x == 0 { 1.5 } else { 1.0 });
        // |1.5 - 1| * 3 / (6 * 1) = 0.25
        assert!((factor_change(&b, &a) - 0.25).abs() < 1e-6);
        let c = Raster::from_fn(1, 1, 3, |_, _, ch| [0.5, 1.0, 1.5][ch]);
        assert_eq!(balance(&c), vec![0.5, 1.0, 1.5]);
    }

    #[test]
    fn flags_jumps_and_colour_changes_but_not_steady_photos() {
        let mut mon = Monitor::new(Thresholds::default());
        let steady = |k: f32| {
            Raster::from_fn(4, 3, 3, |x, _, c| {
                (0.5 + 0.01 * x as f32) * [1.0, 0.9, 0.7][c] * k
            })
        };
        for i in 0..10 {
            let h = mon.observe(&steady(1.0 + 0.01 * i as f32), 0.2);
            assert!(h.flags.is_empty(), "photo {i}: {:?}", h.flags);
        }
        // Altitude jump: F halves.
        let h = mon.observe(&steady(0.5), 0.2);
        assert!(
            h.flags.iter().any(|f| f.starts_with("F changed")),
            "{:?}",
            h.flags
        );
        // Contamination near breakdown.
        let h = mon.observe(&steady(0.5), 0.45);
        assert!(
            h.flags.iter().any(|f| f.starts_with("contamination")),
            "{:?}",
            h.flags
        );
        // Seafloor turns bluish: the balance of F shifts.
        let blue = Raster::from_fn(4, 3, 3, |x, _, c| {
            (0.5 + 0.01 * x as f32) * [0.7, 0.9, 1.0][c] * 0.5
        });
        let h = mon.observe(&blue, 0.2);
        assert!(
            h.flags.iter().any(|f| f.starts_with("F's colour")),
            "{:?}",
            h.flags
        );
        assert!(h.colour_shift > 0.2);
        let mut s = Summary::default();
        s.add(&h.flags);
        s.add(&[]);
        assert_eq!(s.flagged, 1);
        assert!(s.line(2).contains("1 of 2"));
    }
}

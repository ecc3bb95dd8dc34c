//! Transfer curves: how stored sample values relate to light. The model `I = A·F + S` holds for radiance, so a
//! gamma-encoded photo (most JPEGs) is converted to linear values before estimation and correction, and back
//! after. Medians commute with these monotonic curves, so the medians are taken on the stored values.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

#[cfg(target_arch = "x86_64")]
mod avx2;

/// A transfer curve between stored values `v` and linear light `L`, both in `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum Transfer {
    /// Stored values are linear in light (machine-vision cameras, RAW conversions).
    #[default]
    Linear,
    /// The sRGB curve (IEC 61966-2-1), used by almost every JPEG.
    Srgb,
    /// A pure power law `L = v^G`.
    Gamma(f32),
}

impl Transfer {
    /// Stored value to linear light.
    pub fn to_linear(self, v: f32) -> f32 {
        let v = v.clamp(0.0, 1.0);
        match self {
            Transfer::Linear => v,
            Transfer::Srgb => {
                if v <= 0.04045 {
                    v / 12.92
                } else {
                    ((v + 0.055) / 1.055).powf(2.4)
                }
            }
            Transfer::Gamma(g) => v.powf(g),
        }
    }

    /// Linear light to stored value.
    pub fn from_linear(self, l: f32) -> f32 {
        let l = l.clamp(0.0, 1.0);
        match self {
            Transfer::Linear => l,
            Transfer::Srgb => {
                if l <= 0.003_130_8 {
                    l * 12.92
                } else {
                    1.055 * l.powf(1.0 / 2.4) - 0.055
                }
            }
            Transfer::Gamma(g) => l.powf(1.0 / g),
        }
    }

    /// True when stored values are light already.
    pub fn is_linear(self) -> bool {
        self == Transfer::Linear || self == Transfer::Gamma(1.0)
    }
}

impl FromStr for Transfer {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        match t.as_str() {
            "linear" => Ok(Transfer::Linear),
            "srgb" => Ok(Transfer::Srgb),
            _ => {
                let g = t
                    .strip_prefix("gamma:")
                    .and_then(|g| g.parse::<f32>().ok())
                    .filter(|g| *g > 0.0 && g.is_finite() && *g <= 10.0)
                    .ok_or_else(|| {
                        format!("invalid transfer {s:?}: expected srgb, linear or gamma:G (e.g. gamma:2.2)")
                    })?;
                Ok(Transfer::Gamma(g))
            }
        }
    }
}

impl TryFrom<String> for Transfer {
    type Error = String;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<Transfer> for String {
    fn from(t: Transfer) -> String {
        t.to_string()
    }
}

impl fmt::Display for Transfer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Transfer::Linear => write!(f, "linear"),
            Transfer::Srgb => write!(f, "srgb"),
            Transfer::Gamma(g) => write!(f, "gamma:{g}"),
        }
    }
}

/// Tables for one transfer curve and one sample depth (`levels` = 256 or 65536): stored code → linear light, and
/// linear light → nearest stored code.
#[derive(Debug, Clone)]
pub struct Curve {
    transfer: Transfer,
    max: f32,
    to_lin: Vec<f32>,
    /// `thresholds[k]`: linear light at the boundary between codes `k` and `k + 1` (empty when linear).
    thresholds: Vec<f32>,
    /// Exact fast path of [`Curve::code`]: positive floats are bucketed by the top bits of their representation
    /// (monotonic for positive floats); `start[b]` is the number of thresholds at or below the smallest float of
    /// bucket `b`, so a few steps up the threshold table from there give the exact count.
    start: Vec<u16>,
    /// Bits dropped from a float's representation to get its bucket, and the bucket of `thresholds[0]`.
    shift: u32,
    base: u32,
    /// `start` widened to `i32`, for the AVX2 gather of [`Curve::codes_avx2`] (only when `packed` is empty).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    start32: Vec<i32>,
    /// Most steps up the threshold table any bucket needs (so the vector search can run a fixed number).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    max_steps: usize,
    /// When no bucket holds more than one threshold above its smallest float (`max_steps ≤ 1`: sRGB and the usual
    /// gammas at 8 and 16 bits), bucket `b` packed into one `i32` for a single gather: `start[b] << 16 | low`,
    /// where `low` is the bits below `shift` of the threshold inside the bucket, or `1 << shift` (above every such
    /// value) when there is none. Two positive floats of one bucket compare as their low bits do, so
    /// `l ≥ threshold ⇔ low(l) ≥ low`. Empty otherwise.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    packed: Vec<i32>,
}

impl Curve {
    /// The curve for codes `0..levels` (256 or 65536).
    pub fn new(transfer: Transfer, levels: usize) -> Curve {
        let max = (levels - 1) as f32;
        let linear = transfer.is_linear();
        let to_lin = if linear {
            Vec::new()
        } else {
            (0..levels)
                .map(|i| transfer.to_linear(i as f32 / max))
                .collect()
        };
        let thresholds = if linear {
            Vec::new()
        } else {
            (0..levels - 1)
                .map(|k| transfer.to_linear((k as f32 + 0.5) / max))
                .collect()
        };
        // 256 buckets per octave for 8-bit codes, 32768 for 16-bit: at most one threshold inside a bucket for
        // sRGB and the usual gammas, so the vector search is one gather (`packed`). 16-bit sRGB: 688 k buckets,
        // 4 MB of tables, 17 ms to build; with 4096 buckets an octave (before) it took up to six dependent gathers,
        // 2.3x the time per photo.
        let shift = if levels <= 256 { 15 } else { 8 };
        let (base, start) = match (thresholds.first(), thresholds.last()) {
            (Some(&lo), Some(&hi)) if lo > 0.0 => {
                let base = lo.to_bits() >> shift;
                let top = hi.to_bits() >> shift;
                let start = (base..=top)
                    .map(|b| {
                        let smallest = f32::from_bits(b << shift);
                        thresholds.partition_point(|&t| t <= smallest) as u16
                    })
                    .collect();
                (base, start)
            }
            _ => (0, Vec::new()),
        };
        let max_steps = (0..start.len())
            .map(|b| {
                let next = start.get(b + 1).map_or(thresholds.len(), |&n| n as usize);
                next - start[b] as usize
            })
            .max()
            .unwrap_or(0);
        let packed = if max_steps <= 1 && !start.is_empty() {
            // The low bits, and the "no threshold" mark 1 << shift, fit the entry's 16 low bits.
            debug_assert!(shift < 16);
            let low_mask = (1u32 << shift) - 1;
            start
                .iter()
                .enumerate()
                .map(|(b, &i)| {
                    let low = match thresholds.get(i as usize) {
                        Some(t) if t.to_bits() >> shift == base + b as u32 => {
                            t.to_bits() & low_mask
                        }
                        _ => 1 << shift,
                    };
                    ((i as u32) << 16 | low) as i32
                })
                .collect()
        } else {
            Vec::new()
        };
        Curve {
            transfer,
            max,
            to_lin,
            thresholds,
            start32: if packed.is_empty() {
                start.iter().map(|&v| v as i32).collect()
            } else {
                Vec::new()
            },
            start,
            shift,
            base,
            max_steps,
            packed,
        }
    }

    /// Whether the vector codes (`Curve::codes_avx2`, x86-64) can run on this curve: it has thresholds and a
    /// bucket table. A curve whose first threshold rounds to 0 in `f32` (`gamma:9` and steeper at 16 bits) has
    /// none.
    #[inline]
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(crate) fn has_vector_codes(&self) -> bool {
        !self.thresholds.is_empty() && !self.start.is_empty()
    }

    /// The stored code nearest to `l` by binary search over the thresholds (the definition [`Curve::code`] must
    /// match exactly).
    pub fn code_by_search(&self, l: f32) -> u16 {
        if self.thresholds.is_empty() {
            return self.code(l);
        }
        self.thresholds.partition_point(|&t| t <= l) as u16
    }

    /// True when codes are linear in light (no tables): `linear(c) = c / max`, `code(l) = round(l·max)`.
    #[inline]
    pub fn is_identity(&self) -> bool {
        self.to_lin.is_empty() && self.thresholds.is_empty()
    }

    /// The largest code (255 or 65535).
    #[inline]
    pub fn max(&self) -> f32 {
        self.max
    }

    /// The transfer this curve tabulates.
    pub fn transfer(&self) -> Transfer {
        self.transfer
    }

    /// Linear light of every stored code (empty for a linear curve).
    pub fn linear_table(&self) -> &[f32] {
        &self.to_lin
    }

    /// Linear light of a stored code.
    #[inline]
    pub fn linear(&self, code: u16) -> f32 {
        if self.to_lin.is_empty() {
            code as f32 / self.max
        } else {
            self.to_lin[code as usize]
        }
    }

    /// The stored code nearest (in stored values) to linear light `l`, clamped to the code range.
    #[inline]
    pub fn code(&self, l: f32) -> u16 {
        if self.thresholds.is_empty() {
            let v = l * self.max + 0.5;
            return v.clamp(0.0, self.max) as u16;
        }
        // Number of thresholds at or below l. Below the first threshold (and for NaN) that is 0; otherwise start
        // from the count at the bottom of l's bucket and step up.
        if l.is_nan() || l < self.thresholds[0] {
            return 0;
        }
        let b = ((l.to_bits() >> self.shift) - self.base) as usize;
        let mut i = match self.start.get(b) {
            Some(&i) => i as usize,
            // Past the table: every threshold is below.
            None if !self.start.is_empty() => return self.thresholds.len() as u16,
            // No table (the first threshold is 0 in f32: gamma:9 and steeper at 16 bits).
            None => return self.code_by_search(l),
        };
        while i < self.thresholds.len() && self.thresholds[i] <= l {
            i += 1;
        }
        i as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn vector_codes_equal_scalar_codes() {
        let Some(avx2) = crate::simd::Avx2::detect() else {
            eprintln!("no AVX2 on this CPU: vector codes not tested");
            return;
        };
        let mut next = crate::method::xorshift32(0x2468_ACE1);
        let mut packed_seen = [false; 2];
        for (t, levels) in [
            (Transfer::Srgb, 256),
            (Transfer::Srgb, 65536),
            (Transfer::Gamma(2.2), 256),
            (Transfer::Gamma(1.8), 65536),
            (Transfer::Gamma(0.5), 256),
            (Transfer::Gamma(0.5), 65536),
            (Transfer::Gamma(0.8), 65536),
            (Transfer::Gamma(4.0), 65536),
        ] {
            let c = Curve::new(t, levels);
            // Both vector paths are exercised: one packed gather where every bucket holds at most one threshold
            // (8- and 16-bit sRGB, usual gammas), bucket start plus threshold steps otherwise (gamma 0.5 and 0.8
            // at 16 bits).
            assert_eq!(c.packed.is_empty(), c.max_steps > 1, "{t:?}/{levels}");
            packed_seen[c.packed.is_empty() as usize] = true;
            let mut vals: Vec<f32> = vec![
                f32::NAN,
                -f32::NAN,
                f32::INFINITY,
                f32::NEG_INFINITY,
                0.0,
                -0.0,
                -1.0,
                1.0,
                2.0,
                1e-30,
                f32::MIN_POSITIVE,
                f32::MAX,
            ];
            for k in 0..c.thresholds.len() {
                let th = c.thresholds[k];
                vals.extend([
                    th,
                    f32::from_bits(th.to_bits() + 1),
                    f32::from_bits(th.to_bits() - 1),
                ]);
            }
            for _ in 0..20_000 {
                vals.push((next() % 1_000_001) as f32 / 1_000_000.0 * 1.2 - 0.1);
                vals.push(f32::from_bits(next()));
            }
            for chunk in vals.chunks_exact(8) {
                assert!(c.has_vector_codes());
                // SAFETY: the curve has vector codes (asserted above).
                let v = unsafe { c.codes_avx2(avx2, avx2.load_ps(chunk)) };
                let got = avx2.to_epi32(v);
                for (x, g) in chunk.iter().zip(got) {
                    assert_eq!(
                        g as u16,
                        c.code(*x),
                        "{t:?}/{levels}: {x:e} ({:#x})",
                        x.to_bits()
                    );
                    assert_eq!(g as u32, c.code(*x) as u32);
                }
            }
        }
        assert_eq!(packed_seen, [true, true], "both vector paths tested");
    }

    /// A curve so steep at 16 bits that its first threshold is 0 in `f32` has no bucket table: its codes are the
    /// binary search's (every value used to get the largest code), and the vector codes are not offered for it
    /// (their gathers would read an empty table).
    #[test]
    fn a_curve_without_a_bucket_table_codes_by_search() {
        for g in [9.0f32, 10.0] {
            let c = Curve::new(Transfer::Gamma(g), 65536);
            assert_eq!(c.thresholds[0], 0.0, "gamma {g}");
            assert!(!c.has_vector_codes(), "gamma {g}");
            for l in [
                0.0f32,
                1e-30,
                1e-6,
                0.01,
                0.2,
                0.5,
                0.9,
                1.0,
                2.0,
                -1.0,
                f32::NAN,
            ] {
                assert_eq!(c.code(l), c.code_by_search(l), "gamma {g}, {l}");
            }
            assert!(c.code(0.2) < 65535, "gamma {g}");
        }
        assert!(Curve::new(Transfer::Srgb, 65536).has_vector_codes());
        assert!(!Curve::new(Transfer::Linear, 256).has_vector_codes());
    }

    #[test]
    fn srgb_known_values_and_round_trip() {
        let s = Transfer::Srgb;
        assert!((s.to_linear(0.5) - 0.214_041).abs() < 1e-5);
        assert!((s.to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((s.from_linear(0.18) - 0.461_356).abs() < 1e-5);
        for t in [
            Transfer::Srgb,
            Transfer::Gamma(2.2),
            Transfer::Linear,
            Transfer::Gamma(0.8),
        ] {
            for i in 0..=1000 {
                let v = i as f32 / 1000.0;
                assert!((t.from_linear(t.to_linear(v)) - v).abs() < 2e-5, "{t} {v}");
            }
        }
    }

    #[test]
    fn curve_codes_round_trip_exactly_for_8_and_16_bit() {
        for t in [Transfer::Srgb, Transfer::Gamma(2.2), Transfer::Linear] {
            for levels in [256usize, 65536] {
                let c = Curve::new(t, levels);
                let step = if levels == 256 { 1 } else { 97 };
                for code in (0..levels).step_by(step) {
                    assert_eq!(c.code(c.linear(code as u16)) as usize, code, "{t} {levels}");
                }
            }
        }
    }

    #[test]
    fn curve_code_is_the_nearest_stored_value() {
        let c = Curve::new(Transfer::Srgb, 256);
        for i in 0..=2000 {
            let l = i as f32 / 2000.0;
            let expect = (Transfer::Srgb.from_linear(l) * 255.0).round();
            let got = c.code(l) as f32;
            // Ties can fall either way within float error.
            assert!((got - expect).abs() <= 1.0, "{l}: {got} vs {expect}");
            let v = Transfer::Srgb.from_linear(l) * 255.0;
            assert!((got - v).abs() <= 0.5 + 1e-3, "{l}: {got} vs {v}");
        }
        assert_eq!(c.code(-1.0), 0);
        assert_eq!(c.code(2.0), 255);
    }

    #[test]
    fn bucketed_code_equals_binary_search_exactly() {
        for t in [Transfer::Srgb, Transfer::Gamma(2.2), Transfer::Gamma(0.8)] {
            for levels in [256usize, 65536] {
                let c = Curve::new(t, levels);
                let mut probe = vec![-1.0f32, -0.0, 0.0, 1.0, 1.5, f32::NAN, f32::INFINITY, 1e-30];
                // Every threshold and its neighbouring floats: where an off-by-one would show.
                for &th in c
                    .thresholds
                    .iter()
                    .step_by(if levels == 256 { 1 } else { 7 })
                {
                    let b = th.to_bits();
                    probe.extend([f32::from_bits(b - 1), th, f32::from_bits(b + 1)]);
                }
                for i in 0..=20_000 {
                    probe.push(i as f32 / 20_000.0);
                }
                for l in probe {
                    assert_eq!(c.code(l), c.code_by_search(l), "{t} {levels} {l:e}");
                }
            }
        }
    }

    #[test]
    fn parse() {
        assert_eq!("sRGB".parse::<Transfer>().unwrap(), Transfer::Srgb);
        assert_eq!(
            "gamma:2.2".parse::<Transfer>().unwrap(),
            Transfer::Gamma(2.2)
        );
        for bad in ["", "gamma", "gamma:-1", "log"] {
            assert!(bad.parse::<Transfer>().is_err(), "{bad}");
        }
    }
}

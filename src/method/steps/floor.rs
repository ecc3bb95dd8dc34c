//! The floor of `F` (`Steps::relative_floor`, `--relative-floor`): a share of the photo's lit level, with a smooth
//! hand-over ([`soft_floor`]), so that dark corners are not amplified without bound. Applied to `F` at block
//! resolution, so the correction kernel is unchanged.

use crate::method::raster::Raster;
use crate::method::seen::Window;
use crate::method::steps::lit_level::lit_level;

/// `f` floored softly at the step's share of its lit level.
pub(crate) fn apply(w: &Window, f: &mut Raster) {
    soft_floor(f, w.params.steps.relative_floor);
}

/// Smooth floor: `F' = (max(F, 0)⁴ + φ⁴)^¼` with `φ = relative · lit level` per channel. Equal to `F` (within
/// 1 %) from `F ≥ 2.3 φ` up, `φ` for `F ≤ 0`, monotone and smooth in between: no hard edge where the clamp
/// starts (no rings at the edge of narrow beams), and unlit corners get at most a gain of `1/φ`. Returns `φ`.
pub fn soft_floor(f: &mut Raster, relative: f32) -> Vec<f32> {
    // Per channel: the floor follows each channel's own lit level, so the colour of dim regions is not biased
    // (one level for all channels from the brightest one darkened red-starved regions: residual pattern ×7 on
    // the dive matrix, docs/evaluation.md).
    let phi: Vec<f32> = lit_level(f)
        .into_iter()
        .map(|l| (relative * l).max(1e-6))
        .collect();
    let c = f.channels;
    for (i, v) in f.data.iter_mut().enumerate() {
        let p = phi[i % c];
        let x = if v.is_finite() { v.max(0.0) } else { 0.0 };
        // The fourth root as two square roots (correctly rounded each): 4× cheaper than `powf`, within 1 ulp.
        *v = (x.powi(4) + p.powi(4)).sqrt().sqrt();
    }
    phi
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn soft_floor_against_the_formula() {
        // One channel, 21 blocks 0.0, 0.1, …, 2.0: lit level 1.9 (95th percentile), φ = 0.1 · 1.9.
        let mut f = Raster::from_fn(21, 1, 1, |x, _, _| x as f32 * 0.1);
        let orig = f.clone();
        let phi = soft_floor(&mut f, 0.1);
        assert!((phi[0] - 0.19).abs() < 1e-6);
        for (a, b) in orig.data.iter().zip(&f.data) {
            let expect = ((*a as f64).powi(4) + 0.19f64.powi(4)).powf(0.25);
            assert!((*b as f64 - expect).abs() < 1e-5, "{a} -> {b}, {expect}");
            assert!(*b >= *a && *b >= 0.19 - 1e-6);
        }
        // Far above φ the floor changes nothing that matters; negatives and NaN get φ.
        let mut g = Raster {
            width: 3,
            height: 1,
            channels: 1,
            data: vec![-0.5, f32::NAN, 10.0],
        };
        let phi = soft_floor(&mut g, 0.01);
        assert!((g.data[0] - phi[0]).abs() < 1e-6 && (g.data[1] - phi[0]).abs() < 1e-6);
        assert!((g.data[2] - 10.0).abs() < 1e-4);
    }
}

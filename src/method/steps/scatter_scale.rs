//! The scale of `S` (`Steps::backscatter_scale`, `--backscatter-scale`): the water-column `S` scaled per channel for
//! the survey photos, given or estimated per window ([`backscatter_scale`]). Survey rays end at the floor and
//! water-column rays do not, so the water-column `S` over-estimates the survey's backscatter (docs/evaluation.md).

use crate::method::median::quantile;
use crate::method::raster::Raster;
use crate::method::seen::Window;

/// The scale of `S` per channel for the window's `m` (1 without `S`).
pub(crate) fn of(w: &Window, m: &Raster) -> Vec<f32> {
    match (w.params.steps.backscatter_scale, w.s_low) {
        (Some(v), Some(_)) => vec![v; m.channels],
        (None, Some(s)) => backscatter_scale(&w.stack(), m, s),
        _ => vec![1.0; m.channels],
    }
}

/// Scale `k` per channel of the water-column `S` for one window, so that the survey's backscatter is `k·S`.
///
/// Over the window, each block's samples spread around their median `M` because the seafloor under the block
/// changes from photo to photo; that spread is proportional to the light the floor gets, `F·C = M − k·S` (the
/// same albedo variation, lit more or less). So the mean absolute deviation `D` of the window's block medians
/// from `M` is fitted as `D = a·M + b·S + e` over all blocks (robustly: Huber weights, 6 rounds of reweighted
/// least squares; `e` takes the noise floor), and `k = −b/a`. A channel where the fit is degenerate or unsure (`a ≤
/// 0`, fewer than 30 blocks, or a standard error of `k` above [`SCALE_MAX_SE`]) keeps `k = 1`; `k` is clamped to
/// `[0.2, 1]` (survey rays end at the floor, so they cannot gather more backscatter than open water).
pub fn backscatter_scale(stack: &[&Raster], m: &Raster, s: &Raster) -> Vec<f32> {
    let c = m.channels;
    assert_eq!(
        m.layout(),
        s.layout(),
        "window and backscatter differ in size"
    );
    if stack.len() < 3 {
        return vec![1.0; c];
    }
    (0..c)
        .map(|ch| {
            let mut rows: Vec<[f64; 4]> = Vec::with_capacity(m.data.len() / c);
            for i in (ch..m.data.len()).step_by(c) {
                let (mv, sv) = (m.data[i] as f64, s.data[i] as f64);
                let d = stack
                    .iter()
                    .map(|r| (r.data[i] as f64 - mv).abs())
                    .sum::<f64>()
                    / stack.len() as f64;
                if mv.is_finite() && sv.is_finite() && d.is_finite() {
                    rows.push([mv, sv, 1.0, d]);
                }
            }
            scale_from_rows(&rows).unwrap_or(1.0)
        })
        .collect()
}

/// Largest standard error of `k` at which [`backscatter_scale`] trusts its fit.
pub const SCALE_MAX_SE: f64 = 0.03;

/// The robust fit of [`backscatter_scale`] for one channel: rows `[M, S, 1, D]`. `None` when the fit is degenerate
/// or not sure enough: `a ≤ 0`, or a standard error of `k` (delta method, from the weighted least squares'
/// covariance) above [`SCALE_MAX_SE`] — as when `S` is nearly flat across the frame or shaped like `M`, so that
/// its share of `D` cannot be told apart.
fn scale_from_rows(rows: &[[f64; 4]]) -> Option<f32> {
    if rows.len() < 30 {
        return None;
    }
    let mut w = vec![1.0f64; rows.len()];
    let mut beta = [0.0f64; 3];
    let mut normal = [[0.0f64; 3]; 3];
    for _ in 0..6 {
        let mut a = [[0.0f64; 3]; 3];
        let mut y = [0.0f64; 3];
        for (r, &wi) in rows.iter().zip(&w) {
            for p in 0..3 {
                y[p] += wi * r[p] * r[3];
                for q in 0..3 {
                    a[p][q] += wi * r[p] * r[q];
                }
            }
        }
        beta = solve3(a, y)?;
        normal = a;
        let mut res: Vec<f32> = rows
            .iter()
            .map(|r| (r[3] - beta[0] * r[0] - beta[1] * r[1] - beta[2]).abs() as f32)
            .collect();
        let scale = 1.4826 * quantile(&mut res, 0.5) as f64;
        if scale.is_nan() || scale <= 0.0 {
            break;
        }
        let kh = 1.345 * scale;
        for (r, wi) in rows.iter().zip(&mut w) {
            let e = (r[3] - beta[0] * r[0] - beta[1] * r[1] - beta[2]).abs();
            *wi = if e <= kh { 1.0 } else { kh / e };
        }
    }
    if beta[0].is_nan() || beta[0] <= 0.0 {
        return None;
    }
    // Covariance of (a, b): σ²·(XᵀWX)⁻¹, σ² the weighted residual variance.
    let (mut sw, mut sr) = (0.0f64, 0.0f64);
    for (r, &wi) in rows.iter().zip(&w) {
        let e = r[3] - beta[0] * r[0] - beta[1] * r[1] - beta[2];
        sw += wi;
        sr += wi * e * e;
    }
    let sigma2 = sr / (sw - 3.0).max(1.0);
    let col = |j: usize| {
        let mut e = [0.0f64; 3];
        e[j] = 1.0;
        solve3(normal, e)
    };
    let (c0, c1) = (col(0)?, col(1)?);
    let (vaa, vbb, vab) = (sigma2 * c0[0], sigma2 * c1[1], sigma2 * c0[1]);
    let (a, b) = (beta[0], beta[1]);
    let k = -b / a;
    // k = −b/a: gradient (b/a², −1/a).
    let (ga, gb) = (b / (a * a), -1.0 / a);
    let var_k = ga * ga * vaa + gb * gb * vbb + 2.0 * ga * gb * vab;
    (k.is_finite() && var_k.is_finite() && var_k.max(0.0).sqrt() <= SCALE_MAX_SE)
        .then(|| k.clamp(0.2, 1.0) as f32)
}

#[allow(clippy::needless_range_loop)] // the textbook index form reads best here
/// Solve the 3×3 system `a·x = y` (Gaussian elimination with partial pivoting); `None` when it is singular (a pivot
/// below `1e-12` of the largest diagonal entry).
fn solve3(mut a: [[f64; 3]; 3], mut y: [f64; 3]) -> Option<[f64; 3]> {
    let big = a[0][0].abs().max(a[1][1].abs()).max(a[2][2].abs());
    for col in 0..3 {
        let piv = (col..3).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        a.swap(col, piv);
        y.swap(col, piv);
        let pivot = a[col][col].abs();
        if pivot.is_nan() || pivot <= 1e-12 * big {
            return None;
        }
        for r in col + 1..3 {
            let f = a[r][col] / a[col][col];
            for q in col..3 {
                a[r][q] -= f * a[col][q];
            }
            y[r] -= f * y[col];
        }
    }
    let mut x = [0.0f64; 3];
    for r in (0..3).rev() {
        let mut v = y[r];
        for q in r + 1..3 {
            v -= a[r][q] * x[q];
        }
        x[r] = v / a[r][r];
    }
    Some(x)
}

/// `S` scaled per channel by `k`.
pub fn scaled(s: &Raster, k: &[f32]) -> Raster {
    let c = s.channels;
    let mut out = s.clone();
    for (i, v) in out.data.iter_mut().enumerate() {
        *v *= k[i % c];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solve3_against_a_known_solution() {
        let a = [[4.0, 1.0, 2.0], [1.0, 5.0, 3.0], [2.0, 3.0, 6.0]];
        let x = [0.5, -1.25, 2.0];
        let y = [0, 1, 2].map(|r| (0..3).map(|q| a[r][q] * x[q]).sum::<f64>());
        let got = solve3(a, y).unwrap();
        for i in 0..3 {
            assert!((got[i] - x[i]).abs() < 1e-12, "{got:?}");
        }
        // Needs pivoting (zero first pivot), and a singular system is refused.
        let b = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]];
        assert_eq!(solve3(b, [3.0, 4.0, 2.0]).unwrap(), [4.0, 3.0, 1.0]);
        assert!(solve3(
            [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]],
            [1.0; 3]
        )
        .is_none());
    }

    #[test]
    fn backscatter_scale_recovers_a_known_scale() {
        // A window of photos I_j = A_j·F + k·S with a light F and a backscatter S shaped differently across the
        // frame, the albedo changing from photo to photo (a few nodules per block position) and noise 0 — the fit
        // must give k back; with no spread at all (identical photos) it must say 1 (nothing to fit).
        let (w, h) = (40, 30);
        let f = Raster::from_fn(w, h, 1, |x, y, _| {
            let (dx, dy) = (x as f32 / w as f32 - 0.5, y as f32 / h as f32 - 0.3);
            (-(dx * dx + dy * dy) * 6.0).exp()
        });
        let s = Raster::from_fn(w, h, 1, |x, y, _| {
            0.05 + 0.1 * (x as f32 / w as f32) + 0.04 * (y as f32 / h as f32)
        });
        for k in [0.6f32, 0.85, 1.0] {
            let photos: Vec<Raster> = (0..9)
                .map(|j| {
                    Raster::from_fn(w, h, 1, |x, y, _| {
                        let a = if (x * 3 + y * 7 + j * 5) % 9 < 2 {
                            0.1
                        } else {
                            0.4 + 0.02 * (j % 3) as f32
                        };
                        a * f.get(x, y, 0) + k * s.get(x, y, 0)
                    })
                })
                .collect();
            let stack: Vec<&Raster> = photos.iter().collect();
            let m = crate::method::median::stack_median(&stack);
            let got = backscatter_scale(&stack, &m, &s)[0];
            assert!((got - k).abs() < 0.03, "k {k}: got {got}");
        }
        let same = vec![Raster::filled(w, h, 1, 0.3); 5];
        let stack: Vec<&Raster> = same.iter().collect();
        assert_eq!(backscatter_scale(&stack, &same[0], &s), vec![1.0]);
    }
}

//! Baseline corrections for comparison (`correct --method mean|polynomial`). Both produce a stand-in for `M`, the
//! lit seafloor plus backscatter, so the rest of the pipeline (`F = (M − S)/C`, `A = (I − S)/F`) is shared:
//!
//! - `mean` (Pizarro & Singh): `M` is the mission's mean image (each photo reduced to `K`×`K` block means in linear
//!   light, averaged over every photo of the mission). Rescaled to the seafloor colour by `F = (M − S)/C`.
//! - `polynomial` (Singh et al. 2007): per photo, a 2-D polynomial of degree `d` (default 4) in the normalised image
//!   coordinates is fitted to `log(I − S)` per channel on the photo's block-median image, robustly (Tukey biweight,
//!   iteratively reweighted least squares started from a least-absolute-deviations fit), and `M = exp(fit) + S`.

use std::fmt;
use std::str::FromStr;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::method::median::blocks;
use crate::method::raster::Raster;

/// How the lighting is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum Method {
    /// The default: the paper's sliding-window `F`, then per photo a robust gain against its window, a floor
    /// relative to the photo's lit level with a smooth hand-over, and `S` scaled by a factor estimated from the
    /// mission (the steps of `chain::abyss`, one file each in `method/steps/`).
    #[default]
    Abyss,
    /// Köser et al. as published: temporal median over a sliding window of block medians, `F = (M − S)/C`,
    /// `A = (I − S)/max(F, factor_floor)` with the absolute `--factor-floor` (default 0.05).
    Paper,
    /// Divide by the mission's mean image (Pizarro & Singh).
    Mean,
    /// Per-photo robust polynomial fit of log intensity (Singh et al. 2007).
    Polynomial,
}

impl FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "abyss" => Ok(Method::Abyss),
            "paper" => Ok(Method::Paper),
            "mean" => Ok(Method::Mean),
            "polynomial" | "poly" => Ok(Method::Polynomial),
            _ => Err(format!(
                "invalid method {s:?}: expected abyss, paper, mean or polynomial"
            )),
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Method::Abyss => "abyss",
            Method::Paper => "paper",
            Method::Mean => "mean",
            Method::Polynomial => "polynomial",
        })
    }
}

impl TryFrom<String> for Method {
    type Error = String;
    fn try_from(s: String) -> std::result::Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<Method> for String {
    fn from(m: Method) -> String {
        m.to_string()
    }
}

/// `K`×`K` block means of a raster (partial blocks at the border included).
pub fn block_mean(r: &Raster, k: usize) -> Raster {
    let (bw, bh, c) = (blocks(r.width, k), blocks(r.height, k), r.channels);
    let mut out = Raster::filled(bw, bh, c, 0.0);
    let mut counts = vec![0u32; bw * bh];
    for y in 0..r.height {
        for x in 0..r.width {
            let b = (y / k) * bw + x / k;
            counts[b] += 1;
            for ch in 0..c {
                out.data[b * c + ch] += r.data[(y * r.width + x) * c + ch];
            }
        }
    }
    for (b, n) in counts.iter().enumerate() {
        for ch in 0..c {
            out.data[b * c + ch] /= (*n).max(1) as f32;
        }
    }
    out
}

/// Exponents `(i, j)` of the monomials `x^i·y^j` with `i + j ≤ degree`.
fn monomials(degree: usize) -> Vec<(i32, i32)> {
    (0..=degree as i32)
        .flat_map(|t| (0..=t).map(move |i| (i, t - i)))
        .collect()
}

/// Solve `A·x = b` (dense, `n`×`n`, row-major) by Gaussian elimination with partial pivoting.
fn solve(mut a: Vec<f64>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for col in 0..n {
        let piv =
            (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs()))?;
        if a[piv * n + col].abs() < 1e-12 {
            return None;
        }
        if piv != col {
            for k in 0..n {
                a.swap(piv * n + k, col * n + k);
            }
            b.swap(piv, col);
        }
        for r in col + 1..n {
            let f = a[r * n + col] / a[col * n + col];
            if f != 0.0 {
                for k in col..n {
                    a[r * n + k] -= f * a[col * n + k];
                }
                b[r] -= f * b[col];
            }
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r * n + k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r * n + r];
    }
    Some(x)
}

/// Robust fit of a 2-D polynomial of `degree` to `values` at points `(x, y)` (normalised to `[-1, 1]`); returns
/// the fitted values at the same points. Least absolute deviations (IRLS), then Tukey biweight IRLS with the scale
/// from the MAD of the residuals.
pub fn robust_poly_fit(points: &[(f64, f64)], values: &[f64], degree: usize) -> Vec<f64> {
    let terms = monomials(degree);
    let basis: Vec<Vec<f64>> = points
        .iter()
        .map(|&(x, y)| terms.iter().map(|&(i, j)| x.powi(i) * y.powi(j)).collect())
        .collect();
    let m = terms.len();
    let mut w = vec![1.0f64; values.len()];
    let mut fit = vec![0.0f64; values.len()];
    // Least absolute deviations first (IRLS with weights 1/|r|), which a large share of one-sided outliers
    // cannot drag far, then Tukey's biweight with the scale from the MAD of the residuals.
    const L1_ROUNDS: usize = 8;
    for round in 0..L1_ROUNDS + 8 {
        let mut ata = vec![0.0f64; m * m];
        let mut atb = vec![0.0f64; m];
        for ((row, &v), &wi) in basis.iter().zip(values).zip(&w) {
            if wi == 0.0 {
                continue;
            }
            for a in 0..m {
                atb[a] += wi * row[a] * v;
                for b in 0..m {
                    ata[a * m + b] += wi * row[a] * row[b];
                }
            }
        }
        for a in 0..m {
            ata[a * m + a] += 1e-9;
        }
        let Some(coef) = solve(ata, atb) else { break };
        for (f, row) in fit.iter_mut().zip(&basis) {
            *f = row.iter().zip(&coef).map(|(a, b)| a * b).sum();
        }
        let res: Vec<f64> = values
            .iter()
            .zip(&fit)
            .map(|(v, f)| (v - f).abs())
            .collect();
        let mut sorted = res.clone();
        sorted.sort_by(f64::total_cmp);
        let mad = 1.4826 * sorted[sorted.len() / 2];
        if round + 1 < L1_ROUNDS {
            let eps = 1e-3 * mad.max(1e-9);
            for (wi, r) in w.iter_mut().zip(&res) {
                *wi = 1.0 / r.max(eps);
            }
        } else {
            let cutoff = 4.685 * mad.max(1e-6);
            for (wi, r) in w.iter_mut().zip(&res) {
                let u = *r / cutoff;
                *wi = if u < 1.0 { (1.0 - u * u).powi(2) } else { 0.0 };
            }
        }
    }
    fit
}

/// `M` for the polynomial method from a photo's block-resolution image `low` (linear light) and the backscatter
/// at the same resolution: per channel, `exp(robust polynomial fit of log(low − S)) + S`.
pub fn polynomial_m(low: &Raster, s_low: Option<&Raster>, degree: usize) -> Raster {
    let (w, h, c) = (low.width, low.height, low.channels);
    let points: Vec<(f64, f64)> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            (
                2.0 * (x as f64 + 0.5) / w.max(1) as f64 - 1.0,
                2.0 * (y as f64 + 0.5) / h.max(1) as f64 - 1.0,
            )
        })
        .collect();
    let mut out = low.clone();
    let fits: Vec<Vec<f64>> = (0..c)
        .into_par_iter()
        .map(|ch| {
            let vals: Vec<f64> = (0..w * h)
                .map(|p| {
                    let s = s_low.map_or(0.0, |s| s.data[p * c + ch]);
                    ((low.data[p * c + ch] - s) as f64).max(1e-4).ln()
                })
                .collect();
            robust_poly_fit(&points, &vals, degree)
        })
        .collect();
    for (ch, fit) in fits.iter().enumerate() {
        for (p, f) in fit.iter().enumerate() {
            let s = s_low.map_or(0.0, |s| s.data[p * c + ch]);
            out.data[p * c + ch] = f.exp() as f32 + s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polynomial_fit_recovers_a_polynomial_despite_outliers() {
        let pts: Vec<(f64, f64)> = (0..400)
            .map(|i| ((i % 20) as f64 / 9.5 - 1.0, (i / 20) as f64 / 9.5 - 1.0))
            .collect();
        let truth: Vec<f64> = pts
            .iter()
            .map(|&(x, y)| 0.3 - 0.5 * x + 0.2 * y * y - 0.4 * x * x * y + 0.1 * x.powi(4))
            .collect();
        let mut noisy = truth.clone();
        for (i, v) in noisy.iter_mut().enumerate() {
            if i % 5 == 0 {
                *v -= 2.0; // 20 % dark outliers
            }
        }
        let fit = robust_poly_fit(&pts, &noisy, 4);
        for (f, t) in fit.iter().zip(&truth) {
            assert!((f - t).abs() < 1e-6, "{f} vs {t}");
        }
    }

    #[test]
    fn block_mean_by_hand() {
        let r = Raster::from_fn(3, 2, 1, |x, y, _| (x + 3 * y) as f32);
        // Blocks of 2: [0,1,3,4] -> 2, [2,5] -> 3.5.
        let m = block_mean(&r, 2);
        assert_eq!((m.width, m.height), (2, 1));
        assert_eq!(m.data, vec![2.0, 3.5]);
    }

    #[test]
    fn method_names() {
        for m in [Method::Paper, Method::Mean, Method::Polynomial] {
            assert_eq!(m.to_string().parse::<Method>().unwrap(), m);
        }
        assert!("median".parse::<Method>().is_err());
    }
}

//! The per-photo refinements of `--method abyss` (the default), on top of the paper's sliding-window `F`:
//!
//! - [`photo_gain`]: one robust gain per photo and channel, fitted on the photo's own seafloor against its
//!   window's `M` — absorbs altitude bounce and exposure jumps that the window's median averages away;
//! - [`soft_floor`]: a floor relative to the photo's lit level (a high percentile of `F` per channel) with a smooth
//!   hand-over instead of a hard clamp, applied to `F` at block resolution (so the correction kernel is unchanged);
//! - [`backscatter_scale`]: a scale on the water-column `S`, estimated from each photo's window (survey rays end
//!   at the floor, water-column rays do not, so the water-column `S` over-estimates the survey's backscatter; see
//!   docs/evaluation.md);
//! - [`near_shape`]: the window's `M` bent to the smooth shape of a shorter window's `M` around the photo
//!   ([`crate::method::window::near_window`]), so `F` follows the lights' footprint as the vehicle's altitude and
//!   roll change, while the full window still sets the detail.
//!
//! All work on block-resolution rasters in linear light.

use crate::method::raster::Raster;

/// Percentile of `F` (per channel, over blocks) taken as the photo's lit level.
pub const LIT_PERCENTILE: f64 = 0.95;

/// The value at quantile `q` (0..=1, nearest rank) of `v` (reordered in place, by selection: linear time); NaN
/// for an empty slice.
pub fn quantile(v: &mut [f32], q: f64) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    *v.select_nth_unstable_by(i, f32::total_cmp).1
}

/// Lit level of each channel of `f`: its [`LIT_PERCENTILE`] over the finite samples.
pub fn lit_level(f: &Raster) -> Vec<f32> {
    lit_level_every(&f.data, f.channels, 1)
}

/// [`lit_level`] of interleaved `data` with `c` channels, taken on every `stride`-th block.
fn lit_level_every(data: &[f32], c: usize, stride: usize) -> Vec<f32> {
    (0..c)
        .map(|ch| {
            let mut v: Vec<f32> = (ch..data.len())
                .step_by(c * stride)
                .map(|i| data[i])
                .filter(|x| x.is_finite())
                .collect();
            quantile(&mut v, LIT_PERCENTILE)
        })
        .collect()
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

/// One robust gain per channel of a photo against its window: the `q` quantile over the photo's lit blocks of
/// `(own − S) / (M − S)`, where lit means `M − S` at least `min_lit` of the channel's lit level. With `q = 0.5`
/// (the median) blocks of the photo that are not seafloor (nodules, objects) are outvoted as long as they are
/// fewer than half; the window's own quantile `(1 + c)/2` ([`Params::window_quantile`]) takes the seafloor's
/// median under a share `c` of dark blocks, as the window's `M` does (with the median and `M` at that quantile, a
/// dense nodule field's gain followed each photo's own nodule cover: photos with more nodules came out brighter,
/// and overlapping photos disagreed — docs/nodules.md).
/// Gains are clamped to `[0.25, 4]`; a channel with fewer than 8 lit blocks keeps gain 1.
pub fn photo_gain(own: &Raster, m: &Raster, s: Option<&Raster>, min_lit: f32, q: f64) -> Vec<f32> {
    Against::new(m, s, 1).gain(own, min_lit, q, 1)
}

/// A window's `M − S` and its lit level per channel, for the gains of many photos against it.
struct Against<'a> {
    m: &'a Raster,
    s: Option<&'a Raster>,
    lit: Vec<f32>,
    level: Vec<f32>,
}

impl<'a> Against<'a> {
    /// The window `m` over `s`, its lit level ([`lit_level`]) taken on every `stride`-th block.
    fn new(m: &'a Raster, s: Option<&'a Raster>, stride: usize) -> Self {
        let lit: Vec<f32> = m
            .data
            .iter()
            .enumerate()
            .map(|(i, &v)| v - s.map_or(0.0, |s| s.data[i]))
            .collect();
        let level = lit_level_every(&lit, m.channels, stride);
        Against { m, s, lit, level }
    }

    /// [`photo_gain`] of `own` against this window, on every `stride`-th block.
    fn gain(&self, own: &Raster, min_lit: f32, q: f64, stride: usize) -> Vec<f32> {
        assert_eq!(
            own.layout(),
            self.m.layout(),
            "photo and window differ in size"
        );
        let c = own.channels;
        let sv = |i: usize| self.s.map_or(0.0, |s| s.data[i]);
        (0..c)
            .map(|ch| {
                let mut r: Vec<f32> = (ch..own.data.len())
                    .step_by(c * stride)
                    .filter(|&i| self.lit[i] >= min_lit * self.level[ch] && self.lit[i] > 0.0)
                    .map(|i| (own.data[i] - sv(i)) / self.lit[i])
                    .filter(|x| x.is_finite())
                    .collect();
                if r.len() < 8 {
                    1.0
                } else {
                    quantile(&mut r, q).clamp(0.25, 4.0)
                }
            })
            .collect()
    }
}

/// The share of a channel's lit level below which a block of `M − S` does not count in the per-photo gain (nor in
/// the levelling's gains, which are the same estimator).
pub const GAIN_MIN_LIT: f32 = 0.3;

/// A photo whose gain departs more than this share from the median of its own and its two neighbours' in every
/// channel is an exposure jump; a window with one is levelled ([`levelled_stack`]).
pub const EXPOSURE_JUMP: f32 = 0.1;

/// Blocks per channel that [`levelled_stack`]'s gains are taken on, at most (every `k`-th block of larger block
/// images: a 12 MP photo's 187 500 blocks give the same median within a thousandth at a tenth of the work).
pub const LEVEL_SAMPLES: usize = 16_384;

/// Windows shorter than this are not levelled ([`levelled_stack`]): four of a window of 5's photos are judged
/// against the three photos at one of its ends, where an altitude swing that turns looks like a jump (the dive
/// matrix's a01, a window of 5: residual pattern +3.2 % from levelling). The paper's window, and the shortest the
/// survey chooses, is 7; shorter ones come from a `--window` or a low `--contamination` given.
pub const LEVEL_MIN_WINDOW: usize = 7;

/// The longest window whose first and last photos are judged for a jump ([`levelled_stack`]). An end photo is
/// judged against the two photos on its one side, where an altitude swing that turns looks like a jump: in the
/// longer windows of the dive matrix every jump found was at an end (a10's windows of 19, h08's of 30, the whole
/// mission), and levelling them raised their residual pattern by 4.6 % and 7.9 %; there one end photo of so many does not
/// set the median's order, and inner jumps still count. Up to this length the ends stay judged: on the slow
/// sledge of Nephrops run 1627 (windows of 7–11) a quarter of the windows levelled jump at an end alone, and left
/// unlevelled they brought the burrow ghosts back.
pub const EDGE_JUMP_MAX_WINDOW: usize = 11;

/// Blocks per channel of [`levelled_stack`]'s first look for an exposure jump, at most.
pub const GLANCE_SAMPLES: usize = 1_024;

/// The window's photos levelled to one exposure before its `M` is taken, where the exposure jumps along the
/// window: each photo's `own − S` divided by its [`photo_gain`] against `m` (the window's `M` as first taken, at
/// quantile `q`), per channel, on at most [`LEVEL_SAMPLES`] blocks. `None` when no photo of the window (in mission
/// order; not its first and last of more than [`EDGE_JUMP_MAX_WINDOW`]) is an exposure jump ([`EXPOSURE_JUMP`] in
/// every channel against its neighbours): a smooth drift
/// (altitude) is left to the window as before, and so is noise in one starved channel. A first look on at most
/// [`GLANCE_SAMPLES`] blocks spares the windows without a jump the full gains.
///
/// The window's samples at a block are only exchangeable when the photos share one exposure. Where the exposure
/// jumps from photo to photo (a sledge that lifts and drops, an automatic exposure), the photos' levels differ by
/// more than the seafloor's texture, so at most blocks the median is the same photo — the one whose level is the
/// middle one — and `M` (and `F`) takes that photo's burrows and nodules whole: the ghosts of a slow sledge.
pub fn levelled_stack(
    stack: &[&Raster],
    m: &Raster,
    s: Option<&Raster>,
    q: f64,
) -> Option<Vec<Raster>> {
    let blocks = m.width * m.height;
    let stride = blocks.div_ceil(LEVEL_SAMPLES).max(1);
    let against = Against::new(m, s, stride);
    // A long window's end photos are not judged ([`EDGE_JUMP_MAX_WINDOW`]).
    let n = stack.len();
    let judged = |j: usize| n <= EDGE_JUMP_MAX_WINDOW || (j > 0 && j + 1 < n);
    let jumped = |gains: &[Vec<f32>], by: f32| {
        jumps(gains)
            .iter()
            .enumerate()
            .any(|(k, g)| judged(k) && g.iter().all(|j| (j - 1.0).abs() > by))
    };
    // Most windows have no jump: a first look on a few blocks (gains within a few thousandths of the full ones)
    // with half the threshold spares them the full gains.
    let glance = blocks.div_ceil(GLANCE_SAMPLES).max(stride);
    let rough: Vec<Vec<f32>> = stack
        .iter()
        .map(|p| against.gain(p, GAIN_MIN_LIT, q, glance))
        .collect();
    if !jumped(&rough, EXPOSURE_JUMP / 2.0) {
        return None;
    }
    let gains: Vec<Vec<f32>> = stack
        .iter()
        .map(|p| against.gain(p, GAIN_MIN_LIT, q, stride))
        .collect();
    if !jumped(&gains, EXPOSURE_JUMP) {
        return None;
    }
    let levelled = stack
        .iter()
        .zip(&gains)
        .map(|(p, g)| {
            let c = p.channels;
            let mut out = (*p).clone();
            for (i, v) in out.data.iter_mut().enumerate() {
                let sv = s.map_or(0.0, |s| s.data[i]);
                *v = sv + (*v - sv) / g[i % c];
            }
            out
        })
        .collect();
    Some(levelled)
}

/// The jumps of a sequence of gains (photos in mission order, per channel): each gain over the median of it and its
/// two neighbours (at the ends: of the three nearest). A smooth drift (altitude) gives jumps of 1; a photo whose
/// exposure jumps away from its neighbours keeps its jump.
fn jumps(gains: &[Vec<f32>]) -> Vec<Vec<f32>> {
    let n = gains.len();
    if n < 3 {
        return gains.to_vec();
    }
    (0..n)
        .map(|j| {
            let from = j.saturating_sub(1).min(n - 3);
            gains[j]
                .iter()
                .enumerate()
                .map(|(ch, &g)| {
                    let mut three = [gains[from][ch], gains[from + 1][ch], gains[from + 2][ch]];
                    three.sort_by(f32::total_cmp);
                    g / three[1]
                })
                .collect()
        })
        .collect()
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

/// Multiply each channel of `f` by its gain.
pub fn apply_gain(f: &mut Raster, gain: &[f32]) {
    let c = f.channels;
    for (i, v) in f.data.iter_mut().enumerate() {
        *v *= gain[i % c];
    }
}

/// Radius of [`near_shape`]'s squares, as a share of the longer side (in blocks): 1/8 of the frame (1/4 and
/// 1/16 measured alike on the dive matrix with a mean over the square).
pub const NEAR_SHAPE_RADIUS: f64 = 0.125;

/// Smallest `M − S` (linear light, both windows) whose ratio [`near_shape`] uses: a third of the step of an 8-bit
/// sRGB camera's first code. Blocks at or below it (backscatter-dominated corners) carry no ratio worth taking:
/// measured with a mean over the square, with any positive value admitted the matrix's pattern medians came out
/// 2–3 % higher than with this threshold
/// (a11 1.42× instead of 1.13× the pattern without the near window), and 10 % of the lit level (0.1 × its 95th
/// percentile) left a12's dim rim unfollowed (0.70× → 0.80× the paper's).
pub const NEAR_MIN_LIT: f32 = 1e-4;

/// `M` of the window bent to the smooth shape of `near`, the `M` of a shorter window around the same photo:
/// `S + (M − S)·exp(g)` per channel, where `g` is the smooth log ratio `log((near − S) / (M − S))`: its median over a
/// square of `2r + 1` blocks (cut at the edges; `r` = [`NEAR_SHAPE_RADIUS`] of the longer side) at grid nodes `r`
/// blocks apart (and on the last row and column), interpolated bilinearly between them; only blocks where both are
/// above [`NEAR_MIN_LIT`] vote. What is kept changes smoothly across the frame — the lights' footprint, which moves
/// with the vehicle's altitude and roll; the near window's noise and its local breakdowns (it has fewer photos to
/// outvote a nodule or a rock) are outvoted by the median (a mean over the square let the large dark blobs of a
/// test dive without `--contamination` through: albedo error 0.104 → 0.133). Where no node nearby has a vote, `M`
/// is kept.
pub fn near_shape(m: &Raster, near: &Raster, s: Option<&Raster>) -> Raster {
    assert_eq!(
        m.layout(),
        near.layout(),
        "window and near window differ in size"
    );
    let (w, h, c) = (m.width, m.height, m.channels);
    let r = near_radius(w, h);
    let sv = |i: usize| s.map_or(0.0, |s| s.data[i]);
    let (gx, gy) = (near_nodes(w, r), near_nodes(h, r));
    let mut out = m.clone();
    for ch in 0..c {
        // Each block's ratio once (NaN: no vote; a ratio taken is positive and finite): a block votes in the
        // squares of up to four nodes.
        let ratios: Vec<f32> = (0..w * h)
            .map(|b| {
                let i = b * c + ch;
                let (a, b) = (m.data[i] - sv(i), near.data[i] - sv(i));
                match a > NEAR_MIN_LIT && b > NEAR_MIN_LIT && (b / a).is_finite() {
                    true => b / a,
                    false => f32::NAN,
                }
            })
            .collect();
        // The median log ratio around each node (NaN without votes): the log of the median ratio, since the median
        // picks one of the votes and the logarithm keeps their order (one logarithm per node, not per vote).
        let mut node = node_medians_grid(&gx, &gy, r, (w, h), &ratios);
        for v in &mut node {
            *v = v.ln();
        }
        for y in 0..h {
            for x in 0..w {
                if let Some(g) = between_nodes(|j, k| node[j * gx.len() + k], &gx, &gy, x, y) {
                    let i = (y * w + x) * c + ch;
                    out.data[i] = sv(i) + (m.data[i] - sv(i)) * g.exp();
                }
            }
        }
    }
    out
}

/// [`near_shape`]'s radius in blocks for a `w`×`h`-block raster.
fn near_radius(w: usize, h: usize) -> usize {
    ((w.max(h) as f64 * NEAR_SHAPE_RADIUS).round() as usize).max(1)
}

/// Grid nodes along a side of `len` blocks: every `r`, and the last block.
pub(crate) fn near_nodes(len: usize, r: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..len).step_by(r).collect();
    if v.last() != Some(&(len - 1)) {
        v.push(len - 1);
    }
    v
}

/// The median of `value(x, y)` over the `(2r + 1)`² square (cut at the edges of the `w`×`h` blocks) around each
/// grid node `(gx[k], gy[j])`, at `j · gx.len() + k`; `None` values do not vote, NaN where none does.
pub(crate) fn node_medians(
    gx: &[usize],
    gy: &[usize],
    r: usize,
    (w, h): (usize, usize),
    value: impl Fn(usize, usize) -> Option<f32>,
) -> Vec<f32> {
    let mut node = vec![f32::NAN; gx.len() * gy.len()];
    let mut votes = Vec::with_capacity((2 * r + 1) * (2 * r + 1));
    for (j, &ny) in gy.iter().enumerate() {
        for (k, &nx) in gx.iter().enumerate() {
            votes.clear();
            for y in ny.saturating_sub(r)..(ny + r + 1).min(h) {
                for x in nx.saturating_sub(r)..(nx + r + 1).min(w) {
                    votes.extend(value(x, y));
                }
            }
            node[j * gx.len() + k] = quantile(&mut votes, 0.5);
        }
    }
    node
}

/// [`node_medians`] of the values of a `w`×`h` grid, NaN where a block does not vote: the same votes in the same
/// order, taken a row of the square at a time.
pub(crate) fn node_medians_grid(
    gx: &[usize],
    gy: &[usize],
    r: usize,
    (w, h): (usize, usize),
    grid: &[f32],
) -> Vec<f32> {
    assert_eq!(grid.len(), w * h, "grid of another size");
    let mut node = vec![f32::NAN; gx.len() * gy.len()];
    let mut votes = Vec::with_capacity((2 * r + 1) * (2 * r + 1));
    for (j, &ny) in gy.iter().enumerate() {
        for (k, &nx) in gx.iter().enumerate() {
            votes.clear();
            let (x0, x1) = (nx.saturating_sub(r), (nx + r + 1).min(w));
            for y in ny.saturating_sub(r)..(ny + r + 1).min(h) {
                let row = &grid[y * w + x0..y * w + x1];
                votes.extend(row.iter().copied().filter(|v| !v.is_nan()));
            }
            node[j * gx.len() + k] = quantile(&mut votes, 0.5);
        }
    }
    node
}

/// The value at block `(x, y)` interpolated bilinearly between the values `at(j, k)` of the grid nodes
/// `(gx[k], gy[j])` around it; NaN nodes are left out (their weight with them); `None` when all four are NaN.
pub(crate) fn between_nodes(
    at: impl Fn(usize, usize) -> f32,
    gx: &[usize],
    gy: &[usize],
    x: usize,
    y: usize,
) -> Option<f32> {
    let (j, ty) = between(gy, y);
    let (k, tx) = between(gx, x);
    let (j1, k1) = ((j + 1).min(gy.len() - 1), (k + 1).min(gx.len() - 1));
    let corners = [
        (at(j, k), (1.0 - tx) * (1.0 - ty)),
        (at(j, k1), tx * (1.0 - ty)),
        (at(j1, k), (1.0 - tx) * ty),
        (at(j1, k1), tx * ty),
    ];
    let (mut sum, mut weight) = (0.0f32, 0.0f32);
    for (v, wt) in corners {
        if v.is_finite() && wt > 0.0 {
            sum += v * wt;
            weight += wt;
        }
    }
    (weight > 0.0).then(|| sum / weight)
}

/// The node at or before `p` and the share of the way to the next one.
fn between(nodes: &[usize], p: usize) -> (usize, f32) {
    let j = nodes.partition_point(|&n| n <= p).saturating_sub(1);
    match nodes.get(j + 1) {
        Some(&next) => (j, (p - nodes[j]) as f32 / (next - nodes[j]) as f32),
        None => (j, 0.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid's node medians are the closure's, bit for bit: the same votes in the same order (squares cut at
    /// every edge, blocks without a vote, ties, a node without any vote).
    #[test]
    fn node_medians_of_a_grid_are_the_closures() {
        for (w, h, r) in [(37, 23, 5), (9, 30, 4), (1, 1, 1), (16, 16, 16)] {
            let grid: Vec<f32> = (0..w * h)
                .map(|i| match (i * 7919) % 13 {
                    0 | 1 => f32::NAN,
                    k => (k % 5) as f32 * 0.25 + (i % 3) as f32,
                })
                .collect();
            let (gx, gy) = (near_nodes(w, r), near_nodes(h, r));
            let want = node_medians(&gx, &gy, r, (w, h), |x, y| {
                Some(grid[y * w + x]).filter(|v| !v.is_nan())
            });
            let got = node_medians_grid(&gx, &gy, r, (w, h), &grid);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "{w}x{h}, r {r}");
        }
        let none = node_medians_grid(&[0], &[0], 1, (2, 1), &[f32::NAN, f32::NAN]);
        assert!(none[0].is_nan());
    }

    /// [`near_shape`] against a direct computation: the median log ratio over each node's square by sorting, then
    /// bilinear interpolation between the nodes.
    #[test]
    fn near_shape_against_a_direct_median_and_interpolation() {
        let (w, h, c) = (37, 23, 2);
        let m = Raster::from_fn(w, h, c, |x, y, ch| {
            0.2 + 0.01 * ((x * 7 + y * 3 + ch * 5) % 13) as f32
        });
        let s = Raster::from_fn(w, h, c, |x, _, _| 0.02 + 0.001 * x as f32);
        // The near window: a tilt, some noise, and blocks the ratio cannot use (below S, NaN, barely above S).
        let near = Raster::from_fn(w, h, c, |x, y, ch| {
            let v = 0.2 + 0.01 * ((x * 7 + y * 3 + ch * 5) % 13) as f32;
            match (x * 31 + y * 17 + ch) % 23 {
                0 => 0.0,
                1 => f32::NAN,
                2 => s.get(x, y, ch) + 0.5 * NEAR_MIN_LIT,
                k => {
                    s.get(x, y, ch)
                        + (v - s.get(x, y, ch)) * (1.0 + 0.02 * x as f32 - 0.003 * k as f32)
                }
            }
        });
        let got = near_shape(&m, &near, Some(&s));
        let r = near_radius(w, h);
        assert_eq!(r, 5);
        // Nodes every r blocks and on the last one.
        let (nx, ny): (Vec<usize>, Vec<usize>) = (
            (0..w).filter(|x| x % r == 0 || *x == w - 1).collect(),
            (0..h).filter(|y| y % r == 0 || *y == h - 1).collect(),
        );
        for ch in 0..c {
            let node = |x0: usize, y0: usize| {
                let mut logs = Vec::new();
                for y in y0.saturating_sub(r)..(y0 + r + 1).min(h) {
                    for x in x0.saturating_sub(r)..(x0 + r + 1).min(w) {
                        let a = m.get(x, y, ch) - s.get(x, y, ch);
                        let b = near.get(x, y, ch) - s.get(x, y, ch);
                        if a > NEAR_MIN_LIT && b > NEAR_MIN_LIT {
                            logs.push((b / a).ln());
                        }
                    }
                }
                logs.sort_by(f32::total_cmp);
                logs[((logs.len() - 1) as f64 * 0.5).round() as usize]
            };
            // The nodes around `v` and how far along between them it lies.
            let around = |nodes: &[usize], v: usize| {
                let j = nodes.iter().rposition(|&n| n <= v).unwrap();
                let (a, b) = (nodes[j], nodes[(j + 1).min(nodes.len() - 1)]);
                let t = if b > a {
                    (v - a) as f32 / (b - a) as f32
                } else {
                    0.0
                };
                (a, b, t)
            };
            for y in 0..h {
                let (y0, y1, ty) = around(&ny, y);
                for x in 0..w {
                    let (x0, x1, tx) = around(&nx, x);
                    let g = node(x0, y0) * (1.0 - tx) * (1.0 - ty)
                        + node(x1, y0) * tx * (1.0 - ty)
                        + node(x0, y1) * (1.0 - tx) * ty
                        + node(x1, y1) * tx * ty;
                    let sv = s.get(x, y, ch);
                    let expect = sv + (m.get(x, y, ch) - sv) * g.exp();
                    let v = got.get(x, y, ch);
                    assert!(
                        (v - expect).abs() < 1e-5,
                        "({x}, {y}, {ch}): {v} against {expect}"
                    );
                }
            }
        }
    }

    /// A few broken blocks (a dark rock in the near window's median) do not move the shape: the median outvotes
    /// them, where a mean would carry them into every block of their square.
    #[test]
    fn near_shape_outvotes_a_local_breakdown() {
        let m = Raster::from_fn(40, 30, 1, |x, _, _| 0.3 + 0.002 * x as f32);
        let mut near = m.clone();
        for y in 12..16 {
            for x in 18..22 {
                near.data[y * 40 + x] *= 0.2;
            }
        }
        let got = near_shape(&m, &near, None);
        for (a, b) in m.data.iter().zip(&got.data) {
            assert!((a - b).abs() < 1e-6, "{a} -> {b}");
        }
    }

    /// A near window that is the window times a constant per channel gives exactly that gain on `M − S`; the same
    /// `M` gives `M` back.
    #[test]
    fn near_shape_takes_a_uniform_change_whole_and_keeps_an_equal_window() {
        let m = Raster::from_fn(40, 30, 3, |x, y, ch| {
            0.1 + 0.005 * (x + y) as f32 + 0.1 * ch as f32
        });
        let s = Raster::from_fn(40, 30, 3, |_, _, ch| 0.03 + 0.01 * ch as f32);
        let gains = [0.8f32, 1.0, 1.25];
        let near = Raster::from_fn(40, 30, 3, |x, y, ch| {
            s.get(x, y, ch) + (m.get(x, y, ch) - s.get(x, y, ch)) * gains[ch]
        });
        let got = near_shape(&m, &near, Some(&s));
        let same = near_shape(&m, &m, Some(&s));
        for y in 0..30 {
            for x in 0..40 {
                for (ch, g) in gains.iter().enumerate() {
                    let (sv, mv) = (s.get(x, y, ch), m.get(x, y, ch));
                    assert!((got.get(x, y, ch) - (sv + (mv - sv) * g)).abs() < 1e-5);
                    assert!((same.get(x, y, ch) - mv).abs() < 1e-6);
                }
            }
        }
    }

    #[test]
    fn quantile_nearest_rank() {
        let mut v = vec![5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(quantile(&mut v, 0.5), 3.0);
        assert_eq!(quantile(&mut v, 0.0), 1.0);
        assert_eq!(quantile(&mut v, 1.0), 5.0);
        // 21 values 0..=20: the 95th percentile by nearest rank is index round(20·0.95) = 19.
        let mut w: Vec<f32> = (0..=20).rev().map(|x| x as f32).collect();
        assert_eq!(quantile(&mut w, 0.95), 19.0);
        assert!(quantile(&mut [], 0.5).is_nan());
    }

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

    #[test]
    fn photo_gain_recovers_a_known_gain_despite_outliers() {
        // M − S a smooth ramp, the photo 1.3× brighter (red), 0.8× (green), 1× (blue) on its seafloor, with 30 %
        // of its blocks dark nodules (ratio 0.1) and S = 0.05 everywhere.
        let (w, h) = (20, 10);
        let s = Raster::filled(w, h, 3, 0.05);
        let m = Raster::from_fn(w, h, 3, |x, y, _| {
            0.05 + 0.2 + 0.02 * x as f32 + 0.01 * y as f32
        });
        let gains = [1.3f32, 0.8, 1.0];
        let own = Raster::from_fn(w, h, 3, |x, y, c| {
            let lit = 0.2 + 0.02 * x as f32 + 0.01 * y as f32;
            let nodule = (x * 7 + y * 3) % 10 < 3;
            0.05 + lit * if nodule { 0.1 } else { gains[c] }
        });
        let g = photo_gain(&own, &m, Some(&s), 0.3, 0.5);
        for c in 0..3 {
            assert!((g[c] - gains[c]).abs() < 1e-5, "{c}: {}", g[c]);
        }
        // Too few lit blocks: gain 1.
        let tiny = Raster::filled(2, 2, 3, 0.5);
        assert_eq!(photo_gain(&tiny, &tiny, None, 0.3, 0.5), vec![1.0; 3]);
    }

    #[test]
    fn photo_gain_at_the_windows_quantile_holds_under_a_dense_nodule_field() {
        // 60 % of the blocks nodules (ratio 0.1): the median lands on a nodule, the (1 + 0.6)/2 = 0.8 quantile on
        // the seafloor's gain.
        let (w, h) = (20, 10);
        let m = Raster::from_fn(w, h, 3, |x, _, _| 0.2 + 0.02 * x as f32);
        let nodule = |x: usize, y: usize| (x * 7 + y * 3) % 10 < 6;
        let own = Raster::from_fn(w, h, 3, |x, y, _| {
            (0.2 + 0.02 * x as f32) * if nodule(x, y) { 0.1 } else { 1.2 }
        });
        let by_median = photo_gain(&own, &m, None, 0.3, 0.5);
        let by_quantile = photo_gain(&own, &m, None, 0.3, 0.8);
        for c in 0..3 {
            assert!(
                (by_median[c] - 0.25).abs() < 1e-6,
                "clamped nodule ratio: {}",
                by_median[c]
            );
            assert!((by_quantile[c] - 1.2).abs() < 1e-5, "{}", by_quantile[c]);
        }
    }

    /// A window whose exposure jumps photo to photo (more than its seafloor's texture): the plain median at every
    /// block is the middle-exposure photo, scene and all; levelled, `M` follows the light and no photo's scene.
    /// Checked against gains and a median taken by sorting, and `None` when the exposure does not change.
    #[test]
    fn levelled_stack_takes_no_photo_s_scene_whole() {
        use crate::method::median::stack_median;
        let (w, h, c) = (40, 30, 3);
        let light = |x: usize, y: usize| 0.2 + 0.01 * x as f32 + 0.005 * y as f32;
        let texture = |j: usize, x: usize, y: usize| {
            let k = (x * 73 + y * 151 + j * 997) * 2654435761 % 1000;
            1.0 + 0.03 * (k as f32 / 500.0 - 1.0)
        };
        let exposures = [1.0f32, 0.8, 1.25, 0.7, 1.4, 0.9, 1.1];
        let s = Raster::filled(w, h, c, 0.03);
        let photos: Vec<Raster> = exposures
            .iter()
            .enumerate()
            .map(|(j, e)| {
                Raster::from_fn(w, h, c, |x, y, _| 0.03 + e * light(x, y) * texture(j, x, y))
            })
            .collect();
        let stack: Vec<&Raster> = photos.iter().collect();
        let m = stack_median(&stack);
        let levelled = levelled_stack(&stack, &m, Some(&s), 0.5).expect("the exposures differ");
        let m_levelled = stack_median(&levelled.iter().collect::<Vec<_>>());
        // By hand: each photo's gain the median ratio over the blocks lit at least 0.3 of the 95th percentile.
        let lit: Vec<f32> = m.data.iter().map(|v| v - 0.03).collect();
        let mut sorted = lit.clone();
        sorted.sort_by(f32::total_cmp);
        let top = sorted[((sorted.len() - 1) as f64 * LIT_PERCENTILE).round() as usize];
        for (i, want) in m_levelled.data.iter().enumerate() {
            let mut column: Vec<f32> = photos
                .iter()
                .map(|p| {
                    let mut r: Vec<f32> = (i % c..p.data.len())
                        .step_by(c)
                        .filter(|&k| lit[k] >= 0.3 * top)
                        .map(|k| (p.data[k] - 0.03) / lit[k])
                        .collect();
                    r.sort_by(f32::total_cmp);
                    let nearest_rank = ((r.len() - 1) as f64 * 0.5).round() as usize;
                    0.03 + (p.data[i] - 0.03) / r[nearest_rank]
                })
                .collect();
            column.sort_by(f32::total_cmp);
            assert!(
                (column[3] - want).abs() < 1e-6,
                "{i}: {} vs {want}",
                column[3]
            );
        }
        // The scene of the middle-exposure photo (exposure 1.0): the plain M is it, the levelled M is not.
        let scene_share = |m: &Raster| {
            let (mut same, mut n) = (0, 0);
            for y in 0..h {
                for x in 0..w {
                    let rel = (m.get(x, y, 0) - 0.03) / light(x, y);
                    same += usize::from((rel - texture(0, x, y)).abs() < 1e-4);
                    n += 1;
                }
            }
            same as f64 / n as f64
        };
        assert!(scene_share(&m) > 0.95, "plain: {}", scene_share(&m));
        assert!(
            scene_share(&m_levelled) < 0.5,
            "levelled: {}",
            scene_share(&m_levelled)
        );
        // One exposure, or a smooth drift (altitude): nothing to level.
        let same: Vec<&Raster> = vec![&photos[0]; 5];
        assert!(levelled_stack(&same, &photos[0], Some(&s), 0.5).is_none());
        let drift: Vec<Raster> = (0..7)
            .map(|j| {
                let e = 0.85 + 0.05 * j as f32;
                Raster::from_fn(w, h, c, |x, y, _| 0.03 + e * light(x, y) * texture(j, x, y))
            })
            .collect();
        let drift: Vec<&Raster> = drift.iter().collect();
        assert!(levelled_stack(&drift, &stack_median(&drift), Some(&s), 0.5).is_none());
    }

    /// The gains of a 12 MP photo's block image (500×375 blocks) on every `k`-th block are its gains on all of
    /// them, within a thousandth.
    #[test]
    fn levelling_gains_on_a_sample_of_blocks_are_the_gains_on_all() {
        let (w, h) = (500, 375);
        let m = Raster::from_fn(w, h, 3, |x, y, _| {
            0.05 + 0.3 * (1.0 - (x as f32 / w as f32 - 0.5).powi(2)) + 0.0002 * y as f32
        });
        let own = Raster::from_fn(w, h, 3, |x, y, c| {
            let k = ((x * 73 + y * 151 + c * 31) * 2654435761usize % 1000) as f32 / 1000.0;
            let nodule = (x / 7 + y / 5) % 4 == 0;
            m.get(x, y, c) * if nodule { 0.3 } else { 1.1 + 0.2 * (k - 0.5) }
        });
        let against = Against::new(&m, None, 1);
        let stride = (w * h).div_ceil(LEVEL_SAMPLES);
        assert!(stride > 8);
        let (all, sampled) = (
            against.gain(&own, 0.3, 0.5, 1),
            against.gain(&own, 0.3, 0.5, stride),
        );
        for c in 0..3 {
            assert!(
                (all[c] - sampled[c]).abs() < 1e-3,
                "{c}: {} vs {}",
                all[c],
                sampled[c]
            );
            // A quarter nodules: the median is the seafloor's 1/3 quantile, 1.0 + 0.2/3.
            assert!((all[c] - (1.0 + 0.2 / 3.0)).abs() < 0.01, "{c}: {}", all[c]);
        }
    }
}

//! `F` from overlaps: consecutive photos see the same seafloor shifted, and at a point of the seafloor seen at
//! block `x` of photo `a` and at `x + d` of photo `b`,
//! `(L_a(x) − S(x)) / (L_b(x + d) − S(x + d)) = g_a F(x) / (g_b F(x + d))` whatever lies there: nodules, burrows
//! and fauna cancel (`g`: each photo's gain). `log F` is estimated on a grid of nodes over the block grid by
//! robust least squares over every registered pair of a window (the flat field from shifted frames of astronomy,
//! Kuhn, Lin & Loranz 1991, PASP 103, 1097; the vignetting self-calibration of panorama stitching, Goldman 2010,
//! PAMI 32).
//!
//! Shifts along the track fix `F` along the track only: what they leave undetermined — the overall level, the
//! profile across the track, a ramp along the shift (the same ratios as a drift of the photos' gains) — comes from
//! the window's estimate, a prior that every node is pulled towards with a small weight ([`PRIOR_WEIGHT`] of the
//! data's). The result is the correction `log F − log F_window` per block; the per-photo gain is estimated after
//! it, as before.

use crate::method::raster::Raster;

/// Nodes of the solve grid along the longer side, at most (with fewer blocks, one node per block).
pub const MAX_NODES: usize = 48;
/// Samples taken from one pair's overlap, at most (a stride over the blocks).
pub const MAX_PAIR_SAMPLES: usize = 4000;
/// Weight of the window's estimate at a node, as a share of the mean weight of the data at a node.
pub const PRIOR_WEIGHT: f64 = 0.05;
/// Smallest overlap of a pair, as a share of the frame.
pub const MIN_PAIR_OVERLAP: f64 = 0.3;
/// Photos apart in the window, at most, for a pair.
pub const MAX_PAIR_SPAN: usize = 8;
/// Rounds of reweighting (Cauchy weights of the residuals).
const ROUNDS: usize = 4;
/// Smallest scale of the robust weights (log units): residuals below it all count fully.
const MIN_SPREAD: f64 = 0.02;
/// Conjugate-gradient iterations per round, at most.
const CG_ITERATIONS: usize = 120;

/// Two photos of a window and the shift between them, in blocks: a point at block `(x, y)` of photo `a` is at
/// `(x + dx, y + dy)` of photo `b`. `a` and `b` index the images given to [`overlap_correction`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// The first photo.
    pub a: usize,
    /// The second photo.
    pub b: usize,
    /// Where a point of `a` is in `b`, less where it is in `a` (blocks).
    pub shift: (f64, f64),
}

/// What the overlaps of a window give: the correction of `log F` per block and channel, and each photo's log gain
/// per channel against the window's mean.
#[derive(Debug, Clone)]
pub struct Overlaps {
    /// `log F − log F_window` per block and channel.
    pub delta: Raster,
    /// `gains[j][c]`: photo `j`'s log gain in channel `c`, less the window's mean. Fitted beside `F`; the engine
    /// keeps its own per-photo gain, which measured no worse (docs/overlaps.md).
    #[allow(dead_code)]
    pub gains: Vec<Vec<f64>>,
}

/// Every pair of a window whose photos overlap enough, from the shifts between consecutive photos (`steps[j]`:
/// from photo `j − 1` to `j`, `None` where the match failed, which breaks the chain).
pub fn chained_pairs(steps: &[Option<(f64, f64)>], width: usize, height: usize) -> Vec<Pair> {
    let mut pairs = Vec::new();
    for a in 0..steps.len() {
        let mut d = (0.0, 0.0);
        for (b, step) in steps.iter().enumerate().skip(a + 1).take(MAX_PAIR_SPAN) {
            let Some((sx, sy)) = *step else { break };
            d = (d.0 + sx, d.1 + sy);
            let share = (1.0 - d.0.abs() / width as f64).max(0.0)
                * (1.0 - d.1.abs() / height as f64).max(0.0);
            if share >= MIN_PAIR_OVERLAP {
                pairs.push(Pair { a, b, shift: d });
            }
        }
    }
    pairs
}

/// The solve grid: `nw × nh` nodes, `sx`, `sy` blocks apart, the first and last on the first and last block.
#[derive(Debug, Clone, Copy)]
struct Grid {
    nw: usize,
    nh: usize,
    sx: f64,
    sy: f64,
}

/// Four nodes and their bilinear weights.
type Stencil = [(u32, f32); 4];

impl Grid {
    fn new(width: usize, height: usize) -> Grid {
        let long = width.max(height).max(1);
        let step = ((long - 1) as f64 / (MAX_NODES - 1) as f64).max(1.0);
        let nodes = |n: usize| ((n.max(1) - 1) as f64 / step).ceil() as usize + 1;
        let (nw, nh) = (nodes(width), nodes(height));
        let spacing = |n: usize, count: usize| {
            if count > 1 {
                (n - 1) as f64 / (count - 1) as f64
            } else {
                1.0
            }
        };
        Grid {
            nw,
            nh,
            sx: spacing(width, nw),
            sy: spacing(height, nh),
        }
    }

    fn len(&self) -> usize {
        self.nw * self.nh
    }

    /// The bilinear stencil at block position `(x, y)` (inside the block grid).
    fn stencil(&self, x: f64, y: f64) -> Stencil {
        let axis = |v: f64, s: f64, n: usize| {
            if n < 2 {
                return (0, 0, 0.0);
            }
            let g = (v / s).clamp(0.0, (n - 1) as f64);
            let i = (g.floor() as usize).min(n - 2);
            (i, i + 1, (g - i as f64) as f32)
        };
        let (x0, x1, tx) = axis(x, self.sx, self.nw);
        let (y0, y1, ty) = axis(y, self.sy, self.nh);
        let at = |x: usize, y: usize| (y * self.nw + x) as u32;
        [
            (at(x0, y0), (1.0 - tx) * (1.0 - ty)),
            (at(x1, y0), tx * (1.0 - ty)),
            (at(x0, y1), (1.0 - tx) * ty),
            (at(x1, y1), tx * ty),
        ]
    }

    fn eval(&self, f: &[f64], s: &Stencil) -> f64 {
        s.iter().map(|&(k, w)| f[k as usize] * w as f64).sum()
    }
}

/// Bilinear sample of channel `c` of `r` at block position `(x, y)` (inside the grid).
fn sample(r: &Raster, x: f64, y: f64, c: usize) -> f32 {
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(r.width - 1), (y0 + 1).min(r.height - 1));
    let (tx, ty) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let top = r.get(x0, y0, c) * (1.0 - tx) + r.get(x1, y0, c) * tx;
    let bottom = r.get(x0, y1, c) * (1.0 - tx) + r.get(x1, y1, c) * tx;
    top * (1.0 - ty) + bottom * ty
}

/// One ratio of a pair: the nodes at both ends, the photos, and per channel the log ratio and its weight.
#[derive(Debug, Clone)]
struct Observation {
    at: Stencil,
    to: Stencil,
    a: usize,
    b: usize,
    log_ratio: Vec<f64>,
    weight: Vec<f64>,
}

/// The ratios of every pair, sampled with a stride over the overlap; samples below `floor` (dark, noisy) are left
/// out, and samples below `full` weigh less (the log of a dim sample is noisier).
fn observations(
    lit: &[&Raster],
    pairs: &[Pair],
    grid: &Grid,
    floor: &[f32],
    full: &[f32],
) -> Vec<Observation> {
    let (w, h, ch) = (lit[0].width, lit[0].height, lit[0].channels);
    let mut out = Vec::new();
    for p in pairs {
        let (dx, dy) = p.shift;
        let (x0, x1) = (
            (-dx).max(0.0).ceil() as usize,
            ((w - 1) as f64 - dx.max(0.0)).floor(),
        );
        let (y0, y1) = (
            (-dy).max(0.0).ceil() as usize,
            ((h - 1) as f64 - dy.max(0.0)).floor(),
        );
        if x1 < x0 as f64 || y1 < y0 as f64 {
            continue;
        }
        let (x1, y1) = (x1 as usize, y1 as usize);
        let area = (x1 - x0 + 1) * (y1 - y0 + 1);
        let stride = ((area as f64 / MAX_PAIR_SAMPLES as f64).sqrt().ceil() as usize).max(1);
        for y in (y0..=y1).step_by(stride) {
            for x in (x0..=x1).step_by(stride) {
                let (u, v) = (x as f64 + dx, y as f64 + dy);
                let mut log_ratio = Vec::with_capacity(ch);
                let mut weight = Vec::with_capacity(ch);
                for c in 0..ch {
                    let (va, vb) = (lit[p.a].get(x, y, c), sample(lit[p.b], u, v, c));
                    if !(va > floor[c] && vb > floor[c]) {
                        break;
                    }
                    log_ratio.push((va as f64).ln() - (vb as f64).ln());
                    weight.push(((va.min(vb) / full[c]).min(1.0) as f64).powi(2));
                }
                if log_ratio.len() == ch {
                    out.push(Observation {
                        at: grid.stencil(x as f64, y as f64),
                        to: grid.stencil(u, v),
                        a: p.a,
                        b: p.b,
                        log_ratio,
                        weight,
                    });
                }
            }
        }
    }
    out
}

/// The weighted least-squares problem of one channel: minimise
/// `Σ w_o (r_o − (f(at_o) − f(to_o) + g_a − g_b))² + Σ_k λ (f_k − π_k)² + ε Σ_j g_j²`
/// over the nodes `f` and the photos' log gains `g`.
struct Problem<'a> {
    obs: &'a [Observation],
    channel: usize,
    nodes: usize,
    /// Weight of each observation (the data's times the robust one).
    w: Vec<f64>,
    lambda: f64,
    prior: &'a [f64],
}

impl Problem<'_> {
    /// The model's value of observation `o` at the unknowns `u` (nodes, then gains).
    fn predict(&self, u: &[f64], o: &Observation) -> f64 {
        let g = &u[self.nodes..];
        let at: f64 = o.at.iter().map(|&(k, w)| u[k as usize] * w as f64).sum();
        let to: f64 = o.to.iter().map(|&(k, w)| u[k as usize] * w as f64).sum();
        at - to + g[o.a] - g[o.b]
    }

    /// Adds `v·∂model/∂u` of observation `o` to `out`.
    fn spread(&self, out: &mut [f64], o: &Observation, v: f64) {
        for &(k, w) in &o.at {
            out[k as usize] += v * w as f64;
        }
        for &(k, w) in &o.to {
            out[k as usize] -= v * w as f64;
        }
        out[self.nodes + o.a] += v;
        out[self.nodes + o.b] -= v;
    }

    /// The normal matrix times `u`.
    fn apply(&self, u: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; u.len()];
        for (o, &w) in self.obs.iter().zip(&self.w) {
            let v = w * self.predict(u, o);
            self.spread(&mut out, o, v);
        }
        for (k, x) in out.iter_mut().enumerate() {
            *x += u[k] * if k < self.nodes { self.lambda } else { 1e-9 };
        }
        out
    }

    /// The normal equations' right side.
    fn rhs(&self, len: usize) -> Vec<f64> {
        let mut out = vec![0.0; len];
        for (o, &w) in self.obs.iter().zip(&self.w) {
            self.spread(&mut out, o, w * o.log_ratio[self.channel]);
        }
        for (x, p) in out.iter_mut().zip(self.prior) {
            *x += self.lambda * p;
        }
        out
    }

    /// Conjugate gradients on the normal equations from `u`.
    fn solve(&self, u: &mut [f64]) {
        let b = self.rhs(u.len());
        let au = self.apply(u);
        let mut r: Vec<f64> = b.iter().zip(&au).map(|(b, a)| b - a).collect();
        let mut p = r.clone();
        let mut rr: f64 = r.iter().map(|v| v * v).sum();
        let stop = 1e-12 * b.iter().map(|v| v * v).sum::<f64>().max(1e-30);
        for _ in 0..CG_ITERATIONS {
            if rr <= stop {
                break;
            }
            let ap = self.apply(&p);
            let alpha = rr / p.iter().zip(&ap).map(|(a, b)| a * b).sum::<f64>();
            for ((x, ri), (pi, api)) in u.iter_mut().zip(r.iter_mut()).zip(p.iter().zip(&ap)) {
                *x += alpha * pi;
                *ri -= alpha * api;
            }
            let next: f64 = r.iter().map(|v| v * v).sum();
            for (pi, ri) in p.iter_mut().zip(&r) {
                *pi = ri + next / rr * *pi;
            }
            rr = next;
        }
    }
}

/// Median of the absolute values (0 for none).
fn median_abs(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    for x in v.iter_mut() {
        *x = x.abs();
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// `log F` of one channel at the nodes, then the photos' log gains: reweighted least squares (Cauchy weights at
/// 2.4 × the residuals' robust spread, at least [`MIN_SPREAD`]) from the prior `π`, whose weight follows the data's
/// in every round; `robust = false` solves the plain weighted problem once.
fn solve_channel(
    obs: &[Observation],
    channel: usize,
    prior: &[f64],
    photos: usize,
    robust: bool,
) -> Vec<f64> {
    let nodes = prior.len();
    let base: Vec<f64> = obs.iter().map(|o| o.weight[channel]).collect();
    let reach: Vec<f64> = obs
        .iter()
        .map(|o| o.at.iter().chain(&o.to).map(|&(_, v)| (v * v) as f64).sum())
        .collect();
    let mut u: Vec<f64> = prior.iter().copied().chain(vec![0.0; photos]).collect();
    let mut problem = Problem {
        obs,
        channel,
        nodes,
        w: base.clone(),
        lambda: 0.0,
        prior,
    };
    for round in 0..if robust { ROUNDS } else { 1 } {
        if round > 0 {
            let res: Vec<f64> = obs
                .iter()
                .map(|o| o.log_ratio[channel] - problem.predict(&u, o))
                .collect();
            let scale = (2.4 * 1.4826 * median_abs(&mut res.clone())).max(MIN_SPREAD);
            for ((w, b), r) in problem.w.iter_mut().zip(&base).zip(&res) {
                *w = b / (1.0 + (r / scale).powi(2));
            }
        }
        // The data's weight at a node, on average: the prior keeps its share of it whatever the reweighting did.
        let data: f64 = problem.w.iter().zip(&reach).map(|(w, s)| w * s).sum();
        problem.lambda = (PRIOR_WEIGHT * data / nodes as f64).max(1e-9);
        problem.solve(&mut u);
    }
    u
}

/// A high level of each channel of `r` (its 90th percentile over the finite samples).
fn high_level(r: &Raster) -> Vec<f32> {
    (0..r.channels)
        .map(|c| {
            let mut v: Vec<f32> = r
                .data
                .iter()
                .skip(c)
                .step_by(r.channels)
                .copied()
                .filter(|v| v.is_finite())
                .collect();
            if v.is_empty() {
                return 0.0;
            }
            let at = (v.len() - 1) * 9 / 10;
            *v.select_nth_unstable_by(at, f32::total_cmp).1
        })
        .collect()
}

/// The correction `log F − log F_window` per block and channel that the overlaps of `pairs` give, with `lit` the
/// photos' block images less `S` (`L − S`) and `prior` the window's `M − S` (`F·C`, the same shape as `F`).
/// `None` when the pairs give no usable ratio (no pair, or dark photos).
pub fn overlap_correction(lit: &[&Raster], pairs: &[Pair], prior: &Raster) -> Option<Overlaps> {
    overlap_correction_with(lit, pairs, prior, true)
}

/// [`overlap_correction`], robust or not (the plain weighted least squares, for the tests).
#[allow(clippy::needless_range_loop)] // channels index both the gains and the interleaved blocks
fn overlap_correction_with(
    lit: &[&Raster],
    pairs: &[Pair],
    prior: &Raster,
    robust: bool,
) -> Option<Overlaps> {
    if lit.is_empty() || pairs.is_empty() {
        return None;
    }
    let (w, h, ch) = (prior.width, prior.height, prior.channels);
    let grid = Grid::new(w, h);
    let high = high_level(prior);
    let floor: Vec<f32> = high.iter().map(|v| (0.02 * v).max(1e-9)).collect();
    let full: Vec<f32> = high.iter().map(|v| (0.25 * v).max(1e-9)).collect();
    let obs = observations(lit, pairs, &grid, &floor, &full);
    if obs.len() < grid.len() {
        return None;
    }
    let log_prior = |x: usize, y: usize, c: usize| (prior.get(x, y, c).max(floor[c]) as f64).ln();
    let mut out = Raster::filled(w, h, ch, 0.0);
    let mut gains = vec![vec![0.0; ch]; lit.len()];
    for c in 0..ch {
        let prior_nodes: Vec<f64> = (0..grid.len())
            .map(|k| {
                let x = ((k % grid.nw) as f64 * grid.sx).round() as usize;
                let y = ((k / grid.nw) as f64 * grid.sy).round() as usize;
                log_prior(x.min(w - 1), y.min(h - 1), c)
            })
            .collect();
        let mut f = solve_channel(&obs, c, &prior_nodes, lit.len(), robust);
        let g = f.split_off(grid.len());
        let mean = g.iter().sum::<f64>() / g.len() as f64;
        for (j, v) in g.iter().enumerate() {
            gains[j][c] = v - mean;
        }
        let delta: Vec<f64> = f.iter().zip(&prior_nodes).map(|(a, b)| a - b).collect();
        for y in 0..h {
            for x in 0..w {
                let s = grid.stencil(x as f64, y as f64);
                out.data[(y * w + x) * ch + c] = grid.eval(&delta, &s) as f32;
            }
        }
    }
    Some(Overlaps { delta: out, gains })
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the brute force is written with indices, as on paper
mod tests {
    use super::*;

    /// A deterministic pseudo-random value in `[0, 1)` (xorshift of the index).
    fn noise(i: u64) -> f64 {
        let mut x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x2545_F491_4F6C_DD1D;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The true `F` of the tests: a bright spot off centre and a fall-off to the corners.
    fn true_f(x: usize, y: usize) -> f64 {
        let (dx, dy) = (x as f64 - 14.0, y as f64 - 9.0);
        0.15 + 0.85 * (-(dx * dx / 180.0 + dy * dy / 90.0)).exp()
    }

    /// A nodule field: sediment with a little texture, a third of it dark discs.
    fn ground(w: usize, h: usize) -> Vec<f64> {
        let mut a: Vec<f64> = (0..w * h).map(|i| 0.9 + 0.2 * noise(i as u64)).collect();
        for k in 0..(w * h / 12) {
            let (cx, cy) = (
                noise(1000 + 2 * k as u64) * w as f64,
                noise(1001 + 2 * k as u64) * h as f64,
            );
            for y in 0..h {
                for x in 0..w {
                    if (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2) < 2.5 {
                        a[y * w + x] = 0.25;
                    }
                }
            }
        }
        a
    }

    /// `photos` photos of `w × h` blocks (one channel) over `ground`, the camera moving `step` blocks down the
    /// ground per photo, with gains; and the pairs between them.
    fn survey(w: usize, h: usize, photos: usize, step: usize) -> (Vec<Raster>, Vec<Pair>) {
        let gh = h + step * photos;
        let a = ground(w, gh);
        let lit: Vec<Raster> = (0..photos)
            .map(|j| {
                let gain = 1.0 + 0.08 * ((j * 5) % 3) as f64;
                Raster::from_fn(w, h, 1, |x, y, _| {
                    (gain * a[(y + step * j) * w + x] * true_f(x, y)) as f32
                })
            })
            .collect();
        // The ground at row y + step·j of photo j is at row y + step·(j − i) of photo i... a point at row y of photo
        // a is at row y − step·(b − a) of photo b.
        let steps: Vec<Option<(f64, f64)>> = (0..photos)
            .map(|j| (j > 0).then_some((0.0, -(step as f64))))
            .collect();
        (lit, chained_pairs(&steps, w, h))
    }

    /// Root mean square of `log(F_est / F_true)` less its mean (the level is the prior's, not the overlaps').
    fn shape_error(est: impl Fn(usize, usize) -> f64, w: usize, h: usize) -> f64 {
        let d: Vec<f64> = (0..w * h)
            .map(|i| (est(i % w, i / w) / true_f(i % w, i / w)).ln())
            .collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
    }

    /// The window's estimate in a nodule field: `F` with dark blocks where nodules held the median, the
    /// fault the overlaps are to remove.
    fn spoiled_prior(w: usize, h: usize) -> Raster {
        Raster::from_fn(w, h, 1, |x, y, _| {
            let ghost = if noise(5000 + (y * w + x) as u64) < 0.15 {
                0.55
            } else {
                1.0
            };
            let blob = if (x as f64 - 8.0).powi(2) + (y as f64 - 12.0).powi(2) < 6.0 {
                0.6
            } else {
                1.0
            };
            (true_f(x, y) * ghost * blob * 0.4) as f32
        })
    }

    #[test]
    fn overlaps_recover_a_known_factor_from_a_spoiled_window() {
        let (w, h) = (28, 20);
        let (lit, pairs) = survey(w, h, 7, 3);
        assert!(pairs.len() >= 15, "{} pairs", pairs.len());
        let prior = spoiled_prior(w, h);
        let refs: Vec<&Raster> = lit.iter().collect();
        let delta = overlap_correction(&refs, &pairs, &prior)
            .expect("pairs give ratios")
            .delta;
        let before = shape_error(|x, y| prior.get(x, y, 0) as f64, w, h);
        let after = shape_error(
            |x, y| prior.get(x, y, 0) as f64 * (delta.get(x, y, 0) as f64).exp(),
            w,
            h,
        );
        assert!(before > 0.2, "the prior is spoiled: {before}");
        // Measured 0.234 -> 0.143: what stays is what the shifts down the frame leave to the prior (each
        // column's level, the ramp along the track).
        assert!(
            after < 0.7 * before,
            "shape error {before:.3} -> {after:.3}"
        );
    }

    #[test]
    fn a_moving_object_does_not_enter_the_robust_estimate() {
        let (w, h) = (28, 20);
        let (mut lit, pairs) = survey(w, h, 7, 3);
        // A bright animal that moves against the ground, in three photos.
        for (j, photo) in lit.iter_mut().enumerate().skip(2).take(3) {
            for y in 6..11 {
                for x in (4 + 5 * j)..(8 + 5 * j) {
                    photo.data[y * w + x] *= 4.0;
                }
            }
        }
        let prior = spoiled_prior(w, h);
        let refs: Vec<&Raster> = lit.iter().collect();
        let est = |robust| {
            let d = overlap_correction_with(&refs, &pairs, &prior, robust)
                .unwrap()
                .delta;
            shape_error(
                |x, y| prior.get(x, y, 0) as f64 * (d.get(x, y, 0) as f64).exp(),
                w,
                h,
            )
        };
        let (plain, robust) = (est(false), est(true));
        assert!(robust < plain, "plain {plain:.4}, robust {robust:.4}");
        let spoiled = shape_error(|x, y| prior.get(x, y, 0) as f64, w, h);
        assert!(
            robust < 0.5 * spoiled,
            "spoiled {spoiled:.4}, robust {robust:.4}"
        );
    }

    /// Gaussian elimination with partial pivoting.
    fn dense_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
        let n = b.len();
        for col in 0..n {
            let p = (col..n)
                .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
                .unwrap();
            a.swap(col, p);
            b.swap(col, p);
            for r in col + 1..n {
                let m = a[r][col] / a[col][col];
                for k in col..n {
                    a[r][k] -= m * a[col][k];
                }
                b[r] -= m * b[col];
            }
        }
        let mut x = vec![0.0; n];
        for r in (0..n).rev() {
            let s: f64 = (r + 1..n).map(|k| a[r][k] * x[k]).sum();
            x[r] = (b[r] - s) / a[r][r];
        }
        x
    }

    /// One row `log L_a(x) − log L_b(x + d) = f(x) − f(x + d) + g_a − g_b` per sample of each pair (integer
    /// shifts), over `n` unknowns: one `f` per block of `lit`'s photos, then `g_1`, `g_2`, …
    fn ratio_rows(lit: &[Raster], pairs: &[Pair], n: usize) -> Vec<(Vec<f64>, f64)> {
        let (w, h) = (lit[0].width, lit[0].height);
        let mut rows = Vec::new();
        for p in pairs {
            let (dx, dy) = (p.shift.0 as isize, p.shift.1 as isize);
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let (u, v) = (x + dx, y + dy);
                    if u < 0 || v < 0 || u >= w as isize || v >= h as isize {
                        continue;
                    }
                    let mut row = vec![0.0; n];
                    row[(y * w as isize + x) as usize] += 1.0;
                    row[(v * w as isize + u) as usize] -= 1.0;
                    if p.a > 0 {
                        row[w * h + p.a - 1] += 1.0;
                    }
                    if p.b > 0 {
                        row[w * h + p.b - 1] -= 1.0;
                    }
                    let r = (lit[p.a].get(x as usize, y as usize, 0) as f64).ln()
                        - (lit[p.b].get(u as usize, v as usize, 0) as f64).ln();
                    rows.push((row, r));
                }
            }
        }
        rows
    }

    /// The least-squares solution of `rows` (`n` unknowns), by elimination on the normal equations.
    fn least_squares(rows: &[(Vec<f64>, f64)], n: usize) -> Vec<f64> {
        let mut ata = vec![vec![0.0; n]; n];
        let mut atb = vec![0.0; n];
        for (row, r) in rows {
            for i in 0..n {
                atb[i] += row[i] * r;
                for j in 0..n {
                    ata[i][j] += row[i] * row[j];
                }
            }
        }
        dense_solve(ata, atb)
    }

    /// On a tiny grid (one node per block, integer shifts, every sample at full weight) the plain estimate is
    /// the least-squares solution written out: one row per ratio `log L_a(x) − log L_b(x + d) = f(x) − f(x + d) +
    /// g_a − g_b`, the prior's rows `√λ (f_k − π_k)`, `g_0 = 0`, solved by elimination on the normal equations.
    #[test]
    fn the_plain_estimate_is_the_brute_force_least_squares() {
        let (w, h, photos) = (6usize, 5usize, 4usize);
        let lit: Vec<Raster> = (0..photos)
            .map(|j| {
                Raster::from_fn(w, h, 1, |x, y, _| {
                    (0.4 + 0.6 * noise((j * 100 + y * w + x) as u64)) as f32
                })
            })
            .collect();
        let prior = Raster::from_fn(w, h, 1, |x, y, _| {
            (0.9 + 0.1 * noise((7000 + y * w + x) as u64)) as f32
        });
        let pairs = vec![
            Pair {
                a: 0,
                b: 1,
                shift: (0.0, -1.0),
            },
            Pair {
                a: 1,
                b: 2,
                shift: (1.0, -1.0),
            },
            Pair {
                a: 0,
                b: 2,
                shift: (1.0, -2.0),
            },
            Pair {
                a: 2,
                b: 3,
                shift: (0.0, 1.0),
            },
        ];
        let refs: Vec<&Raster> = lit.iter().collect();
        let got = overlap_correction_with(&refs, &pairs, &prior, false)
            .unwrap()
            .delta;
        // Unknowns: f (w·h), g_1 … g_{photos−1}.
        let n = w * h + photos - 1;
        let mut rows = ratio_rows(&lit, &pairs, n);
        // λ: PRIOR_WEIGHT of the mean data weight per node (each ratio weighs 1 at two nodes).
        let lambda = PRIOR_WEIGHT * 2.0 * rows.len() as f64 / (w * h) as f64;
        for k in 0..w * h {
            let mut row = vec![0.0; n];
            row[k] = lambda.sqrt();
            rows.push((row, lambda.sqrt() * (prior.data[k] as f64).ln()));
        }
        let f = least_squares(&rows, n);
        for k in 0..w * h {
            let want = f[k] - (prior.data[k] as f64).ln();
            assert!(
                (got.data[k] as f64 - want).abs() < 1e-4,
                "node {k}: {} vs {want}",
                got.data[k]
            );
        }
    }

    #[test]
    fn pairs_chain_the_shifts_and_stop_at_a_failed_match() {
        let steps = [
            None,
            Some((0.0, -4.0)),
            Some((1.0, -4.0)),
            None,
            Some((0.0, -2.0)),
        ];
        let pairs = chained_pairs(&steps, 20, 20);
        assert_eq!(
            pairs,
            vec![
                Pair {
                    a: 0,
                    b: 1,
                    shift: (0.0, -4.0)
                },
                Pair {
                    a: 0,
                    b: 2,
                    shift: (1.0, -8.0)
                },
                Pair {
                    a: 1,
                    b: 2,
                    shift: (1.0, -4.0)
                },
                Pair {
                    a: 3,
                    b: 4,
                    shift: (0.0, -2.0)
                },
            ]
        );
        // 30 % overlap at least: 14 of 20 rows apart is 30 %, 15 is not.
        assert_eq!(chained_pairs(&[None, Some((0.0, 14.0))], 20, 20).len(), 1);
        assert!(chained_pairs(&[None, Some((0.0, 15.0))], 20, 20).is_empty());
    }

    #[test]
    fn a_coarse_grid_interpolates_its_nodes() {
        let g = Grid::new(200, 100);
        assert_eq!((g.nw, g.nh), (48, 25));
        let s = g.stencil(199.0, 0.0);
        let total: f32 = s.iter().map(|&(_, w)| w).sum();
        assert!((total - 1.0).abs() < 1e-6);
        assert!(s
            .iter()
            .any(|&(k, w)| k as usize == g.nw - 1 && (w - 1.0).abs() < 1e-6));
        let small = Grid::new(10, 8);
        assert_eq!((small.nw, small.nh, small.sx, small.sy), (10, 8, 1.0, 1.0));
    }
}

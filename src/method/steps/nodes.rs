//! A smooth field over the frame from a block image's votes: the median of the votes over a square around each of
//! a grid of nodes ([`node_medians`]), interpolated bilinearly between the nodes ([`between_nodes`]). The near
//! window's shape ([`crate::method::steps::near_window`]) and the bright spots' local level
//! ([`crate::method::outliers`]) are such fields.

use crate::method::median::quantile;

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
}

//! The pruning stage: lower bounds of descriptor distances from principal
//! directions ([`PruneIndex`]), the representative query samples, and each template's
//! pruning score.

use super::template::Template;
use crate::descriptor::SurfaceContext;
use rayon::prelude::*;

/// Principal directions kept for the pruning stage's lower bound.
pub(super) const PRUNE_DIRECTIONS: usize = 32;
/// Every this-many-th template sample goes into the principal-direction estimate.
pub(super) const PRUNE_SAMPLE_STEP: usize = 32;

/// Lower bounds on descriptor distances for the pruning stage.
///
/// An orthonormal basis P of the templates' leading principal descriptor directions,
/// and every template sample t described by its coordinates P·t plus the length of its
/// remainder ‖t − PᵀP·t‖. By Pythagoras and the reverse triangle inequality,
/// ‖q − t‖² ≥ ‖P·q − P·t‖² + (‖rem q‖ − ‖rem t‖)², which is the squared distance of
/// the two descriptions: a sample whose bound already exceeds the best cost so far
/// cannot improve it and is skipped without reading its full descriptor. 32 of the 180
/// directions hold about 92 % of the templates' descriptor variance.
#[derive(Debug, Clone, PartialEq, Default)]
pub(super) struct PruneIndex {
    /// Directions × descriptor values, row-major; rows orthonormal.
    pub(super) basis: Vec<f64>,
    /// Values per descriptor.
    pub(super) dim: usize,
    pub(super) directions: usize,
    /// Values per description: the directions' coordinates, then the remainder's length.
    pub(super) components: usize,
    /// Per template: its samples' projections, component-major (components × samples,
    /// each component's row padded with zeros to [`prune_stride`] samples) so that one
    /// query's bounds against all samples vectorise.
    pub(super) projected: Vec<Vec<f32>>,
}

impl PruneIndex {
    pub(super) fn new(templates: &[Template]) -> Self {
        let Some(dim) = templates.first().map(|t| t.context.dim) else {
            return PruneIndex::default();
        };
        let directions = PRUNE_DIRECTIONS.min(dim);
        let components = directions + 1;
        // Covariance of a deterministic subset of the samples.
        let rows: Vec<&[f32]> = templates
            .iter()
            .flat_map(|t| (0..t.context.len()).map(move |j| t.context.descriptor(j)))
            .step_by(PRUNE_SAMPLE_STEP)
            .collect();
        let m = rows.len();
        let mut mean = vec![0.0f64; dim];
        for r in &rows {
            for (a, &v) in mean.iter_mut().zip(r.iter()) {
                *a += v as f64;
            }
        }
        mean.iter_mut().for_each(|a| *a /= m.max(1) as f64);
        // Lower triangle of the scatter matrix (a matrix product over a centred copy
        // is no faster here and slows the matching after it: docs/design.md).
        let mut scatter = vec![0.0f64; dim * dim];
        let mut c = vec![0.0f64; dim];
        for r in &rows {
            for (ci, (&v, &a)) in c.iter_mut().zip(r.iter().zip(&mean)) {
                *ci = v as f64 - a;
            }
            for a in 0..dim {
                let ca = c[a];
                for (sab, &cb) in scatter[a * dim..a * dim + a + 1].iter_mut().zip(&c) {
                    *sab += ca * cb;
                }
            }
        }
        let cov = nalgebra::DMatrix::from_fn(dim, dim, |a, b| {
            scatter[a.max(b) * dim + a.min(b)] / m.max(1) as f64
        });
        let eigen = nalgebra::SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..dim).collect();
        order.sort_by(|&a, &b| {
            eigen.eigenvalues[b]
                .total_cmp(&eigen.eigenvalues[a])
                .then(a.cmp(&b))
        });
        let mut basis = Vec::with_capacity(directions * dim);
        for &k in &order[..directions] {
            basis.extend(eigen.eigenvectors.column(k).iter());
        }
        let mut index = PruneIndex {
            basis,
            dim,
            directions,
            components,
            projected: Vec::new(),
        };
        index.projected = templates
            .par_iter()
            .map(|t| {
                let (n, stride) = (t.context.len(), prune_stride(t.context.len()));
                let mut one = vec![0.0f32; components];
                let mut p = vec![0.0f32; stride * components];
                for j in 0..n {
                    index.project(t.context.descriptor(j), &mut one);
                    for (c, &v) in one.iter().enumerate() {
                        p[c * stride + j] = v;
                    }
                }
                p
            })
            .collect();
        index
    }

    /// Writes the description of one descriptor into `out` (`components` values): its
    /// coordinates along the directions, then the length of the rest of it.
    pub(super) fn project(&self, descriptor: &[f32], out: &mut [f32]) {
        // Independent partial sums (a single running f64 sum would stay sequential).
        fn dot(a: &[f64], b: &[f32]) -> f64 {
            let mut acc = [0.0f64; 8];
            let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
            let tail: f64 = ca
                .remainder()
                .iter()
                .zip(cb.remainder())
                .map(|(&x, &y)| x * y as f64)
                .sum();
            for (x, y) in ca.zip(cb) {
                for k in 0..8 {
                    acc[k] += x[k] * y[k] as f64;
                }
            }
            acc.iter().sum::<f64>() + tail
        }
        let mut kept = 0.0f64;
        for (o, row) in out.iter_mut().zip(self.basis.chunks_exact(self.dim)) {
            let c = dot(row, descriptor);
            kept += c * c;
            *o = c as f32;
        }
        let all: f64 = descriptor.iter().map(|&d| d as f64 * d as f64).sum();
        out[self.directions] = (all - kept).max(0.0).sqrt() as f32;
    }
}

/// Row length of a template's stored projections: its sample count rounded up to a
/// multiple of 8, so that the bounds' vectorised loop has no scalar leftover.
pub(super) fn prune_stride(samples: usize) -> usize {
    samples.next_multiple_of(8)
}

/// `count` query samples spread over the body: farthest-point order from the sample
/// nearest the centroid.
pub(super) fn representatives(query: &SurfaceContext, count: usize) -> Vec<usize> {
    let n = query.len();
    let count = count.min(n);
    let d2 = |a: [f32; 2], b: [f32; 2]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let first = (0..n)
        .min_by(|&a, &b| {
            d2(query.positions[a], [0.0; 2]).total_cmp(&d2(query.positions[b], [0.0; 2]))
        })
        .unwrap_or(0);
    let mut chosen = vec![first];
    let mut nearest: Vec<f32> = (0..n)
        .map(|i| d2(query.positions[i], query.positions[first]))
        .collect();
    while chosen.len() < count {
        let next = (0..n)
            .max_by(|&a, &b| nearest[a].total_cmp(&nearest[b]).then(b.cmp(&a)))
            .unwrap_or(0);
        chosen.push(next);
        let pn = query.positions[next];
        for (d, p) in nearest.iter_mut().zip(&query.positions) {
            *d = d.min(d2(*p, pn));
        }
    }
    chosen
}
/// The query samples the pruning stage scores with, and their projections onto the
/// [`PruneIndex`] basis (samples × components).
pub(super) struct Representatives {
    pub(super) samples: Vec<usize>,
    pub(super) projected: Vec<f32>,
    pub(super) components: usize,
}

impl Representatives {
    /// `count` samples of `query` spread over the body ([`representatives`]), projected
    /// onto `index`'s basis.
    pub(super) fn new(index: &PruneIndex, query: &SurfaceContext, count: usize) -> Self {
        let samples = representatives(query, count);
        let k = index.components;
        let mut projected = vec![0.0f32; samples.len() * k];
        for (&i, out) in samples.iter().zip(projected.chunks_exact_mut(k.max(1))) {
            index.project(query.descriptor(i), out);
        }
        Representatives {
            samples,
            projected,
            components: k,
        }
    }
}

avx2_dispatch! {
    /// Pruning score × the number of representatives: the sum over representatives of
    /// the cost of their nearest template sample, or `None` as soon as the partial sum
    /// exceeds `give_up` (representatives in order; the sum only grows).
    ///
    /// Exact, but pruned. Per representative, vectorised passes over all template samples
    /// give each pair a lower bound of its cost: the position term plus the bound of the
    /// descriptor distance from the short descriptions ([`PruneIndex`]). Four pairs of
    /// low bound (the least among them) are costed in full first, then only the pairs
    /// whose bounds are below the best cost so far, four at a time: on the default
    /// database about 4 template samples in 100 have a bound below the best (about 7 in
    /// 100 with 24 directions in index order, 85 in 100 by the position term alone).
    /// `t_projected` is the template's component-major description; `scratch` is reused
    /// storage.
    pub(super) fn prune_sum(
        q: &SurfaceContext,
        reps: &Representatives,
        t: &SurfaceContext,
        t_projected: &[f32],
        lw: f32,
        give_up: f32,
        scratch: &mut Vec<f32>,
    ) -> Option<f32> {
        let (k, n, stride) = (reps.components, t.len(), prune_stride(t.len()));
        scratch.clear();
        scratch.resize(stride + n, 0.0);
        let (lower, location) = scratch.split_at_mut(stride);
        let mut total = 0.0;
        for (r, &i) in reps.samples.iter().enumerate() {
            let pi = q.positions[i];
            for (l, pj) in location.iter_mut().zip(&t.positions) {
                *l = (pi[0] - pj[0]) * (pi[0] - pj[0]) + (pi[1] - pj[1]) * (pi[1] - pj[1]);
            }
            // lw·√(squared distance): the same arithmetic as `pair_cost`.
            location.iter_mut().for_each(|l| *l = lw * l.sqrt());
            squared_projection_distances(&reps.projected[r * k..(r + 1) * k], t_projected, lower);
            // Lower bounds of the pair costs. They come from rounded descriptions: the
            // margin lies well above that rounding, so no bound exceeds its pair's cost.
            for (lo, &l) in lower.iter_mut().zip(location.iter()) {
                *lo = l + ((*lo - PRUNE_BOUND_SLACK).max(0.0) / PRUNE_BOUND_MARGIN).sqrt();
            }
            lower[n..].fill(f32::INFINITY);
            // Four pairs of low bound first (the least of all among them; usually the
            // best pair too), then every other pair whose bound is below the best cost
            // so far (any other costs at least its bound, so cannot improve it).
            // Distances four at a time: four cost little more than one, and computing
            // a few pairs the scan would have skipped does not change the least cost.
            let qd = q.descriptor(i);
            let cost4 = |js: [usize; 4]| {
                let d2 = crate::descriptor::squared_distances_x4(qd, js.map(|j| t.descriptor(j)));
                (0..4)
                    .map(|k| d2[k].sqrt() + location[js[k]])
                    .fold(f32::INFINITY, f32::min)
            };
            let firsts = four_low(lower);
            let lower = &mut lower[..n];
            let mut best = cost4(firsts);
            for &j in &firsts {
                lower[j] = f32::INFINITY;
            }
            let (mut batch, mut pending) = ([0usize; 4], 0);
            for (j, &b) in lower.iter().enumerate() {
                if b < best {
                    batch[pending] = j;
                    pending += 1;
                    if pending == 4 {
                        best = best.min(cost4(batch));
                        pending = 0;
                    }
                }
            }
            if pending > 0 {
                // Pad the last batch with repeats of its last pair.
                let last = batch[pending - 1];
                batch[pending..].fill(last);
                best = best.min(cost4(batch));
            }
            total += best;
            if total > give_up {
                return None;
            }
        }
        Some(total)
    }
}

/// `out[j]` = Σ_c (query[c] − projected[c·n + j])² over the components c of one
/// representative's description against every template sample's (component-major
/// `projected` with rows of n = `out.len()` values, a multiple of 8), summed in
/// component order.
///
/// 32 samples at a time (8 at the end) with the components inside, so the sums stay
/// in registers (a pass per component would read and write all n sums each time), as
/// four independent chains of adds. Inlined into `prune_sum`'s AVX2 build.
#[inline(always)]
pub(super) fn squared_projection_distances(query: &[f32], projected: &[f32], out: &mut [f32]) {
    #[inline(always)]
    fn block<const B: usize>(query: &[f32], projected: &[f32], n: usize, j0: usize) -> [f32; B] {
        let mut acc = [0.0f32; B];
        for (c, &qc) in query.iter().enumerate() {
            let row = &projected[c * n + j0..c * n + j0 + B];
            for (a, &v) in acc.iter_mut().zip(row) {
                *a += (qc - v) * (qc - v);
            }
        }
        acc
    }
    let n = out.len();
    debug_assert_eq!(n % 8, 0);
    let mut j0 = 0;
    while j0 + 32 <= n {
        out[j0..j0 + 32].copy_from_slice(&block::<32>(query, projected, n, j0));
        j0 += 32;
    }
    while j0 + 8 <= n {
        out[j0..j0 + 8].copy_from_slice(&block::<8>(query, projected, n, j0));
        j0 += 8;
    }
}

/// Indices of four low values of `values` (length a multiple of 8, not empty): the
/// least of each of the 8 interleaved lanes (j mod 8) is found in one vectorised
/// pass, and the four least of those are returned. The least value overall is among
/// them.
#[inline(always)]
pub(super) fn four_low(values: &[f32]) -> [usize; 4] {
    let mut least = [f32::INFINITY; 8];
    let mut at = [0u32; 8];
    for (c, chunk) in values.chunks_exact(8).enumerate() {
        for l in 0..8 {
            let better = chunk[l] < least[l];
            least[l] = if better { chunk[l] } else { least[l] };
            at[l] = if better { (c * 8 + l) as u32 } else { at[l] };
        }
    }
    let mut lanes: [usize; 8] = std::array::from_fn(|l| l);
    lanes.sort_by(|&a, &b| least[a].total_cmp(&least[b]).then(a.cmp(&b)));
    std::array::from_fn(|k| at[lanes[k]] as usize)
}

/// Relative and absolute margins on the pruning stage's squared bounds (see
/// [`prune_sum`]), far above the rounding of the descriptions and sums (~1e-6
/// relative) and far below the squared costs that matter (~1e-3).
pub(super) const PRUNE_BOUND_MARGIN: f32 = 1.001;
pub(super) const PRUNE_BOUND_SLACK: f32 = 1e-8;

//! The exact stage's costs: the cost of a pair of samples, the cost matrix of a
//! query and a template, and their assignment cost.

#[cfg(target_arch = "x86_64")]
use super::columns::QueryColumns;
#[cfg(target_arch = "x86_64")]
use super::cost_kernel::{cost_rows_avx512, cost_rows_fma};
use crate::assignment::{assignment_with_outliers, AssignmentWorkspace};
use crate::descriptor::SurfaceContext;

/// Cost of pairing query sample i with template sample j.
#[inline]
pub(super) fn pair_cost(
    q: &SurfaceContext,
    i: usize,
    t: &SurfaceContext,
    j: usize,
    lw: f32,
) -> f32 {
    let (a, b) = (q.positions[i], t.positions[j]);
    crate::descriptor::descriptor_distance(q.descriptor(i), t.descriptor(j))
        + lw * planar_distance(a, b)
}

/// Distance of two normalised sample positions (a plain square root: vectorises,
/// unlike `hypot`, and the positions are of order 1, far from overflow).
#[inline]
pub(super) fn planar_distance(a: [f32; 2], b: [f32; 2]) -> f32 {
    ((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1])).sqrt()
}

/// The `pair_cost` of every template sample (rows) with every query sample (columns),
/// row-major into `cost` (m × n: the assignment is the same problem transposed).
///
/// With AVX2 and FMA (detected at run time): a vector holds 8 query samples
/// ([`QueryColumns`]), so the squared differences accumulate along the descriptor
/// with no sums across lanes, and 4 template samples × 16 query samples give 8
/// independent chains of fused multiply-adds. The values differ from `pair_cost`
/// only by rounding (the order of the sum and the fused multiply-add; tested to
/// 1e-5 relative).
pub(super) fn cost_matrix(
    q: &SurfaceContext,
    columns: &QueryColumns,
    t: &SurfaceContext,
    lw: f32,
    cost: &mut Vec<f64>,
) {
    let (n, m) = (q.len(), t.len());
    cost.clear();
    cost.resize(n * m, 0.0);
    let mut from = 0;
    #[cfg(target_arch = "x86_64")]
    if q.dim == t.dim {
        if crate::cpu::avx512() {
            // SAFETY: the CPU supports AVX-512F (checked by `avx512`).
            from = unsafe { cost_rows_avx512(columns, t, lw, n, cost) };
        } else if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            from = unsafe { cost_rows_fma(columns, t, lw, n, cost) };
        }
    }
    let _ = columns; // read by the x86_64 kernel only
    for j in from..m {
        for i in 0..n {
            cost[j * n + i] = pair_cost(q, i, t, j, lw) as f64;
        }
    }
}

/// Mean cost per sample of the best one-to-one assignment with outliers.
pub fn matching_cost(
    q: &SurfaceContext,
    t: &SurfaceContext,
    location_weight: f64,
    dummy_cost: f64,
    ws: &mut AssignmentWorkspace,
    cost: &mut Vec<f64>,
    assign: &mut Vec<Option<usize>>,
) -> f64 {
    let columns = QueryColumns::new(q);
    let scratch = MatchScratch { ws, cost, assign };
    matching_cost_with(q, &columns, t, (location_weight, dummy_cost), scratch)
}

/// The storage [`matching_cost_with`] reuses across templates: the assignment's
/// workspace, the cost matrix and the assignment.
pub(super) struct MatchScratch<'s> {
    pub ws: &'s mut AssignmentWorkspace,
    pub cost: &'s mut Vec<f64>,
    pub assign: &'s mut Vec<Option<usize>>,
}

/// [`matching_cost`] with the query's [`QueryColumns`] made already (and the location
/// weight and the dummy cost as a pair).
pub(super) fn matching_cost_with(
    q: &SurfaceContext,
    columns: &QueryColumns,
    t: &SurfaceContext,
    (location_weight, dummy_cost): (f64, f64),
    scratch: MatchScratch<'_>,
) -> f64 {
    let MatchScratch { ws, cost, assign } = scratch;
    let (n, m) = (q.len(), t.len());
    cost_matrix(q, columns, t, location_weight as f32, cost);
    // Template samples as rows: the optimal total is the same either way round.
    let total = assignment_with_outliers(cost, m, n, dummy_cost, ws, assign)
        .expect("cost matrix sized and finite by construction");
    total / n.max(m) as f64
}

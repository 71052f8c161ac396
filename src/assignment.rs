//! Exact minimum-cost one-to-one assignment (linear assignment problem).
//!
//! Shortest augmenting paths with row/column potentials (the Hungarian method in the
//! form of Jonker and Volgenant, organised as Crouse 2016 describes it): rows are added
//! one at a time, each by a Dijkstra search over reduced costs `c[i][j] − u[i] − v[j]
//! ≥ 0` that relaxes every column from each row it reaches (a branch-free scan that
//! vectorises; settled columns hold NaN and drop out of every comparison), breaks ties
//! toward a free column (which ends the search) and updates the potentials once per
//! row. The whole solve is O(n²·m) for n ≤ m rows. Outliers are handled by
//! [`assignment_with_outliers`]: every item may stay unmatched at a fixed dummy cost.
//!
//! Jonker and Volgenant's column reduction and augmenting row reduction are not used:
//! with the vectorised scan they make the matcher's solves slower, not faster.

use crate::error::{ensure, Result};

/// Reusable storage for [`solve_assignment_into`] (no allocation once warmed up).
#[derive(Debug, Clone, Default)]
pub struct AssignmentWorkspace {
    /// Row and column potentials.
    u: Vec<f64>,
    v: Vec<f64>,
    /// Per column, in the current search: length of the shortest alternating path
    /// found to it (NaN once settled, see `settled`), and the row it was reached from.
    shortest: Vec<f64>,
    path: Vec<usize>,
    /// The current assignment both ways ([`NONE`] where free).
    row_col: Vec<usize>,
    col_row: Vec<usize>,
    /// Rows and columns the current search has reached.
    row_seen: Vec<bool>,
    col_seen: Vec<bool>,
    /// Per column settled in the current search: its final distance.
    settled: Vec<f64>,
    /// Columns not assigned yet.
    free_cols: Vec<usize>,
    /// Padded square cost matrix of [`assignment_with_outliers`].
    padded: Vec<f64>,
}

/// Sentinel "none" in the row ↔ column maps.
const NONE: usize = usize::MAX;

/// Minimum-cost assignment of every row of the `rows`×`cols` row-major `cost` matrix
/// (`rows ≤ cols`, all entries finite) to a distinct column. Writes the column of each
/// row into `row_to_col` and returns the total cost.
pub fn solve_assignment_into(
    cost: &[f64],
    rows: usize,
    cols: usize,
    ws: &mut AssignmentWorkspace,
    row_to_col: &mut Vec<usize>,
) -> Result<f64> {
    ensure(rows <= cols, "cost", || {
        format!("needs rows <= cols, got {rows}x{cols}")
    })?;
    ensure(cost.len() == rows * cols, "cost", || {
        format!(
            "has {} values, {rows}x{cols} needs {}",
            cost.len(),
            rows * cols
        )
    })?;
    ensure(cost.iter().all(|c| c.is_finite()), "cost", || {
        "all costs must be finite".to_string()
    })?;
    row_to_col.clear();
    if rows == 0 {
        return Ok(0.0);
    }
    let reset = |v: &mut Vec<f64>, n: usize| {
        v.clear();
        v.resize(n, 0.0);
    };
    reset(&mut ws.u, rows);
    reset(&mut ws.v, cols);
    ws.row_col.clear();
    ws.row_col.resize(rows, NONE);
    ws.col_row.clear();
    ws.col_row.resize(cols, NONE);
    ws.shortest.resize(cols, 0.0);
    ws.path.resize(cols, NONE);
    ws.row_seen.resize(rows, false);
    ws.col_seen.resize(cols, false);
    assign_rows(cost, rows, cols, ws);
    row_to_col.extend_from_slice(&ws.row_col);
    Ok(row_to_col
        .iter()
        .enumerate()
        .map(|(i, &j)| cost[i * cols + j])
        .sum())
}

/// One step of the search: row `i`, reached at distance `base + u[i]`, relaxes every
/// column (`shortest[j] = min(shortest[j], base + row[j] − v[j])`, `path[j] = i`
/// where that lowered it) and returns the least `shortest` and the first column
/// holding it. Settled columns hold NaN, which no comparison accepts, so they are
/// neither relaxed nor picked; that keeps the scan free of branches.
fn relax_row(
    row: &[f64],
    v: &[f64],
    base: f64,
    i: usize,
    shortest: &mut [f64],
    path: &mut [usize],
) -> (f64, usize) {
    #[cfg(target_arch = "x86_64")]
    {
        if crate::cpu::avx512() {
            // SAFETY: the CPU supports AVX-512F (checked by `avx512`).
            return unsafe { relax_row_avx512(row, v, base, i, shortest, path) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { relax_row_avx2(row, v, base, i, shortest, path) };
        }
    }
    relax_columns(row, v, base, i, shortest, path, Partial::START)
}

/// How far a row's relaxation has gone when [`relax_columns`] takes it over: the first
/// column left, and the least distance so far with its column.
#[derive(Debug, Clone, Copy)]
struct Partial {
    from: usize,
    least: f64,
    pick: usize,
}

impl Partial {
    /// Nothing relaxed yet.
    const START: Partial = Partial {
        from: 0,
        least: f64::INFINITY,
        pick: NONE,
    };
}

/// [`relax_row`] from column `partial.from` on, continuing the search for the least
/// from `partial`.
#[inline(always)]
fn relax_columns(
    row: &[f64],
    v: &[f64],
    base: f64,
    i: usize,
    shortest: &mut [f64],
    path: &mut [usize],
    partial: Partial,
) -> (f64, usize) {
    let Partial {
        from,
        mut least,
        mut pick,
    } = partial;
    for j in from..shortest.len() {
        let r = base + row[j] - v[j];
        if r < shortest[j] {
            shortest[j] = r;
            path[j] = i;
        }
        if shortest[j] < least {
            least = shortest[j];
            pick = j;
        }
    }
    (least, pick)
}

/// The vector kernels' final step: the least of the per-lane minima `lanes`, at its
/// first column (`cols`, −1 where a lane saw none), as the portable scan would pick it.
fn least_across_lanes(lanes: &[f64], cols: &[i64]) -> (f64, usize) {
    let mut best = (f64::INFINITY, NONE);
    for (&d, &j) in lanes.iter().zip(cols) {
        if j >= 0 && (d < best.0 || (d == best.0 && (j as usize) < best.1)) {
            best = (d, j as usize);
        }
    }
    best
}

/// [`relax_row`] with AVX-512, eight columns at a time, the blends and the path
/// writes under mask registers; the same arithmetic and the same result.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn relax_row_avx512(
    row: &[f64],
    v: &[f64],
    base: f64,
    i: usize,
    shortest: &mut [f64],
    path: &mut [usize],
) -> (f64, usize) {
    use std::arch::x86_64::*;
    let n = shortest.len();
    assert!(row.len() >= n && v.len() >= n && path.len() >= n);
    let full = n / 8 * 8;
    let basev = _mm512_set1_pd(base);
    let rowv = _mm512_set1_epi64(i as i64);
    let (mut least, mut at) = (_mm512_set1_pd(f64::INFINITY), _mm512_set1_epi64(-1));
    let (mut index, eight) = (
        _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7),
        _mm512_set1_epi64(8),
    );
    for c in (0..full).step_by(8) {
        // SAFETY: c + 8 <= full <= n, within every slice (asserted above); usize is
        // 64 bits on x86_64.
        let r = _mm512_sub_pd(
            _mm512_add_pd(basev, _mm512_loadu_pd(row.as_ptr().add(c))),
            _mm512_loadu_pd(v.as_ptr().add(c)),
        );
        let s = _mm512_loadu_pd(shortest.as_ptr().add(c));
        let closer = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(r, s);
        let s = _mm512_mask_blend_pd(closer, s, r);
        _mm512_storeu_pd(shortest.as_mut_ptr().add(c), s);
        _mm512_mask_storeu_epi64(path.as_mut_ptr().add(c) as *mut i64, closer, rowv);
        let lower = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(s, least);
        least = _mm512_mask_blend_pd(lower, least, s);
        at = _mm512_mask_blend_epi64(lower, at, index);
        index = _mm512_add_epi64(index, eight);
    }
    let (mut lanes, mut cols) = ([0.0f64; 8], [0i64; 8]);
    _mm512_storeu_pd(lanes.as_mut_ptr(), least);
    _mm512_storeu_epi64(cols.as_mut_ptr(), at);
    let (least, pick) = least_across_lanes(&lanes, &cols);
    let partial = Partial {
        from: full,
        least,
        pick,
    };
    relax_columns(row, v, base, i, shortest, path, partial)
}

/// [`relax_row`] with AVX2, four columns at a time; the same arithmetic and the same
/// result.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn relax_row_avx2(
    row: &[f64],
    v: &[f64],
    base: f64,
    i: usize,
    shortest: &mut [f64],
    path: &mut [usize],
) -> (f64, usize) {
    use std::arch::x86_64::*;
    let n = shortest.len();
    assert!(row.len() >= n && v.len() >= n && path.len() >= n);
    let full = n / 4 * 4;
    let basev = _mm256_set1_pd(base);
    let rowv = _mm256_castsi256_pd(_mm256_set1_epi64x(i as i64));
    let (mut least, mut at) = (_mm256_set1_pd(f64::INFINITY), _mm256_set1_epi64x(-1));
    let (mut index, four) = (_mm256_setr_epi64x(0, 1, 2, 3), _mm256_set1_epi64x(4));
    for c in (0..full).step_by(4) {
        // SAFETY: c + 4 <= full <= n, within every slice (asserted above).
        let r = _mm256_sub_pd(
            _mm256_add_pd(basev, _mm256_loadu_pd(row.as_ptr().add(c))),
            _mm256_loadu_pd(v.as_ptr().add(c)),
        );
        let s = _mm256_loadu_pd(shortest.as_ptr().add(c));
        let closer = _mm256_cmp_pd::<_CMP_LT_OQ>(r, s);
        let s = _mm256_blendv_pd(s, r, closer);
        _mm256_storeu_pd(shortest.as_mut_ptr().add(c), s);
        let pp = path.as_mut_ptr().add(c) as *mut __m256i;
        let p = _mm256_castsi256_pd(_mm256_loadu_si256(pp));
        _mm256_storeu_si256(pp, _mm256_castpd_si256(_mm256_blendv_pd(p, rowv, closer)));
        let lower = _mm256_cmp_pd::<_CMP_LT_OQ>(s, least);
        least = _mm256_blendv_pd(least, s, lower);
        at = _mm256_castpd_si256(_mm256_blendv_pd(
            _mm256_castsi256_pd(at),
            _mm256_castsi256_pd(index),
            lower,
        ));
        index = _mm256_add_epi64(index, four);
    }
    let (mut lanes, mut cols) = ([0.0f64; 4], [0i64; 4]);
    _mm256_storeu_pd(lanes.as_mut_ptr(), least);
    _mm256_storeu_si256(cols.as_mut_ptr() as *mut __m256i, at);
    let (least, pick) = least_across_lanes(&lanes, &cols);
    let partial = Partial {
        from: full,
        least,
        pick,
    };
    relax_columns(row, v, base, i, shortest, path, partial)
}

/// Assigns the rows one at a time, each by a Dijkstra search over reduced costs from
/// it to a free column, then updates the potentials and flips the path.
///
/// Each row the search reaches relaxes every column ([`relax_row`]); a settled
/// column's distance moves to `settled`. The next column to settle is one of least
/// distance: a free one among equals if there is one (it ends the search; looked for
/// among the free columns only when the first such column is taken), else the first.
fn assign_rows(cost: &[f64], rows: usize, cols: usize, ws: &mut AssignmentWorkspace) {
    ws.settled.clear();
    ws.settled.resize(cols, 0.0);
    // Nothing is assigned yet: every column starts free.
    ws.free_cols.clear();
    ws.free_cols.extend(0..cols);
    for start in 0..rows {
        ws.shortest.fill(f64::INFINITY);
        ws.row_seen.fill(false);
        ws.col_seen.fill(false);
        let mut reached = 0.0f64;
        let mut i = start;
        let sink = loop {
            ws.row_seen[i] = true;
            let row = &cost[i * cols..(i + 1) * cols];
            let base = reached - ws.u[i];
            let (least, mut pick) = relax_row(
                row,
                &ws.v[..cols],
                base,
                i,
                &mut ws.shortest[..cols],
                &mut ws.path[..cols],
            );
            // Finite costs: every column is reachable, so `least` is finite.
            if ws.col_row[pick] != NONE {
                if let Some(&j) = ws.free_cols.iter().find(|&&j| ws.shortest[j] == least) {
                    pick = j;
                }
            }
            reached = least;
            ws.settled[pick] = least;
            ws.shortest[pick] = f64::NAN;
            ws.col_seen[pick] = true;
            if ws.col_row[pick] == NONE {
                break pick;
            }
            i = ws.col_row[pick];
        };
        if let Some(k) = ws.free_cols.iter().position(|&j| j == sink) {
            ws.free_cols.swap_remove(k);
        }
        // Potentials: the reached rows and columns move by how far inside the search
        // radius they lie, which keeps every reduced cost ≥ 0 and the new path tight.
        ws.u[start] += reached;
        for r in 0..rows {
            if ws.row_seen[r] && r != start {
                ws.u[r] += reached - ws.settled[ws.row_col[r]];
            }
        }
        for c in 0..cols {
            if ws.col_seen[c] {
                ws.v[c] -= reached - ws.settled[c];
            }
        }
        // Flip the alternating path from the free column back to the new row.
        let mut j = sink;
        loop {
            let r = ws.path[j];
            ws.col_row[j] = r;
            let previous = std::mem::replace(&mut ws.row_col[r], j);
            if r == start {
                break;
            }
            j = previous;
        }
    }
}

/// Minimum total cost of a one-to-one matching between `rows` and `cols` items where
/// any item may instead stay unmatched at `dummy` cost each.
///
/// Exact, by an equivalent square problem of size max(rows, cols): a real pair costs
/// min(c, 2·dummy) (a pair dearer than two outliers is two outliers), and the missing
/// rows or columns are dummies that cost `dummy` against every real item. Writes the
/// matched column of each row (or `None` for an outlier) into `row_to_col`.
pub fn assignment_with_outliers(
    cost: &[f64],
    rows: usize,
    cols: usize,
    dummy: f64,
    ws: &mut AssignmentWorkspace,
    row_to_col: &mut Vec<Option<usize>>,
) -> Result<f64> {
    ensure(dummy.is_finite() && dummy >= 0.0, "dummy", || {
        format!("must be finite and >= 0, got {dummy}")
    })?;
    ensure(cost.len() == rows * cols, "cost", || {
        format!(
            "has {} values, {rows}x{cols} needs {}",
            cost.len(),
            rows * cols
        )
    })?;
    let n = rows.max(cols);
    let cap = 2.0 * dummy;
    let mut padded = std::mem::take(&mut ws.padded);
    padded.clear();
    padded.resize(n * n, dummy);
    for i in 0..rows {
        for j in 0..cols {
            padded[i * n + j] = cost[i * cols + j].min(cap);
        }
    }
    let mut assign = Vec::with_capacity(n);
    let total = solve_assignment_into(&padded, n, n, ws, &mut assign);
    ws.padded = padded;
    let total = total?;
    row_to_col.clear();
    row_to_col.extend((0..rows).map(|i| {
        let j = assign[i];
        (j < cols && cost[i * cols + j] < cap).then_some(j)
    }));
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force(cost: &[f64], rows: usize, cols: usize) -> f64 {
        // Every injective map rows → cols, recursively.
        fn go(cost: &[f64], rows: usize, cols: usize, i: usize, used: &mut Vec<bool>) -> f64 {
            if i == rows {
                return 0.0;
            }
            let mut best = f64::INFINITY;
            for j in 0..cols {
                if !used[j] {
                    used[j] = true;
                    best = best.min(cost[i * cols + j] + go(cost, rows, cols, i + 1, used));
                    used[j] = false;
                }
            }
            best
        }
        go(cost, rows, cols, 0, &mut vec![false; cols])
    }

    /// Outlier formulation by brute force: each row picks a free column or stays out.
    fn brute_outliers(cost: &[f64], rows: usize, cols: usize, dummy: f64) -> f64 {
        fn go(c: &[f64], rows: usize, cols: usize, d: f64, i: usize, used: &mut Vec<bool>) -> f64 {
            if i == rows {
                return d * used.iter().filter(|u| !**u).count() as f64;
            }
            let mut best = d + go(c, rows, cols, d, i + 1, used);
            for j in 0..cols {
                if !used[j] {
                    used[j] = true;
                    best = best.min(c[i * cols + j] + go(c, rows, cols, d, i + 1, used));
                    used[j] = false;
                }
            }
            best
        }
        go(cost, rows, cols, dummy, 0, &mut vec![false; cols])
    }

    proptest! {
        #[test]
        fn matches_brute_force(rows in 1usize..6, extra in 0usize..3,
                               vals in prop::collection::vec(-5.0f64..10.0, 64)) {
            let cols = rows + extra;
            let cost: Vec<f64> = vals[..rows * cols].to_vec();
            let mut ws = AssignmentWorkspace::default();
            let mut a = Vec::new();
            let total = solve_assignment_into(&cost, rows, cols, &mut ws, &mut a).unwrap();
            prop_assert!((total - brute_force(&cost, rows, cols)).abs() < 1e-9);
            // A valid injective assignment whose cost is the reported total.
            let mut seen = vec![false; cols];
            let mut sum = 0.0;
            for (i, &j) in a.iter().enumerate() {
                prop_assert!(!seen[j]);
                seen[j] = true;
                sum += cost[i * cols + j];
            }
            prop_assert!((sum - total).abs() < 1e-9);
        }

        #[test]
        fn square_with_ties_matches_brute_force(n in 1usize..6,
                                               vals in prop::collection::vec(0u8..3, 36)) {
            // Few distinct costs: many ties for the search to break.
            let cost: Vec<f64> = vals[..n * n].iter().map(|&v| v as f64).collect();
            let mut ws = AssignmentWorkspace::default();
            let mut a = Vec::new();
            let total = solve_assignment_into(&cost, n, n, &mut ws, &mut a).unwrap();
            prop_assert_eq!(total, brute_force(&cost, n, n));
            let mut seen = vec![false; n];
            for &j in &a {
                prop_assert!(!seen[j]);
                seen[j] = true;
            }
        }

        /// The square solve against the solve of the same rows beside one extra,
        /// never-needed column: equal optimal totals, on sizes brute force cannot
        /// reach, with and without many ties (they exercise the search's choice
        /// among columns at equal distance).
        #[test]
        fn square_solve_equals_solve_with_a_spare_column(n in 1usize..40, levels in 1u32..6,
                                                       seed in any::<u64>()) {
            let mut s = seed;
            let cost: Vec<f64> = (0..n * n)
                .map(|_| {
                    s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    ((s >> 33) % levels as u64) as f64 + if levels == 5 { (s >> 40) as f64 * 1e-7 } else { 0.0 }
                })
                .collect();
            let mut wide = Vec::with_capacity(n * (n + 1));
            for i in 0..n {
                wide.extend_from_slice(&cost[i * n..(i + 1) * n]);
                wide.push(1e6);
            }
            let mut ws = AssignmentWorkspace::default();
            let (mut a, mut b) = (Vec::new(), Vec::new());
            let square = solve_assignment_into(&cost, n, n, &mut ws, &mut a).unwrap();
            let plain = solve_assignment_into(&wide, n, n + 1, &mut ws, &mut b).unwrap();
            prop_assert!((square - plain).abs() < 1e-9, "{} vs {}", square, plain);
            let mut seen = vec![false; n];
            for &j in &a {
                prop_assert!(!seen[j]);
                seen[j] = true;
            }
        }

        #[test]
        fn outliers_match_brute_force(rows in 0usize..6, cols in 0usize..6,
                                      dummy in 0.0f64..4.0,
                                      vals in prop::collection::vec(0.0f64..10.0, 36)) {
            let cost: Vec<f64> = vals[..rows * cols].to_vec();
            let mut ws = AssignmentWorkspace::default();
            let mut a = Vec::new();
            let total = assignment_with_outliers(&cost, rows, cols, dummy, &mut ws, &mut a).unwrap();
            let want = brute_outliers(&cost, rows, cols, dummy);
            prop_assert!((total - want).abs() < 1e-9, "{} vs {}", total, want);
            let matched = a.iter().flatten().count();
            let mut sum = dummy * (rows + cols - 2 * matched) as f64;
            for (i, j) in a.iter().enumerate() {
                if let Some(j) = j { sum += cost[i * cols + j]; }
            }
            prop_assert!((sum - total).abs() < 1e-9);
        }
    }

    /// The AVX2 and AVX-512 scans (each where the CPU has it) against the portable
    /// one: same distances, paths, least and pick, with settled (NaN) columns, ties
    /// and lengths that are not multiples of 4 or 8.
    #[test]
    fn vectorised_relaxation_equals_portable() {
        let mut s = 5u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) as usize
        };
        type Kernel = fn(&[f64], &[f64], f64, usize, &mut [f64], &mut [usize]) -> (f64, usize);
        let mut kernels: Vec<(&str, Kernel)> = vec![("dispatch", relax_row)];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: only called on a CPU with AVX2 (checked just above).
                kernels.push(("avx2", |r, v, b, i, s, p| unsafe {
                    relax_row_avx2(r, v, b, i, s, p)
                }));
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: only called on a CPU with AVX-512F (checked just above).
                kernels.push(("avx512", |r, v, b, i, s, p| unsafe {
                    relax_row_avx512(r, v, b, i, s, p)
                }));
            }
        }
        for n in [1usize, 3, 4, 7, 8, 9, 16, 17, 101] {
            for _ in 0..20 {
                let row: Vec<f64> = (0..n).map(|_| (next() % 5) as f64 * 0.25).collect();
                let v: Vec<f64> = (0..n).map(|_| (next() % 3) as f64 * -0.5).collect();
                let shortest: Vec<f64> = (0..n)
                    .map(|_| match next() % 4 {
                        0 => f64::NAN,
                        1 => f64::INFINITY,
                        k => k as f64 * 0.5,
                    })
                    .collect();
                let path: Vec<usize> = (0..n).map(|_| next() % 7).collect();
                let base = (next() % 3) as f64 * 0.5 - 0.5;
                let (mut s2, mut p2) = (shortest.clone(), path.clone());
                let plain = relax_columns(&row, &v, base, 9, &mut s2, &mut p2, Partial::START);
                let bits = |x: &[f64]| x.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
                for (name, kernel) in &kernels {
                    let (mut s1, mut p1) = (shortest.clone(), path.clone());
                    let fast = kernel(&row, &v, base, 9, &mut s1, &mut p1);
                    assert_eq!(fast.1, plain.1, "{name}");
                    assert_eq!(fast.0.to_bits(), plain.0.to_bits(), "{name}");
                    assert_eq!(p1, p2, "{name}");
                    assert_eq!(bits(&s1), bits(&s2), "{name}");
                }
            }
        }
    }

    #[test]
    fn rejects_bad_input() {
        let mut ws = AssignmentWorkspace::default();
        let mut a = Vec::new();
        assert!(solve_assignment_into(&[1.0; 6], 3, 2, &mut ws, &mut a).is_err());
        assert!(solve_assignment_into(&[1.0; 5], 2, 3, &mut ws, &mut a).is_err());
        assert!(solve_assignment_into(&[f64::NAN, 1.0, 1.0, 1.0], 2, 2, &mut ws, &mut a).is_err());
        let mut b = Vec::new();
        assert!(assignment_with_outliers(&[1.0; 4], 2, 2, -1.0, &mut ws, &mut b).is_err());
    }

    #[test]
    fn larger_instance_is_optimal_against_dual() {
        // 40×40 pseudo-random costs: the primal total equals a valid dual bound.
        let n = 40;
        let mut s = 12345u64;
        let cost: Vec<f64> = (0..n * n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 33) as f64 / (1u64 << 31) as f64
            })
            .collect();
        let mut ws = AssignmentWorkspace::default();
        let mut a = Vec::new();
        let total = solve_assignment_into(&cost, n, n, &mut ws, &mut a).unwrap();
        // Potentials are feasible (reduced costs >= 0) and tight on the assignment.
        let (u, v) = (&ws.u, &ws.v);
        let dual: f64 = u.iter().sum::<f64>() + v.iter().sum::<f64>();
        for i in 0..n {
            for j in 0..n {
                assert!(cost[i * n + j] - u[i] - v[j] > -1e-9);
            }
            assert!((cost[i * n + a[i]] - u[i] - v[a[i]]).abs() < 1e-9);
        }
        assert!((dual - total).abs() < 1e-9);
    }
}

//! Exact minimum-cost one-to-one assignment (linear assignment problem).
//!
//! Shortest augmenting paths with row/column potentials (the Hungarian method in the
//! form of Jonker and Volgenant, organised as Crouse 2016 describes it): rows are added
//! one at a time, each by a Dijkstra search over reduced costs `c[i][j] − u[i] − v[j]
//! ≥ 0` that scans only the columns it has not reached yet, breaks ties toward a free
//! column (which ends the search) and updates the potentials once per row. The whole
//! solve is O(n²·m) for n ≤ m rows. Outliers are handled by
//! [`assignment_with_outliers`]: every item may stay unmatched at a fixed dummy cost.

use crate::error::{ensure, Result};

/// Reusable storage for [`solve_assignment_into`] (no allocation once warmed up).
#[derive(Debug, Clone, Default)]
pub struct AssignmentWorkspace {
    /// Row and column potentials.
    u: Vec<f64>,
    v: Vec<f64>,
    /// Per column, in the current search: length of the shortest alternating path
    /// found to it, and the row it was reached from.
    shortest: Vec<f64>,
    path: Vec<usize>,
    /// The current assignment both ways ([`NONE`] where free).
    row_col: Vec<usize>,
    col_row: Vec<usize>,
    /// Rows and columns the current search has reached.
    row_seen: Vec<bool>,
    col_seen: Vec<bool>,
    /// Columns not reached yet (the first `remaining_len` entries).
    remaining: Vec<usize>,
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
    for start in 0..rows {
        ws.shortest.fill(f64::INFINITY);
        ws.row_seen.fill(false);
        ws.col_seen.fill(false);
        ws.remaining.clear();
        ws.remaining.extend(0..cols);
        let mut remaining_len = cols;
        let mut reached = 0.0f64;
        let mut i = start;
        let sink = loop {
            ws.row_seen[i] = true;
            let row = &cost[i * cols..(i + 1) * cols];
            let base = reached - ws.u[i];
            let mut lowest = f64::INFINITY;
            let mut pick = 0usize;
            for (k, &j) in ws.remaining[..remaining_len].iter().enumerate() {
                let r = base + row[j] - ws.v[j];
                if r < ws.shortest[j] {
                    ws.path[j] = i;
                    ws.shortest[j] = r;
                }
                let d = ws.shortest[j];
                if d < lowest || (d == lowest && ws.col_row[j] == NONE) {
                    lowest = d;
                    pick = k;
                }
            }
            // Finite costs: every column is reachable, so `lowest` is finite.
            reached = lowest;
            let j = ws.remaining[pick];
            ws.col_seen[j] = true;
            remaining_len -= 1;
            ws.remaining.swap(pick, remaining_len);
            if ws.col_row[j] == NONE {
                break j;
            }
            i = ws.col_row[j];
        };
        // Potentials: the reached rows and columns move by how far inside the search
        // radius they lie, which keeps every reduced cost ≥ 0 and the new path tight.
        ws.u[start] += reached;
        for r in 0..rows {
            if ws.row_seen[r] && r != start {
                ws.u[r] += reached - ws.shortest[ws.row_col[r]];
            }
        }
        for c in 0..cols {
            if ws.col_seen[c] {
                ws.v[c] -= reached - ws.shortest[c];
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
    row_to_col.extend_from_slice(&ws.row_col);
    Ok(row_to_col
        .iter()
        .enumerate()
        .map(|(i, &j)| cost[i * cols + j])
        .sum())
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

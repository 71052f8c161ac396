//! Exact minimum-cost one-to-one assignment (linear assignment problem).
//!
//! Shortest augmenting paths with row/column potentials (the Hungarian method in the
//! form Jonker and Volgenant build on): rows are added one at a time, each by a
//! Dijkstra-like search over reduced costs `c[i][j] − u[i] − v[j] ≥ 0`, so the whole
//! solve is O(n²·m) for n ≤ m rows. Outliers are handled by [`assignment_with_outliers`]:
//! every item may stay unmatched at a fixed dummy cost.

use crate::error::{ensure, Result};

/// Reusable storage for [`solve_assignment_into`] (no allocation once warmed up).
#[derive(Debug, Clone, Default)]
pub struct AssignmentWorkspace {
    u: Vec<f64>,
    v: Vec<f64>,
    way: Vec<usize>,
    col_row: Vec<usize>,
    min_slack: Vec<f64>,
    used: Vec<bool>,
    /// Padded square cost matrix of [`assignment_with_outliers`].
    padded: Vec<f64>,
}

/// Sentinel "no row" in the column → row map.
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
    row_to_col.resize(rows, NONE);
    if rows == 0 {
        return Ok(0.0);
    }
    // Column index 0 is a virtual column holding the row being inserted; real columns
    // are 1..=cols.
    ws.u.clear();
    ws.u.resize(rows + 1, 0.0);
    ws.v.clear();
    ws.v.resize(cols + 1, 0.0);
    ws.way.clear();
    ws.way.resize(cols + 1, 0);
    ws.col_row.clear();
    ws.col_row.resize(cols + 1, NONE);
    ws.min_slack.resize(cols + 1, 0.0);
    ws.used.resize(cols + 1, false);
    for i in 0..rows {
        ws.col_row[0] = i;
        let mut j0 = 0usize;
        ws.min_slack.fill(f64::INFINITY);
        ws.used.fill(false);
        loop {
            ws.used[j0] = true;
            let i0 = ws.col_row[j0];
            let row = &cost[i0 * cols..(i0 + 1) * cols];
            let ui = ws.u[i0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0usize;
            for j in 1..=cols {
                if ws.used[j] {
                    continue;
                }
                let reduced = row[j - 1] - ui - ws.v[j];
                if reduced < ws.min_slack[j] {
                    ws.min_slack[j] = reduced;
                    ws.way[j] = j0;
                }
                if ws.min_slack[j] < delta {
                    delta = ws.min_slack[j];
                    j1 = j;
                }
            }
            for j in 0..=cols {
                if ws.used[j] {
                    ws.u[ws.col_row[j]] += delta;
                    ws.v[j] -= delta;
                } else {
                    ws.min_slack[j] -= delta;
                }
            }
            j0 = j1;
            if ws.col_row[j0] == NONE {
                break;
            }
        }
        // Augment along the alternating path back to the virtual column.
        loop {
            let j1 = ws.way[j0];
            ws.col_row[j0] = ws.col_row[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut total = 0.0;
    for j in 1..=cols {
        let i = ws.col_row[j];
        if i != NONE {
            row_to_col[i] = j - 1;
            total += cost[i * cols + j - 1];
        }
    }
    Ok(total)
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
        let dual: f64 = u[..n].iter().sum::<f64>() + v[1..].iter().sum::<f64>();
        for i in 0..n {
            for j in 0..n {
                assert!(cost[i * n + j] - u[i] - v[j + 1] > -1e-9);
            }
        }
        assert!((dual - total).abs() < 1e-9);
    }
}

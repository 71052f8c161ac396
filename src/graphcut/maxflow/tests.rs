#![allow(clippy::needless_range_loop)]

use super::capacity::Capacity;
use super::grid::grid_edges;
use super::layout::MAX_TIME;
use super::Graph;
use crate::error::{Error, Result};
use proptest::prelude::*;
use std::fmt::Debug;

/// A random small graph: n nodes, edges (i, j, c, r), terminal caps (s, t).
#[derive(Clone, Debug)]
struct Problem {
    n: usize,
    edges: Vec<(usize, usize, i64, i64)>,
    terms: Vec<(i64, i64)>,
}

fn problem(max_n: usize) -> impl Strategy<Value = Problem> {
    (1..=max_n).prop_flat_map(|n| {
        let edges = prop::collection::vec((0..n, 0..n, 0i64..10, 0i64..10), 0..(3 * n));
        let terms = prop::collection::vec((0i64..12, 0i64..12), n);
        (Just(n), edges, terms).prop_map(|(n, edges, terms)| Problem { n, edges, terms })
    })
}

fn cut_value(p: &Problem, sink_side: &[bool]) -> i64 {
    let mut v = 0;
    for (i, &(s, t)) in p.terms.iter().enumerate() {
        v += if sink_side[i] { s } else { t };
    }
    for &(i, j, c, r) in &p.edges {
        if !sink_side[i] && sink_side[j] {
            v += c;
        }
        if sink_side[i] && !sink_side[j] {
            v += r;
        }
    }
    v
}

fn brute_min_cut(p: &Problem) -> i64 {
    (0..1u32 << p.n)
        .map(|mask| {
            let side: Vec<bool> = (0..p.n).map(|i| mask >> i & 1 == 1).collect();
            cut_value(p, &side)
        })
        .min()
        .unwrap()
}

fn graph_of(p: &Problem) -> Graph<i64> {
    let mut g = Graph::new(p.n);
    g.track_terminal_caps();
    g.keep_edge_index();
    for &(i, j, c, r) in &p.edges {
        g.add_edge(i, j, c, r).unwrap();
    }
    for (i, &(s, t)) in p.terms.iter().enumerate() {
        g.add_tweights(i, s, t).unwrap();
    }
    g
}

/// Replaces the terminal capacities of nodes `i % n` in `g` (a dynamic update) and
/// returns the problem with the same changes.
fn set_terminals(p: &Problem, g: &mut Graph<i64>, changes: &[(usize, i64, i64)]) -> Problem {
    let mut q = p.clone();
    for &(i, s, t) in changes {
        let i = i % p.n;
        q.terms[i] = (s, t);
        g.set_tweights(i, s, t).unwrap();
    }
    q
}

/// Flow on every edge from residuals must respect capacities and conservation.
/// After a dynamic update the flow is one of the reparametrised graph (both terminal
/// arcs of a node raised alike), so terminal feasibility is only checked when fresh.
fn check_flow(p: &Problem, g: &Graph<i64>, fresh: bool) {
    let mut net_out = vec![0i64; p.n]; // net flow leaving each node over edges
    for (k, &(i, j, c, r)) in p.edges.iter().enumerate() {
        let (rc, rr) = g.edge_residual(k).unwrap();
        if i == j {
            continue;
        }
        // Residuals sum to the total capacity; flow i→j = c - rc = rr - r.
        assert_eq!(rc + rr, c + r);
        let f = c - rc;
        assert!(-r <= f && f <= c, "edge flow {f} outside [-{r}, {c}]");
        net_out[i] += f;
        net_out[j] -= f;
    }
    // Terminal flows: s_i - t_i = net_out_i with 0 ≤ s_i ≤ cs, 0 ≤ t_i ≤ ct, and the
    // residual tr = cs - ct - net_out.
    let mut total = 0;
    for i in 0..p.n {
        let (cs, ct) = p.terms[i];
        assert_eq!(g.terminal_residual(i), cs - ct - net_out[i]);
        if !fresh {
            continue;
        }
        // Feasible split with s_i ≤ cs and t_i ≤ ct.
        let t_i = ct.min(cs - net_out[i]);
        let s_i = t_i + net_out[i];
        assert!(s_i >= 0 && s_i <= cs && t_i >= 0 && t_i <= ct);
        total += s_i;
    }
    if fresh {
        assert_eq!(total, g.flow());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn maxflow_equals_brute_force_min_cut(p in problem(9)) {
        let mut g = graph_of(&p);
        let f = g.maxflow();
        let best = brute_min_cut(&p);
        prop_assert_eq!(f, best);
        prop_assert_eq!(cut_value(&p, &g.segments()), best);
        check_flow(&p, &g, true);
    }

    #[test]
    fn dynamic_resolve_equals_fresh(p in problem(8), changes in prop::collection::vec((0usize..8, 0i64..12, 0i64..12), 1..6)) {
        let mut g = graph_of(&p);
        g.maxflow();
        let q = set_terminals(&p, &mut g, &changes);
        let f = g.maxflow();
        let mut fresh = graph_of(&q);
        let f2 = fresh.maxflow();
        prop_assert_eq!(f, f2);
        prop_assert_eq!(f, brute_min_cut(&q));
        prop_assert_eq!(cut_value(&q, &g.segments()), f);
        check_flow(&q, &g, false);
    }

    #[test]
    fn float_maxflow_matches_integer(p in problem(8)) {
        let mut gi = graph_of(&p);
        let mut gf = Graph::<f64>::new(p.n);
        for &(i, j, c, r) in &p.edges {
            gf.add_edge(i, j, c as f64, r as f64).unwrap();
        }
        for (i, &(s, t)) in p.terms.iter().enumerate() {
            gf.add_tweights(i, s as f64, t as f64).unwrap();
        }
        prop_assert_eq!(gi.maxflow() as f64, gf.maxflow());
        prop_assert_eq!(cut_value(&p, &gf.segments()), gi.flow());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// The adoption clock restarting after every 1–3 augmentations (instead of
    /// 65,535) leaves the trees acyclic and the flow exact (a restart that keeps stale
    /// distances makes parent cycles, and the solver loops for ever).
    #[test]
    fn clock_restarts_keep_maxflow_exact(
        p in problem(9),
        max_time in 1u32..4,
        changes in prop::collection::vec((0usize..9, 0i64..12, 0i64..12), 1..4),
    ) {
        let mut g = graph_of(&p);
        g.set_max_time(max_time);
        prop_assert_eq!(g.maxflow(), brute_min_cut(&p));
        check_flow(&p, &g, true);
        g.check_trees();
        let q = set_terminals(&p, &mut g, &changes);
        prop_assert_eq!(g.maxflow(), brute_min_cut(&q));
        prop_assert_eq!(cut_value(&q, &g.segments()), g.flow());
        g.check_trees();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// A fresh solve split into 2–4 parts (each part solved alone, then one search
    /// over the whole graph from the parts' trees) gives the exact maximum flow and
    /// cut and valid trees, which a dynamic re-solve then reuses; also with the
    /// adoption clock restarting after every 1–3 augmentations. Random graphs have
    /// arcs between any parts.
    #[test]
    fn parts_solve_equals_brute_force_min_cut(
        p in problem(9),
        k in 2usize..5,
        max_time in prop::sample::select(vec![1u32, 2, 3, MAX_TIME]),
        changes in prop::collection::vec((0usize..9, 0i64..12, 0i64..12), 1..4),
    ) {
        let mut g = graph_of(&p);
        g.force_parts(k);
        g.set_max_time(max_time);
        let best = brute_min_cut(&p);
        prop_assert_eq!(g.maxflow(), best);
        prop_assert_eq!(cut_value(&p, &g.segments()), best);
        check_flow(&p, &g, true);
        g.check_trees();
        let q = set_terminals(&p, &mut g, &changes);
        prop_assert_eq!(g.maxflow(), brute_min_cut(&q));
        prop_assert_eq!(cut_value(&q, &g.segments()), g.flow());
        check_flow(&q, &g, false);
        g.check_trees();
    }
}

/// A random grid problem: `h`×`w`, 4- or 8-connected, integer capacities below
/// `cap` on the edges and below `tcap` on the terminal arcs.
fn grid_problem(h: usize, w: usize, conn: u8, seed: u64, cap: i64, tcap: i64) -> Problem {
    let mut rng = seed | 1;
    let mut next = move |m: i64| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng % m as u64) as i64
    };
    let edges = grid_edges(h, w, conn).unwrap();
    Problem {
        n: h * w,
        edges: edges
            .iter()
            .map(|&[i, j]| (i as usize, j as usize, next(cap), next(cap)))
            .collect(),
        terms: (0..h * w).map(|_| (next(tcap), next(tcap))).collect(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(60))]

    /// On grids (the case the parts are for: arcs only between neighbouring rows) a
    /// solve in 2–6 parts gives the one-thread solve's flow and the same cut, valid
    /// trees and a conserved flow, and a dynamic re-solve after it matches too.
    #[test]
    fn parts_solve_on_grids_equals_one_part(
        h in 2usize..40,
        w in 2usize..50,
        conn in prop::sample::select(vec![4u8, 8]),
        k in 2usize..7,
        seed in any::<u64>(),
        changes in prop::collection::vec((0usize..2000, 0i64..30, 0i64..30), 1..20),
    ) {
        let p = grid_problem(h, w, conn, seed, 20, 30);
        let mut one = graph_of(&p);
        one.force_parts(1);
        let f = one.maxflow();
        let mut g = graph_of(&p);
        g.force_parts(k);
        prop_assert_eq!(g.maxflow(), f);
        prop_assert_eq!(g.segments(), one.segments());
        check_flow(&p, &g, true);
        g.check_trees();
        let q = set_terminals(&p, &mut g, &changes);
        set_terminals(&p, &mut one, &changes);
        prop_assert_eq!(g.maxflow(), one.maxflow());
        prop_assert_eq!(g.segments(), one.segments());
        check_flow(&q, &g, false);
        g.check_trees();
    }
}

/// The default split: a 256×256 grid is solved in parts when the pool has several
/// threads (65,536 nodes, bandwidth 256), a graph of the same size with long edges
/// and a small grid are not; the split solve matches the one-part solve, in `i64`
/// and `f64`.
#[test]
fn large_grids_are_split_by_default() {
    let p = grid_problem(256, 256, 4, 7, 50, 60);
    let mut g = graph_of(&p);
    g.finalize();
    let threads = rayon::current_num_threads();
    assert_eq!(g.parallel_parts(), threads.clamp(1, 4));
    let mut one = graph_of(&p);
    one.force_parts(1);
    assert_eq!(g.maxflow(), one.maxflow());
    assert_eq!(g.segments(), one.segments());
    g.check_trees();
    let mut gf = Graph::<f64>::new(p.n);
    for &(i, j, c, r) in &p.edges {
        gf.add_edge(i, j, c as f64, r as f64).unwrap();
    }
    for (i, &(s, t)) in p.terms.iter().enumerate() {
        gf.add_tweights(i, s as f64, t as f64).unwrap();
    }
    assert_eq!(gf.maxflow(), one.flow() as f64);
    assert_eq!(gf.segments(), one.segments());

    let mut long = graph_of(&p);
    long.add_edge(0, p.n - 1, 1, 1).unwrap();
    long.finalize();
    assert_eq!(long.parallel_parts(), 1);
    let mut small = graph_of(&grid_problem(100, 100, 4, 3, 5, 5));
    small.finalize();
    assert_eq!(small.parallel_parts(), 1);
}

/// The pass over short paths before the search is greedy: here it sends a's unit to
/// b (a → b is the last edge added, so a's first arc scanned), which leaves d no
/// short path. The search must then undo part of it through the reverse residual of
/// a → b: s → d → b → a → c → t.
#[test]
fn greedy_short_paths_are_rerouted_by_the_search() {
    let (a, b, c, d) = (0, 1, 2, 3);
    let p = Problem {
        n: 4,
        edges: vec![(a, c, 1, 0), (d, b, 1, 0), (a, b, 1, 0)],
        terms: vec![(1, 0), (0, 1), (0, 1), (1, 0)],
    };
    let mut g = graph_of(&p);
    assert_eq!(g.maxflow(), 2);
    assert_eq!(brute_min_cut(&p), 2);
    let side: Vec<bool> = (0..4).map(|i| g.is_sink_side(i)).collect();
    assert_eq!(cut_value(&p, &side), 2);
    // The maximum flow saturates a → c and d → b and leaves a → b unused (its
    // unit came back); every terminal arc is saturated.
    assert_eq!(g.edge_residual(0), Some((0, 1)));
    assert_eq!(g.edge_residual(1), Some((0, 1)));
    assert_eq!(g.edge_residual(2), Some((1, 0)));
    for i in 0..4 {
        assert_eq!(g.terminal_residual(i), 0, "node {i}");
    }
}

/// A grid large enough for thousands of augmentations, solved with the clock
/// restarting every few of them and without restarts: same flow, same cut value.
#[test]
fn clock_restarts_on_a_grid() {
    let (h, w) = (48usize, 64usize);
    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move |m: i64| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng % m as u64) as i64
    };
    let edges = grid_edges(h, w, 8).unwrap();
    let p = Problem {
        n: h * w,
        edges: edges
            .iter()
            .map(|&[i, j]| (i as usize, j as usize, next(20), next(20)))
            .collect(),
        terms: (0..h * w).map(|_| (next(30), next(30))).collect(),
    };
    let mut plain = graph_of(&p);
    let f = plain.maxflow();
    for max_time in [1, 2, 5, 97] {
        let mut g = graph_of(&p);
        g.set_max_time(max_time);
        assert_eq!(g.maxflow(), f, "max_time {max_time}");
        g.check_trees();
        assert_eq!(cut_value(&p, &g.segments()), f);
        check_flow(&p, &g, true);
    }
}

/// Problems with a hub: most edges touch node 0 (degrees above the 15 arcs that a
/// sister hint covers, so the overflow table is used), with parallel edges,
/// self-loops and isolated nodes.
fn hub_problem() -> impl Strategy<Value = Problem> {
    (3usize..=9).prop_flat_map(|n| {
        let spoke = (0..n, 0i64..6, 0i64..6, any::<bool>());
        let edges = prop::collection::vec(spoke, 16..48);
        let extra = prop::collection::vec((0..n, 0..n, 0i64..6, 0i64..6), 0..6);
        let terms = prop::collection::vec((0i64..15, 0i64..15), n);
        (Just(n), edges, extra, terms).prop_map(|(n, spokes, extra, terms)| {
            let mut edges: Vec<_> = spokes
                .into_iter()
                .map(|(j, c, r, flip)| if flip { (j, 0, c, r) } else { (0, j, c, r) })
                .collect();
            edges.extend(extra);
            Problem { n, edges, terms }
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn hub_graphs_match_brute_force(p in hub_problem(), changes in prop::collection::vec((0usize..9, 0i64..15, 0i64..15), 1..4)) {
        let mut g = graph_of(&p);
        prop_assert_eq!(g.maxflow(), brute_min_cut(&p));
        prop_assert_eq!(cut_value(&p, &g.segments()), g.flow());
        check_flow(&p, &g, true);
        // Dynamic changes on top, and a graph built by the batch call.
        let q = set_terminals(&p, &mut g, &changes);
        prop_assert_eq!(g.maxflow(), brute_min_cut(&q));
        check_flow(&q, &g, false);
        let mut b = Graph::<i64>::new(p.n);
        let src: Vec<u32> = p.edges.iter().map(|e| e.0 as u32).collect();
        let dst: Vec<u32> = p.edges.iter().map(|e| e.1 as u32).collect();
        let cap: Vec<i64> = p.edges.iter().map(|e| e.2).collect();
        let rev: Vec<i64> = p.edges.iter().map(|e| e.3).collect();
        b.add_edges(&src, &dst, &cap, &rev).unwrap();
        for (i, &(s, t)) in p.terms.iter().enumerate() {
            b.add_tweights(i, s, t).unwrap();
        }
        prop_assert_eq!(b.maxflow(), brute_min_cut(&p));
        // Split into parts: arcs whose sister sits in the overflow table, across
        // and within parts.
        for k in 2..4 {
            let mut g = graph_of(&p);
            g.force_parts(k);
            prop_assert_eq!(g.maxflow(), brute_min_cut(&p));
            check_flow(&p, &g, true);
            g.check_trees();
        }
    }
}

#[test]
fn hub_graph_uses_the_overflow_table() {
    let n = 40;
    let mut g = Graph::<i64>::new(n);
    for j in 1..n {
        g.add_edge(0, j, 1, 1).unwrap();
    }
    g.add_tweights(0, 100, 0).unwrap();
    for j in 1..n {
        g.add_tweights(j, 0, 1).unwrap();
    }
    assert_eq!(g.maxflow(), (n - 1) as i64);
    assert!(!g.overflow.is_empty());
    // Every arc's reverse points back to it.
    for a in 0..g.arcs.len() {
        assert_eq!(g.sister(g.sister(a)), a);
    }
}

#[test]
fn edges_added_after_solve_are_used() {
    let mut g = Graph::<i64>::new(3);
    g.add_tweights(0, 5, 0).unwrap();
    g.add_tweights(2, 0, 5).unwrap();
    g.add_edge(0, 1, 3, 0).unwrap();
    assert_eq!(g.maxflow(), 0);
    g.add_edge(1, 2, 2, 0).unwrap();
    assert_eq!(g.maxflow(), 2);
    assert!(!g.is_sink_side(0) && g.is_sink_side(2));
}

proptest! {
    /// Rounds as an expansion solver runs them on one graph: capacities on a subset
    /// of the nodes and the edges inside it, a seeded solve, `reset_touched`. Every
    /// round's flow and cut equal the brute-force minimum cut of its capacities,
    /// also with an occasional full `reset` and the adoption clock restarting.
    #[test]
    fn seeded_solves_after_touched_resets_match_brute_force(
        p in problem(9),
        rounds in prop::collection::vec(
            (any::<u16>(), prop::collection::vec((0i64..12, 0i64..12, 0i64..10, 0i64..10), 9), any::<bool>()),
            1..6,
        ),
        max_time in 1u32..40,
    ) {
        let mut g = Graph::<i64>::new(p.n);
        g.keep_edge_index();
        g.set_max_time(max_time);
        for &(i, j, _, _) in &p.edges {
            g.add_edge(i, j, 0, 0).unwrap();
        }
        g.finalize();
        for (mask, caps, full_reset) in rounds {
            let seeds: Vec<u32> = (0..p.n as u32).filter(|&i| mask >> i & 1 == 1).collect();
            let inside = |i: usize| mask >> i & 1 == 1;
            let mut q = Problem { n: p.n, edges: Vec::new(), terms: vec![(0, 0); p.n] };
            let mut touched = Vec::new();
            for (k, &(i, j, _, _)) in p.edges.iter().enumerate() {
                if inside(i) && inside(j) && i != j {
                    let (c, r) = (caps[i].2, caps[j].3);
                    g.set_edge_caps_unchecked(k, c, r);
                    touched.push(k as u32);
                    q.edges.push((i, j, c, r));
                }
            }
            for &i in &seeds {
                let (s, t, _, _) = caps[i as usize];
                g.update_tweights_unchecked(i as usize, s, t);
                q.terms[i as usize] = (s, t);
            }
            prop_assert_eq!(g.maxflow_seeded(&seeds), brute_min_cut(&q));
            prop_assert_eq!(cut_value(&q, &g.segments()), g.flow());
            g.check_trees();
            if full_reset {
                g.reset();
            } else {
                g.reset_touched(&touched, &seeds);
            }
        }
    }
}

#[test]
fn reset_and_reuse_structure() {
    let p = Problem {
        n: 4,
        edges: vec![(0, 1, 2, 1), (1, 2, 3, 0), (2, 3, 1, 4), (0, 3, 2, 2)],
        terms: vec![(4, 0), (1, 2), (0, 3), (2, 2)],
    };
    let mut g = graph_of(&p);
    let f = g.maxflow();
    g.reset();
    for (k, &(_, _, c, r)) in p.edges.iter().enumerate() {
        g.set_edge_caps(k, c, r).unwrap();
    }
    for (i, &(s, t)) in p.terms.iter().enumerate() {
        g.add_tweights(i, s, t).unwrap();
    }
    assert_eq!(g.maxflow(), f);
    assert_eq!(f, brute_min_cut(&p));
}

#[test]
fn bad_input_is_rejected() {
    let mut g = Graph::<f64>::new(2);
    assert!(g.add_edge(0, 2, 1.0, 1.0).is_err());
    assert!(g.add_edge(0, 1, -1.0, 1.0).is_err());
    assert!(g.add_edge(0, 1, f64::NAN, 1.0).is_err());
    assert!(g.add_tweights(0, f64::INFINITY, 0.0).is_err());
    assert!(g.add_edges(&[0], &[1, 0], &[1.0], &[1.0]).is_err());
    assert!(g.set_tweights(0, 1.0, 1.0).is_err()); // not tracked
    assert!(grid_edges(2, 2, 6).is_err());
}

/// Integer capacities whose sum could pass `i64::MAX` are refused by every entry
/// point, naming the argument and changing nothing (unchecked, three terminal arcs
/// of 2^62 would wrap to a flow of −2^62).
#[test]
fn integer_sums_past_int64_are_refused_and_change_nothing() {
    let big = 1i64 << 62;
    let name_of = |r: Result<()>| match r {
        Err(Error::InvalidArgument { name, .. }) => name,
        other => panic!("expected a refusal, got {other:?}"),
    };
    let mut g = Graph::<i64>::new(3);
    g.track_terminal_caps();
    g.keep_edge_index();
    g.add_tweights_batch(&[0, 1], &[big / 2, big / 2], &[0, 0])
        .unwrap();
    assert_eq!(name_of(g.add_tweights(2, big, 0)), "source_cap");
    assert_eq!(
        name_of(g.add_tweights_batch(&[2], &[0], &[big])),
        "source_cap"
    );
    assert_eq!(name_of(g.add_edge(0, 1, big, 0).map(|_| ())), "cap");
    assert_eq!(name_of(g.add_edges(&[0], &[2], &[0], &[big])), "cap");
    assert_eq!(name_of(g.update_tweights(2, big, 0)), "delta_source");
    // All or nothing: the first change fits, the second would not.
    assert_eq!(
        name_of(g.update_tweights_batch(&[2, 2], &[1, big], &[0, 0])),
        "delta_source"
    );
    assert_eq!(name_of(g.set_tweights(2, 0, big)), "source_cap");
    g.add_tweights(2, 0, big / 2).unwrap();
    g.add_edge(0, 2, big / 4, 0).unwrap();
    // Negative deltas count by their magnitude too (the sum is now 1.75 · 2^62):
    // the budget bounds every intermediate value, not only the final capacities.
    assert_eq!(name_of(g.update_tweights(0, -(big / 2), 0)), "delta_source");
    assert_eq!(g.maxflow(), big / 4); // the refused calls left the graph unchanged
                                      // Edge capacities set after a reset are charged from zero again.
    g.reset();
    assert_eq!(name_of(g.set_edge_caps(0, big, big)), "cap");
    g.set_edge_caps(0, big / 2, 0).unwrap();
    g.add_tweights(0, big / 4, 0).unwrap();
    g.add_tweights(2, 0, big / 8).unwrap();
    assert_eq!(g.maxflow(), big / 8);
    // With tracked capacities the budget is checked before the new capacity is
    // formed: 2^62 + (2^62 + 2^61) would overflow (a panic in debug builds).
    let mut t = Graph::<i64>::new(1);
    t.track_terminal_caps();
    t.add_tweights(0, big, 0).unwrap();
    let huge = big + big / 2;
    assert_eq!(name_of(t.update_tweights(0, huge, 0)), "delta_source");
    assert_eq!(
        name_of(t.update_tweights_batch(&[0], &[huge], &[0])),
        "delta_source"
    );
    // Floats have no such budget (they round, and overflow only to infinity).
    let mut f = Graph::<f64>::new(2);
    for _ in 0..4 {
        f.add_tweights(0, 4.0e18, 0.0).unwrap();
    }
}

#[test]
fn terminal_changes_in_a_batch_are_checked_on_their_sum() {
    let mut g = Graph::<i64>::new(2);
    g.track_terminal_caps();
    g.add_tweights(0, 3, 0).unwrap();
    g.add_edge(0, 1, 5, 0).unwrap();
    g.add_tweights(1, 0, 4).unwrap();
    // Each change alone keeps node 0's source capacity ≥ 0; together they do not.
    assert!(g
        .update_tweights_batch(&[0, 0], &[-2, -2], &[0, 0])
        .is_err());
    assert!(g.update_tweights_batch(&[0], &[1], &[0, 0]).is_err()); // lengths
    assert!(g.update_tweights_batch(&[2], &[1], &[0]).is_err()); // node index
    assert_eq!(g.maxflow(), 3); // unchanged by the refused batches
    g.update_tweights_batch(&[0, 0, 1], &[-1, 2], &[0, 0])
        .unwrap_err(); // lengths again (3 nodes, 2 deltas)
    g.update_tweights_batch(&[0, 0], &[-1, 2], &[0, 0]).unwrap();
    assert_eq!(g.maxflow(), 4); // source capacity 4, sink capacity 4
    let mut f = Graph::<f64>::new(1);
    assert!(f.update_tweights_batch(&[0], &[f64::NAN], &[0.0]).is_err());
}

/// Bytes per node of a solved 4-connected `h`×`w` grid graph with capacities `C`,
/// from [`Graph::memory_bytes`]; also checks the cut and returns the graph.
fn grid_memory<C: Capacity>(h: usize, w: usize, one: C) -> (f64, Graph<C>) {
    let e = grid_edges(h, w, 4).unwrap();
    let (s, d): (Vec<u32>, Vec<u32>) = e.iter().map(|&[i, j]| (i, j)).unzip();
    let c = vec![one; e.len()];
    let mut g = Graph::<C>::with_capacity(h * w, e.len());
    g.add_edges(&s, &d, &c, &c).unwrap();
    // Unary terms on every node (like a segmentation), one seed on each side.
    for i in 0..h * w {
        let (a, b) = if (i / w + i % w).is_multiple_of(3) {
            (one, C::ZERO)
        } else {
            (C::ZERO, one)
        };
        g.add_tweights(i, a, b).unwrap();
    }
    g.maxflow();
    (g.memory_bytes() as f64 / (h * w) as f64, g)
}

#[test]
fn grid_graph_memory_per_node() {
    // Bytes per node = everything the graph holds after a solve (arcs: 4-byte head
    // + 8-byte residual, ~4 per node; node record 16; CSR offset 4; bit sets and
    // queues), divided by the node count. Must stay within 70 bytes for 8-byte
    // capacities of both kinds.
    let (h, w) = (120, 160);
    let (pf, gf) = grid_memory::<f64>(h, w, 1.0);
    let (pi, gi) = grid_memory::<i64>(h, w, 1);
    assert_eq!(gf.flow(), gi.flow() as f64);
    for per_node in [pf, pi] {
        assert!(per_node <= 70.0, "{per_node} bytes per node");
        // A real size: at least the arcs, node records and offsets themselves.
        let arcs = 2 * grid_edges(h, w, 4).unwrap().len();
        let floor = (arcs * 12 + h * w * 20) as f64 / (h * w) as f64;
        assert!(per_node >= floor, "{per_node} < {floor}");
    }
    // The same graph solved again after a change still fits (queues are reused).
    let mut g = gf;
    g.update_tweights(5, 3.0, 0.0).unwrap();
    g.maxflow();
    assert!(g.memory_bytes() as f64 / (h * w) as f64 <= 70.0);
}

#[test]
fn grid_edges_count() {
    assert_eq!(grid_edges(3, 4, 4).unwrap().len(), 3 * 3 + 2 * 4);
    assert_eq!(
        grid_edges(3, 4, 8).unwrap().len(),
        3 * 3 + 2 * 4 + 2 * 2 * 3
    );
}

#[test]
fn grid_segmentation_matches_brute_force() {
    // 3×4 grid with random-ish integer data: 12 nodes, exhaustive check.
    let (h, w) = (3, 4);
    for conn in [4u8, 8] {
        let e = grid_edges(h, w, conn).unwrap();
        let p = Problem {
            n: h * w,
            edges: e
                .iter()
                .enumerate()
                .map(|(k, &[i, j])| {
                    (
                        i as usize,
                        j as usize,
                        (k * 7 % 5) as i64,
                        (k * 3 % 4) as i64,
                    )
                })
                .collect(),
            terms: (0..h * w)
                .map(|i| ((i * 5 % 9) as i64, (i * 11 % 7) as i64))
                .collect(),
        };
        let mut g = graph_of(&p);
        assert_eq!(g.maxflow(), brute_min_cut(&p));
        check_flow(&p, &g, true);
    }
}

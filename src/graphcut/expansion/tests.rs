use super::problem::check_problem;
use super::*;
use crate::error::Error;
use proptest::prelude::*;

#[derive(Clone, Debug)]
struct Prob {
    l: usize,
    unary: Vec<i64>,
    edges: Vec<[u32; 2]>,
    weights: Vec<i64>,
}

impl Prob {
    fn view<'a>(&'a self, pairwise: Option<&'a [i64]>) -> CrfProblem<'a, i64> {
        CrfProblem {
            unary: &self.unary,
            n_labels: self.l,
            edges: &self.edges,
            weights: &self.weights,
            pairwise,
        }
    }
}

fn prob(max_n: usize, max_l: usize) -> impl Strategy<Value = Prob> {
    (1..=max_n, 2..=max_l).prop_flat_map(|(n, l)| {
        (
            Just(l),
            prop::collection::vec(0i64..20, n * l),
            prop::collection::vec((0..n as u32, 0..n as u32, 0i64..8), 0..(2 * n + 1)),
        )
            .prop_map(|(l, unary, e)| Prob {
                l,
                unary,
                edges: e.iter().map(|&(i, j, _)| [i, j]).collect(),
                weights: e.iter().map(|&(_, _, w)| w).collect(),
            })
    })
}

fn exhaustive(p: &CrfProblem<i64>) -> i64 {
    let l = p.n_labels;
    let n = p.unary.len() / l;
    let mut labels = vec![0i32; n];
    let mut best = i64::MAX;
    loop {
        best = best.min(energy(p, &labels).unwrap());
        let mut k = 0;
        loop {
            if k == n {
                return best;
            }
            labels[k] += 1;
            if (labels[k] as usize) < l {
                break;
            }
            labels[k] = 0;
            k += 1;
        }
    }
}

/// Iterated conditional modes: each node takes its best label given its neighbours.
fn icm(p: &CrfProblem<i64>, init: &[i32]) -> i64 {
    let mut labels = init.to_vec();
    let l = p.n_labels as i32;
    loop {
        let mut changed = false;
        for i in 0..labels.len() {
            let cur = energy(p, &labels).unwrap();
            let keep = labels[i];
            let mut best = (cur, keep);
            for a in 0..l {
                labels[i] = a;
                let e = energy(p, &labels).unwrap();
                if e < best.0 {
                    best = (e, a);
                }
            }
            labels[i] = best.1;
            changed |= best.1 != keep;
        }
        if !changed {
            return energy(p, &labels).unwrap();
        }
    }
}

/// A metric on labels on a line, truncated: V(a,b) = min(|a−b|, 2) (a metric).
fn truncated_linear(l: usize) -> Vec<i64> {
    (0..l * l)
        .map(|k| ((k / l) as i64 - (k % l) as i64).abs().min(2))
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(150))]

    #[test]
    fn expansion_is_within_factor_two_and_monotone(p in prob(6, 3)) {
        let v = p.view(None);
        let r = alpha_expansion(&v, None, &MoveConfig::default()).unwrap();
        let opt = exhaustive(&v);
        prop_assert!(r.energy <= 2 * opt, "energy {} vs optimum {}", r.energy, opt);
        prop_assert_eq!(r.energy, energy(&v, &r.labels).unwrap());
        prop_assert!(r.trace.windows(2).all(|w| w[1] < w[0]));
        prop_assert_eq!(*r.trace.last().unwrap(), r.energy);
        prop_assert_eq!(icm(&v, &r.labels), r.energy);
        // Deterministic.
        prop_assert_eq!(alpha_expansion(&v, None, &MoveConfig::default()).unwrap(), r);
    }

    #[test]
    fn expansion_with_metric_is_icm_stable(p in prob(6, 4), seed in 0u32..1000) {
        // Every single-node change is part of some expansion move, so the result is
        // a fixed point of ICM. (Beating ICM's own result is not guaranteed for a
        // general metric: two nodes with min(|a−b|, 2) can trap expansion at 7 where
        // ICM reaches 5.)
        let tl = truncated_linear(p.l);
        let v = p.view(Some(&tl));
        let n = p.unary.len() / p.l;
        let init: Vec<i32> = (0..n).map(|i| ((i as u32 * 7 + seed) % p.l as u32) as i32).collect();
        let r = alpha_expansion(&v, Some(&init), &MoveConfig::default()).unwrap();
        prop_assert_eq!(icm(&v, &r.labels), r.energy);
        prop_assert!(r.energy <= energy(&v, &init).unwrap());
        prop_assert!(r.trace.windows(2).all(|w| w[1] < w[0]));
        prop_assert!(r.energy >= exhaustive(&v));
    }

    #[test]
    fn swap_monotone_and_icm_stable(p in prob(6, 3)) {
        let v = p.view(None);
        let init = c_init(&v);
        let r = alpha_beta_swap(&v, Some(&init), &MoveConfig::default()).unwrap();
        prop_assert_eq!(r.energy, energy(&v, &r.labels).unwrap());
        prop_assert!(r.trace.windows(2).all(|w| w[1] < w[0]));
        prop_assert_eq!(icm(&v, &r.labels), r.energy);
        prop_assert!(r.energy <= energy(&v, &init).unwrap());
        prop_assert!(r.energy >= exhaustive(&v));
    }

    #[test]
    fn float_and_integer_agree(p in prob(6, 3)) {
        let v = p.view(None);
        let r = alpha_expansion(&v, None, &MoveConfig::default()).unwrap();
        let uf: Vec<f64> = p.unary.iter().map(|&x| x as f64).collect();
        let wf: Vec<f64> = p.weights.iter().map(|&x| x as f64).collect();
        let vf = CrfProblem { unary: &uf, n_labels: p.l, edges: &p.edges, weights: &wf, pairwise: None };
        let rf = alpha_expansion(&vf, None, &MoveConfig::default()).unwrap();
        prop_assert_eq!(rf.labels, r.labels);
        prop_assert_eq!(rf.energy, r.energy as f64);
    }

    /// The lane-summed check of float costs is the value-by-value definition, for
    /// any length (the tail past the last eight) and any bad value anywhere.
    #[test]
    fn float_plain_check_is_the_definition(
        values in prop::collection::vec(-1e300f64..1e300, 0..40),
        bad in prop::option::of((0usize..40, 0usize..4)),
    ) {
        let mut values = values;
        if let Some((at, which)) = bad {
            if !values.is_empty() {
                let k = at % values.len();
                values[k] = [f64::INFINITY, f64::NEG_INFINITY, f64::NAN, 1e308 * 10.0][which];
            }
        }
        let definition = values.iter().all(|&u| u.is_finite() && u != f64::FORBIDDEN);
        prop_assert_eq!(<f64 as Cost>::all_plain(&values), definition);
        prop_assert_eq!(<i64 as Cost>::all_plain(&[1, 2, i64::MAX]), false);
    }
}

#[test]
fn potts_expansion_rarely_worse_than_icm() {
    // Expansion can end above ICM from the same start: on 7 nodes with Potts weights
    // [5, 7, 2, 6] (see below) it takes a greedy move to 40 and stops in a local
    // minimum, while ICM reaches the optimum 37. So we assert: ICM-stability of
    // every result, the factor-2 bound, and that on a fixed sample expansion is at
    // least as good as ICM in the vast majority of cases.
    use proptest::strategy::ValueTree;
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let strategy = prob(7, 4);
    let (mut n_ok, n_total) = (0, 300);
    for _ in 0..n_total {
        let p = strategy.new_tree(&mut runner).unwrap().current();
        let v = p.view(None);
        let init = c_init(&v);
        let cfg = MoveConfig::default();
        let r = alpha_expansion(&v, Some(&init), &cfg).unwrap();
        assert_eq!(icm(&v, &r.labels), r.energy, "{p:?}");
        assert!(r.energy <= 2 * exhaustive(&v), "{p:?}");
        n_ok += usize::from(r.energy <= icm(&v, &init));
        // Any single-node change is a swap move, so swap's result is ICM-stable too.
        let s = alpha_beta_swap(&v, Some(&init), &cfg).unwrap();
        assert_eq!(icm(&v, &s.labels), s.energy, "{p:?}");
    }
    assert!(
        n_ok * 100 >= 95 * n_total,
        "expansion ≤ ICM in only {n_ok}/{n_total}"
    );
    // The counterexample.
    let p = Prob {
        l: 4,
        unary: vec![
            12, 5, 16, 15, 2, 10, 12, 12, 7, 14, 17, 4, 18, 15, 14, 7, 10, 4, 14, 4, 2, 6, 18, 13,
            6, 14, 4, 16,
        ],
        edges: vec![[6, 6], [5, 3], [0, 3], [4, 3]],
        weights: vec![5, 7, 2, 6],
    };
    let v = p.view(None);
    let init = c_init(&v);
    let r = alpha_expansion(&v, Some(&init), &MoveConfig::default()).unwrap();
    assert_eq!((r.energy, icm(&v, &init), exhaustive(&v)), (40, 37, 37));
}

fn c_init(p: &CrfProblem<i64>) -> Vec<i32> {
    check_problem(p, false, false, false)
        .unwrap()
        .argmin_unary()
}

#[test]
fn two_label_expansion_is_exact() {
    // With two labels one expansion move is the global optimum of the binary problem.
    let p = Prob {
        l: 2,
        unary: vec![0, 5, 4, 1, 3, 3, 6, 0, 2, 2],
        edges: vec![[0, 1], [1, 2], [2, 3], [3, 4], [0, 4]],
        weights: vec![3, 2, 4, 1, 2],
    };
    let v = p.view(None);
    let r = alpha_expansion(&v, None, &MoveConfig::default()).unwrap();
    assert_eq!(r.energy, exhaustive(&v));
}

#[test]
fn forbidden_labels_are_avoided() {
    let f = i64::MAX;
    let p = Prob {
        l: 3,
        unary: vec![f, 1, 2, 0, f, f, 5, 5, f],
        edges: vec![[0, 1], [1, 2]],
        weights: vec![10, 10],
    };
    let v = p.view(None);
    // Start from a forbidden labelling.
    let r = alpha_expansion(&v, Some(&[0, 1, 2]), &MoveConfig::default()).unwrap();
    assert_eq!(r.labels[1], 0);
    assert!(r.labels[0] != 0 && r.labels[2] != 2);
    assert_eq!(r.energy, exhaustive(&v));
    assert_eq!(r.trace[0], i64::MAX);
    let all_forbidden = Prob {
        l: 2,
        unary: vec![f, f],
        edges: vec![],
        weights: vec![],
    };
    let err = alpha_expansion(&all_forbidden.view(None), None, &MoveConfig::default());
    assert!(matches!(err, Err(Error::InvalidArgument { name, .. }) if name == "unary"));
}

/// Float costs whose energies or flows could overflow are refused, never looped on.
#[test]
fn float_costs_that_could_overflow_are_refused_not_looped_on() {
    // weights × pairwise overflows to inf (a max-flow on infinite capacities never ends).
    let unary = [3.18, 1.35, 0.20, 0.08];
    let v2 = [0.0, 2.0, 2.0, 0.0];
    let v3 = [0.0, 2.0, 2.0, 2.0, 0.0, 2.0, 2.0, 2.0, 0.0];
    let unary3 = [3.18, 1.35, 0.5, 0.20, 0.08, 0.7];
    for (u, l, v) in [(&unary[..], 2, &v2[..]), (&unary3[..], 3, &v3[..])] {
        for weights in [[1e308], [f64::MAX / 3.0]] {
            let p = CrfProblem {
                unary: u,
                n_labels: l,
                edges: &[[0, 1]],
                weights: &weights,
                pairwise: Some(v),
            };
            let cfg = MoveConfig { max_cycles: 1 };
            for r in [
                alpha_expansion(&p, None, &cfg).err(),
                alpha_beta_swap(&p, None, &cfg).err(),
                energy(&p, &[0, 1]).err(),
            ] {
                assert!(
                    matches!(r, Some(Error::InvalidArgument { ref name, .. }) if name == "weights"),
                    "{r:?}"
                );
            }
        }
    }
    // Huge unary costs over many nodes: the energy could pass the float range.
    let n = 8;
    let u: Vec<f64> = (0..2 * n)
        .map(|k| if k % 2 == 0 { 1e308 } else { 0.0 })
        .collect();
    let p = CrfProblem {
        unary: &u,
        n_labels: 2,
        edges: &[],
        weights: &[],
        pairwise: None,
    };
    let r = alpha_expansion(&p, None, &MoveConfig::default());
    assert!(matches!(r, Err(Error::InvalidArgument { ref name, .. }) if name == "unary"));
    // Large but safe costs still solve, with a finite energy.
    let w = [1e300];
    let p = CrfProblem {
        unary: &unary,
        n_labels: 2,
        edges: &[[0, 1]],
        weights: &w,
        pairwise: Some(&v2),
    };
    let r = alpha_expansion(&p, None, &MoveConfig::default()).unwrap();
    assert!(r.energy.is_finite());
}

/// Integer costs whose energies could pass int64 are refused (unchecked, four nodes at
/// 2⁶² each would wrap to an energy of 0); the largest safe ones still solve.
#[test]
fn integer_costs_that_could_overflow_are_refused() {
    let big = 1i64 << 62;
    let edges = vec![[0, 1], [1, 2], [2, 3]];
    for (unary, weights) in [
        (vec![big; 12], vec![1; 3]),
        (vec![0; 12], vec![big; 3]),
        (vec![i64::MIN, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0], vec![1; 3]),
    ] {
        let p = Prob {
            l: 3,
            unary,
            edges: edges.clone(),
            weights,
        };
        for r in [
            alpha_expansion(&p.view(None), None, &MoveConfig::default()).err(),
            alpha_beta_swap(&p.view(None), None, &MoveConfig::default()).err(),
        ] {
            assert!(matches!(r, Some(Error::InvalidArgument { ref name, .. }) if name == "unary"));
        }
    }
    // 4 × (1 + 4 × max|u| + Σ w) just fits.
    let u = (i64::MAX / 4 - 10) / 4;
    let p = Prob {
        l: 3,
        unary: (0..12).map(|k| if k % 3 == 0 { u } else { 0 }).collect(),
        edges,
        weights: vec![1; 3],
    };
    let r = alpha_expansion(&p.view(None), None, &MoveConfig::default()).unwrap();
    assert_eq!(r.energy, 0);
}

#[test]
fn bad_pairwise_is_rejected() {
    let p = Prob {
        l: 3,
        unary: vec![0; 6],
        edges: vec![[0, 1]],
        weights: vec![1],
    };
    // Not a metric: V(0,2) = 5 > V(0,1) + V(1,2) = 2. Fine for swap.
    let v = [0, 1, 5, 1, 0, 1, 5, 1, 0];
    let err = alpha_expansion(&p.view(Some(&v)), None, &MoveConfig::default());
    assert!(matches!(err, Err(Error::InvalidArgument { ref name, .. }) if name == "pairwise"));
    assert!(alpha_beta_swap(&p.view(Some(&v)), None, &MoveConfig::default()).is_ok());
    for bad in [
        vec![0, 1, 1, 2, 0, 1, 1, 1, 0], // asymmetric
        vec![0, 0, 1, 0, 0, 1, 1, 1, 0], // zero off the diagonal
        vec![1, 1, 1, 1, 0, 1, 1, 1, 0], // non-zero diagonal
        vec![0, 1, 1, 1, 0, -1, 1, -1, 0],
        vec![0, 1],
    ] {
        let err = alpha_beta_swap(&p.view(Some(&bad)), None, &MoveConfig::default());
        assert!(matches!(err, Err(Error::InvalidArgument { ref name, .. }) if name == "pairwise"));
    }
    let bad_edges = Prob {
        edges: vec![[0, 2]],
        ..p.clone()
    };
    assert!(alpha_expansion(&bad_edges.view(None), None, &MoveConfig::default()).is_err());
    let bad_init = alpha_expansion(&p.view(None), Some(&[0, 3]), &MoveConfig::default());
    assert!(matches!(bad_init, Err(Error::InvalidArgument { ref name, .. }) if name == "init"));
    let nan = [f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0];
    let w = [1.0];
    let pf = CrfProblem {
        unary: &nan,
        n_labels: 3,
        edges: &p.edges,
        weights: &w,
        pairwise: None,
    };
    assert!(
        matches!(energy(&pf, &[0, 0]), Err(Error::InvalidArgument { ref name, .. }) if name == "unary")
    );
}

/// The least energy over all expansion moves of `alpha` from `labels` (2^n subsets).
fn best_move(p: &CrfProblem<i64>, labels: &[i32], alpha: i32) -> i64 {
    let n = labels.len();
    (0u32..1 << n)
        .map(|mask| {
            let moved: Vec<i32> = (0..n)
                .map(|i| if mask >> i & 1 == 1 { alpha } else { labels[i] })
                .collect();
            energy(p, &moved).unwrap()
        })
        .min()
        .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Each expansion move, pruned or not, reaches the optimal move energy; with
    /// widely spread unaries most nodes are pruned, so this checks the pruning rule.
    #[test]
    fn pruned_and_plain_moves_are_optimal(
        p in prob(7, 4),
        scale in 1i64..6,
        seed in 0u32..10_000,
        metric in any::<bool>(),
    ) {
        let p = Prob { unary: p.unary.iter().map(|u| u * scale).collect(), ..p };
        let tl = truncated_linear(p.l);
        let v = p.view(if metric { Some(&tl) } else { None });
        let n = p.unary.len() / p.l;
        let labels: Vec<i32> = (0..n)
            .map(|i| ((seed as usize / (i + 1) + i * 7) % p.l) as i32)
            .collect();
        let c = check_problem(&v, true, false, false).unwrap();
        let e0 = c.energy(&labels);
        // One solver for every move in turn: the graph is cleared only where the
        // previous move touched it.
        let mut s = CrfSolver::new(n, &p.edges).unwrap();
        s.prepare_expansion(&c, false);
        for k in 0..2 * p.l {
            let alpha = ((seed as usize + k) % p.l) as i32;
            let best = best_move(&v, &labels, alpha);
            for prune in [true, false] {
                s.set_pruning(prune);
                s.collect_candidates(&c, &labels);
                s.candidate.copy_from_slice(&labels);
                let e = s.expansion_move(&c, &labels, alpha, &e0);
                prop_assert_eq!(e.value(), best, "prune {}", prune);
                // The energy by differences equals the moved labelling's own.
                prop_assert_eq!(e, c.energy(&s.candidate));
            }
        }
    }
}

/// Reference for the candidate sets: expansion cycles with the sets rebuilt from
/// every node before each move (what a scan over all nodes visits). Unlike
/// `alpha_expansion` it retries moves that failed on the same labels, which cannot
/// change the result: the optimal move of the same labels fails again.
fn expansion_rebuilding_candidates(p: &CrfProblem<i64>, init: &[i32], cycles: usize) -> Vec<i32> {
    let c = check_problem(p, true, false, false).unwrap();
    let mut s = CrfSolver::new(c.n, p.edges).unwrap();
    s.prepare_expansion(&c, false);
    let mut labels = init.to_vec();
    let mut e = c.energy(&labels);
    for _ in 0..cycles {
        let mut improved = false;
        for alpha in 0..c.l as i32 {
            s.collect_candidates(&c, &labels);
            s.candidate.copy_from_slice(&labels);
            let new_e = s.expansion_move(&c, &labels, alpha, &e);
            if new_e.lt(&e) {
                labels.copy_from_slice(&s.candidate);
                e = new_e;
                improved = true;
            }
        }
        if !improved {
            break;
        }
    }
    labels
}

/// An `h`×`w` 4-connected grid with `l` labels, its unaries and weights the
/// seeds' first values.
fn grid_prob(w: usize, h: usize, l: usize, unary_seed: &[i64], weight_seed: &[i64]) -> Prob {
    let edges = crate::graphcut::grid_edges(h, w, 4).unwrap();
    Prob {
        l,
        unary: unary_seed[..w * h * l].to_vec(),
        weights: weight_seed[..edges.len()].to_vec(),
        edges,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// The per-label candidate sets, kept up to date as nodes switch (and pruned of
    /// the nodes a move finds fixed), give exactly the labelling of sets rebuilt
    /// before every move: no node that may switch is
    /// ever missed. Grids with spread unaries, so that pruning and switching both
    /// happen many times.
    #[test]
    fn candidate_lists_match_rebuilt_lists(
        // Up to 144 nodes: the candidate sets span several 64-bit words.
        w in 2usize..13,
        h in 2usize..13,
        l in 2usize..6,
        unary_seed in prop::collection::vec(0i64..40, 144 * 6),
        weight_seed in prop::collection::vec(0i64..12, 2 * 144),
        metric in any::<bool>(),
    ) {
        let n = w * h;
        let p = grid_prob(w, h, l, &unary_seed, &weight_seed);
        let tl = truncated_linear(l);
        let v = p.view(if metric { Some(&tl) } else { None });
        let init: Vec<i32> = (0..n).map(|i| ((i * 5 + 1) % l) as i32).collect();
        let mut s = CrfSolver::new(n, &p.edges).unwrap();
        let cfg = MoveConfig { max_cycles: 5 };
        let got = s.alpha_expansion(&v, Some(&init), &cfg).unwrap();
        prop_assert_eq!(got.labels, expansion_rebuilding_candidates(&v, &init, 5));
    }
}

proptest! {
    /// The work beside the cycles changes nothing in the expansion, runs beside
    /// every cycle, and its output is returned exactly when its cycle accepted no
    /// move, having seen the labelling returned.
    #[test]
    fn work_beside_the_last_cycle_sees_the_result(
        w in 2usize..9,
        h in 2usize..9,
        l in 2usize..6,
        unary_seed in prop::collection::vec(0i64..40, 64 * 6),
        weight_seed in prop::collection::vec(0i64..12, 2 * 64),
        max_cycles in 1usize..5,
    ) {
        let n = w * h;
        let p = grid_prob(w, h, l, &unary_seed, &weight_seed);
        let v = p.view(None);
        let init: Vec<i32> = (0..n).map(|i| ((i * 3 + 1) % l) as i32).collect();
        let cfg = MoveConfig { max_cycles };
        let mut s = CrfSolver::new(n, &p.edges).unwrap();
        let plain = s.alpha_expansion(&v, Some(&init), &cfg).unwrap();
        let mut seen = Vec::new();
        let (with, output) = s
            .alpha_expansion_beside(&v, Some(&init), &cfg, &mut |labels, _| {
                seen.push(labels.to_vec());
                labels.to_vec()
            })
            .unwrap();
        prop_assert_eq!(&with, &plain);
        prop_assert_eq!(seen.len(), plain.cycles);
        prop_assert_eq!(&seen[0], &init);
        // Whether the last cycle accepted no move: one cycle fewer (none: the
        // starting labels) ends elsewhere.
        let before_last = match plain.cycles - 1 {
            0 => init.clone(),
            fewer => {
                let fewer = MoveConfig { max_cycles: fewer };
                s.alpha_expansion(&v, Some(&init), &fewer).unwrap().labels
            }
        };
        let last_cycle_idle = before_last == plain.labels;
        prop_assert_eq!(output.is_some(), last_cycle_idle);
        if let Some(labels) = output {
            prop_assert_eq!(&labels, &plain.labels);
        }
    }
}

proptest! {
    /// One solver over problems that differ in their weights (the per-node weight
    /// sums are kept from call to call while the weights stay the same) gives each
    /// problem's one-shot labelling.
    #[test]
    fn reused_solver_follows_new_weights(
        w in 2usize..7,
        h in 2usize..7,
        l in 2usize..5,
        unary_seed in prop::collection::vec(0i64..40, 36 * 5),
        weight_seeds in prop::collection::vec(prop::collection::vec(0i64..12, 72), 3),
    ) {
        let n = w * h;
        let problems: Vec<Prob> = weight_seeds
            .iter()
            .map(|ws| grid_prob(w, h, l, &unary_seed, ws))
            .collect();
        let init: Vec<i32> = (0..n).map(|i| ((i * 3 + 1) % l) as i32).collect();
        let cfg = MoveConfig::default();
        let mut s = CrfSolver::new(n, &problems[0].edges).unwrap();
        for k in [0, 1, 1, 2, 0] {
            let v = problems[k].view(None);
            let reused = s.alpha_expansion(&v, Some(&init), &cfg).unwrap();
            prop_assert_eq!(reused, alpha_expansion(&v, Some(&init), &cfg).unwrap());
        }
    }
}

#[test]
fn solver_reuse_matches_one_shot() {
    let p = Prob {
        l: 3,
        unary: vec![0, 5, 4, 1, 3, 3, 6, 0, 2, 2, 7, 1],
        edges: vec![[0, 1], [1, 2], [2, 3], [0, 3]],
        weights: vec![3, 2, 4, 1],
    };
    let mut s = CrfSolver::new(4, &p.edges).unwrap();
    let cfg = MoveConfig::default();
    let a = s.alpha_expansion(&p.view(None), None, &cfg).unwrap();
    let b = s.alpha_beta_swap(&p.view(None), None, &cfg).unwrap();
    let a2 = s.alpha_expansion(&p.view(None), None, &cfg).unwrap();
    assert_eq!(a, a2);
    assert_eq!(b, alpha_beta_swap(&p.view(None), None, &cfg).unwrap());
}

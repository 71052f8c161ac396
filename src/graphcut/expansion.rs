//! Move-making minimisation of a pairwise CRF energy
//!
//! E(l) = Σ_i U(i, l_i) + Σ_{e=(i,j)} w_e · V(l_i, l_j)
//!
//! by alpha-expansion (metric V) and alpha-beta swap (semi-metric V) (Boykov, Veksler &
//! Zabih, PAMI 2001). Each move is a binary problem solved exactly by one min cut, with
//! the construction of Kolmogorov & Zabih (PAMI 2004): a pairwise term with values
//! A = E(0,0), B = E(0,1), C = E(1,0), D = E(1,1) becomes the unary parts A(1−x_i) + C·x_i
//! and C(1−x_j) + D·x_j (up to a constant) plus an arc i→j of capacity B + C − A − D ≥ 0.
//!
//! A move is kept only if it lowers the energy, so the energy never increases, and the
//! result is deterministic. A unary cost equal to [`Cost::FORBIDDEN`] (`f64::INFINITY`,
//! `i64::MAX`) forbids that label at that node: energies are compared first by the
//! number of forbidden assignments, then by the finite sum.
//!
//! [`CrfSolver`] builds the graph structure once and reuses it (and all buffers) across
//! moves and calls; the free functions are one-shot conveniences.

use super::bitset::BitSet;
use super::maxflow::{Capacity, Graph};
use crate::error::{ensure, Error, Result};
use rayon::prelude::*;
use std::cmp::Ordering;
use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};

/// Default number of cycles over all labels (or label pairs).
pub const DEFAULT_MAX_CYCLES: usize = 20;
/// Below this many nodes, the energy is summed on one thread (rayon does not pay).
const PARALLEL_MIN_NODES: usize = 65_536;
/// Chunk size of the parallel energy sum (fixed, so float sums are deterministic).
const ENERGY_CHUNK: usize = 16_384;
/// Relative tolerance of the float triangle-inequality check on `pairwise`.
const METRIC_RTOL: f64 = 1e-12;

/// A cost type for the CRF: `f64` or `i64` (exact).
pub trait Cost: Capacity {
    /// The unary value meaning "this label is not allowed here".
    const FORBIDDEN: Self;
    /// Multiplication of two costs (weights × pairwise), `None` on overflow.
    fn mul(self, other: Self) -> Option<Self> {
        self.checked_mul(other)
    }
    /// Whether every value is finite and not [`Self::FORBIDDEN`].
    fn all_plain(values: &[Self]) -> bool {
        values.iter().fold(true, |ok, &u| {
            ok & u.is_finite_value() & (u != Self::FORBIDDEN)
        })
    }
    /// [`Self::all_plain`] and, for floats, the largest |value| (meaningful when all
    /// are plain; 0 for integers, whose range is checked exactly).
    fn plain_and_max_abs(values: &[Self]) -> (bool, f64) {
        (Self::all_plain(values), 0.0)
    }
}

impl Cost for f64 {
    const FORBIDDEN: Self = f64::INFINITY;
    fn all_plain(values: &[f64]) -> bool {
        // x · 0 is ±0 for a finite x and NaN for ±inf or NaN (so for the forbidden
        // +inf too). Sums in eight lanes vectorise, where the fold of comparisons ran
        // one value at a time (most of an E-step's checks).
        let mut lanes = [0.0f64; 8];
        let mut chunks = values.chunks_exact(8);
        for c in &mut chunks {
            for (lane, &x) in lanes.iter_mut().zip(c) {
                *lane += x * 0.0;
            }
        }
        let rest = chunks.remainder().iter().fold(0.0, |s, &x| s + x * 0.0);
        lanes.iter().sum::<f64>() + rest == 0.0
    }
    fn plain_and_max_abs(values: &[f64]) -> (bool, f64) {
        // One pass for both (the costs are read once): the sums of x · 0 as in
        // `all_plain`, and the largest |x| per lane.
        let (mut zero, mut most) = ([0.0f64; 8], [0.0f64; 8]);
        let mut chunks = values.chunks_exact(8);
        for c in &mut chunks {
            for k in 0..8 {
                zero[k] += c[k] * 0.0;
                let a = c[k].abs();
                most[k] = if a > most[k] { a } else { most[k] };
            }
        }
        let rest = chunks.remainder();
        let plain = zero.iter().sum::<f64>() + rest.iter().fold(0.0, |s, &x| s + x * 0.0) == 0.0;
        let max = rest
            .iter()
            .chain(&most)
            .fold(0.0f64, |m, &x| m.max(x.abs()));
        (plain, max)
    }
}

impl Cost for i64 {
    const FORBIDDEN: Self = i64::MAX;
}

/// The energy to minimise. `unary` is N×L row-major, `edges` pairs of node indices,
/// `weights` one per edge, `pairwise` L×L row-major (None: Potts, V(a,b) = [a ≠ b]).
#[derive(Clone, Copy, Debug)]
pub struct CrfProblem<'a, C: Cost> {
    pub unary: &'a [C],
    pub n_labels: usize,
    pub edges: &'a [[u32; 2]],
    pub weights: &'a [C],
    pub pairwise: Option<&'a [C]>,
}

/// Options of the move-making solvers.
#[derive(Clone, Copy, Debug)]
pub struct MoveConfig {
    /// At most this many cycles over all labels (expansion) or label pairs (swap).
    pub max_cycles: usize,
}

impl Default for MoveConfig {
    fn default() -> Self {
        MoveConfig {
            max_cycles: DEFAULT_MAX_CYCLES,
        }
    }
}

/// A labelling and its energy.
#[derive(Clone, Debug, PartialEq)]
pub struct Labelling<C> {
    /// One label per node.
    pub labels: Vec<i32>,
    /// E(labels) ([`Cost::FORBIDDEN`] if some node has a forbidden label).
    pub energy: C,
    /// The energy at the start and after every accepted move (non-increasing).
    pub trace: Vec<C>,
    /// Cycles run (a cycle with no accepted move ends the solve).
    pub cycles: usize,
    /// Max-flow problems solved.
    pub moves_tried: usize,
}

/// An energy as (number of forbidden assignments, sum of everything else), compared in
/// that order, which is exact even where the forbidden value is infinite.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Energy<C> {
    forbidden: usize,
    sum: C,
}

impl<C: Cost> Energy<C> {
    fn lt(&self, other: &Self) -> bool {
        match self.forbidden.cmp(&other.forbidden) {
            Ordering::Less => true,
            Ordering::Greater => false,
            Ordering::Equal => self.sum < other.sum,
        }
    }
    fn value(&self) -> C {
        if self.forbidden > 0 {
            C::FORBIDDEN
        } else {
            self.sum
        }
    }
}

/// Checked view of a problem: sizes and the pairwise table resolved.
struct Checked<'a, C: Cost> {
    n: usize,
    l: usize,
    unary: &'a [C],
    edges: &'a [[u32; 2]],
    weights: &'a [C],
    /// L×L pairwise values (Potts filled in when none was given).
    v: Vec<C>,
    /// V is Potts (1 off the diagonal): a pair's cost is just its edge weight.
    potts: bool,
    /// Stand-in for a forbidden unary inside the graph: more than any finite energy.
    big: C,
    /// Labels allowed at some node.
    allowed_somewhere: Vec<bool>,
}

/// Checks `p` (`edges_checked`: its edges are known to be in range for its nodes;
/// `weights_checked`: its weights are known to be finite and non-negative).
fn check_problem<'a, C: Cost>(
    p: &CrfProblem<'a, C>,
    need_metric: bool,
    edges_checked: bool,
    weights_checked: bool,
) -> Result<Checked<'a, C>> {
    let l = p.n_labels;
    ensure(l >= 1, "unary", || "needs at least one label".into())?;
    ensure(l <= i32::MAX as usize, "unary", || "too many labels".into())?;
    ensure(
        p.unary.len().is_multiple_of(l) && !p.unary.is_empty(),
        "unary",
        || {
            format!(
                "length {} is not a positive multiple of {l} labels",
                p.unary.len()
            )
        },
    )?;
    let n = p.unary.len() / l;
    ensure(n <= super::maxflow::MAX_NODES, "unary", || {
        "too many nodes".into()
    })?;
    // One branch-free (vectorised) pass settles the common case: every cost finite and
    // none forbidden. Only otherwise are the costs searched for the bad or forbidden.
    let (plain, umax) = C::plain_and_max_abs(p.unary);
    if let Some(k) = (!plain)
        .then(|| {
            p.unary
                .iter()
                .position(|&u| !(u.is_finite_value() || u == C::FORBIDDEN))
        })
        .flatten()
    {
        return Err(Error::invalid(
            "unary",
            format!(
                "holds {:?} at node {}, label {} (costs must be finite, or +inf / the maximum to forbid a label)",
                p.unary[k],
                k / l,
                k % l
            ),
        ));
    }
    ensure(p.weights.len() == p.edges.len(), "weights", || {
        format!(
            "length {} does not match the {} edges",
            p.weights.len(),
            p.edges.len()
        )
    })?;
    if let Some(k) = (!edges_checked)
        .then(|| {
            p.edges
                .iter()
                .position(|e| e[0] as usize >= n || e[1] as usize >= n)
        })
        .flatten()
    {
        return Err(Error::invalid(
            "edges",
            format!(
                "edge {k} = {:?} has a node index out of range for {n} nodes",
                p.edges[k]
            ),
        ));
    }
    let weights_ok = weights_checked
        || p.weights
            .iter()
            .fold(true, |ok, &w| ok & w.is_finite_value() & (w >= C::ZERO));
    if let Some(k) = (!weights_ok)
        .then(|| {
            p.weights
                .iter()
                .position(|&w| !(w.is_finite_value() && w >= C::ZERO))
        })
        .flatten()
    {
        return Err(Error::invalid(
            "weights",
            format!(
                "must be finite and non-negative, got {:?} at edge {k}",
                p.weights[k]
            ),
        ));
    }
    let v = match p.pairwise {
        None => (0..l * l)
            .map(|k| {
                if k / l == k % l {
                    C::ZERO
                } else {
                    C::from_i32(1)
                }
            })
            .collect(),
        Some(v) => {
            check_pairwise(v, l, need_metric)?;
            v.to_vec()
        }
    };
    // Every node needs an allowed label (without forbidden costs, all are allowed).
    let mut allowed_somewhere = vec![plain; l];
    let rows_to_check = if plain { 0 } else { n };
    for i in 0..rows_to_check {
        let row = &p.unary[i * l..(i + 1) * l];
        let mut any = false;
        for (a, &u) in row.iter().enumerate() {
            if u != C::FORBIDDEN {
                allowed_somewhere[a] = true;
                any = true;
            }
        }
        if !any {
            return Err(Error::invalid(
                "unary",
                format!("node {i} forbids every label"),
            ));
        }
    }
    let big = if plain {
        // Integer costs: every energy, and every move graph's flow (a few such terms
        // per node and edge), must fit, or the sums would wrap around silently.
        if C::EXACT {
            energy_bound(p.unary, l, p.weights, &v)
                .and_then(|t| t.checked_mul(C::from_i32(4)))
                .ok_or_else(|| {
                    Error::invalid(
                        "unary",
                        "integer costs too large: the energies could overflow int64; use \
                         smaller units or float costs",
                    )
                })?;
        } else {
            check_float_range(umax, n, p.weights, &v)?;
        }
        C::ZERO
    } else {
        forbidden_stand_in(p.unary, l, p.weights, &v)?
    };
    let one = C::from_i32(1);
    let potts = (0..l * l).all(|k| v[k] == if k / l == k % l { C::ZERO } else { one });
    Ok(Checked {
        n,
        l,
        unary: p.unary,
        edges: p.edges,
        weights: p.weights,
        v,
        potts,
        big,
        allowed_somewhere,
    })
}

/// Checks an L×L pairwise table: V(a,a) = 0, V(a,b) > 0 for a ≠ b, symmetric, finite,
/// and (for expansion) the triangle inequality.
fn check_pairwise<C: Cost>(v: &[C], l: usize, need_metric: bool) -> Result<()> {
    ensure(v.len() == l * l, "pairwise", || {
        format!(
            "must be {l}×{l} (the number of labels), got {} values",
            v.len()
        )
    })?;
    let at = |a: usize, b: usize| v[a * l + b];
    for a in 0..l {
        for b in 0..l {
            let x = at(a, b);
            ensure(x.is_finite_value() && x >= C::ZERO, "pairwise", || {
                format!("V[{a},{b}] = {x:?} must be finite and non-negative")
            })?;
            ensure((a == b) == (x == C::ZERO), "pairwise", || {
                format!("V[{a},{b}] = {x:?}: V(a,b) must be 0 exactly when a = b")
            })?;
            ensure(x == at(b, a), "pairwise", || {
                format!(
                    "not symmetric: V[{a},{b}] = {x:?} but V[{b},{a}] = {:?}",
                    at(b, a)
                )
            })?;
        }
    }
    if need_metric {
        for a in 0..l {
            for b in 0..l {
                for c in 0..l {
                    let lhs = at(a, c).to_f64();
                    let rhs = at(a, b).to_f64() + at(b, c).to_f64();
                    ensure(lhs <= rhs + METRIC_RTOL * rhs.abs(), "pairwise", || {
                        format!(
                            "not a metric (needed by alpha-expansion; use alpha_beta_swap for semi-metrics): V[{a},{c}] > V[{a},{b}] + V[{b},{c}]"
                        )
                    })?;
                }
            }
        }
    }
    Ok(())
}

/// 1 + the largest |energy| of any labelling without forbidden labels (Σ of each node's
/// largest allowed |unary| + Σ weight × the largest V), `None` on overflow.
fn energy_bound<C: Cost>(unary: &[C], l: usize, weights: &[C], v: &[C]) -> Option<C> {
    let mut vmax = C::ZERO;
    for &x in v {
        if x > vmax {
            vmax = x;
        }
    }
    let mut total = C::from_i32(1);
    for row in unary.chunks(l) {
        let mut m = C::ZERO;
        for &u in row {
            if u != C::FORBIDDEN {
                // checked: −i64::MIN does not exist
                let a = if u < C::ZERO {
                    u.checked_mul(C::from_i32(-1))?
                } else {
                    u
                };
                if a > m {
                    m = a;
                }
            }
        }
        total = total.checked_add(m)?;
    }
    for &w in weights {
        total = total.checked_add(w.mul(vmax)?)?;
    }
    Some(total)
}

/// Float costs: refuses a problem whose energies or move-graph flows could overflow to
/// infinity (weights × pairwise near the float range, or many huge costs). An
/// infinite capacity never saturates, so a max-flow on it would not end; energies
/// would not compare. Bounds every energy by n · max|unary| (`umax`) + Σ weights ·
/// max V (a cheap upper bound of [`energy_bound`]) and asks for head-room of 4.
fn check_float_range<C: Cost>(umax: f64, n: usize, weights: &[C], v: &[C]) -> Result<()> {
    let vmax = v.iter().map(|x| x.to_f64()).fold(0.0, f64::max);
    // Eight lanes vectorise the sum (the weights are known finite and >= 0).
    let mut lanes = [0.0f64; 8];
    let mut chunks = weights.chunks_exact(8);
    for c in &mut chunks {
        for (lane, &w) in lanes.iter_mut().zip(c) {
            *lane += w.to_f64();
        }
    }
    let wsum =
        lanes.iter().sum::<f64>() + chunks.remainder().iter().map(|w| w.to_f64()).sum::<f64>();
    let pairs = wsum * vmax;
    ensure((4.0 * pairs).is_finite(), "weights", || {
        format!(
            "weights × pairwise costs reach {} (sum of weights {} times the largest \
             pairwise value {}), too close to the float64 range for a graph cut; scale the \
             costs down",
            crate::error::brief(pairs),
            crate::error::brief(wsum),
            crate::error::brief(vmax)
        )
    })?;
    let bound = 1.0 + n as f64 * umax + pairs;
    ensure((4.0 * bound).is_finite(), "unary", || {
        format!(
            "costs too large for a graph cut (the largest |unary| {} over {n} nodes passes \
             the float64 range); scale the costs down",
            crate::error::brief(umax)
        )
    })
}

/// A cost larger than the energy of any labelling without forbidden labels, so that a
/// forbidden assignment inside a move graph always loses. Zero if nothing is forbidden.
fn forbidden_stand_in<C: Cost>(unary: &[C], l: usize, weights: &[C], v: &[C]) -> Result<C> {
    if !unary.contains(&C::FORBIDDEN) {
        return Ok(C::ZERO);
    }
    let too_large = || Error::invalid("unary", "costs too large to forbid labels safely");
    let total = energy_bound(unary, l, weights, v).ok_or_else(too_large)?;
    // Move graphs add up to a few such terms per node; keep head-room against overflow.
    let n = unary.len() / l;
    total
        .checked_mul(C::from_i32(4))
        .and_then(|t| t.checked_mul(C::from_i32(n.min(i32::MAX as usize) as i32)))
        .ok_or_else(too_large)?;
    Ok(total)
}

impl<C: Cost> Checked<'_, C> {
    #[inline(always)]
    fn u(&self, i: usize, a: usize) -> C {
        self.unary[i * self.l + a]
    }

    /// Unary cost with a forbidden value replaced by the stand-in.
    #[inline(always)]
    fn u_graph(&self, i: usize, a: usize) -> C {
        let u = self.u(i, a);
        if u == C::FORBIDDEN {
            self.big
        } else {
            u
        }
    }

    #[inline(always)]
    fn pair(&self, k: usize, a: i32, b: i32) -> C {
        if a == b {
            return C::ZERO;
        }
        if self.potts {
            return self.weights[k];
        }
        let v = self.v[a as usize * self.l + b as usize];
        // Checked at set-up not to overflow (weights × max V fit when costs do).
        self.weights[k].checked_mul(v).unwrap_or(C::FORBIDDEN)
    }

    fn energy_range(
        &self,
        labels: &[i32],
        nodes: std::ops::Range<usize>,
        edges: std::ops::Range<usize>,
    ) -> Energy<C> {
        let mut e = Energy {
            forbidden: 0,
            sum: C::ZERO,
        };
        for i in nodes {
            let u = self.u(i, labels[i] as usize);
            if u == C::FORBIDDEN {
                e.forbidden += 1;
            } else {
                e.sum += u;
            }
        }
        for k in edges {
            let [i, j] = self.edges[k];
            e.sum += self.pair(k, labels[i as usize], labels[j as usize]);
        }
        e
    }

    fn energy(&self, labels: &[i32]) -> Energy<C> {
        if self.n < PARALLEL_MIN_NODES {
            return self.energy_range(labels, 0..self.n, 0..self.edges.len());
        }
        let n_chunks = self.n.div_ceil(ENERGY_CHUNK);
        let m = self.edges.len();
        let parts: Vec<Energy<C>> = (0..n_chunks)
            .into_par_iter()
            .map(|c| {
                let nodes = c * ENERGY_CHUNK..((c + 1) * ENERGY_CHUNK).min(self.n);
                let e0 = m * c / n_chunks;
                let e1 = m * (c + 1) / n_chunks;
                self.energy_range(labels, nodes, e0..e1)
            })
            .collect();
        let mut e = Energy {
            forbidden: 0,
            sum: C::ZERO,
        };
        for p in parts {
            e.forbidden += p.forbidden;
            e.sum += p.sum;
        }
        e
    }

    fn check_init(&self, init: Option<&[i32]>) -> Result<Vec<i32>> {
        match init {
            Some(init) => {
                ensure(init.len() == self.n, "init", || {
                    format!("length {} does not match {} nodes", init.len(), self.n)
                })?;
                if let Some(i) = init.iter().position(|&a| a < 0 || a as usize >= self.l) {
                    return Err(Error::invalid(
                        "init",
                        format!("label {} at node {i} is not in 0..{}", init[i], self.l),
                    ));
                }
                Ok(init.to_vec())
            }
            None => Ok(self.argmin_unary()),
        }
    }

    /// The label of least unary cost at each node (the first on ties).
    fn argmin_unary(&self) -> Vec<i32> {
        let l = self.l;
        let pick = |row: &[C]| {
            let mut best = 0;
            for a in 1..l {
                let (u, b) = (row[a], row[best]);
                if u != C::FORBIDDEN && (b == C::FORBIDDEN || u < b) {
                    best = a;
                }
            }
            best as i32
        };
        if self.n < PARALLEL_MIN_NODES {
            self.unary.chunks(l).map(pick).collect()
        } else {
            self.unary.par_chunks(l).map(pick).collect()
        }
    }
}

/// The energy of `labels` (with `unary` N×L etc. as in [`CrfProblem`]).
/// Returns [`Cost::FORBIDDEN`] if a node has a forbidden label.
pub fn energy<C: Cost>(problem: &CrfProblem<C>, labels: &[i32]) -> Result<C> {
    let c = check_problem(problem, false, false, false)?;
    ensure(labels.len() == c.n, "labels", || {
        format!("length {} does not match {} nodes", labels.len(), c.n)
    })?;
    if let Some(i) = labels.iter().position(|&a| a < 0 || a as usize >= c.l) {
        return Err(Error::invalid(
            "labels",
            format!("label {} at node {i} is not in 0..{}", labels[i], c.l),
        ));
    }
    Ok(c.energy(labels).value())
}

/// The energy of `labels` under Potts costs (`pairwise` None), unchecked: the sum
/// [`CrfSolver`] computes (same order, so the same bits), which lets a caller that
/// tracks energies hand one to [`ExpansionHints::init_energy`] or compare it with a
/// [`Labelling`]'s. Sizes and labels must be in range (panics otherwise); a forbidden
/// label gives [`Cost::FORBIDDEN`].
pub(crate) fn potts_energy<C: Cost>(
    unary: &[C],
    n_labels: usize,
    edges: &[[u32; 2]],
    weights: &[C],
    labels: &[i32],
) -> C {
    let c = Checked {
        n: labels.len(),
        l: n_labels,
        unary,
        edges,
        weights,
        // Potts: `pair` reads neither; `energy` needs neither.
        v: Vec::new(),
        potts: true,
        big: C::ZERO,
        allowed_somewhere: Vec::new(),
    };
    c.energy(labels).value()
}

/// Alpha-expansion (metric `pairwise`), one shot. See [`CrfSolver`] to reuse storage.
pub fn alpha_expansion<C: Cost>(
    problem: &CrfProblem<C>,
    init: Option<&[i32]>,
    config: &MoveConfig,
) -> Result<Labelling<C>> {
    let n = problem.unary.len() / problem.n_labels.max(1);
    CrfSolver::new(n, problem.edges)?.alpha_expansion(problem, init, config)
}

/// Alpha-beta swap (semi-metric `pairwise`), one shot.
pub fn alpha_beta_swap<C: Cost>(
    problem: &CrfProblem<C>,
    init: Option<&[i32]>,
    config: &MoveConfig,
) -> Result<Labelling<C>> {
    let n = problem.unary.len() / problem.n_labels.max(1);
    CrfSolver::new(n, problem.edges)?.alpha_beta_swap(problem, init, config)
}

/// The labels a node labelled `own`, with unary row `row` and sum of edge weights
/// `slack`, may switch to in an expansion move on a Potts problem with nothing
/// forbidden (bit per label): those whose unary exceeds its own by at most `slack`,
/// the exact pruning test of the moves (`CrfSolver::expansion_move`).
#[inline(always)]
pub fn potts_candidate_mask<C: Cost>(row: &[C], own: usize, slack: C) -> u64 {
    let base = row[own];
    let mask = row
        .iter()
        .enumerate()
        .fold(0u64, |m, (a, &u)| m | (((u - base <= slack) as u64) << a));
    mask & !(1u64 << own)
}

/// The state of one `alpha_expansion` call between its cycles.
struct ExpansionRun<C: Cost> {
    labels: Vec<i32>,
    e: Energy<C>,
    trace: Vec<C>,
    /// Accepted moves so far.
    version: usize,
    /// Per label: the version at which its move last failed.
    failed_at: Vec<usize>,
    tried: usize,
}

/// What a caller inside the crate may know about an expansion's problem and so spare
/// the solver from working out again (see [`CrfSolver::expansion_with`]). Wrong hints
/// give a wrong labelling; each is checked in debug builds.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ExpansionHints<'a, C> {
    /// The per-label candidate sets the expansion starts from, computed by the caller
    /// (in parallel, where it computes the unary terms): for each block of 64 nodes
    /// `w` and label `a`, `candidates[w * l + a]` has bit `b` set where node `64w +
    /// b`'s [`potts_candidate_mask`] (of its unary row, its `init` label and its sum of
    /// edge weights in edge order) has bit `a` set. Used when the problem takes that
    /// form (Potts, nothing forbidden, at most 64 labels, pruning on, finite weight
    /// sums), else the sets are collected by the solver.
    pub candidates: Option<&'a [u64]>,
    /// E(init), as [`potts_energy`] gives it for this problem (bit for bit); used when
    /// nothing is forbidden.
    pub init_energy: Option<C>,
    /// The problem's edges and weights are, value for value, those of this solver's
    /// last expansion that returned `Ok` (an E-step's neighbourhood graph and weights
    /// stay the same across its frame's EM iterations): their checks, the edge
    /// comparison and the weight sums are not redone.
    pub same_structure: bool,
}

impl<C> Default for ExpansionHints<'_, C> {
    fn default() -> Self {
        ExpansionHints {
            candidates: None,
            init_energy: None,
            same_structure: false,
        }
    }
}

/// No work beside an expansion's cycles (for [`CrfSolver::expansion_with`]).
pub(crate) const NO_WORK_BESIDE: Option<&mut fn(&[i32], &AtomicBool)> = None;

/// Move-making solver for a fixed node set and edge list: the move graph is built once
/// and only its capacities are reset for each move; buffers are reused across calls
/// (the E-step calls it several times per frame on the same neighbourhood graph).
#[derive(Clone, Debug)]
pub struct CrfSolver<C: Cost> {
    graph: Graph<C>,
    edges: Vec<[u32; 2]>,
    /// Per-node move costs for "keep" (x = 0, source side) and "switch" (x = 1).
    e0: Vec<C>,
    e1: Vec<C>,
    /// Per node: the sum of its edges' weights, `None` on overflow (see
    /// `expansion_move`).
    incident_weight: Vec<Option<C>>,
    /// Every `incident_weight` is finite (set with it).
    weights_finite: bool,
    /// The edge weights `incident_weight` was summed from (none yet).
    weights_of_sums: Option<Vec<C>>,
    /// Per node, in the current expansion move: may switch to α (not labelled α, not
    /// pruned). Only free nodes are in the cut. All false between moves.
    is_free: Vec<bool>,
    /// Per label α, during one `alpha_expansion` call: a bit set of every node that
    /// could be free in α's move (a superset: each node that passed the pruning test for
    /// α at the start of the call or when it last switched label), so that a move visits
    /// these instead of every node. A bit set iterates in ascending node order and holds
    /// no duplicates for free; sorted lists cost a sort per move, which on dense
    /// problems (most nodes candidates for most labels) took longer than the full scan
    /// they replace.
    candidates: Vec<BitSet>,
    /// The free nodes of the current move, ascending; then those that switched.
    free: Vec<u32>,
    /// Node → incident edges (CSR, ascending edge index, self-loops left out).
    adj_start: Vec<u32>,
    adj: Vec<u32>,
    /// Edges and nodes given capacities since the graph was last cleared, and whether
    /// that list is complete (a swap move clears the whole graph instead).
    touched_edges: Vec<u32>,
    touched_nodes: Vec<u32>,
    touched_valid: bool,
    /// Whether expansion moves leave provably fixed nodes out of the cut.
    prune: bool,
    /// The labels a move proposes: equal to the labels it starts from except at the
    /// nodes it switches (and restored there when the move is rejected).
    candidate: Vec<i32>,
}

// Node and label indices address several parallel arrays at once in these loops.
#[allow(clippy::needless_range_loop)]
impl<C: Cost> CrfSolver<C> {
    /// A solver for `n_nodes` nodes joined by `edges`.
    pub fn new(n_nodes: usize, edges: &[[u32; 2]]) -> Result<Self> {
        if let Some(k) = edges
            .iter()
            .position(|e| e[0] as usize >= n_nodes || e[1] as usize >= n_nodes)
        {
            return Err(Error::invalid(
                "edges",
                format!(
                    "edge {k} = {:?} has a node index out of range for {n_nodes} nodes",
                    edges[k]
                ),
            ));
        }
        let mut graph = Graph::with_capacity(n_nodes, edges.len());
        graph.keep_edge_index();
        for &[i, j] in edges {
            graph.add_edge(i as usize, j as usize, C::ZERO, C::ZERO)?;
        }
        graph.finalize();
        let mut adj_start = vec![0u32; n_nodes + 1];
        for &[i, j] in edges {
            if i != j {
                adj_start[i as usize + 1] += 1;
                adj_start[j as usize + 1] += 1;
            }
        }
        for i in 0..n_nodes {
            adj_start[i + 1] += adj_start[i];
        }
        let mut pos = adj_start.clone();
        let mut adj = vec![0u32; adj_start[n_nodes] as usize];
        for (k, &[i, j]) in edges.iter().enumerate() {
            if i != j {
                for x in [i as usize, j as usize] {
                    adj[pos[x] as usize] = k as u32;
                    pos[x] += 1;
                }
            }
        }
        Ok(CrfSolver {
            graph,
            edges: edges.to_vec(),
            e0: vec![C::ZERO; n_nodes],
            e1: vec![C::ZERO; n_nodes],
            incident_weight: vec![None; n_nodes],
            weights_finite: false,
            weights_of_sums: None,
            is_free: vec![false; n_nodes],
            candidates: Vec::new(),
            free: Vec::new(),
            adj_start,
            adj,
            touched_edges: Vec::new(),
            touched_nodes: Vec::new(),
            touched_valid: true,
            prune: true,
            candidate: vec![0; n_nodes],
        })
    }

    /// Turns on (the default) or off the exact pruning of expansion moves: a node whose
    /// switch to α costs more unary than all its edges could ever give back keeps its
    /// label in every optimal move, so it is left out of the cut. Off gives the plain
    /// construction (same move energies; only ties may resolve differently).
    pub fn set_pruning(&mut self, on: bool) {
        self.prune = on;
    }

    fn check<'a>(&self, problem: &CrfProblem<'a, C>, metric: bool) -> Result<Checked<'a, C>> {
        self.check_hinted(problem, metric, false)
    }

    /// Whether to take [`ExpansionHints::same_structure`] (`hinted`) for `problem`: only
    /// where an expansion has summed its weights and the lengths agree.
    fn structure_known(&self, problem: &CrfProblem<C>, hinted: bool) -> bool {
        hinted
            && self.weights_of_sums.is_some()
            && problem.edges.len() == self.edges.len()
            && problem.weights.len() == self.edges.len()
    }

    /// [`Self::check`], with the edges and weights not checked again where
    /// `same_structure` (from [`Self::structure_known`]).
    fn check_hinted<'a>(
        &self,
        problem: &CrfProblem<'a, C>,
        metric: bool,
        same_structure: bool,
    ) -> Result<Checked<'a, C>> {
        debug_assert!(
            !same_structure
                || (problem.edges == self.edges.as_slice()
                    && self.weights_of_sums.as_deref() == Some(problem.weights)),
            "ExpansionHints::same_structure given for a different structure"
        );
        // The solver's own edges were checked against its node count when it was
        // built; equal edges and node count need no second range check.
        let same_edges = same_structure || problem.edges == self.edges.as_slice();
        let n = problem.unary.len() / problem.n_labels.max(1);
        let c = check_problem(
            problem,
            metric,
            same_edges && n == self.graph.n_nodes(),
            same_structure,
        )?;
        ensure(c.n == self.graph.n_nodes(), "unary", || {
            format!(
                "{} nodes, but the solver was built for {}",
                c.n,
                self.graph.n_nodes()
            )
        })?;
        ensure(same_edges, "edges", || {
            "differ from the edges the solver was built with".into()
        })?;
        Ok(c)
    }

    /// Alpha-expansion: for each label α in turn, every node may switch to α in one
    /// min-cut move; repeats until a cycle brings no improvement or `max_cycles`.
    pub fn alpha_expansion(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
    ) -> Result<Labelling<C>> {
        self.expansion_with(
            problem,
            init,
            config,
            ExpansionHints::default(),
            NO_WORK_BESIDE,
        )
        .map(|(labelling, _)| labelling)
    }

    /// [`Self::alpha_expansion`] with `beside` run on another worker of rayon's pool
    /// beside every cycle, for the labelling that cycle starts from. The expansion
    /// ends with a cycle that accepts no move, so the labelling that cycle starts from
    /// is usually the result: `beside` can start the work that needs the result
    /// before the last cycle has confirmed it (beside the first cycle, for the case
    /// that the starting labelling is already the result). Returns `beside`'s
    /// output for the cycle that ended the solve when it accepted no move (its
    /// labelling is then exactly the result's), else `None`. The flag passed to
    /// `beside` is raised as soon as its cycle accepts a move: its output will be
    /// dropped, and it may stop early. The labelling is the same as
    /// [`Self::alpha_expansion`]'s.
    pub fn alpha_expansion_beside<R, F>(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
        beside: &mut F,
    ) -> Result<(Labelling<C>, Option<R>)>
    where
        R: Send,
        F: FnMut(&[i32], &AtomicBool) -> R + Send,
    {
        self.expansion_with(
            problem,
            init,
            config,
            ExpansionHints::default(),
            Some(beside),
        )
    }

    /// [`Self::alpha_expansion`] (with `beside`, [`Self::alpha_expansion_beside`]),
    /// sparing the work `hints` make unneeded. Wrong hints give a wrong labelling,
    /// hence crate-only.
    pub(crate) fn expansion_with<R, F>(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
        hints: ExpansionHints<C>,
        mut beside: Option<&mut F>,
    ) -> Result<(Labelling<C>, Option<R>)>
    where
        R: Send,
        F: FnMut(&[i32], &AtomicBool) -> R + Send,
    {
        let same_structure = self.structure_known(problem, hints.same_structure);
        let c = self.check_hinted(problem, true, same_structure)?;
        let labels = c.check_init(init)?;
        self.prepare_expansion(&c, same_structure);
        match hints.candidates {
            Some(words)
                if self.masks_apply(&c)
                    && init.is_some()
                    && words.len() == c.n.div_ceil(64) * c.l =>
            {
                self.set_candidates(&c, words)
            }
            _ => self.collect_candidates(&c, &labels),
        }
        self.candidate.copy_from_slice(&labels);
        let e = match hints.init_energy {
            Some(sum) if c.big == C::ZERO => {
                debug_assert!(
                    c.energy(&labels).sum == sum,
                    "ExpansionHints::init_energy differs from the energy"
                );
                Energy { forbidden: 0, sum }
            }
            _ => c.energy(&labels),
        };
        let mut run = ExpansionRun {
            labels,
            e,
            trace: vec![e.value()],
            version: 0,
            failed_at: vec![usize::MAX; c.l],
            tried: 0,
        };
        let mut cycles = 0;
        let mut beside_output = None;
        // The labelling the work beside a cycle sees (a copy: the cycle changes its own).
        let mut seen = Vec::new();
        while cycles < config.max_cycles {
            cycles += 1;
            let improved = match beside.as_deref_mut() {
                Some(work) => {
                    seen.clone_from(&run.labels);
                    let accepted = AtomicBool::new(false);
                    let (improved, output) = rayon::join(
                        || self.expansion_cycle(&c, &mut run, Some(&accepted)),
                        || work(&seen, &accepted),
                    );
                    if !improved {
                        beside_output = Some(output);
                    }
                    improved
                }
                None => self.expansion_cycle(&c, &mut run, None),
            };
            if !improved {
                break;
            }
        }
        // The moves update the energy by differences; the result is summed afresh so
        // that it equals `energy(labels)` exactly (floats may differ in the last bits
        // from the running value, which the trace keeps). With no move accepted the
        // labels are the start's, whose energy was summed so.
        let energy = if run.version == 0 {
            run.e.value()
        } else {
            c.energy(&run.labels).value()
        };
        let labelling = Labelling {
            labels: run.labels,
            energy,
            trace: run.trace,
            cycles,
            moves_tried: run.tried,
        };
        Ok((labelling, beside_output))
    }

    /// One cycle of expansion moves over every label; whether a move was accepted (then
    /// `accepted`, if given, is raised at the first).
    fn expansion_cycle(
        &mut self,
        c: &Checked<C>,
        run: &mut ExpansionRun<C>,
        accepted: Option<&AtomicBool>,
    ) -> bool {
        // `version` counts accepted moves; a label whose move failed at the current
        // version would fail again (same input), so it is skipped. An accepted move
        // carries a failed label on to the new version when its switched nodes and
        // their neighbours stay clear of that label's last move (see
        // `still_failing`): the label's move would be the same max-flow problem again.
        let mut improved = false;
        for alpha in 0..c.l {
            if !c.allowed_somewhere[alpha] || run.failed_at[alpha] == run.version {
                continue;
            }
            run.tried += 1;
            let new_e = self.expansion_move(c, &run.labels, alpha as i32, &run.e);
            if new_e.lt(&run.e) {
                if !improved {
                    if let Some(flag) = accepted {
                        flag.store(true, AtomicOrdering::Relaxed);
                    }
                }
                std::mem::swap(&mut run.labels, &mut self.candidate);
                // The proposal is the labelling again (see `candidate`).
                for &i in &self.free {
                    self.candidate[i as usize] = alpha as i32;
                }
                self.add_switched_candidates(c, alpha);
                run.e = new_e;
                run.trace.push(run.e.value());
                let version = run.version;
                for (beta, f) in run.failed_at.iter_mut().enumerate() {
                    if *f == version && self.still_failing(c, beta) {
                        *f = version + 1;
                    }
                }
                run.version += 1;
                improved = true;
            } else {
                for &i in &self.free {
                    self.candidate[i as usize] = run.labels[i as usize];
                }
                run.failed_at[alpha] = run.version;
            }
        }
        improved
    }

    /// After an accepted move (its switched nodes in `self.free`, their new candidate
    /// sets added), whether the move of `beta`, which failed before it, is sure to
    /// fail again. After a failed move a label's candidate set is exactly that move's
    /// free nodes (the others leave it, see `expansion_move`). If no switched node and
    /// no neighbour of one is in that set now, then the free nodes, their labels and
    /// their neighbours' labels are what they were, so the move would build the same
    /// graph, find the same cut and bring the same (non-negative) change again.
    fn still_failing(&self, c: &Checked<C>, beta: usize) -> bool {
        let set = &self.candidates[beta];
        self.free.iter().all(|&iu| {
            let i = iu as usize;
            let (lo, hi) = (self.adj_start[i] as usize, self.adj_start[i + 1] as usize);
            !set.get(i)
                && self.adj[lo..hi].iter().all(|&k| {
                    let [p, q] = c.edges[k as usize];
                    !set.get(if p as usize == i { q } else { p } as usize)
                })
        })
    }

    /// Per-problem set-up of the expansion moves: each node's sum of edge weights.
    fn prepare_expansion(&mut self, c: &Checked<C>, same_structure: bool) {
        // The edges are the solver's; with the weights of the last call the sums are
        // those already there (the EM's E-steps all have the same weights).
        if same_structure || self.weights_of_sums.as_deref() == Some(c.weights) {
            return;
        }
        let kept = self.weights_of_sums.get_or_insert_with(Vec::new);
        kept.clear();
        kept.extend_from_slice(c.weights);
        self.incident_weight.fill(Some(C::ZERO));
        for (&[i, j], &w) in c.edges.iter().zip(c.weights) {
            if i != j {
                for x in [i as usize, j as usize] {
                    self.incident_weight[x] =
                        self.incident_weight[x].and_then(|s| s.checked_add(w));
                }
            }
        }
        self.weights_finite = self.incident_weight.iter().all(Option::is_some);
    }

    /// Whether every node's candidate labels are its [`potts_candidate_mask`] (the
    /// fast path of `add_candidate` for every node).
    fn masks_apply(&self, c: &Checked<C>) -> bool {
        self.prune && c.potts && c.big == C::ZERO && c.l <= 64 && self.weights_finite
    }

    /// The candidate sets an expansion of `problem` from `labels` collects, as the
    /// words [`Self::expansion_with`] takes (for tests of callers that compute them).
    #[cfg(test)]
    pub(crate) fn collected_candidate_words(
        &mut self,
        problem: &CrfProblem<C>,
        labels: &[i32],
    ) -> Vec<u64> {
        let c = self.check(problem, true).unwrap();
        assert!(self.prune && c.potts);
        self.prepare_expansion(&c, false);
        self.collect_candidates(&c, labels);
        let n_words = c.n.div_ceil(64);
        (0..n_words * c.l)
            .map(|k| self.candidates[k % c.l].word(k / c.l))
            .collect()
    }

    /// The candidate sets from the caller's words (see [`Self::expansion_with`]).
    fn set_candidates(&mut self, c: &Checked<C>, words: &[u64]) {
        self.candidates.resize_with(c.l, || BitSet::new(c.n));
        for (a, set) in self.candidates.iter_mut().enumerate() {
            for (w, block) in words.chunks_exact(c.l).enumerate() {
                set.set_word(w, block[a]);
            }
        }
    }

    /// Whether node `i`, labelled `fi` (≠ α), must be in the cut of α's move: the exact
    /// pruning test of [`Self::expansion_move`] does not fix it.
    #[inline(always)]
    fn may_switch(&self, c: &Checked<C>, i: usize, fi: usize, a: usize) -> bool {
        if !self.prune {
            return true;
        }
        match self.incident_weight[i].and_then(|w| w.mul(c.v[fi * c.l + a])) {
            Some(slack) => c.u_graph(i, a) - c.u_graph(i, fi) <= slack,
            None => true, // overflow: no pruning for this node
        }
    }

    /// The per-label candidate sets of one `alpha_expansion` call: one pass over the
    /// nodes' unary rows instead of one per move.
    fn collect_candidates(&mut self, c: &Checked<C>, labels: &[i32]) {
        self.candidates.resize_with(c.l, || BitSet::new(c.n));
        self.candidates.iter_mut().for_each(BitSet::clear_all);
        for (i, &fi) in labels.iter().enumerate() {
            self.add_candidate(c, i, fi as usize);
        }
    }

    /// After an accepted move of `alpha`: the nodes that switched (`self.free`) join
    /// the sets of the labels they may now switch to.
    fn add_switched_candidates(&mut self, c: &Checked<C>, alpha: usize) {
        for k in 0..self.free.len() {
            self.add_candidate(c, self.free[k] as usize, alpha);
        }
    }

    /// Puts node `i`, labelled `fi`, in the set of every other label it may switch to.
    #[inline]
    fn add_candidate(&mut self, c: &Checked<C>, i: usize, fi: usize) {
        // Potts without forbidden costs (the EM's case): V(f_i, α) = 1 and the graph's
        // unary is the unary, so the test of `may_switch` is U_i(α) − U_i(f_i) ≤ W_i
        // for every α at once, as a bit mask (same arithmetic, same outcome).
        if self.prune && c.potts && c.big == C::ZERO && c.l <= 64 {
            if let Some(slack) = self.incident_weight[i] {
                let mut mask = potts_candidate_mask(&c.unary[i * c.l..(i + 1) * c.l], fi, slack);
                while mask != 0 {
                    self.candidates[mask.trailing_zeros() as usize].set(i);
                    mask &= mask - 1;
                }
                return;
            }
        }
        for a in 0..c.l {
            if a != fi && self.may_switch(c, i, fi, a) {
                self.candidates[a].set(i);
            }
        }
    }

    /// Builds and solves the expansion move of `alpha` from `labels`, whose energy is
    /// `e`; leaves the moved labelling in `self.candidate` (which must hold `labels`
    /// on entry; only the switched nodes, left in `self.free`, are written) and returns
    /// its energy.
    ///
    /// Only the free nodes (see below) and their edges are visited: the move costs
    /// O(N) for the unary terms plus work proportional to the free nodes' edges, not a
    /// pass over every edge. The new energy is `e` plus the change on the nodes that
    /// switched and their edges.
    fn expansion_move(
        &mut self,
        c: &Checked<C>,
        labels: &[i32],
        alpha: i32,
        e: &Energy<C>,
    ) -> Energy<C> {
        let a = alpha as usize;
        if self.touched_valid {
            self.graph
                .reset_touched(&self.touched_edges, &self.touched_nodes);
        } else {
            self.graph.reset();
        }
        self.touched_edges.clear();
        self.touched_nodes.clear();
        self.touched_valid = true;
        // Pruning (exact). Take any optimal move in which node i (label f_i ≠ α) switches
        // to α and switch i back: its unary term drops by U_i(α) − U_i(f_i), and each
        // edge term w·V(α, x_j) becomes w·V(f_i, x_j) ≤ w·V(f_i, α) + w·V(α, x_j)
        // (triangle inequality), so the edges rise by at most slack_i = Σ_j w_ij·V(f_i, α)
        // = V(f_i, α)·W_i with W_i the sum of i's edge weights (computed once per call).
        // Where U_i(α) − U_i(f_i) > slack_i that would lower an optimal energy, so i keeps
        // f_i in every optimal move and can be left out of the cut. On the EM's body
        // parts this removes most nodes from most moves (points far from segment α).
        // The nodes left, not labelled α, are the free ones.
        // Only α's candidates can pass (see `candidates`); visited in ascending order, so
        // the move is the one a scan over every node would build. A candidate that is
        // not free leaves α's set: it can become free only by switching label, which
        // puts it back (`add_switched_candidates`).
        self.free.clear();
        let mut candidates = std::mem::take(&mut self.candidates[a]);
        let this = &mut *self;
        candidates.retain(|i| {
            let fi = labels[i];
            let free = fi != alpha && this.may_switch(c, i, fi as usize, a);
            if free {
                this.e0[i] = c.u_graph(i, fi as usize);
                this.e1[i] = c.u_graph(i, a);
                this.is_free[i] = true;
                this.free.push(i as u32);
            }
            free
        });
        self.candidates[a] = candidates;
        // Edge terms, x = 1 meaning "switch to α", fixed nodes at x = 0 and α nodes at
        // α either way. Each free node adds its own terms, edge by edge in ascending
        // order; an edge between two free nodes gets its capacity from its first end.
        for &iu in &self.free {
            let i = iu as usize;
            let (lo, hi) = (self.adj_start[i] as usize, self.adj_start[i + 1] as usize);
            for &ku in &self.adj[lo..hi] {
                let k = ku as usize;
                let [p, q] = c.edges[k];
                let (p, q) = (p as usize, q as usize);
                let (fp, fq) = (labels[p], labels[q]);
                let i_is_p = p == i;
                let other = if i_is_p { q } else { p };
                if labels[other] == alpha {
                    // x_i = 0 keeps (f_i, α); x_i = 1 gives (α, α) = 0.
                    self.e0[i] += if i_is_p {
                        c.pair(k, fp, alpha)
                    } else {
                        c.pair(k, alpha, fq)
                    };
                } else if !self.is_free[other] {
                    // The other end stays: (f_p, f_q) or i's side at α.
                    self.e0[i] += c.pair(k, fp, fq);
                    self.e1[i] += if i_is_p {
                        c.pair(k, alpha, fq)
                    } else {
                        c.pair(k, fp, alpha)
                    };
                } else {
                    // Both free: E(0,0) = A, E(0,1) = B, E(1,0) = C, E(1,1) = 0; p pays
                    // A or C by x_p, q pays C for x_q = 0 and p→q carries B + C − A.
                    let ea = c.pair(k, fp, fq);
                    let ec = c.pair(k, alpha, fq);
                    if i_is_p {
                        self.e0[i] += ea;
                        self.e1[i] += ec;
                        let eb = c.pair(k, fp, alpha);
                        // ≥ 0 by the triangle inequality (clamped against float rounding).
                        let mut cap = eb + ec - ea;
                        if cap < C::ZERO {
                            cap = C::ZERO;
                        }
                        self.graph.set_edge_caps_unchecked(k, cap, C::ZERO);
                        self.touched_edges.push(ku);
                    } else {
                        self.e0[i] += ec;
                    }
                }
            }
        }
        for &iu in &self.free {
            let i = iu as usize;
            let (x0, x1) = (self.e0[i], self.e1[i]);
            let m = x0.min_of(x1);
            // Source side (x = 0, keep) pays the sink arc and vice versa.
            self.graph.update_tweights_unchecked(i, x1 - m, x0 - m);
        }
        self.touched_nodes.extend_from_slice(&self.free);
        // Only the free nodes have terminal arcs (and edges): the solve visits them alone.
        self.graph.maxflow_seeded(&self.free);
        // The switched nodes: free and on the sink side.
        for &i in &self.free {
            self.is_free[i as usize] = false;
        }
        let graph = &self.graph;
        self.free.retain(|&i| graph.is_sink_side(i as usize));
        for &i in &self.free {
            self.candidate[i as usize] = alpha;
        }
        // The energy change: unary terms of the switched nodes, then every edge with a
        // switched end once (from its first end when both switched).
        let mut forbidden = e.forbidden as isize;
        let mut sum = e.sum;
        for &iu in &self.free {
            let i = iu as usize;
            let old = c.u(i, labels[i] as usize);
            let new = c.u(i, a);
            if old == C::FORBIDDEN {
                forbidden -= 1;
            } else {
                sum -= old;
            }
            if new == C::FORBIDDEN {
                forbidden += 1;
            } else {
                sum += new;
            }
            let (lo, hi) = (self.adj_start[i] as usize, self.adj_start[i + 1] as usize);
            for &ku in &self.adj[lo..hi] {
                let k = ku as usize;
                let [p, q] = c.edges[k];
                let (p, q) = (p as usize, q as usize);
                let other = if p == i { q } else { p };
                if self.candidate[other] != labels[other] && p != i {
                    continue; // both switched: counted from p
                }
                sum += c.pair(k, self.candidate[p], self.candidate[q]);
                sum -= c.pair(k, labels[p], labels[q]);
            }
        }
        Energy {
            forbidden: forbidden as usize,
            sum,
        }
    }

    /// Alpha-beta swap: for each pair of labels (α, β), the nodes labelled α or β may
    /// exchange them in one min-cut move; repeats until a cycle brings no improvement.
    pub fn alpha_beta_swap(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
    ) -> Result<Labelling<C>> {
        let c = self.check(problem, false)?;
        let mut labels = c.check_init(init)?;
        let mut e = c.energy(&labels);
        let mut trace = vec![e.value()];
        let l = c.l;
        let mut version = 0usize;
        let mut failed_at = vec![usize::MAX; l * l];
        let mut count = vec![0usize; l];
        let (mut cycles, mut tried) = (0, 0);
        while cycles < config.max_cycles {
            cycles += 1;
            let mut improved = false;
            for alpha in 0..l {
                for beta in alpha + 1..l {
                    count.fill(0);
                    for &x in &labels {
                        count[x as usize] += 1;
                    }
                    let useless = count[alpha] + count[beta] == 0
                        || !c.allowed_somewhere[alpha] && count[alpha] == 0
                        || !c.allowed_somewhere[beta] && count[beta] == 0;
                    if useless || failed_at[alpha * l + beta] == version {
                        continue;
                    }
                    tried += 1;
                    let new_e = self.swap_move(&c, &labels, alpha as i32, beta as i32);
                    if new_e.lt(&e) {
                        std::mem::swap(&mut labels, &mut self.candidate);
                        e = new_e;
                        trace.push(e.value());
                        version += 1;
                        improved = true;
                    } else {
                        failed_at[alpha * l + beta] = version;
                    }
                }
            }
            if !improved {
                break;
            }
        }
        Ok(Labelling {
            labels,
            energy: e.value(),
            trace,
            cycles,
            moves_tried: tried,
        })
    }

    /// Builds and solves the swap move of (α, β): x = 0 gives α, x = 1 gives β.
    fn swap_move(&mut self, c: &Checked<C>, labels: &[i32], alpha: i32, beta: i32) -> Energy<C> {
        let (a, b) = (alpha as usize, beta as usize);
        let in_set = |x: i32| x == alpha || x == beta;
        self.graph.reset();
        // Swap moves set capacities anywhere: the next expansion move clears it all.
        self.touched_valid = false;
        for i in 0..c.n {
            if in_set(labels[i]) {
                self.e0[i] = c.u_graph(i, a);
                self.e1[i] = c.u_graph(i, b);
            }
        }
        for (k, &[i, j]) in c.edges.iter().enumerate() {
            let (i, j) = (i as usize, j as usize);
            let (fi, fj) = (labels[i], labels[j]);
            if i == j {
                continue;
            }
            match (in_set(fi), in_set(fj)) {
                (true, true) => {
                    let eb = c.pair(k, alpha, beta);
                    let ec = c.pair(k, beta, alpha);
                    // A = D = 0: unary parts C·x_i and C(1 − x_j), arc B + C.
                    self.e1[i] += ec;
                    self.e0[j] += ec;
                    self.graph.set_edge_caps_unchecked(k, eb + ec, C::ZERO);
                }
                (true, false) => {
                    self.e0[i] += c.pair(k, alpha, fj);
                    self.e1[i] += c.pair(k, beta, fj);
                }
                (false, true) => {
                    self.e0[j] += c.pair(k, fi, alpha);
                    self.e1[j] += c.pair(k, fi, beta);
                }
                (false, false) => {}
            }
        }
        for i in 0..c.n {
            if in_set(labels[i]) {
                let (x0, x1) = (self.e0[i], self.e1[i]);
                let m = x0.min_of(x1);
                self.graph.update_tweights_unchecked(i, x1 - m, x0 - m);
            }
        }
        self.graph.maxflow();
        for i in 0..c.n {
            self.candidate[i] = if in_set(labels[i]) {
                if self.graph.is_sink_side(i) {
                    beta
                } else {
                    alpha
                }
            } else {
                labels[i]
            };
        }
        c.energy(&self.candidate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
                12, 5, 16, 15, 2, 10, 12, 12, 7, 14, 17, 4, 18, 15, 14, 7, 10, 4, 14, 4, 2, 6, 18,
                13, 6, 14, 4, 16,
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

    /// Integer costs whose energies could pass int64 are refused (they used to wrap:
    /// four nodes at 2⁶² each reported energy 0); the largest safe ones still solve.
    #[test]
    fn float_costs_that_could_overflow_are_refused_not_looped_on() {
        // weights × pairwise overflows to inf: once a max-flow that never ended.
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
                assert!(
                    matches!(r, Some(Error::InvalidArgument { ref name, .. }) if name == "unary")
                );
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
            assert!(
                matches!(err, Err(Error::InvalidArgument { ref name, .. }) if name == "pairwise")
            );
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
    fn expansion_rebuilding_candidates(
        p: &CrfProblem<i64>,
        init: &[i32],
        cycles: usize,
    ) -> Vec<i32> {
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
}

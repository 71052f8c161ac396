//! The CRF energy: cost types, the problem and the checks that resolve it into the
//! form the moves read ([`Checked`]), and the energy of a labelling.

use crate::error::{ensure, Error, Result};
use crate::graphcut::maxflow::Capacity;
use rayon::prelude::*;
use std::cmp::Ordering;

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
        // +inf too). Sums in eight lanes vectorise, where a fold of comparisons runs
        // one value at a time (these checks are most of an E-step's).
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
pub(super) struct Energy<C> {
    pub(super) forbidden: usize,
    pub(super) sum: C,
}

impl<C: Cost> Energy<C> {
    pub(super) fn lt(&self, other: &Self) -> bool {
        match self.forbidden.cmp(&other.forbidden) {
            Ordering::Less => true,
            Ordering::Greater => false,
            Ordering::Equal => self.sum < other.sum,
        }
    }
    pub(super) fn value(&self) -> C {
        if self.forbidden > 0 {
            C::FORBIDDEN
        } else {
            self.sum
        }
    }
}

/// Checked view of a problem: sizes and the pairwise table resolved.
pub(super) struct Checked<'a, C: Cost> {
    pub(super) n: usize,
    pub(super) l: usize,
    pub(super) unary: &'a [C],
    pub(super) edges: &'a [[u32; 2]],
    pub(super) weights: &'a [C],
    /// L×L pairwise values (Potts filled in when none was given).
    pub(super) v: Vec<C>,
    /// V is Potts (1 off the diagonal): a pair's cost is just its edge weight.
    pub(super) potts: bool,
    /// Stand-in for a forbidden unary inside the graph: more than any finite energy.
    pub(super) big: C,
    /// Labels allowed at some node.
    pub(super) allowed_somewhere: Vec<bool>,
}

/// Checks `p` (`edges_checked`: its edges are known to be in range for its nodes;
/// `weights_checked`: its weights are known to be finite and non-negative).
pub(super) fn check_problem<'a, C: Cost>(
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
    ensure(n <= crate::graphcut::maxflow::MAX_NODES, "unary", || {
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
pub(super) fn check_pairwise<C: Cost>(v: &[C], l: usize, need_metric: bool) -> Result<()> {
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
pub(super) fn energy_bound<C: Cost>(unary: &[C], l: usize, weights: &[C], v: &[C]) -> Option<C> {
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
pub(super) fn forbidden_stand_in<C: Cost>(
    unary: &[C],
    l: usize,
    weights: &[C],
    v: &[C],
) -> Result<C> {
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
    pub(super) fn u(&self, i: usize, a: usize) -> C {
        self.unary[i * self.l + a]
    }

    /// Unary cost with a forbidden value replaced by the stand-in.
    #[inline(always)]
    pub(super) fn u_graph(&self, i: usize, a: usize) -> C {
        let u = self.u(i, a);
        if u == C::FORBIDDEN {
            self.big
        } else {
            u
        }
    }

    #[inline(always)]
    pub(super) fn pair(&self, k: usize, a: i32, b: i32) -> C {
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

    pub(super) fn energy_range(
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

    pub(super) fn energy(&self, labels: &[i32]) -> Energy<C> {
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

    pub(super) fn check_init(&self, init: Option<&[i32]>) -> Result<Vec<i32>> {
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
    pub(super) fn argmin_unary(&self) -> Vec<i32> {
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

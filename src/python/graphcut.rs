//! Max-flow graphs and CRF move-making solvers for Python (`depthpose.graphcut`).

use super::convert::{
    check_result_bytes, f64_array, i64_array, invalid, to_numpy, too_large, wrong_type, Int,
};
use super::{native, native_ok};
use crate::graphcut::{
    alpha_beta_swap as swap_core, alpha_expansion as expansion_core, energy as energy_core,
    grid_edges as grid_edges_core, maxflow::MAX_NODES, Cost, CrfProblem, Graph, Labelling,
    MoveConfig,
};
use numpy::{PyArrayDescrMethods, PyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyAny;

type BoolArray<'py> = Bound<'py, PyArrayDyn<bool>>;
type I32Array<'py> = Bound<'py, PyArrayDyn<i32>>;
type I64Array<'py> = Bound<'py, PyArrayDyn<i64>>;

/// A graph of either capacity type.
enum Inner {
    F(Graph<f64>),
    I(Graph<i64>),
}

/// True if `dtype` (anything `numpy.dtype()` accepts) is an integer type, false for a
/// float type; an error naming `dtype` otherwise.
fn is_integer_dtype(dtype: &Bound<PyAny>) -> PyResult<bool> {
    let py = dtype.py();
    let dt = py
        .import("numpy")?
        .getattr("dtype")?
        .call1((dtype,))
        .map_err(|_| wrong_type("dtype", "a dtype (float or int)", &type_name(dtype)))?;
    let kind: String = dt.getattr("kind")?.extract()?;
    match kind.as_str() {
        "f" => Ok(false),
        "i" | "u" => Ok(true),
        _ => Err(invalid("dtype", format!("must be float or int, got {dt}"))),
    }
}

fn type_name(obj: &Bound<PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// Most labels of a CRF (its pairwise table has L × L entries, and expansion checks
/// the triangle inequality on every triple).
pub const MAX_LABELS: usize = 1024;

/// Is `obj` a numpy array with an integer dtype?
fn array_is_integer(obj: &Bound<PyAny>) -> bool {
    obj.cast::<PyUntypedArray>()
        .map(|a| {
            let k = a.dtype().kind();
            k == b'i' || k == b'u'
        })
        .unwrap_or(false)
}

/// A 1-D index array of node ids (each in 0..n) as `u32`. Empty arrays are allowed.
fn node_indices(obj: &Bound<PyAny>, name: &str, n: usize) -> PyResult<Vec<u32>> {
    if is_empty_array(obj, name, Some(1))? {
        return Ok(Vec::new());
    }
    let a = i64_array(obj, name, Some(1))?;
    indices_in_range(&a.data, name, n)
}

fn indices_in_range(data: &[i64], name: &str, n: usize) -> PyResult<Vec<u32>> {
    if let Some(k) = data.iter().position(|&v| v < 0 || v as u64 >= n as u64) {
        return Err(invalid(
            name,
            format!(
                "node index {} at position {k} out of range for {n} nodes",
                data[k]
            ),
        ));
    }
    Ok(data.iter().map(|&v| v as u32).collect())
}

/// True for a numpy array of size 0 (with `ndim` checked); errors for non-arrays.
fn is_empty_array(obj: &Bound<PyAny>, name: &str, ndim: Option<usize>) -> PyResult<bool> {
    let arr = obj
        .cast::<PyUntypedArray>()
        .map_err(|_| wrong_type(name, "a numpy array", &type_name(obj)))?;
    if let Some(d) = ndim {
        if arr.ndim() != d {
            return Err(invalid(
                name,
                format!("expected a {d}-D array, got shape {:?}", arr.shape()),
            ));
        }
    }
    Ok(arr.len() == 0)
}

fn f64_caps(obj: &Bound<PyAny>, name: &str) -> PyResult<Vec<f64>> {
    if is_empty_array(obj, name, Some(1))? {
        return Ok(Vec::new());
    }
    Ok(f64_array(obj, name, Some(1), true)?.data)
}

fn i64_caps(obj: &Bound<PyAny>, name: &str) -> PyResult<Vec<i64>> {
    if is_empty_array(obj, name, Some(1))? {
        return Ok(Vec::new());
    }
    if !array_is_integer(obj) {
        let dtype = obj
            .cast::<PyUntypedArray>()
            .map(|a| a.dtype().to_string())
            .unwrap_or_default();
        return Err(invalid(
            name,
            format!("an int graph needs integer capacities, got dtype {dtype}"),
        ));
    }
    Ok(i64_array(obj, name, Some(1))?.data)
}

/// A directed graph with source and sink for max-flow / min-cut (Boykov–Kolmogorov).
#[pyclass(name = "MaxflowGraph", module = "depthpose._core")]
pub struct PyGraph {
    /// Integer graphs refuse capacities whose sum could pass int64 (the core keeps it).
    inner: Inner,
}

impl PyGraph {
    /// Terminal capacities of many nodes: added (`update` false: `source_cap`,
    /// `sink_cap` ≥ 0) or changed by deltas (`update` true: `delta_source`, `delta_sink`).
    fn terminal_batch(
        &mut self,
        nodes: &Bound<PyAny>,
        source: &Bound<PyAny>,
        sink: &Bound<PyAny>,
        update: bool,
    ) -> PyResult<()> {
        let idx = node_indices(nodes, "nodes", self.n_nodes())?;
        let names = if update {
            ("delta_source", "delta_sink")
        } else {
            ("source_cap", "sink_cap")
        };
        macro_rules! apply {
            ($g:expr, $caps:expr) => {{
                let (s, t) = ($caps(source, names.0)?, $caps(sink, names.1)?);
                if update {
                    $g.update_tweights_batch(&idx, &s, &t)?
                } else {
                    $g.add_tweights_batch(&idx, &s, &t)?
                }
            }};
        }
        match &mut self.inner {
            Inner::F(g) => apply!(g, f64_caps),
            Inner::I(g) => apply!(g, i64_caps),
        }
        Ok(())
    }
}

#[pymethods]
impl PyGraph {
    #[new]
    #[pyo3(signature = (n_nodes, dtype=None, edge_hint=Int::new(0)))]
    fn new(n_nodes: Int, dtype: Option<&Bound<PyAny>>, edge_hint: Int) -> PyResult<Self> {
        let n_nodes = n_nodes.in_range(1, MAX_NODES as i128, "n_nodes")?;
        let max_hint = i128::from(u32::MAX) / 2;
        let hint = edge_hint.in_range(0, max_hint, "edge_hint")? as usize;
        // About 32 bytes a node and 48 an edge (its two arcs and its pending record).
        check_result_bytes(
            (n_nodes as usize)
                .checked_mul(32)
                .and_then(|b| b.checked_add(hint.checked_mul(48)?)),
            "n_nodes/edge_hint",
            "the graph",
        )?;
        let integer = match dtype {
            Some(d) => is_integer_dtype(d)?,
            None => false,
        };
        let n = n_nodes as usize;
        let inner = if integer {
            Inner::I(Graph::try_with_capacity(n, hint)?)
        } else {
            Inner::F(Graph::try_with_capacity(n, hint)?)
        };
        Ok(PyGraph { inner })
    }

    /// Number of nodes.
    #[getter]
    fn n_nodes(&self) -> usize {
        match &self.inner {
            Inner::F(g) => g.n_nodes(),
            Inner::I(g) => g.n_nodes(),
        }
    }

    /// Number of edges added.
    #[getter]
    fn n_edges(&self) -> usize {
        match &self.inner {
            Inner::F(g) => g.n_edges(),
            Inner::I(g) => g.n_edges(),
        }
    }

    /// True for an integer-capacity graph.
    #[getter]
    fn is_integer(&self) -> bool {
        matches!(self.inner, Inner::I(_))
    }

    /// Heap bytes held by the graph.
    fn memory_bytes(&self) -> usize {
        match &self.inner {
            Inner::F(g) => g.memory_bytes(),
            Inner::I(g) => g.memory_bytes(),
        }
    }

    /// Adds edges src[k] → dst[k] with capacity cap[k] and dst[k] → src[k] with rev_cap[k].
    fn add_edges(
        &mut self,
        py: Python<'_>,
        src: &Bound<PyAny>,
        dst: &Bound<PyAny>,
        cap: &Bound<PyAny>,
        rev_cap: &Bound<PyAny>,
    ) -> PyResult<()> {
        let n = self.n_nodes();
        let s = node_indices(src, "src", n)?;
        let d = node_indices(dst, "dst", n)?;
        match &mut self.inner {
            Inner::F(g) => {
                let (c, r) = (f64_caps(cap, "cap")?, f64_caps(rev_cap, "rev_cap")?);
                native(py, || g.add_edges(&s, &d, &c, &r))?;
            }
            Inner::I(g) => {
                let (c, r) = (i64_caps(cap, "cap")?, i64_caps(rev_cap, "rev_cap")?);
                native(py, || g.add_edges(&s, &d, &c, &r))?;
            }
        }
        Ok(())
    }

    /// Adds source_cap[k] to source → nodes[k] and sink_cap[k] to nodes[k] → sink.
    fn add_terminal_edges(
        &mut self,
        nodes: &Bound<PyAny>,
        source_cap: &Bound<PyAny>,
        sink_cap: &Bound<PyAny>,
    ) -> PyResult<()> {
        self.terminal_batch(nodes, source_cap, sink_cap, false)
    }

    /// Changes terminal capacities by (possibly negative) deltas, also after a solve;
    /// the next `maxflow()` then reuses the previous search trees.
    fn update_terminal_edges(
        &mut self,
        nodes: &Bound<PyAny>,
        delta_source: &Bound<PyAny>,
        delta_sink: &Bound<PyAny>,
    ) -> PyResult<()> {
        self.terminal_batch(nodes, delta_source, delta_sink, true)
    }

    /// Builds the arc arrays from the edges added so far (otherwise the next `maxflow()`
    /// does it), so that `maxflow()` times the solve alone. Edges added later are merged
    /// by another build.
    fn finalize(&mut self, py: Python<'_>) -> PyResult<()> {
        match &mut self.inner {
            Inner::F(g) => native_ok(py, || g.finalize()),
            Inner::I(g) => native_ok(py, || g.finalize()),
        }
    }

    /// Computes the maximum flow; returns its value (float, or int for an int graph).
    /// A fresh solve of a large grid uses up to `threads` threads (None: all of the
    /// pool's); the cut does not depend on it.
    #[pyo3(signature = (threads=None))]
    fn maxflow(&mut self, py: Python<'_>, threads: Option<Int>) -> PyResult<Py<PyAny>> {
        let threads = match threads {
            None => 0,
            // More threads than the pool has gain nothing; a huge count is just all.
            Some(t) => t.at_least(1, "threads").or_else(|e| {
                if t.get("threads").is_ok_and(|v| v > 0) {
                    Ok(usize::MAX)
                } else {
                    Err(e)
                }
            })?,
        };
        match &mut self.inner {
            Inner::F(g) => g.set_max_threads(threads),
            Inner::I(g) => g.set_max_threads(threads),
        }
        Ok(match &mut self.inner {
            Inner::F(g) => native_ok(py, || g.maxflow())?
                .into_pyobject(py)?
                .into_any()
                .unbind(),
            Inner::I(g) => native_ok(py, || g.maxflow())?
                .into_pyobject(py)?
                .into_any()
                .unbind(),
        })
    }

    /// The side of each node in the minimum cut: True = sink side.
    fn segments<'py>(&self, py: Python<'py>) -> PyResult<BoolArray<'py>> {
        let (seg, n) = match &self.inner {
            Inner::F(g) => (g.segments(), g.n_nodes()),
            Inner::I(g) => (g.segments(), g.n_nodes()),
        };
        to_numpy(py, seg, &[n])
    }
}

/// Edges (E, 2) int64 of an h×w pixel grid with row-major node ids, 4- or 8-connected.
#[pyfunction]
#[pyo3(signature = (h, w, connectivity=Int::new(4)))]
fn grid_edges<'py>(py: Python<'py>, h: Int, w: Int, connectivity: Int) -> PyResult<I64Array<'py>> {
    let h = h.at_least(1, "h")?;
    let w = w.at_least(1, "w")?;
    let connectivity = super::convert::connectivity(&connectivity)?.neighbours() as u8;
    // Up to connectivity / 2 edges a node, each 8 bytes here and 16 in the result.
    let bytes = h
        .checked_mul(w)
        .and_then(|n| n.checked_mul(usize::from(connectivity) / 2 * 24));
    check_result_bytes(bytes, "h/w", "the grid's edges")?;
    let e = native(py, || grid_edges_core(h, w, connectivity))?;
    let m = e.len();
    let flat: Vec<i64> = e.into_iter().flatten().map(i64::from).collect();
    to_numpy(py, flat, &[m, 2])
}

/// Parsed CRF arguments of one cost type.
struct CrfArgs<C> {
    unary: Vec<C>,
    n_labels: usize,
    edges: Vec<[u32; 2]>,
    weights: Vec<C>,
    pairwise: Option<Vec<C>>,
}

impl<C: Cost> CrfArgs<C> {
    fn problem(&self) -> CrfProblem<'_, C> {
        CrfProblem {
            unary: &self.unary,
            n_labels: self.n_labels,
            edges: &self.edges,
            weights: &self.weights,
            pairwise: self.pairwise.as_deref(),
        }
    }
}

fn edges_arg(edges: &Bound<PyAny>, n: usize) -> PyResult<Vec<[u32; 2]>> {
    if is_empty_array(edges, "edges", None)? {
        return Ok(Vec::new());
    }
    let e = i64_array(edges, "edges", Some(2))?;
    if e.shape[1] != 2 {
        return Err(invalid(
            "edges",
            format!("expected shape (E, 2), got {:?}", e.shape),
        ));
    }
    let idx = indices_in_range(&e.data, "edges", n)?;
    Ok(idx.chunks_exact(2).map(|p| [p[0], p[1]]).collect())
}

fn unary_shape(unary: &Bound<PyAny>) -> PyResult<(usize, usize)> {
    let arr = unary
        .cast::<PyUntypedArray>()
        .map_err(|_| wrong_type("unary", "a numpy array", &type_name(unary)))?;
    if arr.ndim() != 2 || arr.len() == 0 {
        return Err(invalid(
            "unary",
            format!(
                "expected a non-empty (N, L) array, got shape {:?}",
                arr.shape()
            ),
        ));
    }
    let l = arr.shape()[1];
    if l > MAX_LABELS {
        return Err(too_large(
            "unary",
            format!("{l} labels exceed the limit MAX_LABELS = {MAX_LABELS}"),
        ));
    }
    Ok((arr.shape()[0], l))
}

fn f64_crf(
    unary: &Bound<PyAny>,
    edges: &Bound<PyAny>,
    weights: &Bound<PyAny>,
    pairwise: Option<&Bound<PyAny>>,
) -> PyResult<CrfArgs<f64>> {
    let (n, l) = unary_shape(unary)?;
    // +inf forbids a label; NaN and -inf are rejected by the core check.
    let u = f64_array(unary, "unary", Some(2), false)?.data;
    let e = edges_arg(edges, n)?;
    let w = f64_caps(weights, "weights")?;
    let v = match pairwise {
        Some(p) => Some(pairwise_arg(p, l, |o| {
            f64_array(o, "pairwise", Some(2), true)
        })?),
        None => None,
    };
    Ok(CrfArgs {
        unary: u,
        n_labels: l,
        edges: e,
        weights: w,
        pairwise: v,
    })
}

fn i64_crf(
    unary: &Bound<PyAny>,
    edges: &Bound<PyAny>,
    weights: &Bound<PyAny>,
    pairwise: Option<&Bound<PyAny>>,
) -> PyResult<CrfArgs<i64>> {
    let (n, l) = unary_shape(unary)?;
    let u = i64_array(unary, "unary", Some(2))?.data;
    let e = edges_arg(edges, n)?;
    let w = if is_empty_array(weights, "weights", Some(1))? {
        Vec::new()
    } else {
        i64_array(weights, "weights", Some(1))?.data
    };
    let v = match pairwise {
        Some(p) => Some(pairwise_arg(p, l, |o| i64_array(o, "pairwise", Some(2)))?),
        None => None,
    };
    Ok(CrfArgs {
        unary: u,
        n_labels: l,
        edges: e,
        weights: w,
        pairwise: v,
    })
}

fn pairwise_arg<C>(
    p: &Bound<PyAny>,
    l: usize,
    conv: impl Fn(&Bound<PyAny>) -> PyResult<super::convert::Arr<C>>,
) -> PyResult<Vec<C>> {
    if let Ok(arr) = p.cast::<PyUntypedArray>() {
        if arr.shape() != [l, l] {
            return Err(invalid(
                "pairwise",
                format!(
                    "expected shape ({l}, {l}) for {l} labels, got {:?}",
                    arr.shape()
                ),
            ));
        }
    }
    let a = conv(p)?;
    Ok(a.data)
}

fn init_arg(init: Option<&Bound<PyAny>>) -> PyResult<Option<Vec<i32>>> {
    let Some(init) = init else { return Ok(None) };
    let a = i64_array(init, "init", Some(1))?;
    if let Some(k) = a
        .data
        .iter()
        .position(|&v| v < i64::from(i32::MIN) || v > i64::from(i32::MAX))
    {
        return Err(invalid(
            "init",
            format!("label {} at node {k} out of range", a.data[k]),
        ));
    }
    Ok(Some(a.data.iter().map(|&v| v as i32).collect()))
}

/// Integer mode: unary, weights (and pairwise) all of integer dtype.
fn integer_mode(
    unary: &Bound<PyAny>,
    weights: &Bound<PyAny>,
    pairwise: Option<&Bound<PyAny>>,
) -> bool {
    let weights_int = array_is_integer(weights)
        || weights
            .cast::<PyUntypedArray>()
            .map(|a| a.len() == 0)
            .unwrap_or(false);
    array_is_integer(unary) && weights_int && pairwise.is_none_or(array_is_integer)
}

type Solver<C> = fn(&CrfProblem<C>, Option<&[i32]>, &MoveConfig) -> crate::Result<Labelling<C>>;

/// The arguments `alpha_expansion` and `alpha_beta_swap` share.
struct CrfCall<'a, 'py> {
    unary: &'a Bound<'py, PyAny>,
    edges: &'a Bound<'py, PyAny>,
    weights: &'a Bound<'py, PyAny>,
    pairwise: Option<&'a Bound<'py, PyAny>>,
    init: Option<&'a Bound<'py, PyAny>>,
    max_cycles: Int,
}

fn solve<'py>(
    py: Python<'py>,
    call: CrfCall<'_, 'py>,
    f: Solver<f64>,
    i: Solver<i64>,
) -> PyResult<(I32Array<'py>, Py<PyAny>)> {
    let CrfCall {
        unary,
        edges,
        weights,
        pairwise,
        init,
        max_cycles,
    } = call;
    let cfg = MoveConfig {
        // Each cycle but the last lowers the energy, so the cycles end at a fixed point
        // whatever the bound; a bound beyond usize is no bound.
        max_cycles: max_cycles.count("max_cycles").or_else(|e| {
            match max_cycles.get("max_cycles") {
                Ok(v) if v > 0 => Ok(usize::MAX),
                _ => Err(e),
            }
        })?,
    };
    let init = init_arg(init)?;
    if integer_mode(unary, weights, pairwise) {
        let args = i64_crf(unary, edges, weights, pairwise)?;
        let r = native(py, || i(&args.problem(), init.as_deref(), &cfg))?;
        let n = r.labels.len();
        Ok((
            to_numpy(py, r.labels, &[n])?,
            r.energy.into_pyobject(py)?.into_any().unbind(),
        ))
    } else {
        let args = f64_crf(unary, edges, weights, pairwise)?;
        let r = native(py, || f(&args.problem(), init.as_deref(), &cfg))?;
        let n = r.labels.len();
        Ok((
            to_numpy(py, r.labels, &[n])?,
            r.energy.into_pyobject(py)?.into_any().unbind(),
        ))
    }
}

/// Alpha-expansion on E(l) = Σ unary[i, l_i] + Σ_e weights[e]·pairwise[l_i, l_j].
/// Returns (labels int32 (N,), energy); integer inputs give an exact int energy.
#[pyfunction]
#[pyo3(signature = (unary, edges, weights, *, pairwise=None, init=None, max_cycles=Int::new(20)))]
fn alpha_expansion<'py>(
    py: Python<'py>,
    unary: &Bound<'py, PyAny>,
    edges: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
    pairwise: Option<&Bound<'py, PyAny>>,
    init: Option<&Bound<'py, PyAny>>,
    max_cycles: Int,
) -> PyResult<(I32Array<'py>, Py<PyAny>)> {
    let call = CrfCall {
        unary,
        edges,
        weights,
        pairwise,
        init,
        max_cycles,
    };
    solve(py, call, expansion_core::<f64>, expansion_core::<i64>)
}

/// Alpha-beta swap (semi-metric pairwise), same arguments as `alpha_expansion`.
#[pyfunction]
#[pyo3(signature = (unary, edges, weights, *, pairwise=None, init=None, max_cycles=Int::new(20)))]
fn alpha_beta_swap<'py>(
    py: Python<'py>,
    unary: &Bound<'py, PyAny>,
    edges: &Bound<'py, PyAny>,
    weights: &Bound<'py, PyAny>,
    pairwise: Option<&Bound<'py, PyAny>>,
    init: Option<&Bound<'py, PyAny>>,
    max_cycles: Int,
) -> PyResult<(I32Array<'py>, Py<PyAny>)> {
    let call = CrfCall {
        unary,
        edges,
        weights,
        pairwise,
        init,
        max_cycles,
    };
    solve(py, call, swap_core::<f64>, swap_core::<i64>)
}

/// The CRF energy of `labels` (int for integer inputs; inf if a label is forbidden).
#[pyfunction]
#[pyo3(signature = (labels, unary, edges, weights, pairwise=None))]
fn crf_energy(
    py: Python<'_>,
    labels: &Bound<PyAny>,
    unary: &Bound<PyAny>,
    edges: &Bound<PyAny>,
    weights: &Bound<PyAny>,
    pairwise: Option<&Bound<PyAny>>,
) -> PyResult<Py<PyAny>> {
    let lab = i64_array(labels, "labels", Some(1))?;
    if let Some(k) = lab
        .data
        .iter()
        .position(|&v| v < 0 || v > i64::from(i32::MAX))
    {
        return Err(invalid(
            "labels",
            format!("label {} at node {k} out of range", lab.data[k]),
        ));
    }
    let lab: Vec<i32> = lab.data.iter().map(|&v| v as i32).collect();
    if integer_mode(unary, weights, pairwise) {
        let a = i64_crf(unary, edges, weights, pairwise)?;
        let e = native(py, || energy_core(&a.problem(), &lab))?;
        Ok(e.into_pyobject(py)?.into_any().unbind())
    } else {
        let a = f64_crf(unary, edges, weights, pairwise)?;
        let e = native(py, || energy_core(&a.problem(), &lab))?;
        Ok(e.into_pyobject(py)?.into_any().unbind())
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyGraph>()?;
    m.add_function(wrap_pyfunction!(grid_edges, m)?)?;
    m.add_function(wrap_pyfunction!(alpha_expansion, m)?)?;
    m.add_function(wrap_pyfunction!(alpha_beta_swap, m)?)?;
    m.add_function(wrap_pyfunction!(crf_energy, m)?)?;
    m.add("MAX_LABELS", MAX_LABELS)?;
    Ok(())
}

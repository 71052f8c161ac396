"""depthpose.graphcut: max-flow against brute force, CRF solvers, and every bad input."""

from __future__ import annotations

import itertools
import time

import numpy as np
import pytest
from depthpose import graphcut as gc
from depthpose._core import DepthPoseError, InvalidInputError
from hypothesis import given, settings
from hypothesis import strategies as st


def brute_min_cut(n, edges, caps, revs, src_caps, snk_caps):
    best = None
    for bits in itertools.product([False, True], repeat=n):
        side = np.array(bits)  # True = sink side
        v = np.where(side, src_caps, snk_caps).sum()
        for (i, j), c, r in zip(edges, caps, revs, strict=False):
            if not side[i] and side[j]:
                v += c
            if side[i] and not side[j]:
                v += r
        best = v if best is None else min(best, v)
    return int(best)


def cut_value(side, edges, caps, revs, src_caps, snk_caps):
    v = np.where(side, src_caps, snk_caps).sum()
    s, d = edges[:, 0], edges[:, 1]
    v += caps[~side[s] & side[d]].sum() + revs[side[s] & ~side[d]].sum()
    return v


@st.composite
def small_graph(draw):
    n = draw(st.integers(1, 8))
    m = draw(st.integers(0, 2 * n))
    idx = st.integers(0, n - 1)
    edges = np.array([[draw(idx), draw(idx)] for _ in range(m)], dtype=np.int64).reshape(m, 2)
    cap = np.array(draw(st.lists(st.integers(0, 9), min_size=m, max_size=m)), dtype=np.int64)
    rev = np.array(draw(st.lists(st.integers(0, 9), min_size=m, max_size=m)), dtype=np.int64)
    src = np.array(draw(st.lists(st.integers(0, 12), min_size=n, max_size=n)), dtype=np.int64)
    snk = np.array(draw(st.lists(st.integers(0, 12), min_size=n, max_size=n)), dtype=np.int64)
    return n, edges, cap, rev, src, snk


def build(n, edges, cap, rev, src, snk, dtype):
    g = gc.Graph(n, dtype=dtype)
    conv = np.int64 if dtype is int else np.float64
    g.add_edges(edges[:, 0], edges[:, 1], cap.astype(conv), rev.astype(conv))
    g.add_terminal_edges(np.arange(n), src.astype(conv), snk.astype(conv))
    return g


@settings(max_examples=150, deadline=None)
@given(small_graph())
def test_maxflow_equals_brute_force(p):
    n, edges, cap, rev, src, snk = p
    best = brute_min_cut(n, edges, cap, rev, src, snk)
    for dtype, early in [(int, False), (float, False), (int, True)]:
        g = build(n, edges, cap, rev, src, snk, dtype)
        if early:
            g.finalize()  # arc arrays built before the solve: same answer
        f = g.maxflow()
        assert f == best
        assert isinstance(f, int if dtype is int else float)
        seg = g.segments()
        assert seg.dtype == np.bool_ and seg.shape == (n,)
        assert cut_value(seg, edges, cap, rev, src, snk) == best


@settings(max_examples=60, deadline=None)
@given(small_graph(), st.data())
def test_dynamic_update_equals_fresh_solve(p, data):
    n, edges, cap, rev, src, snk = p
    g = build(n, edges, cap, rev, src, snk, int)
    g.maxflow()
    nodes = np.arange(n)
    new_src = np.array(data.draw(st.lists(st.integers(0, 12), min_size=n, max_size=n)))
    new_snk = np.array(data.draw(st.lists(st.integers(0, 12), min_size=n, max_size=n)))
    g.update_terminal_edges(nodes, new_src - src, new_snk - snk)
    assert g.maxflow() == brute_min_cut(n, edges, cap, rev, new_src, new_snk)
    fresh = build(n, edges, cap, rev, new_src, new_snk, int)
    assert fresh.maxflow() == brute_min_cut(n, edges, cap, rev, new_src, new_snk)


def test_grid_edges_and_fast_large_build():
    e4 = gc.grid_edges(3, 4)
    assert e4.shape == (3 * 3 + 2 * 4, 2) and e4.dtype == np.int64
    assert [0, 1] in e4.tolist() and [0, 4] in e4.tolist()
    e8 = gc.grid_edges(3, 4, connectivity=8)
    assert e8.shape == (3 * 3 + 2 * 4 + 2 * 2 * 3, 2)
    assert [0, 5] in e8.tolist() and [1, 4] in e8.tolist()
    # A 640×480 grid graph: build and cut a bright square from a dark background.
    h, w = 480, 640
    img = np.zeros((h, w))
    img[100:300, 200:400] = 1.0
    t0 = time.perf_counter()
    e = gc.grid_edges(h, w)
    g = gc.Graph(h * w, edge_hint=len(e))
    wts = np.full(len(e), 0.2)
    g.add_edges(e[:, 0], e[:, 1], wts, wts)
    g.add_terminal_edges(np.arange(h * w), img.ravel(), 1.0 - img.ravel())
    build_s = time.perf_counter() - t0
    # Only the square's boundary edges are cut: 2·(200 + 200) of them, 0.2 each.
    assert g.maxflow() == pytest.approx(800 * 0.2)
    # Inside (source capacity 1) stays on the source side.
    assert np.array_equal(g.segments().reshape(h, w), img < 0.5)
    assert build_s < 5.0  # generous bound for a loaded CI machine; benches measure speed


@pytest.mark.parametrize("conn", [4, 8])
def test_threaded_solve_matches_one_thread(conn):
    # A 320×240 grid is split into row bands, one per thread (when the pool has more
    # than one); integer capacities: the flow must be exactly the one-thread solve's,
    # the cut identical, and a dynamic update afterwards must agree too.
    rng = np.random.default_rng(11)
    h, w = 240, 320
    e = gc.grid_edges(h, w, conn)
    wts = rng.integers(0, 20, size=len(e))
    src, snk = rng.integers(0, 30, size=h * w), rng.integers(0, 30, size=h * w)
    nodes = np.arange(h * w)
    flows, cuts, graphs = [], [], []
    for threads in (1, None, 2, 64):
        g = gc.Graph(h * w, dtype=int, edge_hint=len(e))
        g.add_edges(e[:, 0], e[:, 1], wts, wts)
        g.add_terminal_edges(nodes, src, snk)
        flows.append(g.maxflow(threads=threads))
        cuts.append(g.segments())
        graphs.append(g)
    assert all(f == flows[0] for f in flows) and isinstance(flows[0], int)
    assert all(np.array_equal(c, cuts[0]) for c in cuts)
    delta = rng.integers(-10, 10, size=500)
    changed = rng.choice(h * w, size=500, replace=False)
    after = []
    for g in graphs:
        g.update_terminal_edges(changed, np.maximum(delta, 0), np.maximum(-delta, 0))
        after.append((g.maxflow(), g.segments()))
    assert all(f == after[0][0] and np.array_equal(c, after[0][1]) for f, c in after)


def potts_problem(rng, n, l, m):
    unary = rng.integers(0, 20, size=(n, l))
    edges = rng.integers(0, n, size=(m, 2))
    weights = rng.integers(0, 8, size=m)
    return unary, edges, weights


def exhaustive(unary, edges, weights, pairwise=None):
    n, l = unary.shape
    return min(
        gc.energy(np.array(lab), unary, edges, weights, pairwise)
        for lab in itertools.product(range(l), repeat=n)
    )


def test_alpha_expansion_factor_two_and_deterministic():
    rng = np.random.default_rng(7)
    for _ in range(40):
        unary, edges, weights = potts_problem(rng, 6, 3, 9)
        labels, e = gc.alpha_expansion(unary, edges, weights)
        assert labels.dtype == np.int32 and labels.shape == (6,)
        assert isinstance(e, int)
        assert e == gc.energy(labels, unary, edges, weights)
        assert e <= 2 * exhaustive(unary, edges, weights)
        labels2, e2 = gc.alpha_expansion(unary, edges, weights)
        assert e2 == e and np.array_equal(labels, labels2)
        s_labels, s_e = gc.alpha_beta_swap(unary, edges, weights)
        assert s_e == gc.energy(s_labels, unary, edges, weights)
        assert s_e >= exhaustive(unary, edges, weights)


def test_expansion_float_matches_int_and_respects_init_and_pairwise():
    rng = np.random.default_rng(3)
    unary, edges, weights = potts_problem(rng, 7, 4, 10)
    li, ei = gc.alpha_expansion(unary, edges, weights)
    lf, ef = gc.alpha_expansion(unary.astype(float), edges, weights.astype(float))
    assert isinstance(ef, float) and ef == float(ei) and np.array_equal(li, lf)
    # max_cycles=0 returns the start labelling and its energy.
    init = np.zeros(7, dtype=np.int32)
    l0, e0 = gc.alpha_expansion(unary, edges, weights, init=init, max_cycles=0)
    assert np.array_equal(l0, init) and e0 == gc.energy(init, unary, edges, weights)
    # A truncated-linear metric.
    v = np.minimum(np.abs(np.subtract.outer(np.arange(4), np.arange(4))), 2)
    lv, ev = gc.alpha_expansion(unary, edges, weights, pairwise=v, init=init)
    assert ev == gc.energy(lv, unary, edges, weights, v)
    assert ev <= gc.energy(init, unary, edges, weights, v)


def test_forbidden_label_is_avoided():
    unary = np.array([[np.inf, 1.0, 2.0], [0.0, np.inf, np.inf], [5.0, 5.0, np.inf]])
    edges = np.array([[0, 1], [1, 2]])
    weights = np.array([10.0, 10.0])
    labels, e = gc.alpha_expansion(unary, edges, weights, init=np.array([0, 1, 2]))
    assert labels[1] == 0 and labels[0] != 0 and labels[2] != 2
    assert np.isfinite(e)
    assert gc.energy(np.array([0, 0, 0]), unary, edges, weights) == np.inf


def test_empty_edges_give_per_node_argmin():
    unary = np.array([[3.0, 1.0], [0.0, 2.0]])
    edges = np.zeros((0, 2), dtype=np.int64)
    labels, e = gc.alpha_expansion(unary, edges, np.zeros(0))
    assert labels.tolist() == [1, 0] and e == 1.0


# ----- bad input: every case raises InvalidInputError naming the argument -----


def _raises(name, fn, *args, **kwargs):
    with pytest.raises(InvalidInputError, match=name):
        fn(*args, **kwargs)


def test_graph_bad_input():
    g = gc.Graph(3)
    i = np.array([0, 1])
    c = np.array([1.0, 2.0])
    _raises("cap", g.add_edges, i, i, np.array([1.0, -1.0]), c)
    _raises("rev_cap", g.add_edges, i, i, c, np.array([np.nan, 1.0]))
    _raises("dst", g.add_edges, i, np.array([0, 3]), c, c)
    _raises("src", g.add_edges, np.array([-1, 0]), i, c, c)
    _raises("dst", g.add_edges, i, np.array([0]), c, c)
    _raises("rev_cap", g.add_edges, i, i, c, np.array([1.0]))
    _raises("src", g.add_edges, [0, 1], i, c, c)  # not a numpy array
    _raises("source_cap", g.add_terminal_edges, i, np.array([np.inf, 1.0]), c)
    _raises("sink_cap", g.add_terminal_edges, i, c, np.array([1.0, -2.0]))
    _raises("nodes", g.add_terminal_edges, np.array([5, 0]), c, c)
    _raises("sink_cap", g.add_terminal_edges, i, c, np.array([1.0]))
    gi = gc.Graph(3, dtype=int)
    _raises("cap", gi.add_edges, i, i, np.array([1.5, 2.0]), np.array([1, 2]))
    _raises("n_nodes", gc.Graph, 0)
    _raises("n_nodes", gc.Graph, 2**40)
    _raises("edge_hint", gc.Graph, 3, edge_hint=-1)
    _raises("edge_hint", gc.Graph, 3, edge_hint=2**40)
    _raises("dtype", gc.Graph, 3, dtype=str)
    _raises("connectivity", gc.grid_edges, 3, 3, connectivity=6)
    _raises("h", gc.grid_edges, 0, 3)
    _raises("w", gc.grid_edges, 3, 2**70)  # was truncated to 64 bits
    _raises("connectivity", gc.grid_edges, 3, 3, connectivity=2**64 + 4)
    _raises("threads", gc.Graph(4).maxflow, threads=0)
    assert issubclass(InvalidInputError, DepthPoseError)
    assert issubclass(InvalidInputError, ValueError)


def test_integer_sums_that_could_pass_int64_are_refused():
    # Unchecked, such sums wrap: three terminal edges of 2**62 each would give a flow of
    # -2**62, and four unary costs of 2**62 an energy of 0.
    big = 2**62
    g = gc.Graph(3, dtype=np.int64)
    g.add_terminal_edges(np.array([0, 1]), np.full(2, big // 2), np.zeros(2, np.int64))
    _raises("source_cap", g.add_terminal_edges, np.array([2]), np.array([big]), np.array([0]))
    _raises("cap", g.add_edges, np.array([0]), np.array([1]), np.array([big]), np.array([0]))
    _raises("delta_source", g.update_terminal_edges, np.array([2]), np.array([big]), np.array([0]))
    g.add_terminal_edges(np.array([2]), np.array([0]), np.array([big // 2]))
    g.add_edges(np.array([0]), np.array([2]), np.array([big // 4]), np.array([0]))
    assert g.maxflow() == big // 4  # the refused additions left the graph unchanged
    # A batch of changes is all or nothing: the first fits, the second does not.
    _raises(
        "delta_source",
        g.update_terminal_edges,
        np.array([2, 2]),
        np.array([1, big]),
        np.zeros(2, np.int64),
    )
    assert g.maxflow() == big // 4
    edges = np.array([[0, 1], [1, 2], [2, 3]])
    for fn in (gc.alpha_expansion, gc.alpha_beta_swap):
        _raises("unary", fn, np.full((4, 3), big, np.int64), edges, np.ones(3, np.int64))
        _raises("unary", fn, np.zeros((4, 3), np.int64), edges, np.full(3, big, np.int64))


def test_crf_bad_input():
    unary = np.zeros((3, 2))
    edges = np.array([[0, 1], [1, 2]])
    w = np.ones(2)
    for fn in (gc.alpha_expansion, gc.alpha_beta_swap):
        _raises("unary", fn, np.array([[np.nan, 0.0], [0, 0], [0, 0]]), edges, w)
        _raises("unary", fn, np.array([[-np.inf, 0.0], [0, 0], [0, 0]]), edges, w)
        _raises("unary", fn, np.zeros(3), edges, w)
        _raises("unary", fn, np.full((3, 2), np.inf), edges, w)  # every label forbidden
        _raises("edges", fn, unary, np.array([[0, 3], [1, 2]]), w)
        _raises("edges", fn, unary, np.array([[0, -1], [1, 2]]), w)
        _raises("edges", fn, unary, np.array([0, 1, 2]), w)
        _raises("weights", fn, unary, edges, np.ones(3))
        _raises("weights", fn, unary, edges, np.array([1.0, -1.0]))
        _raises("weights", fn, unary, edges, np.array([1.0, np.nan]))
        _raises("pairwise", fn, unary, edges, w, pairwise=np.ones((2, 2)))  # diagonal ≠ 0
        _raises("pairwise", fn, unary, edges, w, pairwise=np.array([[0, 1.0], [2.0, 0]]))
        _raises("pairwise", fn, unary, edges, w, pairwise=np.zeros((3, 3)))
        _raises("init", fn, unary, edges, w, init=np.array([0, 2, 0]))
        _raises("init", fn, unary, edges, w, init=np.array([0, 0]))
        _raises("max_cycles", fn, unary, edges, w, max_cycles=-1)
    # Not a metric (V(0,2) > V(0,1) + V(1,2)): expansion refuses, swap accepts.
    u3 = np.zeros((3, 3))
    v = np.array([[0, 1, 5], [1, 0, 1], [5, 1, 0]], dtype=float)
    _raises("pairwise", gc.alpha_expansion, u3, edges, w, pairwise=v)
    labels, e = gc.alpha_beta_swap(u3, edges, w, pairwise=v)
    assert e == 0.0
    _raises("labels", gc.energy, np.array([0, 5, 0]), unary, edges, w)
    _raises("labels", gc.energy, np.array([0, 0]), unary, edges, w)

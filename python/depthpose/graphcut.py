"""Graph cuts: Boykov–Kolmogorov max-flow and CRF labelling by alpha-expansion / swap.

The E-step of the pose fit labels points with body parts by minimising
``E(l) = Σ_i unary[i, l_i] + Σ_e weights[e] · pairwise[l_i, l_j]`` with
:func:`alpha_expansion`; :class:`Graph` is the max-flow underneath, usable on its own.
Integer inputs (costs, capacities) give exact integer answers. Bad input raises
:class:`depthpose.InvalidInputError` naming the argument; costs so large that a move's
flow could overflow float64 are refused the same way (a graph cut on an infinite
capacity would never end). Arrays may have any memory layout. A CRF has at most
``MAX_LABELS`` (1024) labels.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _core

__all__ = ["Graph", "grid_edges", "alpha_expansion", "alpha_beta_swap", "energy", "MAX_LABELS"]

#: Default number of cycles over all labels (expansion) or label pairs (swap).
DEFAULT_MAX_CYCLES = 20

Number = int | float


#: Most labels of a CRF (its pairwise table is L × L).
MAX_LABELS: int = _core.MAX_LABELS


def _c(a: Any) -> Any:
    """An argument as the native checks take it: numpy arrays of any layout (column
    slices like ``edges[:, 0]``, Fortran order, reversed views) pass as they are,
    without a copy before the size checks; anything else too, for the native checks to
    reject by name."""
    return a


class Graph:
    """A directed graph with a source and a sink, for max-flow / min-cut.

    ``Graph(n_nodes, dtype=float)`` holds float64 capacities; ``dtype=int`` int64 ones
    (exact). Build in batches from numpy arrays, then call :meth:`maxflow`;
    :meth:`segments` gives the side of each node (True = sink side).
    """

    def __init__(self, n_nodes: int, dtype: Any = float, edge_hint: int = 0) -> None:
        self._g = _core.MaxflowGraph(n_nodes, dtype, edge_hint)

    @property
    def n_nodes(self) -> int:
        return int(self._g.n_nodes)

    @property
    def n_edges(self) -> int:
        return int(self._g.n_edges)

    @property
    def is_integer(self) -> bool:
        return bool(self._g.is_integer)

    def add_edges(
        self, src: np.ndarray, dst: np.ndarray, cap: np.ndarray, rev_cap: np.ndarray
    ) -> None:
        """Edges ``src[k] → dst[k]`` of capacity ``cap[k]`` and back of ``rev_cap[k]``."""
        self._g.add_edges(_c(src), _c(dst), _c(cap), _c(rev_cap))

    def add_terminal_edges(
        self, nodes: np.ndarray, source_cap: np.ndarray, sink_cap: np.ndarray
    ) -> None:
        """Adds ``source_cap[k]`` to source → ``nodes[k]`` and ``sink_cap[k]`` to → sink."""
        self._g.add_terminal_edges(_c(nodes), _c(source_cap), _c(sink_cap))

    def update_terminal_edges(
        self, nodes: np.ndarray, delta_source: np.ndarray, delta_sink: np.ndarray
    ) -> None:
        """Changes terminal capacities by deltas (may be negative), also after a solve;
        the next :meth:`maxflow` reuses the previous search trees (dynamic cuts). All or
        nothing: a refused batch (bad index, non-finite delta, an int graph's capacities
        summing past int64) changes no capacity."""
        self._g.update_terminal_edges(_c(nodes), _c(delta_source), _c(delta_sink))

    def finalize(self) -> None:
        """Build the arc arrays now (else the next ``maxflow()`` does), so that
        ``maxflow()`` times the solve alone."""
        self._g.finalize()

    def maxflow(self, threads: int | None = None) -> Number:
        """The maximum flow value (int for an int graph).

        A fresh solve of a large graph whose edges join nearby node ids (a pixel grid)
        is split into row bands solved on up to ``threads`` threads (default: all of
        the pool's, see ``RAYON_NUM_THREADS``), then joined by one more search; the cut
        is the same for any ``threads``, a float flow value may differ in the last bits.
        """
        return self._g.maxflow(threads)

    def segments(self) -> np.ndarray:
        """Bool array (n_nodes,): True for nodes on the sink side of the minimum cut."""
        return self._g.segments()

    def memory_bytes(self) -> int:
        """Heap bytes held by the native graph."""
        return int(self._g.memory_bytes())


def grid_edges(h: int, w: int, connectivity: int = 4) -> np.ndarray:
    """Edges (E, 2) int64 of an ``h``×``w`` grid, row-major node ids, 4- or 8-connected."""
    return _core.grid_edges(h, w, connectivity)


def alpha_expansion(
    unary: np.ndarray,
    edges: np.ndarray,
    weights: np.ndarray,
    *,
    pairwise: np.ndarray | None = None,
    init: np.ndarray | None = None,
    max_cycles: int = DEFAULT_MAX_CYCLES,
) -> tuple[np.ndarray, Number]:
    """Minimises the CRF energy by alpha-expansion; returns ``(labels, energy)``.

    ``unary`` (N, L) costs (``+inf`` forbids a label at a node), ``edges`` (E, 2) node
    indices, ``weights`` (E,) ≥ 0, ``pairwise`` (L, L) a metric (default Potts),
    ``init`` (N,) start labels (default: least unary cost). Integer ``unary``,
    ``weights`` and ``pairwise`` give an exact int energy.
    """
    return _core.alpha_expansion(
        _c(unary),
        _c(edges),
        _c(weights),
        pairwise=_c(pairwise),
        init=_c(init),
        max_cycles=max_cycles,
    )


def alpha_beta_swap(
    unary: np.ndarray,
    edges: np.ndarray,
    weights: np.ndarray,
    *,
    pairwise: np.ndarray | None = None,
    init: np.ndarray | None = None,
    max_cycles: int = DEFAULT_MAX_CYCLES,
) -> tuple[np.ndarray, Number]:
    """Like :func:`alpha_expansion` by alpha-beta swap moves (``pairwise`` may be a
    semi-metric: symmetric, zero exactly on the diagonal)."""
    return _core.alpha_beta_swap(
        _c(unary),
        _c(edges),
        _c(weights),
        pairwise=_c(pairwise),
        init=_c(init),
        max_cycles=max_cycles,
    )


def energy(
    labels: np.ndarray,
    unary: np.ndarray,
    edges: np.ndarray,
    weights: np.ndarray,
    pairwise: np.ndarray | None = None,
) -> Number:
    """The CRF energy of ``labels`` (``inf`` if a node has a forbidden label)."""
    return _core.crf_energy(_c(labels), _c(unary), _c(edges), _c(weights), _c(pairwise))

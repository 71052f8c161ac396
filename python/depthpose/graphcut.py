"""Graph cuts: Boykov–Kolmogorov max-flow and CRF labelling by alpha-expansion / swap.

The E-step of the pose fit labels points with body parts by minimising
``E(l) = Σ_i unary[i, l_i] + Σ_e weights[e] · pairwise[l_i, l_j]`` with
:func:`alpha_expansion`; :class:`Graph` is the max-flow underneath, usable on its own.
Integer inputs (costs, capacities) give exact integer answers. Bad input raises
:class:`depthpose.InvalidInputError` naming the argument; costs so large that a move's
flow could overflow float64 are refused the same way (a graph cut on an infinite
capacity would never end). Arrays may have any memory layout: column slices like
``edges[:, 0]``, Fortran order and reversed views are read without a copy before the
size checks. A CRF has at most ``MAX_LABELS`` (1024) labels.

These are the native objects themselves; their documentation is in ``_core.pyi``.
"""

from __future__ import annotations

from . import _core

__all__ = ["Graph", "grid_edges", "alpha_expansion", "alpha_beta_swap", "energy", "MAX_LABELS"]

#: A directed graph with a source and a sink, for max-flow / min-cut.
Graph = _core.MaxflowGraph
grid_edges = _core.grid_edges
alpha_expansion = _core.alpha_expansion
alpha_beta_swap = _core.alpha_beta_swap
#: The CRF energy of a labelling.
energy = _core.crf_energy

#: Most labels of a CRF (its pairwise table is L × L).
MAX_LABELS: int = _core.MAX_LABELS

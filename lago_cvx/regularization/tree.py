"""The seed's orientation regularization along a spanning tree (Section IV-E: Theorem 3, eqs. (20)–(23),
Corollary 3).

Measured relative orientations δ are only known modulo 2π (a sensor reports them in [−π, π)), but
phase 1 treats them as real numbers whose sums around every cycle vanish up to noise. Theorem 3 (for
any δ there is a correction v such that δ + v satisfies the zero-sum property) is proved by the
correction v = [−(Cδ)ᵀ 0ᵀ]ᵀ of eq. (23), rounded to multiples of 2π — one integer per chord of a
spanning tree:

    θ_tree = orientations integrated along the spanning tree from the anchor (tree edges unchanged),
    for every chord c = (i → j):   r_c = (C δ)_c = δ_c − (θ_tree[j] − θ_tree[i])   (cycle residual, eq. (20)),
                                   k_c = branch(r_c, 0),   δ_reg,c = δ_c + 2π k_c,
    so that (C δ_reg)_c = r_c + 2π k_c ∈ (−π, π]                                 (eqs. (21)–(23)).

``branch`` is the one rounding rule of ``lago_cvx.rounding`` (ties go to +π). A chord whose residual
lies within ``margin`` of ±π is listed in ``RegularizationReport.ambiguous``: the rounding is then not
guaranteed to pick the right integer (the accumulated rotation noise along the tree path is of the
order of π).
"""

from __future__ import annotations

import numpy as np

from ..graph import SpanningTree
from ..posegraph import PoseGraph
from ..rounding import AMBIGUITY_MARGIN, check_angles, round_residual, tree_cycle_residuals
from .report import RegularizationReport, chord_report

__all__ = ["regularize_tree"]


def regularize_tree(graph: PoseGraph, tree: SpanningTree, *, margin: float = AMBIGUITY_MARGIN) -> RegularizationReport:
    """2kπ regularization of the chords of ``tree`` (Theorem 3, eqs. (20)–(23)); vectorized, O(m + n log n).

    Returns a ``RegularizationReport``; logs a warning listing (up to 10) ambiguous chords."""
    check_angles(graph)
    before = tree_cycle_residuals(graph, tree)
    k = np.zeros(graph.n_edges, np.int64)
    k[tree.chords] = round_residual(before)
    return chord_report(graph, tree, k, margin=margin, regularization="tree",
                        why="rotation noise too large along the tree path; the chordal regularizer needs no "
                            'tree path: regularization="chordal"')

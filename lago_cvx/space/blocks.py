"""Sparse matrices made of small dense blocks, one pair of blocks per edge (shared by the 3-D closed forms).

Every 3-D least-squares problem here has a residual per edge that depends on two poses, r_e = P_e x_j + N_e x_i
− b_e, with x_i ∈ ℝᵈ the unknowns of pose i (d = 3: a rotation's rows or a position; d = 6: a tangent step).
``edge_matrix`` stacks them into the sparse M (m·r × n·d) of ‖M x − b‖²; ``without_anchor`` drops the anchor's
columns (its unknowns are known), moving their contribution to the right-hand side. ``factor`` and ``solve`` are the
closed forms' way to the engine (``lago_cvx.sparse``) for the same problems written edge by edge (``EdgeSystem``):
``GraphElimination.factor`` / ``solve``, the path of the planar systems.
"""

from __future__ import annotations

import weakref

import numpy as np
import scipy.sparse as sp


__all__ = ["edge_matrix", "without_anchor", "free_index", "block_diagonal", "factor", "solve", "per_graph"]


def edge_matrix(tails, heads, P_head: np.ndarray, N_tail: np.ndarray, n: int) -> sp.csc_matrix:
    """M with block row e = [… N_e at block column i … P_e at block column j …]: shape (m·r, n·d) for blocks
    of shape (m, r, d)."""
    m, r, d = P_head.shape
    rows = (np.arange(m)[:, None, None] * r + np.arange(r)[None, :, None]) + np.zeros((1, 1, d), np.int64)
    cj = heads[:, None, None] * d + np.arange(d)[None, None, :] + np.zeros((1, r, 1), np.int64)
    ci = tails[:, None, None] * d + np.arange(d)[None, None, :] + np.zeros((1, r, 1), np.int64)
    data = np.concatenate([P_head.ravel(), N_tail.ravel()])
    return sp.csc_matrix((data, (np.concatenate([rows.ravel(), rows.ravel()]),
                                 np.concatenate([cj.ravel(), ci.ravel()]))), shape=(m * r, n * d))


def free_index(n: int, d: int, anchor: int) -> np.ndarray:
    """Column indices of every pose's d unknowns but the anchor's, shape ((n − 1)·d,)."""
    keep = np.ones(n * d, bool)
    keep[anchor * d:(anchor + 1) * d] = False
    return np.flatnonzero(keep)


def without_anchor(M: sp.csc_matrix, b: np.ndarray, anchor: int, d: int, x_anchor: np.ndarray):
    """(M without the anchor's d columns, b − M_anchor x_anchor): the problem in the free unknowns.
    ``b`` (rows,) or (rows, k); ``x_anchor`` (d,) or (d, k) accordingly."""
    n = M.shape[1] // d
    cols = M[:, anchor * d:(anchor + 1) * d]
    return M[:, free_index(n, d, anchor)], b - cols @ x_anchor


def block_diagonal(blocks: np.ndarray, offset: int = 0) -> sp.csc_matrix:
    """The block-diagonal sparse matrix of ``blocks`` (k, b, b), preceded by ``offset`` zero rows and columns
    (one vectorized COO construction; ``scipy.sparse.block_diag`` of a list pays per block)."""
    k, b, _ = blocks.shape
    base = offset + b * np.arange(k)[:, None, None]
    rows = base + np.arange(b)[None, :, None] + np.zeros((1, 1, b), np.int64)
    cols = base + np.arange(b)[None, None, :] + np.zeros((1, b, 1), np.int64)
    n = offset + k * b
    return sp.csc_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))


def factor(elimination, system):
    """The factor of ``system``'s normal matrix (an ``EdgeSystem`` on ``elimination``): ``elimination.factor``."""
    return elimination.factor(system)


def solve(elimination, system):
    """``(x, factor, stats)`` of ``system`` on ``elimination``: ``elimination.solve``."""
    return elimination.solve(system)


_PER_GRAPH: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def per_graph(graph, name: str, compute):
    """``compute(graph)``, computed once per graph and ``name`` and kept while the graph lives (a graph is immutable):
    what the closed forms take from the information at any poses, such as its square roots. Arrays come back
    read-only."""
    found = _PER_GRAPH.setdefault(graph, {})
    if name not in found:
        value = compute(graph)
        for a in value if isinstance(value, tuple) else (value,):
            a.setflags(write=False)
        found[name] = value
    return found[name]

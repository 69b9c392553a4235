"""Sparse matrices made of small dense blocks, one pair of blocks per edge (shared by the 3-D closed forms).

Every 3-D least-squares problem here has a residual per edge that depends on two poses, r_e = P_e x_j + N_e x_i
− b_e, with x_i ∈ ℝᵈ the unknowns of pose i (d = 3: a rotation's rows or a position; d = 6: a tangent step).
``edge_matrix`` stacks them into the sparse M (m·r × n·d) of ‖M x − b‖²; ``without_anchor`` drops the anchor's
columns (its unknowns are known), moving their contribution to the right-hand side. ``factor`` and ``solve`` are the
closed forms' way to the engine (``lago_cvx.sparse``) for the same problems written edge by edge (``EdgeSystem``).
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp

__all__ = ["edge_matrix", "without_anchor", "free_index", "block_diagonal", "COMPILED_MIN_3D", "factor", "solve"]

log = logging.getLogger(__name__)

#: The 3-D systems (b = 3: the chordal relaxation, the positions; b = 6: the joint step) with at least this many
#: unknowns d·b are factored by the engine's compiled multifrontal engine (``GraphElimination.factor(engine=
#: "compiled")``), smaller ones as the engine chooses (QDLDL there). The engine's own threshold is set by the planar
#: systems (300 000 unknowns, b ≤ 3, little fill per unknown); a 3-D graph fills more per pose and the 6×6 blocks
#: multiply it by 36, where dense fronts pay far sooner. Measured (in process, one BLAS thread, median of 7,
#: engine = QDLDL / compiled, the whole elimination built per call): the joint step's b = 6 factorization on
#: torus3D (30 000 unknowns) 0.74 / 0.11 s, sphere2500 (15 000) 0.175 / 0.066 s; the b = 3 systems 0.063 / 0.055
#: and 0.026 / 0.010 s; lago3d's default route on parking-garage (b = 6: 9 960 unknowns) 0.137 / 0.126 s CPU,
#: on smallGrid3D (744) equal. Below, QDLDL spares a small graph Numba's import (about 0.16 s per process).
COMPILED_MIN_3D = 6_000


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
    """The factor of ``system``'s normal matrix (an ``EdgeSystem`` on ``elimination``, a ``GraphElimination``):
    compiled from :data:`COMPILED_MIN_3D` unknowns, else (or if the compiled engine cannot run, or finds the matrix
    not positive definite) as the engine chooses."""
    if system.d * system.b >= COMPILED_MIN_3D:
        try:
            return elimination.factor(system, engine="compiled")
        except Exception as exc:  # no Numba, a kernel that cannot compile, NotPositiveDefinite: the engine's way
            log.info("compiled factorization not used (%s): the engine's choice", exc)
    return elimination.factor(system)


def solve(elimination, system):
    """``elimination.solve(system)`` (x, factor, stats) on :func:`factor`'s factorization: the corrected
    semi-normal equations, the engine's fallbacks (the augmented system) included."""
    if system.d * system.b >= COMPILED_MIN_3D:
        try:
            f = elimination.factor(system, engine="compiled")
        except Exception as exc:
            log.info("compiled factorization not used (%s): the engine's choice", exc)
        else:
            return elimination.solve(system, factor=f)
    return elimination.solve(system)

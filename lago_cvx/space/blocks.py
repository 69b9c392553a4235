"""Sparse matrices made of small dense blocks, one pair of blocks per edge (shared by the 3-D closed forms).

Every 3-D least-squares problem here has a residual per edge that depends on two poses, r_e = P_e x_j + N_e x_i
− b_e, with x_i ∈ ℝᵈ the unknowns of pose i (d = 3: a rotation's rows or a position; d = 6: a tangent step).
``edge_matrix`` stacks them into the sparse M (m·r × n·d) of ‖M x − b‖²; ``without_anchor`` drops the anchor's
columns (its unknowns are known), moving their contribution to the right-hand side. ``factor`` and ``solve`` are the
closed forms' way to the engine (``lago_cvx.sparse``) for the same problems written edge by edge (``EdgeSystem``).
"""

from __future__ import annotations

import contextlib
import logging

import numpy as np
import scipy.sparse as sp

__all__ = ["edge_matrix", "without_anchor", "free_index", "block_diagonal", "COMPILED_MIN_3D", "factor", "solve"]

log = logging.getLogger(__name__)

#: The 3-D systems (b = 3: the chordal relaxation, the positions; b = 6: the joint step) with at least this many
#: unknowns d·b are factored by the engine's compiled multifrontal engine (``GraphElimination.factor(engine=
#: "compiled")``), smaller ones as the engine chooses (QDLDL there). The engine's own threshold is set by the planar
#: systems (300 000 unknowns, b ≤ 3, little fill per unknown); a 3-D graph fills more per pose and the 6×6 blocks
#: multiply it by 36, where dense fronts pay far sooner. Measured in process (one BLAS thread, median of 7, QDLDL /
#: compiled, the whole elimination built per call): the joint step's b = 6 factorization on torus3D (30 000
#: unknowns) 0.74 / 0.11 s, sphere2500 (15 000) 0.175 / 0.066 s; the b = 3 systems 0.063 / 0.055 and 0.026 / 0.010
#: s. But the first compiled factorization of a process imports Numba and loads the kernels, about 1 s: a whole
#: ``lago-cvx solve parking-garage.g2o`` (b = 6: 9 960 unknowns, 10 ms gained in process) took 1.45-1.58 s with it
#: against 0.75-0.91 s without. Hence the threshold above parking-garage's joint step.
COMPILED_MIN_3D = 12_000


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


#: The compiled factorizations of the 3-D systems run with one BLAS thread. The engine gives its largest fronts every
#: BLAS thread; OpenBLAS's threads wait for each other by spinning, and with the other core busy (another process)
#: the waits dominate. lago3d's default route in process, alternating, median of 5, with a loaded second core:
#: sphere2500 0.85-0.97 s with the threads against 0.26-0.29 s with one (QDLDL, before: 0.38-0.45 s), torus3D
#: 3.3-4.5 s against 0.37-0.60 s (QDLDL: 1.22-1.62 s).
_ONE_BLAS_THREAD = []


def _one_blas_thread():
    """A context manager holding every loaded BLAS to one thread (``threadpoolctl``), or a no-op without it."""
    if not _ONE_BLAS_THREAD:
        try:
            import scipy.linalg  # noqa: F401  (SciPy's own OpenBLAS loaded, so that it is found)
            from threadpoolctl import ThreadpoolController

            _ONE_BLAS_THREAD.append(ThreadpoolController())
        except Exception as exc:  # a dependency; without it only speed is lost
            log.debug("BLAS threads left as they are (%s)", exc)
            _ONE_BLAS_THREAD.append(None)
    controller = _ONE_BLAS_THREAD[0]
    if controller is None:
        return contextlib.nullcontext()
    return controller.limit(limits=1, user_api="blas")


def _compiled(elimination, system):
    """The compiled factorization (one BLAS thread), or None (logged) when it cannot be had."""
    try:
        with _one_blas_thread():
            return elimination.factor(system, engine="compiled")
    except Exception as exc:  # no Numba, a kernel that cannot compile, NotPositiveDefinite: the engine's way
        log.info("compiled factorization not used (%s): the engine's choice", exc)
        return None


def factor(elimination, system):
    """The factor of ``system``'s normal matrix (an ``EdgeSystem`` on ``elimination``, a ``GraphElimination``):
    compiled from :data:`COMPILED_MIN_3D` unknowns, else (or if the compiled engine cannot run, or finds the matrix
    not positive definite) as the engine chooses."""
    f = _compiled(elimination, system) if system.d * system.b >= COMPILED_MIN_3D else None
    return elimination.factor(system) if f is None else f


def solve(elimination, system):
    """``elimination.solve(system)`` (x, factor, stats) on :func:`factor`'s factorization: the corrected
    semi-normal equations, the engine's fallbacks (the augmented system) included."""
    f = _compiled(elimination, system) if system.d * system.b >= COMPILED_MIN_3D else None
    return elimination.solve(system) if f is None else elimination.solve(system, factor=f)

"""Sparse linear algebra shared by the closed forms: SPD solves of any pattern (``factorize``), least squares with
the corrected semi-normal equations, the BLAS thread guard. The pose-graph systems of the closed forms do not come
through ``factorize``: they go through ``normal_equations.GraphElimination`` (the multifrontal engine).
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..errors import NumericalError, OptionError
from .threads import blas_limit

__all__ = ["blas_threads", "Factor", "factorize", "solve_least_squares", "refine_normal_equations",
           "augmented_least_squares", "refined_or_augmented", "REFINEMENT_STEPS", "REFINEMENT_STOP", "TRUST_TOLERANCE",
           "SOLVER_BACKENDS"]

log = logging.getLogger(__name__)

SOLVER_BACKENDS = ("auto", "qdldl", "superlu", "cholmod")

_BLAS: list = []  # threadpoolctl's controllers of the loaded BLAS libraries, found on first use
_BLAS_LOCK = threading.Lock()
_BLAS_USERS: list = [0, None]  # [blocks inside blas_threads now, the counts on entry of the first]


def _reset_blas_state() -> None:  # a forked child: no block of the parent's is running in it
    global _BLAS_LOCK
    _BLAS_LOCK = threading.Lock()
    _BLAS_USERS[:] = [0, None]


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reset_blas_state)


@contextlib.contextmanager
def blas_threads(n: int | None):
    """Run a block with at most ``n`` BLAS threads (None: as many as on entry) and yield a setter ``threads(k)``
    that changes it inside the block (k None: back to the count on entry) — only inside
    ``threads.engine_threads(blas_threads=m)``, which also caps every count at m; otherwise the setter does nothing
    (``threads``: the count is process-wide). Through threadpoolctl, every loaded BLAS; the process's count is
    restored when the last such block ends, also when blocks of several threads overlap."""
    limit = blas_limit()
    if limit is None:
        yield lambda k: None  # the setter does nothing: the process's BLAS is left alone
        return
    n = limit if n is None else min(n, limit)
    if not _BLAS:
        import scipy.linalg  # noqa: F401  (loads SciPy's BLAS, so that it is found)

        try:
            from threadpoolctl import ThreadpoolController

            found = ThreadpoolController().select(user_api="blas").lib_controllers
        except Exception as exc:  # a dependency, but without it only speed is lost
            log.debug("BLAS threads left as they are (%s)", exc)
            found = []
        _BLAS.append(found)
    with _BLAS_LOCK:
        if _BLAS_USERS[0] == 0:
            _BLAS_USERS[1] = [(lib, lib.get_num_threads()) for lib in _BLAS[0]]  # now, not when found
        _BLAS_USERS[0] += 1
        libs = _BLAS_USERS[1]
    state = [None]

    def threads(k: int | None) -> None:
        k = limit if k is None else min(k, limit)
        if k != state[0]:
            for lib, on_entry in libs:
                lib.set_num_threads(max(1, min(k, on_entry)))
            state[0] = k

    threads(n)
    try:
        yield threads
    finally:
        with _BLAS_LOCK:
            _BLAS_USERS[0] -= 1
            if _BLAS_USERS[0] == 0:
                for lib, on_entry in libs:
                    lib.set_num_threads(on_entry)


class NotPositiveDefinite(NumericalError):
    """A pivot block was not numerically positive definite (the matrix is not SPD in floating point)."""


def _no_factor() -> None:
    """What a pickled ``Factor`` becomes (a named function: joblib's hasher cannot pickle ``type(None)``)."""
    return None


class Factor:
    """A factored sparse SPD matrix N of shape (dim, dim): ``factor.solve(rhs)`` solves N x = rhs for rhs of shape
    (dim,) or (dim, r); ``factor.backend`` names the library used; ``matrix`` is N itself — whole and symmetric, in
    the factor's own numbering — or None when it is not kept (it may be given as a function that builds it on first
    use). A factor is engine state, not data: pickled or deep-copied, it becomes None (results keep the matrices
    from which it is rebuilt, as ``Phase3.pose_covariances`` factors ``info`` anew)."""

    def __reduce__(self):
        return _no_factor, ()

    def __init__(self, solve: Callable[[np.ndarray], np.ndarray], dim: int, backend: str, matrix=None):
        self._solve = solve
        self.dim = dim
        self.backend = backend
        self._matrix = matrix

    @property
    def matrix(self):
        if callable(self._matrix):
            self._matrix = self._matrix()
        return self._matrix

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._solve(np.asarray(rhs, dtype=float))

    __call__ = solve


def factorize(N: sp.spmatrix, *, backend: str = "auto") -> Factor:
    """Factor the sparse SPD matrix ``N`` (shape (d, d)) once; return a ``Factor``. ``backend``: ``"auto"`` and
    ``"qdldl"`` (the ``qdldl`` package's public ``Solver``, LDLᵀ after AMD), ``"superlu"`` (SciPy, symmetric mode:
    many right-hand sides at once), ``"cholmod"`` (scikit-sparse, an optional extra: ImportError naming it if
    missing)."""
    if backend not in SOLVER_BACKENDS:
        raise OptionError(f"unknown backend {backend!r}; expected one of {SOLVER_BACKENDS}")
    N = sp.csc_matrix(N)
    d = N.shape[0]
    if backend == "cholmod":
        try:
            from sksparse.cholmod import cholesky
        except ImportError as exc:  # depends on the optional extra
            raise ImportError("backend='cholmod' needs the optional extra: pip install 'lago-cvx[cholmod]'") from exc
        return Factor(cholesky(N), d, "cholmod")
    if backend in ("qdldl", "auto"):
        import qdldl

        solver = qdldl.Solver(sp.triu(N, format="csc"), upper=True)

        def solve(rhs: np.ndarray) -> np.ndarray:
            if rhs.ndim == 1:
                return solver.solve(rhs)
            return np.column_stack([solver.solve(np.ascontiguousarray(rhs[:, j])) for j in range(rhs.shape[1])])

        return Factor(solve, d, "qdldl", N)
    import scipy.sparse.linalg as spla  # SuperLU: imported only when it is used

    lu = spla.splu(N, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return Factor(lu.solve, d, "superlu")


#: Maximum number of correction steps of the corrected semi-normal equations in ``solve_least_squares``.
REFINEMENT_STEPS = 5

#: The refinement stops once a correction is below this size relative to ‖x‖∞: the error left is then at rounding
#: level (docs/performance.md, "Refinement").
REFINEMENT_STOP = 1e-9

#: After refinement, a last correction larger than this (relative to ‖x‖∞) means the normal equations
#: are too ill-conditioned to trust: the augmented system is solved instead.
TRUST_TOLERANCE = 1e-8


def augmented_least_squares(M: sp.spmatrix, b: np.ndarray) -> np.ndarray:
    """min ‖Mx − b‖ through the augmented system [[I, M], [Mᵀ, 0]] [r; x] = [b; 0] by sparse LU with partial
    pivoting (its conditioning that of M, not cond(M)² as for MᵀM); ``NumericalError`` if it gives no finite
    answer. The fallback of every normal-equation solve of the package."""
    import scipy.sparse.linalg as spla

    try:
        M = sp.csc_matrix(M)
        K = sp.bmat([[sp.identity(M.shape[0], format="csc"), M], [M.T, None]], format="csc")
        x = spla.splu(K).solve(np.concatenate([np.asarray(b, dtype=float), np.zeros(M.shape[1])]))[M.shape[0]:]
    except Exception as exc:
        raise NumericalError(f"the least-squares system is numerically singular ({exc}); check for "
                             "information matrices spanning more than ~1e15") from None
    if not np.isfinite(x).all():
        raise NumericalError("the least-squares system is numerically singular (non-finite solution); "
                             "check for information matrices spanning more than ~1e15")
    return x


def refine_normal_equations(solve, matvec, rmatvec, b: np.ndarray, *, first: np.ndarray | None = None):
    """x = N⁻¹Mᵀb for a factored N = MᵀM (``solve``), then the corrected semi-normal equations
    x ← x + N⁻¹Mᵀ(b − Mx) while the correction shrinks (at most ``REFINEMENT_STEPS``, stopping below
    ``REFINEMENT_STOP`` relative). ``matvec(x) = Mx``, ``rmatvec(r) = Mᵀr``; ``first``, when given, is Mᵀb computed
    already. Returns ``(x, stats, trusted)``: ``stats`` with ``method``, ``refinement_steps``, ``relative_correction``
    (the last correction relative to ‖x‖∞); ``trusted`` False when x is not finite or that correction exceeds
    ``TRUST_TOLERANCE``."""
    stats = {"method": "normal equations", "refinement_steps": 0, "relative_correction": 0.0}
    x = solve(rmatvec(b) if first is None else first)
    scale = max(np.max(np.abs(x)) if x.size else 0.0, np.finfo(float).tiny)
    last, rel, steps = np.inf, 0.0, 0
    for steps in range(1, REFINEMENT_STEPS + 1):
        dx = solve(rmatvec(b - matvec(x)))
        size = np.max(np.abs(dx)) if dx.size else 0.0
        if not size < last:  # no longer converging (or non-finite): keep the previous iterate
            steps -= 1
            break
        x = x + dx
        rel = size / scale
        last = size
        if rel < REFINEMENT_STOP:
            break
    stats.update(refinement_steps=steps, relative_correction=float(rel))
    trusted = bool(np.isfinite(x).all()) and rel <= TRUST_TOLERANCE
    return x, stats, trusted


def solve_least_squares(M: sp.spmatrix, b: np.ndarray, *, backend: str = "auto"):
    """Minimise ‖M x − b‖² for a sparse M (r × c) of full column rank: N = MᵀM factored once, then the corrected
    semi-normal equations (``refine_normal_equations``), whose residual b − Mx, formed in the original space,
    recovers the accuracy of a QR factorization even when cond(M)² ε ≈ 1 (information spanning 1e1 … 1e8, as in
    carlone/input_INTEL_g2o.g2o, loses 6 digits in the plain normal equations). Where N's factorization fails (N
    singular in floating point although M is not, e.g. one edge with information 1e16 and the others 1) or the
    answer is not trusted, the augmented system (``refined_or_augmented``); ``NumericalError`` (a ``GraphError``) if
    that gives no finite answer. Returns ``(x, N, factor, stats)``: ``factor`` None after the augmented system;
    ``stats`` as ``refine_normal_equations`` reports it, ``method`` "augmented system" after the fallback."""
    M = sp.csc_matrix(M)
    N = (M.T @ M).tocsc()
    if M.shape[1] == 0:  # nothing to estimate (a single pose)
        return np.zeros(0), N, None, {"method": "normal equations", "refinement_steps": 0, "relative_correction": 0.0}
    x, factor, stats = refined_or_augmented(lambda: factorize(N, backend=backend), M.dot, M.T.dot, b, lambda: M)
    return x, N, factor, stats


def refined_or_augmented(factor, matvec, rmatvec, b: np.ndarray, sparse):
    """min ‖M x − b‖ (b (r,) or (r, k)) by ``refine_normal_equations`` on ``factor()`` (a ``Factor`` of MᵀM); where
    that factorization fails or the refined answer is not trusted, by the augmented system of ``sparse()`` (M)
    instead, logged. Returns ``(x, factor, stats)``, ``factor`` None after the fallback."""
    stats = {"method": "normal equations", "refinement_steps": 0, "relative_correction": 0.0}
    f, x, trusted = None, None, False
    try:
        f = factor()
        x, stats, trusted = refine_normal_equations(f.solve, matvec, rmatvec, b)
    except Exception as exc:  # NotPositiveDefinite, qdldl "not quasi-definite", SuperLU "exactly singular", …
        log.info("normal equations could not be factored (%s): using the augmented system", exc)
    if not trusted:
        log.warning("least squares: normal equations too ill-conditioned (relative correction %.2g); "
                    "solving the augmented system instead", stats["relative_correction"])
        M, B = sparse(), b.reshape(b.shape[0], -1)
        x = np.stack([augmented_least_squares(M, B[:, j]) for j in range(B.shape[1])], 1)
        x = x.reshape((M.shape[1],) + b.shape[1:])
        stats["method"], f = "augmented system", None
    return x, f, stats

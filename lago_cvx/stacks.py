r"""Arithmetic on per-edge stacks (m, …): one small matrix or vector per edge, for graphs of millions of edges.

Not the sparse engine's business (no sparse matrix, no factorization): the mathematics calls these by name on its
(m, k, k) stacks of information and covariance blocks and on its (m, …) per-edge arrays.

* ``spd_inverse(A)`` — A⁻¹ = adj(A)/det(A) of symmetric positive definite A (m, k, k), k = 2, 3 (the cofactors of
  the symmetric matrix; the result symmetric); ``spd_inverse_corner(A)`` its (2, 2) entry alone (P_δ of an edge's
  3×3 information); ``cholesky(A)`` — lower L with L Lᵀ = A (the column recurrences of an unblocked Cholesky);
  ``whitening_2x2(info)`` — U = Lᵀ, UᵀU = info. NumPy's ``linalg`` calls LAPACK once per matrix of a stack; these
  closed forms take a few vectorized passes. ``spd_inverse`` and ``cholesky`` hand a matrix whose closed form breaks
  down (a pivot ≤ 0 or not finite) to ``numpy.linalg``, which gives the same answer or raises ``LinAlgError``.
* ``rotate(α, v)`` — R(α_k) v_k for m rotations at once.
* ``row_blocks(m)`` — per-edge arithmetic a block of ``BLOCK`` rows at a time: NumPy makes a fresh temporary for
  every operation; on a whole 1 786 812-edge stack each is 14–130 MB of memory handed over (and zeroed) anew, while
  in blocks the temporaries stay in cache and are recycled by the allocator (``benchmarks/million.md``).
* ``unique_sorted(a)`` — ``numpy.unique(a)`` by a sort: NumPy 2.4's hash-based path for a plain integer array is far
  slower on large arrays of distinct keys such as the pose-pair keys of a 1 000 000-pose graph.
"""

from __future__ import annotations

import numpy as np

__all__ = ["spd_inverse", "spd_inverse_corner", "cholesky", "whitening_2x2", "rotate", "row_blocks", "unique_sorted",
           "BLOCK"]

#: Rows per block of ``row_blocks`` (a (BLOCK, 3, 3) float stack is 1.2 MB).
BLOCK = 1 << 14


def unique_sorted(a) -> np.ndarray:
    """The distinct values of ``a`` (any shape, flattened), ascending: ``numpy.unique(a)`` by a sort."""
    v = np.sort(np.asarray(a).reshape(-1))
    if v.size:
        v = v[np.concatenate(([True], v[1:] != v[:-1]))]
    return v


def row_blocks(m: int, block: int | None = None):
    """Slices ``lo:hi`` covering ``range(m)`` in order, ``block`` rows each (default ``BLOCK``, read at
    the call; the last one shorter)."""
    block = BLOCK if block is None else int(block)
    for lo in range(0, m, block):
        yield slice(lo, min(lo + block, m))


def _closed_form(A, kernel, lapack) -> np.ndarray:
    """``kernel(A, out) -> ok (m,)`` on a stack A (m, k, k) of 2×2 or 3×3 matrices, ``lapack`` (the
    ``numpy.linalg`` function) on every matrix the kernel did not take — and on any other shape."""
    A = np.asarray(A, dtype=float)
    if A.ndim != 3 or A.shape[-1] not in (2, 3):
        return lapack(A)
    out = np.zeros_like(A)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ok = kernel(A, out)
    bad = ~ok | ~np.isfinite(out).all(axis=(1, 2))
    if bad.any():
        out[bad] = lapack(A[bad])  # the same answer, or numpy's LinAlgError
    return out


def spd_inverse(A: np.ndarray) -> np.ndarray:
    """Inverses of the symmetric positive definite matrices A (m, k, k), k ∈ {2, 3}; other k through
    ``numpy.linalg.inv``. Only the lower triangle of A is read."""
    return _closed_form(A, _adjugate, np.linalg.inv)


def _adjugate(A: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out = adj(A)/det(A) for symmetric A (m, k, k); True where det(A) is positive and finite."""
    if A.shape[-1] == 2:
        a, b, d = A[:, 0, 0], A[:, 1, 0], A[:, 1, 1]
        det = a * d - b * b
        out[:, 0, 0], out[:, 1, 1] = d / det, a / det
        out[:, 0, 1] = out[:, 1, 0] = -b / det
    else:
        (a00, a10, a11, a20, a21, a22), (c00, c10, c20), det = _cofactors3(A)
        out[:, 0, 0] = c00 / det
        out[:, 1, 0] = out[:, 0, 1] = c10 / det
        out[:, 2, 0] = out[:, 0, 2] = c20 / det
        out[:, 1, 1] = (a00 * a22 - a20 * a20) / det
        out[:, 2, 1] = out[:, 1, 2] = (a10 * a20 - a00 * a21) / det
        out[:, 2, 2] = (a00 * a11 - a10 * a10) / det
    return (det > 0) & np.isfinite(det)


def _cofactors3(A: np.ndarray):
    """The lower triangle of symmetric A (m, 3, 3), the cofactors of its first column and det(A)."""
    a00, a10, a11 = A[:, 0, 0], A[:, 1, 0], A[:, 1, 1]
    a20, a21, a22 = A[:, 2, 0], A[:, 2, 1], A[:, 2, 2]
    c00 = a11 * a22 - a21 * a21
    c10 = a21 * a20 - a10 * a22
    c20 = a10 * a21 - a11 * a20
    return (a00, a10, a11, a20, a21, a22), (c00, c10, c20), a00 * c00 + a10 * c10 + a20 * c20


def spd_inverse_corner(A: np.ndarray) -> np.ndarray:
    """(A⁻¹)[2, 2] (m,) of symmetric positive definite A (m, 3, 3): ``spd_inverse(A)[:, 2, 2]`` by the
    same operations, so the same values, without the other five entries; a matrix whose closed form
    breaks down goes through ``spd_inverse`` as a whole. Only the lower triangle of A is read."""
    A = np.asarray(A, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        (a00, a10, a11, _, _, _), _, det = _cofactors3(A)
        v = (a00 * a11 - a10 * a10) / det
    bad = ~((det > 0) & np.isfinite(det) & np.isfinite(v))
    if bad.any():
        v[bad] = spd_inverse(A[bad])[:, 2, 2]
    return v


def cholesky(A: np.ndarray) -> np.ndarray:
    """Lower Cholesky factors L (m, k, k) of the SPD matrices A (m, k, k), k ∈ {2, 3}; other k through
    ``numpy.linalg.cholesky``. Only the lower triangle of A is read. Raises ``numpy.linalg.LinAlgError``
    if a matrix is not positive definite, as ``numpy.linalg.cholesky`` does."""
    return _closed_form(A, _cholesky, np.linalg.cholesky)


def _cholesky(A: np.ndarray, L: np.ndarray) -> np.ndarray:
    """L Lᵀ = A column by column (L zero on entry); True where every pivot is positive."""
    l00 = np.sqrt(A[:, 0, 0])
    l10 = A[:, 1, 0] / l00
    l11 = np.sqrt(A[:, 1, 1] - l10 * l10)
    L[:, 0, 0], L[:, 1, 0], L[:, 1, 1] = l00, l10, l11
    ok = (l00 > 0) & (l11 > 0)
    if A.shape[-1] == 3:
        l20 = A[:, 2, 0] / l00
        l21 = (A[:, 2, 1] - l20 * l10) / l11
        l22 = np.sqrt(A[:, 2, 2] - l20 * l20 - l21 * l21)
        L[:, 2, 0], L[:, 2, 1], L[:, 2, 2] = l20, l21, l22
        ok &= l22 > 0
    return ok


def rotate(angles: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(α_k) v_k for angles (m,) and vectors v (m, 2) → (m, 2): the same numbers as
    ``np.einsum("kab,kb->ka", rot2(angles), v)``, written out a block of rows at a time (no (m, 2, 2)
    stack of rotations; temporaries that stay in cache: ``row_blocks``)."""
    angles = np.asarray(angles, dtype=float)
    v = np.asarray(v, dtype=float)
    out = np.empty((angles.shape[0], 2))
    for k in row_blocks(angles.shape[0]):
        cs, sn = np.cos(angles[k]), np.sin(angles[k])
        x, y = v[k, 0], v[k, 1]
        out[k, 0] = cs * x - sn * y
        out[k, 1] = sn * x + cs * y
    return out


def whitening_2x2(info: np.ndarray) -> np.ndarray:
    """Upper-triangular square roots U (m, 2, 2) with UᵀU = info for SPD 2×2 ``info`` (m, 2, 2).

    U = Lᵀ for the Cholesky factor L of ``info``; ‖U r‖² = rᵀ info r. Vectorized closed form."""
    a = np.sqrt(info[:, 0, 0])
    b = info[:, 1, 0] / a
    c = np.sqrt(info[:, 1, 1] - b * b)
    U = np.zeros_like(info)
    U[:, 0, 0] = a
    U[:, 0, 1] = b
    U[:, 1, 1] = c
    return U

r"""Closed forms on stacks of small symmetric matrices: one per edge, (m, k, k) with k = 2 or 3.

NumPy's ``linalg`` calls LAPACK once per matrix of a stack, a Python-level cost per matrix on graphs of millions of
edges (``benchmarks/million.md``); the closed forms below do each in a few vectorized passes. Symmetric positive definite input is assumed;
a matrix whose closed form breaks down (a pivot ≤ 0 or not finite) is handed to ``numpy.linalg``
instead, which gives the same answer or raises ``numpy.linalg.LinAlgError`` as before.

* ``spd_inverse(A)`` — A⁻¹ = adj(A)/det(A) (cofactors of the symmetric matrix; the result symmetric);
  ``spd_inverse_corner(A)`` its (2, 2) entry alone (P_δ of an edge's 3×3 information).
* ``cholesky(A)`` — lower L with L Lᵀ = A (the column-by-column recurrences of an unblocked Cholesky).
"""

from __future__ import annotations

import numpy as np

__all__ = ["spd_inverse", "spd_inverse_corner", "cholesky", "rotate"]


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
    stack of rotations; temporaries that stay in cache: ``arrays.row_blocks``)."""
    from .arrays import row_blocks

    angles = np.asarray(angles, dtype=float)
    v = np.asarray(v, dtype=float)
    out = np.empty((angles.shape[0], 2))
    for k in row_blocks(angles.shape[0]):
        cs, sn = np.cos(angles[k]), np.sin(angles[k])
        x, y = v[k, 0], v[k, 1]
        out[k, 0] = cs * x - sn * y
        out[k, 1] = sn * x + cs * y
    return out

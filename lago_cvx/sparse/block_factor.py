r"""The multifrontal factor (MF) front by front in NumPy, on the storage of ``compiled.CompiledLayout`` (front f's
block column [L_PP; X] (D × k) packed column by column from ``L[Lptr[f]]``: the upper trapezoid of its transpose, row
by row): the fallback of the C kernels (``factor``, ``solve``), and the selected inversion (T) for both
(``inverse_blocks``).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack, solve_triangular

from .linalg import NotPositiveDefinite

__all__ = ["factor", "solve", "inverse_blocks"]

_TRAPEZOIDS: dict = {}


def _column(lay, L: np.ndarray, f: int) -> np.ndarray:
    """Front f's block column [L_PP; X] (D, k) from the packed L."""
    k, D = int(lay.K[f]), int(lay.D[f])
    idx = _TRAPEZOIDS.get((k, D))
    if idx is None:
        idx = _TRAPEZOIDS.setdefault((k, D), np.triu_indices(k, 0, D))
    out = np.zeros((k, D))
    out[idx] = L[lay.Lptr[f]:lay.Lptr[f + 1]]
    return out.T


def _vars(lay, f: int):
    """(pivot slots, update-row slots, the update rows' local variables in the parent's front) of front f."""
    b, comp = lay.b, np.arange(lay.b)
    rows = slice(lay.rptr[f], lay.rptr[f + 1])
    return (np.arange(lay.fptr[f] * b, lay.fptr[f + 1] * b), (lay.rows[rows, None] * b + comp).reshape(-1),
            (lay.rel[rows, None] * b + comp).reshape(-1))


def factor(lay, asm, blocks: np.ndarray, L: np.ndarray, progress=None) -> None:
    """(MF) of N = Σ blocks (q, b, b) at the assembler's pose pairs (``blocks[order]`` by front) into the packed
    ``L``. Raises ``NotPositiveDefinite`` naming the front whose pivot block is not positive definite."""
    b, F = lay.b, lay.plan.n_fronts
    cr = np.arange(b)[None, :, None]
    children = [[] for _ in range(F)]
    for c, p in enumerate(lay.plan.parent.tolist()):
        if p >= 0:
            children[p].append(c)
    update: dict = {}
    for f in range(F):
        k, D = int(lay.K[f]), int(lay.D[f])
        Fm = np.zeros((D, D))
        sl = slice(asm.bptr[f], asm.bptr[f + 1])
        vals = blocks[asm.order[sl]]
        vals = np.where(asm.transposed[sl, None, None], np.swapaxes(vals, 1, 2), vals)
        np.add.at(Fm, (asm.li[sl, None, None] * b + cr, asm.lj[sl, None, None] * b + np.swapaxes(cr, 1, 2)), vals)
        for c in children[f]:  # extend-add
            rel = _vars(lay, c)[2]
            Fm[np.ix_(rel, rel)] += update.pop(c)
        try:
            Lpp = np.linalg.cholesky(Fm[:k, :k])  # reads the lower triangle
        except np.linalg.LinAlgError:
            raise NotPositiveDefinite(f"the matrix is not positive definite (front {f})") from None
        X = solve_triangular(Lpp, Fm[k:, :k].T, lower=True, check_finite=False).T
        if D > k:
            update[f] = Fm[k:, k:] - X @ X.T
        L[lay.Lptr[f]:lay.Lptr[f + 1]] = np.vstack([Lpp, X]).T[np.triu_indices(k, 0, D)]
        if progress is not None and (f % max(F // 50, 1) == 0 or f == F - 1):
            progress(f + 1, F)


def solve(lay, L: np.ndarray, Y: np.ndarray) -> None:
    """N x = y in place for Y (N, r) in elimination slots: forward L_PP z_P = y_P, y_R −= X z_P (leaves up), then back
    x_P = L_PP⁻ᵀ(z_P − Xᵀx_R) (root down)."""
    F = lay.plan.n_fronts
    for f in range(F):
        C, (piv, rows, _) = _column(lay, L, f), _vars(lay, f)
        k = piv.size
        Y[piv] = z = solve_triangular(C[:k], Y[piv], lower=True, check_finite=False)
        if rows.size:
            Y[rows] -= C[k:] @ z
    for f in range(F - 1, -1, -1):
        C, (piv, rows, _) = _column(lay, L, f), _vars(lay, f)
        k = piv.size
        z = Y[piv] - C[k:].T @ Y[rows] if rows.size else Y[piv]
        Y[piv] = solve_triangular(C[:k], z, lower=True, trans="T", check_finite=False)


def inverse_blocks(factor, prow=None, pcol=None, *, progress=None):
    """Blocks of Σ = N⁻¹ by selected inversion (T) on ``factor`` (a ``compiled.CompiledFactor``): ``diag`` (d, b, b)
    each pose's b×b block (in pose order) and, when ``prow``/``pcol`` (q,) are given — pose pairs on the pattern of
    L, e.g. the ends of edges — ``pairs`` (q, b, b), pairs[t] = Σ[prow[t], pcol[t]]. Returns ``(diag, pairs)``. Root
    down, Σ_RR read from the parent's front and Y = X L_PP⁻¹: Σ_RP = −Σ_RR Y, Σ_PP = L_PP⁻ᵀ L_PP⁻¹ − Yᵀ Σ_RP."""
    lay, L = factor.layout, factor.L
    plan, b, F = lay.plan, lay.b, lay.plan.n_fronts
    pose_at = np.empty(plan.d, np.int64)
    pose_at[plan.position] = np.arange(plan.d)
    diag = np.zeros((plan.d, b, b))
    pairs = None
    if prow is not None:
        asm = lay.assembler(np.asarray(prow, np.int64), np.asarray(pcol, np.int64))
        pairs = np.empty((np.size(prow), b, b))
        cr = np.arange(b)[None, :, None]
    sig: list = [None] * F
    left = lay.nchild.copy()
    for f in range(F - 1, -1, -1):
        C, (piv, rows, rel) = _column(lay, L, f), _vars(lay, f)
        k, D = piv.size, int(lay.D[f])
        Li = np.tril(lapack.dtrtri(C[:k], lower=1)[0])  # L_PP⁻¹
        S = np.empty((D, D))
        S[:k, :k] = Li.T @ Li
        if rows.size:
            p = plan.parent[f]
            S[k:, k:] = SRR = sig[p][np.ix_(rel, rel)]
            Y = C[k:] @ Li
            S[k:, :k] = SRP = -(SRR @ Y)
            S[:k, k:] = SRP.T
            S[:k, :k] -= Y.T @ SRP
            left[p] -= 1
            if left[p] == 0:
                sig[p] = None  # its last child has read it
        kp = k // b
        diag[pose_at[plan.fptr[f] + np.arange(kp)]] = S[:k, :k].reshape(kp, b, kp, b)[np.arange(kp), :, np.arange(kp)]
        if pairs is not None:
            sl = slice(asm.bptr[f], asm.bptr[f + 1])
            blk = S[asm.li[sl, None, None] * b + cr, asm.lj[sl, None, None] * b + np.swapaxes(cr, 1, 2)]
            pairs[asm.order[sl]] = np.where(asm.transposed[sl, None, None], np.swapaxes(blk, 1, 2), blk)
        sig[f] = S if lay.nchild[f] else None
        if progress is not None and (f % max(F // 50, 1) == 0 or f == 0):
            progress(F - f, F)
    return diag, pairs

r"""The numeric side of a multifrontal factor (``lago_cvx.sparse.multifrontal``): solves N x = y and the
selected inversion (T) that gives marginal covariances.

``BlockFactor`` holds, per group of fronts of the ``multifrontal.BlockLayout``, L_PP (B, Kb, Kb), its
inverse for batched groups (None for a single large front, solved by triangular solves) and X (B, Rb, Kb),
where L's block column of a front's pivots P is [L_PP; X] (eq. (MF) of ``lago_cvx.sparse.multifrontal``).

**Solve** N x = y, group by group (the fronts of a group are independent): forward z_P = L_PP⁻¹ y_P,
y_R −= X z_P from the leaves up; back x_P = L_PP⁻ᵀ(z_P − Xᵀ x_R) from the root down.

**Selected inversion** (Takahashi, Fagan, Chen 1973; Erisman, Tinney 1975): Σ = N⁻¹ on the pattern of L,
front by front from the root down, by eq. (T) of ``lago_cvx.sparse.multifrontal``.
"""

from __future__ import annotations

import numpy as np

from .linalg import blas_threads

__all__ = ["BlockFactor", "inverse_blocks"]


class BlockFactor:
    """N = L Lᵀ by (MF): ``solve(rhs)`` for rhs (N,) or (N, r) in elimination-slot order (see
    ``BlockLayout``); ``selected_inverse`` the entries of N⁻¹ on the pattern of L (T)."""

    def __init__(self, layout, L11, Linv, X):  # layout: the multifrontal.BlockLayout
        self.layout = layout
        self.L11, self.Linv, self.X = L11, Linv, X

    def solve(self, rhs: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """Solve N x = rhs for rhs (N,) or (N, r) in a system's own variable numbering, ``slots`` its
        elimination slots (``BlockLayout.slots``)."""
        rhs = np.asarray(rhs, dtype=float)
        return self.solve_slots(rhs[np.argsort(slots)])[slots]

    def _row_maps(self):
        """Per group, the distinct update-row slots of its fronts and where each (front, row) lands
        among them: the forward solve sums the fronts' updates by ``bincount`` over the group's own rows
        (siblings share rows), never over all N slots."""
        maps = self.__dict__.get("_row_map_cache")
        if maps is None:
            maps = [np.unique(g.rowv.reshape(-1), return_inverse=True) if g.R else None
                    for g in self.layout.groups]
            self._row_map_cache = maps
        return maps

    def solve_slots(self, y: np.ndarray) -> np.ndarray:
        """Solve N x = y with y (N,) or (N, r) indexed by elimination slots; returns x likewise. Group by
        group (fronts of a group are independent): forward z_P = L_PP⁻¹ y_P, y_R −= X z_P (leaves up),
        back x_P = L_PP⁻ᵀ(z_P − Xᵀ x_R) (root down); a large front by triangular solves, a batch of
        small ones by products with the stored L_PP⁻¹."""
        lay = self.layout
        one = y.ndim == 1
        r = 1 if one else y.shape[1]
        Y = np.zeros((lay.N + 1, r))  # slot N: the padding's dummy, kept at zero
        Y[:-1] = y.reshape(lay.N, r)
        maps = self._row_maps()
        with blas_threads(1):
            self._sweeps(Y, maps, r)
        out = Y[:-1]
        return out[:, 0] if one else out

    def _sweeps(self, Y: np.ndarray, maps, r: int) -> None:
        from scipy.linalg import solve_triangular

        lay = self.layout
        for gi, g in enumerate(lay.groups):  # forward
            z = Y[g.piv]  # (B, Kb, r)
            Li = self.Linv[gi]
            if Li is None:
                z[0] = solve_triangular(self.L11[gi][0], z[0], lower=True, check_finite=False)
            else:
                z = Li @ z
            Y[g.piv] = z
            if g.R:
                upd = (self.X[gi] @ z).reshape(-1, r)
                rows, inv = maps[gi]
                for j in range(r):
                    Y[rows, j] -= np.bincount(inv, upd[:, j], minlength=rows.size)
                Y[-1] = 0.0
        for gi in range(len(lay.groups) - 1, -1, -1):  # back
            g = lay.groups[gi]
            z = Y[g.piv]
            if g.R:
                z -= np.swapaxes(self.X[gi], 1, 2) @ Y[g.rowv]
            Li = self.Linv[gi]
            if Li is None:
                z[0] = solve_triangular(self.L11[gi][0], z[0], lower=True, trans="T", check_finite=False)
            else:
                z = np.swapaxes(Li, 1, 2) @ z
            Y[g.piv] = z
            Y[-1] = 0.0

    def selected_inverse(self, *, progress=None):
        """Σ = N⁻¹ on every front by (T), from the root down. Returns, per group, the dense front blocks
        Σ_f (B, D, D) in the group's local variable order (zero on padded variables)."""
        from scipy.linalg import lapack

        lay = self.layout
        nG = len(lay.groups)
        sig: list = [None] * nG
        for gi in range(nG - 1, -1, -1):
            g = lay.groups[gi]
            B, D, Kb = g.fronts.size, g.D, g.K * lay.b
            Rb = D - Kb
            c, ci, X = self.L11[gi], self.Linv[gi], self.X[gi]
            if ci is None:
                ci = np.tril(lapack.dtrtri(c[0], lower=1)[0])[None]
            S = np.zeros((B, D, D))
            if Rb:
                SRR = np.zeros((B, Rb, Rb))
                for s_, f in enumerate(g.fronts.tolist()):
                    p = lay.plan.parent[f]
                    rel = lay.rel[f]
                    nv = rel.size
                    SRR[s_, :nv, :nv] = sig[lay.group_of[p]][lay.slot_of_front[p]][rel[:, None], rel]
                Y = X @ ci
                SRP = -(SRR @ Y)
                S[:, :Kb, :Kb] = np.swapaxes(ci, 1, 2) @ ci - np.swapaxes(Y, 1, 2) @ SRP
                S[:, Kb:, Kb:] = SRR
                S[:, Kb:, :Kb] = SRP
                S[:, :Kb, Kb:] = np.swapaxes(SRP, 1, 2)
            else:
                S[:, :Kb, :Kb] = np.swapaxes(ci, 1, 2) @ ci
            sig[gi] = S
            if progress is not None:
                progress(nG - gi, nG)
        return sig


def inverse_blocks(factor: BlockFactor, prow=None, pcol=None, *, progress=None):
    """Blocks of Σ = N⁻¹ by selected inversion (T): ``diag`` (d, b, b) the b×b block of every pose (in
    pose order) and, when ``prow``/``pcol`` (q,) are given — pose pairs on the pattern of L, e.g. the
    ends of edges — ``pairs`` (q, b, b) with pairs[t] = Σ[prow[t], pcol[t]] (rows: prow's variables).
    Returns ``(diag, pairs)`` (``pairs`` None without pairs)."""
    lay = factor.layout
    plan, b = lay.plan, lay.b
    with blas_threads(1):  # small dense products: one BLAS thread is faster (see BlockLayout.factor)
        sig = factor.selected_inverse(progress=progress)
    pose_at = np.empty(plan.d, np.int64)
    pose_at[plan.position] = np.arange(plan.d)
    diag = np.zeros((plan.d, b, b))
    for g, S in zip(lay.groups, sig):
        B, K = g.fronts.size, g.K
        Sr = S[:, :K * b, :K * b].reshape(B, K, b, K, b)
        t = np.arange(K)
        blk = Sr[:, t, :, t, :]  # (K, B, b, b)
        pos = g.piv[:, ::b].T  # (K, B) slots of component 0
        ok = pos < lay.N
        diag[pose_at[pos[ok] // b]] = blk[ok]
    pairs = None
    if prow is not None:
        grp, off, D, tr = lay.block_targets(np.asarray(prow, np.int64), np.asarray(pcol, np.int64))
        cr, cc = np.divmod(np.arange(b * b), b)
        rr = np.where(tr[:, None], cc[None, :], cr[None, :])
        ccs = np.where(tr[:, None], cr[None, :], cc[None, :])
        flat = off[:, None] + rr * D[:, None] + ccs
        pairs = np.empty((grp.size, b * b))
        order = np.argsort(grp, kind="stable")  # the pairs group by group, one pass each
        cuts = np.flatnonzero(np.diff(grp[order])) + 1
        for sel in np.split(order, cuts):
            if sel.size:
                pairs[sel] = sig[grp[sel[0]]].reshape(-1)[flat[sel]]
        pairs = pairs.reshape(-1, b, b)
    return diag, pairs

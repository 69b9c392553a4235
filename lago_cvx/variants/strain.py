r"""Strain of hard anchors (V3): does the data agree with a pose held fixed?

The gradient of the cost at the known coordinates, g_K = 2 M_Kᵀ(M x − W z), is the negated Lagrange
multiplier of ``x[K] == x̄_K`` (cvxpy's dual value ν satisfies ∇f + ν = 0). Releasing the coordinates c
of one anchor alone (everything else re-optimized) lowers the cost by

    Δχ²_c = ¼ g_cᵀ S_c⁺ g_c,    S_c = M_cᵀM_c − M_cᵀM_U (M_UᵀM_U)⁻¹ M_UᵀM_c,

the Lagrange-multiplier (score) test: χ² with |c| degrees of freedom when the anchor agrees with the
measurements. Orientations are tested in phase 1 (1 dof), positions in phase 3 (2 dof); an anchor is
reported *strained* when the p-value of its statistic is below ``strain_level`` and a warning names it.
A hard anchor cannot compromise: the measurement residuals absorb the inconsistency, and this
statistic is what tells.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .systems import SystemSolution

__all__ = ["STRAIN_LEVEL", "AnchorStrain", "strain_report"]

log = logging.getLogger("lago_cvx.variants")

#: Default significance level of the anchor strain test.
STRAIN_LEVEL = 1e-3


@dataclass(frozen=True)
class AnchorStrain:
    """Lagrange-multiplier test of one anchor (V3). ``chi2_theta`` (1 dof, phase 1) and
    ``chi2_position`` (2 dof, phase 3) are None for unknown components; ``chi2``/``dof`` their sum;
    ``p_value`` = P(χ²_dof > chi2); ``strained`` when p_value < the level; ``gradient`` the cost
    gradient at the anchored coordinates (x, y, θ; NaN where not anchored) — the negated multipliers."""

    id: int
    kind: str
    chi2_theta: float | None
    chi2_position: float | None
    chi2: float
    dof: int
    p_value: float
    strained: bool
    gradient: tuple


def _release_statistics(M: sp.csc_matrix, known: np.ndarray, sol: SystemSolution, coord_sets: list) -> list:
    """Δχ²_c = ¼ g_cᵀ S_c⁺ g_c (V3) for each coordinate set c (global coordinate indices, all known)."""
    if not coord_sets:
        return []
    U = ~known
    MU = M[:, U]
    kpos = np.full(known.size, -1, np.int64)
    kpos[np.flatnonzero(known)] = np.arange(int(known.sum()))
    factor = sol.factorized()
    out = []
    batch = 64
    for s in range(0, len(coord_sets), batch):  # loop over anchors (not edges), in batches
        sets = coord_sets[s:s + batch]
        cols = np.concatenate(sets)
        Mc = M[:, cols]
        B = (MU.T @ Mc).toarray()
        X = factor.solve(B) if B.shape[0] else np.zeros_like(B)
        G = (Mc.T @ Mc).toarray() - B.T @ X
        off = 0
        for c in sets:
            j = slice(off, off + c.size)
            off += c.size
            Sc = 0.5 * (G[j, j] + G[j, j].T)
            g = sol.grad_known[kpos[c]]
            w, V = np.linalg.eigh(Sc)
            scale = max(float(np.abs(np.diag((Mc[:, j].T @ Mc[:, j]).toarray())).max()), np.finfo(float).tiny)
            ok = w > 1e-12 * scale
            out.append(float(0.25 * np.sum((V[:, ok].T @ g) ** 2 / w[ok])))
    return out


def strain_report(graph, anc, sys1, sol1, sys3, sol3, level) -> list:
    """One ``AnchorStrain`` per anchor of ``anc`` from the phase-1 and phase-3 systems and solutions."""
    from scipy import stats as sps

    th_sets = [np.array([a.index]) for a in anc if a.theta is not None]
    p_sets = [np.array([2 * a.index, 2 * a.index + 1]) for a in anc if a.position is not None]
    chi_th = _release_statistics(sys1.design(), sys1.known, sol1, th_sets)
    chi_p = _release_statistics(sys3.design(), sys3.known, sol3, p_sets)
    kpos1 = np.cumsum(sys1.known) - 1
    kpos3 = np.cumsum(sys3.known) - 1
    out, it, ip = [], iter(chi_th), iter(chi_p)
    for a in anc:  # loop over anchors
        ct = next(it) if a.theta is not None else None
        cpv = next(ip) if a.position is not None else None
        dof = (1 if ct is not None else 0) + (2 if cpv is not None else 0)
        total = (ct or 0.0) + (cpv or 0.0)
        pval = float(sps.chi2.sf(total, dof))
        grad = [np.nan, np.nan, np.nan]
        if a.position is not None:
            grad[0:2] = sol3.grad_known[kpos3[[2 * a.index, 2 * a.index + 1]]]
        if a.theta is not None:
            grad[2] = sol1.grad_known[kpos1[a.index]]
        out.append(AnchorStrain(a.id, a.kind, ct, cpv, total, dof, pval, pval < level, tuple(float(g) for g in grad)))
    bad = [s for s in out if s.strained]
    if bad:
        log.warning("%d of %d anchors are strained (hard anchors cannot compromise: the measurement residuals absorb "
                    "the inconsistency): %s", len(bad), len(out),
                    "; ".join(f"anchor {s.id} ({s.kind}): Lagrange-multiplier χ² = {s.chi2:.4g} with {s.dof} dof, "
                              f"p = {s.p_value:.2g}" for s in bad[:10]))
    return out

r"""SE-Sync's optimality certificate in 3-D (Rosen, Carlone, Bandeira, Leonard, IJRR 2019, §4.2).

The cost
========
SE-Sync certifies its own cost, not χ²: with SE-Sync's weights (the isotropic Gaussians closest to each edge's
blocks, ``space.chordal``) κ_ij = 3 / (2 tr(Ω_rr⁻¹)), τ_ij = 3 / tr(Ω_tt⁻¹),

    f(t, R) = Σ_ij κ_ij ‖R_j − R_i R̃_ij‖²_F + τ_ij ‖t_j − t_i − R_i t̃_ij‖²                      (S1)

The weights are SE-Sync's own reading of each edge's 6×6 matrix **as written** (its rotation and translation blocks;
the cross terms ignored), whichever cost the graph means (``graph.cost``, :mod:`lago_cvx.posegraph3d`): f, its
certificate and the optima SE-Sync publishes for these files do not depend on ``cost``. f is neither cost's χ²; the
χ² reported beside it (``lago-cvx certify``) is the graph's cost at the certified point.

In the variable Y = [t_0 … t_{n−1} | R_0 … R_{n−1}] (3 × 4n, poses indexed from 0 as in the graph) every residual
is linear, so f = tr(Y M Yᵀ) with M = CᵀC (4n × 4n, C stacking √κ [I at R_j, −R̃ᵀ at R_i] and
√τ [1 at t_j, −1 at t_i, −t̃ᵀ at R_i] per edge).

The certificate
===============
Lagrange multipliers of R_iᵀR_i = I: Λ_i = sym(R_iᵀ (Y M)_{R_i}) (3 × 3), S = M − blkdiag(0, Λ_0, …, Λ_{n−1}). For any
symmetric Λ with S ⪰ 0, weak duality gives f* ≥ Σ tr Λ_i; at a critical point Σ tr Λ_i = f, so S ⪰ 0 proves Y
globally optimal (SE-Sync's Theorem 7). S has the null vectors Yᵀ (3) and the translation shift [1; 0]; grounding
the anchor's translation (after moving it to the origin) removes the latter, and by Haynsworth's inertia formula
(the planar ``certification.certificate``, the same argument) the grounded S_g + η Î_R has no negative pivot in an
LDLᵀ iff λ_min(S_Q) ≥ −η, S_Q = SE-Sync's translation-free certificate matrix. The pivots are counted in one sparse
factorization (SuperLU with diagonal pivots only: LU = L D Lᵀ, Sylvester's law of inertia).

Honest bounds: η = ``NUMERICAL_TOL`` · ‖M‖_∞ (an upper bound of ‖M‖₂; the entries of S are known to rounding only).
With zero negative pivots, Λ − ηI is dual feasible and f* ≥ Σ tr Λ_i − 3nη. Otherwise μ is multiplied by 4, starting
from η (μ = 4^k η, k = 1, 2, …, at most up to 10³‖M‖_∞), until S_g + μÎ_R has none, and f* ≥ Σ tr Λ_i − 3nμ (valid,
usually weak); ``Certificate3D.shift`` is that μ (η itself when the first count finds no negative pivot). The
point is *certified* when (f − f*_lower)/f ≤ ``tol`` (``conventions.CERTIFY_TOL``) or, with ``abs_tol`` > 0, by
SE-Sync's absolute test (``optimality.absolute_test``: f − f*_lower ≤ abs_tol, or no negative pivot of
S_g + abs_tol·Î_R, i.e. λ_min(S_Q) ≥ −abs_tol).

The local solver
================
The certificate needs a critical point of (S1); ``refine_sesync3d`` finds one from any estimate (LAGO's, or the
χ²-refined one) by Gauss–Newton with the right retraction R_i ← R_i Exp(δφ_i), t_i ← t_i + δt_i (steps accepted
only when f decreases), the anchor held fixed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..conventions import CERTIFY_TOL
from ..errors import OptionError
from ..optimality import ProvenBound, absolute_test, check_abs_tol, relative_suboptimality
from ..sparse import factorize
from ..so3 import exp_so3, hat
from .blocks import block_diagonal, edge_matrix, free_index

__all__ = ["NUMERICAL_TOL", "sesync_weights3d", "sesync_cost3d", "data_matrix3d", "refine_sesync3d", "Certificate3D",
           "certify3d"]

#: Numerical floor of the PSD test, relative to ‖M‖_∞ (as the planar certificate's, relative to ‖M‖₂).
NUMERICAL_TOL = 1e-12


def sesync_weights3d(graph):
    """(κ (m,), τ (m,)) of (S1), from the blocks of the information as written (module docstring)."""
    O = graph.information
    kappa = 3.0 / (2.0 * np.trace(np.linalg.inv(O[:, 3:, 3:]), axis1=1, axis2=2))
    tau = 3.0 / np.trace(np.linalg.inv(O[:, :3, :3]), axis1=1, axis2=2)
    return kappa, tau


def sesync_cost3d(graph, t, R) -> float:
    """f of (S1) at t (n, 3), R (n, 3, 3)."""
    kappa, tau = sesync_weights3d(graph)
    i, j = graph.tails, graph.heads
    dR = R[j] - R[i] @ graph.delta_R
    dt = t[j] - t[i] - np.einsum("kab,kb->ka", R[i], graph.delta_t)
    return float(kappa @ np.einsum("kab,kab->k", dR, dR) + tau @ np.einsum("ka,ka->k", dt, dt))


def data_matrix3d(graph) -> sp.csr_matrix:
    """C (4m × 4n) with f = ‖Y Cᵀ‖²_F and M = CᵀC; Y's columns: t_0 … t_{n−1}, then the columns of R_0 … R_{n−1}."""
    kappa, tau = sesync_weights3d(graph)
    n, m = graph.n_poses, graph.n_edges
    i, j = graph.tails, graph.heads
    sk, st = np.sqrt(kappa), np.sqrt(tau)
    rows, cols, vals = [], [], []
    r0 = 4 * np.arange(m)
    for a in range(3):  # rotation rows: √κ (R_j e_a − R_i R̃ e_a)
        rows += [r0 + a]
        cols += [n + 3 * j + a]
        vals += [sk]
        for b in range(3):
            rows += [r0 + a]
            cols += [n + 3 * i + b]
            vals += [-sk * graph.delta_R[:, b, a]]
    rows += [r0 + 3, r0 + 3]
    cols += [j, i]
    vals += [st, -st]
    for b in range(3):
        rows += [r0 + 3]
        cols += [n + 3 * i + b]
        vals += [-st * graph.delta_t[:, b]]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(4 * m, 4 * n))


def _jacobian(graph, t, R, sk, st):
    """(residuals (m, 12), blocks for the head (m, 12, 6) and the tail (m, 12, 6)); step order (δt, δφ)."""
    m = graph.n_edges
    i, j = graph.tails, graph.heads
    Ri, Rj, dR = R[i], R[j], graph.delta_R
    res = np.concatenate([(sk[:, None, None] * (Rj - Ri @ dR)).reshape(m, 9),
                          st[:, None] * (t[j] - t[i] - np.einsum("kab,kb->ka", Ri, graph.delta_t))], axis=1)
    Pj, Ni = np.zeros((m, 12, 6)), np.zeros((m, 12, 6))
    E = hat(np.eye(3))  # [e_k]×
    for k in range(3):
        Pj[:, :9, 3 + k] = (sk[:, None, None] * (Rj @ E[k])).reshape(m, 9)
        Ni[:, :9, 3 + k] = (-sk[:, None, None] * (Ri @ E[k] @ dR)).reshape(m, 9)
    Pj[:, 9:, :3] = st[:, None, None] * np.eye(3)
    Ni[:, 9:, :3] = -st[:, None, None] * np.eye(3)
    Ni[:, 9:, 3:] = st[:, None, None] * (Ri @ hat(graph.delta_t))
    return res, Pj, Ni


def _curvature(graph, t, R, kappa, tau) -> np.ndarray:
    """The second-order term of f along the retraction, per pose (n, 6, 6) (zero in the δt rows): with
    R Exp(φ) = R (I + [φ]× + ½[φ]×² + …) and tr(X [φ]×²) = φᵀ sym(X) φ − ‖φ‖² tr X, the residuals' curvature adds
    sym(X) − tr(X) I to the φφ block of each pose, X summed over its edges: κ Dᵀ R_j (head), −κ R̃ Dᵀ R_i − τ t̃ dᵀ R_i
    (tail), D = R_j − R_i R̃, d = t_j − t_i − R_i t̃."""
    i, j = graph.tails, graph.heads
    D = R[j] - R[i] @ graph.delta_R
    d = t[j] - t[i] - np.einsum("kab,kb->ka", R[i], graph.delta_t)
    Xj = kappa[:, None, None] * (np.swapaxes(D, 1, 2) @ R[j])
    Xi = -kappa[:, None, None] * (graph.delta_R @ np.swapaxes(D, 1, 2) @ R[i]) \
        - tau[:, None, None] * (np.einsum("ka,kb->kab", graph.delta_t, d) @ R[i])
    X = np.zeros((graph.n_poses, 3, 3))
    np.add.at(X, j, Xj)
    np.add.at(X, i, Xi)
    H = np.zeros((graph.n_poses, 6, 6))
    H[:, 3:, 3:] = 0.5 * (X + np.swapaxes(X, 1, 2)) - np.trace(X, axis1=1, axis2=2)[:, None, None] * np.eye(3)
    return H


def refine_sesync3d(graph, t, R, *, anchor_index: int = 0, max_iterations: int = 30, tolerance: float = 1e-14):
    """A critical point of (S1) from (t, R): Newton steps (JᵀJ plus the retraction's curvature, ``_curvature``),
    falling back to the Gauss–Newton step when Newton's does not decrease f; steps are accepted only when f
    decreases. Ends when f decreases by less than ``tolerance`` relative (or not at all), after ``max_iterations``.
    Returns (t, R, f, iterations)."""
    kappa, tau = sesync_weights3d(graph)
    sk, st = np.sqrt(kappa), np.sqrt(tau)
    t, R = np.array(t, dtype=float), np.array(R, dtype=float)
    n = graph.n_poses
    free = free_index(n, 6, anchor_index)
    cost = sesync_cost3d(graph, t, R)
    it = 0
    for it in range(1, max_iterations + 1):
        res, Pj, Ni = _jacobian(graph, t, R, sk, st)
        J = edge_matrix(graph.tails, graph.heads, Pj, Ni, n)[:, free]
        N = (J.T @ J).tocsc()
        g = J.T @ res.ravel()
        curv = block_diagonal(_curvature(graph, t, R, kappa, tau))[free][:, free]
        best = None
        for H in ((N + curv).tocsc(), N):
            d = np.zeros((n, 6))
            try:
                d.ravel()[free] = -factorize(H).solve(g)
            except Exception:  # an indefinite Newton matrix: the Gauss–Newton step instead
                continue
            t2, R2 = t + d[:, :3], R @ exp_so3(d[:, 3:])
            new = sesync_cost3d(graph, t2, R2)
            if np.isfinite(new) and new < cost:
                best = (t2, R2, new)
                break
        if best is None:
            break
        done = cost - best[2] <= tolerance * cost
        t, R, cost = best
        if done:
            break
    return t, R, cost, it


@dataclass(eq=False)
class Certificate3D(ProvenBound):
    """Outcome of ``certify3d`` (module docstring): ``certified``, ``verdict``; ``cost`` f at the point certified
    (``t``, ``R``), ``dual_value`` Σ tr Λ_i, ``lower_bound`` a proven lower bound on f*, ``shift`` the μ (≥ η) it
    used, ``eta`` the floor, ``n_negative`` negative pivots of S_g + ηÎ_R, ``lambda_min`` the smallest eigenvalue of
    S_g by shift-invert Lanczos (informational; NaN if it failed), ``residual_rel`` ‖S Yᵀ‖_F / (‖M‖_∞ √(3n)),
    ``times`` seconds per step."""

    t: np.ndarray
    R: np.ndarray
    tol: float = CERTIFY_TOL
    abs_tol: float = 0.0
    times: dict = field(default_factory=dict)


def _negative_pivots(A: sp.csc_matrix) -> int | None:
    """Negative eigenvalues of the symmetric A by the signs of D in A = L D Lᵀ (SuperLU, diagonal pivots; None when
    SuperLU pivoted off the diagonal or failed: then no inertia is known)."""
    import scipy.sparse.linalg as spla

    try:
        lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return None
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return None
    return int((lu.U.diagonal() < 0).sum())


def certify3d(graph, t, R=None, *, tol: float = CERTIFY_TOL, abs_tol: float = 0.0, anchor=None, local: bool = True,
              max_iterations: int = 30, anchor_index: int | None = None) -> Certificate3D:
    """SE-Sync's certificate for (S1) at (t, R) — after ``refine_sesync3d`` from there (at most ``max_iterations``)
    when ``local`` (module docstring); ``tol`` relative, ``abs_tol`` absolute (0: none). ``t`` may be a whole
    estimate instead (a result with ``t`` and ``R``, or the pair), R then left out. ``anchor``: the id of the pose
    whose translation is grounded (default the smallest id, as everywhere); ``anchor_index`` (an index) is the older
    spelling, kept for callers that have one."""
    check_abs_tol(abs_tol)
    if R is None:
        from .refine import estimate3d

        t, R = estimate3d(t)
    if anchor_index is not None and anchor is not None:
        raise OptionError("certify3d: give anchor (an id) or anchor_index, not both")
    anchor_index = graph.anchor_index(anchor) if anchor_index is None else int(anchor_index)
    times = {}
    start = time.perf_counter()
    if local:
        t, R, _, _ = refine_sesync3d(graph, t, R, anchor_index=anchor_index, max_iterations=max_iterations)
    t = np.asarray(t, float) - np.asarray(t, float)[anchor_index]  # the anchor at the origin: Yᵀ stays null in S_g
    times["local"] = time.perf_counter() - start
    n = graph.n_poses
    C = data_matrix3d(graph)
    M = (C.T @ C).tocsr()
    Y = np.concatenate([t.T, np.concatenate(list(R), axis=1)], axis=1)  # 3 × 4n
    YM = (M @ Y.T).T
    lam = np.einsum("iba,bic->iac", R, YM[:, n:].reshape(3, n, 3))  # R_iᵀ (YM)_{R_i}
    lam = 0.5 * (lam + np.swapaxes(lam, 1, 2))
    S = (M - block_diagonal(lam, offset=n)).tocsr()
    cost = float(np.einsum("ij,ij->", Y, YM))
    dual = float(np.trace(lam, axis1=1, axis2=2).sum())
    normM = float(abs(M).sum(axis=1).max())
    eta = NUMERICAL_TOL * normM
    keep = np.r_[np.delete(np.arange(n), anchor_index), np.arange(n, 4 * n)]
    Sg = S[keep][:, keep].tocsc()
    IR = sp.diags(np.r_[np.zeros(n - 1), np.ones(3 * n)], format="csc")
    t0 = time.perf_counter()
    mu, neg = eta, _negative_pivots((Sg + eta * IR).tocsc())
    first_neg = neg
    while neg != 0 and mu < 1e3 * normM:
        mu *= 4.0
        neg = _negative_pivots((Sg + mu * IR).tocsc())
    times["inertia"] = time.perf_counter() - t0
    lower = dual - 3 * n * mu if neg == 0 else float("-inf")
    residual = float(np.linalg.norm((S @ Y.T))) / (normM * np.sqrt(3 * n))
    t0 = time.perf_counter()
    try:
        import scipy.sparse.linalg as spla

        lmin = float(spla.eigsh(Sg, k=1, sigma=-1e-3 * max(abs(cost), 1e-12) / n, which="LM",
                                return_eigenvectors=False)[0])
    except Exception:  # informational only
        lmin = float("nan")
    times["eigenvalue"] = time.perf_counter() - t0
    bound = relative_suboptimality(cost, lower)
    absolute = None if neg is None or bound <= tol else absolute_test(
        cost - lower, abs_tol, eta, lambda: _negative_pivots((Sg + abs_tol * IR).tocsc()) == 0)
    certified = (neg == 0 and bound <= tol) or absolute is not None
    if absolute is not None:
        verdict = (f"certified: globally optimal for the SE-Sync cost within the absolute tolerance {abs_tol:.3g} "
                   f"({absolute}; relative bound {bound:.3g} > {tol:g})")
    elif neg is None:
        verdict = "not certified: the inertia of S could not be counted (singular or pivoted factorization)"
    elif certified:
        verdict = f"certified: globally optimal for the SE-Sync cost within a relative {bound:.3g}"
        if first_neg:
            verdict += f" (S + μÎ_R ⪰ 0 proven with μ = {mu:.3g} > η: the point is a critical point to that accuracy)"
    elif neg == 0 and first_neg == 0:
        verdict = f"not certified: bound too weak (S ⪰ -ηI proven, relative bound {bound:.3g} > {tol:g})"
    else:
        verdict = (f"not certified: S has {first_neg} eigenvalue(s) below -η (a suboptimal critical point); proven "
                   f"relative suboptimality ≤ {bound:.3g}")
    times["total"] = time.perf_counter() - start
    return Certificate3D(certified=bool(certified), verdict=verdict, cost=cost, dual_value=dual,
                         lower_bound=float(lower), shift=float(mu), eta=float(eta),
                         n_negative=-1 if first_neg is None else int(first_neg), lambda_min=lmin,
                         residual_rel=residual, t=t, R=np.asarray(R), tol=tol, abs_tol=abs_tol,
                         times=times)

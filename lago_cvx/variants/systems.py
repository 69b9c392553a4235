r"""Each phase of a variant as one weighted linear least-squares system with known coordinates (V1–V2,
V5–V8), its closed form, and its cvxpy problem with a loss (V10) and named constraints (V9).

(V1) minimise ‖W (z − Bᵀx)‖²  subject to  x_K = x̄_K, W a sparse whitening, Bᵀ the design.
(V2) Closed form: with M = W Bᵀ the known columns move to the right-hand side,
     x_U = (M_UᵀM_U)⁻¹ M_Uᵀ (W z − M_K x̄_K)  (``lago_cvx.sparse.linalg.solve_least_squares``); cvxpy: one
     variable x, ``cp.sum_squares(W @ (z − Bᵀ @ x))`` and ONE equality constraint ``x[K] == x̄_K``, whose
     dual value is −g_K, g_K = 2 M_Kᵀ(M x − W z) (the force the data exert on the anchors).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import OptionError
from ..graph import incidence_matrix
from ..sparse import Factor, factorize, solve_least_squares
from ..phases import Phase2, edge_whitening, phase2_blocks
from ..posegraph import PoseGraph, rot2, wrap_angle
from ..solvers import INFEASIBLE_STATUSES, ClarabelSettings, solve
from ..uncertainty import EdgeUncertainty
from .anchors import PriorArrays, prior_arrays
from .constraints import collect_constraints, diagnose

__all__ = ["LOSSES", "DEFAULT_THRESHOLD", "WeightedSystem", "phase1_system", "AnchoredPhase2", "anchored_phase2",
           "phase3_system", "position_system", "SystemSolution", "solve_system", "system_problem",
           "solve_system_cvxpy"]

log = logging.getLogger("lago_cvx.variants")

#: Losses accepted by the variants (``loss=...``).
LOSSES = ("l2", "huber", "l1")
#: Default robust threshold M in whitened units (≈ the 95 % point of a χ with 3 dof, √7.81 = 2.8).
DEFAULT_THRESHOLD = 3.0


@dataclass(frozen=True, eq=False)
class WeightedSystem:
    """One phase as (V1): minimise ‖W (z − Bᵀx)‖² over x ∈ ℝᴺ subject to x[known] = values[known].

    ``Bt`` sparse (r, N); ``z`` (r,); ``W`` sparse (s, r); ``known`` (N,) bool; ``values`` (N,) (used
    where known); ``groups`` (s,) int: the edge of each whitened row, −1 for rows that are never
    robustified (priors); ``name`` "phase1" / "phase3"."""

    Bt: sp.csr_matrix
    z: np.ndarray
    W: sp.csr_matrix
    known: np.ndarray
    values: np.ndarray
    groups: np.ndarray
    name: str

    @property
    def n_coords(self) -> int:
        return int(self.Bt.shape[1])

    def design(self) -> sp.csc_matrix:
        """M = W Bᵀ, the whitened design (s, N)."""
        return (self.W @ self.Bt).tocsc()

    def whitened_residual(self, x: np.ndarray) -> np.ndarray:
        """W (z − Bᵀx), shape (s,)."""
        return self.W @ (self.z - self.Bt @ x)

    def cost(self, x: np.ndarray) -> float:
        return float(np.sum(self.whitened_residual(x) ** 2))


def phase1_system(graph: PoseGraph, delta_reg, unc: EdgeUncertainty, known: np.ndarray, values: np.ndarray,
                  priors: PriorArrays | None = None, *, edge_weights: np.ndarray | None = None) -> WeightedSystem:
    """Phase 1 with known orientations and priors (V5): Bᵀ₁ = [Aᵀ; E_Q] ((m + q) × n),
    z₁ = [δ_reg; μ̃_θ], W₁ = diag(√w P_δ^{-1/2}, σ_Q⁻¹) (w = ``edge_weights``, default 1).
    ``known`` (n,) bool, ``values`` (n,) the known (regularized) orientations."""
    n, m = graph.n_poses, graph.n_edges
    pr = priors if priors is not None else prior_arrays([], np.zeros(0))
    E = sp.csr_matrix((np.ones(pr.q), (np.arange(pr.q), pr.index)), shape=(pr.q, n))
    Bt = sp.vstack([incidence_matrix(graph).T, E], format="csr")
    w = unc.sqrt_info_delta if edge_weights is None else unc.sqrt_info_delta * np.sqrt(edge_weights)
    W = sp.diags(np.concatenate([w, 1.0 / pr.sigma_theta])).tocsr()
    z = np.concatenate([np.asarray(delta_reg, dtype=float), pr.mean[:, 2]])
    groups = np.concatenate([np.arange(m), -np.ones(pr.q, np.int64)])
    return WeightedSystem(Bt, z, W, np.asarray(known, bool).copy(), np.asarray(values, float).copy(), groups, "phase1")


@dataclass(frozen=True, eq=False)
class AnchoredPhase2(Phase2):
    """Phase 2 with known orientations (V6), a ``Phase2`` (``anchored_phase2`` for both forms): ``delta_g``
    (m, 2); ``z``, ``W`` (and for the full form ``Bt``) of the phase-3 system; ``jac``; ``anchor_index`` the
    reference pose; ``free_theta`` (d_θ,) the poses of unknown orientation; ``groups`` the edge of each
    row of W (−1: prior)."""

    free_theta: np.ndarray = None
    groups: np.ndarray = None


def anchored_phase2(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, free_theta: np.ndarray,
                    L: sp.spmatrix, L_groups: np.ndarray, reference: int, *, information: str = "marginal",
                    delta_reg=None) -> AnchoredPhase2:
    """Phase 2 with known orientations (V6). ``theta`` (n,) the phase-1 orientations (global frame).

    ``information="marginal"`` — Δᵍ = R(θ̂_i)Δˡ (eq. 9), z = [Δᵍ; θ̂_U] and the sparse square root
    W = [[P_Δ^{-1/2}Rᵀ, −P_Δ^{-1/2}SΔˡe_iᵀ], [0, L]] of P_z⁻¹, ``L`` (r_L × d_θ) the square root of the
    phase-1 information (LᵀL = P_θ⁻¹); an edge whose tail has a known orientation has no J block.
    ``information="full"`` — the edges' joint residuals of ``lago_cvx.phases`` (module docstring) over all
    coordinates x = [p (2n); θ (n)]: ``Bt`` (3m × 3n) = [[Aᵀ⊗I₂, −J], [0, Aᵀ]], z = [Δᵍ − Jθ̂; δ_reg]
    (``delta_reg`` (m,) needed), W = the per-edge U_k T_kᵀ blocks; the prior rows are added by
    ``phase3_system`` (``L`` is not used: the phase-1 rows are the edges' δ rows themselves)."""
    n, m = graph.n_poses, graph.n_edges
    if information == "marginal":
        d = free_theta.size
        col_of = np.full(n, -1, np.int64)
        col_of[free_theta] = np.arange(d)
        delta_g, jac, top = phase2_blocks(graph, theta, unc, col_of, d)
        z = np.concatenate([delta_g.reshape(-1), theta[free_theta]])
        bottom = sp.hstack([sp.csr_matrix((L.shape[0], 2 * m)), sp.csr_matrix(L)])
        W = sp.vstack([top, bottom], format="csr")
        groups = np.concatenate([np.repeat(np.arange(m), 2), L_groups])
        return AnchoredPhase2(delta_g=delta_g, z=z, W=W, jac=jac, anchor_index=int(reference),
                              information="marginal", free_theta=free_theta, groups=groups)
    if delta_reg is None:
        raise OptionError("anchored_phase2(information='full') needs delta_reg")
    delta_g, jac, _ = phase2_blocks(graph, theta, unc, np.arange(n), n)  # J over all n orientations
    At = incidence_matrix(graph).T  # (m, n)
    Bt = sp.bmat([[sp.kron(At, sp.identity(2)), -jac], [None, At]], format="csr")
    z = np.concatenate([delta_g.reshape(-1) - jac @ theta, np.asarray(delta_reg, dtype=float)])
    groups = np.concatenate([np.repeat(np.arange(m), 2), np.arange(m)])
    return AnchoredPhase2(delta_g=delta_g, z=z, W=edge_whitening(graph, theta, unc), jac=jac,
                          anchor_index=int(reference), Bt=Bt, information="full", free_theta=free_theta,
                          groups=groups)


def phase3_system(graph: PoseGraph, ph2: AnchoredPhase2, known: np.ndarray, values: np.ndarray,
                  priors: PriorArrays | None = None) -> WeightedSystem:
    """Phase 3 with known coordinates and priors (V7), over x = [p (interleaved, 2n); θ (n)].

    marginal: Bᵀ = [[A ⊗ I₂ᵀ, 0], [0, E_U], [E_Q,p, h E_Q,θ]], z = [Δᵍ; θ̂_U; μ_p + h μ̃_θ],
    W = blkdiag(phase-2 W, C_q). full: Bᵀ = [phase-2 Bᵀ; E_Q,θ; [E_Q,p, h E_Q,θ]],
    z = [phase-2 z; μ̃_θ; μ_p + h μ̃_θ], W = blkdiag(phase-2 W, σ_Q⁻¹, C_q) — the prior's marginal θ part
    (which the seed's form carries inside L) and its conditional part (V8). ``known`` (3n,) bool and
    ``values`` (3n,) in the same order."""
    n, m = graph.n_poses, graph.n_edges
    pr = priors if priors is not None else prior_arrays([], np.zeros(0))
    q = pr.q
    rq = np.arange(2 * q)
    qi = np.repeat(pr.index, 2)
    D = sp.csr_matrix((np.concatenate([np.ones(2 * q), pr.h.reshape(-1)]),
                       (np.concatenate([rq, rq]), np.concatenate([2 * qi + np.tile([0, 1], q), 2 * n + qi]))),
                      shape=(2 * q, 3 * n))
    z_cond = (pr.mean[:, :2] + pr.h * pr.mean[:, 2:3]).reshape(-1)
    C = sp.block_diag(list(pr.C), format="csr") if q else sp.csr_matrix((0, 0))
    if ph2.information == "full":
        Eq = sp.csr_matrix((np.ones(q), (np.arange(q), 2 * n + pr.index)), shape=(q, 3 * n))
        Bt = sp.vstack([ph2.Bt, Eq, D], format="csr")
        z = np.concatenate([ph2.z, pr.mean[:, 2], z_cond])
        W = sp.block_diag([ph2.W, sp.diags(1.0 / pr.sigma_theta), C], format="csr")
        groups = np.concatenate([ph2.groups, -np.ones(3 * q, np.int64)])
    else:
        d = ph2.free_theta.size
        Bp = sp.kron(incidence_matrix(graph).T, sp.identity(2), format="csr")  # (2m, 2n)
        Eu = sp.csr_matrix((np.ones(d), (np.arange(d), 2 * n + ph2.free_theta)), shape=(d, 3 * n))
        Bt = sp.vstack([sp.hstack([Bp, sp.csr_matrix((2 * m, n))]), Eu, D], format="csr")
        z = np.concatenate([ph2.z, z_cond])
        W = sp.block_diag([ph2.W, C], format="csr")
        groups = np.concatenate([ph2.groups, -np.ones(2 * q, np.int64)])
    return WeightedSystem(Bt, z, W, np.asarray(known, bool).copy(), np.asarray(values, float).copy(), groups, "phase3")


def position_system(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, known: np.ndarray,
                    values: np.ndarray, priors: PriorArrays | None = None) -> WeightedSystem:
    """The position polish with known coordinates and priors, over x = [p (interleaved, 2n)] for the
    orientations ``theta`` (n,) held fixed (``lago_cvx.positions``, eq. (P)): per edge p_j − p_i ≈ R(θ_i)t_k,
    t_k = Δˡ − h_k ē_k, weight C_kR(θ_i)ᵀ; per prior p_q ≈ μ_p − h_q(θ_q − μ̃_θ,q), weight C_q (the
    conditional part of V8 with θ fixed). ``known``/``values`` (2n,)."""
    n, m = graph.n_poses, graph.n_edges
    pr = priors if priors is not None else prior_arrays([], np.zeros(0))
    q = pr.q
    Ri = rot2(theta[graph.tails])
    e = wrap_angle(theta[graph.heads] - theta[graph.tails] - graph.delta)
    g = np.einsum("kab,kb->ka", Ri, graph.delta_l - unc.shift * e[:, None]).reshape(-1)
    blocks = unc.sqrt_info_pp @ np.swapaxes(Ri, 1, 2)
    Wedges = sp.block_diag(list(blocks), format="csr") if m else sp.csr_matrix((0, 0))
    Bp = sp.kron(incidence_matrix(graph).T, sp.identity(2), format="csr")  # (2m, 2n)
    rq = np.arange(2 * q)
    Eq = sp.csr_matrix((np.ones(2 * q), (rq, 2 * np.repeat(pr.index, 2) + np.tile([0, 1], q))), shape=(2 * q, 2 * n))
    e_q = theta[pr.index] - pr.mean[:, 2]
    zq = (pr.mean[:, :2] - pr.h * e_q[:, None]).reshape(-1)
    C = sp.block_diag(list(pr.C), format="csr") if q else sp.csr_matrix((0, 0))
    return WeightedSystem(sp.vstack([Bp, Eq], format="csr"), np.concatenate([g, zq]),
                          sp.block_diag([Wedges, C], format="csr"), np.asarray(known, bool).copy(),
                          np.asarray(values, float).copy(), np.concatenate([np.repeat(np.arange(m), 2),
                                                                            -np.ones(2 * q, np.int64)]),
                          "positions")


@dataclass(eq=False)
class SystemSolution:
    """Solution of a ``WeightedSystem``: ``x`` (N,) all coordinates; ``info`` sparse (d_U, d_U) =
    M_UᵀM_U; ``grad_known`` (|K|,) g_K of (V3) (cvxpy: −dual value); ``factor``/``stats`` (closed form);
    ``problem`` (cvxpy); ``weights`` (s,) IRLS weights of the whitened rows (robust losses, else 1);
    ``constraint_names`` the named constraints that were imposed (cvxpy)."""

    x: np.ndarray
    info: sp.csc_matrix
    grad_known: np.ndarray | None
    factor: Factor | None = None
    stats: dict | None = None
    problem: object | None = None
    weights: np.ndarray | None = None
    constraint_names: tuple = ()

    def factorized(self) -> Factor:
        if self.factor is None:
            self.factor = factorize(self.info, backend="superlu")
        return self.factor


def solve_system(sys_: WeightedSystem, *, backend: str = "auto") -> SystemSolution:
    """Closed form (V2): x_U = argmin ‖M_U x_U − (W z − M_K x̄_K)‖² by ``solve_least_squares``;
    also returns g_K = 2 M_Kᵀ(M x − W z) (V3)."""
    M = sys_.design()
    U, K = ~sys_.known, sys_.known
    MU, MK = M[:, U], M[:, K]
    Wz = sys_.W @ sys_.z
    xU, N, factor, stats = solve_least_squares(MU, Wz - MK @ sys_.values[K], backend=backend)
    x = sys_.values.copy()
    x[U] = xU
    g = 2.0 * (MK.T @ (M @ x - Wz))
    return SystemSolution(x, N.tocsc(), g, factor, stats)


def _group_matrices(groups: np.ndarray, rows: np.ndarray):
    """For the robust rows ``rows`` (indices into the whitened rows) with edge ``groups[rows]``: the
    list of sparse selectors S_a (n_g × |rows|) picking the a-th row of every group, and n_g."""
    g = groups[rows]
    uniq, gid = np.unique(g, return_inverse=True)
    order = np.argsort(gid, kind="stable")
    starts = np.r_[0, np.flatnonzero(np.diff(gid[order])) + 1]
    rank = np.empty(rows.size, np.int64)
    rank[order] = np.arange(rows.size) - np.repeat(starts, np.diff(np.r_[starts, rows.size]))
    sel = []
    for a in range(int(rank.max()) + 1 if rows.size else 0):  # loop over the ≤ 3 rows of an edge
        j = np.flatnonzero(rank == a)
        sel.append(sp.csr_matrix((np.ones(j.size), (gid[j], j)), shape=(uniq.size, rows.size)))
    return sel, uniq.size


def _robust_objective(sys_: WeightedSystem, r, loss: str, threshold: float, grouping: str):
    """The loss of V10 on the edge rows of W r (the prior rows stay quadratic), DCP."""
    import cvxpy as cp

    robust = np.flatnonzero(sys_.groups >= 0)
    quad = np.flatnonzero(sys_.groups < 0)
    Wr = sys_.W[robust]
    terms = [cp.sum_squares(sys_.W[quad] @ r)] if quad.size else []
    groups = sys_.groups if grouping == "edge" else np.arange(sys_.groups.size)
    sel, _ = _group_matrices(groups, robust)
    if len(sel) <= 1:  # one row per group: scalar atoms
        terms.append(cp.sum(cp.huber(Wr @ r, threshold)) if loss == "huber"
                     else 2.0 * threshold * cp.norm1(Wr @ r))
    elif loss == "huber":  # group Huber as a Moreau envelope: min_v ‖r − v‖² + 2M Σ‖v_g‖
        v = cp.Variable(robust.size, name="outlier_part")
        norms = cp.norm(cp.vstack([S @ v for S in sel]), 2, axis=0)
        terms += [cp.sum_squares(Wr @ r - v), 2.0 * threshold * cp.sum(norms)]
    else:
        e = Wr @ r
        terms.append(2.0 * threshold * cp.sum(cp.norm(cp.vstack([S @ e for S in sel]), 2, axis=0)))
    return cp.sum(cp.hstack(terms)) if len(terms) > 1 else terms[0]


def system_problem(sys_: WeightedSystem, *, loss: str = "l2", threshold: float = DEFAULT_THRESHOLD,
                   grouping: str = "edge"):
    """The phase as a cvxpy problem (V1 with the loss of V10).

    Returns ``(problem, x, anchor_constraint)``: ``x`` (N,) the variable of all coordinates,
    ``anchor_constraint`` the equality ``x[K] == x̄_K`` (None when nothing is known; its
    ``dual_value`` is −g_K). Objective: ``cp.sum_squares(W @ (z − Bᵀ @ x))`` for ``loss="l2"``;
    for ``"huber"``/``"l1"`` the edge rows use the robust loss (``grouping="edge"``: the rows of an
    edge as one group, ``"component"``: each row alone) and the prior rows stay quadratic."""
    import cvxpy as cp

    if loss not in LOSSES:
        raise OptionError(f"unknown loss {loss!r}; expected one of {LOSSES}")
    if grouping not in ("edge", "component"):
        raise OptionError(f"grouping must be 'edge' or 'component', got {grouping!r}")
    if not threshold > 0:
        raise OptionError(f"threshold must be > 0, got {threshold}")
    x = cp.Variable(sys_.n_coords, name="theta" if sys_.name == "phase1" else "x")
    r = sys_.z - sys_.Bt @ x
    objective = (cp.sum_squares(sys_.W @ r) if loss == "l2"
                 else _robust_objective(sys_, r, loss, threshold, grouping))
    K = np.flatnonzero(sys_.known)
    anchor = (x[K] == sys_.values[K]) if K.size else None
    return cp.Problem(cp.Minimize(objective), [anchor] if anchor is not None else []), x, anchor


def _row_weights(sys_: WeightedSystem, x: np.ndarray, loss: str, threshold: float, grouping: str) -> np.ndarray:
    """IRLS weights of the whitened rows at x: w_g = min(1, M/‖r_g‖) for robust groups, 1 else."""
    w = np.ones(sys_.W.shape[0])
    if loss == "l2":
        return w
    r = sys_.whitened_residual(x)
    rob = sys_.groups >= 0
    groups = sys_.groups if grouping == "edge" else np.arange(sys_.groups.size)
    uniq, gid = np.unique(groups[rob], return_inverse=True)
    norm = np.sqrt(np.bincount(gid, weights=r[rob] ** 2, minlength=uniq.size))
    w[rob] = np.minimum(1.0, threshold / np.maximum(norm, np.finfo(float).tiny))[gid]
    return w


def solve_system_cvxpy(sys_: WeightedSystem, *, loss: str = "l2", threshold: float = DEFAULT_THRESHOLD,
                       grouping: str = "edge", constraints=None, pose_variables=None,
                       settings: ClarabelSettings | None = None, preset=None) -> SystemSolution:
    """Build (``system_problem``) and solve with Clarabel (``lago_cvx.solvers.solve``). Named convex
    constraints (V9) come either as a list of ``NamedConstraint`` (``constraints``) or from a function
    ``constraints(pv)`` called with ``pose_variables(x)`` (a ``PoseVariables`` of this phase's variable);
    an infeasible problem raises ``InfeasibleConstraintsError`` naming them."""
    from ..solvers import LEAST_SQUARES

    problem, x, anchor = system_problem(sys_, loss=loss, threshold=threshold, grouping=grouping)
    named = [] if constraints is None else collect_constraints(
        constraints, pose_variables(x) if pose_variables is not None else None, sys_.name)
    named = [c for c in named if c.constraints]
    if named:
        import cvxpy as cp

        problem = cp.Problem(problem.objective, problem.constraints + [k for c in named for k in c.constraints])
    preset = LEAST_SQUARES if preset is None else preset
    fixed = [anchor] if anchor is not None else []
    status = solve(problem, settings, preset=preset, what=sys_.name, allow=INFEASIBLE_STATUSES)
    if status in INFEASIBLE_STATUSES:
        diagnose(sys_.name, fixed, named, lambda p: solve(p, settings, preset=preset, what=sys_.name,
                                                         allow=INFEASIBLE_STATUSES))
    xv = np.asarray(x.value, dtype=float).copy()
    K = sys_.known
    xv[K] = sys_.values[K]  # exact, not to solver tolerance
    MU = sys_.design()[:, ~K]
    g = -np.asarray(anchor.dual_value, dtype=float).reshape(-1) if anchor is not None else np.zeros(0)
    return SystemSolution(xv, (MU.T @ MU).tocsc(), g, problem=problem,
                          weights=_row_weights(sys_, xv, loss, threshold, grouping),
                          constraint_names=tuple(c.name for c in named))

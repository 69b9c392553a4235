r"""SE-Sync's semidefinite relaxation of the planar pose-graph problem as an explicit cvxpy problem,
solved by Clarabel, with rounding and a proven lower bound.

Z = YᵀY (3n × 3n) and dropping rank(Z) = 2 gives SE-Sync's relaxation (their Problem 7)::

    primal   f_SDP = min tr(M Z)  s.t.  Z ⪰ 0,  Z_{R_i R_i} = I₂  (i = 0 … n−1)                       (S9)
    dual             max Σ tr Λ_i  s.t.  M − Λ̂ ⪰ 0                                                    (S10)

f_SDP ≤ f*. Z_{R_i R_i} = I₂ only says R_iᵀR_i = I, i.e. it relaxes SO(2) to **O(2)**: a rank-2 Z
could contain reflections; ``SdpResult.n_reflected`` counts the rotation blocks of the rounded factor
whose determinant has the minority sign. Translation gauge: M 1_t = 0 makes (S10) have no strictly
feasible point and (S9) an unbounded optimal face, which interior-point methods dislike; we **ground
the anchor's translation** (drop row/column 3a of M and Z; exact, since f is translation invariant),
after which both are strictly feasible (Z = I; Λ_i = −εI) and strong duality holds.
(S10) has the sparsity pattern of the pose graph (3×3 blocks), which Clarabel's chordal decomposition
exploits; its dual variable is the (PSD-completed) primal Z. Rounding: Y_R = top-2 eigenpairs of the
rotation block Z_RR, sign-fix the reflection by the majority of det(Y_{R_i}), project each block to
SO(2), then optimal translations by a weighted Laplacian solve; gap = (f(rounded) − f_SDP)/f_SDP.
f(rounded) ≥ f* always (a feasible point); Clarabel's Λ shifted by λ_min(S_Q(Λ)) (eq. (S8)) gives a
proven lower bound, so f* is bracketed whatever the solver's accuracy.

Scaling and accuracy (measured). The translation indices are scaled by L = √(mean rotation diagonal
/ mean translation diagonal of M) (an exact congruence; without it Clarabel stalls 10× earlier on
CSAIL). An interior-point method resolves M − Λ̂ ⪰ 0 to ≈ 1e-9–1e-10 of ‖M‖, i.e. f_SDP to about
2n·1e-10‖M‖ absolutely; real SLAM data have f* ≪ n‖M‖ (CSAIL: κ up to 1e4, f* = 31.7), so the relative
accuracy of f_SDP is 1e-8 on synthetic/manhattan sub-graphs but only 1e-6…1e-3 on CSAIL/intel
sub-graphs, where Clarabel ends "AlmostSolved" or, sometimes, with a numerical error (then
``solve_sdp`` retries with L = 1 and with the non-compact chordal transformation). The **dense
primal** (S9) as a cvxpy PSD variable has no sparsity for Clarabel to exploit (a 3n−1 dense cone), so it is
for cross-checks on n ≲ 15; the dual (S10) is what scales (CSAIL's 1045 poses: ``benchmarks/certify.md``).

Dangling chains are peeled first (``lago_cvx.graph.prune_leaves``), which is **exact for both f* and
f_SDP**: a leaf ℓ on edge (i, ℓ) can always be placed with zero residual on that edge — R_ℓ = R_i R̃,
t_ℓ = t_i + R_i t̃ also for the r × 2 Stiefel blocks of any factor Z = YᵀY of the relaxation — so it
changes neither optimum. Dangling chains add n‖M‖ but no cost, and SDP accuracy scales like f/(n‖M‖);
pruning them matters (CSAIL's first 500 poses: 512 edges, core 213 poses).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import OptionError, SolverError
from ..graph import check_connected, prune_leaves
from ..posegraph import PoseGraph
from ..reports import Summary, fmt_timings, short_repr
from ..solvers import OK_STATUSES, SDP, ClarabelSettings, solve
from .certificate import Certificate, certify, dual_lower_bound
from .local import refine_sesync
from .sesync import data_matrix, grounded_index, optimal_translations, rotation_index, sesync_cost

__all__ = ["sdp_relaxation", "round_solution", "SdpResult", "solve_sdp"]

log = logging.getLogger("lago_cvx.certification")


def _translation_scale(M: sp.spmatrix) -> float:
    """Data-only length L for the translation indices of the SDP: L² = mean rotation diagonal of M /
    mean translation diagonal of M, so that the congruence D M D has balanced diagonal blocks
    (≈ √(κ/τ); CSAIL ≈ 9, intel ≈ 1)."""
    d = M.diagonal().reshape(-1, 3)
    rot, tra = float(d[:, 1:].mean()), float(d[:, 0].mean())
    return float(np.sqrt(rot / tra)) if rot > 0 and tra > 0 else 1.0


def sdp_relaxation(graph: PoseGraph, *, form: str = "dual", anchor=None, translation_scale=None):
    """The SDP relaxation of eq. (S9) (``form="primal"``) or its dual eq. (S10) (``form="dual"``) as an
    explicit cvxpy problem; ``problem.value`` is f_SDP (≤ f*) in both forms.

    Gauge: the anchor's translation index is removed (N = 3n − 1 rows and columns), see the module
    docstring. Scaling: translation indices are multiplied by L = ``translation_scale`` (default:
    L² = mean rotation / mean translation diagonal of M), i.e. M' = D M D, Z' = D⁻¹ Z D⁻¹ with D = diag(L on translations, 1 on rotations):
    an exact congruence that keeps Λ̂, the constraints Z_RiRi = I and the objective unchanged, and only
    balances the magnitudes Clarabel sees.

    dual — variable ``lam`` (3n,): Λ_i = [[lam[i], lam[n+i]], [lam[n+i], lam[2n+i]]];
        maximize Σ (lam[i] + lam[2n+i]) subject to ``M' − Λ̂ >> 0`` (N × N; its sparsity is the pose
        graph's, which Clarabel's chordal decomposition exploits; the constraint's dual value is Z').
    primal — variable ``Z`` (N × N, PSD): minimize Σ M' ⊙ Z' subject to Z'[r, r] = 1 and
        Z'[3i+1, 3i+2] = 0 on every rotation block. Dense: only for small graphs (n ≲ 40).

    Returns ``(problem, variables)``; ``variables`` has ``"lam"`` or ``"Z"``, ``"psd"`` (the PSD
    constraint or None), ``"index"`` (N,) the kept indices of 0 … 3n−1, ``"scale"`` (N,) the diagonal
    of D, ``"M"`` M' (sparse N × N) and ``"anchor"``."""
    if form not in ("dual", "primal"):
        raise OptionError(f"unknown form {form!r}; expected 'dual' or 'primal'")
    import cvxpy as cp

    check_connected(graph)
    a = graph.anchor_index(anchor)
    n = graph.n_poses
    M = data_matrix(graph)
    L = _translation_scale(M) if translation_scale is None else float(translation_scale)
    if not L > 0:
        raise OptionError(f"translation_scale must be > 0, got {translation_scale}")
    keep = grounded_index(n, a)
    N = keep.size
    dscale = np.where(keep % 3 == 0, L, 1.0)
    Ms = (sp.diags(dscale) @ M[keep][:, keep] @ sp.diags(dscale)).tocsc()
    Ms = 0.5 * (Ms + Ms.T)
    rot = rotation_index(n)
    r0, r1 = np.searchsorted(keep, rot[:, 0]), np.searchsorted(keep, rot[:, 1])
    variables = {"index": keep, "scale": dscale, "M": Ms, "anchor": a, "r0": r0, "r1": r1, "L": L}
    if form == "dual":
        lam = cp.Variable(3 * n, name="lam")
        # vec(Λ̂) = B·lam (column-major), 4 entries per pose
        flat = np.concatenate([r0 + N * r0, r1 + N * r1, r0 + N * r1, r1 + N * r0])
        which = np.concatenate([np.arange(n), 2 * n + np.arange(n), n + np.arange(n), n + np.arange(n)])
        B = sp.csc_matrix((np.ones(flat.size), (flat, which)), shape=(N * N, 3 * n))
        Lhat = cp.reshape(B @ lam, (N, N), order="F")
        psd = Ms - Lhat >> 0
        problem = cp.Problem(cp.Maximize(cp.sum(lam[:n]) + cp.sum(lam[2 * n:])), [psd])
        variables.update(lam=lam, psd=psd)
    else:
        Z = cp.Variable((N, N), PSD=True, name="Z")
        vecZ = cp.vec(Z, order="F")
        diag_idx = np.concatenate([r0 + N * r0, r1 + N * r1])
        off_idx = r0 + N * r1
        cons = [vecZ[diag_idx] == 1.0, vecZ[off_idx] == 0.0]
        Mc = Ms.tocoo()
        objective = cp.Minimize(Mc.data @ vecZ[Mc.row + N * Mc.col])
        problem = cp.Problem(objective, cons)
        variables.update(Z=Z, psd=None)
    return problem, variables


def round_solution(graph: PoseGraph, Z_rr: np.ndarray, *, anchor=None):
    """Round the rotation block Z_RR ≈ Y_RᵀY_R (2n × 2n, rotation indices in pose order: 2i, 2i+1
    are R_i's columns) of an SDP solution to poses (SE-Sync's rounding, d = 2).

    Y_R = diag(√w₁, √w₂)·[v₁ v₂]ᵀ from the top-2 eigenpairs (2 × 2n); the 2×2 blocks B_i of Y_R are
    O(2) elements times a common G ∈ O(2). If most det(B_i) are negative the second row of Y_R is
    negated (G·diag(1, −1) is an equally valid gauge); each block is then projected to its nearest
    rotation θ_i = atan2(B₁₀ − B₀₁, B₀₀ + B₁₁), the anchor's angle is subtracted, and the
    translations are the optimal ones for these rotations (``optimal_translations``, anchor at the
    origin). Returns ``(poses (n, 3), n_reflected, eigenvalues)``: ``n_reflected`` blocks whose
    determinant has the minority sign (a genuine O(2) \\ SO(2) element), ``eigenvalues`` the three
    largest eigenvalues of Z_RR (rank 2 ⟺ the third is ≈ 0)."""
    n = graph.n_poses
    a = graph.anchor_index(anchor)
    Z_rr = 0.5 * (np.asarray(Z_rr, dtype=float) + np.asarray(Z_rr, dtype=float).T)
    k = min(3, 2 * n)
    if 2 * n <= 400:
        w, V = np.linalg.eigh(Z_rr)
        w, V = w[::-1][:k], V[:, ::-1][:, :k]
    else:
        w, V = spla.eigsh(Z_rr, k=k, which="LA", v0=np.ones(2 * n))
        order = np.argsort(w)[::-1]
        w, V = w[order], V[:, order]
    Yr = (np.sqrt(np.maximum(w[:2], 0.0))[:, None] * V[:, :2].T)  # (2, 2n)
    B = Yr.reshape(2, n, 2).transpose(1, 0, 2)  # B[i] = Y_R[:, 2i:2i+2]
    det = np.linalg.det(B)
    if np.count_nonzero(det < 0) > n / 2:
        B[:, 1, :] *= -1.0
        det = -det
    n_reflected = int(np.count_nonzero(det < 0))
    theta = np.arctan2(B[:, 1, 0] - B[:, 0, 1], B[:, 0, 0] + B[:, 1, 1])
    theta = theta - theta[a]
    poses = np.zeros((n, 3))
    poses[:, 2] = theta
    poses[:, :2] = optimal_translations(graph, theta, anchor=anchor)
    return poses, n_reflected, w


@dataclass(eq=False)
class SdpResult:
    """Outcome of ``solve_sdp``.

    ``value`` f_SDP as reported by Clarabel (a lower bound on f* up to solver accuracy; equal for the
    graph and its 2-core); ``status``
    cvxpy's status; ``form``; ``lower_bound`` a **proven** lower bound on f*: Clarabel's multipliers Λ
    shifted by λ_min(S_Q(Λ)) to exact dual feasibility (eq. (S8)), NaN if not computed;
    ``multipliers`` Λ (n, 2, 2); ``poses`` the rounded solution (n, 3), ``cost_rounded`` f there (an
    upper bound on f*), ``gap`` = (cost_rounded − value)/|value| (signed: a small negative gap is
    solver inaccuracy), ``n_reflected`` rotation blocks of the rank-2 factor with the minority
    determinant sign; ``z_eigenvalues`` the three largest eigenvalues of Z_RR (tight relaxation ⟺
    rank 2 ⟺ the third ≈ 0); ``Z`` the (grounded, unscaled) N × N primal matrix, ``index`` its rows
    in 0 … 3n−1; ``iterations``; ``times`` seconds (``build``, ``solve`` — cvxpy compile + Clarabel,
    ``round``, ``bound``, ``polish``, ``total``); ``n_poses``, ``n_edges`` of the graph, ``n_core`` poses
    of the 2-core the SDP was solved on; ``attempts`` the retry ladder's record; ``primal_value`` tr(MZ) of the
    recovered Z and ``primal_violation`` max_i ‖Z_RiRi − I‖_max (primal–dual consistency: with an
    accurate solve ``primal_value`` ≈ ``value``); with ``polish``: ``cost_polished`` f after
    ``refine_sesync`` from the rounded poses and ``certificate`` (``certify`` there) — SE-Sync's
    pipeline, which makes the answer exact even where the interior-point value is not."""

    value: float
    status: str
    form: str
    lower_bound: float
    multipliers: np.ndarray
    poses: np.ndarray
    cost_rounded: float
    gap: float
    n_reflected: int
    z_eigenvalues: np.ndarray
    Z: np.ndarray
    index: np.ndarray
    iterations: int
    times: dict
    n_poses: int
    n_edges: int
    primal_value: float = float("nan")
    primal_violation: float = float("nan")
    cost_polished: float = float("nan")
    certificate: "Certificate | None" = None
    attempts: list = field(default_factory=list)
    n_core: int = 0

    def __repr__(self) -> str:
        lines = [f"f_SDP = {self.value:.10g} ({self.status}, {self.iterations} iterations); proven f* ≥ "
                 f"{self.lower_bound:.10g}; rounded f = {self.cost_rounded:.10g}, gap {self.gap:.3g}",
                 f"rank: top eigenvalues of Z_RR {', '.join(f'{v:.3g}' for v in np.ravel(self.z_eigenvalues)[:3])}; "
                 f"{self.n_reflected} reflected blocks"]
        if self.certificate is not None:
            lines.append(f"polished f = {self.cost_polished:.10g}: "
                         + ("CERTIFIED" if self.certificate.certified else "NOT certified"))
        lines.append("time " + fmt_timings(self.times))
        return short_repr("SdpResult", f"{self.form} form, {self.n_poses} poses ({self.n_core} in the 2-core), "
                          f"{self.n_edges} edges", lines)

    def summary(self) -> Summary:
        """The relaxation's numbers as a dict that prints as a small table."""
        return Summary("SDP relaxation (SE-Sync (S9)/(S10), Clarabel)", [
            ("n_poses", "poses", self.n_poses), ("n_core", "poses in the 2-core", self.n_core),
            ("form", "form", self.form), ("status", "status", self.status), ("value", "f_SDP", self.value),
            ("lower_bound", "proven f* ≥", self.lower_bound), ("cost_rounded", "f rounded", self.cost_rounded),
            ("gap", "gap (relative)", self.gap), ("n_reflected", "reflected blocks", self.n_reflected),
            ("cost_polished", "f polished", self.cost_polished),
            ("certified", "polished certified", None if self.certificate is None else bool(self.certificate.certified)),
        ], timings=self.times)


def solve_sdp(graph: PoseGraph, *, form: str = "dual", settings: ClarabelSettings | None = None, anchor=None,
              translation_scale=None, prune: bool = True, lower_bound: bool = True, polish: bool = False,
              retries: bool = True) -> SdpResult:
    """Build (``sdp_relaxation``) and solve the SDP relaxation with Clarabel (``settings`` over the preset
    ``lago_cvx.solvers.SDP``), recover Z (dual form: the PSD constraint's dual value, PSD-completed by
    Clarabel) and Λ (primal form: Λ_i = sym([M Z]_{R_i R_i}), complementary slackness (M − Λ̂)Z = 0),
    round Z to poses (``round_solution``), if ``lower_bound`` make Λ exactly dual feasible, and if
    ``polish`` refine the rounded poses (``refine_sesync``) and ``certify`` them. With ``prune`` (default)
    the SDP is solved on the 2-core (``prune_leaves``: exact) and the rounded poses are extended to the
    whole graph; ``Z``, ``index`` and ``multipliers`` then refer to the core graph. ``anchor`` is a pose
    id (default the smallest).

    Accuracy: an interior-point method resolves M − Λ̂ ⪰ 0 to ~1e-9‖M‖, so f_SDP is known to about
    2n·1e-9·‖M‖ absolutely; when f* ≪ n‖M‖ (low-noise real data: CSAIL has κ up to 1e4 and f* = 31.7)
    the relative accuracy of ``value`` is correspondingly limited, while ``cost_rounded`` (a feasible
    point) is exact. Near that accuracy floor Clarabel sometimes stops with a numerical error; with
    ``retries`` the solve is repeated with L = 1, then with the (slower, ≈ 4×) non-compact chordal
    transformation (``SdpResult.attempts`` lists what was tried). Raises ``SolverError`` if every
    attempt fails."""
    from dataclasses import replace

    t_all = time.perf_counter()
    times = {"build": 0.0, "solve": 0.0}
    full = graph
    pruning = prune_leaves(graph, anchor=anchor) if prune else None
    if pruning is not None:
        graph = pruning.core
        log.info("SDP: 2-core has %d of %d poses", graph.n_poses, full.n_poses)
    ladder = [(translation_scale, {})]
    if retries:
        ladder += [(1.0, {}), (translation_scale, {"chordal_decomposition_compact": False})]
    attempts = []
    for scale, extra in ladder:
        t = time.perf_counter()
        problem, var = sdp_relaxation(graph, form=form, anchor=anchor, translation_scale=scale)
        times["build"] += time.perf_counter() - t
        t = time.perf_counter()
        try:  # an inaccurate solve is logged below at INFO: near the accuracy floor it is the rule
            status = solve(problem, settings, preset=replace(SDP, **extra), what="the SDP relaxation",
                           allow=OK_STATUSES)
        except SolverError as exc:
            status = exc.status or "solver_error"
        times["solve"] += time.perf_counter() - t
        attempts.append({"translation_scale": var["L"], "settings": extra, "status": status,
                         "time": time.perf_counter() - t})
        if status in OK_STATUSES:
            break
        log.warning("Clarabel: SDP attempt with L = %.3g, %s ended with %s", var["L"], extra or "defaults", status)
    else:
        raise SolverError(f"Clarabel did not solve the SDP relaxation ({len(attempts)} attempt(s): "
                          + ", ".join(a_["status"] for a_ in attempts) + ")", attempts[-1]["status"])
    if problem.status == "optimal_inaccurate":
        log.info("Clarabel: inaccurate SDP solution (status %s)", problem.status)
    n, a = graph.n_poses, var["anchor"]
    d = var["scale"]
    r0, r1 = var["r0"], var["r1"]
    if form == "dual":
        Zs = np.asarray(var["psd"].dual_value)
        x = np.asarray(var["lam"].value)
        lam = np.empty((n, 2, 2))
        lam[:, 0, 0], lam[:, 0, 1], lam[:, 1, 0], lam[:, 1, 1] = x[:n], x[n:2 * n], x[n:2 * n], x[2 * n:]
    else:
        Zs = np.asarray(var["Z"].value)
        MZ = var["M"] @ Zs  # (N, N) dense
        lam = np.empty((n, 2, 2))
        lam[:, 0, 0], lam[:, 1, 1] = MZ[r0, r0], MZ[r1, r1]
        lam[:, 0, 1] = lam[:, 1, 0] = 0.5 * (MZ[r0, r1] + MZ[r1, r0])
    Zs = 0.5 * (Zs + Zs.T)
    Z = Zs * d[:, None] * d[None, :]
    t = time.perf_counter()
    rr = np.column_stack([r0, r1]).reshape(-1)
    poses, n_reflected, w = round_solution(graph, Z[np.ix_(rr, rr)], anchor=int(graph.ids[a]))
    if pruning is not None:
        poses = pruning.extend(poses)
    cost_rounded = sesync_cost(full, poses)
    times["round"] = time.perf_counter() - t
    t = time.perf_counter()
    lb = dual_lower_bound(graph, lam, a) if lower_bound else float("nan")
    times["bound"] = time.perf_counter() - t
    value = float(problem.value)
    den = max(abs(value), abs(cost_rounded))
    gap = (cost_rounded - value) / den if den > 1e-12 else 0.0  # both ≈ 0 (e.g. a tree): no gap
    Mg = data_matrix(graph)[var["index"]][:, var["index"]]
    primal_value = float(np.sum(Mg.multiply(Z)))
    blocks = Z[np.ix_(rr, rr)].reshape(n, 2, n, 2)[np.arange(n), :, np.arange(n), :]
    primal_violation = float(np.abs(blocks - np.eye(2)).max())
    cost_polished, cert = float("nan"), None
    if polish:
        t = time.perf_counter()
        pol = refine_sesync(full, poses, anchor=graph.ids[a])
        cost_polished = pol.cost
        cert = certify(full, pol.poses, anchor=graph.ids[a], full=False)
        times["polish"] = time.perf_counter() - t
    stats = problem.solver_stats
    times["total"] = time.perf_counter() - t_all
    log.info("SDP (%s form, %d poses): f_SDP = %.10g, rounded f = %.10g, gap %.2g, %.2f s", form, n, value,
             cost_rounded, gap, times["total"])
    return SdpResult(value=value, status=problem.status, form=form, lower_bound=lb, multipliers=lam, poses=poses,
                     cost_rounded=cost_rounded, gap=gap, n_reflected=n_reflected, z_eigenvalues=w, Z=Z,
                     index=var["index"], iterations=int(getattr(stats, "num_iters", 0) or 0), times=times,
                     n_poses=full.n_poses, n_edges=full.n_edges, primal_value=primal_value,
                     primal_violation=primal_violation, cost_polished=cost_polished, certificate=cert,
                     attempts=attempts, n_core=graph.n_poses)

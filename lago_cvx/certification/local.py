r"""A local solver for the SE-Sync cost (eq. (S1) of ``sesync.py``): Gauss–Newton, or Newton where it
descends, with a backtracking line search.

Gauss–Newton on (x, y, θ) per pose (the anchor fixed), with residuals whose squares sum to f::

    r_t = √τ (t_j − t_i − R_i t̃)  (2,),     r_R = √(8κ) sin(e/2),  e = wrap(θ_j − θ_i − δ)        (S3)

(r_R² = 4κ(1 − cos e)). Jacobian, with v = R_i t̃ and S = [[0, −1], [1, 0]]:
∂r_t/∂t_j = √τ I, ∂r_t/∂t_i = −√τ I, ∂r_t/∂θ_i = −√τ S v = √τ (v_y, −v_x);
∂r_R/∂θ_j = −∂r_R/∂θ_i = √(2κ) cos(e/2). Eight entries per edge, one sparse J (3m × 3(n−1)),
normal equations JᵀJ dx = −Jᵀr by ``lago_cvx.sparse.linalg.factorize``; a backtracking line search makes f
monotone. Reached from the χ²-refined LAGO estimate: manhattan 6431.39, city10000 638.625, CSAIL
31.7037, intel 52.3482 — SE-Sync's Table 1 (4 digits) for city10000, CSAIL and intel; manhattan's
6431.39 prints as 6.431e3 against Table 1's 6.432e3 (one unit of the last digit, 9e-5 relative; certified
optimal for eq. (S1) on the file, see benchmarks/certify.md).

GN converges only linearly here when the neglected curvature Σ r∇²r is not small (intel: rate ≈ 0.74,
21 iterations from the start refined in g2o's χ² to a relative decrease of 1e-12; Newton: 4).
``method="newton"`` adds it — it has only θ–θ entries::

    ½∇²f = JᵀJ + C,  C[θ_i, θ_i] += τ (t_j − t_i − R_i t̃)·(R_i t̃),
                     C[(θ_i, θ_j)] += −2κ sin²(e/2)·[[1, −1], [−1, 1]]                               (S3')

(from ∂²(R_i t̃)/∂θ_i² = −R_i t̃ and ∂²(4κ(1 − cos e)) = 4κ cos e = 2(√(2κ)cos(e/2))² − 4κ sin²(e/2)),
and takes the Newton step whenever it is a descent direction (else the GN step); 3–4 iterations on the
SE-Sync datasets.

"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import OptionError
from ..sparse import factorize
from ..posegraph import PoseGraph
from ..refinement import prepare, small_step
from ..reports import Summary, short_repr
from .sesync import edge_residuals, sesync_weights

__all__ = ["SESYNC_METHODS", "SesyncRefineResult", "refine_sesync"]

log = logging.getLogger("lago_cvx.certification")


#: Maximum number of step halvings of the backtracking line search of ``refine_sesync``.
MAX_HALVINGS = 20
# A step with ‖dx‖∞ ≤ STEP_TOLERANCE·(1 + ‖x‖∞) counts as converged (``lago_cvx.refinement.small_step``).


@dataclass(eq=False)
class SesyncRefineResult:
    """Outcome of ``refine_sesync``: ``poses`` (n, 3) (θ unwrapped), ``cost`` f of eq. (S1) there and
    ``cost_initial`` at the start; ``iterations`` accepted GN steps; ``converged`` and ``reason``;
    ``gradient_norm`` ‖∇f‖∞ = ‖2Jᵀr‖∞ at the last linearization (the point before the last step); ``anchor`` the fixed
    pose's id; ``log`` one dict per iteration (``iteration``, ``cost``, ``step_norm``, ``halvings``,
    ``time``); ``time`` seconds."""

    poses: np.ndarray
    cost: float
    cost_initial: float
    iterations: int
    converged: bool
    reason: str = ""
    gradient_norm: float = float("nan")
    anchor: int = 0
    log: list = field(default_factory=list)
    time: float = 0.0

    def __repr__(self) -> str:
        return short_repr("SesyncRefineResult", f"{self.poses.shape[0]} poses: f {self.cost_initial:.10g} → "
                          f"{self.cost:.10g} (SE-Sync cost)", [
                              f"{self.iterations} iterations, {'converged' if self.converged else 'not converged'}"
                              f"{': ' + self.reason if self.reason else ''}; ‖∇f‖∞ = {self.gradient_norm:.3g}; "
                              f"anchor pose {self.anchor}; time {self.time:.3g} s"])

    def summary(self) -> Summary:
        """The refinement's numbers as a dict that prints as a small table."""
        return Summary("SE-Sync refinement (Newton / Gauss–Newton on f)", [
            ("n_poses", "poses", int(self.poses.shape[0])), ("cost_initial", "f at the start", self.cost_initial),
            ("cost", "f at the end", self.cost), ("iterations", "iterations", self.iterations),
            ("converged", "converged", bool(self.converged)), ("reason", "reason", self.reason),
            ("gradient_norm", "‖∇f‖∞", self.gradient_norm), ("anchor", "anchor pose", self.anchor),
        ], timings={"total": self.time})


class _SesyncProblem:
    """Residuals (S3) and their Jacobian with a fixed sparsity pattern (8 entries per edge)."""

    def __init__(self, graph: PoseGraph, anchor: int):
        n, m = graph.n_poses, graph.n_edges
        self.graph, self.n, self.m, self.anchor = graph, n, m, anchor
        kappa, tau = sesync_weights(graph)
        self.sqrt_tau = np.sqrt(tau)
        self.sqrt_8kappa = np.sqrt(8.0 * kappa)
        col = np.arange(3 * n).reshape(n, 3)
        col = np.where(np.arange(n)[:, None] > anchor, col - 3, col)
        col[anchor] = -1
        self.free = np.ones(n, bool)
        self.free[anchor] = False
        i, j = graph.tails, graph.heads
        k3 = 3 * np.arange(m)
        # entry order: (row, column) for the 8 derivatives listed in the module docstring
        rows = np.column_stack([k3, k3, k3, k3 + 1, k3 + 1, k3 + 1, k3 + 2, k3 + 2])
        cols = np.column_stack([col[i, 0], col[i, 2], col[j, 0], col[i, 1], col[i, 2], col[j, 1],
                                col[i, 2], col[j, 2]])
        keep = cols >= 0
        self.keep = keep.reshape(-1)
        self.rows = rows.reshape(-1)[self.keep]
        self.cols = cols.reshape(-1)[self.keep]
        self.dim = 3 * (n - 1)
        self.col_theta = col[:, 2]

    def residuals(self, poses: np.ndarray):
        d, v, e = edge_residuals(self.graph, poses)
        r = np.empty((self.m, 3))
        r[:, :2] = self.sqrt_tau[:, None] * d
        r[:, 2] = self.sqrt_8kappa * np.sin(0.5 * e)
        return r, v, e

    def cost(self, poses: np.ndarray) -> float:
        r = self.residuals(poses)[0]
        return float(np.einsum("ka,ka->", r, r))

    def linearize(self, poses: np.ndarray):
        r, v, e = self.residuals(poses)
        st = self.sqrt_tau
        dR = 0.5 * self.sqrt_8kappa * np.cos(0.5 * e)  # = √(2κ) cos(e/2)
        vals = np.column_stack([-st, st * v[:, 1], st, -st, -st * v[:, 0], st, -dR, dR]).reshape(-1)[self.keep]
        J = sp.csr_matrix((vals, (self.rows, self.cols)), shape=(3 * self.m, self.dim))
        return r.reshape(-1), J

    def curvature(self, poses: np.ndarray) -> sp.csr_matrix:
        """½Σ r_k ∇²r_k (3(n−1) square, sparse): what the exact Hessian ½∇²f adds to JᵀJ (eq. (S3')).

        Only θ–θ entries: τ d·v on (θ_i, θ_i) from ∂²d/∂θ_i² = v, and −2κ sin²(e/2)·[[1, −1], [−1, 1]]
        on (θ_i, θ_j) from ∂²(4κ(1 − cos e)) = 4κ cos e = 2(√(2κ)cos(e/2))² − 4κ sin²(e/2)."""
        d, v, e = edge_residuals(self.graph, poses)
        tau = self.sqrt_tau ** 2
        w = -0.25 * self.sqrt_8kappa ** 2 * np.sin(0.5 * e) ** 2  # −2κ sin²(e/2)
        ci, cj = self.col_theta[self.graph.tails], self.col_theta[self.graph.heads]
        rows = np.concatenate([ci, ci, cj, ci, cj])
        cols = np.concatenate([ci, ci, cj, cj, ci])
        vals = np.concatenate([tau * np.einsum("ka,ka->k", d, v), w, w, -w, -w])
        keep = (rows >= 0) & (cols >= 0)
        return sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(self.dim, self.dim))

    def update(self, poses: np.ndarray, dx: np.ndarray) -> np.ndarray:
        new = poses.copy()
        new[self.free] += dx.reshape(-1, 3)
        return new


def _newton_step(H: sp.spmatrix, g: np.ndarray, backend: str):
    """Newton step −H⁻¹g with the exact (½-scaled) Hessian H, or None when H cannot be factored or the
    step is not a descent direction (H indefinite away from a minimum)."""
    try:
        dx = -factorize(sp.csc_matrix(H), backend=backend).solve(g)
    except (RuntimeError, ValueError):
        return None
    if not np.isfinite(dx).all() or not float(g @ dx) < 0.0:
        return None
    return dx


#: Accepted values of ``refine_sesync(method=...)``.
SESYNC_METHODS = ("gauss-newton", "newton")


def refine_sesync(graph: PoseGraph, poses, *, max_iterations: int = 50, tolerance: float = 1e-12,
                  anchor=None, method: str = "gauss-newton", backend: str = "auto") -> SesyncRefineResult:
    """Minimise the SE-Sync cost f of eq. (S1) from ``poses`` (n, 3) by Gauss–Newton on the residuals (S3).

    Keyword-only: ``max_iterations`` GN iterations; ``tolerance`` stop when the relative decrease of f
    in an iteration is below it; ``anchor`` id of the pose held fixed (default the smallest id);
    ``method`` ``"gauss-newton"`` (default) or ``"newton"`` (exact Hessian of eq. (S3') whenever its step
    is a descent direction, else the GN step: quadratic instead of linear convergence near a minimum);
    ``backend`` sparse solver (``lago_cvx.sparse.linalg.factorize``). Each iteration factors JᵀJ
    (3(n−1) square, sparse); a step that does not decrease f is halved (at most ``MAX_HALVINGS``
    times), so f never increases. Raises ``GraphError`` for a disconnected graph."""
    if method not in SESYNC_METHODS:
        raise OptionError(f"unknown method {method!r}; expected one of {SESYNC_METHODS}")
    x, a = prepare(graph, poses, anchor=anchor, max_iterations=max_iterations, tolerance=tolerance)
    t0 = time.perf_counter()
    prob = _SesyncProblem(graph, a)
    f = prob.cost(x)
    res = SesyncRefineResult(poses=x, cost=f, cost_initial=f, iterations=0, converged=False, anchor=int(graph.ids[a]),
                             log=[{"iteration": 0, "cost": f, "step_norm": 0.0, "halvings": 0, "time": 0.0}],
                             reason="max_iterations reached")
    if prob.dim == 0 or graph.n_edges == 0:
        res.converged, res.reason = True, "nothing to optimize"
        return res
    tiny = np.finfo(float).tiny
    for it in range(1, max_iterations + 1):
        r, J = prob.linearize(x)
        Jt = J.T.tocsr()
        g = Jt @ r
        res.gradient_norm = float(np.max(np.abs(2.0 * g)))  # ∇f = 2Jᵀr
        H = (Jt @ J).tocsc()
        dx = None
        if method == "newton":
            dx = _newton_step(H + prob.curvature(x), g, backend)
        if dx is None:
            try:
                dx = -factorize(H, backend=backend).solve(g)
            except RuntimeError as exc:
                res.reason = f"singular normal equations ({exc})"
                break
        if not np.isfinite(dx).all():
            res.reason = "non-finite Gauss-Newton step (singular normal equations)"
            break
        step = float(np.max(np.abs(dx)))
        if small_step(dx, x):
            res.converged, res.reason = True, f"step norm {step:.3g} below tolerance"
            break
        predicted = -float(g @ dx)  # ‖r‖² − ‖r + J dx‖² = −gᵀdx for the GN step
        alpha, halvings = 1.0, 0
        new = prob.update(x, dx)
        f_new = prob.cost(new)
        while not f_new <= f and halvings < MAX_HALVINGS:
            halvings += 1
            alpha *= 0.5
            new = prob.update(x, alpha * dx)
            f_new = prob.cost(new)
        if not f_new <= f:
            res.converged = predicted <= 10.0 * max(tolerance, 1e-15) * max(f, tiny)
            res.reason = ("no further decrease (stationary to working precision)" if res.converged else
                          f"line search failed after {halvings} halvings (predicted decrease {predicted:.3g})")
            break
        rel = (f - f_new) / max(f, tiny)
        x, f = new, f_new
        res.iterations += 1
        res.log.append({"iteration": res.iterations, "cost": f, "step_norm": alpha * step, "halvings": halvings,
                        "time": time.perf_counter() - t0})
        log.info("SE-Sync GN iteration %d: f = %.12g, |dx| = %.3g, halvings %d", res.iterations, f, alpha * step,
                 halvings)
        if rel < tolerance:
            res.converged, res.reason = True, "relative decrease below tolerance"
            break
    res.poses, res.cost = x, f
    res.time = time.perf_counter() - t0
    log.info("refine_sesync: f %.10g → %.10g in %d steps, %.3f s; %s", res.cost_initial, f, res.iterations,
             res.time, res.reason)
    return res

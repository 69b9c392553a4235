r"""What ``refine`` adds to the nonlinear least squares of ``lago_cvx.refinement`` for the variants: priors
(full or on part of a pose), convex constraints kept feasible at every step, and the marginal covariances of
the refined problem. Notation as in ``lago_cvx.refinement``: unknowns the d = 3n − |K| coordinates not held
(pose-major order), r the whitened edge residuals (3m,), J their Jacobian (3m, d).

Priors (R1). A prior q on pose v measures the components k_q ⊆ {x, y, θ} (all three, the position
(x, y) — a GPS fix — or θ alone; ``lago_cvx.variants.normalize_priors``) with information Λ_q (|k_q| × |k_q|,
SPD) and mean μ_q. Its error e_q = (x_v − μ_q)[k_q], θ wrapped to (−π, π]; with the upper Cholesky factor
U_q (U_qᵀU_q = Λ_q) its whitened residual is r_q = U_q e_q and its χ² term r_qᵀr_q = e_qᵀΛ_q e_q (no ½, as
every χ² here). ∂r_q/∂x_v[k_q] = U_q (the wrap is piecewise constant): one dense |k_q|×|k_q| block per
prior, on the columns of pose v not held. The problem becomes

    minimise  ‖r(x)‖² + Σ_q ‖r_q(x)‖²  =  ‖r̄(x)‖²,   r̄ = [r; r_1; …; r_Q],   J̄ = [J; J_1; …; J_Q],

and Gauss–Newton / Levenberg–Marquardt run on (r̄, J̄) unchanged (``PriorProblem`` wraps the edge
problem). The gauge: priors fix it as anchors do (``refinement.held_coordinates``): a position prior
fixes the translation, a θ prior the rotation, two distinct known positions (anchors or priors) the
rotation too; what is left open is held at the reference pose.

Convex constraints (R2). A constraint function f(pv) receives ``PoseVariables`` whose ``x``, ``y``,
``theta`` (n,) are the affine cvxpy expressions x_k + S dx of the poses after the step dx (S the (3n × d)
selector of the coordinates not held; held entries constant). Each Gauss–Newton step is the convex problem

    minimise_dx  ‖r̄ + J̄ dx‖²     subject to  f(x_k + S dx)                                  (R2)

(``cp.sum_squares``, one second-order cone for Clarabel, whose relative gap is then measured against χ²
itself, not against the vanishing model decrease of the last steps; the ``ROBUST`` preset's 1e-9
tolerances, since a conic problem with inequalities cannot reach ``LEAST_SQUARES``' 1e-12), then a
backtracking line search
x_{k+1} = x_k + α dx, α = 1, ½, …: when x_k and x_k + dx are feasible so is every point between them
(the feasible set is convex), so every iterate is feasible. A start outside the feasible set takes the
first step in full (it lands in the set) and logs it.

Covariances (R3). The marginal 3×3 covariance of pose v at the refined estimate x̂ is the (v, v) block
of (J̄ᵀJ̄)⁻¹ at x̂ — the inverse Gauss–Newton Hessian of the refined problem, priors included — over the
coordinates not held (held ones: rows and columns zero), by selected inversion
(``lago_cvx.variants.engine.known_blocks``). With constraints, the Hessian is the unconstrained one at
x̂: an active inequality makes the true posterior truncated, and that is not modelled (the blocks are
then an upper bound in the Loewner order for the directions the constraint cuts).
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp

from .errors import OptionError, SolverError
from .posegraph import wrap_angle
from .variants.anchors import normalize_priors
from .variants.constraints import PoseVariables, collect_constraints
from .variants.engine import known_blocks

__all__ = ["PriorProblem", "constrained_gauss_newton", "pose_covariances", "FEASIBILITY_TOLERANCE"]

log = logging.getLogger("lago_cvx.refinement")

#: A start whose constraint violation exceeds this is outside the feasible set (R2).
FEASIBILITY_TOLERANCE = 1e-7


class PriorProblem:
    """The edge problem ``base`` (a ``refinement`` problem: ``linearize``, ``chi2``, ``update``, ``dim``,
    ``held``, ``col``) with the prior residuals (R1) stacked under the edge residuals."""

    def __init__(self, base, priors: list):
        self.base = base
        self.dim, self.held, self.col = base.dim, base.held, base.col
        self.priors = priors
        rows, cols, vals, self._u, self._comp, self._mean, self._pose = [], [], [], [], [], [], []
        row = 0
        for p in priors:  # loop over priors (few)
            comp = np.flatnonzero(p.known)
            U = np.linalg.cholesky(p.information[np.ix_(comp, comp)]).T  # UᵀU = Λ_q
            c = base.col[p.index, comp]
            for a in range(comp.size):
                keep = c >= 0
                rows.extend([row + a] * int(keep.sum()))
                cols.extend(c[keep])
                vals.extend(U[a, keep])
            self._u.append(U)
            self._comp.append(comp)
            self._mean.append(p.mean[comp])
            self._pose.append(p.index)
            row += comp.size
        self.rows = row
        self.J_prior = sp.csr_matrix((vals, (rows, cols)), shape=(row, self.dim))

    def prior_residuals(self, poses: np.ndarray) -> np.ndarray:
        """r_q = U_q e_q stacked, shape (Σ|k_q|,)."""
        out = []
        for U, comp, mu, v in zip(self._u, self._comp, self._mean, self._pose):
            e = poses[v, comp] - mu
            if comp[-1] == 2:
                e[-1] = wrap_angle(e[-1])
            out.append(U @ e)
        return np.concatenate(out) if out else np.zeros(0)

    def chi2(self, poses: np.ndarray) -> float:
        rp = self.prior_residuals(poses)
        return self.base.chi2(poses) + float(rp @ rp)

    def linearize(self, poses: np.ndarray):
        """r̄ (3m + Σ|k_q|,) and J̄ (·, d) CSR (R1)."""
        r, J = self.base.linearize(poses)
        return np.concatenate([r, self.prior_residuals(poses)]), sp.vstack([J, self.J_prior], format="csr")

    def update(self, poses: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return self.base.update(poses, dx)


def with_priors(base, graph, priors):
    """``PriorProblem`` of ``base`` and the normalized ``priors`` ({id: (mean, information)}, as in ``lago``)."""
    return PriorProblem(base, normalize_priors(graph, priors))


def prior_positions(graph, priors) -> tuple[list, list]:
    """(pose indices with a position prior, their means (2,)) and (indices with a θ prior) — what fixes the
    gauge as position / orientation anchors would."""
    pri = normalize_priors(graph, priors)
    pos = [(p.index, p.mean[:2]) for p in pri if p.has_position]
    return pos, [p.index for p in pri if p.has_theta]


# ------------------------------------------------------------------------------ constraints (R2)
def _selector(held: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
    """S_x, S_y, S_θ (n × d): coordinate c of every pose from the unknown vector dx."""
    n = held.shape[0]
    free = ~held.reshape(-1)
    d = int(free.sum())
    col = np.full(3 * n, -1, np.int64)
    col[free] = np.arange(d)
    col = col.reshape(n, 3)
    out = []
    for c in range(3):
        rows = np.flatnonzero(col[:, c] >= 0)
        out.append(sp.csr_matrix((np.ones(rows.size), (rows, col[rows, c])), shape=(n, d)))
    return tuple(out)


def _violation(named: list) -> float:
    v = [float(np.max(np.atleast_1d(k.violation()), initial=0.0)) for c in named for k in c.constraints]
    return max(v, default=0.0)


def constrained_gauss_newton(graph, prob, res, constraints, max_iterations: int, tol: float, t0: float,
                             solver_settings=None) -> None:
    """Gauss–Newton with each step the convex problem (R2), solved by Clarabel; fills ``res`` (a
    ``RefineResult``) as ``refinement``'s solvers do. Raises ``InfeasibleConstraintsError`` naming the
    constraints when a step problem is infeasible."""
    import cvxpy as cp

    from .solvers import INFEASIBLE_STATUSES, ROBUST, solve
    from .variants.constraints import diagnose

    Sx, Sy, St = _selector(prob.held)
    dx = cp.Variable(prob.dim, name="dx")
    x = res.poses
    res.reason = "max_iterations reached"
    chi = res.chi2
    for it in range(1, max_iterations + 1):
        r, J = prob.linearize(x)
        H = (J.T @ J).tocsc()
        g = J.T @ r
        pv = PoseVariables(graph, "refine", dx, x[:, 2].copy(),
                           exprs=(x[:, 0] + Sx @ dx, x[:, 1] + Sy @ dx, x[:, 2] + St @ dx))
        named = collect_constraints(constraints, pv, "refine")
        cons = [k for c in named for k in c.constraints]
        dx.value = np.zeros(prob.dim)
        outside = _violation(named) > FEASIBILITY_TOLERANCE
        problem = cp.Problem(cp.Minimize(cp.sum_squares(J @ dx + r)), cons)
        status = solve(problem, solver_settings, preset=ROBUST, what=f"refine step {it}", allow=INFEASIBLE_STATUSES)
        if status in INFEASIBLE_STATUSES:
            diagnose(f"refine step {it}", [], named, lambda p: solve(p, solver_settings, preset=ROBUST, what="refine",
                                                                      allow=INFEASIBLE_STATUSES))
        if dx.value is None:
            raise SolverError(f"refine step {it}: Clarabel returned no step", str(status))
        step_dx = np.asarray(dx.value, dtype=float)
        step = float(np.max(np.abs(step_dx), initial=0.0))
        predicted = -float(g @ step_dx) - 0.5 * float(step_dx @ (H @ step_dx))
        alpha, halvings = 1.0, 0
        new = prob.update(x, step_dx)
        chi_new = prob.chi2(new)
        if outside:
            log.info("refine: the start violates the constraints by %.3g; the first step is taken in full",
                     _violation(named))
        else:
            while not chi_new < chi and halvings < 10:
                halvings += 1
                alpha *= 0.5
                new = prob.update(x, alpha * step_dx)
                chi_new = prob.chi2(new)
        entry = {"iteration": res.iterations, "chi2": chi, "step_norm": alpha * step,
                 "time": time.perf_counter() - t0, "halvings": halvings}
        if not outside and not chi_new < chi:
            res.log.append(entry)
            res.converged = predicted <= 1e3 * max(tol, 1e-9) * max(chi, np.finfo(float).tiny)
            res.reason = ("no further decrease (stationary to the step solver's precision)" if res.converged else
                          f"line search failed (predicted decrease {predicted:.3g})")
            break
        rel = (chi - chi_new) / max(chi, np.finfo(float).tiny)
        x, chi = new, chi_new
        res.iterations += 1
        entry.update(iteration=res.iterations, chi2=chi)
        res.log.append(entry)
        log.info("constrained GN iteration %d: χ² = %.10g, |dx| = %.3g", res.iterations, chi, alpha * step)
        if not outside and (0 <= rel < tol or step <= 1e-12 * (1 + float(np.max(np.abs(x))))):
            res.converged, res.reason = True, "relative χ² decrease below tolerance"
            break
    res.poses, res.chi2, res.backend = x, chi, "clarabel (cvxpy)"
    res.constraint_names = [c.name for c in named] if max_iterations else []


# ------------------------------------------------------------------------------ covariances (R3)
def pose_covariances(prob, poses: np.ndarray) -> np.ndarray:
    """(n, 3, 3) marginal covariances of (x, y, θ) of every pose at ``poses``: the diagonal blocks of
    (J̄ᵀJ̄)⁻¹ (R3), rows and columns of held coordinates zero."""
    n = prob.held.shape[0]
    if prob.dim == 0:
        return np.zeros((n, 3, 3))
    _, J = prob.linearize(poses)
    H = (J.T @ J).tocsc()
    try:
        return known_blocks(H, prob.held.reshape(-1), np.arange(3 * n).reshape(n, 3))
    except Exception as exc:  # a singular Hessian: the refined problem leaves a direction free
        raise OptionError(f"pose_covariances: the refined problem's Hessian is singular ({exc})") from None

r"""Refinement in space with anchors, priors and rotation constraints, and the covariances of the refined problem
(what ``lago_cvx.refine`` runs on a 3-D graph; ``refine3d`` is its old name).

The unknowns: a restricted tangent step
=======================================
A step moves pose i on the right, R_i ← R_i Exp(δφ_i), t_i ← t_i + R_i δv_i (``gauss_newton``), δ_i = (δv_i, δφ_i) ∈
ℝ⁶. Each pose's step is restricted to a subspace, δ_i = B_i ξ_i with B_i = blkdiag(B_i^t, B_i^r) (6 × k_i,
orthonormal columns), and the unknowns are ξ = (ξ_1, …, ξ_n) (d = Σ k_i, pose-major):

* an **anchor** {id: (t, R)} holds what it gives: B^t = ∅ (3 × 0) for a known position, B^r = ∅ for a known
  rotation (either may be None: a partial anchor); the pose is set to the given values first;
* a **rotation constraint** R_i a = b (``space.constraints``) allows δφ_i ∥ a only, B^r = a: the constraint then
  holds exactly at every iterate (R_i is projected onto it first, eq. (PC));
* the **gauge** the anchors and priors leave open is held at the reference pose (``anchor``, default the smallest
  id): its position when no position is known (anchor or prior); its rotation when no rotation is known and the
  known positions and the constraints' world directions b span no two directions — entirely when they span none,
  about their one direction u otherwise (B^r ⊥ R_refᵀ u): a global rotation about u is then the only rotation
  that leaves the data, the priors and the constraints unchanged.

The cost
========
χ̄² = Σ_edges eᵀΩe (the graph's cost, ``posegraph3d``) + Σ_priors e_qᵀΛ_q e_q, a prior q on pose v being
{id: (t̄ or None, R̄ or None, Λ)} with error e_q = t_v − t̄ (position, world frame), Log(R̄ᵀR_v) (rotation) or both
stacked (Λ 6×6, position first), of Jacobians ∂(t_v − t̄)/∂δv_v = R_v and ∂Log(R̄ᵀR_v)/∂δφ_v = J_r⁻¹ (SO(3)'s
inverse right Jacobian, the rotation block of ``so3.right_jacobian_inverse``). With the whitened residuals
r̄ = [L e; U_q e_q] (LᵀL = Ω, U_qᵀU_q = Λ_q) and J̄ their Jacobian in ξ (the edge blocks of ``gauss_newton``
times B), Gauss–Newton solves (J̄ᵀJ̄) ξ = −J̄ᵀr̄; Levenberg–Marquardt damps it (``refine3d``). Without anchors,
priors and constraints the step is the one of the closed forms' pose-level elimination (``gauss_newton_step``).

Covariances
===========
The Laplace approximation at the refined poses: Σ = B (J̄ᵀJ̄)⁻¹ Bᵀ in the coordinates δ = (δv, δφ) of every pose —
translation first, in the pose's own frame, as ``covariance.pose_covariances3d`` — zero in the held directions.
Its 6×6 diagonal blocks by selected inversion of N̄ = P F P + (I − P), F = J̄_δᵀJ̄_δ in all 6n coordinates and
P = BBᵀ the projector onto the allowed steps: N̄⁻¹ = B (BᵀFB)⁻¹ Bᵀ + (I − P), whose blocks less (I − P)_ii are Σ_ii.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..conventions import REFINE_MAX_ITERATIONS, REFINE_METHOD, REFINE_TOLERANCE
from ..errors import OptionError, check_choice
from ..reports import refine_repr, refine_summary
from ..posegraph3d import chi2_3d
from ..so3 import exp_so3, log_so3, right_jacobian_inverse
from .blocks import edge_matrix
from .constraints import check_rotation_constraints, constraint_violation, project_constrained
from .fixed import check_fixed
from .gauss_newton import gauss_newton_step, jacobians, normal_equations, whitening

__all__ = ["REFINE_METHODS", "STEP_TOLERANCE", "MAX_HALVINGS", "Refine3DResult", "Refined3D", "refine_space",
           "Problem3D", "check_anchors3d", "check_priors3d", "estimate3d", "refine3d"]

log = logging.getLogger("lago_cvx.refinement")

REFINE_METHODS = ("gauss-newton", "levenberg-marquardt")
#: A step with max|ξ| ≤ STEP_TOLERANCE·(1 + max|t|) counts as no further change (the planar rule).
STEP_TOLERANCE = 1e-12
#: Step halvings of the Gauss–Newton line search (as the planar one).
MAX_HALVINGS = 10


def estimate3d(estimate):
    """(t (n, 3), R (n, 3, 3)) of a 3-D estimate: a pair (t, R), or anything with ``t`` and ``R`` (a
    ``Lago3DResult``, a refined result, a certificate, a synthetic world); ``OptionError`` otherwise."""
    if hasattr(estimate, "t") and hasattr(estimate, "R"):
        return estimate.t, estimate.R
    if isinstance(estimate, (tuple, list)) and len(estimate) == 2:
        return estimate
    raise OptionError("a 3-D estimate is a pair (t (n, 3), R (n, 3, 3)) or a result with t and R (lago's, "
                      f"refine's); got {type(estimate).__name__}")


def check_anchors3d(graph, anchors) -> list:
    """[(index, t (3,) or None, R (3, 3) or None)] of ``{id: (t, R)}`` (either may be None: a partial anchor)."""
    out = []
    for pid, value in (anchors or {}).items():
        try:
            t, R = value
        except (TypeError, ValueError):
            raise OptionError(f"anchor {pid}: expected (t (3,) or None, R (3, 3) or None)") from None
        if t is None and R is None:
            raise OptionError(f"anchor {pid}: give t, R or both")
        (i,), (tt,), (RR,) = check_fixed(graph, {pid: (np.zeros(3) if t is None else t,
                                                        np.eye(3) if R is None else R)}, "anchor")
        out.append((int(i), None if t is None else tt, None if R is None else RR))
    if len({a[0] for a in out}) != len(out):
        raise OptionError("anchors: a pose is anchored twice")
    return out


def check_priors3d(graph, priors) -> list:
    """[(index, t̄ (3,) or None, R̄ (3, 3) or None, U (k, k) with UᵀU = Λ)] of ``{id: (t̄, R̄, Λ)}``: Λ 3×3 for a
    position or rotation prior, 6×6 (position first) for both."""
    out = []
    for pid, value in (priors or {}).items():
        try:
            t, R, info = value
        except (TypeError, ValueError):
            raise OptionError(f"prior {pid}: expected (t (3,) or None, R (3, 3) or None, information)") from None
        if t is None and R is None:
            raise OptionError(f"prior {pid}: give a position, a rotation or both")
        (i,), (tt,), (RR,) = check_fixed(graph, {pid: (np.zeros(3) if t is None else t,
                                                        np.eye(3) if R is None else R)}, "prior")
        k = 6 if t is not None and R is not None else 3
        info = np.asarray(info, dtype=float)
        if info.shape != (k, k) or not np.isfinite(info).all():
            raise OptionError(f"prior {pid}: the information must be {k}×{k} "
                              f"({'position and rotation' if k == 6 else 'position' if t is not None else 'rotation'})")
        try:
            U = np.linalg.cholesky(0.5 * (info + info.T)).T
        except np.linalg.LinAlgError:
            raise OptionError(f"prior {pid}: the information is not positive definite") from None
        out.append((int(i), None if t is None else tt, None if R is None else RR, U))
    return out


class Problem3D:
    """The restricted least-squares problem of the module docstring: ``special`` {pose: B_i (6, k_i)} for the
    restricted poses (B_i = I₆ elsewhere), ``B`` (6n, d) sparse, ``dim`` d, ``plain`` (one pose held, no priors: the pose-level elimination's fast step), ``held`` (n, 6) bool
    (coordinates of δ that cannot move), ``start`` the poses set to the anchors and projected onto the
    constraints."""

    def __init__(self, graph, t, R, *, reference: int, anchors=(), priors=(), constraints=None):
        n = graph.n_poses
        self.graph, self.priors, self.reference = graph, list(priors), reference
        t, R = np.array(t, dtype=float), np.array(R, dtype=float)
        eye, none = np.eye(3), np.zeros((3, 0))
        Bt, Br = {}, {}  # the poses whose step is restricted (few); every other pose moves freely (B_i = I₆)
        for i, ta, Ra in anchors:
            if ta is not None:
                t[i], Bt[i] = ta, none
            if Ra is not None:
                R[i], Br[i] = Ra, none
        ci, ca, cb = constraints if constraints is not None else (np.zeros(0, np.int64), np.zeros((0, 3)),
                                                                  np.zeros((0, 3)))
        self.constraints = (ci, ca, cb)
        if ci.size:
            R[ci] = project_constrained(R[ci], ca, cb)
            for i, a in zip(ci, ca):
                if Br.get(i, eye).shape[1]:
                    Br[i] = a[:, None]
        known_t = [ta for _, ta, _ in anchors if ta is not None] + [p[1] for p in self.priors if p[1] is not None]
        rot_known = any(Ra is not None for _, _, Ra in anchors) or any(p[2] is not None for p in self.priors)
        if not known_t:
            Bt[reference] = none
        if not rot_known:
            dirs = list(cb)
            if len(known_t) > 1:  # the directions the known positions span stay put too
                P = np.array(known_t) - np.mean(known_t, axis=0)
                _, sv, Vt = np.linalg.svd(P, full_matrices=False)
                dirs += list(Vt[sv > 1e-9 * max(np.abs(P).max(), 1.0)])
            D = np.array(dirs).reshape(-1, 3)
            s, V = (np.linalg.svd(D)[1:] if D.size else (np.zeros(0), None))
            rank = int((s > 1e-9).sum())
            if rank == 0:
                Br[reference] = none
            elif rank == 1:  # rotations about u remain: hold the reference's about R_refᵀ u
                c = R[reference].T @ V[0]
                base = Br.get(reference, eye)
                u, sv, _ = np.linalg.svd(base - np.outer(c, c) @ base, full_matrices=False)
                Br[reference] = u[:, sv > 1e-9]
        self.start = (t, R)
        special = sorted(set(Bt) | set(Br))
        self.special = {i: _blkdiag(Bt.get(i, eye), Br.get(i, eye)) for i in special}
        k = np.full(n, 6)
        k[special] = [b.shape[1] for b in self.special.values()]
        self.dim = int(k.sum())
        self.held = np.zeros((n, 6), bool)
        for i, b in self.special.items():
            self.held[i] = ~np.abs(b).any(axis=1)
        self.plain = not self.priors and not ci.size and special == [reference] and k[reference] == 0
        off = np.concatenate([[0], np.cumsum(k)])
        free = np.setdiff1d(np.arange(n), special)
        rows = [(6 * free[:, None] + np.arange(6)).ravel()]
        cols = [(off[free][:, None] + np.arange(6)).ravel()]
        vals = [np.ones(6 * free.size)]
        for i, b in self.special.items():  # loop over the restricted poses (few)
            r, c = np.nonzero(b)
            rows.append(6 * i + r)
            cols.append(off[i] + c)
            vals.append(b[r, c])
        self.B = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                               shape=(6 * n, self.dim))
        self.L = whitening(graph)

    # -- residuals
    def prior_terms(self, t, R, jacobian: bool = False):
        """The whitened prior residuals (Σk_q,) and, with ``jacobian``, their rows (Σk_q, 6n) sparse."""
        res, rows, cols, vals, row = [], [], [], [], 0
        for i, tb, Rb, U in self.priors:  # loop over priors (few)
            e, J = [], []
            if tb is not None:
                e.append(t[i] - tb)
                J.append((0, R[i]))
            if Rb is not None:
                phi = log_so3(Rb.T @ R[i])
                e.append(phi)
                J.append((3, right_jacobian_inverse(np.r_[np.zeros(3), phi])[3:, 3:]))
            res.append(U @ np.concatenate(e))
            if jacobian:
                Jq = np.zeros((U.shape[0], 6))
                for (c, Jc), r0 in zip(J, range(0, U.shape[0], 3)):
                    Jq[r0:r0 + 3, c:c + 3] = Jc
                Jq = U @ Jq
                rr, cc = np.meshgrid(np.arange(U.shape[0]), np.arange(6), indexing="ij")
                rows.append(row + rr.ravel())
                cols.append(6 * i + cc.ravel())
                vals.append(Jq.ravel())
            row += U.shape[0]
        r = np.concatenate(res) if res else np.zeros(0)
        if not jacobian:
            return r
        n6 = 6 * self.graph.n_poses
        P = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(row, n6)) \
            if row else sp.csr_matrix((0, n6))
        return r, P

    def chi2(self, t, R) -> float:
        rp = self.prior_terms(t, R)
        return chi2_3d(self.graph, t, R) + float(rp @ rp)

    def linearize(self, t, R):
        """(r̄ (N,), J̄_δ (N, 6n) sparse): the whitened residuals and their Jacobian in all poses' δ."""
        g = self.graph
        e, Ji, Jj = jacobians(g, t, R)
        M = edge_matrix(g.tails, g.heads, self.L @ Jj, self.L @ Ji, g.n_poses)
        rp, P = self.prior_terms(t, R, jacobian=True)
        return np.concatenate([np.einsum("kij,kj->ki", self.L, e).ravel(), rp]), sp.vstack([M, P], format="csr")

    def normal(self, t, R):
        """(H = J̄ᵀJ̄ (d, d) sparse, g = J̄ᵀr̄ (d,)) in ξ."""
        if self.plain:
            N, g, _ = normal_equations(self.graph, t, R, self.L, self.reference)
            return N, g
        r, J = self.linearize(t, R)
        J = (J @ self.B).tocsc()
        return (J.T @ J).tocsc(), J.T @ r

    def step(self, t, R, elimination=None):
        """(ξ, the linear model's decrease χ̄² − ‖r̄ + J̄ξ‖² or None) of the Gauss–Newton step (on the pose-level
        elimination the decrease is left to ``predicted``, asked only when no step decreases χ̄²)."""
        if self.plain:
            xi = gauss_newton_step(self.graph, t, R, anchor_index=self.reference, L=self.L, elimination=elimination)
            return xi, None
        from ..sparse import factorize

        H, gr = self.normal(t, R)
        xi = -factorize(H).solve(gr)
        return xi, -float(gr @ xi)

    def predicted(self, t, R, xi) -> float:
        """χ̄² − ‖r̄ + J̄ξ‖², the decrease the linear model predicts for the step ξ."""
        r, J = self.linearize(t, R)
        lin = r + J @ (self.B @ xi)
        return float(r @ r - lin @ lin)

    def update(self, t, R, xi):
        """The poses moved by ξ: R_i Exp(δφ_i), t_i + R_i δv_i, δ = Bξ."""
        d = (self.B @ xi).reshape(-1, 6)
        return t + np.einsum("kij,kj->ki", R, d[:, :3]), R @ exp_so3(d[:, 3:])

    def covariances(self, t, R) -> np.ndarray:
        """Σ_ii (n, 6, 6) of the module docstring at (t, R)."""
        from ..sparse import marginal_blocks

        n = self.graph.n_poses
        if self.dim == 0:
            return np.zeros((n, 6, 6))
        _, J = self.linearize(t, R)
        F = (J.T @ J).tocsc()
        P = (self.B @ self.B.T).tocsc()
        rest = sp.identity(6 * n, format="csc") - P
        Nbar = (P @ F @ P + rest).tocsc()
        Nbar.eliminate_zeros()
        try:
            blocks = marginal_blocks(Nbar, np.arange(6 * n).reshape(n, 6))
        except Exception as exc:  # a direction the data, priors and anchors leave free
            raise OptionError(f"pose_covariances: the refined problem's Hessian is singular ({exc})") from None
        for i, b in self.special.items():
            blocks[i] -= np.eye(6) - b @ b.T
        return 0.5 * (blocks + np.swapaxes(blocks, 1, 2))


def _blkdiag(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros((6, a.shape[1] + b.shape[1]))
    out[:3, :a.shape[1]] = a
    out[3:, a.shape[1]:] = b
    return out


@dataclass(eq=False)
class Refine3DResult:
    """A refined 3-D estimate, named as the planar ``RefineResult`` where the meaning is the same: ``t`` (n, 3),
    ``R`` (n, 3, 3) (``poses`` the pair), ``chi2`` (edges and priors, no ½), ``chi2_initial``, ``iterations``
    (accepted steps), ``converged``, ``reason``, ``log`` (one dict per iteration: chi2, time, …), ``method``,
    ``anchor`` (id of the reference pose), ``cost``, ``held`` (n, 6) bool (coordinates of δ = (δv, δφ) held:
    anchors, the gauge, rotation constraints), ``constraint_names``, ``problem`` (``Problem3D``), ``backend`` (the
    sparse solver of the steps)."""

    t: np.ndarray
    R: np.ndarray
    chi2: float
    iterations: int
    converged: bool
    log: list
    chi2_initial: float = float("nan")
    reason: str = ""
    method: str = ""
    anchor: int = 0
    cost: str = "g2o"
    held: np.ndarray | None = None
    constraint_names: list = field(default_factory=list)
    problem: object = field(default=None, repr=False)
    backend: str = ""

    dim = 3

    def __repr__(self) -> str:
        return refine_repr(self)

    def summary(self):
        """The numbers of the refinement as a small table (``reports.Summary``, also a dict), as planar."""
        return refine_summary(self)

    @property
    def poses(self):
        """(t, R)."""
        return self.t, self.R

    @property
    def times(self) -> np.ndarray:
        return np.array([e["time"] for e in self.log])

    def pose_covariances(self) -> np.ndarray:
        """Marginal covariances (n, 6, 6) of δ = (δv, δφ) of every pose at the refined estimate: the blocks of
        B (J̄ᵀJ̄)⁻¹ Bᵀ (module docstring; edges and priors, anchors and the gauge held — zero rows and columns —,
        rotation constraints restricting δφ), in ``pose_covariances3d``'s convention."""
        return self.problem.covariances(self.t, self.R)


#: The old name of the 3-D result.
Refined3D = Refine3DResult


def refine_space(graph, t, R, *, method: str, max_iterations: int, tolerance: float, anchor=None, anchors=None,
                 priors=None, constraints=None, initial_lambda: float = 1e-5) -> Refine3DResult:
    """Gauss–Newton (``"gauss-newton"``: the step, halved up to ``MAX_HALVINGS`` times until χ̄² decreases) or
    Levenberg–Marquardt (the Gauss–Newton step when it decreases χ̄², else damped steps (H + λ diag H) ξ = −g, λ from
    ``initial_lambda`` up ×10 per rejected step, ÷10 after an accepted one, up to 1e10) on the problem of the module
    docstring. Stops when χ̄² decreases by less than ``tolerance`` relative, when the step is below
    ``STEP_TOLERANCE``, after ``max_iterations``, or when no step decreases χ̄² (converged when the model predicted
    no more than rounding). ``anchor``: the reference pose's id (default the smallest)."""
    from ..sparse import GraphElimination, factorize

    check_choice("method", method, REFINE_METHODS)
    if not int(max_iterations) >= 0:
        raise OptionError(f"max_iterations must be >= 0, got {max_iterations}")
    if not tolerance >= 0:
        raise OptionError(f"tolerance must be >= 0, got {tolerance}")
    t, R = graph.check_poses(t, R)
    con = None if constraints is None else check_rotation_constraints(graph, constraints)
    prob = Problem3D(graph, t, R, reference=graph.anchor_index(anchor), anchors=check_anchors3d(graph, anchors),
                     priors=check_priors3d(graph, priors), constraints=con)
    t, R = prob.start
    start = time.perf_counter()
    chi = prob.chi2(t, R)
    res = Refine3DResult(t, R, chi, 0, False, [{"iteration": 0, "chi2": chi, "step_norm": 0.0, "time": 0.0}],
                         chi2_initial=chi, method=method, anchor=int(graph.ids[prob.reference]), cost=graph.cost,
                         held=prob.held, problem=prob,
                         constraint_names=[f"R_{graph.ids[i]} a = b" for i in prob.constraints[0]],
                         backend="pose-level elimination" if prob.plain else "factorize")
    if prob.dim == 0 or graph.n_edges == 0:
        res.converged, res.reason = True, "nothing to optimize"
        return res
    el = GraphElimination(graph, prob.reference) if prob.plain else None
    tiny = np.finfo(float).tiny
    lam = initial_lambda
    res.reason = "max_iterations reached"
    for _ in range(int(max_iterations)):
        try:
            xi, predicted = prob.step(t, R, el)
        except (RuntimeError, np.linalg.LinAlgError) as exc:
            res.reason = f"singular normal equations ({exc})"
            break
        if not np.isfinite(xi).all():
            res.reason = "non-finite Gauss-Newton step (singular normal equations)"
            break
        step = float(np.abs(xi).max(initial=0.0))
        if step <= STEP_TOLERANCE * (1.0 + float(np.abs(t).max())):
            res.converged, res.reason = True, f"step norm {step:.3g} below tolerance"
            break
        t2, R2 = prob.update(t, R, xi)
        new, halvings, used = prob.chi2(t2, R2), 0, 0.0
        if method == "gauss-newton":
            alpha = 1.0
            while not new < chi and halvings < MAX_HALVINGS and not abs(chi - new) <= tolerance * max(chi, tiny):
                halvings += 1
                alpha *= 0.5
                t2, R2 = prob.update(t, R, alpha * xi)
                new = prob.chi2(t2, R2)
        elif not new <= chi:
            H, g = prob.normal(t, R)
            D = sp.diags(H.diagonal(), format="csc")
            while not new <= chi and lam <= 1e10:
                xi = -factorize((H + lam * D).tocsc()).solve(g)
                t2, R2 = prob.update(t, R, xi)
                new = prob.chi2(t2, R2)
                used = lam
                lam = lam / 10.0 if new <= chi else lam * 10.0
        if not new <= chi:  # no decrease along any step tried: stationary to working precision, or a failure
            predicted = prob.predicted(t, R, xi) if predicted is None else predicted
            res.converged = predicted <= 10 * max(tolerance, 1e-12) * max(chi, tiny) or new - chi <= 1e-9 * chi
            res.reason = ("no further decrease (stationary to working precision)" if res.converged else
                          f"line search failed (predicted decrease {predicted:.3g})")
            break
        rel = (chi - new) / max(chi, tiny)
        t, R, chi = t2, R2, new
        res.iterations += 1
        res.log.append({"iteration": res.iterations, "chi2": chi, "step_norm": step, "lambda": used,
                        "halvings": halvings, "time": time.perf_counter() - start})
        if rel <= tolerance:
            res.converged, res.reason = True, "relative χ² decrease below tolerance"
            break
    res.t, res.R, res.chi2 = t, R, float(chi)
    if prob.constraints[0].size:
        log.info("refine (3-D): rotation constraints hold to %.3g", constraint_violation(R, *prob.constraints))
    log.info("refine (3-D, %s): χ² %.6g → %.6g in %d steps; %s", method, res.chi2_initial, res.chi2,
             res.iterations, res.reason)
    return res


def refine3d(graph, t, R, *, cost: str | None = None, method: str = REFINE_METHOD, anchor=None, anchors=None,
             priors=None, constraints=None, max_iterations: int = REFINE_MAX_ITERATIONS,
             tolerance: float = REFINE_TOLERANCE, initial_lambda: float = 1e-5) -> Refine3DResult:
    """``lago_cvx.refine`` on a 3-D graph with the poses given as t (n, 3), R (n, 3, 3): ``refine_space`` on the χ²
    of ``cost`` (None: the graph's; ``"g2o"`` or ``"gtsam"``), the defaults of ``refine`` (``conventions``)."""
    if cost is not None:
        graph = graph.with_cost(cost)
    return refine_space(graph, t, R, method=method, max_iterations=max_iterations, tolerance=tolerance,
                        anchor=anchor, anchors=anchors, priors=priors, constraints=constraints,
                        initial_lambda=initial_lambda)

r"""Constrained variants of LAGO: fixed anchors, priors, convex constraints, robust losses —
each phase still one explicit cvxpy problem, and (for the least-squares variants) a sparse closed form.

Notation as in ``lago_cvx.phases``: n poses, m edges, A the (n × m) incidence matrix, δ_reg the
regularized relative orientations, P_δ, P_Δ the per-edge marginal covariances, S = [[0, −1], [1, 0]].
Here the phases are written over **all** coordinates and a set K of them is *known*:
phase 1 over θ ∈ ℝⁿ, phase 3 over x = [p; θ] ∈ ℝ³ⁿ (p interleaved x₀, y₀, x₁, y₁, …). U is the rest.

(V1) Every phase is a weighted linear least-squares problem with known coordinates,
         minimise ‖W (z − Bᵀx)‖²   subject to   x_K = x̄_K,
     W a sparse whitening (rows × measurements), Bᵀ the design (measurements × coordinates).
(V2) Closed form: with M = W Bᵀ the known columns move to the right-hand side (the reduced incidence
     matrix loses the anchored rows),
         x_U = argmin ‖M_U x_U − (W z − M_K x̄_K)‖² = (M_UᵀM_U)⁻¹ M_Uᵀ (W z − M_K x̄_K),
     solved by ``lago_cvx.sparse.linalg.solve_least_squares`` (sparse factorization + refinement).
     cvxpy: one variable x for all coordinates, the objective ``cp.sum_squares(W @ (z − Bᵀ @ x))``,
     and the anchors as ONE equality constraint ``x[K] == x̄_K``.
Phase 1 (V5), with priors Q (pose q, mean μ_q, information Λ_q, 3×3 SPD):
     Bᵀ₁ = [Aᵀ; E_Q] ((m + |Q|) × n),  z₁ = [δ_reg; μ̃_θ],  W₁ = diag(P_δ^{-1/2}, σ_Q⁻¹),
     σ_q² = (Λ_q⁻¹)_θθ the prior's marginal variance of θ, μ̃_θ the rounded prior mean.
Phase 2 (V6): z = [Δᵍ; θ̂_U] ∈ ℝ^{2m + d_θ}, Δᵍ = R(θ̂_i)Δˡ, and
     W = [[P_Δ^{-1/2} Rᵀ, −P_Δ^{-1/2} S Δˡ e_iᵀ], [0, L]],   L = (W₁ Bᵀ₁)[:, U_θ],
     so WᵀW = P_z⁻¹ with P_θ⁻¹ = LᵀL (the anchored, prior-informed phase-1 information). An edge
     whose tail has a known orientation has no J block (θ_i carries no uncertainty).
Phase 3 (V7): x = [p; θ] ∈ ℝ³ⁿ, rows
     Δᵍ − (A ⊗ I₂)ᵀ p      (2m, whitened by the first block row of W),
     θ̂_U − θ_U            (d_θ, whitened by L),
     μ_p,q + h_q μ̃_θ,q − (p_q + h_q θ_q)   (2 per prior, whitened by C_q, C_qᵀC_q = Λ_pp,q),
     h_q = Λ_pp⁻¹Λ_pθ. (V8) This splits a prior exactly:
     eᵀΛe = (e_p + h e_θ)ᵀΛ_pp(e_p + h e_θ) + e_θ²/σ²,   e = pose − μ:
     the marginal θ part enters phase 1 (and reaches phase 3 through θ̂ and L), the conditional
     (x, y, θ) part enters phase 3 — every prior is counted once. A prior with information → ∞
     converges to the anchor (tested at 1e12).

Where the rest lives: anchors and priors, and their 2kπ rounding (V4), in ``anchors.py``; the weighted
systems of every phase (V1, V2, V5–V7) in ``systems.py``; the strain test of hard anchors (V3) in
``strain.py``; the frame decision and the steps of a run in ``engine.py``; named convex constraints (V9)
in ``constraints.py``; convex robust losses (V10) in the engine (``lago_variant(loss="huber")``, ``"l1"``);
graduated non-convexity against false loop closures (V11, ``lago(graph, robust=True)``) in ``gnc.py``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from ..errors import OptionError
from ..metrics import relative_difference
from ..posegraph import PoseGraph
from ..rounding import AMBIGUITY_MARGIN
from ..routes import resolve_route
from ..solvers import ClarabelSettings, IntegerSearch
from .anchors import Anchor, AnchorRegularization, Prior, normalize_anchors, normalize_priors
from .constraints import (NamedConstraint, PoseVariables, box_constraint, halfplane_constraint, orientation_bounds,
                          polygon_constraint)
from .engine import VariantOptions, VariantPhase1, VariantPhase3, VariantResult, lago_variant
from .robust3d import Robust3DResult
from .gnc import (ROBUST_LOSSES, RobustResult, RobustSettings, RobustVariantResult, gnc_lago, gnc_threshold,
                  gnc_weights, odometric_chain_complete, robust_settings)
from .strain import STRAIN_LEVEL, AnchorStrain
from .systems import (DEFAULT_THRESHOLD, LOSSES, WeightedSystem, anchored_phase2, phase1_system, phase3_system,
                      solve_system, solve_system_cvxpy, system_problem)

__all__ = [
    "Anchor", "Prior", "normalize_anchors", "normalize_priors", "AnchorRegularization", "AnchorStrain",
    "VariantOptions", "VariantPhase1", "VariantPhase3", "VariantResult",
    "anchored_lago", "constrained_lago", "lago_variant", "compare_anchored_methods",
    "WeightedSystem", "phase1_system", "anchored_phase2", "phase3_system", "system_problem", "solve_system",
    "solve_system_cvxpy", "PoseVariables", "NamedConstraint", "box_constraint", "polygon_constraint",
    "halfplane_constraint", "orientation_bounds", "LOSSES", "DEFAULT_THRESHOLD", "STRAIN_LEVEL",
    "RobustSettings", "RobustResult", "RobustVariantResult", "Robust3DResult", "ROBUST_LOSSES", "robust_settings", "gnc_lago",
    "gnc_threshold", "gnc_weights", "odometric_chain_complete",
]


def anchored_lago(graph: PoseGraph, *, anchors=None, priors=None, method: str = "closed_form", route: str = "default",
                  spanning_tree=None, regularization: str | None = None, information: str | None = None,
                  positions: str | None = None, anchor=None, anchor_pose=None, margin: float = AMBIGUITY_MARGIN,
                  strain_level: float = STRAIN_LEVEL, solver_settings: ClarabelSettings | None = None,
                  backend: str = "auto", integer_search: IntegerSearch | None = None,
                  progress=None) -> VariantResult:
    """LAGO with hard anchors and/or priors (V1–V8), closed form or cvxpy (``method``); what
    ``lago(graph, anchors=...)`` runs. Every keyword of ``lago`` is accepted and means what it means there
    (``route`` and the four choices after it, ``integer_search`` for ``regularization="integer"``,
    ``progress``); see ``lago_variant`` for the other options and ``engine`` for the frame decision.
    ``result.strain`` holds the per-anchor Lagrange-multiplier test (V3)."""
    choice, name = resolve_route(route, spanning_tree=spanning_tree, regularization=regularization,
                                 information=information, positions=positions)
    return lago_variant(graph, anchors=anchors, priors=priors, method=method, anchor=anchor, anchor_pose=anchor_pose,
                        margin=margin, strain_level=strain_level, solver_settings=solver_settings, backend=backend,
                        integer_search=integer_search, progress=progress, route=name, **choice)


def constrained_lago(graph: PoseGraph, constraints_fn: Callable, *, anchors=None, priors=None, loss: str = "l2",
                     threshold: float = DEFAULT_THRESHOLD, route: str = "default", spanning_tree=None,
                     regularization: str | None = None, information: str | None = None, anchor=None,
                     anchor_pose=None, margin: float = AMBIGUITY_MARGIN,
                     solver_settings: ClarabelSettings | None = None) -> VariantResult:
    """LAGO with named convex constraints (V9): phases 1 and 3 as cvxpy problems plus
    ``constraints_fn(pv) -> list[NamedConstraint]`` (called with ``PoseVariables`` of each phase; use
    ``box_constraint``, ``polygon_constraint``, ``halfplane_constraint``, ``orientation_bounds``, or
    ``NamedConstraint(name, [...])`` with any cvxpy constraint on ``pv.x``, ``pv.y``, ``pv.theta``).
    ``route``, ``spanning_tree``, ``regularization``, ``information`` as in ``lago``; the poses are phase
    3's (an unconstrained position polish would leave the feasible set). Raises
    ``InfeasibleConstraintsError`` naming the constraints when they cannot hold."""
    choice, name = resolve_route(route, spanning_tree=spanning_tree, regularization=regularization,
                                 information=information, positions="phase3")
    return lago_variant(graph, anchors=anchors, priors=priors, constraints_fn=constraints_fn, loss=loss,
                        threshold=threshold, method="cvxpy", anchor=anchor, anchor_pose=anchor_pose, margin=margin,
                        solver_settings=solver_settings, route=name, **choice)


def compare_anchored_methods(graph: PoseGraph, *, anchors=None, priors=None,
                             solver_settings: ClarabelSettings | None = None,
                             **kwargs) -> tuple[VariantResult, dict]:
    """``compare_methods`` for anchored LAGO: the closed form, then phases 1 and 3 as cvxpy problems (with
    the anchors as equality constraints) **on the same inputs**. ``kwargs``: every keyword of
    ``anchored_lago`` but ``method`` (both methods run: ``OptionError``). Report: ``max_rel_diff`` {phase1,
    phase3} (over the unknown coordinates), ``max_rel_diff_gradient`` {phase1, phase3} (cvxpy's −dual vs
    the closed form's g_K, relative to max |g_K|), ``cvxpy_timings``, ``problems``."""
    if "method" in kwargs:
        raise OptionError("method: compare_methods solves both ways (closed form, then cvxpy); do not pass method")
    res = anchored_lago(graph, anchors=anchors, priors=priors, method="closed_form",
                        solver_settings=solver_settings, **kwargs)
    t = time.perf_counter()
    s1 = solve_system_cvxpy(res.phase1.system, settings=solver_settings)
    t1 = time.perf_counter() - t
    t = time.perf_counter()
    s3 = solve_system_cvxpy(res.phase3.system, settings=solver_settings)
    t3 = time.perf_counter() - t
    U1, U3 = ~res.phase1.system.known, ~res.phase3.system.known
    report = {
        "max_rel_diff": {"phase1": relative_difference(s1.x[U1], res.phase1.solution.x[U1]),
                         "phase3": relative_difference(s3.x[U3], res.phase3.solution.x[U3])},
        "max_rel_diff_gradient": {"phase1": relative_difference(s1.grad_known, res.phase1.solution.grad_known),
                                  "phase3": relative_difference(s3.grad_known, res.phase3.solution.grad_known)},
        "cvxpy_timings": {"phase1": t1, "phase3": t3},
        "problems": {"phase1": s1.problem, "phase3": s3.problem},
    }
    return res, report

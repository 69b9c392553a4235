"""The certified route on a graph: LAGO → Gauss–Newton on χ² → Newton on the SE-Sync cost → SE-Sync's
certificate of the result (and, on request, of the raw LAGO estimate for comparison). What ``lago-cvx
certify`` runs.

Which point each number is about (the report's keys):

* ``f_lago`` — f at the LAGO estimate as LAGO returned it;
* ``f_chi2_refined`` — f at the χ²-refined estimate (Gauss–Newton on eq. (3), poses as refined);
* ``f`` — f at the SE-Sync-refined estimate with its translations re-optimised for its rotations (the
  point the certificate is about; ``f_input`` at the poses as refined, equal at convergence);
* ``lago_certificate.f`` — f at LAGO's *rotations* with the translations re-optimised for them: what the
  comparison certificate is about, below ``f_lago`` (LAGO's own translations are not the optimal ones for
  its rotations under f); ``lago_certificate.f_input`` = ``f_lago``.

The comparison certificate of the raw LAGO estimate is opt-in (``compare_lago=True``): by construction it
is never certified (its f is above the refined one), and it costs as much as the certificate itself
(on a 200 000-pose world, more: LAGO's rotations are far from a critical point, so S_Q has many negative
eigenvalues to locate). Its time is reported apart (``timings["certify_lago"]``).

Anchors. The certificate is about the global minimum of f over all poses. f is invariant under one rigid
motion of every pose (R_i → R₀R_i, t_i → R₀t_i + t₀; the multipliers Λ_i with it), so one anchor — one
pose, fully or partly given — is a choice of frame: the certified estimate is moved rigidly to put that
pose where it is given, and the certificate holds unchanged. Two or more anchored poses constrain the
problem; the certificate does not speak about constrained optima, so they are refused (``OptionError``).
"""

from __future__ import annotations

import time

import numpy as np

from ..conventions import SESYNC_COST_CONVENTION
from ..errors import GraphError, NonFiniteError, OptionError
from ..pipeline import lago
from ..posegraph import PoseGraph, between, compose
from ..refinement import refine
from .certificate import CERTIFY_TOL, Certificate, certify
from .local import refine_sesync
from .sesync import sesync_cost

__all__ = ["SESYNC_COST_CONVENTION", "certificate_fields", "certify_estimate", "gauge_anchor", "COST_LABELS"]

#: What each reported f is (the keys of ``certify_estimate``'s report).
COST_LABELS = {
    "f_lago": "f at the LAGO estimate as returned",
    "f_chi2_refined": "f at the χ²-refined estimate (Gauss–Newton on eq. (3)), poses as refined",
    "f": "f at the SE-Sync-refined estimate, translations re-optimised for its rotations (the certified point)",
    "f_input": "f at the SE-Sync-refined estimate, poses as refined",
    "lago_certificate.f": "f at LAGO's rotations with translations re-optimised for them (the comparison point)",
    "lago_certificate.f_input": "f at the LAGO estimate as returned (= f_lago)",
}


def _one_anchor(graph: PoseGraph, anchors: dict) -> tuple[int, int, tuple]:
    """(id, index, (x, y, θ) with None for a field not given) of the only anchor; ``OptionError`` for more."""
    if len(anchors) > 1:
        raise OptionError(f"anchors at {len(anchors)} poses ({', '.join(str(k) for k in sorted(anchors))}) constrain "
                          "the problem, and the certificate is about the unconstrained global optimum: give at most "
                          "one anchor (a choice of frame)")
    (pid, value), = anchors.items()
    a = graph.anchor_index(pid)
    value = (0.0, 0.0, 0.0) if value is None else tuple(value)
    if len(value) != 3:
        raise OptionError(f"anchor {pid}: expected (x, y, θ), got {value!r}")
    return int(pid), a, value


def gauge_anchor(graph: PoseGraph, poses: np.ndarray, anchors: dict | None) -> tuple[np.ndarray, int | None]:
    """Move ``poses`` (n, 3) rigidly so that the one anchored pose is where ``anchors`` says.

    ``anchors`` ``{id: (x, y, θ)}`` with at most one entry; a missing field (None) keeps the pose's own
    value (only θ given: a rotation about the pose; only x, y: a translation); ``{id: None}`` puts the
    pose at the origin (LAGO's frame). With p_a the pose and a' the target, every pose becomes T ⊕ p with
    T = a' ⊕ (⊖p_a) (eq. (1)); f and the certificate are invariant. Returns ``(poses, id)`` (``id`` None
    without anchors). Raises ``OptionError`` for two or more anchors."""
    if not anchors:
        return poses, None
    pid, a, value = _one_anchor(graph, anchors)
    target = np.array([poses[a, k] if v is None else float(v) for k, v in enumerate(value)])
    T = compose(target, between(poses[a], np.zeros(3)))  # a' ⊕ (⊖p_a)
    out = compose(np.broadcast_to(T, poses.shape), poses)
    out[a] = target  # exactly, not to rounding
    return out, pid


def certificate_fields(cert: Certificate) -> dict:
    """The JSON-ready fields of one ``Certificate`` (see its docstring)."""
    return {
        "certified": bool(cert.certified), "verdict": cert.verdict,
        "f": cert.cost, "f_input": cert.cost_input,  # f with translations re-optimised / at the poses as given
        "lambda_min": cert.lambda_min, "eigenvalues": [float(v) for v in cert.eigenvalues],
        "eta": cert.eta, "norm_M": cert.norm_M, "n_negative": int(cert.n_negative),
        "residual_rel": cert.residual_rel, "lower_bound": cert.lower_bound,
        "suboptimality_bound": cert.suboptimality_bound,
        "relative_suboptimality_bound": cert.relative_suboptimality_bound,
    }


def certify_estimate(graph: PoseGraph, *, route: str = "default", spanning_tree: str | None = None,
                     regularization: str | None = None, tol: float = CERTIFY_TOL, abs_tol: float = 0.0,
                     max_iterations: int = 50, integer_search=None, compare_lago: bool = False,
                     anchors: dict | None = None) -> tuple[dict, Certificate]:
    """The certified route on ``graph``: LAGO → χ² Gauss–Newton (``refine``) → Newton (GN where Newton does
    not descend) on the SE-Sync cost f (``refine_sesync``) → SE-Sync's optimality certificate
    (``certify``) of the refined estimate and, with ``compare_lago=True``, of the raw LAGO estimate for
    comparison (never certified: its cost is above the refined one; it costs as much again or more, so it
    is opt-in). ``tol`` is the largest relative suboptimality bound accepted as certified (≤ 1e-3); ``abs_tol`` ≥ 0
    SE-Sync's absolute threshold (0: none; ``certify``).

    ``anchors`` ``{id: (x, y, θ)}`` (None fields allowed) — at most one pose, a choice of frame: the
    certified poses are moved rigidly to put it there (``gauge_anchor``; f and the verdict are invariant);
    two or more raise ``OptionError``. ``{id: None}`` only picks LAGO's anchor pose.

    Returns ``(report, cert)``: the JSON-ready report (the keys of ``COST_LABELS`` say which point each f
    is about; ``lago_certificate`` None unless ``compare_lago``; ``timings`` seconds per step, the
    comparison as ``certify_lago``) and the refined estimate's ``Certificate`` (``cert.poses`` are the
    certified poses, translations re-optimised for the certified rotations, in the anchor's frame).
    ``route``, ``spanning_tree``, ``regularization``, ``integer_search`` choose LAGO as in ``lago``. Raises
    ``GraphError`` for a graph without edges or not connected, ``NonFiniteError`` when LAGO's estimate or its
    χ² is not finite (data that overflow double precision)."""
    if graph.n_edges == 0:
        raise GraphError(f"the graph has {graph.n_poses} pose(s) and no edges: nothing to certify")
    anchor_id = _one_anchor(graph, anchors)[0] if anchors else None  # refused before any work if several
    times = {}
    t = time.perf_counter()
    res = lago(graph, route=route, spanning_tree=spanning_tree, regularization=regularization,
               integer_search=integer_search)  # in LAGO's own frame: the anchor only moves the result
    if not (np.isfinite(res.chi2) and np.isfinite(res.poses).all()):
        raise NonFiniteError(f"the LAGO estimate is not finite (χ² = {res.chi2}): the measurements or information "
                             "overflow double precision; nothing to certify")
    times["lago"] = time.perf_counter() - t
    t = time.perf_counter()
    ref = refine(graph, res.poses, max_iterations=max_iterations)
    times["refine"] = time.perf_counter() - t
    t = time.perf_counter()
    ses = refine_sesync(graph, ref.poses, max_iterations=max_iterations, method="newton")
    times["refine_sesync"] = time.perf_counter() - t
    t = time.perf_counter()
    f_lago = sesync_cost(graph, res.poses)
    # a point above a cost already reached is never certified (the refinement only descends, so the
    # refined point is below both LAGO's and the χ²-refined one's; if it is not, something went wrong)
    # full=False: λ_min of the full S (structurally ≤ 0) is not reported, and its bisection costs a third
    cert = certify(graph, ses.poses, tol=tol, abs_tol=abs_tol, known_cost=min(f_lago, ses.cost_initial), full=False)
    times["certify"] = time.perf_counter() - t
    cert_lago = None
    if compare_lago:
        t = time.perf_counter()
        cert_lago = certify(graph, res.poses, tol=tol, abs_tol=abs_tol, known_cost=cert.cost, full=False)
        times["certify_lago"] = time.perf_counter() - t
    cert.poses = gauge_anchor(graph, cert.poses, anchors)[0]
    reg = res.regularization
    report = {
        "n_poses": graph.n_poses, "n_edges": graph.n_edges, "route": res.route, "spanning_tree": res.tree.kind,
        "regularization": reg.regularization, "n_regularized": reg.n_regularized,
        "n_ambiguous": int(reg.ambiguous.size), "tol": tol, "abs_tol": abs_tol, "cost_convention": SESYNC_COST_CONVENTION,
        "chi2_lago": res.chi2, "chi2_refined": ref.chi2, "refine_iterations": ref.iterations,
        "refine_converged": bool(ref.converged),
        "f_lago": f_lago, "f_chi2_refined": ses.cost_initial,
        "sesync_iterations": ses.iterations, "sesync_converged": bool(ses.converged), "sesync_reason": ses.reason,
        **certificate_fields(cert),
        "compare_lago": bool(compare_lago),
        "lago_certificate": certificate_fields(cert_lago) if cert_lago is not None else None,
        "cost_labels": dict(COST_LABELS),
        "anchor": anchor_id,
        "timings": times,
    }
    return report, cert

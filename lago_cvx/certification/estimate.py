"""The certified route on a graph: LAGO → Gauss–Newton on χ² → Newton on the SE-Sync cost → SE-Sync's
certificate of the result (and, for comparison, of the raw LAGO estimate). What ``lago-cvx certify``
runs."""

from __future__ import annotations

import time

import numpy as np

from ..conventions import SESYNC_COST_CONVENTION
from ..errors import GraphError, NonFiniteError
from ..pipeline import lago
from ..posegraph import PoseGraph
from ..refinement import refine
from .certificate import CERTIFY_TOL, Certificate, certify
from .local import refine_sesync
from .sesync import sesync_cost

__all__ = ["SESYNC_COST_CONVENTION", "certificate_fields", "certify_estimate"]




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
                     regularization: str | None = None, tol: float = CERTIFY_TOL,
                     max_iterations: int = 50, integer_search=None) -> tuple[dict, Certificate]:
    """The certified route on ``graph``: LAGO → χ² Gauss–Newton (``refine``) → Newton (GN where Newton does
    not descend) on the SE-Sync cost f (``refine_sesync``) → SE-Sync's optimality certificate
    (``certify``) of the refined estimate and, for comparison, of the raw LAGO estimate. ``tol`` is the
    largest relative suboptimality bound accepted as certified (≤ 1e-3); neither point is certified when
    its cost is above a cost the route has already reached.

    Returns ``(report, cert)``: the JSON-ready report and the refined estimate's ``Certificate``
    (``cert.poses`` are the certified poses, translations re-optimised for the certified rotations).
    ``route``, ``spanning_tree``, ``regularization``, ``integer_search`` choose LAGO as in ``lago``. Raises
    ``GraphError`` for a graph without edges or not connected, ``NonFiniteError`` when LAGO's estimate or its
    χ² is not finite (data that overflow double precision)."""
    if graph.n_edges == 0:
        raise GraphError(f"the graph has {graph.n_poses} pose(s) and no edges: nothing to certify")
    times = {}
    t = time.perf_counter()
    res = lago(graph, route=route, spanning_tree=spanning_tree, regularization=regularization,
               integer_search=integer_search)
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
    cert = certify(graph, ses.poses, tol=tol, known_cost=min(f_lago, ses.cost_initial))
    times["certify"] = time.perf_counter() - t
    t = time.perf_counter()
    cert_lago = certify(graph, res.poses, tol=tol, known_cost=cert.cost)
    times["certify_lago"] = time.perf_counter() - t
    reg = res.regularization
    report = {
        "n_poses": graph.n_poses, "n_edges": graph.n_edges, "route": res.route, "spanning_tree": res.tree.kind,
        "regularization": reg.regularization, "n_regularized": reg.n_regularized,
        "n_ambiguous": int(reg.ambiguous.size), "tol": tol, "cost_convention": SESYNC_COST_CONVENTION,
        "chi2_lago": res.chi2, "chi2_refined": ref.chi2, "refine_iterations": ref.iterations,
        "refine_converged": bool(ref.converged),
        "f_lago": f_lago, "f_chi2_refined": ses.cost_initial,
        "sesync_iterations": ses.iterations, "sesync_converged": bool(ses.converged), "sesync_reason": ses.reason,
        **certificate_fields(cert),
        "lago_certificate": certificate_fields(cert_lago),
        "timings": times,
    }
    return report, cert

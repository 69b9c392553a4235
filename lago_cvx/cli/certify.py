"""``lago-cvx certify``: LAGO → χ² Gauss–Newton → SE-Sync Newton → SE-Sync's certificate."""

from __future__ import annotations

import argparse

import numpy as np

from ..conventions import CERTIFY_TOL, SESYNC_COST_CONVENTION
from .common import (
    EXIT_BAD_INPUT,
    EXIT_INTERNAL,
    EXIT_NOT_CERTIFIED,
    EXIT_OK,
    EXIT_RESOURCE,
    add_input_options,
    add_route_options,
    check_regularization,
    emit,
    integer_search,
    nonneg_int,
    output_target,
    read_input,
    write_estimate,
)


def _tol_arg(value: str) -> float:
    try:
        tol = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tol must be a number, got {value!r}") from None
    if not (np.isfinite(tol) and 0 < tol <= CERTIFY_TOL):
        raise argparse.ArgumentTypeError(f"--tol must be a number in (0, {CERTIFY_TOL:g}], got {value!r}")
    return tol


def _bound_text(bound: float, digits: int) -> str:
    return f"{bound:.{digits}g}" + (" (vacuous: f ≥ 0 always)" if bound <= 0 else "")


def _reason(verdict: str) -> str:
    """The verdict without its leading "not certified: " (the caller says it)."""
    for head in ("not certified: ", "NOT certified "):
        if verdict.startswith(head):
            return verdict[len(head):]
    return verdict


def _certify_lines(file, payload: dict) -> list[str]:
    p, lc = payload, payload["lago_certificate"]
    return [
        f"certify: LAGO ({p['spanning_tree']} spanning tree, {p['regularization']} regularization) → χ² "
        f"Gauss–Newton → SE-Sync Newton → SE-Sync certificate, on {file}",
        f"  poses {p['n_poses']}, edges {p['n_edges']}",
        f"  chi2 (g2o convention, sum e'Ωe): LAGO {p['chi2_lago']:.6g}, refined {p['chi2_refined']:.6g} "
        f"({p['refine_iterations']} GN iterations{'' if p['refine_converged'] else ', not converged'})",
        f"  {p['cost_convention']}:",
        f"    LAGO estimate        f = {p['f_lago']:.10g}",
        f"    χ²-refined           f = {p['f_chi2_refined']:.10g}",
        f"    SE-Sync-refined      f = {p['f']:.12g}  ({p['sesync_iterations']} Newton iterations, "
        + ("converged)" if p["sesync_converged"] else f"not converged: {p['sesync_reason']})"),
        f"  LAGO estimate alone: {'certified' if lc['certified'] else 'NOT certified'}: {_reason(lc['verdict'])}",
        f"  SE-Sync-refined:     {'CERTIFIED globally optimal' if p['certified'] else 'NOT certified'}",
        f"    λ_min(S_Q) = {p['lambda_min']:.3g}; numerical floor η = {p['eta']:.3g} (1e-12 × ‖M‖₂ "
        f"{p['norm_M']:.4g})",
        f"    proven lower bound f* ≥ {_bound_text(p['lower_bound'], 12)}; relative suboptimality (f − bound)/f ≤ "
        f"{p['relative_suboptimality_bound']:.3g}; certified iff ≤ tol {p['tol']:.3g}",
        f"    verdict: {p['verdict']}",
    ]


def cmd_certify(args) -> int:
    from ..certification import certify_estimate
    from ..errors import GraphError

    out = output_target(args)
    graph = read_input(args)
    if graph.n_edges == 0:
        raise GraphError(f"{args.file}: the graph has {graph.n_poses} pose(s) and no edges: nothing to certify")
    if graph.dim == 3:
        from .space import certify3d_cmd

        return certify3d_cmd(args, graph, out)
    check_regularization(graph, args.regularization)
    payload, cert = certify_estimate(graph, route=args.route, spanning_tree=args.spanning_tree,
                                     regularization=args.regularization, integer_search=integer_search(args),
                                     tol=args.tol, max_iterations=args.max_iterations)
    payload = {"file": str(args.file), **payload}
    lines = _certify_lines(args.file, payload)
    if out is not None:
        write_estimate(out, graph, cert.poses)
        payload["output"] = "<stdout>" if out == "-" else str(out)
        lines.append(f"  {'certified' if cert.certified else 'refined (NOT certified)'} estimate written to "
                     + ("standard output" if out == "-" else str(out)))
    status = EXIT_OK if cert.certified else EXIT_NOT_CERTIFIED
    if status != EXIT_OK:
        lines.append(f"  exit status {status}: not certified (a local minimum, an unconverged refinement, a "
                     "relaxation that is not tight, or a bound too weak for the cost's scale)")
    payload["exit_status"] = status
    emit(args, payload, lines, stdout_taken=out == "-")
    return status


def add_parser(sub) -> None:
    s = sub.add_parser(
        "certify", help="LAGO, refinement and SE-Sync's global-optimality certificate",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run LAGO on FILE, refine it (Gauss-Newton on the g2o chi2, then Newton on the SE-Sync cost f), and\n"
                    "verify global optimality with SE-Sync's Lagrangian-dual certificate (lago_cvx.certification).\n"
                    f"{SESYNC_COST_CONVENTION}.\nThe raw LAGO estimate is certified too, for comparison; a point "
                    "whose cost is above one already reached\nis never certified.",
        epilog=f"exit status: {EXIT_OK} certified globally optimal; {EXIT_NOT_CERTIFIED} NOT certified (the report is "
               f"still printed\nand -o still written); {EXIT_BAD_INPUT} bad input (malformed file, no edges, "
               f"graph not connected,\nbad option, estimate not finite); {EXIT_RESOURCE} resource limit; "
               f"{EXIT_INTERNAL} internal error.")
    s.add_argument("file")
    add_input_options(s)
    s.add_argument("-o", "--output", metavar="OUT", help="write the SE-Sync-refined estimate (the poses the "
                                                         "certificate is about) as g2o to OUT (- for standard output)")
    add_route_options(s)
    s.add_argument("--tol", type=_tol_arg, default=CERTIFY_TOL, metavar="TOL",
                   help="certified iff the proven relative suboptimality (f − f*_lower)/f ≤ TOL "
                        f"(0 < TOL ≤ {CERTIFY_TOL:g}, the default)")
    s.add_argument("--max-iterations", type=nonneg_int, default=50,
                   help="iterations of each refinement, chi2 and SE-Sync (default 50)")
    s.add_argument("--overwrite-input", action="store_true", help="allow -o to name the input file")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_certify)

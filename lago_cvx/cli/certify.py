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
    UsageError,
    abs_tol_hint,
    add_input_options,
    add_route_options,
    check_regularization,
    emit,
    integer_search,
    nonneg_float,
    nonneg_int,
    output_target,
    read_input,
    robust_payload,
    write_estimate,
)
from .robust import add_robust_options, robust_request


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


def _seconds(t: float) -> str:
    return f"{t:.2f} s" if t < 10 else f"{t:.1f} s"


def _certify_lines(file, payload: dict) -> list[str]:
    p, lc, tm = payload, payload["lago_certificate"], payload["timings"]
    lines = [
        f"certify: LAGO ({p['spanning_tree']} spanning tree, {p['regularization']} regularization) → χ² "
        f"Gauss–Newton → SE-Sync Newton → SE-Sync certificate, on {file}",
        f"  poses {p['n_poses']}, edges {p['n_edges']}"
        + (f" (the accepted edges of {p['n_edges_input']}: robust {p['robust']} rejected {p['n_rejected']} as "
           "outliers; everything below, the certificate too, is about the accepted edges)" if "robust" in p else "")
        + (f"; frame: pose {p['anchor']} as anchored (one anchor is a choice of frame)" if p["anchor"] is not None
           else ""),
        f"  chi2 (cost {p['cost']}, sum e'Ωe): LAGO estimate {p['chi2_lago']:.6g}, χ²-refined estimate "
        f"{p['chi2_refined']:.6g} ({p['refine_iterations']} GN iterations"
        f"{'' if p['refine_converged'] else ', not converged'})",
        f"  {p['cost_convention']}:",
        f"    LAGO estimate, poses as returned                         f = {p['f_lago']:.10g}",
        f"    χ²-refined estimate, poses as refined                    f = {p['f_chi2_refined']:.10g}",
        f"    SE-Sync-refined estimate, translations re-optimised      f = {p['f']:.12g}  ({p['sesync_iterations']} "
        "Newton iterations, " + ("converged)" if p["sesync_converged"] else f"not converged: {p['sesync_reason']})"),
        "  certificate of the SE-Sync-refined estimate: "
        + ("CERTIFIED globally optimal" if p["certified"] else "NOT certified"),
        f"    λ_min(S_Q) = {p['lambda_min']:.3g}; numerical floor η = {p['eta']:.3g} (1e-12 × ‖M‖₂ "
        f"{p['norm_M']:.4g})",
        f"    proven lower bound f* ≥ {_bound_text(p['lower_bound'], 12)}; relative suboptimality (f − bound)/f ≤ "
        f"{p['relative_suboptimality_bound']:.3g}; certified iff ≤ tol {p['tol']:.3g}"
        + (f", or by the absolute test (abs-tol {p['abs_tol']:.3g})" if p.get("abs_tol") else ""),
        f"    verdict: {p['verdict']}",
    ]
    if lc is None:
        lines.append("  comparison certificate of the raw LAGO estimate: not run (--compare-lago runs it; it is never "
                     "certified, its f being above the refined one)")
    else:
        lines += [
            "  comparison certificate of the raw LAGO estimate (--compare-lago): "
            + ("certified" if lc["certified"] else "NOT certified"),
            f"    at LAGO's rotations with the translations re-optimised for them: f = {lc['f']:.10g} "
            + (f"(with LAGO's own translations f = {p['f_lago']:.10g}, above)"
               if abs(lc["f"] - p["f_lago"]) > 1e-9 * max(abs(p["f_lago"]), 1e-300) else
               "(= f at LAGO's estimate above: its translations are already the optimal ones for its rotations)"),
            f"    verdict: {_reason(lc['verdict'])}"]
    steps = [("robust GNC", "robust"), ("LAGO", "lago"), ("χ² GN", "refine"), ("SE-Sync Newton", "refine_sesync"), ("certificate", "certify"),
             ("comparison certificate", "certify_lago")]
    lines.append("  time: " + ", ".join(f"{name} {_seconds(tm[key])}" for name, key in steps if key in tm)
                 + f"; total {_seconds(sum(tm.values()))}")
    return lines


def _certify_anchors(specs) -> dict | None:
    """``--anchor`` values as ``{id: (x, y, θ)}`` (a bare ``ID``: ``{id: None}``, the pose at the origin)."""
    if not specs:
        return None
    from .solve import parse_anchor_spec

    anchors = {}
    for spec in specs:
        if ":" in spec:
            pid, value = parse_anchor_spec(spec)
        else:
            try:
                pid, value = int(spec), None
            except ValueError:
                raise UsageError(f"bad anchor {spec!r}: expected ID or ID:X,Y,THETA") from None
        if pid in anchors:
            raise UsageError(f"anchor {pid} given twice")
        anchors[pid] = value
    if len(anchors) > 1:
        raise UsageError(f"certify takes at most one --anchor (a choice of frame), got {len(anchors)}: anchors at "
                         "several poses constrain the problem and the certificate is about the unconstrained optimum; "
                         "use solve --anchor to hold several poses")
    return anchors


def cmd_certify(args) -> int:
    from ..certification import certify_estimate
    from ..errors import GraphError

    out = output_target(args)
    graph = read_input(args)
    if graph.n_edges == 0:
        raise GraphError(f"{args.file}: the graph has {graph.n_poses} pose(s) and no edges: nothing to certify")
    written, robust = graph, None
    settings = robust_request(args, graph.dim)
    if settings is not None:  # certify LAGO on the edges GNC accepts (-o still writes every edge)
        robust = _robust_run(args, graph, settings)
        graph = robust.graph
    if graph.dim == 3:  # --anchor ID or ID:X,Y,Z,QX,QY,QZ,QW (cli/space.py)
        from .space import certify3d_cmd

        return certify3d_cmd(args, graph, out, written=written, robust=robust)
    anchors = _certify_anchors(args.anchor)
    check_regularization(graph, args.regularization)
    payload, cert = certify_estimate(graph, route=args.route, spanning_tree=args.spanning_tree,
                                     regularization=args.regularization, integer_search=integer_search(args),
                                     tol=args.tol, abs_tol=args.abs_tol, max_iterations=args.max_iterations,
                                     compare_lago=args.compare_lago, anchors=anchors)
    payload = {"file": str(args.file), "cost": graph.cost, **payload}
    if robust is not None:
        payload.update(robust_payload(args, written, robust))
        payload["timings"] = {"robust": robust.timings["robust"], **payload["timings"]}
    lines = _certify_lines(args.file, payload)
    if out is not None:
        write_estimate(out, written, cert.poses)
        payload["output"] = "<stdout>" if out == "-" else str(out)
        lines.append(f"  {'certified' if cert.certified else 'refined (NOT certified)'} estimate written to "
                     + ("standard output" if out == "-" else str(out)))
    status = EXIT_OK if cert.certified else EXIT_NOT_CERTIFIED
    if status != EXIT_OK:
        lines.append(f"  exit status {status}: not certified (a local minimum, an unconverged refinement, a "
                     "relaxation that is not tight, or a bound too weak for the cost's scale)"
                     + (f"; {abs_tol_hint(cert, args)}" if abs_tol_hint(cert, args) else ""))
    payload["exit_status"] = status
    emit(args, payload, lines, stdout_taken=out == "-")
    return status


def _robust_run(args, graph, settings):
    """``--robust``: GNC around LAGO with the command's route options (``lago(graph, robust=settings)``), planar or
    3-D."""
    from ..pipeline import lago

    if graph.dim == 3:
        return lago(graph, robust=settings, route=args.route)
    check_regularization(graph, args.regularization)
    return lago(graph, robust=settings, route=args.route, spanning_tree=args.spanning_tree,
                regularization=args.regularization, integer_search=integer_search(args))


def add_parser(sub) -> None:
    s = sub.add_parser(
        "certify", help="LAGO, refinement and SE-Sync's global-optimality certificate",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run LAGO on FILE, refine it (Gauss-Newton on the file's chi2 (--cost), then Newton on the SE-Sync cost f), and\n"
                    "verify global optimality with SE-Sync's Lagrangian-dual certificate (lago_cvx.certification).\n"
                    f"{SESYNC_COST_CONVENTION}.\nA point whose cost is above one already reached is never "
                    "certified; so the raw LAGO estimate never is,\nand its comparison certificate runs only with "
                    "--compare-lago (it costs as much as the certificate\nitself, or more). One --anchor is a choice "
                    "of frame (the certified estimate is moved rigidly to put\nthat pose there; the certificate is "
                    "unchanged); anchors at several poses are refused.",
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
                   help="certified when the proven relative suboptimality (f − f*_lower)/f ≤ TOL "
                        f"(0 < TOL ≤ {CERTIFY_TOL:g}, the default)")
    s.add_argument("--abs-tol", type=nonneg_float, default=0.0, metavar="ABS",
                   help="also certified when the proven gap f − f*_lower ≤ ABS or λ_min(S) ≥ −ABS (SE-Sync's "
                        "absolute test, in units of f; for nearly noise-free graphs, whose f is too small for any "
                        "relative test; default 0: none)")
    s.add_argument("--max-iterations", type=nonneg_int, default=50,
                   help="iterations of each refinement, chi2 and SE-Sync (default 50; 3-D: the SE-Sync refinement, "
                        "the only one)")
    s.add_argument("--compare-lago", action="store_true",
                   help="also certify the raw LAGO estimate, for comparison (never certified; its time is reported "
                        "apart)")
    s.add_argument("--anchor", action="append", metavar="ID[:X,Y,THETA]",
                   help="at most one: the pose ID (at the origin) or ID:X,Y,THETA (empty fields keep the estimate's "
                        "own; 3-D: ID:X,Y,Z,QX,QY,QZ,QW) fixes the frame of the written estimate; several poses are "
                        "refused")
    add_robust_options(s, calibrate=False, robust_help=(
        "first reject false loop closures as solve --robust does (graduated non-convexity), then certify LAGO on the "
        "accepted edges: chi2, f and the certificate are about them (JSON certified_edges = accepted, rejected_edges "
        "in file order); -o still writes every edge"))
    s.add_argument("--overwrite-input", action="store_true", help="allow -o to name the input file")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_certify)

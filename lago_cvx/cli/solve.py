"""``lago-cvx info`` and ``lago-cvx solve``."""

from __future__ import annotations

import math
import re

import numpy as np

from ..errors import LagoError
from ..routes import resolve_route
from .common import (
    EXIT_OK,
    UsageError,
    add_input_options,
    add_route_options,
    check_fields,
    check_finite,
    check_line,
    check_regularization,
    emit,
    graph_lines,
    integer_search,
    method_arg,
    nonneg_int,
    output_target,
    progress_callback,
    read_input,
    route_information,
    speak_cli,
    write_estimate,
)
from .robust import add_robust_options, robust_request

_FIELD = r"\s*([^,]*)\s*"
_SPEC = re.compile(r"^\s*([+-]?\d+)\s*:" + _FIELD + "," + _FIELD + "," + _FIELD + "$")


def parse_anchor_spec(spec: str) -> tuple[int, tuple]:
    """Parse ``"ID:X,Y,THETA"`` → ``(id, (x, y, θ))``; empty fields give None (partial anchors):
    ``"5:,,1.57"`` orientation only, ``"5:1,2,"`` position only. Raises ``UsageError`` naming the
    spec when it is malformed, when only one of X, Y is given, or when all three are empty."""
    m = _SPEC.match(spec)
    if not m:
        raise UsageError(f"bad anchor {spec!r}: expected ID:X,Y,THETA (empty fields allowed, e.g. 5:,,1.57)")
    vals = []
    for name, text in zip("x y theta".split(), m.groups()[1:]):
        text = text.strip()
        if text == "":
            vals.append(None)
            continue
        try:
            v = float(text)
        except ValueError:
            raise UsageError(f"bad anchor {spec!r}: {name} = {text!r} is not a number") from None
        if not math.isfinite(v):
            raise UsageError(f"bad anchor {spec!r}: {name} must be finite")
        vals.append(v)
    if (vals[0] is None) != (vals[1] is None):
        raise UsageError(f"bad anchor {spec!r}: give both X and Y, or neither")
    if all(v is None for v in vals):
        raise UsageError(f"bad anchor {spec!r}: at least the position or the orientation must be given")
    return int(m.group(1)), tuple(vals)


def _parse_anchors(specs) -> tuple[int | None, dict]:
    """``--anchor`` values: one bare ``ID`` picks the anchor pose of plain LAGO; ``ID:X,Y,THETA``
    (repeatable, empty fields for partial anchors) fixes poses exactly (``lago_cvx.variants``)."""
    if not specs:
        return None, {}
    if len(specs) == 1 and specs[0].strip().lstrip("-").isdigit():
        return int(specs[0]), {}
    anchors = {}
    for spec in specs:
        try:
            pid, value = parse_anchor_spec(spec)
        except UsageError as exc:
            raise UsageError(f"{exc} (a bare ID is accepted only alone)") from None
        if pid in anchors:
            raise UsageError(f"anchor {pid} given twice")
        anchors[pid] = value
    return None, anchors


# ------------------------------------------------------------------------------------- info
def cmd_info(args) -> int:
    from ..graph import connected_components, spanning_tree
    from ..io import detect_format
    from ..regularization import regularize

    graph = read_input(args)
    if graph.dim == 3:
        from .space import info3d

        return info3d(args, graph)
    k, _ = connected_components(graph)
    payload = {
        "file": str(args.file), "format": detect_format(args.file), "cost": graph.cost,
        "n_poses": graph.n_poses, "n_edges": graph.n_edges,
        "n_odometric": graph.n_odometric, "n_loop_closures": graph.n_loop_closures,
        "n_components": int(k), "cyclomatic_number": int(graph.n_edges - graph.n_poses + k),
        "has_initial_guess": graph.initial is not None,
        "spanning_tree": args.spanning_tree, "regularization": args.regularization, "n_regularized": None,
        "n_ambiguous": None,
    }
    note = ""
    if k == 1:
        try:
            check_regularization(graph, args.regularization)
            choice, _ = resolve_route(args.route, spanning_tree=args.spanning_tree,
                                      regularization=args.regularization)
            payload.update(spanning_tree=choice["spanning_tree"], regularization=choice["regularization"])
            reg = regularize(graph, spanning_tree(graph, choice["spanning_tree"]),
                             regularization=choice["regularization"], search=integer_search(args))
            payload["n_regularized"] = reg.n_regularized
            payload["n_ambiguous"] = int(reg.ambiguous.size)
        except LagoError as exc:  # e.g. broken odometric chain: report, don't fail the whole info
            if exc.exit_status != 2:
                raise
            note = speak_cli(str(exc))
            payload["note"] = note
    else:
        note = "graph is not connected: no spanning tree"
        payload["note"] = note
    lines = [
        f"file              {args.file} ({payload['format']}; cost {graph.cost})",
        *graph_lines(graph, k, payload["cyclomatic_number"]),
        f"regularized ({payload['regularization']}, {payload['spanning_tree']} tree) "
        + (f"{payload['n_regularized']} cycles need a 2kπ correction" if payload["n_regularized"] is not None
           else f"n/a: {note}"),
    ]
    emit(args, payload, lines)
    return EXIT_OK


# ------------------------------------------------------------------------------------ solve
def cmd_solve(args) -> int:
    out = output_target(args)
    graph = read_input(args)
    calibrate = args.robust_calibrate
    args.robust_settings = robust_request(args, graph.dim)  # None, or the RobustSettings of the --robust options
    if graph.dim == 3:
        from .space import solve3d

        return solve3d(args, graph, out)
    from ..metrics import chi2
    from ..pipeline import compare_methods, lago
    from ..posegraph import compose

    def compose_anchor(res, poses):  # phase 3's poses in the output frame (an anchored run's are already)
        return poses if anchors else compose(np.broadcast_to(res.anchor_pose, poses.shape), poses)

    anchor, anchors = _parse_anchors(args.anchor)
    check_regularization(graph, args.regularization)
    kw = dict(route=args.route, spanning_tree=args.spanning_tree, anchor=anchor, regularization=args.regularization,
              information=route_information(args), positions=args.positions, integer_search=integer_search(args))
    if anchors:
        kw["anchors"] = anchors
    if args.robust:
        kw["robust"] = args.robust_settings
    if args.check:
        res, report = compare_methods(graph, **kw)
    elif anchors and not args.robust:  # the variants engine directly: it honours every option of lago (the integer limits too)
        from ..variants import anchored_lago

        res, report = anchored_lago(graph, method=args.method, progress=progress_callback(args), **kw), None
    else:
        res, report = lago(graph, method=args.method, progress=progress_callback(args), **kw), None
    check_finite(res.chi2, res.poses, what="LAGO estimate")
    reg = res.regularization
    solved = res.graph  # the accepted edges of a robust run (χ² is over them), else the graph read
    payload = {
        "file": str(args.file), "n_poses": graph.n_poses, "n_edges": graph.n_edges,
        "cost": graph.cost, "method": "closed_form" if args.check else args.method, "spanning_tree": res.tree.kind,
        "regularization": reg.regularization, "n_chords": int(reg.chords.size), "n_regularized": reg.n_regularized,
        "n_ambiguous": int(reg.ambiguous.size), "route": res.route, "information": res.information,
        "positions": res.positions, "chi2": res.chi2,  # χ² of the poses returned (phase 3's, or re-solved)
        "timings": {k: res.timings[k] for k in ("regularization", "phase1", "phase2", "phase3", "positions",
                                                "total")},
    }
    if res.polish is not None:
        payload["chi2_phase3"] = chi2(solved, compose_anchor(res, res.phase3.poses))
        payload["positions_alpha"] = res.polish.alpha
    payload["timings"]["regularization"] += res.timings["tree"]
    if graph.initial is not None:
        payload["chi2_initial"] = chi2(solved, graph.initial)
    if args.robust:
        payload.update(robust=args.robust, chi2_edges="accepted", n_rejected=int(res.rejected_edges.size),
                       rejected_edges=res.rejected_edges.tolist(), robust_iterations=res.iterations,
                       robust_threshold=res.settings.c2_for(2))
        if calibrate is not None:  # the c̄² of the run returned: calibrated, or the default where that run was kept
            payload.update(robust_calibrate=calibrate,
                           robust_calibrated=res.settings.threshold != args.robust_settings.threshold)
        payload["timings"]["robust"] = res.timings["robust"]
    strained = getattr(res, "strained", None)
    if anchors:
        payload["anchors"] = {str(k): list(v) for k, v in anchors.items()}
        payload["strained_anchors"] = [int(a) for a in (strained or [])]
    if report is not None:
        payload.update(check_fields(report, args.robust))
    final = res.poses
    if args.refine:
        from ..refinement import refine

        # the poses the user fixed stay fixed: the anchors' known coordinates (or the bare anchor pose) are held
        ref = refine(solved, res.poses, method=args.refine_method, max_iterations=args.max_iterations,
                     anchor=anchor if anchor is not None else res.anchor, anchors=anchors or None)
        check_finite(ref.chi2, ref.poses, what="refined estimate")
        final = ref.poses
        payload["chi2_refined"] = ref.chi2
        payload["refine_iterations"] = ref.iterations
        payload["refine_converged"] = ref.converged
        payload["timings"]["refine"] = ref.log[-1]["time"] if ref.log else 0.0
    if out is not None:
        write_estimate(out, graph, final)
        payload["output"] = "<stdout>" if out == "-" else str(out)
    t = payload["timings"]
    lines = [
        f"LAGO ({payload['method'].replace('_', '-')}, {res.route} route: {res.tree.kind} spanning tree, "
        f"{reg.regularization} regularization, {res.information} information, {res.positions} positions) on "
        f"{args.file}",
        f"  poses {graph.n_poses}, edges {graph.n_edges}, chords {reg.chords.size}, "
        f"regularized {reg.n_regularized}, ambiguous {reg.ambiguous.size}",
        *([f"  robust ({args.robust}, c̄² = {res.settings.c2_for(2):.4g}"
           + ((" calibrated on the odometry" if payload["robust_calibrated"] else " (the default run kept)")
              if calibrate is not None else "")
           + f"): {res.rejected_edges.size} of {graph.n_edges} edges rejected as outliers "
           f"after {res.iterations} GNC iterations ({res.timings['robust']:.3f} s); every chi2 below is over the "
           f"{solved.n_edges} accepted edges"] if args.robust else []),
        f"  chi2 = {res.chi2:.6g}  (cost {graph.cost}: sum e'Ωe, no 1/2)"
        + (f"; phase 3's poses {payload['chi2_phase3']:.6g}" if "chi2_phase3" in payload else "")
        + (f"; at the file's initial guess {payload['chi2_initial']:.6g}" if "chi2_initial" in payload else ""),
        f"  time [s]: regularization {t['regularization']:.4f}, phase1 {t['phase1']:.4f}, "
        f"phase2 {t['phase2']:.4f}, phase3 {t['phase3']:.4f}, positions {t['positions']:.4f}, total {t['total']:.4f}",
    ]
    if report is not None:
        lines.append(check_line(report, args.robust))
    if anchors:
        lines.append(f"  anchors {sorted(anchors)}; strained: {payload['strained_anchors'] or 'none'}")
    if args.refine:
        lines.append(f"  refined ({args.refine_method}): chi2 = {payload['chi2_refined']:.6g} after "
                     f"{payload['refine_iterations']} iterations"
                     + ("" if payload["refine_converged"] else " (not converged)"))
    if out is not None:
        lines.append(f"  {'refined ' if args.refine else ''}estimate written to "
                     + ("standard output" if out == "-" else str(out)))
    emit(args, payload, lines, stdout_taken=out == "-")
    return EXIT_OK


def add_parsers(sub) -> None:
    s = sub.add_parser("info", help="counts of a pose-graph file")
    s.add_argument("file")
    add_input_options(s)
    add_route_options(s)
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("solve", help="run LAGO on a file")
    s.add_argument("file")
    add_input_options(s, information=False)
    s.add_argument("-o", "--output", metavar="OUT",
                   help="write the estimate as g2o to OUT (- for standard output; the summary then goes to "
                        "standard error). A regular file is replaced atomically, a link is written through, "
                        "a FIFO or device is written to")
    s.add_argument("--method", type=method_arg, default="closed_form", help="closed-form (default) or cvxpy")
    add_route_options(s, phases=True)
    s.add_argument("--anchor", action="append", metavar="ID[:X,Y,THETA]",
                   help="ID alone: the pose held at the origin (default: smallest id); ID:X,Y,THETA "
                        "(repeatable; leave fields empty for partial anchors, e.g. 7:,,1.57): poses known exactly; "
                        "on a 3-D file ID:X,Y,Z,QX,QY,QZ,QW (all seven fields)")
    s.add_argument("--check", action="store_true", help="solve both ways and report the largest relative "
                                                        "difference per phase")
    add_robust_options(s, calibrate=True, robust_help=(
        "reject false loop closures by graduated non-convexity around weighted LAGO runs (truncated least squares); "
        "odometric edges trusted when the odometric chain is complete. JSON gives rejected_edges (indices of EDGE "
        "records in file order); chi2 (and --refine) are over the accepted edges"))
    s.add_argument("--refine", action="store_true", help="refine the LAGO estimate on the full nonlinear cost (--cost; "
                                                         "with --robust: on the accepted edges)")
    s.add_argument("--refine-method", choices=["gauss-newton", "levenberg-marquardt"], default="gauss-newton")
    s.add_argument("--max-iterations", type=nonneg_int, default=50, help="refinement iterations (default 50)")
    s.add_argument("--overwrite-input", action="store_true", help="allow -o to name the input file")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_solve)

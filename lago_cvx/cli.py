"""Command-line interface ``lago-cvx`` (also ``python -m lago_cvx``).

Sub-commands: ``info``, ``solve``, ``certify``, ``generate``, ``demo``. Exit status: 0 success, 2 bad input
(unreadable or malformed file, unusable graph, bad option), 1 internal error, 3 (``certify`` only) the
estimate was computed but is **not** certified globally optimal. Errors are printed as one line
``lago-cvx: error: …`` on stderr, never as a traceback (set ``LAGO_CVX_DEBUG=1`` to see one).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import re
import sys

from pathlib import Path

import numpy as np

from ._version import __version__
from .errors import LagoError, OptionError
from .regularization import MAX_INTEGER_CHORDS, REGULARIZATIONS
from .routes import POSITIONS, ROUTES, resolve_route
from .uncertainty import INFORMATION_MODES

EXIT_OK, EXIT_INTERNAL, EXIT_BAD_INPUT = 0, 1, 2
#: ``certify``: the refined estimate is not certified globally optimal (the report is still printed).
EXIT_NOT_CERTIFIED = 3

REGULARIZATION_HELP = ("2kπ regularization: tree (the seed's rounding along the spanning tree), chordal (round "
                       "every edge against the chordal relaxation), integer (weighted integer least squares of "
                       "the cycle integers, exact; small/medium graphs); default: the route's")
ROUTE_HELP = ("default (BFS tree, chordal regularization, full information, positions re-solved: chosen by "
              "measurement, see the README) or seed (exactly the paper's procedure: odometric tree, tree "
              "rounding, blkdiag(P_Δ, P_δ), phase-3 poses)")

log = logging.getLogger("lago_cvx")


class UsageError(OptionError):
    """A bad option value or a refused action (exit status 2)."""


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


def _tree_arg(value: str) -> str:
    v = value.replace("-", "_").lower()
    if v not in ("bfs", "odometry", "mst"):
        raise argparse.ArgumentTypeError(f"unknown spanning tree {value!r} (choose bfs, odometry or mst)")
    return v


def _method_arg(value: str) -> str:
    v = value.replace("-", "_").lower()
    if v not in ("closed_form", "cvxpy"):
        raise argparse.ArgumentTypeError(f"unknown method {value!r} (choose closed-form or cvxpy)")
    return v


def _strict(obj):
    """Non-finite floats become null: the output must be strict JSON (RFC 8259 has no NaN/Infinity)."""
    if isinstance(obj, dict):
        return {k: _strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_strict(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def _check_regularization(graph, regularization: str) -> None:
    """Refuse ``integer`` on graphs with more than ``MAX_INTEGER_CHORDS`` independent cycles (its cycle
    covariance is dense in their number) with a usage error instead of an internal one."""
    if regularization != "integer":
        return
    from .graph import connected_components

    k, _ = connected_components(graph)
    n_cycles = graph.n_edges - graph.n_poses + k
    if n_cycles > MAX_INTEGER_CHORDS:
        raise UsageError(f"--regularization integer works with a dense {n_cycles} x {n_cycles} cycle covariance; "
                         f"this graph has {n_cycles} independent cycles (more than {MAX_INTEGER_CHORDS}): "
                         "use --regularization chordal")


def _emit(args, payload: dict, lines: list[str]) -> None:
    if getattr(args, "json", False):
        print(json.dumps(_strict(payload), allow_nan=False))
    else:
        print("\n".join(lines))


# ----------------------------------------------------------------------------- info
def cmd_info(args) -> int:
    from .graph import connected_components, spanning_tree
    from .io import detect_format, read_graph
    from .regularization import regularize

    graph = read_graph(args.file)
    k, _ = connected_components(graph)
    payload = {
        "file": str(args.file), "format": detect_format(args.file),
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
            _check_regularization(graph, args.regularization)
            choice, _ = resolve_route(args.route, spanning_tree=args.spanning_tree,
                                      regularization=args.regularization)
            payload.update(spanning_tree=choice["spanning_tree"], regularization=choice["regularization"])
            reg = regularize(graph, spanning_tree(graph, choice["spanning_tree"]),
                             regularization=choice["regularization"])
            payload["n_regularized"] = reg.n_regularized
            payload["n_ambiguous"] = int(reg.ambiguous.size)
        except LagoError as exc:  # e.g. broken odometric chain: report, don't fail the whole info
            note = str(exc)
            payload["note"] = note
    else:
        note = "graph is not connected: no spanning tree"
        payload["note"] = note
    lines = [
        f"file              {args.file} ({payload['format']})",
        f"poses             {graph.n_poses}" + ("" if graph.initial is not None else "  (no initial guess)"),
        f"edges             {graph.n_edges}",
        f"odometric edges   {graph.n_odometric}  (consecutive ids)",
        f"loop closures     {graph.n_loop_closures}",
        f"components        {k}",
        f"cyclomatic number {payload['cyclomatic_number']}  (l = m - n + components)",
        f"regularized ({args.regularization}, {args.spanning_tree} tree) "
        + (f"{payload['n_regularized']} cycles need a 2kπ correction" if payload["n_regularized"] is not None
           else f"n/a: {note}"),
    ]
    _emit(args, payload, lines)
    return EXIT_OK


# ---------------------------------------------------------------------------- solve
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


def _check_output(args) -> Path | None:
    if not args.output:
        return None
    out = Path(args.output)
    src = Path(args.file)
    if out.exists() and src.exists() and out.resolve() == src.resolve() and not args.overwrite_input:
        raise UsageError(f"refusing to overwrite the input file {src} with the estimate "
                         "(pass --overwrite-input to allow it)")
    return out


def cmd_solve(args) -> int:
    from .io import read_graph, write_graph
    from .metrics import chi2
    from .pipeline import compare_methods, lago
    from .posegraph import compose

    def compose_anchor(res, poses):
        return compose(np.broadcast_to(res.anchor_pose, poses.shape), poses)

    out = _check_output(args)
    anchor, anchors = _parse_anchors(args.anchor)
    graph = read_graph(args.file)
    _check_regularization(graph, args.regularization)
    kw = dict(route=args.route, spanning_tree=args.spanning_tree, anchor=anchor, regularization=args.regularization,
              information=args.information, positions=args.positions)
    if anchors:
        kw["anchors"] = anchors
    if args.check:
        res, report = compare_methods(graph, **kw)
    else:
        res, report = lago(graph, method=args.method, **kw), None
    reg = res.regularization
    payload = {
        "file": str(args.file), "n_poses": graph.n_poses, "n_edges": graph.n_edges,
        "method": "closed_form" if args.check else args.method, "spanning_tree": res.tree.kind,
        "regularization": reg.regularization, "n_chords": int(reg.chords.size), "n_regularized": reg.n_regularized,
        "n_ambiguous": int(reg.ambiguous.size), "route": res.route, "information": res.information,
        "positions": res.positions, "chi2": res.chi2,  # χ² of the poses returned (phase 3's, or re-solved)
        "timings": {k: res.timings[k] for k in ("regularization", "phase1", "phase2", "phase3", "positions",
                                                "total")},
    }
    if res.polish is not None:
        payload["chi2_phase3"] = chi2(graph, compose_anchor(res, res.phase3.poses))
        payload["positions_alpha"] = res.polish.alpha
    payload["timings"]["regularization"] += res.timings["tree"]
    if graph.initial is not None:
        payload["chi2_initial"] = chi2(graph, graph.initial)
    strained = getattr(res, "strained", None)
    if anchors:
        payload["anchors"] = {str(k): list(v) for k, v in anchors.items()}
        payload["strained_anchors"] = [int(a) for a in (strained or [])]
    if report is not None:
        payload["max_rel_diff"] = report["max_rel_diff"]
        payload["cvxpy_timings"] = report["cvxpy_timings"]
    final = res.poses
    if args.refine:
        from .refinement import refine

        ref = refine(graph, res.poses, method=args.refine_method, max_iterations=args.max_iterations)
        final = ref.poses
        payload["chi2_refined"] = ref.chi2
        payload["refine_iterations"] = ref.iterations
        payload["refine_converged"] = ref.converged
        payload["timings"]["refine"] = ref.log[-1]["time"] if ref.log else 0.0
    if out is not None:
        write_graph(out, graph, final)
        payload["output"] = str(out)
    t = payload["timings"]
    lines = [
        f"LAGO ({payload['method'].replace('_', '-')}, {res.route} route: {res.tree.kind} spanning tree, "
        f"{reg.regularization} regularization, {res.information} information, {res.positions} positions) on "
        f"{args.file}",
        f"  poses {graph.n_poses}, edges {graph.n_edges}, chords {reg.chords.size}, "
        f"regularized {reg.n_regularized}, ambiguous {reg.ambiguous.size}",
        f"  chi2 = {res.chi2:.6g}  (g2o convention: sum e'Ωe, no 1/2)"
        + (f"; phase 3's poses {payload['chi2_phase3']:.6g}" if "chi2_phase3" in payload else "")
        + (f"; at the file's initial guess {payload['chi2_initial']:.6g}" if "chi2_initial" in payload else ""),
        f"  time [s]: regularization {t['regularization']:.4f}, phase1 {t['phase1']:.4f}, "
        f"phase2 {t['phase2']:.4f}, phase3 {t['phase3']:.4f}, positions {t['positions']:.4f}, total {t['total']:.4f}",
    ]
    if report is not None:
        d = report["max_rel_diff"]
        lines.append("  cvxpy vs closed form, max relative difference: "
                     + ", ".join(f"{k} {v:.2e}" for k, v in d.items()))
    if anchors:
        lines.append(f"  anchors {sorted(anchors)}; strained: {payload['strained_anchors'] or 'none'}")
    if args.refine:
        lines.append(f"  refined ({args.refine_method}): chi2 = {payload['chi2_refined']:.6g} after "
                     f"{payload['refine_iterations']} iterations"
                     + ("" if payload["refine_converged"] else " (not converged)"))
    if out is not None:
        lines.append(f"  {'refined ' if args.refine else ''}estimate written to {out}")
    _emit(args, payload, lines)
    return EXIT_OK


# -------------------------------------------------------------------------- certify
def _tol_arg(value: str) -> float:
    try:
        tol = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tol must be a number, got {value!r}") from None
    if not (np.isfinite(tol) and tol > 0):
        raise argparse.ArgumentTypeError(f"--tol must be a finite number > 0, got {value!r}")
    return tol


def _bound_text(bound: float, digits: int) -> str:
    return f"{bound:.{digits}g}" + (" (vacuous: f ≥ 0 always)" if bound <= 0 else "")


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
        f"  LAGO estimate alone: {'certified' if lc['certified'] else 'NOT certified'}, "
        f"proven f* ≥ {_bound_text(lc['lower_bound'], 10)}",
        f"  SE-Sync-refined:     {'CERTIFIED globally optimal' if p['certified'] else 'NOT certified'}",
        f"    λ_min(S_Q) = {p['lambda_min']:.3g}, η = {p['eta']:.3g} (tol {p['tol']:.3g} × ‖M‖₂ {p['norm_M']:.4g}); "
        "certified iff λ_min(S_Q) ≥ −η",
        f"    proven lower bound f* ≥ {_bound_text(p['lower_bound'], 12)}; relative suboptimality (f − bound)/f ≤ "
        f"{p['relative_suboptimality_bound']:.3g}",
        f"    verdict: {p['verdict']}",
    ]


def cmd_certify(args) -> int:
    from .certification import certify_estimate
    from .errors import GraphError
    from .io import read_graph, write_graph

    if args.max_iterations < 0:
        raise UsageError("--max-iterations must be >= 0")
    out = _check_output(args)
    graph = read_graph(args.file)
    if graph.n_edges == 0:
        raise GraphError(f"{args.file}: the graph has {graph.n_poses} pose(s) and no edges: nothing to certify")
    _check_regularization(graph, args.regularization)
    payload, cert = certify_estimate(graph, route=args.route, spanning_tree=args.spanning_tree,
                                     regularization=args.regularization,
                                     tol=args.tol, max_iterations=args.max_iterations)
    payload = {"file": str(args.file), **payload}
    lines = _certify_lines(args.file, payload)
    if out is not None:
        write_graph(out, graph, cert.poses)
        payload["output"] = str(out)
        lines.append(f"  {'certified' if cert.certified else 'refined (NOT certified)'} estimate written to {out}")
    status = EXIT_OK if cert.certified else EXIT_NOT_CERTIFIED
    if status != EXIT_OK:
        lines.append(f"  exit status {status}: not certified (a local minimum, an unconverged refinement, or a "
                     "relaxation that is not tight)")
    payload["exit_status"] = status
    _emit(args, payload, lines)
    return status


# ------------------------------------------------------------------------- generate
def _world(kind: str, poses: int, seed: int, sigma_xy: float | None, sigma_theta: float | None, laps: float):
    from . import synthetic

    kw = {}
    if sigma_xy is not None:
        kw["sigma_xy"] = sigma_xy
    if sigma_theta is not None:
        kw["sigma_theta"] = sigma_theta
    if kind == "manhattan":
        return synthetic.manhattan_world(poses, seed=seed, **kw)
    return synthetic.circle_world(poses, seed=seed, laps=laps, **kw)


def cmd_generate(args) -> int:
    from .io import write_graph

    if args.poses < 2:
        raise UsageError("--poses must be at least 2")
    world = _world(args.world, args.poses, args.seed, args.sigma_xy, args.sigma_theta, args.laps)
    out = Path(args.output)
    truth_path = Path(args.truth) if args.truth else out.with_name(out.stem + ".truth" + (out.suffix or ".g2o"))
    write_graph(out, world.graph)  # vertices = dead-reckoning guess, as in real datasets
    write_graph(truth_path, world.graph, world.truth)  # same edges, vertices = ground truth
    g = world.graph
    payload = {"output": str(out), "truth": str(truth_path), "world": args.world, "seed": args.seed,
               "n_poses": g.n_poses, "n_edges": g.n_edges, "n_loop_closures": g.n_loop_closures}
    _emit(args, payload, [f"wrote {out}: {args.world} world, {g.n_poses} poses, {g.n_edges} edges "
                          f"({g.n_loop_closures} loop closures), seed {args.seed}; vertices = dead-reckoning guess",
                          f"wrote {truth_path}: same edges, vertices = ground truth"])
    return EXIT_OK


# ----------------------------------------------------------------------------- demo
def cmd_demo(args) -> int:
    from .metrics import ate, chi2
    from .pipeline import compare_methods

    world = _world("manhattan", args.poses, args.seed, None, None, 1.0)
    g, truth = world.graph, world.truth
    res, report = compare_methods(g, anchor_pose=truth[0])
    d = report["max_rel_diff"]
    payload = {
        "n_poses": g.n_poses, "n_edges": g.n_edges, "seed": args.seed,
        "n_regularized": res.regularization.n_regularized,
        "chi2": {"lago": res.chi2, "truth": chi2(g, truth), "odometry": chi2(g, g.initial)},
        "ate": {"lago": ate(res.poses, truth, align=False), "odometry": ate(g.initial, truth, align=False)},
        "max_rel_diff": d, "timings": res.timings, "cvxpy_timings": report["cvxpy_timings"],
    }
    lines = [
        f"Synthetic Manhattan world: {g.n_poses} poses, {g.n_edges} edges ({g.n_loop_closures} loop closures), "
        f"seed {args.seed}",
        f"  regularization: {res.regularization.n_regularized} of {res.regularization.chords.size} chords "
        "needed a 2kπ correction",
        "  chi2 (g2o convention, sum e'Ωe):",
        f"    odometric guess {payload['chi2']['odometry']:12.4f}",
        f"    LAGO            {payload['chi2']['lago']:12.4f}",
        f"    ground truth    {payload['chi2']['truth']:12.4f}",
        f"  trajectory error (RMS position vs truth): odometry {payload['ate']['odometry']:.4f} m, "
        f"LAGO {payload['ate']['lago']:.4f} m",
        f"  cvxpy (Clarabel) vs closed form, max relative difference: phase1 {d['phase1']:.2e}, "
        f"phase3 {d['phase3']:.2e}",
        f"  closed form {res.timings['total']:.3f} s; cvxpy phase1 {report['cvxpy_timings']['phase1']:.3f} s, "
        f"phase3 {report['cvxpy_timings']['phase3']:.3f} s",
    ]
    if not args.no_figure:
        path = _demo_figure(g, truth, res.poses, Path(args.out_dir))
        payload["figure"] = str(path)
        lines.append(f"  figure: {path}")
    _emit(args, payload, lines)
    return EXIT_OK


def _demo_figure(graph, truth, est, out_dir: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plotting import plot_edges, plot_trajectory

    out_dir.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 3, figsize=(15, 5), constrained_layout=True)
    for ax, poses, title in zip(axes, [graph.initial, est, truth],
                                ["odometric guess (dead reckoning)", "LAGO estimate", "ground truth"]):
        plot_edges(ax, graph, poses, which="loop_closures", linewidth=0.3, alpha=0.3)
        if poses is not truth:
            plot_trajectory(ax, truth, color="tab:green", linewidth=2.0, alpha=0.35, label="ground truth")
        plot_trajectory(ax, poses, color="k", linewidth=0.8, label=title.split(" (")[0])
        ax.set_title(title)
        ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"lago-cvx demo: synthetic Manhattan world, {graph.n_poses} poses, {graph.n_edges} edges "
                 "(loop closures in red); all three share the anchor pose 0")
    path = out_dir / "demo.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# ----------------------------------------------------------------------------- main
def _route_options(s, *, phases: bool = False) -> None:
    """--route and the choices it makes (left unset: the route's)."""
    s.add_argument("--route", choices=list(ROUTES), default="default", help=ROUTE_HELP)
    s.add_argument("--spanning-tree", type=_tree_arg, default=None,
                   help="bfs, odometry or mst (default: the route's: bfs, or odometry for --route seed)")
    s.add_argument("--regularization", choices=list(REGULARIZATIONS), default=None, help=REGULARIZATION_HELP)
    if phases:
        s.add_argument("--information", choices=list(INFORMATION_MODES), default=None,
                       help="full (each edge's 3×3 information in phases 2–3) or marginal (the seed's "
                            "blkdiag(P_Δ, P_δ)); default: the route's")
        s.add_argument("--positions", choices=list(POSITIONS), default=None,
                       help="phase3 (the seed's poses) or resolve (positions re-solved exactly for the "
                            "orientations); default: the route's")


def build_parser() -> argparse.ArgumentParser:
    from .certification.estimate import SESYNC_COST_CONVENTION

    p = argparse.ArgumentParser(prog="lago-cvx", description="LAGO for planar pose graphs (g2o / TORO files).")
    p.add_argument("--version", action="version", version=f"lago-cvx {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0, help="log progress (-vv for debug)")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("info", help="counts of a pose-graph file")
    s.add_argument("file")
    _route_options(s)
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("solve", help="run LAGO on a file")
    s.add_argument("file")
    s.add_argument("-o", "--output", help="write the estimate as g2o to this path")
    s.add_argument("--method", type=_method_arg, default="closed_form", help="closed-form (default) or cvxpy")
    _route_options(s, phases=True)
    s.add_argument("--anchor", action="append", metavar="ID[:X,Y,THETA]",
                   help="ID alone: the pose held at the origin (default: smallest id); ID:X,Y,THETA "
                        "(repeatable; leave fields empty for partial anchors, e.g. 7:,,1.57): poses known exactly")
    s.add_argument("--check", action="store_true", help="solve both ways and report the largest relative "
                                                        "difference per phase")
    s.add_argument("--refine", action="store_true", help="refine the LAGO estimate on the full cost eq. (3)")
    s.add_argument("--refine-method", choices=["gauss-newton", "levenberg-marquardt"], default="gauss-newton")
    s.add_argument("--max-iterations", type=int, default=50, help="refinement iterations (default 50)")
    s.add_argument("--overwrite-input", action="store_true", help="allow -o to name the input file")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_solve)

    s = sub.add_parser(
        "certify", help="LAGO, refinement and SE-Sync's global-optimality certificate",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run LAGO on FILE, refine it (Gauss-Newton on the g2o chi2, then Newton on the SE-Sync cost f), and\n"
                    "verify global optimality with SE-Sync's Lagrangian-dual certificate (lago_cvx.certification).\n"
                    f"{SESYNC_COST_CONVENTION}.\nThe raw LAGO estimate is certified too, for comparison.",
        epilog=f"exit status: {EXIT_OK} certified globally optimal; {EXIT_NOT_CERTIFIED} NOT certified (the report is "
               f"still printed\nand -o still written); {EXIT_BAD_INPUT} bad input (malformed file, no edges, "
               f"graph not connected,\nbad option); {EXIT_INTERNAL} internal error.")
    s.add_argument("file")
    s.add_argument("-o", "--output", help="write the SE-Sync-refined estimate (the poses the certificate is "
                                          "about) as g2o to this path")
    _route_options(s)
    s.add_argument("--tol", type=_tol_arg, default=1e-12, metavar="TOL",
                   help="relative PSD tolerance: certified iff λ_min(S_Q) ≥ −η, η = TOL·‖M‖₂ "
                        "(default 1e-12 = lago_cvx.certification.CERTIFY_TOL)")
    s.add_argument("--max-iterations", type=int, default=50,
                   help="iterations of each refinement, chi2 and SE-Sync (default 50)")
    s.add_argument("--overwrite-input", action="store_true", help="allow -o to name the input file")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_certify)

    s = sub.add_parser("generate", help="write a seeded synthetic world (g2o) and its ground truth")
    s.add_argument("--world", choices=["manhattan", "circle"], default="manhattan")
    s.add_argument("--poses", type=int, default=500)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--sigma-xy", type=float, default=None, help="position noise std [m]")
    s.add_argument("--sigma-theta", type=float, default=None, help="orientation noise std [rad]")
    s.add_argument("--laps", type=float, default=3.0, help="circle world: number of turns")
    s.add_argument("-o", "--output", required=True, help="graph file (vertices = dead-reckoning guess)")
    s.add_argument("--truth", help="ground-truth file (default: OUTPUT with .truth before the suffix)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_generate)

    s = sub.add_parser("demo", help="the main job on the embedded default: synthetic world, LAGO both ways")
    s.add_argument("--poses", type=int, default=1000)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out-dir", default="figures", help="where demo.png goes (default: figures)")
    s.add_argument("--no-figure", action="store_true")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_demo)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)],
                        format="lago-cvx: %(levelname)s: %(message)s")
    try:
        return args.func(args)
    except LagoError as exc:  # everything the package reports on purpose; the class carries the status
        if exc.exit_status == EXIT_INTERNAL and os.environ.get("LAGO_CVX_DEBUG"):
            raise
        print(f"lago-cvx: {'internal ' if exc.exit_status == EXIT_INTERNAL else ''}error: {exc}", file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print("lago-cvx: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # an internal error: one line, exit 1 (traceback with LAGO_CVX_DEBUG=1)
        if os.environ.get("LAGO_CVX_DEBUG"):
            raise
        print(f"lago-cvx: internal error: {type(exc).__name__}: {exc} "
              "(set LAGO_CVX_DEBUG=1 for a traceback)", file=sys.stderr)
        return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())

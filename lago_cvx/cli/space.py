"""The commands on 3-D graphs (``graph.dim == 3``, ``lago_cvx.space``): ``info``, ``solve``, ``certify`` and the 3-D
worlds of ``generate``. The planar commands hand over here after reading the file (with ``--cost`` and
``--information``); every χ² is the graph's cost (``graph.cost``, named by the key ``"cost"``). JSON keys are the
planar ones where they mean the same, plus ``dim``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..conventions import CHI2_CONVENTION, COST_DESCRIPTION
from .common import (EXIT_NOT_CERTIFIED, EXIT_OK, UsageError, check_finite, emit, graph_lines, robust_payload,
                     sigma_keywords, write_estimate)

WORLDS3D = ("sphere3d", "torus3d", "grid3d")


def _components(graph) -> int:
    from ..graph import connected_components

    return connected_components(graph)[0]


def info3d(args, graph) -> int:
    k = _components(graph)
    payload = {"file": str(args.file), "format": "g2o", "dim": 3, "cost": graph.cost, "n_poses": graph.n_poses,
               "n_edges": graph.n_edges,
               "n_odometric": graph.n_odometric, "n_loop_closures": graph.n_loop_closures, "n_components": k,
               "cyclomatic_number": int(graph.n_edges - graph.n_poses + k),
               "has_initial_guess": graph.initial is not None, "spanning_tree": None, "regularization": None,
               "n_regularized": None, "n_ambiguous": None,
               "note": "3-D graph: rotations by the chordal relaxation, no 2kπ regularization"}
    lines = [f"file              {args.file} (g2o, 3-D: VERTEX_SE3:QUAT/EDGE_SE3:QUAT; cost {graph.cost})",
             *graph_lines(graph, k, payload["cyclomatic_number"]),
             "regularization    none needed in 3-D (rotation matrices do not wrap)"]
    emit(args, payload, lines)
    return EXIT_OK


def _anchor(specs):
    if not specs:
        return None
    if len(specs) == 1 and specs[0].strip().lstrip("-").isdigit():
        return int(specs[0])
    raise UsageError("3-D graphs take --anchor ID only (the pose held at the identity)")


def solve3d(args, graph, out) -> int:
    from ..space import compare_methods3d, lago3d, refine3d

    anchor = _anchor(args.anchor)
    if args.check:
        res, report = compare_methods3d(graph, route=args.route, anchor=anchor)
    elif args.robust:  # GNC around lago3d (lago_cvx.variants.robust3d): χ² and --refine over the accepted edges
        from ..pipeline import lago

        res, report = lago(graph, robust=args.robust, route=args.route, method=args.method, anchor=anchor), None
    else:
        res, report = lago3d(graph, route=args.route, method=args.method, anchor=anchor), None
    check_finite(res.chi2, res.t, what="LAGO estimate")
    solved = res.graph if args.robust else graph  # the accepted edges of a robust run
    payload = {"file": str(args.file), "dim": 3, "cost": graph.cost, "n_poses": graph.n_poses,
               "n_edges": graph.n_edges, "method": "closed_form" if args.check else args.method, "route": res.route,
               "weighting": res.weighting,
               "chi2": res.chi2, "chi2_seed": res.chi2_seed, "joint_alpha": res.alpha,
               "timings": dict(res.timings)}
    if graph.initial is not None:
        from ..posegraph3d import chi2_3d

        payload["chi2_initial"] = chi2_3d(solved, *graph.initial)
    if args.robust:
        payload.update(robust=args.robust, chi2_edges="accepted", n_rejected=int(res.rejected_edges.size),
                       rejected_edges=res.rejected_edges.tolist(), robust_iterations=res.iterations,
                       robust_threshold=res.settings.c2_for(3))
    if report is not None:
        payload["max_rel_diff"] = report["max_rel_diff"]
        payload["cvxpy_timings"] = report["cvxpy_timings"]
    final = (res.t, res.R)
    if args.refine:
        method = "levenberg-marquardt" if args.refine_method == "levenberg-marquardt" else "gauss-newton"
        ref = refine3d(solved, res.t, res.R, method=method, anchor=anchor, max_iterations=args.max_iterations)
        check_finite(ref.chi2, ref.t, what="refined estimate")
        final = (ref.t, ref.R)
        payload.update(chi2_refined=ref.chi2, refine_iterations=ref.iterations, refine_converged=ref.converged)
        payload["timings"]["refine"] = ref.log[-1]["time"] if ref.log else 0.0
    if out is not None:
        write_estimate(out, graph, final)
        payload["output"] = "<stdout>" if out == "-" else str(out)
    t = payload["timings"]
    lines = [f"LAGO 3-D ({payload['method'].replace('_', '-')}, {res.route} route: chordal relaxation "
             f"({res.weighting} weights) → positions" + (" → joint step" if res.route == "default" else "")
             + f") on {args.file}",
             f"  poses {graph.n_poses}, edges {graph.n_edges}; cost {graph.cost}: {COST_DESCRIPTION[graph.cost]}",
             *([f"  robust ({args.robust}, c̄² = {payload['robust_threshold']:.4g}): {res.rejected_edges.size} of "
                f"{graph.n_edges} edges rejected as outliers after {res.iterations} GNC iterations "
                f"({res.timings['robust']:.3f} s); every chi2 below is over the {solved.n_edges} accepted edges"]
               if args.robust else []),
             f"  chi2 = {res.chi2:.6g}  (cost {graph.cost}: {CHI2_CONVENTION})"
             + ("" if res.route == "seed" else f"; chordal + positions {res.chi2_seed:.6g}, step α = {res.alpha}")
             + (f"; at the file's initial guess {payload['chi2_initial']:.6g}" if "chi2_initial" in payload else ""),
             "  time [s]: " + ", ".join(f"{k} {v:.4f}" for k, v in t.items())]
    if report is not None:
        lines.append("  cvxpy vs closed form, max relative difference: "
                     + ", ".join(f"{k} {v:.2e}" for k, v in report["max_rel_diff"].items()))
    if args.refine:
        lines.append(f"  refined ({args.refine_method}): chi2 = {payload['chi2_refined']:.10g} after "
                     f"{payload['refine_iterations']} iterations" + ("" if payload["refine_converged"]
                                                                     else " (not converged)"))
    if out is not None:
        lines.append(f"  {'refined ' if args.refine else ''}estimate written to "
                     + ("standard output" if out == "-" else str(out)))
    emit(args, payload, lines, stdout_taken=out == "-")
    return EXIT_OK


def _frame3d(specs, graph):
    """``--anchor`` on a 3-D file: (anchor id or None, the frame pose (t (3,), R (3, 3)) or None). One anchor at most
    (a choice of frame): a bare ``ID`` puts that pose at the identity, ``ID:X,Y,Z,QX,QY,QZ,QW`` at the given pose; the
    id must exist (``GraphError``, exit 2)."""
    if not specs:
        return None, None
    if len(specs) > 1:
        raise UsageError(f"certify takes at most one --anchor (a choice of frame), got {len(specs)}")
    head, _, rest = specs[0].partition(":")
    try:
        pid = int(head)
        values = [float(v) for v in rest.split(",")] if rest else []
    except ValueError:
        raise UsageError(f"bad anchor {specs[0]!r}: expected ID or ID:X,Y,Z,QX,QY,QZ,QW on a 3-D file") from None
    graph.index_of(pid)  # an unknown id: GraphError naming it
    if not values:
        return pid, None
    if len(values) != 7 or not np.isfinite(values).all() or np.linalg.norm(values[3:]) == 0:
        raise UsageError(f"bad anchor {specs[0]!r}: expected ID:X,Y,Z,QX,QY,QZ,QW (a finite position and a non-zero "
                         "quaternion) on a 3-D file")
    from ..so3 import quat_to_rot

    q = np.asarray(values[3:]) / np.linalg.norm(values[3:])
    return pid, (np.asarray(values[:3]), quat_to_rot(q[None])[0])


def certify3d_cmd(args, graph, out, *, written=None, robust=None) -> int:
    """``certify`` on a 3-D graph; with ``robust`` (a ``Robust3DResult``) ``graph`` is its accepted edges and
    ``written`` the graph read (what ``-o`` writes)."""
    from ..posegraph3d import chi2_3d
    from ..space import lago3d
    from ..space.certify import certify3d, sesync_cost3d

    anchor, frame = _frame3d(args.anchor, graph)
    res = lago3d(graph, route=args.route, anchor=anchor)
    cert = certify3d(graph, res.t, res.R, tol=args.tol, anchor_index=res.anchor_index)
    if frame is not None:  # the certified estimate moved rigidly: the anchor pose at the given one (f is unchanged)
        a = graph.index_of(anchor)
        G = frame[1] @ cert.R[a].T
        cert = replace(cert, t=(cert.t - cert.t[a]) @ G.T + frame[0], R=np.einsum("ab,kbc->kac", G, cert.R))
    payload = {"file": str(args.file), "dim": 3, "cost": graph.cost, "n_poses": graph.n_poses,
               "n_edges": graph.n_edges, "chi2_lago": res.chi2, "f_lago": sesync_cost3d(graph, res.t, res.R),
               "f": cert.cost,
               "chi2_certified_point": chi2_3d(graph, cert.t, cert.R), "dual_value": cert.dual_value,
               "certified": cert.certified, "verdict": cert.verdict, "lower_bound": cert.lower_bound,
               "relative_suboptimality_bound": cert.relative_suboptimality_bound, "tol": cert.tol, "eta": cert.eta,
               "shift": cert.shift, "n_negative": cert.n_negative, "lambda_min": cert.lambda_min,
               "residual_rel": cert.residual_rel, "times": cert.times}
    if robust is not None:
        payload.update(robust_payload(args, written, robust), robust_seconds=robust.timings["robust"])
    lines = [f"certify (3-D): LAGO → SE-Sync Newton → SE-Sync certificate, on {args.file}",
             f"  poses {graph.n_poses}, edges {graph.n_edges}; chi2 (cost {graph.cost}, {CHI2_CONVENTION}) of LAGO "
             f"{res.chi2:.6g}, at the certified point {payload['chi2_certified_point']:.6g}",
             f"  SE-Sync cost f = Σ κ‖R_j−R_iR̃‖²_F + τ‖t_j−t_i−R_i t̃‖² (κ = 3/(2tr Ω_rr⁻¹), τ = 3/tr Ω_tt⁻¹ of "
             f"the information as written, as SE-Sync reads the file; not the chi2): "
             f"LAGO {payload['f_lago']:.10g}, refined {cert.cost:.12g}",
             f"  {'CERTIFIED globally optimal' if cert.certified else 'NOT certified'}: proven lower bound "
             f"f* ≥ {cert.lower_bound:.12g}; relative suboptimality ≤ {cert.relative_suboptimality_bound:.3g} "
             f"(tol {cert.tol:.3g}); η = {cert.eta:.3g}, negative pivots {cert.n_negative}",
             f"    verdict: {cert.verdict}"]
    if robust is not None:
        lines.insert(1, f"  robust ({args.robust}): {robust.rejected_edges.size} of {written.n_edges} edges rejected "
                        f"as outliers ({robust.timings['robust']:.2f} s); everything below, the certificate too, is "
                        f"about the {graph.n_edges} accepted edges")
    if out is not None:
        write_estimate(out, graph if written is None else written, (cert.t, cert.R))
        payload["output"] = "<stdout>" if out == "-" else str(out)
        lines.append("  estimate written to " + ("standard output" if out == "-" else str(out)))
    status = EXIT_OK if cert.certified else EXIT_NOT_CERTIFIED
    payload["exit_status"] = status
    emit(args, payload, lines, stdout_taken=out == "-")
    return status


def world3d(kind: str, poses: int, seed: int, sigma_xy, sigma_theta):
    """A 3-D world of about ``poses`` poses (``lago_cvx.synthetic.space``); the sigmas as translation and rotation."""
    from ..synthetic import space

    kw = sigma_keywords(sigma_xy, sigma_theta, names=("sigma_t", "sigma_r"))
    if kind == "grid3d":
        return space.cube_grid_world(max(2, round(poses ** (1 / 3))), seed=seed, **kw)
    rings = max(2, round((poses / 2) ** 0.5))
    per = max(3, poses // rings)
    if kind == "sphere3d":
        return space.sphere_world(rings, per, seed=seed, **kw)
    return space.torus_world(rings, per, seed=seed, **kw)


def plot3d(args, graph, out: str, fmt: str) -> int:
    """``plot`` on a 3-D graph: the estimate (ESTIMATE's vertices, else LAGO's) and the file's initial guess in
    three projections (x–y, x–z, y–z). ``--covariances`` is planar-only."""
    import io as _io
    from pathlib import Path

    from matplotlib.figure import Figure

    from ..plotting import plot_trajectory3d
    from .common import read_input, write_bytes

    if args.covariances:
        raise UsageError("--covariances draws planar ellipses; it does not apply to 3-D graphs")
    if args.estimate:
        est = read_input(args, args.estimate)
        if getattr(est, "dim", 2) != 3 or est.initial is None or not np.array_equal(est.ids, graph.ids):
            raise UsageError(f"{args.estimate}: needs VERTEX_SE3:QUAT lines for every pose id of the graph")
        t, label = est.initial_t, f"estimate ({Path(args.estimate).name})"
    else:
        from ..space import lago3d

        res = lago3d(graph, route=args.route)
        t, label = res.t, f"LAGO ({res.route} route)"
    fig = Figure(figsize=(args.size * 1.5, args.size / 2), layout="constrained")
    for ax, plane in zip(fig.subplots(1, 3), ("xy", "xz", "yz")):
        if graph.initial is not None and not args.no_guess:
            plot_trajectory3d(ax, graph.initial_t, plane=plane, color="0.7", linewidth=0.6,
                              label="the file's initial guess")
        plot_trajectory3d(ax, t, plane=plane, color="k", linewidth=0.8, label=label)
    fig.suptitle(args.title or f"{Path(args.file).name}: {graph.n_poses} poses, {graph.n_edges} edges (projections)")
    fig.axes[0].legend(loc="best", fontsize=8)
    buf = _io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=args.dpi, metadata={"png": {"Software": None}, "svg": {"Date": None},
                                                          "pdf": {"CreationDate": None}}[fmt])
    write_bytes(out, buf.getvalue())
    payload = {"file": str(args.file), "estimate": args.estimate, "output": str(out), "format": fmt, "dim": 3,
               "n_poses": graph.n_poses, "n_edges": graph.n_edges, "n_ellipses": 0}
    emit(args, payload, [f"figure written to {out} ({graph.n_poses} poses, {graph.n_loop_closures} loop closures; "
                         "x-y, x-z and y-z projections)"])
    return EXIT_OK

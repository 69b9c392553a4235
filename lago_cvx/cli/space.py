"""The commands on 3-D graphs (``graph.dim == 3``, ``lago_cvx.space``): ``info``, ``solve``, ``certify`` and the 3-D
worlds of ``generate``. The planar commands hand over here after reading the file (with ``--cost`` and
``--information``); every χ² is the graph's cost (``graph.cost``, named by the key ``"cost"``). JSON keys are the
planar ones where they mean the same, plus ``dim``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..conventions import CHI2_CONVENTION, COST_DESCRIPTION
from .common import (EXIT_NOT_CERTIFIED, EXIT_OK, UsageError, abs_tol_hint, check_fields, check_finite, check_line,
                     emit, graph_lines, robust_payload, sigma_keywords, write_estimate)

WORLDS3D = ("sphere3d", "torus3d", "grid3d")

# Options of the planar commands that have no meaning on a 3-D graph: (attribute, flag, value when not given, why).
# Each given is refused by ``refuse_planar_options`` (exit 2) instead of being ignored.
_PLANAR_ONLY = (
    ("edge2_order", "--edge2-order", None, "a 3-D file has no EDGE2 lines"),
    ("spanning_tree", "--spanning-tree", None, "3-D LAGO has no spanning tree: the chordal relaxation estimates "
                                               "every rotation at once"),
    ("regularization", "--regularization", None, "3-D rotations are matrices: there is no 2kπ to regularize"),
    ("max_nodes", "--max-nodes", None, "it limits --regularization integer, which is planar"),
    ("max_shift", "--max-shift", None, "it limits --regularization integer, which is planar"),
    ("time_limit", "--time-limit", None, "it limits --regularization integer, which is planar"),
    ("positions", "--positions", None, "the 3-D routes set the positions themselves (--route default: re-solved "
                                       "and a joint step; --route seed: the chordal rotations' positions)"),
)


def refuse_planar_options(args) -> None:
    """``UsageError`` (exit 2) naming the first option given that a 3-D graph cannot honour (``_PLANAR_ONLY``), so
    that none is silently ignored."""
    for attr, flag, unset, why in _PLANAR_ONLY:
        value = getattr(args, attr, unset)
        if value != unset:
            shown = flag if isinstance(value, bool) else f"{flag} {value}".replace("_", "-")
            raise UsageError(f"{shown} applies to planar graphs only: {args.file} is 3-D ({why})")
    if getattr(args, "information", None) == "marginal":
        raise UsageError(f"--information marginal applies to planar graphs only: {args.file} is 3-D (the paper's "
                         "blkdiag(P_Δ, P_δ) is planar; 3-D positions use each edge's full information)")


def _components(graph) -> int:
    from ..graph import connected_components

    return connected_components(graph)[0]


def info3d(args, graph) -> int:
    refuse_planar_options(args)
    if args.route != "default":
        raise UsageError(f"info --route {args.route}: info reports the route's 2kπ regularization of a planar graph; "
                         f"{args.file} is 3-D and needs none (solve and certify take --route on 3-D files)")
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


def parse_anchor3d(spec: str, graph):
    """One ``--anchor`` on a 3-D file: ``(id, None)`` for a bare ``ID``, ``(id, (t (3,), R (3, 3)))`` for
    ``ID:X,Y,Z,QX,QY,QZ,QW`` (the quaternion normalized). ``UsageError`` naming the spec when it is malformed,
    ``GraphError`` naming an id the graph does not have (exit 2 both)."""
    head, colon, rest = spec.partition(":")
    try:
        pid = int(head)
        values = [float(v) for v in rest.split(",")] if colon else []
    except ValueError:
        raise UsageError(f"bad anchor {spec!r}: expected ID or ID:X,Y,Z,QX,QY,QZ,QW on a 3-D file") from None
    graph.index_of(pid)  # an unknown id: GraphError naming it
    if not colon:
        return pid, None
    if len(values) != 7 or not np.isfinite(values).all() or np.linalg.norm(values[3:]) == 0:
        raise UsageError(f"bad anchor {spec!r}: expected ID:X,Y,Z,QX,QY,QZ,QW (a finite position and a non-zero "
                         "quaternion) on a 3-D file")
    from ..so3 import quat_to_rot

    q = np.asarray(values[3:]) / np.linalg.norm(values[3:])
    return pid, (np.asarray(values[:3]), quat_to_rot(q[None])[0])


def _anchors3d(specs, graph):
    """``solve --anchor`` on a 3-D file: (the bare anchor id or None, ``{id: (t, R)}`` of the poses known exactly,
    for ``lago3d(fixed=)``). A bare ID is accepted only alone, as on a planar file."""
    if not specs:
        return None, {}
    parsed = [parse_anchor3d(spec, graph) for spec in specs]
    if len(parsed) == 1 and parsed[0][1] is None:
        return parsed[0][0], {}
    fixed = {}
    for spec, (pid, pose) in zip(specs, parsed):
        if pose is None:
            raise UsageError(f"bad anchor {spec!r}: a bare ID is accepted only alone (give ID:X,Y,Z,QX,QY,QZ,QW)")
        if pid in fixed:
            raise UsageError(f"anchor {pid} given twice")
        fixed[pid] = pose
    return None, fixed


def solve3d(args, graph, out) -> int:
    from ..space import lago3d, refine3d

    refuse_planar_options(args)
    anchor, fixed = _anchors3d(args.anchor, graph)
    if args.robust and fixed:
        raise UsageError("--robust with --anchor ID:X,Y,Z,QX,QY,QZ,QW on a 3-D graph: graduated non-convexity holds "
                         "one pose for the frame (a bare --anchor ID)")
    if fixed:  # poses known exactly (space.fixed): closed form; the refinement holds every one of them
        for given, flag in ((args.check, "--check"), (args.method != "closed_form", "--method cvxpy")):
            if given:
                raise UsageError(f"{flag} with --anchor ID:X,Y,Z,QX,QY,QZ,QW on a 3-D graph: "
                                 "poses known exactly are solved in closed form only")
    if args.check:  # with --robust, on the accepted edges (pipeline.compare_methods)
        from ..pipeline import compare_methods

        res, report = compare_methods(graph, robust=args.robust_settings, route=args.route, anchor=anchor)
    elif args.robust:  # GNC around lago3d (lago_cvx.variants.robust3d): χ² and --refine over the accepted edges
        from ..pipeline import lago

        res, report = lago(graph, robust=args.robust_settings, route=args.route, method=args.method, anchor=anchor), None
    else:
        res, report = lago3d(graph, route=args.route, method=args.method, anchor=anchor, fixed=fixed or None), None
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
        payload.update(check_fields(report, args.robust))
    if fixed:
        from ..so3 import rot_to_quat

        payload["anchors"] = {str(k): [*map(float, v[0]), *map(float, rot_to_quat(v[1][None])[0])]
                              for k, v in fixed.items()}
    final = (res.t, res.R)
    if args.refine:
        method = "levenberg-marquardt" if args.refine_method == "levenberg-marquardt" else "gauss-newton"
        held = {"anchors": fixed} if fixed else {"anchor": anchor if anchor is not None else res.anchor}
        ref = refine3d(solved, res.t, res.R, method=method, max_iterations=args.max_iterations, **held)
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
        lines.append(check_line(report, args.robust))
    if fixed:
        lines.append(f"  anchors {sorted(fixed)}: poses known exactly (the frame they define)")
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
    """``certify --anchor`` on a 3-D file: (anchor id or None, the frame pose (t (3,), R (3, 3)) or None). One anchor
    at most (a choice of frame): a bare ``ID`` puts that pose at the identity, ``ID:X,Y,Z,QX,QY,QZ,QW`` at the given
    pose (``parse_anchor3d``)."""
    if not specs:
        return None, None
    if len(specs) > 1:
        raise UsageError(f"certify takes at most one --anchor (a choice of frame), got {len(specs)}")
    return parse_anchor3d(specs[0], graph)


def certify3d_cmd(args, graph, out, *, written=None, robust=None) -> int:
    """``certify`` on a 3-D graph; with ``robust`` (a ``Robust3DResult``) ``graph`` is its accepted edges and
    ``written`` the graph read (what ``-o`` writes)."""
    from ..posegraph3d import chi2_3d
    from ..space import lago3d
    from ..space.certify import certify3d, sesync_cost3d

    refuse_planar_options(args)
    anchor, frame = _frame3d(args.anchor, graph)
    res = lago3d(graph, route=args.route, anchor=anchor)
    check_finite(res.chi2, res.t, what="LAGO estimate")
    cert = certify3d(graph, res.t, res.R, tol=args.tol, abs_tol=args.abs_tol, anchor_index=res.anchor_index,
                     max_iterations=args.max_iterations)
    cert_lago = None
    if args.compare_lago:  # the raw LAGO point, not refined (never certified unless it is already the optimum)
        cert_lago = certify3d(graph, res.t, res.R, tol=args.tol, abs_tol=args.abs_tol,
                              anchor_index=res.anchor_index, local=False)
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
               "residual_rel": cert.residual_rel, "abs_tol": cert.abs_tol, "max_iterations": args.max_iterations,
               "times": cert.times, "compare_lago": bool(args.compare_lago),
               "lago_certificate": None if cert_lago is None else {
                   "certified": cert_lago.certified, "verdict": cert_lago.verdict, "f": cert_lago.cost,
                   "lower_bound": cert_lago.lower_bound, "lambda_min": cert_lago.lambda_min,
                   "n_negative": cert_lago.n_negative,
                   "relative_suboptimality_bound": cert_lago.relative_suboptimality_bound, "times": cert_lago.times}}
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
             f"(tol {cert.tol:.3g}" + (f", abs-tol {cert.abs_tol:.3g}" if cert.abs_tol else "")
             + f"); η = {cert.eta:.3g}, negative pivots {cert.n_negative}",
             f"    verdict: {cert.verdict}"]
    if cert_lago is None:
        lines.append("  comparison certificate of the raw LAGO estimate: not run (--compare-lago runs it)")
    else:
        lines += ["  comparison certificate of the raw LAGO estimate (--compare-lago): "
                  + ("certified" if cert_lago.certified else "NOT certified") + f", f = {cert_lago.cost:.10g}",
                  f"    verdict: {cert_lago.verdict}"]
    if robust is not None:
        lines.insert(1, f"  robust ({args.robust}): {robust.rejected_edges.size} of {written.n_edges} edges rejected "
                        f"as outliers ({robust.timings['robust']:.2f} s); everything below, the certificate too, is "
                        f"about the {graph.n_edges} accepted edges")
    if out is not None:
        write_estimate(out, graph if written is None else written, (cert.t, cert.R))
        payload["output"] = "<stdout>" if out == "-" else str(out)
        lines.append("  estimate written to " + ("standard output" if out == "-" else str(out)))
    status = EXIT_OK if cert.certified else EXIT_NOT_CERTIFIED
    if abs_tol_hint(cert, args):
        lines.append(f"  {abs_tol_hint(cert, args)}")
    payload["exit_status"] = status
    emit(args, payload, lines, stdout_taken=out == "-")
    return status


def world3d(kind: str, poses: int, seed: int, sigma_xy, sigma_theta, info=(None, None)):
    """A 3-D world of about ``poses`` poses (``lago_cvx.synthetic.space``); the sigmas as translation and rotation,
    ``info`` those of the information (None: the noise's)."""
    from ..synthetic import space

    kw = {**sigma_keywords(sigma_xy, sigma_theta, names=("sigma_t", "sigma_r")),
          **sigma_keywords(*info, names=("info_sigma_t", "info_sigma_r"))}
    if kind == "grid3d":
        return space.cube_grid_world(max(2, round(poses ** (1 / 3))), seed=seed, **kw)
    rings = max(2, round((poses / 2) ** 0.5))
    per = max(3, poses // rings)
    if kind == "sphere3d":
        return space.sphere_world(rings, per, seed=seed, **kw)
    return space.torus_world(rings, per, seed=seed, **kw)


def plot3d(args, graph, out: str, fmt: str) -> int:
    """``plot`` on a 3-D graph, in three projections (x–y, x–z, y–z): the estimate (ESTIMATE's vertices, else LAGO's),
    its loop closures, the file's initial guess rigidly aligned to it (``plotting.aligned3d``) and, with
    ``--covariances``, the projections of the position-uncertainty ellipsoids (JᵀΩJ)⁻¹ at the estimate drawn
    (``space.covariance.pose_covariances3d``, the smallest id held: zero there)."""
    import io as _io
    from pathlib import Path

    from matplotlib.figure import Figure

    from ..plotting import aligned3d, plot_covariances3d, plot_edges3d, plot_trajectory3d
    from .common import read_input, write_bytes

    refuse_planar_options(args)
    if args.estimate:
        est = read_input(args, args.estimate)
        if getattr(est, "dim", 2) != 3 or est.initial is None or not np.array_equal(est.ids, graph.ids):
            raise UsageError(f"{args.estimate}: needs VERTEX_SE3:QUAT lines for every pose id of the graph")
        t, R, label = est.initial_t, est.initial_R, f"estimate ({Path(args.estimate).name})"
    else:
        from ..space import lago3d

        res = lago3d(graph, route=args.route)
        t, R, label = res.t, res.R, f"LAGO ({res.route} route)"
    covs = None
    if args.covariances:
        from ..space.covariance import pose_covariances3d

        covs = pose_covariances3d(graph, t, R)
    guess = None
    if graph.initial is not None and not args.no_guess:  # in the estimate's frame: best rigid fit to it
        guess = aligned3d(graph.initial_t, None, t)[0]
    fig = Figure(figsize=(args.size * 1.5, args.size / 2), layout="constrained")
    thin = 0.8 if graph.n_poses <= 2000 else 0.5
    for ax, plane in zip(fig.subplots(1, 3), ("xy", "xz", "yz")):
        if guess is not None:
            plot_trajectory3d(ax, guess, plane=plane, color="0.65", linewidth=thin,
                              label="the file's initial guess (rigidly aligned to the estimate)")
        plot_trajectory3d(ax, t, plane=plane, color="k", linewidth=thin, label=label)
        plot_edges3d(ax, graph, t, plane=plane, label=f"loop closures ({graph.n_loop_closures})")
        if covs is not None:
            plot_covariances3d(ax, t, covs, R=R, plane=plane, every=args.every, n_sigma=args.sigma)
    n_ellipses = len(range(0, graph.n_poses, args.every)) if covs is not None else 0
    fig.suptitle(args.title or f"{Path(args.file).name}: {graph.n_poses} poses, {graph.n_edges} edges (projections)"
                 + (f"; {args.sigma:g}σ ellipsoids' projections, every {args.every} poses" if covs is not None
                    else ""))
    leg = fig.axes[0].legend(loc="best", fontsize=8)
    for line in leg.get_lines():
        line.set_linewidth(1.5)
        line.set_alpha(1.0)
    buf = _io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=args.dpi, metadata={"png": {"Software": None}, "svg": {"Date": None},
                                                          "pdf": {"CreationDate": None}}[fmt])
    write_bytes(out, buf.getvalue())
    payload = {"file": str(args.file), "estimate": args.estimate, "output": str(out), "format": fmt, "dim": 3,
               "n_poses": graph.n_poses, "n_edges": graph.n_edges, "n_ellipses": n_ellipses}
    emit(args, payload, [f"figure written to {out} ({graph.n_poses} poses, {graph.n_loop_closures} loop closures"
                         + (f", {n_ellipses} covariance ellipsoids" if n_ellipses else "")
                         + "; x-y, x-z and y-z projections)"])
    return EXIT_OK

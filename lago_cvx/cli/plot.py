"""``lago-cvx plot FILE [ESTIMATE] -o fig.png``: the graph, its loop closures, an estimate and, optionally,
LAGO's covariance ellipses."""

from __future__ import annotations

import io as _io
from pathlib import Path

import numpy as np

from .common import (
    EXIT_OK,
    UsageError,
    add_input_options,
    add_route_options,
    emit,
    output_target,
    positive_float,
    positive_int,
    progress_callback,
    read_input,
    write_bytes,
)

FORMATS = ("png", "svg", "pdf")


def _estimate_from_file(graph, path: str, args):
    """The vertices of ``path`` reordered to ``graph``'s poses (matched by id)."""
    est = read_input(args, path)
    if est.initial is None:
        raise UsageError(f"{path}: has no VERTEX lines, so it holds no estimate to plot")
    missing = np.setdiff1d(graph.ids, est.ids)
    if missing.size:
        raise UsageError(f"{path}: no vertex for pose id(s) {missing[:5].tolist()} of the graph")
    order = {int(i): k for k, i in enumerate(est.ids)}
    return est.initial[[order[int(i)] for i in graph.ids]]


def cmd_plot(args) -> int:
    from matplotlib.figure import Figure

    from ..plotting import aligned, plot_covariances, plot_edges, plot_trajectory, set_title

    out = output_target(args, what="the figure")
    if out == "-":
        raise UsageError("-o -: a figure needs a file name (.png, .svg or .pdf)")
    fmt = Path(out).suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise UsageError(f"-o {out}: the file name must end in .png, .svg or .pdf")
    graph = read_input(args)
    if graph.dim == 3:
        from .space import plot3d

        return plot3d(args, graph, out, fmt)
    res = None
    if args.estimate:
        poses, label = _estimate_from_file(graph, args.estimate, args), f"estimate ({Path(args.estimate).name})"
    else:
        from ..pipeline import lago

        res = lago(graph, route=args.route, spanning_tree=args.spanning_tree, regularization=args.regularization)
        poses, label = res.poses, f"LAGO ({res.route} route)"
    fig = Figure(figsize=(args.size, args.size), layout="constrained")
    ax = fig.subplots()
    thin = 0.8 if graph.n_poses <= 2000 else 0.5
    if graph.initial is not None and not args.no_guess:  # in the estimate's frame: best rigid fit to it
        plot_trajectory(ax, aligned(graph.initial, poses), color="0.65", linewidth=thin,
                        label="the file's initial guess (rigidly aligned to the estimate)")
    plot_trajectory(ax, poses, color="k", linewidth=thin, label=label)
    plot_edges(ax, graph, poses, which="loop_closures", color="tab:red",
               label=f"loop closures ({graph.n_loop_closures})")
    n_ellipses = 0
    if args.covariances:
        if res is None:
            from ..pipeline import lago

            res = lago(graph, route=args.route, spanning_tree=args.spanning_tree, regularization=args.regularization)
        covs = res.pose_covariances(progress=progress_callback(args))
        plot_covariances(ax, poses, covs, every=args.every, n_sigma=args.sigma)
        n_ellipses = len(range(0, graph.n_poses, args.every))
    set_title(ax, args.title or f"{Path(args.file).name}: {graph.n_poses} poses, {graph.n_edges} edges"
              + (f"; {args.sigma:g}σ ellipses of LAGO's covariance, every {args.every} poses" if args.covariances
                 else ""))
    leg = ax.legend(loc="best", fontsize=8)
    for line in leg.get_lines():  # legend swatches readable whatever the width and alpha drawn
        line.set_linewidth(1.5)
        line.set_alpha(1.0)
    buf = _io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=args.dpi, metadata={"png": {"Software": None}, "svg": {"Date": None},
                                                          "pdf": {"CreationDate": None}}[fmt])
    write_bytes(out, buf.getvalue())
    payload = {"file": str(args.file), "estimate": args.estimate, "output": str(out), "format": fmt,
               "n_poses": graph.n_poses, "n_edges": graph.n_edges, "n_ellipses": n_ellipses}
    emit(args, payload, [f"figure written to {out} ({graph.n_poses} poses, {graph.n_loop_closures} loop closures"
                         + (f", {n_ellipses} covariance ellipses" if n_ellipses else "") + ")"])
    return EXIT_OK


def add_parser(sub) -> None:
    s = sub.add_parser("plot", help="draw a graph, its loop closures, an estimate and covariance ellipses",
                       description="Draw FILE's loop closures on an estimate: ESTIMATE's vertices (a g2o/TORO file "
                                   "with the same pose ids, e.g. written by `lago-cvx solve -o`) or, without it, "
                                   "LAGO's estimate. --covariances adds the ellipses of LAGO's first-order pose "
                                   "covariances (eq. (15)), centred on the poses drawn. A 3-D file is drawn in "
                                   "three projections (x-y, x-z, y-z), its covariances as the projections of "
                                   "the ellipsoids of (J'ΩJ)^-1 at the estimate drawn.")
    s.add_argument("file")
    add_input_options(s)
    s.add_argument("estimate", nargs="?", help="a file whose vertices are the estimate to draw")
    s.add_argument("-o", "--output", required=True, metavar="FIG", help="figure file: .png, .svg or .pdf")
    add_route_options(s, integer=False)
    s.add_argument("--covariances", action="store_true", help="draw covariance ellipses (runs LAGO)")
    s.add_argument("--every", type=positive_int, default=10, help="one ellipse every EVERY poses (default 10)")
    s.add_argument("--sigma", type=positive_float, default=3.0, help="ellipse size in standard deviations (3)")
    s.add_argument("--no-guess", action="store_true", help="do not draw the file's own initial guess")
    s.add_argument("--title", default=None)
    s.add_argument("--size", type=positive_float, default=8.0, help="figure size in inches (square, default 8)")
    s.add_argument("--dpi", type=positive_int, default=150)
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_plot)

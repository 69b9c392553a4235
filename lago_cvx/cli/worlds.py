"""``lago-cvx generate`` (a seeded synthetic world and its ground truth) and ``lago-cvx demo`` (the main
job on the embedded default)."""

from __future__ import annotations

import os
from pathlib import Path

from .common import (EXIT_OK, UsageError, emit, nonneg_float, nonneg_int, output_target, positive_float,
                     positive_int, sigma_keywords)
from .space import WORLDS3D


def _world(kind: str, poses: int, seed: int, sigma_xy: float | None, sigma_theta: float | None, laps: float,
           info=(None, None)):
    from .. import synthetic

    kw = {**sigma_keywords(sigma_xy, sigma_theta), **sigma_keywords(*info, names=("info_sigma_xy", "info_sigma_theta"))}
    if kind == "manhattan":
        return synthetic.manhattan_world(poses, seed=seed, **kw)
    return synthetic.circle_world(poses, seed=seed, laps=laps, **kw)


def cmd_generate(args) -> int:
    from ..io import write_graph

    if args.poses < 2:
        raise UsageError("--poses must be at least 2")
    out = output_target(args)
    if out == "-" and not args.truth:
        raise UsageError("-o - writes the graph to standard output: name the ground-truth file with --truth")
    truth_path = args.truth or str(Path(out).with_name(Path(out).stem + ".truth" + (Path(out).suffix or ".g2o")))
    truth_args = type("A", (), {"output": truth_path, "json": args.json and truth_path == "-"})()
    truth_path = output_target(truth_args, flag="--truth")
    if truth_path == out:
        raise UsageError("--truth and -o name the same file")
    if args.world in WORLDS3D:
        if args.laps != 3.0:
            raise UsageError(f"--laps applies to the circle world only (--world {args.world} is 3-D)")
        from .space import world3d

        world = world3d(args.world, args.poses, args.seed, args.sigma_xy, args.sigma_theta,
                        info=(args.info_sigma_xy, args.info_sigma_theta))
    else:
        world = _world(args.world, args.poses, args.seed, args.sigma_xy, args.sigma_theta, args.laps,
                       info=(args.info_sigma_xy, args.info_sigma_theta))
    g, outliers = world.graph, None
    if args.outliers:  # false loop closures appended after the world's edges (lago_cvx.synthetic.outliers)
        from ..synthetic import add_false_loop_closures

        g, outliers = add_false_loop_closures(g, args.outliers, seed=args.seed)
    write_graph(out, g)  # vertices = dead-reckoning guess, as in real datasets
    write_graph(truth_path, g, world.truth)  # same edges, vertices = ground truth
    shown = {p: ("standard output" if p == "-" else p) for p in (out, truth_path)}
    payload = {"output": str(out), "truth": str(truth_path), "world": args.world, "seed": args.seed,
               "n_poses": g.n_poses, "n_edges": g.n_edges, "n_loop_closures": g.n_loop_closures}
    lines = [f"wrote {shown[out]}: {args.world} world, {g.n_poses} poses, {g.n_edges} edges "
             f"({g.n_loop_closures} loop closures), seed {args.seed}; vertices = dead-reckoning guess",
             f"wrote {shown[truth_path]}: same edges, vertices = ground truth"]
    if outliers is not None:
        payload.update(outlier_fraction=args.outliers, outlier_edges=outliers.tolist())
        lines.append(f"{outliers.size} false loop closures appended: EDGE records {outliers[0] if outliers.size else '-'}"
                     f"…{outliers[-1] if outliers.size else '-'} (0-based, file order)")
    emit(args, payload, lines, stdout_taken="-" in (out, truth_path))
    return EXIT_OK


def cmd_demo(args) -> int:
    from ..metrics import ate, chi2
    from ..pipeline import compare_methods

    out_dir = Path(args.out_dir)
    if not args.no_figure and out_dir.exists() and not out_dir.is_dir():
        raise UsageError(f"--out-dir {args.out_dir}: exists and is not a directory")
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
        f"  regularization ({res.regularization.regularization}): {res.regularization.n_regularized} of "
        f"{res.regularization.chords.size} chords needed a 2kπ correction",
        "  chi2 (sum e'Ωe, no 1/2):",
        f"    odometric guess {payload['chi2']['odometry']:12.4f}",
        f"    LAGO            {payload['chi2']['lago']:12.4f}",
        f"    ground truth    {payload['chi2']['truth']:12.4f}",
        f"  trajectory error (RMS position vs truth): odometry {payload['ate']['odometry']:.4f} m, "
        f"LAGO {payload['ate']['lago']:.4f} m",
        "  cvxpy (Clarabel) vs closed form, max relative difference: "
        + ", ".join(f"{k} {v:.2e}" for k, v in d.items()),
        f"  closed form {res.timings['total']:.3f} s; cvxpy "
        + ", ".join(f"{k} {v:.3f} s" for k, v in report["cvxpy_timings"].items()),
    ]
    if not args.no_figure:
        path = _demo_figure(g, truth, res.poses, out_dir)
        payload["figure"] = str(path)
        lines.append(f"  figure: {path}")
    emit(args, payload, lines)
    return EXIT_OK


def _demo_figure(graph, truth, est, out_dir: Path) -> Path:
    from matplotlib.figure import Figure

    from ..plotting import plot_edges, plot_trajectory

    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out-dir {out_dir}: cannot create it ({exc.strerror})") from None
    if not os.access(out_dir, os.W_OK):
        raise UsageError(f"--out-dir {out_dir}: not writable")
    fig = Figure(figsize=(15, 5), layout="constrained")
    axes = fig.subplots(1, 3)
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
    try:
        fig.savefig(path, dpi=110, metadata={"Software": None})
    except OSError as exc:
        raise UsageError(f"cannot write {path} ({exc.strerror})") from None
    return path


def add_parsers(sub) -> None:
    s = sub.add_parser("generate", help="write a seeded synthetic world (g2o) and its ground truth")
    s.add_argument("--world", choices=["manhattan", "circle", *WORLDS3D], default="manhattan",
                   help="planar: manhattan, circle; 3-D: sphere3d, torus3d, grid3d (about --poses poses; the sigmas "
                        "are those of translation and rotation)")
    s.add_argument("--poses", type=positive_int, default=500)
    s.add_argument("--seed", type=nonneg_int, default=0)
    s.add_argument("--sigma-xy", type=nonneg_float, default=None, help="position noise std [m]")
    s.add_argument("--sigma-theta", type=nonneg_float, default=None, help="orientation noise std [rad]")
    s.add_argument("--info-sigma-xy", type=positive_float, default=None, metavar="SIGMA",
                   help="the position sigma the information is written with (default: --sigma-xy's, or 0.05 when "
                        "it is 0); a tiny --sigma-xy with a realistic one gives a nearly noise-free graph")
    s.add_argument("--info-sigma-theta", type=positive_float, default=None, metavar="SIGMA",
                   help="the same for the orientation (default: --sigma-theta's, or 0.02 when it is 0)")
    s.add_argument("--laps", type=positive_float, default=3.0, help="circle world: number of turns")
    s.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="graph file (vertices = dead-reckoning guess); - for standard output (then give --truth)")
    s.add_argument("--outliers", type=nonneg_float, default=0.0, metavar="FRACTION",
                   help="append FRACTION × (number of edges) false loop closures: random pairs of "
                        "poses, a uniform relative pose (translation in a 20 m square, 3-D: cube; any rotation), the "
                        "information of a real edge; seeded by --seed; --json lists them as outlier_edges")
    s.add_argument("--truth", help="ground-truth file (default: OUT with .truth before the suffix)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_generate)

    s = sub.add_parser("demo", help="the main job on the embedded default: synthetic world, LAGO both ways")
    s.add_argument("--poses", type=positive_int, default=1000)
    s.add_argument("--seed", type=nonneg_int, default=0)
    s.add_argument("--out-dir", default="figures", help="where demo.png goes (default: figures)")
    s.add_argument("--no-figure", action="store_true")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_demo)

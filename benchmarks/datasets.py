"""Section ``datasets`` of ``python benchmarks/run.py``: LAGO on every public dataset.

Per file (``_bench.FILES``), in one pass:

* the regularization — chords l = m − n + 1, fundamental cycles with k ≠ 0 for the seed's route
  (odometric tree, tree rounding) and for the default route (BFS tree, chordal regularizer), χ² of LAGO by
  each route against the reference minimum (``lago_cvx.datasets.REFERENCE_CHI2``) and the ratios;
* the time of each step of closed-form LAGO, default route (median of ``--repeat`` runs of ``lago(graph)``,
  file reading excluded), of the whole pipeline with ``method="cvxpy"`` (median of max(1, repeat/2) runs), and the
  largest relative difference cvxpy ↔ closed form of phases 1 and 3 on the same inputs
  (``compare_methods``);
* Gauss–Newton (``lago_cvx.refine``) from LAGO and from odometry: dead reckoning along the odometric
  chain (``odometry_guess``; along the BFS tree when the chain is broken, marked "bfs");
* GTSAM's ``lago.initialize`` (``lago_cvx.peers``), its median time and its χ², when gtsam is installed.
"""

from __future__ import annotations

import statistics

import _bench
from lago_cvx import chi2, compare_methods, lago, odometry_guess, refine, spanning_tree
from lago_cvx.datasets import REFERENCE_CHI2
from lago_cvx.errors import GraphError
from lago_cvx.peers import gtsam_factor_graph, gtsam_lago, have_gtsam

STEPS = ("tree", "regularization", "phase1", "phase2", "phase3", "positions", "total")

REGULARIZATION_HEAD = ["file", "poses", "edges", "chords", "k≠0 (seed)", "k≠0 (default)",
                       "χ² LAGO seed route", "χ² LAGO default route", "χ² reference min", "ratio (seed)",
                       "ratio (default)", "closed form [ms]", "max rel diff cvxpy (ph1 / ph3 / positions)"]
TIMING_HEAD = ["file", "poses", "edges", "reg [ms]", "ph1 [ms]", "ph2 [ms]", "ph3 [ms]", "positions [ms]",
               "LAGO total [ms]",
               "cvxpy total [ms]", "χ² LAGO", "χ² min", "χ² GN from LAGO (iters)", "χ² GN from odometry (iters)",
               "GTSAM lago [ms]", "ours / GTSAM", "χ² GTSAM"]


def add_arguments(group) -> None:
    group.add_argument("--gn-iterations", type=int, default=50,
                       help="Gauss–Newton iterations from LAGO and from odometry (default 50)")


def has_odometric_chain(graph) -> bool:
    try:
        spanning_tree(graph, "odometry")
    except GraphError:
        return False
    return True


def odometry_start(graph):
    """(dead-reckoning poses, label): along the odometric chain, or along the BFS tree if it is broken."""
    if has_odometric_chain(graph):
        return odometry_guess(graph, spanning_tree="odometry"), ""
    return odometry_guess(graph, spanning_tree="bfs"), ", bfs"


def measure(rel: str, graph, repeat: int, gn_iterations: int) -> tuple[list, list]:
    """One row of each table for ``graph`` (read from dataset file ``rel``)."""
    chain = has_odometric_chain(graph)
    odo = lago(graph, route="seed") if chain else None
    runs = [lago(graph) for _ in range(repeat)]
    res = runs[-1]
    ms = {k: 1e3 * statistics.median(r.timings[k] for r in runs) for k in STEPS}
    t_cvx, _ = _bench.median_time(lambda: lago(graph, method="cvxpy"), max(1, repeat // 2))
    _, report = compare_methods(graph)
    diff = report["max_rel_diff"]
    from_lago = refine(graph, res.poses, max_iterations=gn_iterations)
    start, how = odometry_start(graph)
    from_odo = refine(graph, start, max_iterations=gn_iterations)
    gt = ["–", "–", "–"]
    if have_gtsam():
        poses, t_g = gtsam_lago(graph, odometric_path=chain, repeat=repeat, factor_graph=gtsam_factor_graph(graph))
        gt = [f"{1e3 * t_g:.1f}", f"{ms['total'] / (1e3 * t_g):.2f}", f"{chi2(graph, poses):.6g}"]
    ref = REFERENCE_CHI2.get(rel)
    reg_row = [rel, graph.n_poses, graph.n_edges, res.regularization.chords.size,
               odo.regularization.n_regularized if odo else "–", res.regularization.n_regularized,
               _bench.fmt(odo.chi2 if odo else None), f"{res.chi2:.6g}", _bench.fmt(ref),
               _bench.fmt(odo.chi2 / ref if (odo and ref) else None, ".3f"),
               _bench.fmt(res.chi2 / ref if ref else None, ".4f"), f"{ms['total']:.1f}",
               f"{diff['phase1']:.1e} / {diff['phase3']:.1e} / {diff['positions']:.1e}"]
    time_row = [rel, graph.n_poses, graph.n_edges, f"{ms['tree'] + ms['regularization']:.1f}",
                f"{ms['phase1']:.1f}", f"{ms['phase2']:.1f}", f"{ms['phase3']:.1f}", f"{ms['positions']:.1f}",
                f"{ms['total']:.1f}",
                f"{1e3 * t_cvx:.0f}", f"{res.chi2:.6g}", _bench.fmt(ref),
                f"{from_lago.chi2:.6g} ({from_lago.iterations})",
                f"{from_odo.chi2:.6g} ({from_odo.iterations}{how})", *gt]
    return reg_row, time_row


def run(args) -> str:
    out = ["# LAGO on the public datasets", ""]
    skipped = _bench.datasets_skipped()
    if skipped:
        return "\n".join(out + [skipped])
    _bench.warm_up()
    reg_rows, time_rows = [], []
    for rel, graph in _bench.each_dataset():
        reg_row, time_row = measure(rel, graph, args.repeat, args.gn_iterations)
        print(f"  {rel}: χ² LAGO {time_row[10]}, GN from LAGO {time_row[12]}, from odometry {time_row[13]}, "
              f"{time_row[8]} ms", flush=True)
        reg_rows.append(reg_row)
        time_rows.append(time_row)
    out += [
        f"Medians of {args.repeat} runs. gtsam installed: {have_gtsam()}.",
        "",
        "Conventions: χ² = Σ eᵀΩe (no ½) in each file's own cost (g2o's χ² for g2o files, eq. (3) for TORO files; `lago_cvx.conventions`). Reference minima: the lower of `refine` and g2o's LM from there "
        "(`lago_cvx.datasets.REFERENCE_CHI2`; best found by Gauss–Newton, not certified). Times are medians "
        "over the runs, wall clock, of the LAGO step only (file reading excluded).",
        "",
        "## Regularization, χ² and cvxpy against the closed form",
        "",
        "chords = m − n + 1 loop closures of the spanning tree; k≠0 = fundamental cycles whose sum needed a 2kπ "
        "correction, by the seed's route (`lago(graph, route=\"seed\")`: odometric tree, tree rounding, "
        "blkdiag(P_Δ, P_δ), phase-3 poses; – where the odometric chain is broken) and by the default route "
        "(`lago(graph)`: BFS tree, chordal regularizer, full information, positions re-solved); ratio = χ² / "
        "reference minimum; closed form = median time of `lago(graph)`; max rel diff = ‖a − b‖∞/‖b‖∞ between "
        "the cvxpy (Clarabel) and closed-form solutions of phases 1 and 3 and of the position polish on the "
        "same inputs (`compare_methods`).",
        "",
        _bench.table(REGULARIZATION_HEAD, reg_rows),
        "",
        "## Time per step, refinement from LAGO and from odometry, GTSAM side by side",
        "",
        "Default route. reg = spanning tree + regularization; positions = the position polish; cvxpy total = "
        "`lago(graph, method=\"cvxpy\")`, the chordal relaxation, phases 1 and 3 and the polish as cvxpy "
        f"problems solved by Clarabel (median of {max(1, args.repeat // 2)} run(s)). Refinement = "
        f"`lago_cvx.refine` Gauss–Newton (at most {args.gn_iterations} iterations, tolerance 1e-9 relative χ² "
        "decrease) from the LAGO estimate and from odometry = dead reckoning along the odometric chain "
        "(`lago_cvx.odometry_guess`), which is what the files' own VERTEX lines hold (\", bfs\": along the BFS "
        "tree, the chain being broken). GTSAM (`gtsam.lago.initialize`, `lago_cvx.peers`) is given diagonal "
        "noise models (marginal sigmas) and a prior on the anchor, the odometric path when the chain is "
        "complete; only `initialize` is timed (median of the same number of runs); ours / GTSAM = LAGO total "
        "/ GTSAM time; χ² GTSAM = χ² of GTSAM's estimate on our graph.",
        "",
        _bench.table(TIMING_HEAD, time_rows),
    ]
    return "\n".join(out)

"""Section ``scaling`` of ``python benchmarks/run.py``: the graph machinery and LAGO on synthetic
Manhattan worlds of growing size.

Per size n (``manhattan_world(n, seed=0)``), medians of ``--repeat`` runs: reading the world back from a
g2o file, the three spanning trees (BFS, odometric chain, minimum spanning tree), the tree rounding
(``regularize`` on the BFS tree) and closed-form LAGO (``lago(graph)``); at the sizes of
``--cvxpy-sizes`` also phases 1 and 3 as cvxpy problems solved by Clarabel on the closed form's inputs
(``compare_methods``, one run) and their largest relative difference to the closed form. Then the
least-squares slope of log(LAGO time) against log(edges): 1 is linear time.

The fundamental cycle basis C is not timed at scale: nnz(C) is the total length of the fundamental
cycles, O(l·n) for long trajectories, and LAGO never forms it.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

import _bench
from lago_cvx import compare_methods, lago, manhattan_world, read_graph, regularize, spanning_tree, write_graph

SIZES = [1000, 3000, 10000, 30000, 100000]
CVXPY_SIZES = [1000, 10000, 100000]
QUICK_SIZES = [1000, 3000, 10000]
QUICK_CVXPY_SIZES = [1000, 10000]
TREES = ("bfs", "odometry", "mst")

HEAD = ["poses", "edges", "read g2o [s]", "bfs tree [s]", "odometry tree [s]", "mst tree [s]", "regularize [s]",
        "LAGO closed form [s]", "cvxpy (Clarabel) phases 1+3 [s]", "max rel diff (ph1 / ph3)"]


def add_arguments(group) -> None:
    group.add_argument("--sizes", type=int, nargs="+", default=None,
                       help=f"poses of the synthetic worlds (default {' '.join(map(str, SIZES))}; "
                            f"--quick {' '.join(map(str, QUICK_SIZES))})")
    group.add_argument("--cvxpy-sizes", type=int, nargs="*", default=None,
                       help=f"sizes also solved with cvxpy (default {' '.join(map(str, CVXPY_SIZES))}; "
                            f"--quick {' '.join(map(str, QUICK_CVXPY_SIZES))})")


def loglog_slope(x, y) -> float:
    """Least-squares slope of log y against log x (nan with fewer than two points)."""
    if len(x) < 2:
        return float("nan")
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def measure(n: int, repeat: int, with_cvxpy: bool) -> tuple[list, int, float]:
    """(table row, edges, median closed-form LAGO seconds) for the world of ``n`` poses."""
    g = manhattan_world(n, seed=0).graph
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "world.g2o"
        write_graph(path, g)
        t_read, _ = _bench.median_time(lambda: read_graph(path), repeat)
    trees = {k: _bench.median_time(lambda k=k: spanning_tree(g, k), repeat) for k in TREES}
    t_reg, _ = _bench.median_time(lambda: regularize(g, trees["bfs"][1]), repeat)
    t_lago, _ = _bench.median_time(lambda: lago(g), repeat)
    cvx = ["–", "–"]
    if with_cvxpy:
        _, report = compare_methods(g)
        d = report["max_rel_diff"]
        cvx = [f"{sum(report['cvxpy_timings'].values()):.2f}", f"{d['phase1']:.1e} / {d['phase3']:.1e}"]
    row = [g.n_poses, g.n_edges, f"{t_read:.3f}", *(f"{trees[k][0]:.3f}" for k in TREES), f"{t_reg:.3f}",
           f"{t_lago:.3f}", *cvx]
    return row, g.n_edges, t_lago


def run(args) -> str:
    sizes = args.sizes or (QUICK_SIZES if args.quick else SIZES)
    cvxpy_sizes = set(args.cvxpy_sizes if args.cvxpy_sizes is not None
                      else QUICK_CVXPY_SIZES if args.quick else CVXPY_SIZES)
    _bench.warm_up()
    rows, edges, times = [], [], []
    for n in sizes:
        row, m, t = measure(n, args.repeat, n in cvxpy_sizes)
        print("  " + " | ".join(map(str, row)), flush=True)
        rows.append(row)
        edges.append(m)
        times.append(t)
    return "\n".join([
        "# Scaling on synthetic Manhattan worlds (seed 0)", "",
        f"Medians of {args.repeat} runs (cvxpy: one run). read g2o = `read_graph` of the world written by "
        "`write_graph`; trees = `spanning_tree(graph, kind)`; regularize = the tree rounding on the BFS tree; "
        "LAGO closed form = `lago(graph)` (tree, regularization, phases 1–3); cvxpy = phases 1 and 3 as cvxpy "
        "problems solved by Clarabel on the closed form's inputs (`compare_methods`), max rel diff = "
        "‖a − b‖∞/‖b‖∞ against the closed form. The fundamental cycle basis C is not timed: nnz(C) is the "
        "total length of the fundamental cycles, O(l·n) for long trajectories, and LAGO never forms it.", "",
        _bench.table(HEAD, rows), "",
        f"Log–log slope of closed-form LAGO time against edges: **{loglog_slope(edges, times):.2f}**",
    ])

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

import json
import subprocess
import sys
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
    group.add_argument("--process-sizes", type=int, nargs="*", default=None,
                       help=f"sizes of the per-process time/memory sweep (default {' '.join(map(str, PROCESS_SIZES))}; "
                            f"--quick {' '.join(map(str, QUICK_PROCESS_SIZES))})")
    group.add_argument("--cvxpy-sizes", type=int, nargs="*", default=None,
                       help=f"sizes also solved with cvxpy (default {' '.join(map(str, CVXPY_SIZES))}; "
                            f"--quick {' '.join(map(str, QUICK_CVXPY_SIZES))})")


#: Sizes of the per-process sweep (time and peak memory of the LAGO step, each size in its own process).
PROCESS_SIZES = [1000, 3000, 10000, 30000, 100000, 300000, 1000000]
QUICK_PROCESS_SIZES = [1000, 3000, 10000]

#: What each child process runs: world generation (not timed), the LAGO step (default route, then the
#: seed route), and Σ colcount² of phase 3's actual factor (QDLDL's L, or the multifrontal plan).
_CHILD = r"""
import json, sys, time
import numpy as np
import lago_cvx as lc
n = int(sys.argv[1])
g = lc.manhattan_world(n, seed=0).graph
out = {"n": n, "m": g.n_edges}
for route in ("default", "seed"):
    t = time.perf_counter()
    res = lc.lago(g, route=route)
    out[route] = {"total": time.perf_counter() - t, **{k: v for k, v in res.timings.items()}}
    f = getattr(res.phase3.factor, "pose_major", None)
    if getattr(f, "blocks", None) is not None:
        out[route + "_flops"] = f.blocks.layout.plan.flops(3)
    elif hasattr(f, "flops"):  # QDLDL: Σ colcount² of its L
        out[route + "_flops"] = f.flops()
    # this process's own high-water mark: VmHWM (ru_maxrss would include the parent's, copied at fork)
    with open("/proc/self/status") as fh:
        out[route + "_rss"] = next(int(ln.split()[1]) for ln in fh if ln.startswith("VmHWM:")) * 1024
print(json.dumps(out))
"""


def process_sweep(sizes) -> list[dict]:
    """Each size in its own child process: the child's timings, Σ colcount² and its own peak resident
    memory (``VmHWM`` of ``/proc/self/status`` at its end: world, graph and both LAGO runs; ``ru_maxrss``
    would report the parent's, which Linux copies into a child at fork)."""
    rows = []
    for n in sorted(sizes):
        proc = subprocess.run([sys.executable, "-c", _CHILD, str(n)], capture_output=True, text=True, check=True)
        out = json.loads(proc.stdout.strip().splitlines()[-1])
        out["peak_children"] = max(out["default_rss"], out["seed_rss"])
        rows.append(out)
        print(f"  {n} poses: default {out['default']['total']:.2f} s, seed {out['seed']['total']:.2f} s, "
              f"peak {out['peak_children'] / 2**30:.2f} GiB", flush=True)
    return rows


def scaling_figure(rows, path: Path) -> dict:
    """Log–log plots against edges: the LAGO step's time (default and seed routes) with Σ colcount² of
    phase 3 scaled onto it, and the process's peak memory; written to ``path`` with fixed metadata (the
    PNG is byte-stable for the same numbers). Returns the fitted slopes."""
    from matplotlib.figure import Figure

    m = np.array([r["m"] for r in rows], float)
    slopes = {}
    fig = Figure(figsize=(11, 4.4))
    ax, ax_mem = fig.subplots(1, 2)
    for route, style in (("default", "o-"), ("seed", "s--")):
        t = np.array([r[route]["total"] for r in rows])
        slopes[route] = loglog_slope(m, t)
        ax.loglog(m, t, style, label=f"LAGO {route} route (slope {slopes[route]:.2f})")
    fl = np.array([r.get("default_flops", np.nan) for r in rows])
    if np.isfinite(fl).all():
        slopes["flops"] = loglog_slope(m, fl)
        scale = rows[-1]["default"]["total"] / fl[-1]
        ax.loglog(m, fl * scale, ":", color="gray", label=f"Σ colcount², phase 3 (slope {slopes['flops']:.2f}, scaled)")
    ax.set(xlabel="edges", ylabel="seconds", title="LAGO step on Manhattan worlds (one process per size)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    peak = np.array([r["peak_children"] for r in rows], float) / 2**30
    slopes["memory"] = loglog_slope(m, peak)
    ax_mem.loglog(m, peak, "o-", color="C2", label=f"peak resident memory (slope {slopes['memory']:.2f})")
    ax_mem.set(xlabel="edges", ylabel="GiB", title="peak memory of the process (VmHWM)")
    ax_mem.legend(fontsize=8)
    ax_mem.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100, metadata={"Software": None})
    return slopes


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
    psizes = args.process_sizes if args.process_sizes is not None else (
        QUICK_PROCESS_SIZES if args.quick else PROCESS_SIZES)
    prows = process_sweep(psizes) if psizes else []
    slopes = scaling_figure(prows, Path(args.out) / "scaling.png") if len(prows) > 1 else {}
    ptable = _bench.table(
        ["poses", "edges", "default route [s]", "tree", "regularization", "phase1", "phase2", "phase3", "positions",
         "seed route [s]", "seed phase3 [s]", "Σ colcount² (phase 3)", "peak memory [GiB]"],
        [[r["n"], r["m"], f"{r['default']['total']:.2f}",
          *(f"{r['default'][k]:.2f}" for k in ("tree", "regularization", "phase1", "phase2", "phase3", "positions")),
          f"{r['seed']['total']:.2f}", f"{r['seed']['phase3']:.2f}", _bench.fmt(r.get("default_flops"), ".3g"),
          f"{r['peak_children'] / 2**30:.2f}"] for r in prows])
    return "\n".join([
        "# Scaling on synthetic Manhattan worlds (seed 0)", "",
        "## The LAGO step per process, 1 000 to 1 000 000 poses", "",
        "Each size in its own child process (world generated there, not timed); time of `lago(graph)` "
        "(default route) by step and of `lago(graph, route=\"seed\")`; Σ colcount² of phase 3's actual "
        "factor (the Cholesky multiply–add count); peak memory = the child's own high-water mark "
        "(`VmHWM`: world, graph, both runs and the extra factorization that counts Σ colcount² — more than a "
        "solve needs: the whole `lago-cvx solve` of the 1M world peaks at 3.6–4.4 GiB, `million.md`). Figure: [`scaling.png`](scaling.png).", "",
        ptable, "",
        "Log–log slopes against edges: " + ", ".join(f"{k} {v:.2f}" for k, v in slopes.items()), "",
        "How to read them. A planar graph of n vertices has a factorization with O(n log n) fill and "
        "O(n^1.5) multiply–adds under nested dissection (Lipton, Rose and Tarjan, 1979), and no ordering does "
        "better in general; Manhattan worlds are nearly planar (loop closures join poses close in space), so "
        "Σ colcount² should grow with a slope between 1 and 1.5 against the edges (m ≈ 1.8 n), and the LAGO "
        "time with it once phase 3's factorization dominates — the other steps (trees, the chordal and "
        "position solves on 2n unknowns, phase 1 on n) are cheaper by a constant, not by an order.", "",
        "## Graph machinery and cvxpy, in process", "",
        f"Medians of {args.repeat} runs (cvxpy: one run). read g2o = `read_graph` of the world written by "
        "`write_graph`; trees = `spanning_tree(graph, kind)`; regularize = the tree rounding on the BFS tree; "
        "LAGO closed form = `lago(graph)` (tree, regularization, phases 1–3); cvxpy = phases 1 and 3 as cvxpy "
        "problems solved by Clarabel on the closed form's inputs (`compare_methods`), max rel diff = "
        "‖a − b‖∞/‖b‖∞ against the closed form. The fundamental cycle basis C is not timed: nnz(C) is the "
        "total length of the fundamental cycles, O(l·n) for long trajectories, and LAGO never forms it.", "",
        _bench.table(HEAD, rows), "",
        f"Log–log slope of closed-form LAGO time against edges: **{loglog_slope(edges, times):.2f}**",
    ])

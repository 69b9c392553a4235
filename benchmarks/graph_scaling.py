"""Scaling of the graph machinery and of closed-form LAGO on synthetic Manhattan worlds.

    python benchmarks/graph_scaling.py [--sizes 1000 10000 100000] [--repeat 3]

Prints a Markdown table (medians over --repeat runs): poses, edges, time to read the g2o file,
build the three spanning trees, regularize, and run closed-form LAGO; writes
benchmarks/graph_scaling.md. The fundamental cycle basis C is not timed at scale: nnz(C) is the
total length of the fundamental cycles, O(l·n) for long trajectories, and LAGO never forms it.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lago_cvx import lago, manhattan_world, read_graph, regularize, spanning_tree, write_graph  # noqa: E402


def median_time(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 3000, 10000, 30000, 100000])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "graph_scaling.md"))
    args = ap.parse_args(argv)
    rows = ["| poses | edges | read g2o [s] | bfs tree [s] | odometry tree [s] | mst tree [s] | "
            "regularize [s] | LAGO closed form [s] |", "|" + "---|" * 8]
    edges, lago_t = [], []
    for n in args.sizes:
        g = manhattan_world(n, seed=0).graph
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "w.g2o"
            write_graph(p, g)
            t_read, _ = median_time(lambda: read_graph(p), args.repeat)
        tt = {k: median_time(lambda k=k: spanning_tree(g, k), args.repeat) for k in ("bfs", "odometry", "mst")}
        t_reg, _ = median_time(lambda: regularize(g, tt["bfs"][1]), args.repeat)
        t_lago, _ = median_time(lambda: lago(g), args.repeat)
        rows.append(f"| {g.n_poses} | {g.n_edges} | {t_read:.3f} | {tt['bfs'][0]:.3f} | {tt['odometry'][0]:.3f} | "
                    f"{tt['mst'][0]:.3f} | {t_reg:.3f} | {t_lago:.3f} |")
        print(rows[-1], flush=True)
        edges.append(g.n_edges)
        lago_t.append(t_lago)
    if len(edges) > 1:
        slope = np.polyfit(np.log(edges), np.log(lago_t), 1)[0]
        rows.append("")
        rows.append(f"log–log slope of closed-form LAGO time vs edges: {slope:.2f}")
        print(rows[-1])
    machine = f"{platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}"
    Path(args.out).write_text("\n".join([f"<!-- python benchmarks/graph_scaling.py ({machine}) -->", *rows, ""]))
    return 0


if __name__ == "__main__":
    sys.exit(main())

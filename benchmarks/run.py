"""The benchmark suite: LAGO on every public dataset and on a synthetic scaling sweep, refinement from
LAGO vs from odometry, and GTSAM's ``lago.initialize`` side by side (when the ``gtsam`` extra is
installed). Prints Markdown tables and writes them to ``benchmarks/results.md``.

    python benchmarks/run.py                       # everything (≈ 10 min on a 2-core machine)
    python benchmarks/run.py --quick               # fewer repeats, sweep up to 30k poses
    python benchmarks/run.py --datasets DIR        # datasets elsewhere than ../shared/datasets

Conventions: χ² = Σ eᵀΩe (g2o, no ½). Times are medians over ``--repeat`` runs, wall clock, on the
machine named in the output; the LAGO step only (file reading excluded). "odometry" = dead reckoning
along the odometric chain (``lago_cvx.refine.odometry_guess``), which is what the files' own VERTEX
lines hold. Refinement = ``lago_cvx.refine`` Gauss–Newton, tolerance 1e-9 relative χ² decrease.
GTSAM is given diagonal noise models (marginal sigmas) and a prior on pose 0 (see lago_cvx/peers.py).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lago_cvx import chi2, lago, manhattan_world, read_graph  # noqa: E402
from lago_cvx.graph import spanning_tree  # noqa: E402
from lago_cvx.peers import gtsam_factor_graph, gtsam_lago, have_gtsam  # noqa: E402
from lago_cvx.posegraph import GraphError  # noqa: E402
from lago_cvx.refine import odometry_guess, refine  # noqa: E402

#: (file, χ² minimum of the datasets README §4.2 or None)
DATASETS = [
    ("gtsam/noisyToyGraph.txt", None),
    ("se-sync/MIT.g2o", 39.6013),
    ("carlone/FR079_P_toro.graph", 36.4248),
    ("se-sync/CSAIL.g2o", 61.143),
    ("carlone/CSAIL_P_toro.graph", 61.143),
    ("carlone/INTEL_P_toro.graph", 213.212),
    ("carlone/input_INTEL_g2o.g2o", 214.171),
    ("se-sync/intel.g2o", 44.4178),
    ("se-sync/manhattan.g2o", 3533.46),
    ("carlone/M3500_P_toro.graph", 3533.46),
    ("carlone/input_M3500_g2o.g2o", 137.913),
    ("carlone/input_M3500a_g2o.g2o", 912.115),
    ("se-sync/city10000.g2o", 511.985),
]


def median_time(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}"


def odometry_start(graph):
    try:
        return odometry_guess(graph, spanning_tree="odometry"), "odometry"
    except GraphError:
        return odometry_guess(graph, spanning_tree="bfs"), "bfs dead reckoning"


def dataset_rows(base: Path, repeat: int, gn_iterations: int):
    head = ("| file | poses | edges | reg [ms] | ph1 [ms] | ph2 [ms] | ph3 [ms] | LAGO total [ms] | cvxpy total [ms] "
            "| χ² LAGO | χ² min | χ² GN from LAGO (iters) | χ² GN from odometry (iters) | GTSAM lago [ms] "
            "| ours / GTSAM | χ² GTSAM |")
    rows = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for rel, ref in DATASETS:
        p = base / rel
        if not p.is_file():
            rows.append(f"| {rel} | missing | | | | | | | | | | | | | | |")
            continue
        g = read_graph(p)
        runs = [lago(g) for _ in range(repeat)]
        res = runs[-1]
        med = {k: 1e3 * statistics.median(r.timings[k] for r in runs)
               for k in ("tree", "regularization", "phase1", "phase2", "phase3", "total")}
        t_cvx, _ = median_time(lambda: lago(g, method="cvxpy"), max(1, repeat // 2))
        from_lago = refine(g, res.poses, max_iterations=gn_iterations)
        start, _ = odometry_start(g)
        from_odo = refine(g, start, max_iterations=gn_iterations)
        gt = "–", "–", "–"
        if have_gtsam():
            fg = gtsam_factor_graph(g)
            has_chain = True
            try:
                spanning_tree(g, "odometry")
            except GraphError:
                has_chain = False
            poses, t_g = gtsam_lago(g, odometric_path=has_chain, repeat=repeat, factor_graph=fg)
            gt = f"{1e3 * t_g:.1f}", f"{med['total'] / (1e3 * t_g):.2f}", f"{chi2(g, poses):.6g}"
        rows.append(
            f"| {rel} | {g.n_poses} | {g.n_edges} | {med['tree'] + med['regularization']:.1f} | {med['phase1']:.1f} | "
            f"{med['phase2']:.1f} | {med['phase3']:.1f} | {med['total']:.1f} | {1e3 * t_cvx:.0f} | {res.chi2:.6g} | "
            f"{ref if ref else '–'} | {from_lago.chi2:.6g} ({from_lago.iterations}) | "
            f"{from_odo.chi2:.6g} ({from_odo.iterations}) | {gt[0]} | {gt[1]} | {gt[2]} |")
        print(rows[-1], flush=True)
    return rows


def sweep_rows(sizes, repeat: int, cvxpy_sizes):
    head = "| poses | edges | LAGO closed form [s] | cvxpy (Clarabel) phases 1+3 [s] | max rel diff (ph1 / ph3) |"
    rows = [head, "|---|---|---|---|---|"]
    edges, times = [], []
    for n in sizes:
        g = manhattan_world(n, seed=0).graph
        t, res = median_time(lambda: lago(g), repeat)
        cvx = "–"
        if n in cvxpy_sizes:
            t0 = time.perf_counter()
            r = lago(g, method="cvxpy")
            t_c = time.perf_counter() - t0
            d1 = np.abs(r.phase1.theta - res.phase1.theta).max() / np.abs(res.phase1.theta).max()
            d3 = np.abs(r.phase3.x_star - res.phase3.x_star).max() / np.abs(res.phase3.x_star).max()
            cvx = f"{t_c:.2f} | {d1:.1e} / {d3:.1e}"
        else:
            cvx = "– | –"
        rows.append(f"| {g.n_poses} | {g.n_edges} | {t:.3f} | {cvx} |")
        print(rows[-1], flush=True)
        edges.append(g.n_edges)
        times.append(t)
    slope = float(np.polyfit(np.log(edges), np.log(times), 1)[0]) if len(edges) > 1 else float("nan")
    rows += ["", f"Log–log slope of closed-form LAGO time against edges: **{slope:.2f}**"]
    print(rows[-1])
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", default=str(ROOT.parent / "shared" / "datasets"))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--gn-iterations", type=int, default=50)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results.md"))
    args = ap.parse_args(argv)
    repeat = 2 if args.quick else args.repeat
    sizes = [1000, 3000, 10000, 30000] if args.quick else [1000, 3000, 10000, 30000, 100000]
    cvxpy_sizes = {1000, 10000} if args.quick else {1000, 10000, 100000}
    lines = [f"# Benchmark results", "", f"Generated by `python benchmarks/run.py` on {machine()},",
             f"{time.strftime('%Y-%m-%d')}. Medians of {repeat} runs. gtsam installed: {have_gtsam()}.", ""]
    base = Path(args.datasets)
    if base.is_dir():
        lines += ["## Public datasets", ""] + dataset_rows(base, repeat, args.gn_iterations) + [""]
    else:
        print(f"datasets folder {base} not found: dataset table skipped", file=sys.stderr)
    lines += ["## Synthetic Manhattan worlds (seed 0)", ""] + sweep_rows(sizes, repeat, cvxpy_sizes) + [""]
    Path(args.out).write_text("\n".join(lines))
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

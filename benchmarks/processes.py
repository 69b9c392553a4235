"""LAGO in the processes scientific Python users run: forked workers after a warm parent, spawned workers,
two threads at once, joblib, and joblib's Dask backend — every result identical to the serial run.

    python benchmarks/processes.py [--rounds 8] [--data ../shared/datasets] [--dask]

Writes ``benchmarks/processes.md``. The parent warms itself with ``lago()`` (the engine's pools, orderings
and thread state exist before the fork), then runs ``--rounds`` rounds of a forked
``ProcessPoolExecutor(2)`` over the graphs; every χ² must equal the serial one to the last bit and no
warning may be raised. Without the datasets, seeded synthetic worlds stand in.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import logging
import multiprocessing as mp
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import lago_cvx as lc  # noqa: E402

REAL = ["se-sync/MIT.g2o", "se-sync/CSAIL.g2o", "se-sync/intel.g2o", "se-sync/manhattan.g2o",
        "carlone/input_INTEL_g2o.g2o", "carlone/input_M3500_g2o.g2o"]


def graphs(data: Path) -> dict:
    found = {name: data / name for name in REAL if (data / name).exists()}
    if len(found) == len(REAL):
        return {Path(k).stem: lc.read_graph(v) for k, v in found.items()}
    return {f"manhattan_{n}_{s}": lc.manhattan_world(n, seed=s).graph for n, s in
            ((300, 0), (800, 1), (1500, 2), (3000, 3), (500, 4), (1000, 5))}


class _Count(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.records = []

    def emit(self, record):
        self.records.append(record.getMessage())


def chi2_of(graph) -> float:
    """χ² of ``lago(graph)``; a Python warning or a logged warning in the worker is a failure (memory two
    processes write at once shows as "normal equations too ill-conditioned" before it shows in χ²)."""
    counter = _Count()
    logging.getLogger("lago_cvx").addHandler(counter)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            value = float(lc.lago(graph).chi2)
    finally:
        logging.getLogger("lago_cvx").removeHandler(counter)
    if counter.records:
        raise RuntimeError(f"warnings in a worker: {counter.records[:2]}")
    return value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--data", type=Path, default=HERE.parent.parent / "shared" / "datasets")
    ap.add_argument("--dask", action="store_true", help="also joblib's Dask backend on a LocalCluster")
    ap.add_argument("--out", type=Path, default=HERE / "processes.md")
    args = ap.parse_args(argv)
    gs = graphs(args.data)
    names = list(gs)
    t = time.perf_counter()
    serial = {k: chi2_of(g) for k, g in gs.items()}  # also warms the parent
    rows = [("serial", 1, time.perf_counter() - t, "reference")]

    def check(label, rounds, values_per_round, seconds):
        bad = [(r, k) for r, vals in enumerate(values_per_round) for k, v in zip(names, vals) if v != serial[k]]
        rows.append((label, rounds, seconds, "identical" if not bad else f"DIFFERENT in {len(bad)}"))
        return not bad

    ok = True
    for method in ("fork", "spawn"):
        ctx = mp.get_context(method)
        t = time.perf_counter()
        got = []
        for _ in range(args.rounds if method == "fork" else 1):
            with cf.ProcessPoolExecutor(2, mp_context=ctx) as ex:
                got.append(list(ex.map(chi2_of, [gs[k] for k in names])))
        ok &= check(f"ProcessPoolExecutor(2), {method}", len(got), got, time.perf_counter() - t)
    t = time.perf_counter()
    with cf.ThreadPoolExecutor(2) as ex:
        got = [list(ex.map(chi2_of, [gs[k] for k in names]))]
    ok &= check("two threads at once", 1, got, time.perf_counter() - t)
    import joblib

    t = time.perf_counter()
    got = [joblib.Parallel(n_jobs=2)(joblib.delayed(lc.lago)(gs[k]) for k in names)]
    ok &= check("joblib.Parallel(n_jobs=2), results pickled back", 1, [[float(r.chi2) for r in got[0]]],
                time.perf_counter() - t)
    if args.dask:
        from dask.distributed import Client, LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                Client(cluster):
            t = time.perf_counter()
            with joblib.parallel_config(backend="dask"):
                got = joblib.Parallel()(joblib.delayed(lc.lago)(gs[k]) for k in names)
            ok &= check("joblib on dask.distributed.LocalCluster(2)", 1, [[float(r.chi2) for r in got]],
                        time.perf_counter() - t)
    lines = [
        "# LAGO in worker processes and threads",
        "",
        f"`python benchmarks/processes.py --rounds {args.rounds}{' --dask' if args.dask else ''}` — lago_cvx "
        f"{lc.__version__}, {time.strftime('%Y-%m-%d')}, {platform.machine()} Linux, "
        f"{len(__import__('os').sched_getaffinity(0))} cores, Python {platform.python_version()}.",
        "",
        f"Graphs: {', '.join(names)}. The parent runs `lago()` on each first (the serial reference, which also "
        "warms the engine). Every χ² is compared with the serial one for exact equality; a warning in a worker "
        "fails it.",
        "",
        "| how | rounds | seconds | χ² against serial |",
        "|---|---|---|---|",
        *[f"| {a} | {b} | {c:.2f} | {d} |" for a, b, c, d in rows],
        "",
    ]
    args.out.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

"""Section ``processes`` of benchmarks/run.py: LAGO in the processes scientific Python users run — forked
workers after a warm parent, spawned workers, two threads at once, joblib, and joblib's Dask backend —
every result identical to the serial run.

    python benchmarks/run.py processes [--processes-rounds 8]

The parent warms itself with ``lago()`` (the engine's pools, orderings and thread state exist before the
fork), then runs the rounds of a forked ``ProcessPoolExecutor(2)`` over six real graphs; every χ² must equal
the serial one to the last bit, and a warning in a worker (a Python warning or a logged one) fails it.
Without the datasets, seeded synthetic worlds stand in. ``python benchmarks/processes.py`` runs it alone
and exits 1 if anything differs.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import multiprocessing as mp
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


def graphs() -> dict:
    import _bench

    found = {name: _bench.find(name) for name in REAL}
    if all(found.values()):
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


def add_arguments(group) -> None:
    group.add_argument("--processes-rounds", type=int, default=8, metavar="N",
                       help="rounds of the forked pool after a warm parent (default 8)")


def run(args) -> str:
    text, ok = measure(2 if args.quick else args.processes_rounds)
    if not ok:
        raise RuntimeError("a worker's result differed from the serial one:\n" + text)
    return text


def measure(rounds: int) -> tuple[str, bool]:
    gs = graphs()
    names = list(gs)
    t = time.perf_counter()
    serial = {k: chi2_of(g) for k, g in gs.items()}  # also warms the parent
    rows = [("serial", 1, time.perf_counter() - t, "reference")]

    def check(label, n_rounds, values_per_round, seconds):
        bad = [(r, k) for r, vals in enumerate(values_per_round) for k, v in zip(names, vals) if v != serial[k]]
        rows.append((label, n_rounds, seconds, "identical" if not bad else f"DIFFERENT in {len(bad)}"))
        return not bad

    ok = True
    for method in ("fork", "spawn"):
        ctx = mp.get_context(method)
        t = time.perf_counter()
        got = []
        for _ in range(rounds if method == "fork" else 1):
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
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        rows.append(("joblib on dask.distributed.LocalCluster(2)", 0, 0.0, "skipped: `dask` extra not installed"))
    else:
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
        f"Graphs: {', '.join(names)}. The parent runs `lago()` on each first (the serial reference, which also "
        "warms the engine). Every χ² is compared with the serial one for exact equality; a warning in a worker "
        "(a Python warning or a logged one) fails it.",
        "",
        "| how | rounds | seconds | χ² against serial |",
        "|---|---|---|---|",
        *[f"| {a} | {b} | {c:.2f} | {d} |" for a, b, c, d in rows],
    ]
    return "\n".join(lines), ok


if __name__ == "__main__":
    text, ok = measure(8)
    print(text)
    sys.exit(0 if ok else 1)

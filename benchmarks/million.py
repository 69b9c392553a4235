"""Section ``million`` of ``python benchmarks/run.py``: large synthetic worlds, whole process, step by step.

For each size (``--million-poses``, default 100 000, 300 000 and 1 000 000 poses): the world is generated
once (``lago-cvx generate --poses n``), then ``python -m lago_cvx solve FILE -o OUT --json`` runs as a fresh
child process by the seed route and by the default route, alternately, ``--million-repeat`` times each
(after one warm-up run each). Reported: the medians of the
whole process's wall clock and peak memory (``os.wait4``), and of each LAGO step as the CLI's JSON gives
it (regularization includes the spanning tree; phase 1 includes the pose-level analysis, AMD and the
factorization of Ω_θ, that every system shares), the rest of the process (start-up, reading, χ², writing)
as the difference.

Second table: phase 3 alone (factorization and refined solve of eq. (15), ``GraphElimination.solve``) in
a fresh process per measurement, by the engine's C kernels (``lago_cvx.sparse.compiled``, their loading reported
apart) and by its NumPy fallback (``LAGO_CVX_NUMPY_ENGINE=1``, as an install without a C compiler).
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

import _bench

SIZES = (100_000, 300_000, 1_000_000)
STEPS = ("regularization", "phase1", "phase2", "phase3", "positions", "total")
PHASE3_SIZES = (30_000, 100_000, 300_000)

_PHASE3 = r"""
import os, sys, time, json
if sys.argv[2] == "numpy":
    os.environ["LAGO_CVX_NUMPY_ENGINE"] = "1"
import lago_cvx as lc
from lago_cvx.sparse import normal_equations as ne
n, engine = int(sys.argv[1]), sys.argv[2]
g = lc.manhattan_world(n, seed=0).graph
ne.GraphElimination.prepare = lambda self, b: None  # nothing made ready beside phases 1, 2: all timed here
cap = {}
if engine == "compiled":  # the kernels' start, timed apart (first: the plan and phase 1's products also use them)
    t = time.perf_counter(); from lago_cvx.sparse import compiled; compiled.available()
    cap["start"] = time.perf_counter() - t
orig = ne.GraphElimination.solve
def solve(self, system, **kw):
    if system.b == 3 and "t" not in cap:
        t = time.perf_counter()
        out = orig(self, system, **kw)
        cap["t"] = time.perf_counter() - t
        cap["backend"] = out[1].backend
        return out
    return orig(self, system, **kw)
ne.GraphElimination.solve = solve
lc.lago(g, route="seed")
print(json.dumps(cap))
"""


def add_arguments(group) -> None:
    group.add_argument("--million-poses", type=int, nargs="+", default=None, metavar="N",
                       help=f"world sizes (default {' '.join(map(str, SIZES))}; 0: none, the phase-3 table only)")
    group.add_argument("--million-repeat", type=int, default=3, metavar="K",
                       help="alternating runs per route and size (default 3)")


def run(args) -> str:
    sizes = [n for n in (args.million_poses or ((10_000, 30_000) if args.quick else SIZES)) if n > 0]
    repeat = 1 if args.quick else args.million_repeat
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            world = Path(tmp) / f"world{n}.g2o"
            _bench.run_child([sys.executable, "-m", "lago_cvx", "generate", "--poses", str(n), "-o", str(world)])
            out = Path(tmp) / "out.g2o"
            runs = {"seed": [], "default": []}
            for k in range(repeat + 1):
                for route in runs:
                    wall, peak, text = _bench.run_child([sys.executable, "-m", "lago_cvx", "solve", str(world), "-o",
                                                         str(out), "--route", route, "--json"])
                    if k:  # the first run of each route warms up
                        runs[route].append((wall, peak, json.loads(text)))
            for route, rs in runs.items():
                med = {s: statistics.median(r[2]["timings"][s] for r in rs) for s in STEPS}
                wall = statistics.median(r[0] for r in rs)
                rows.append([f"{n:,}", route, f"{wall:.1f}", f"{min(r[0] for r in rs):.1f}–{max(r[0] for r in rs):.1f}",
                             f"{statistics.median(r[1] for r in rs) / 1024:.2f}",
                             *(f"{med[s]:.2f}" for s in STEPS), f"{wall - med['total']:.1f}",
                             f"{rs[-1][2]['chi2']:.6g}"])
                print("  " + " | ".join(rows[-1]), flush=True)
            os.remove(world)
            world.with_suffix(".truth.g2o").unlink(missing_ok=True)
    p3 = []
    for n in ((3_000, 10_000) if args.quick else PHASE3_SIZES):
        res = {}
        for engine in ("numpy", "compiled"):
            ts, nb = [], []
            for _ in range(1 if args.quick else 3):
                _, _, text = _bench.run_child([sys.executable, "-c", _PHASE3, str(n), engine])
                cap = json.loads(text.strip().splitlines()[-1])
                assert cap["backend"] == {"numpy": "multifrontal"}.get(engine, engine), cap
                ts.append(cap["t"])
                nb.append(cap.get("start", 0.0))
            res[engine] = (statistics.median(ts), statistics.median(nb))
        p3.append([f"{n:,}", f"{3 * (n - 1):,}", f"{res['compiled'][0]:.3f}", f"{res['compiled'][1]:.3f}",
                   f"{res['numpy'][0]:.3f}", f"{res['numpy'][0] / (res['compiled'][0] + res['compiled'][1]):.2f}"])
        print("  " + " | ".join(p3[-1]), flush=True)
    head = ["poses", "route", "wall [s]", "range [s]", "peak [GiB]", *(f"{s} [s]" for s in STEPS),
            "rest [s]", "χ²"]
    return "\n".join([
        "# Large worlds: the whole `lago-cvx solve -o` process, step by step", "",
        f"Medians of {repeat} alternating runs per route (seed, default) after one warm-up each; "
        "`rest` = wall − LAGO's total (start-up, reading, χ², writing). Synthetic Manhattan worlds "
        "(`lago-cvx generate --poses n`, seed 0).", "",
        _bench.table(head, rows), "",
        "## Phase 3 by the C kernels and by the NumPy fallback", "",
        "Factorization and refined solve of phase 3 (seed route, 3(n − 1) unknowns) in a fresh process each, "
        "median of 3; `start` = loading the C kernels (`compiled.available()`), paid once per process; the NumPy "
        "fallback runs the same equations front by front where no C compiler was present at install.", "",
        _bench.table(["poses", "unknowns", "C [s]", "start [s]", "NumPy [s]", "NumPy / (C + start)"], p3),
    ])

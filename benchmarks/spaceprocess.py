"""Section ``spaceprocess`` of ``python benchmarks/run.py``: 3-D graphs as whole processes.

1. ``lago-cvx solve FILE -o OUT`` (``python -m lago_cvx``; both routes) against ``python
   ../shared/bench/gtsam_init3d.py FILE OUT`` (readG2o, ``InitializePose3``, writeG2o), as fresh child processes
   run alternately after one warm-up each; medians of ``--repeat`` pairs (at least 9) and the spread of the
   pairwise ratios.
2. What every such process pays before it reads a byte: the interpreter with each side's imports (NumPy and
   SciPy's sparse modules for ours, ``gtsam`` for GTSAM's), and the engine's start (loading its C kernels), each a
   fresh process, median of the same number of runs.
3. A ``lago-cvx generate --world sphere3d --poses 100000`` world: read + initialization + write as one process by
   both routes, wall time and peak memory (``os.wait4``), median of three.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
from pathlib import Path

import _bench

FILES = ("se-sync-3d/sphere2500.g2o", "se-sync-3d/torus3D.g2o", "se-sync-3d/parking-garage.g2o")
GTSAM_SCRIPT = _bench.HERE.parent.parent / "shared" / "bench" / "gtsam_init3d.py"
BIG_POSES = 100_000
_START = "import numpy as np, lago_cvx.cli.main, lago_cvx.io, lago_cvx.space; from lago_cvx.sparse import compiled; "
_CALL = "z = np.zeros(1, np.int64); compiled.kernels()['pose_local'](z, z, np.array([0, 1]), np.array([0, 1]), z)"
STARTS = {
    "Python alone": "pass",
    "ours: NumPy + SciPy's sparse modules": "import numpy, scipy.sparse, scipy.sparse.linalg, scipy.linalg",
    "ours: the whole CLI imported": "import lago_cvx.cli.main, lago_cvx.io, lago_cvx.space",
    "ours: + the engine's start, its C kernels (and SciPy's LAPACK, whose addresses they call)":
        _START + _CALL,
    "GTSAM: import gtsam": "import gtsam",
}


def _wall(argv: list) -> float:
    return _bench.run_child(argv)[0]


def _pairs(ours: list, theirs: list, pairs: int) -> list:
    a, b = ([w for w, _ in side] for side in _bench.alternating(ours, theirs, pairs))
    ratios = sorted(x / y for x, y in zip(a, b))
    ma, mb = statistics.median(a), statistics.median(b)
    return [f"{ma:.3f}", f"{mb:.3f}", f"{ma / mb:.2f}", f"{ratios[0]:.2f}–{ratios[-1]:.2f}"]


def run(args) -> str:
    skipped = _bench.gtsam_script_skipped(GTSAM_SCRIPT)
    if skipped:
        return skipped
    pairs = 3 if args.quick else max(9, args.repeat)
    py = sys.executable
    rows = []
    with tempfile.TemporaryDirectory(prefix="lago_bench_space_") as d:
        out, gt_out = Path(d) / "ours.g2o", Path(d) / "gtsam.g2o"
        for rel in FILES:
            path = _bench.find(rel)
            if path is None:
                continue
            gtsam = [py, str(GTSAM_SCRIPT), str(path), str(gt_out)]
            for route in ("default", "seed"):
                ours = [py, "-m", "lago_cvx", "solve", str(path), "-o", str(out), "--route", route]
                rows.append([Path(rel).name, route, *_pairs(ours, gtsam, pairs)])
                print("  " + " | ".join(rows[-1]), flush=True)
        starts = []
        for label, code in STARTS.items():
            _wall([py, "-c", code])
            starts.append([label, f"{statistics.median(_wall([py, '-c', code]) for _ in range(pairs)):.3f}"])
            print("  " + " | ".join(starts[-1]), flush=True)
        big = Path(d) / "w100k.g2o"
        _bench.run_child([py, "-m", "lago_cvx", "generate", "--world", "sphere3d", "--poses", str(BIG_POSES),
                          "-o", str(big)])
        world = []
        for route in ("default", "seed"):
            runs = [_bench.run_child([py, "-m", "lago_cvx", "solve", str(big), "-o", str(out), "--route", route])
                    for _ in range(1 if args.quick else 3)]
            wall = statistics.median(r[0] for r in runs)
            world.append([route, f"{wall:.1f}", f"{max(r[1] for r in runs) / 1024:.2f}",
                          "yes" if wall < 30 else "**no**"])
            print("  " + " | ".join(world[-1]), flush=True)
    return "\n".join([
        "# 3-D graphs as whole processes", "",
        "## `lago-cvx solve FILE -o OUT` against `gtsam_init3d.py FILE OUT` [s]", "",
        f"Medians of {pairs} alternating pairs of fresh processes after one warm-up each; the same GTSAM script "
        "beside both routes (it pins the first pose by a prior and runs readG2o, InitializePose3, writeG2o).", "",
        _bench.table(["file", "route", "ours", "GTSAM", "ours / GTSAM", "pairwise ratios"], rows), "",
        "## What a process pays before it reads its file [s]", "",
        f"Fresh processes, median of {pairs}. The engine's C kernels factor every system; their start is paid once "
        "per process.", "",
        _bench.table(["what", "wall"], starts), "",
        f"## A {BIG_POSES:,}-pose 3-D world: read + initialization + write".replace(",", " "), "",
        f"`lago-cvx generate --world sphere3d --poses {BIG_POSES}` (the sphere of rings nearest that size), then "
        "`lago-cvx solve FILE -o OUT [--route seed]` as one process; median wall time of "
        f"{1 if args.quick else 3} runs, the largest peak resident memory.", "",
        _bench.table(["route", "wall [s]", "peak [GiB]", "under 30 s"], world),
    ])

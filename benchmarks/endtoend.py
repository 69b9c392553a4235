"""Section ``endtoend`` of ``python benchmarks/run.py``: the whole process against GTSAM's.

Ours: ``python -m lago_cvx solve FILE -o OUT`` (what ``lago-cvx solve FILE -o OUT`` runs: start-up, reading,
the default route, writing). GTSAM's: ``python ../shared/bench/gtsam_lago.py FILE OUT`` (readG2o,
``lago.initialize``, writeG2o; the script the issue names). Both as fresh child processes, run
alternately (ours, GTSAM, ours, …) after one warm-up each, so that a drift of the machine's speed hits
both; medians of ``--repeat`` pairs (at least 9), the spread of the pairwise ratios, and each side's
peak memory (``os.wait4``).
"""

from __future__ import annotations

import importlib.util
import os
import resource
import statistics
import sys
import tempfile
from pathlib import Path

import _bench

FILES = ("se-sync/city10000.g2o", "carlone/input_M3500_g2o.g2o", "se-sync/MIT.g2o", "se-sync/intel.g2o")
GTSAM_SCRIPT = _bench.HERE.parent.parent / "shared" / "bench" / "gtsam_lago.py"


def run(args) -> str:
    skipped = _bench.gtsam_script_skipped(GTSAM_SCRIPT)
    if skipped:
        return skipped
    pairs = max(9, args.repeat)
    rows = []
    with tempfile.TemporaryDirectory(prefix="lago_bench_e2e_") as d:
        ours_out, gt_out = Path(d) / "ours.g2o", Path(d) / "gtsam.g2o"
        for rel in FILES:
            path = _bench.find(rel)
            if path is None:
                continue
            ours = [sys.executable, "-m", "lago_cvx", "solve", str(path), "-o", str(ours_out)]
            gtsam = [sys.executable, str(GTSAM_SCRIPT), str(path), str(gt_out)]
            a, b = _bench.alternating(ours, gtsam, pairs)
            wa, wb = [w for w, _ in a], [w for w, _ in b]
            ratios = sorted(x / y for x, y in zip(wa, wb))
            rows.append([rel, f"{statistics.median(wa):.3f}", f"{statistics.median(wb):.3f}",
                         f"{statistics.median(wa) / statistics.median(wb):.2f}",
                         f"{ratios[0]:.2f}–{ratios[-1]:.2f}", f"{max(p for _, p in a):.0f}",
                         f"{max(p for _, p in b):.0f}"])
            print("  " + " | ".join(rows[-1]), flush=True)
    src = _bench.HERE.parent / "lago_cvx" / "__init__.py"
    if Path(importlib.util.cache_from_source(str(src))).exists():
        bytecode = "compiled (`__pycache__` present)"
    elif os.environ.get("PYTHONDONTWRITEBYTECODE"):
        bytecode = "absent and never written (PYTHONDONTWRITEBYTECODE is set), so every start compiles it"
    else:
        bytecode = "written by the warm-up run"
    parent_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    head = ["file", "ours [s]", "GTSAM [s]", "ours / GTSAM", "pairwise ratios", "ours peak [MiB]",
            "GTSAM peak [MiB]"]
    return "\n".join([
        "# The whole process against GTSAM's", "",
        f"Medians of {pairs} alternating pairs of fresh processes, after one warm-up each. Ours: `python -m "
        "lago_cvx solve FILE -o OUT` (default route); GTSAM: `python ../shared/bench/gtsam_lago.py FILE OUT` "
        f"(readG2o, lago.initialize, writeG2o). Bytecode of the package: {bytecode} (`python -m compileall "
        "-q lago_cvx` once compiles it where PYTHONDONTWRITEBYTECODE is set). Peaks are each child's "
        "`ru_maxrss` (`os.wait4`), which Linux starts from the parent's resident size at the fork: this "
        f"run's parent had peaked at {parent_peak:.0f} MiB, so no peak above can read lower than that (run "
        "this section first, or alone, for the children's own peaks).", "",
        _bench.table(head, rows),
    ])

"""The benchmark suite: one entry point, one Markdown result file per section.

    python benchmarks/run.py                       # every section, committed settings (≈ 45 min, 2 cores)
    python benchmarks/run.py datasets scaling      # some sections
    python benchmarks/run.py --quick               # every section in about a minute (smoke test; results
                                                   # go to a temporary folder unless --out DIR is given)
    python benchmarks/run.py certify --sdp-timeout 900 --sdp-sizes-intel 1728 --sdp-sizes-csail

Sections (each a module of this folder exposing ``run(args) -> str`` — ``io`` is ``io_bench.py``; written to
``benchmarks/<section>.md`` — or ``--out DIR`` —, whose first line names the command, the machine and the
date):

* ``datasets`` — LAGO on every public dataset: regularization counts, χ² against the reference minimum,
  time per step, cvxpy against the closed form, Gauss–Newton from LAGO and from odometry, GTSAM's
  ``lago.initialize`` side by side (when the ``gtsam`` extra is installed);
* ``perf``     — the LAGO step against GTSAM's ``lago.initialize`` step by step on city10000 and
  input_M3500 (interleaved runs), ``pose_covariances`` on city10000 and a 100 000-pose world, and
  phase 3's solve by QDLDL, the multifrontal engine and (if installed) CHOLMOD up to 1M poses;
* ``endtoend`` — ``lago-cvx solve FILE -o OUT`` against GTSAM's script (``../shared/bench/gtsam_lago.py``)
  as whole processes, alternating, on city10000 and input_M3500;
* ``scaling``  — the graph machinery and closed-form LAGO on synthetic Manhattan worlds up to 100 000
  poses, cvxpy on some of them, the log–log slope of time against edges;
* ``chordal``  — tree rounding against the chordal regularizer, on every dataset and over rising
  rotation noise;
* ``certify``  — SE-Sync cost, local optimum and optimality certificate on every dataset, and the SDP
  relaxation by Clarabel on sub-graphs (each SDP in a child process with a time-out);
* ``integer``  — the integer program of the cycle integers against the rounding over rising rotation
  noise, on the BFS and the odometric tree;
* ``theorem1`` — Theorem 1 measured on every dataset (the identity of eqs. (16)–(17) holds, the cost
  claim does not) and the first-order optimality of the full-information phases;
* ``route``    — tree against chordal rounding and phase-3 against re-solved positions, alone and after
  Gauss–Newton, on every dataset and on Manhattan worlds with rising rotation noise: the default route;
* ``io``       — ``lago-cvx generate``, ``read_graph`` and ``write_graph`` at 10k, 100k and 1M poses, each in a
  fresh process with its peak memory (``--io-baseline REV``: the same at an earlier revision, before/after;
  ``--io-solve``: the whole ``lago-cvx solve -o`` pipeline too).
* ``unseen``   — the default route on real graphs it was never tuned on (GTSAM's example graphs, and any
  folder given with ``--unseen DIR``): χ² against the best Gauss–Newton minimum found.
* ``processes`` — forked workers after a warm parent, spawned workers, two threads, joblib and Dask: every
  χ² identical to the serial run;
* ``space``    — 3-D graphs: our initialization (both routes and weightings) against GTSAM's
  ``InitializePose3`` and the minimum, χ² and times;
* ``spaceprocess`` — 3-D graphs as whole processes: ``lago-cvx solve -o`` against GTSAM's ``gtsam_init3d.py``,
  what each process pays before reading (imports, the compiled engine's start), and a 100 000-pose 3-D world;
* ``costs``    — the χ² ``lago-cvx solve [--refine] -o`` reports against g2o's own χ² of the file written (g2opy)
  and, with ``--cost gtsam``, GTSAM's 2·error(); each peer's Levenberg–Marquardt from our refined estimate;
* ``robust``   — false loop closures appended to intel, M3500, CSAIL, MIT and city10000 (10 %, 30 %, seeds
  0–2): precision, recall, ATE and χ² of robust LAGO (graduated non-convexity) against the clean solution;
  ``--robust-gtsam``: GTSAM's GNC on the same graphs;
* ``clean``    — ``lago-cvx solve F --robust --refine`` against ``lago-cvx solve F --refine`` as whole processes on
  every clean public graph, planar and 3-D: edges rejected, χ² over every edge, the ratio (≤ 1.001 passes);
* ``separable`` — the false loop closures robust LAGO keeps (intel, M3500, CSAIL, MIT at 10 % and 30 %, seeds
  0–5): each one's leave-one-out cost change Δχ² against the true loop closures', i.e. whether any threshold
  could reject it and keep the true ones; and a per-file threshold from the trusted odometry;
* ``share``    — the share of the loop closures that are false at 10 % and 30 % of the edges (intel, M3500, CSAIL,
  MIT), how many false and true ones pass dead reckoning's test alone and in consistent pairs, and robust LAGO's
  result beside them; ``--share-variants``: the package's other robust settings on MIT + 30 %;
* ``window``   — the truncation c̄² at which robust LAGO passes each 3-D file with 10 % false loop closures (a grid
  of ``--robust-threshold`` values, the χ²₆ quantiles among them), beside each file's clean χ² per residual degree
  of freedom;
* ``million``  — ``lago-cvx solve -o`` as a whole process on 100 000 to 1 000 000-pose worlds by both routes,
  step by step with peak memory, and phase 3 by the C kernels against the NumPy fallback.

Datasets are found through ``lago_cvx.datasets`` (``LAGO_CVX_DATASETS=DIR`` to point elsewhere than
``../shared/datasets``); a section that needs them says "skipped: datasets not found" without them.
``--repeat N`` sets the number of timed runs whose median is reported (default 5; 2 with ``--quick``).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
import tempfile
import time
import traceback
from pathlib import Path

import _bench

SECTIONS = ("datasets", "scaling", "perf", "endtoend", "chordal", "certify", "integer", "theorem1", "route", "io",
            "unseen", "million", "processes", "space", "spaceprocess", "costs", "robust", "clean", "separable",
            "share", "window")
#: Sections whose module has another name (``io`` would be the standard library's).
MODULE_OF = {"io": "io_bench"}


def parser(modules: dict) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sections", nargs="*", metavar="SECTION",
                    help=f"one or more of {' '.join(SECTIONS)} (default: all)")
    ap.add_argument("--quick", action="store_true",
                    help="fewer repeats and smaller sweeps in every section (smoke test)")
    ap.add_argument("--repeat", type=int, default=None,
                    help="timed runs per measurement, median reported (default 5, --quick 2)")
    ap.add_argument("--out", type=Path, default=None, metavar="DIR",
                    help="folder of the result files (default benchmarks/; with --quick a new temporary "
                         "folder, so that a smoke test never overwrites the committed results)")
    for name, module in modules.items():
        if hasattr(module, "add_arguments"):
            module.add_arguments(ap.add_argument_group(f"section {name}"))
    return ap


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    modules = {name: importlib.import_module(MODULE_OF.get(name, name)) for name in SECTIONS}
    ap = parser(modules)
    args = ap.parse_intermixed_args(argv)
    unknown = [s for s in args.sections if s not in SECTIONS]
    if unknown:
        ap.error(f"unknown section(s) {' '.join(unknown)}; choose from {' '.join(SECTIONS)}")
    if args.repeat is None:
        args.repeat = 2 if args.quick else 5
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    if args.out is None:
        args.out = Path(tempfile.mkdtemp(prefix="lago_bench_quick_")) if args.quick else _bench.HERE
    args.out.mkdir(parents=True, exist_ok=True)
    # LAGO warns about ambiguous 2kπ roundings (e.g. MIT on the odometric tree): the tables report them.
    logging.basicConfig(level=logging.ERROR, format="%(name)s: %(levelname)s: %(message)s")
    print(f"{_bench.machine()}; repeat {args.repeat}{', quick' if args.quick else ''}", flush=True)
    failed = []
    for name in dict.fromkeys(args.sections or SECTIONS):
        print(f"\n== {name}", flush=True)
        t = time.perf_counter()
        try:
            text = modules[name].run(args)
        except Exception:
            traceback.print_exc()
            failed.append(name)
            continue
        elapsed = time.perf_counter() - t
        path = _bench.write_result(name, f"{text.rstrip()}\n\nSection time: {elapsed:.0f} s.", argv, args.out)
        print(f"== {name}: {elapsed:.0f} s, written to {path}", flush=True)
    if failed:
        print(f"\nfailed: {' '.join(failed)} (their result files were left as they were)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

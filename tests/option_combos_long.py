"""Random option combinations on real graphs the suite does not run the matrix on (issue 30); not a test
module (no ``test_`` prefix): run it by hand, it takes minutes.

    PYTHONPATH=. python tests/option_combos_long.py --runs 100 --seed 0

Each run draws a graph, a command that reads it and a value (or none) for every option of that command
from the parser's own option space (``test_option_matrix.parser_space``), runs ``main([...])`` in process
and judges it with ``test_option_matrix.check_run`` (exit 0 or a documented 2, 3, 4 with one CLI line, never
1 nor a traceback; anchors held to 1e-9 in the poses written, also after --refine; --check within 1e-6).
Then every anchor form × --refine × --check of ``solve`` runs on each graph. Prints one line per run and
the counts; exits 1 when any run misbehaved.
"""

from __future__ import annotations

import argparse
import collections
import itertools
import random
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from test_option_matrix import anchor_forms, check_run, parser_space, run_cli

from lago_cvx import datasets
from lago_cvx.io import read_graph

#: Small real graphs (the matrix itself runs on synthetic ones).
HELD_OUT = ("gtsam/noisyToyGraph.txt", "se-sync/MIT.g2o", "carlone/FR079_P_toro.graph", "se-sync/CSAIL.g2o")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("graphs", nargs="*", default=list(HELD_OUT), help="dataset names or paths")
    args = ap.parse_args(argv)
    paths = []
    for g in args.graphs:
        p = Path(g) if Path(g).is_file() else datasets.locate(g)
        if p is None:
            print(f"skipped {g}: not found")
            continue
        paths.append(p)
    rnd = random.Random(args.seed)
    out = Path(tempfile.mkdtemp(prefix="lago-combos-"))
    ctxs = {p: {"graph": p, "out": out, "ids": read_graph(p).ids} for p in paths}
    runs = []
    for _ in range(args.runs):
        p = rnd.choice(paths)
        space = parser_space(ctxs[p])
        cmd = rnd.choice(sorted(space))
        argv = [cmd, str(p)]
        for _, values in space[cmd]:
            argv += rnd.choice(values)
        runs.append(("random", argv))
    for p in paths:
        for form in anchor_forms(ctxs[p]["ids"]).values():
            for refine, check in itertools.product([[], ["--refine"]], [[], ["--check"]]):
                runs.append(("anchors", ["solve", str(p), *form, *refine, *check, "-o", str(out / "anchored.g2o")]))
    counts, bad = collections.Counter(), 0
    t0 = time.perf_counter()
    for kind, argv in runs:
        t = time.perf_counter()
        code, o, e = run_cli(argv)
        why = check_run(argv, code, o, e, out)
        counts[(kind, code)] += 1
        bad += bool(why)
        last = e.strip().splitlines()[-1][:150] if code and e.strip() else ""
        print(f"[{kind}] exit {code} {time.perf_counter() - t:6.2f} s  lago-cvx {' '.join(argv)}"
              + (f"\n    {last}" if last else "") + (f"\n    PROBLEM: {'; '.join(why)}" if why else ""), flush=True)
    print(f"\n{len(runs)} runs in {time.perf_counter() - t0:.0f} s on {len(paths)} graphs; exit statuses "
          + ", ".join(f"{k} {c}: {n}" for (k, c), n in sorted(counts.items())) + f"; misbehaved: {bad}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

"""Section ``io`` of ``python benchmarks/run.py`` (``benchmarks/io.md``): generating, reading and writing synthetic Manhattan
worlds of 10 000, 100 000 and 1 000 000 poses.

Every measurement runs in a fresh child process, so nothing is cached between them:

* ``generate`` — the whole ``lago-cvx generate --poses n`` process (start-up, the world, two files);
* ``read`` — ``read_graph`` of that file, timed inside the child;
* ``write`` — ``write_graph`` of the graph just read, timed inside the child (the read is not counted);
* peak memory — the child's peak resident set as the operating system accounts it (``os.wait4``);
* ``solve`` (``--io-solve``) — the whole ``lago-cvx solve FILE -o OUT`` process and its peak memory:
  read + LAGO + write, the pipeline that must stay below 8 GiB at 1M poses.

Wall seconds are medians of ``--repeat`` runs (one run at 1M poses). With ``--io-baseline REV`` the same
children also run on the package as it was at git revision REV (``git archive`` into a temporary folder,
nothing in the repository touched), for a before/after table.
"""

from __future__ import annotations

import json
import os
import site
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import _bench

SIZES = [10_000, 100_000, 1_000_000]
QUICK_SIZES = [10_000, 100_000]

_READ = ("import json, sys, time\nfrom lago_cvx.io import read_graph\nt = time.perf_counter()\n"
         "g = read_graph(sys.argv[1])\n"
         "print(json.dumps({'seconds': time.perf_counter() - t, 'poses': g.n_poses, 'edges': g.n_edges}))")
_WRITE = ("import json, sys, time\nfrom lago_cvx.io import read_graph, write_graph\ng = read_graph(sys.argv[1])\n"
          "t = time.perf_counter()\nwrite_graph(sys.argv[2], g)\nprint(json.dumps({'seconds': time.perf_counter() - t}))")


def add_arguments(group) -> None:
    group.add_argument("--io-sizes", type=int, nargs="+", default=None,
                       help=f"poses of the worlds (default {' '.join(map(str, SIZES))}; "
                            f"--quick {' '.join(map(str, QUICK_SIZES))})")
    group.add_argument("--io-baseline", metavar="REV", default=None,
                       help="also time the package at this git revision (before/after)")
    group.add_argument("--io-solve", action="store_true",
                       help="also time `lago-cvx solve FILE -o OUT` and its peak memory")


def _run(argv: list, env: dict) -> tuple[float, float, str]:
    """``_bench.run_child`` outside the checkout: a child's sys.path starts with its working directory."""
    return _bench.run_child(argv, env=env, cwd=tempfile.gettempdir())


def _env(pythonpath: Path) -> dict:
    """The children's environment: ``lago_cvx`` from ``pythonpath`` and everything else from this
    interpreter's site-packages. The children run with ``python -S`` (``PY``), so that no ``.pth`` file is
    read: an editable install's import hook would otherwise win over PYTHONPATH and the "baseline" would
    silently be the working tree (``_check`` makes sure it is not; so does running the children outside
    the checkout, ``_run``)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), *site.getsitepackages()])
    return env


#: How every child is started (see ``_env``).
PY = [sys.executable, "-S"]


def _check(env: dict, pythonpath: Path) -> None:
    """Raise unless the children import ``lago_cvx`` from ``pythonpath``."""
    _, _, out = _run([*PY, "-c", "import lago_cvx; print(lago_cvx.__file__)"], env)
    where = Path(out.strip()).resolve()
    if Path(pythonpath).resolve() not in where.parents:
        raise RuntimeError(f"the children import lago_cvx from {where}, not from {pythonpath}")


def _measure(n: int, repeat: int, folder: Path, env: dict, solve: bool) -> dict:
    path = folder / f"world{n}.g2o"
    gen = [_run([*PY, "-m", "lago_cvx", "generate", "--poses", str(n), "-o", str(path)], env)
           for _ in range(repeat)]
    reads = [_run([*PY, "-c", _READ, str(path)], env) for _ in range(repeat)]
    writes = [_run([*PY, "-c", _WRITE, str(path), str(folder / "out.g2o")], env) for _ in range(repeat)]
    info = json.loads(reads[-1][2])
    row = {
        "poses": info["poses"], "edges": info["edges"], "mb": path.stat().st_size / 1e6,
        "generate": statistics.median(w for w, _, _ in gen), "generate_peak": max(p for _, p, _ in gen),
        "read": statistics.median(json.loads(o)["seconds"] for _, _, o in reads),
        "read_peak": max(p for _, p, _ in reads),
        "write": statistics.median(json.loads(o)["seconds"] for _, _, o in writes),
    }
    if solve:
        wall, peak, _ = _run([*PY, "-m", "lago_cvx", "solve", str(path), "-o", str(folder / "est.g2o"),
                              "--json"], env)
        row.update(solve=wall, solve_peak=peak)
    for f in folder.glob("*.g2o"):
        f.unlink()
    return row


def _baseline(rev: str, folder: Path) -> Path:
    """The package at ``rev``, extracted with ``git archive`` (the repository is not touched)."""
    root = _bench.HERE.parent
    target = folder / f"baseline-{rev}"
    target.mkdir()
    archive = subprocess.run(["git", "-C", str(root), "archive", rev, "lago_cvx"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(target)], input=archive, check=True)
    return target


def run(args) -> str:
    sizes = args.io_sizes or (QUICK_SIZES if args.quick else SIZES)
    root = _bench.HERE.parent
    rows, base_rows = [], []
    with tempfile.TemporaryDirectory(prefix="lago_bench_io_") as d:
        folder = Path(d)
        base = _baseline(args.io_baseline, folder) if args.io_baseline else None
        _check(_env(root), root)
        if base is not None:
            _check(_env(base), base)
        for n in sizes:
            repeat = 1 if n >= 1_000_000 else args.repeat
            rows.append(_measure(n, repeat, folder, _env(root), args.io_solve))
            print(f"  n={n}: {rows[-1]}", flush=True)
            if base is not None:
                base_rows.append(_measure(n, repeat, folder, _env(base), args.io_solve))
                print(f"  n={n} baseline {args.io_baseline}: {base_rows[-1]}", flush=True)
    f = _bench.fmt
    head = ["poses", "edges", "file [MB]", "generate [s]", "read [s]", "read peak [MiB]", "write [s]"]
    if args.io_solve:
        head += ["solve -o [s]", "solve peak [MiB]"]
    lines = ["# Reading, writing and generating synthetic Manhattan worlds (seed 0)", "",
             "Each figure comes from a fresh process: generate = the whole `lago-cvx generate --poses n` process "
             "(world + graph file + truth file); read = `read_graph` of the graph file; write = `write_graph` of "
             "the graph read (g2o, bytes identical to one `repr` per number); peak = the process's peak resident "
             "memory; solve = the whole `lago-cvx solve FILE -o OUT` process (read, LAGO, write). Medians of "
             f"{args.repeat} runs, one run at 1M poses.", ""]

    def table_row(r):
        cells = [r["poses"], r["edges"], f(r["mb"], ".1f"), f(r["generate"], ".2f"), f(r["read"], ".3f"),
                 f(r["read_peak"], ".0f"), f(r["write"], ".2f")]
        if args.io_solve:
            cells += [f(r.get("solve"), ".1f"), f(r.get("solve_peak"), ".0f")]
        return cells

    lines.append(_bench.table(head, [table_row(r) for r in rows]))
    if base_rows:
        lines += ["", "## Before: the package at the baseline revision (`--io-baseline REV`)", "",
                  _bench.table(head, [table_row(r) for r in base_rows]), "",
                  "## Speed-up (before / after)", "",
                  _bench.table(["poses", "generate", "read", "write"],
                               [[a["poses"], f(b["generate"] / a["generate"], ".1f") + "×",
                                 f(b["read"] / a["read"], ".1f") + "×", f(b["write"] / a["write"], ".1f") + "×"]
                                for a, b in zip(rows, base_rows)])]
    return "\n".join(lines)

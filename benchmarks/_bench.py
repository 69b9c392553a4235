"""Shared helpers of the benchmark sections of ``python benchmarks/run.py``.

Every section (``datasets.py``, ``scaling.py``, ``chordal.py``, ``certify.py``, ``integer.py``) exposes
``run(args) -> str`` (Markdown) and, when it has options of its own, ``add_arguments(group)``; ``run.py``
writes each result to ``benchmarks/<section>.md`` behind the one-line ``header``. What lives here:

* ``machine`` — the CPU model, core count, architecture, memory, Python and numpy versions (the header
  names it, with the package version);
* ``median_time(fn, repeat)`` — wall-clock median of ``repeat`` calls, and the last output; ``warm_up``
  — imports and first-call set-up done before anything is timed;
* ``table``, ``fmt`` — Markdown tables, "–" for a missing or non-finite value;
* ``FILES``, ``datasets_skipped``, ``find``, ``each_dataset`` — the public datasets, found through
  ``lago_cvx.datasets`` (``$LAGO_CVX_DATASETS``, then ``../shared/datasets``); a section that needs them
  reports "skipped: datasets not found" instead of failing. Reference values (χ² minima, SE-Sync
  costs) are read from ``lago_cvx.datasets`` by the sections, never typed here;
* ``alternating``, ``have_gtsam``, ``gtsam_script_skipped`` — whole processes of ours and GTSAM's scripts in
  alternating pairs, and why such a comparison cannot run here.
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from lago_cvx import lago, manhattan_world, read_graph
from lago_cvx.datasets import DATASET_FILES, DatasetNotFound, dataset, datasets_dir

#: The folder of the benchmark scripts and of their results.
HERE = Path(__file__).resolve().parent

#: Variants of ``gtsam/noisyToyGraph.txt`` that differ from it only in their VERTEX lines (the initial
#: guess, which LAGO ignores): benchmarked once, through noisyToyGraph.
SAME_EDGES = frozenset({"gtsam/orientationsNoisyToyGraph.txt", "gtsam/optimizedNoisyToyGraph.txt"})

#: The dataset files the sections report, in the order of ``lago_cvx.datasets.DATASET_TABLE``.
FILES = tuple(rel for rel in DATASET_FILES if rel not in SAME_EDGES)


# ----------------------------------------------------------------------------- child processes
def run_child(argv: list, *, env: dict | None = None, cwd=None) -> tuple[float, float, str]:
    """(wall seconds, peak resident MiB, stdout) of one child process, its peak memory from ``wait4``;
    raises on a non-zero exit with the end of its standard error."""
    t = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(argv, env=env, stdout=out, stderr=err, cwd=cwd)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        code = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if code:
            raise RuntimeError(f"{' '.join(map(str, argv))} failed ({code}): {err.read().decode()[-500:]}")
        return wall, usage.ru_maxrss / 1024, out.read().decode()


def alternating(first: list, second: list, pairs: int) -> tuple[list, list]:
    """Two commands run as child processes in turn (first, second, first, …) after one warm-up each (file cache,
    bytecode), so that a drift of the machine's speed hits both: ([(wall s, peak MiB)] × pairs, the same)."""
    run_child(first), run_child(second)
    a, b = [], []
    for _ in range(pairs):
        a.append(run_child(first)[:2])
        b.append(run_child(second)[:2])
    return a, b


def have_gtsam() -> bool:
    """True when this Python can import ``gtsam`` (asked of a child process: nothing is imported here)."""
    return subprocess.run([sys.executable, "-c", "import gtsam"], capture_output=True).returncode == 0


def gtsam_script_skipped(script: Path) -> str | None:
    """None when both sides of a whole-process comparison can run; otherwise the line saying why not: the datasets
    missing (``datasets_skipped``), or GTSAM's side (``script`` in ``../shared/bench``, the ``gtsam`` extra)."""
    skipped = datasets_skipped()
    if skipped is None and not (Path(script).is_file() and have_gtsam()):
        skipped = f"skipped: GTSAM's side needs {script} and the `gtsam` extra"
    return skipped


# ------------------------------------------------------------------------------------- the machine
def machine() -> str:
    """'CPU model, N cores, architecture, memory, Python x.y.z, numpy a.b.c' of the machine running the
    benchmarks."""
    cpu = platform.processor() or platform.machine()
    memory = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                memory = f", {int(line.split()[1]) / 2**20:.0f} GiB"
                break
    except (OSError, ValueError, IndexError):
        pass
    return (f"{cpu}, {os.cpu_count()} cores, {platform.machine()}{memory}, Python {platform.python_version()}, "
            f"numpy {np.__version__}")


#: options whose value is a revision of this repository: the header names them REV
REVISION_OPTIONS = ("--io-baseline",)


def header(argv: list[str]) -> str:
    """The first line of every result file: the command that wrote it (a revision given as an option shown
    as REV), the package's version, the machine and the date."""
    from lago_cvx import __version__

    shown = [("REV" if i and argv[i - 1] in REVISION_OPTIONS else a) for i, a in enumerate(argv)]
    command = shlex.join(["python", "benchmarks/run.py", *shown])
    return (f"Generated by `{command}` with lago_cvx {__version__} on {machine()}, "
            f"{datetime.date.today().isoformat()}.")


def write_result(section: str, text: str, argv: list[str], folder: Path = HERE) -> Path:
    """Write ``<folder>/<section>.md`` (default ``benchmarks/``): ``header(argv)``, a blank line, then
    ``text``."""
    path = Path(folder) / f"{section}.md"
    path.write_text(f"{header(argv)}\n\n{text.rstrip()}\n", encoding="utf-8")
    return path


# ------------------------------------------------------------------------------------- timing
def median_time(fn, repeat: int):
    """(median wall-clock seconds over ``repeat`` ≥ 1 calls of ``fn()``, the last call's output)."""
    times, out = [], None
    for _ in range(max(1, int(repeat))):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def warm_up() -> None:
    """Run LAGO once in closed form and once through cvxpy on a small synthetic world, so that no timing
    includes imports (cvxpy is imported on the first cvxpy solve) or first-call set-up."""
    g = manhattan_world(50, seed=0).graph
    lago(g)
    lago(g, method="cvxpy")


# ------------------------------------------------------------------------------------- Markdown
def fmt(x, spec: str = ".6g") -> str:
    """``format(x, spec)``, or "–" for None and non-finite floats."""
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "–"
    return format(x, spec)


def table(head, rows) -> str:
    """A Markdown table: ``head`` the column titles, ``rows`` sequences of cells (``str()`` applied)."""
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------- datasets
def datasets_skipped() -> str | None:
    """None when the datasets folder is found; otherwise the line "skipped: datasets not found — …"
    naming the places tried — printed, and returned for the section's result file."""
    if datasets_dir() is not None:
        return None
    try:
        dataset(FILES[0])
        reason = "folder not found"
    except DatasetNotFound as exc:
        reason = str(exc)
    line = f"skipped: datasets not found — {reason}"
    print(line, flush=True)
    return line


def find(rel: str) -> Path | None:
    """Path of dataset file ``rel`` (``lago_cvx.datasets.dataset``), or None — named on stderr — when it
    is not found."""
    try:
        return dataset(rel)
    except DatasetNotFound as exc:
        print(f"skipped {rel}: {exc}", file=sys.stderr, flush=True)
        return None


def corrupted_plan(args, files, quick_files, fractions, n_seeds: int) -> tuple:
    """(skipped, files, fractions, seeds) of a section over real graphs with false loop closures: ``skipped`` the line
    of ``datasets_skipped`` (None when the datasets are found); ``files``, ``fractions`` and seeds 0..``n_seeds``−1,
    or with ``--quick`` the ``quick_files``, the first fraction and seed 0."""
    if args.quick:
        return datasets_skipped(), quick_files, fractions[:1], range(1)
    return datasets_skipped(), files, fractions, range(n_seeds)


def each_dataset(files=FILES):
    """Yield (file, PoseGraph) for every file of ``files`` that is found (``find``)."""
    for rel in files:
        path = find(rel)
        if path is not None:
            yield rel, read_graph(path)

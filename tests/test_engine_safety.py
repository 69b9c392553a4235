"""The sparse engine's safety (issue 41): it leaves the process's BLAS thread count alone unless asked and caps its
own threads at ``workers``; a malformed plan raises instead of crashing the process; the symbolic analysis's
postorder is linear on hub graphs."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.errors import OptionError
from lago_cvx.sparse import compiled as C
from lago_cvx.sparse import engine_threads
from lago_cvx.sparse import normal_equations as ne

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _run(code: str, **env) -> subprocess.CompletedProcess:
    """``code`` in a fresh Python process with this checkout first on the path."""
    e = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""), **env)
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=e,
                          timeout=600)


_BLAS_WATCH = """
    import threading, numpy as np
    from threadpoolctl import threadpool_info
    import lago_cvx as lc
    from lago_cvx.sparse import compiled as C, normal_equations as ne, engine_threads
    C.SMALL_WORK, C.THREADED_FRONT = 0, 0  # every front through LAPACK/BLAS, large ones on every BLAS thread
    g = lc.manhattan_world(300, seed=5).graph
    el = ne.GraphElimination(g, 0)
    rng = np.random.default_rng(0)
    A, B = rng.standard_normal((2, g.n_edges, 4, 3))
    system = ne.EdgeSystem(el.tails, el.heads, A, B, rng.standard_normal((g.n_edges, 4)), el.d)
    import scipy.linalg  # noqa: F401  (SciPy's BLAS loaded before the watch starts)
    def blas():
        return sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})
    before = blas()
    seen, stop = set(), threading.Event()
    def watch():
        while not stop.is_set():
            seen.update(blas())
    w = threading.Thread(target=watch); w.start()
    with engine_threads(blas_threads=ASK):
        for engine in ["compiled", True] * 20:
            el.factor(system, engine=engine).solve(np.ones(el.d * 3))
    stop.set(); w.join()
    print(before, sorted(seen), blas())
"""


@pytest.mark.skipif(not C.available(), reason="the compiled engine cannot run here")
def test_solve_leaves_the_process_blas_threads_alone():
    """A second thread reads threadpoolctl's view of every BLAS while the compiled and NumPy engines factor and solve
    in the first (every front by LAPACK/BLAS): with the default it sees the process's count (2) throughout; asked
    for ``blas_threads=1`` the engine does lower it (so the watch can see a change), and restores it after."""
    out = _run(_BLAS_WATCH.replace("ASK", "None"), OPENBLAS_NUM_THREADS="2")
    assert out.returncode == 0, out.stderr
    before, seen, after = (eval(x) for x in out.stdout.strip().replace("] [", "]|[").split("|"))
    assert before == [2] and seen == [2] and after == [2], out.stdout
    asked = _run(_BLAS_WATCH.replace("ASK", "1"), OPENBLAS_NUM_THREADS="2")
    assert asked.returncode == 0, asked.stderr
    before, seen, after = (eval(x) for x in asked.stdout.strip().replace("] [", "]|[").split("|"))
    assert before == [2] and 1 in seen and after == [2], asked.stdout


def test_workers_one_runs_the_engine_in_the_calling_thread(monkeypatch):
    """``lago(workers=1)`` on a graph large enough for the background elimination and the compiled engine's
    preparation: no thread of the engine's (named "lago-…") is ever alive, and the poses are those of the default."""
    monkeypatch.setattr(ne, "OVERLAP_MIN", 0)
    monkeypatch.setattr(ne, "COMPILED_MIN", 0)
    g = lc.manhattan_world(400, seed=2).graph
    names, stop = set(), threading.Event()

    def watch():
        while not stop.is_set():
            names.update(t.name for t in threading.enumerate() if t.name.startswith("lago-"))

    w = threading.Thread(target=watch)
    w.start()
    try:
        one = lc.lago(g, workers=1)
    finally:
        stop.set()
        w.join()
    assert names == set()
    ref = lc.lago(g)
    assert np.abs(one.poses - ref.poses).max() <= 1e-9 * max(1.0, np.abs(ref.poses).max())


def test_workers_caps_the_compiled_schedule(monkeypatch):
    """``engine_threads(workers=k)`` caps ``cores()``, so the compiled factorization's subtrees go to at most k
    threads (none shared with k = 1); a bad count is an OptionError naming the option."""
    monkeypatch.setattr(C, "PARALLEL_WORK", 0.0)
    monkeypatch.setenv("LAGO_CVX_THREADS", "")
    g = lc.manhattan_world(300, seed=5).graph
    el = ne.GraphElimination(g, 0)
    rng = np.random.default_rng(0)
    A, B = rng.standard_normal((2, g.n_edges, 3, 2))
    system = ne.EdgeSystem(el.tails, el.heads, A, B, rng.standard_normal((g.n_edges, 3)), el.d)
    if not C.available():
        pytest.skip("the compiled engine cannot run here")
    with engine_threads(workers=1):
        f = el.factor(system, engine="compiled")
    assert f.compiled.n_threads == 1
    for bad in (0, -1, 1.5, "2", True):
        with pytest.raises(OptionError, match="workers"):
            lc.lago(g, workers=bad)

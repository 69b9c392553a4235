"""``progress.held_back``: the inner runs of graduated non-convexity keep their records below ERROR out of the log in
their own thread only, and leave every logger's level as it was — under threads too (it used to set the package
logger's level, which two concurrent robust runs could leave at ERROR for the rest of the process)."""

from __future__ import annotations

import logging
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import lago_cvx as lc
from lago_cvx.progress import held_back
from lago_cvx.synthetic import add_false_loop_closures, manhattan_world
from lago_cvx.variants import RobustSettings

LOG = logging.getLogger("lago_cvx.variants")


def test_only_the_blocks_thread_is_held_back(caplog):
    inside, done = threading.Event(), threading.Event()

    def worker():
        with held_back():
            LOG.warning("held warning")
            LOG.error("passing error")
            inside.set()
            done.wait(10)
        LOG.warning("after the block")

    with caplog.at_level(logging.INFO, logger="lago_cvx"):
        t = threading.Thread(target=worker)
        t.start()
        assert inside.wait(10)
        LOG.warning("other thread meanwhile")
        logging.getLogger("lago_cvx.a_new_module").info("a logger created meanwhile")
        done.set()
        t.join(10)
    text = caplog.text
    assert "held warning" not in text
    assert all(m in text for m in ("passing error", "after the block", "other thread meanwhile",
                                   "a logger created meanwhile"))


def test_concurrent_robust_runs_leave_the_levels_and_later_warnings_alone(caplog):
    levels = {n: logging.getLogger(n).level for n in ("lago_cvx", "lago_cvx.variants")}
    graphs = [add_false_loop_closures(manhattan_world(100, seed=s).graph, 0.1, seed=s)[0] for s in (1, 2)]
    settings = RobustSettings(local_search=0)
    with ThreadPoolExecutor(2) as pool:
        for _ in range(2):
            together = list(pool.map(lambda g: lc.lago(g, robust=settings), graphs))
    alone = [lc.lago(g, robust=settings) for g in graphs]
    assert all(np.array_equal(a.rejected_edges, b.rejected_edges) for a, b in zip(together, alone))
    assert {n: logging.getLogger(n).level for n in levels} == levels
    with caplog.at_level(logging.WARNING, logger="lago_cvx"):
        lc.lago(graphs[0], robust=RobustSettings(max_iterations=2))
    assert "without converging" in caplog.text


def test_stages_are_logged_inside_held_back_and_count_their_steps(caplog):
    from lago_cvx.progress import Stages

    calls = []
    stages = Stages("robust", callback=lambda s, f: calls.append((s, f)), logger=LOG, interval=0.0)
    with caplog.at_level(logging.INFO, logger="lago_cvx"), held_back():
        stages.stage("GNC iterations", 4)
        for _ in range(6):  # more steps than the total: the fraction stays at 1
            stages.step()
        stages.stage("local moves", 10)
        stages.step()
        LOG.info("an inner run's record")
        stages.finish()
    assert calls[0] == ("robust: GNC iterations", 0.0) and ("robust: GNC iterations", 0.5) in calls
    assert max(f for s, f in calls if s == "robust: GNC iterations") == 1.0
    assert calls[-2:] == [("robust: local moves", 0.1), ("robust: local moves", 1.0)]
    assert "robust: GNC iterations: 50 %" in caplog.text and "robust: local moves: done" in caplog.text
    assert "an inner run's record" not in caplog.text


def test_a_robust_run_reports_its_stages_not_its_inner_runs():
    calls = []
    go = add_false_loop_closures(manhattan_world(100, seed=3).graph, 0.1, seed=3)[0]
    res = lc.lago(go, robust=True, progress=lambda s, f: calls.append((s, f)))
    stages = list(dict.fromkeys(s for s, _ in calls))
    assert stages == ["robust GNC-TLS: GNC iterations (start lago)", "robust GNC-TLS: local moves"], stages
    assert calls[-1] == ("robust GNC-TLS: local moves", 1.0) and res.rejected_edges.size > 0


def test_every_logger_of_the_package_is_a_module_or_package_name():
    """``held_back`` makes the loggers of the package's module and package names before a block, so that a module
    imported inside it is held back too: every ``getLogger`` of the package must use such a name."""
    import re
    from pathlib import Path

    from lago_cvx.progress import _package_loggers

    root = Path(lc.__file__).parent
    names = set(_package_loggers())
    used = {m for p in root.rglob("*.py") for m in re.findall(r'getLogger\("([^"]+)"\)', p.read_text())}
    assert used and used <= names, used - names

"""benchmarks/share.py: the shares of consistent pairs by kind, and a run's score against the clean classification —
on a generated world, without the datasets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import bench_module
from lago_cvx import lago, refine
from lago_cvx.synthetic import manhattan_world


@pytest.fixture(scope="module")
def share():
    return bench_module("share")


def test_pair_rates_count_each_unordered_pair_once_by_kind(share):
    # loop closures 0, 1 true, 2, 3 false; consistent: (0,1) t–t, (0,2) t–f, (2,3) f–f; not: (0,3), (1,2), (1,3)
    d2 = np.full((4, 4), 50.0)
    np.fill_diagonal(d2, 0.0)
    for i, j in ((0, 1), (0, 2), (2, 3)):
        d2[i, j] = d2[j, i] = 1.0
    tt, tf, ff = share.pair_rates(d2, np.array([False, False, True, True]), 11.34)
    assert (tt, tf, ff) == (1.0, 0.25, 1.0)
    assert math.isnan(share.pair_rates(d2[:2, :2], np.array([False, False]), 11.34)[2])  # no false–false pair


def test_score_of_a_run_that_recovers_the_clean_classification(share):
    """A world where robust LAGO rejects exactly the false loop closures: nothing kept or wrongly rejected, the
    truncated cost equal to the clean classification's (gap 0), the clean χ² recovered, a pass; the same run
    scored against a graph with one more false edge than it rejected fails."""
    g = manhattan_world(150, seed=2).graph
    go, idx, clean_cost = share.corrupted(g, 0.05, 0)
    res = lago(go, robust=True)
    assert set(res.rejected_edges.tolist()) == set(idx.tolist())
    clean_chi2 = refine(g, lago(g).poses).chi2
    s = share.score(g, go, idx, res, clean_chi2, clean_cost)
    assert (s["kept"], s["wrong"], s["ok"]) == (0, 0, True)
    assert s["gap"] == pytest.approx(0.0, abs=1e-9) and s["ratio"] == pytest.approx(1.0, abs=1e-9)
    extra = np.r_[idx, np.flatnonzero(~go.is_odometric & ~np.isin(np.arange(go.n_edges), idx))[:1]]
    worse = share.score(g, go, extra, res, clean_chi2, clean_cost)
    assert (worse["kept"], worse["ok"]) == (1, False)

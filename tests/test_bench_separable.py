"""The leave-one-out Δχ² of each loop closure (``lago_cvx.experiments.removal_costs``) and the verdict that
benchmarks/separable.py draws from it."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import bench_module
from lago_cvx import lago
from lago_cvx.experiments import removal_costs
from lago_cvx.synthetic import add_false_loop_closures, manhattan_world


@pytest.fixture(scope="module")
def separable():
    return bench_module("separable")


def test_verdict_counts_the_true_loop_closures_at_or_above_the_weakest_false_one(separable):
    assert separable.verdict(np.array([0.1, 1.4, 0.7]), np.array([2.7, 8.0])) == ("separable", 0)
    assert separable.verdict(np.array([0.1, 1.4, 0.7]), np.array([0.62, 8.0])) == ("not separable", 2)
    assert separable.verdict(np.array([0.1, 1.4]), np.array([1.4])) == ("not separable", 1)


def test_a_false_loop_closure_kept_strains_the_graph_most(separable):
    """One false loop closure left in a small world: its removal lowers LAGO's χ² by more than any true loop
    closure's, each Δχ² is the χ² difference of two LAGO runs, odometric edges get NaN."""
    g = manhattan_world(80, seed=4).graph
    go, idx = add_false_loop_closures(g, 1.5 / g.n_edges, seed=0)
    seen = []
    d = removal_costs(go, progress=lambda i, n: seen.append((i, n)))
    assert np.isnan(d[go.is_odometric]).all() and np.isfinite(d[~go.is_odometric]).all()
    assert seen[-1] == (go.n_loop_closures, go.n_loop_closures) and len(seen) == go.n_loop_closures
    k = int(np.flatnonzero(~go.is_odometric)[0])
    keep = np.arange(go.n_edges) != k
    assert d[k] == pytest.approx(lago(go).chi2 - lago(go.subgraph_edges(keep)).chi2, rel=1e-12)
    true_lc = ~go.is_odometric & ~np.isin(np.arange(go.n_edges), idx)
    assert idx.size == 1 and separable.verdict(d[true_lc], d[idx]) == ("separable", 0)


def test_removal_costs_leave_a_bridge_out():
    """A loop closure whose removal disconnects the graph (an odometric chain broken at pose 40, bridged by one loop
    closure) has no Δχ²: NaN, not an error."""
    g = manhattan_world(80, seed=4).graph
    cut = np.flatnonzero(g.is_odometric & (np.minimum(g.tails, g.heads) == 40))
    keep = np.ones(g.n_edges, bool)
    keep[cut] = False
    broken = g.subgraph_edges(keep)
    lcs = np.flatnonzero(~broken.is_odometric)
    lo, hi = np.minimum(broken.tails, broken.heads), np.maximum(broken.tails, broken.heads)
    crossing = lcs[(lo[lcs] <= 40) & (hi[lcs] > 40)]
    if crossing.size > 1:  # keep exactly one loop closure across the cut: the bridge
        keep2 = np.ones(broken.n_edges, bool)
        keep2[crossing[1:]] = False
        broken = broken.subgraph_edges(keep2)
    d = removal_costs(broken)
    lo, hi = np.minimum(broken.tails, broken.heads), np.maximum(broken.tails, broken.heads)
    bridge = np.flatnonzero(~broken.is_odometric & (lo <= 40) & (hi > 40))
    assert bridge.size == 1 and np.isnan(d[bridge]).all()
    others = np.setdiff1d(np.flatnonzero(~broken.is_odometric), bridge)
    assert np.isfinite(d[others]).all()

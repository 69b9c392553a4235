"""The start of every closed form, made cheaper at stop 27: AMD of the pose graph called directly
(``lago_cvx.sparse.amd``), the weighted Laplacian factored on the graph's b = 1 pattern
(``upper_pattern.PoseLaplacian``, at once or on first read), L's arrays on reused huge pages
(``ldl.huge_empty``), P_δ by its one cofactor (``EdgeUncertainty.var_delta``), the BFS adjacency from one
sort (``graph._neighbours``) and the refinement's stopping rule (``linalg.REFINEMENT_STOP``). Each is
held to what it replaced or to dense algebra."""

from __future__ import annotations

import gc

import numpy as np
import pytest
import qdldl
import scipy.sparse as sp

import lago_cvx as lc
from lago_cvx import graph as G
from lago_cvx.sparse import amd, ldl, linalg
from lago_cvx.sparse.arrays import unique_sorted
from lago_cvx.errors import GraphError
from lago_cvx.sparse.normal_equations import GraphElimination
from lago_cvx.sparse.smallmat import spd_inverse
from lago_cvx.uncertainty import _sym, edge_uncertainty
from lago_cvx.sparse.upper_pattern import PoseLaplacian

pytestmark = pytest.mark.skipif(not (ldl.available() and amd.available()),
                                reason="qdldl's C routines are not exported by this build")


def _laplacian(el: GraphElimination, w: np.ndarray) -> sp.csc_matrix:
    """A2 diag(w) A2ᵀ over the free poses, assembled by scipy (the edges at the anchor on the diagonal)."""
    d, t, h = el.d, el.tails, el.heads
    rows, cols, vals = [], [], []
    for k in range(t.size):
        ends = [e for e in (t[k], h[k]) if e >= 0]
        for e in ends:
            rows.append(e), cols.append(e), vals.append(w[k])
        if len(ends) == 2:
            rows += [t[k], h[k]]
            cols += [h[k], t[k]]
            vals += [-w[k], -w[k]]
    return sp.csc_matrix((vals, (rows, cols)), shape=(d, d))


@pytest.mark.parametrize("n, seed, anchor", [(60, 1, 0), (400, 3, 17), (1500, 5, 1499)])
def test_amd_gives_qdldl_solvers_order_and_the_laplacian_solves_like_dense(n, seed, anchor):
    g = lc.manhattan_world(n, seed=seed).graph
    w = edge_uncertainty(g).info_delta
    el = GraphElimination(g, anchor, weights=w)
    lap, upper = el.laplacian
    assert isinstance(lap, PoseLaplacian) and upper is None
    N = _laplacian(el, w)
    reference = qdldl.Solver(sp.triu(N).tocsc(), upper=True)
    assert np.array_equal(lap.perm, np.asarray(reference.factors()[2]))  # the same AMD permutation
    assert abs(lap.matrix() - N).max() <= 1e-12 * abs(N).max()
    rhs = np.random.default_rng(seed).standard_normal((el.d, 2))
    dense = np.linalg.solve(N.toarray(), rhs)
    assert np.abs(lap.solve(rhs) - dense).max() <= 1e-9 * np.abs(dense).max()
    L, D, perm = lap.factors()  # (I + L) D (I + L)ᵀ = N permuted
    I = sp.identity(el.d)
    P = N[perm][:, perm]
    assert abs((I + L) @ sp.diags(D) @ (I + L).T - P).max() <= 1e-10 * abs(N).max()


def test_the_laplacian_waits_when_told_and_equals_the_eager_one():
    g = lc.manhattan_world(300, seed=2).graph
    w = edge_uncertainty(g).info_delta
    eager = GraphElimination(g, 0, weights=w)
    lazy = GraphElimination(g, 0, weights=w, factor_laplacian=False)
    assert lazy._lap_pending is not None and lazy._laplacian is None  # nothing factored yet
    assert np.array_equal(lazy.elimination_position, eager.elimination_position)
    rhs = np.arange(eager.d, dtype=float)
    assert np.array_equal(lazy.laplacian[0].solve(rhs), eager.laplacian[0].solve(rhs))
    assert lazy._lap_pending is None


def test_without_amd_qdldl_solver_orders_and_lago_is_unchanged(monkeypatch):
    g = lc.manhattan_world(500, seed=4).graph
    ref = {r: lc.lago(g, route=r) for r in ("default", "seed")}
    monkeypatch.setattr(amd, "_AMD", [None])  # as if the symbol were not exported
    assert not amd.available()
    el = GraphElimination(g, 0, weights=edge_uncertainty(g).info_delta)
    assert isinstance(el.laplacian[0], qdldl.Solver)
    for r, res0 in ref.items():
        res = lc.lago(g, route=r)
        assert np.abs(res.poses - res0.poses).max() <= 1e-12 * np.abs(res0.poses).max()
        assert res.chi2 == pytest.approx(res0.chi2, rel=1e-12)


def test_a_singular_laplacian_leaves_the_plan_to_the_pattern():
    g = lc.manhattan_world(50, seed=1).graph
    w = np.zeros(g.n_edges)  # no rotational information at all: zero pivots
    el = GraphElimination(g, 0, weights=w)
    assert el.laplacian is None
    assert el.plan.d == el.d and np.array_equal(el.elimination_position, el.plan.position)


def test_huge_pages_are_aligned_and_reused_only_after_the_last_view(monkeypatch):
    monkeypatch.setattr(ldl, "_POOL", [])  # regions earlier tests left: not this test's
    monkeypatch.setattr(ldl, "_RETURNED", [])
    n = ldl.HUGE_MIN // 8 + 1000
    a = ldl.huge_empty(n, np.float64)
    assert a.shape == (n,) and a.dtype == np.float64
    if a.base is None:  # no MADV_HUGEPAGE here (another OS, or a kernel that refuses it): plain NumPy memory
        pytest.skip("transparent huge pages cannot be advised on this machine")
    assert a.ctypes.data % (2 << 20) == 0
    a[:] = 7.0
    view = a[5:9]
    address = a.ctypes.data
    del a
    gc.collect()
    b = ldl.huge_empty(n, np.float64)  # the first region is still held by the view: a new one
    assert b.ctypes.data != address and np.all(view == 7.0)
    del view
    gc.collect()
    c = ldl.huge_empty(n, np.int64)
    assert c.ctypes.data == address  # the freed region, reused
    small = ldl.huge_empty(10, np.float64)
    assert small.base is None  # below HUGE_MIN: plain NumPy memory
    del b, c
    gc.collect()
    assert sum(len(r) for r in ldl._POOL + ldl._RETURNED) <= ldl.HUGE_POOL


def test_var_delta_is_spd_inverses_entry_bit_for_bit():
    rng = np.random.default_rng(0)
    m = 5000
    X = rng.standard_normal((m, 3, 3))
    info = X @ np.swapaxes(X, 1, 2) + 0.1 * np.eye(3)
    info[:, 0, 1] += rng.standard_normal(m) * 1e-9  # slightly asymmetric, as files are
    info[7] = [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]  # indefinite: the closed form breaks down
    ref = np.empty(m)
    ok = np.ones(m, bool)
    ok[7] = False
    ref[ok] = spd_inverse(_sym(info[ok]))[:, 2, 2]
    ref[7] = np.linalg.inv(_sym(info[7:8]))[0, 2, 2]
    graph = lc.manhattan_world(10, seed=0).graph
    unc = type(edge_uncertainty(graph))(info)
    assert np.array_equal(unc.var_delta, ref)


def _neighbours_by_lexsort(n, tails, heads):
    """The adjacency as it was built before: two sorted key sets and a lexsort."""
    t, h = np.asarray(tails, np.int64), np.asarray(heads, np.int64)
    out, inn = unique_sorted(t * n + h), unique_sorted(h * n + t)
    src = np.concatenate([out // n, inn // n])
    dst = np.concatenate([out % n, inn % n])
    part = np.concatenate([np.zeros(out.size, np.int8), np.ones(inn.size, np.int8)])
    order = np.lexsort((dst, part, src))
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=indptr[1:])
    return indptr, dst[order]


@pytest.mark.parametrize("seed", range(4))
def test_bfs_adjacency_from_one_sort_is_the_same(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 300))
    m = int(rng.integers(1, 4 * n))
    tails, heads = rng.integers(0, n, m), rng.integers(0, n, m)  # repeats and self-loops included
    for a, b in zip(G._neighbours(n, tails, heads), _neighbours_by_lexsort(n, tails, heads)):
        assert np.array_equal(a, b)


def test_bfs_tree_still_names_the_components_of_a_disconnected_graph():
    g = lc.manhattan_world(40, seed=0).graph
    keep = (g.tails < 20) == (g.heads < 20)  # cut every edge between the first 20 poses and the rest
    parts = g.subgraph_edges(np.flatnonzero(keep))
    with pytest.raises(GraphError, match="20"):
        G.spanning_tree(parts, "bfs")


def test_refinement_stops_once_the_next_correction_would_be_rounding():
    g = lc.manhattan_world(300, seed=7).graph
    res = lc.lago(g, route="seed")
    assert res.phase3.stats["refinement_steps"] == 1
    assert res.phase3.stats["relative_correction"] < linalg.REFINEMENT_STOP
    x = res.phase3.x_star  # against a QR-accurate dense least squares of the same system
    M = (res.phase2.W @ res.phase2.Bt).toarray()
    ref = np.linalg.lstsq(M, res.phase2.W @ res.phase2.z, rcond=None)[0]
    assert np.abs(x - ref).max() <= 1e-11 * np.abs(ref).max()

"""The start of every closed form: the pose-level plan from the pattern alone (the weighted Laplacian of phase 1
factored on it by the engine, held to dense algebra), P_δ by its one cofactor (``EdgeUncertainty.var_delta``), the
BFS adjacency from one sort (``graph._neighbours``) and the refinement's stopping rule
(``linalg.REFINEMENT_STOP``). Each is held to what it replaced or to dense algebra."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx import graph as G
from lago_cvx.sparse import EdgeSystem, linalg
from lago_cvx.stacks import unique_sorted
from lago_cvx.errors import GraphError
from lago_cvx.sparse.normal_equations import GraphElimination
from lago_cvx.stacks import spd_inverse
from lago_cvx.uncertainty import _sym, edge_uncertainty


@pytest.mark.parametrize("n, seed, anchor", [(60, 1, 0), (400, 3, 17), (1500, 5, 1499)])
def test_the_weighted_laplacian_solves_like_dense(n, seed, anchor):
    """Phase 1's system (b = q = 1, A_k = −√w_k, B_k = √w_k) factored on the plan of the pattern alone (built in a
    worker by ``start``) solves like a dense solve of A2 diag(w) A2ᵀ, and the plan is the one built in the caller's
    thread."""
    g = lc.manhattan_world(n, seed=seed).graph
    w = np.random.default_rng(seed).uniform(0.5, 3.0, g.n_edges)
    el = GraphElimination.start(g, anchor)
    s = np.sqrt(w)[:, None, None]
    system = EdgeSystem(el.tails, el.heads, -s, s, np.zeros((g.n_edges, 1)), el.d)
    M = system.sparse().toarray()
    rhs = np.random.default_rng(0).standard_normal(el.d)
    ref = np.linalg.solve(M.T @ M, rhs)
    assert np.abs(el.factor(system).solve(rhs) - ref).max() <= 1e-10 * np.abs(ref).max()
    assert np.array_equal(el.plan.position, GraphElimination(g, anchor).plan.position)


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

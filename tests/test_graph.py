"""Graph machinery: incidence matrices (eqs. 6–7), Proposition 1, spanning trees, chords, cycle basis
(Corollaries 1–2)."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse import csgraph

from lago_cvx.graph import (check_connected, connected_components, cycle_basis, cyclomatic_number,
                            incidence_matrix, reduced_incidence, spanning_tree)
from lago_cvx.errors import GraphError
from lago_cvx.posegraph import PoseGraph
from lago_cvx.synthetic import circle_world, manhattan_world, random_graph

from helpers import graph_from_truth, winding_world


@pytest.fixture(scope="module")
def world():
    return random_graph(40, 75, seed=3, sigma_xy=0.0, sigma_theta=0.0)


def test_incidence_signs_and_differences(world):
    g = world.graph
    A = incidence_matrix(g)
    assert A.shape == (g.n_poses, g.n_edges)
    assert np.all(np.asarray(A.sum(axis=0)).ravel() == 0)
    theta = world.truth[:, 2]
    np.testing.assert_allclose(A.T @ theta, theta[g.heads] - theta[g.tails])
    k = 5
    assert A[g.tails[k], k] == -1 and A[g.heads[k], k] == 1


@pytest.mark.parametrize("anchor", [0, 7, 39])
def test_proposition1_rank(world, anchor):
    g = world.graph
    A = incidence_matrix(g).toarray()
    A2 = reduced_incidence(g, anchor).toarray()
    assert A2.shape == (g.n_poses - 1, g.n_edges)
    np.testing.assert_array_equal(A2, np.delete(A, anchor, axis=0))
    assert np.linalg.matrix_rank(A) == np.linalg.matrix_rank(A2) == g.n_poses - 1


def test_proposition1_disconnected_rank_drops():
    truth = np.zeros((4, 3))
    truth[:, 0] = np.arange(4)
    g = graph_from_truth(truth, [0, 2], [1, 3])
    assert np.linalg.matrix_rank(reduced_incidence(g, 0).toarray()) < 3
    with pytest.raises(GraphError, match=r"not connected: 2 components of sizes 2 poses .*2 poses"):
        check_connected(g)
    assert connected_components(g)[0] == 2


@pytest.mark.parametrize("kind", ["bfs", "odometry", "mst"])
def test_spanning_trees_are_trees(kind):
    w = manhattan_world(300, seed=1)
    g = w.graph
    t = spanning_tree(g, kind, anchor=0)
    n = g.n_poses
    assert t.tree_edges.size == n - 1 and t.chords.size == g.n_edges - n + 1
    assert np.intersect1d(t.tree_edges, t.chords).size == 0
    assert connected_components(g.subgraph_edges(t.tree_edges))[0] == 1
    # parent/edge structure consistent
    child = np.flatnonzero(t.parent >= 0)
    pe = t.parent_edge[child]
    ends = np.sort(np.stack([g.tails[pe], g.heads[pe]], 1), axis=1)
    np.testing.assert_array_equal(ends, np.sort(np.stack([t.parent[child], child], 1), axis=1))
    assert t.parent[0] == -1 and t.depth[0] == 0


@pytest.mark.parametrize("kind", ["odometry", "bfs", "mst"])
def test_large_trees_are_rooted_in_c_with_the_same_parents(kind, monkeypatch):
    """Above ``graph._CSGRAPH_TREE`` poses a tree is rooted by csgraph's traversal instead of the
    level-by-level walk: a tree has one path from each pose to the root, so parents, parent edges and
    depths are the same whichever rooting runs."""
    import lago_cvx.graph as G

    g = manhattan_world(600, seed=4).graph
    monkeypatch.setattr(G, "_CSGRAPH_TREE", 10**12)
    ref = G.spanning_tree(g, kind)
    monkeypatch.setattr(G, "_CSGRAPH_TREE", 0)
    got = G.spanning_tree(g, kind)
    for field in ("parent", "parent_edge", "forward", "depth", "tree_edges", "chords"):
        assert np.array_equal(getattr(got, field), getattr(ref, field)), field


def test_bfs_tree_has_shortest_depth():
    g = manhattan_world(400, seed=2).graph
    t = spanning_tree(g, "bfs", anchor=5)
    adj = sp.csr_matrix((np.ones(g.n_edges), (g.tails, g.heads)), shape=(g.n_poses,) * 2)
    hops = csgraph.shortest_path(adj, directed=False, unweighted=True, indices=5)
    np.testing.assert_array_equal(t.depth, hops.astype(int))
    assert t.root == 5


def test_odometry_tree_uses_consecutive_ids_and_broken_chain_is_named():
    g = manhattan_world(200, seed=0).graph
    t = spanning_tree(g, "odometry")
    assert g.is_odometric[t.tree_edges].all()
    broken = g.subgraph_edges(~((g.tails == 50) & (g.heads == 51)))
    with pytest.raises(GraphError, match=r"odometric chain is broken: no edge between poses 50 and 51"):
        spanning_tree(broken, "odometry")


def test_mst_minimises_total_delta_variance():
    g = random_graph(60, 150, seed=9, information="full").graph
    var = g.covariance[:, 2, 2]
    w = {k: var[spanning_tree(g, k).tree_edges].sum() for k in ("bfs", "mst")}
    assert w["mst"] <= w["bfs"] + 1e-15


def test_user_given_tree_and_rejections(world):
    g = world.graph
    edges = spanning_tree(g, "bfs").tree_edges
    t = spanning_tree(g, edges[::-1])
    np.testing.assert_array_equal(np.sort(t.tree_edges), np.sort(edges))
    with pytest.raises(GraphError, match="spanning tree"):
        spanning_tree(g, edges[:-1])
    cyc = np.concatenate([edges[:-1], t.chords[:1]])
    # n−1 edges that contain a cycle do not span
    if connected_components(g.subgraph_edges(cyc))[0] != 1:
        with pytest.raises(GraphError, match="not a spanning tree"):
            spanning_tree(g, cyc)
    with pytest.raises(ValueError, match="unknown spanning tree"):
        spanning_tree(g, "dfs")


@pytest.mark.parametrize("kind", ["bfs", "odometry", "mst"])
def test_cycle_basis_corollaries(kind):
    w, g, t, C = winding_world(60, 3, 4, kind)
    l = g.n_edges - g.n_poses + 1
    assert cyclomatic_number(g) == l == C.shape[0]  # Corollary 1
    Cd = C.toarray()
    # Corollary 2: in the order [chords, tree edges] C = [I_l B]
    np.testing.assert_array_equal(Cd[:, t.chords], np.eye(l))
    assert set(np.unique(Cd)) <= {-1.0, 0.0, 1.0}
    assert np.linalg.matrix_rank(Cd) == l
    # every row is a cycle: in the null space of the incidence matrix
    assert np.abs(incidence_matrix(g) @ C.T).max() == 0
    # exact unwrapped orientation differences sum to zero around every cycle
    th = w.truth[:, 2]
    assert np.abs(C @ (th[g.heads] - th[g.tails])).max() < 1e-9


def test_tree_integration_matches_truth_on_noiseless_winding_world():
    w = circle_world(90, laps=4, seed=0, sigma_xy=0.0, sigma_theta=0.0)
    g = w.graph
    t = spanning_tree(g, "odometry")
    # odometric measurements are small increments, so integrating them gives the unwrapped truth
    np.testing.assert_allclose(t.integrate(g), w.truth[:, 2] - w.truth[0, 2], atol=1e-9)


def test_single_pose_and_two_poses():
    g = PoseGraph(2, [0], [1], [[1.0, 0.0]], [0.1], [np.eye(3)])
    t = spanning_tree(g, "bfs")
    assert t.tree_edges.tolist() == [0] and t.chords.size == 0
    assert cycle_basis(g, t).shape == (0, 1)


def test_scales_to_100k_edges():
    """Not a timing assertion (see benchmarks/): the machinery runs on a 100k-edge graph."""
    w = manhattan_world(60000, seed=0)
    g = w.graph
    assert g.n_edges > 90000
    for kind in ("bfs", "odometry", "mst"):
        t = spanning_tree(g, kind)
        assert t.tree_edges.size == g.n_poses - 1


@pytest.mark.parametrize("narrow", [0, 3, 64])
def test_numpy_traversals_equal_scipy_csgraph(narrow, monkeypatch):
    """The BFS tree and the component labels are computed in NumPy (importing ``scipy.sparse.csgraph`` costs
    the command line ~0.15 s); they must be exactly what ``csgraph`` gives: same parents (neighbours in
    csgraph's order: out-edges then in-edges, ascending), same labels. ``narrow`` is the widest level
    walked in Python: 0 vectorizes every level, 3 switches between the two kinds of step often (chains
    glued to stars below), 64 is the default."""
    import scipy.sparse as sp
    from scipy.sparse import csgraph

    from lago_cvx import graph as graph_module
    from lago_cvx.graph import _bfs_parents, connected_components

    monkeypatch.setattr(graph_module, "_NARROW_LEVEL", narrow)
    rng = np.random.default_rng(0)
    for trial in range(40):
        n = int(rng.integers(2, 300))
        m = int(rng.integers(1, 3 * n))
        t, h = rng.integers(0, n, m), rng.integers(0, n, m)
        if trial % 4 == 0:  # a chain, a star at its end, chains out of the star's leaves
            c = n // 3
            hub = c
            leaves = np.arange(c + 1, n)
            t = np.r_[np.arange(c), np.full(min(8, leaves.size), hub), leaves[:-8]]
            h = np.r_[np.arange(1, c + 1), leaves[:8], leaves[8:]]
        keep = t != h
        t, h = t[keep], h[keep]
        if t.size == 0:
            continue
        adj = sp.csr_matrix((np.ones(t.size), (t, h)), shape=(n, n))
        root = int(rng.integers(0, n))
        _, pred = csgraph.breadth_first_order(adj, root, directed=False, return_predecessors=True)
        want = np.where(pred < 0, -1, pred)
        want[root] = -1
        np.testing.assert_array_equal(_bfs_parents(n, t, h, root), want)
        k, labels = csgraph.connected_components(adj, directed=False)
        g = PoseGraph(n_poses=n, tails=t, heads=h, delta_l=np.zeros((t.size, 2)), delta=np.zeros(t.size),
                      information=np.broadcast_to(np.eye(3), (t.size, 3, 3)), ids=np.arange(n))
        k2, labels2 = connected_components(g)
        assert k2 == k
        np.testing.assert_array_equal(labels2, labels)

"""χ², its parts and the SE-Sync cost take what the package returns: arrays, LAGO's results (planar and 3-D), the
refinements', GNC's and SE-Sync's, in either dimension through one door (``metrics3d.poses_of``); anything else is
a one-line ``LagoError``, never a raw TypeError."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.errors import GraphError, LagoError, OptionError
from lago_cvx.posegraph3d import edge_errors3d
from lago_cvx.space.certify import sesync_cost3d

from conftest import dataset_path


def _naive_chi2(graph, poses) -> float:
    """eq. (3) edge by edge in plain Python (g2o / paper cost): e = [R(θ_i)ᵀ(p_j − p_i) − Δˡ; wrap(θ_j − θ_i − δ)]."""
    total = 0.0
    for k in range(graph.n_edges):
        pi, pj = poses[graph.tails[k]], poses[graph.heads[k]]
        c, s = np.cos(pi[2]), np.sin(pi[2])
        d = pj[:2] - pi[:2]
        e = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], 0.0])
        e[:2] -= graph.delta_l[k]
        e[2] = (pj[2] - pi[2] - graph.delta[k] + np.pi) % (2 * np.pi) - np.pi
        total += float(e @ graph.information[k] @ e)
    return total


@pytest.fixture(scope="module")
def planar():
    world = lc.manhattan_world(60, seed=1)
    return world, lc.lago(world.graph)


@pytest.fixture(scope="module")
def space():
    world = lc.sphere_world(4, 10, seed=1)
    return world, lc.lago(world.graph)


def test_chi2_of_a_planar_lago_result_is_its_own_chi2_and_eq3(planar):
    world, res = planar
    g = world.graph
    assert g.cost != "gtsam"
    value = lc.chi2(g, res)
    assert value == pytest.approx(res.chi2, rel=1e-12)
    assert value == pytest.approx(_naive_chi2(g, res.poses), rel=1e-10)
    assert lc.chi2(world, res) == value  # a world stands for its graph
    assert lc.chi2(g, world) == pytest.approx(_naive_chi2(g, world.truth), rel=1e-10)  # a world's poses: its truth


def test_chi2_of_a_3d_lago_result_is_chi2_3d(space):
    world, res = space
    g = world.graph
    assert type(res).__name__ == "Lago3DResult"
    value = lc.chi2(g, res)
    assert value == pytest.approx(res.chi2, rel=1e-12)
    assert value == lc.chi2_3d(g, res.t, res.R)
    assert lc.chi2(g, (res.t, res.R)) == value
    assert lc.chi2(world, res) == value
    assert lc.chi2(g, world) == pytest.approx(lc.chi2_3d(g, *world.truth), rel=1e-12)


def test_chi2_of_refine_results_both_dimensions(planar, space):
    for world, res in (planar, space):
        ref = lc.refine(world.graph, res, max_iterations=3)
        assert lc.chi2(world.graph, ref) == pytest.approx(ref.chi2, rel=1e-10)  # no priors: χ² of the edges alone
        assert lc.chi2(world.graph, ref) < lc.chi2(world.graph, res)


def test_chi2_of_a_robust_result_is_over_the_graph_passed_in():
    world = lc.manhattan_world(60, seed=2)
    g, false = lc.add_false_loop_closures(world.graph, 0.05, seed=2)
    res = lc.lago(g, robust=True)
    assert type(res).__name__ == "RobustResult" and res.rejected_edges.size > 0
    assert lc.chi2(res.graph, res) == pytest.approx(res.chi2, rel=1e-12)  # the accepted edges: its own χ²
    everything = lc.chi2(g, res)
    assert everything == pytest.approx(_naive_chi2(g, res.poses), rel=1e-10)
    assert everything > res.chi2  # the false loop closures count when the whole graph is passed


def test_chi2_of_a_3d_robust_result_is_over_the_graph_passed_in(space):
    world, _ = space
    res = lc.lago(world.graph, robust=True)
    assert type(res).__name__ == "Robust3DResult"
    assert lc.chi2(res.graph, res) == pytest.approx(res.chi2, rel=1e-12)
    assert lc.chi2(world.graph, res) == lc.chi2_3d(world.graph, res.t, res.R)


def test_chi2_parts_add_up_in_both_dimensions(planar, space):
    for world, res in (planar, space):
        parts = lc.chi2_parts(world.graph, res)
        assert parts["translation"] + parts["rotation"] + parts["cross"] == pytest.approx(parts["chi2"], rel=1e-12)
        assert parts["chi2"] == pytest.approx(lc.chi2(world.graph, res), rel=1e-12)
        assert parts["translation"] > 0 and parts["rotation"] > 0
    world, res = space
    g = world.graph
    e = edge_errors3d(g, res.t, res.R)
    assert lc.chi2_parts(g, res)["translation"] == pytest.approx(
        float(np.einsum("ka,kab,kb->", e[:, :3], g.information[:, :3, :3], e[:, :3])), rel=1e-12)
    assert lc.edge_errors(g, res).shape == (g.n_edges, 6)
    assert np.sum(lc.whitened_errors(g, res) ** 2) == pytest.approx(res.chi2, rel=1e-12)


def test_sesync_cost_takes_results_of_either_dimension(planar, space):
    world, res = planar
    assert lc.sesync_cost(world.graph, res) == lc.sesync_cost(world.graph, res.poses)
    sesync = lc.refine_sesync(world.graph, res)  # takes a LAGO result as its start too
    assert lc.sesync_cost(world.graph, sesync) == pytest.approx(sesync.cost, rel=1e-10)
    world, res = space
    assert lc.sesync_cost(world.graph, res) == sesync_cost3d(world.graph, res.t, res.R)


BAD = {
    "other dimension": lambda p, s: (p[0].graph, s[1]),
    "planar poses for 3-D": lambda p, s: (s[0].graph, p[1]),
    "wrong length": lambda p, s: (p[0].graph, np.zeros((5, 3))),
    "wrong 3-D length": lambda p, s: (s[0].graph, (np.zeros((3, 3)), np.zeros((3, 3, 3)))),
    "a string": lambda p, s: (p[0].graph, "poses.g2o"),
    "None": lambda p, s: (p[0].graph, None),
    "ragged": lambda p, s: (p[0].graph, [[1.0, 2.0], [3.0]]),
    "a graph as poses": lambda p, s: (p[0].graph, p[0].graph),
    "a result as graph": lambda p, s: (p[1], p[1]),
}


@pytest.mark.parametrize("fn", ["chi2", "chi2_parts", "edge_errors", "whitened_errors", "sesync_cost"])
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_arguments_are_one_line_lago_errors(planar, space, fn, case):
    args = BAD[case](planar, space)
    with pytest.raises(LagoError) as info:
        getattr(lc, fn)(*args)
    assert isinstance(info.value, (OptionError, GraphError))
    assert "\n" not in str(info.value)
    if case == "a result as graph":
        assert isinstance(info.value, GraphError) and "LagoResult" in str(info.value)


@pytest.mark.parametrize("rel", ["se-sync/MIT.g2o", "se-sync-3d/smallGrid3D.g2o"])
def test_chi2_of_lago_on_the_datasets_is_its_own_chi2(rel):
    graph = lc.read_graph(dataset_path(rel))
    res = lc.lago(graph)
    value = lc.chi2(graph, res)
    assert value == pytest.approx(res.chi2, rel=1e-12)
    if graph.dim == 3:
        assert value == lc.chi2_3d(graph, res.t, res.R)
    else:
        assert value == pytest.approx(_naive_chi2(graph, res.poses), rel=1e-9)

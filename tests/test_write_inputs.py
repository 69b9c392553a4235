"""What ``write_graph`` takes: a pose graph or a generated world (its graph), and poses as arrays or any result
of the graph's dimension; everything else a one-line ``LagoError`` before the target is touched."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.errors import GraphError, OptionError
from lago_cvx.io.writer import _wrap_vertex_angles


@pytest.fixture(scope="module")
def planar():
    world = lc.manhattan_world(40, seed=3)
    return world, lc.lago(world.graph)


@pytest.fixture(scope="module")
def space():
    world = lc.sphere_world(3, 8, seed=3)
    return world, lc.lago(world.graph)


def test_a_planar_world_is_written_as_its_graph_with_dead_reckoning(tmp_path, planar):
    world, _ = planar
    path = lc.write_graph(tmp_path / "w.g2o", world)
    back = lc.read_graph(path)
    g = world.graph
    assert (back.n_poses, back.n_edges) == (g.n_poses, g.n_edges)
    np.testing.assert_array_equal(back.delta_l, g.delta_l)
    np.testing.assert_array_equal(back.initial[:, :2], g.initial[:, :2])
    np.testing.assert_array_equal(back.initial[:, 2], _wrap_vertex_angles(g.initial[:, 2]))
    assert path.read_bytes() == lc.write_graph(tmp_path / "g.g2o", g).read_bytes()


def test_a_world_with_a_result_writes_the_result(tmp_path, planar, space):
    for world, res in (planar, space):
        a = lc.write_graph(tmp_path / "a.g2o", world, res).read_bytes()
        b = lc.write_graph(tmp_path / "b.g2o", world.graph, res.poses).read_bytes()
        assert a == b
    world, res = space
    back = lc.read_graph(tmp_path / "a.g2o")
    assert back.dim == 3
    np.testing.assert_allclose(back.initial[0], res.t, atol=1e-12)


BAD = {
    "wrong length": lambda p, s: (p[0].graph, np.zeros((5, 3)), OptionError, "shape (40, 3)"),
    "3-D result for a planar graph": lambda p, s: (p[0].graph, s[1], OptionError, "planar graph"),
    "planar result for a 3-D graph": lambda p, s: (s[0].graph, p[1], OptionError, "3-D graph"),
    "wrong 3-D length": lambda p, s: (s[0].graph, (np.zeros((3, 3)), np.zeros((3, 3, 3))), OptionError, "(24, 3)"),
    "a string as poses": lambda p, s: (p[0].graph, "out.g2o", OptionError, "got str"),
    "ragged poses": lambda p, s: (p[0].graph, [[0.0, 1.0, 2.0], [1.0]], OptionError, "got list"),
    "a result as graph": lambda p, s: (p[1], None, GraphError, "got LagoResult"),
    "a path as graph": lambda p, s: ("in.g2o", None, GraphError, "got str"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_arguments_are_one_line_errors_and_nothing_is_written(tmp_path, planar, space, case):
    graph, poses, kind, words = BAD[case](planar, space)
    target = tmp_path / "out.g2o"
    with pytest.raises(kind) as info:
        lc.write_graph(target, graph, poses)
    assert "\n" not in str(info.value) and words in str(info.value)
    assert not target.exists()


@pytest.mark.parametrize("make", [lambda: lc.manhattan_world(40, seed=2), lambda: lc.sphere_world(40, seed=2)],
                         ids=["planar", "3-D"])
def test_lago_and_refine_take_a_generated_world_as_its_graph(make):
    """``lago(world)`` and ``refine(world, …)`` run on ``world.graph`` (bit for bit), as ``write_graph`` and the
    metrics take a world; anything else that is not a graph is a one-line GraphError."""
    world = make()
    a, b = lc.lago(world), lc.lago(world.graph)
    assert a.chi2 == b.chi2
    assert lc.refine(world, a).chi2 == lc.refine(world.graph, b).chi2
    for bad in ("graph.g2o", None, world.truth):
        with pytest.raises(lc.GraphError, match="expected a pose graph") as err:
            lc.lago(bad)
        assert "\n" not in str(err.value)

"""The two 3-D costs (``posegraph3d``): g2o's [t_E ; q_v] (w ≥ 0) and GTSAM's Log(E) — the errors against hand
formulas, the sign rule, the Jacobians of both against finite differences, the information in Log coordinates,
refine3d's ``cost``, the defaults of hand-built graphs and synthetic worlds, and ``information="blocks"`` on a file
whose 6×6 matrices are indefinite while their blocks are positive definite."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lago_cvx.cli import main
from lago_cvx.errors import OptionError, ParseError
from lago_cvx.io import read_graph, write_graph
from lago_cvx.posegraph3d import (LOG_SCALE, PoseGraph3D, chi2_3d, edge_errors3d, information_in_log_coordinates,
                                  without_cross_terms)
from lago_cvx.so3 import exp_so3, log_se3
from lago_cvx.space import lago3d, refine3d
from lago_cvx.space.certify import certify3d
from lago_cvx.space.gauss_newton import error_derivative, jacobians, retract
from lago_cvx.synthetic.space import cube_grid_world, sphere_world


def _two_poses(E_R, E_t, info=None, cost="g2o"):
    """A graph of two poses, the first at the identity, whose one edge has the error E = (E_R, E_t) at the poses
    returned: measurement Z = (I, 0), head pose E."""
    info = np.diag([1.0, 2.0, 3.0, 40.0, 50.0, 60.0]) if info is None else info
    g = PoseGraph3D(2, [0], [1], [[0.0, 0.0, 0.0]], [np.eye(3)], [info], cost=cost)
    return g, np.array([[0.0, 0.0, 0.0], E_t]), np.array([np.eye(3), E_R])


def _quaternion_by_hand(R):
    """(x, y, z, w) of a rotation whose angle is below π/2 (w = ½√(1 + tr R) is then the largest component)."""
    w = 0.5 * np.sqrt(1.0 + np.trace(R))
    return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (4 * w), w


def _random_graph(seed=0, cost="g2o", scale=0.3):
    """A small loop graph with correlated 6×6 information and errors of ~``scale`` rad at the poses returned."""
    rng = np.random.default_rng(seed)
    n, m = 6, 9
    tails = np.array([0, 1, 2, 3, 4, 0, 1, 2, 5])
    heads = np.array([1, 2, 3, 4, 5, 3, 4, 5, 0])
    A = rng.normal(size=(m, 6, 6))
    info = A @ np.swapaxes(A, 1, 2) + 5 * np.eye(6)
    g = PoseGraph3D(n, tails, heads, rng.normal(size=(m, 3)), exp_so3(scale * rng.normal(size=(m, 3))), info,
                    cost=cost)
    t, R = rng.normal(size=(n, 3)), exp_so3(rng.normal(size=(n, 3)))
    return g, t, R


# ------------------------------------------------------------------ the errors
def test_g2o_error_is_the_translation_and_the_quaternions_vector_part():
    E_R, E_t = exp_so3(np.array([0.3, -0.2, 0.5])), np.array([1.0, -2.0, 0.5])
    info = np.diag([1.0, 2.0, 3.0, 40.0, 50.0, 60.0])
    g, t, R = _two_poses(E_R, E_t, info)
    qv, w = _quaternion_by_hand(E_R)
    e = np.r_[E_t, qv]
    assert np.allclose(edge_errors3d(g, t, R)[0], e, rtol=0, atol=1e-15)
    assert chi2_3d(g, t, R) == pytest.approx(e @ info @ e, rel=1e-14)
    # GTSAM's: the Log of SE(3), the same matrix weighing it
    xi = log_se3(E_R, E_t)
    assert chi2_3d(g, t, R, cost="gtsam") == pytest.approx(xi @ info @ xi, rel=1e-14)
    assert np.allclose(edge_errors3d(g.with_cost("gtsam"), t, R)[0], xi, atol=1e-15)


@pytest.mark.parametrize("angle", [0.9 * np.pi, 1.1 * np.pi, 1.7 * np.pi])
def test_g2o_rotation_error_keeps_w_nonnegative(angle):
    """E = Exp(θa): q = ±(sin(θ/2)a, cos(θ/2)); g2o's sign makes w ≥ 0, so q_v = sin(θ/2)a for θ < π and
    −sin(θ/2)a beyond (a rotation by θ about a is one by 2π − θ about −a)."""
    a = np.array([2.0, -1.0, 2.0]) / 3.0
    g, t, R = _two_poses(exp_so3(angle * a), np.zeros(3))
    qv = edge_errors3d(g, t, R)[0, 3:]
    sign = 1.0 if angle < np.pi else -1.0
    assert np.allclose(qv, sign * np.sin(angle / 2) * a, atol=1e-12)
    assert np.linalg.norm(qv) <= 1.0


def test_costs_agree_to_first_order_and_the_log_information():
    """e_g2o = S e_gtsam + O(‖ξ‖²) at small errors, so Ω weighs the Log error like S Ω S
    (information_in_log_coordinates), and D(E = I) = S."""
    g, _, _ = _random_graph()
    h = 1e-4
    xi = h * np.array([0.3, -0.5, 0.2, 0.7, -0.4, 0.9])
    from lago_cvx.synthetic.space import _exp_se3

    Rx, tx = _exp_se3(xi[None])
    one, t, R = _two_poses(Rx[0], tx[0], g.information[0])
    assert np.allclose(edge_errors3d(one, t, R)[0], LOG_SCALE @ xi, rtol=0, atol=h ** 2)
    W = information_in_log_coordinates(one)[0]
    assert chi2_3d(one, t, R) == pytest.approx(xi @ W @ xi, rel=10 * h)
    assert np.allclose(W[3:, 3:], 0.25 * g.information[0, 3:, 3:]) and np.allclose(W[:3, 3:], 0.5 *
                                                                                 g.information[0, :3, 3:])
    assert np.array_equal(information_in_log_coordinates(one.with_cost("gtsam")), one.information)
    _, D = error_derivative(one, np.zeros((2, 3)), np.array([np.eye(3)] * 2))
    assert np.array_equal(D[0], LOG_SCALE)


@pytest.mark.parametrize("cost", ["g2o", "gtsam"])
@pytest.mark.parametrize("scale", [0.05, 1.0])
def test_jacobians_of_both_costs_against_finite_differences(cost, scale):
    """∂e/∂δ of the head (D) and the tail (−D Ad(T_j⁻¹T_i)) with the retraction refine3d uses, at errors of
    ``scale`` rad (w near 1 and well below it), every edge and every column."""
    g, t, R = _random_graph(seed=3, cost=cost, scale=scale)
    R = R.copy()
    R[g.heads] = R[g.tails] @ g.delta_R  # errors of about the measurement noise: w ≥ 0 stays far from 0
    R = R @ exp_so3(scale * np.random.default_rng(1).normal(size=(g.n_poses, 3)))
    e, Ji, Jj = jacobians(g, t, R)
    n, h = g.n_poses, 1e-6
    anchor = 0
    worst = 0.0
    for k in range(g.n_edges):
        for pose, J in ((g.tails[k], Ji[k]), (g.heads[k], Jj[k])):
            if pose == anchor:
                continue
            num = np.empty((6, 6))
            for c in range(6):
                d = np.zeros((n, 6))
                d[pose, c] = h
                plus = edge_errors3d(g, *retract(t, R, d[1:].ravel(), anchor))[k]
                minus = edge_errors3d(g, *retract(t, R, -d[1:].ravel(), anchor))[k]
                num[:, c] = (plus - minus) / (2 * h)
            worst = max(worst, np.abs(num - J).max() / max(1.0, np.abs(J).max()))
    assert worst < 1e-7, worst
    assert np.array_equal(e, edge_errors3d(g, t, R))


def test_refine3d_minimizes_the_cost_it_is_given():
    g, t, R = _random_graph(seed=5, scale=0.2)
    res = lago3d(g)
    # a graph of large residuals, where Gauss–Newton converges linearly: the gradient test asks for more than
    # refine's defaults (a relative decrease below 1e-9 stops it at a gradient of 3e-6 relative here)
    tight = {"tolerance": 1e-12, "max_iterations": 100}
    a = refine3d(g, res.t, res.R, **tight)
    b = refine3d(g, res.t, res.R, cost="gtsam", **tight)
    c = refine3d(g.with_cost("gtsam"), res.t, res.R, **tight)
    assert a.converged and b.converged and b.chi2 == c.chi2 and np.array_equal(b.t, c.t)
    assert a.chi2 == pytest.approx(chi2_3d(g, a.t, a.R), rel=1e-15)
    # each is a minimum of its own cost: the gradient JᵀΩe vanishes there
    for graph, out in ((g, a), (g.with_cost("gtsam"), b)):
        e, Ji, Jj = jacobians(graph, out.t, out.R)
        r = np.einsum("kij,kj->ki", graph.information, e)
        grad = np.zeros((graph.n_poses, 6))
        np.add.at(grad, graph.tails, np.einsum("kji,kj->ki", Ji, r))
        np.add.at(grad, graph.heads, np.einsum("kji,kj->ki", Jj, r))
        assert np.abs(grad[1:]).max() < 1e-6 * out.chi2  # measured 8.7e-8 (g2o), 7.6e-8 (gtsam) relative
    assert a.chi2 < chi2_3d(g, b.t, b.R) and b.chi2 < chi2_3d(g, a.t, a.R, cost="gtsam")
    with pytest.raises(OptionError, match="planar"):
        refine3d(g, res.t, res.R, cost="paper")


# ------------------------------------------------------------------ the graph
def test_cost_field_defaults_and_with_cost():
    g, t, R = _random_graph()
    assert g.cost == "g2o"
    h = g.with_cost("gtsam")
    assert h.cost == "gtsam" and np.array_equal(h.information, g.information) and np.array_equal(h.delta_R, g.delta_R)
    assert h.with_cost("g2o").equals(g) and not h.equals(g) and g.with_cost("g2o") is g
    assert chi2_3d(h, t, R) == chi2_3d(g, t, R, cost="gtsam") != chi2_3d(g, t, R)
    with pytest.raises(OptionError, match=r"unknown cost 'paper' \(the paper's eq. \(3\) is planar\)"):
        g.with_cost("paper")
    with pytest.raises(OptionError, match="planar"):
        PoseGraph3D(2, [0], [1], [[1.0, 0, 0]], [np.eye(3)], [np.eye(6)], cost="paper")
    with pytest.raises(OptionError, match="unknown cost"):
        chi2_3d(g, t, R, cost="toro")


@pytest.mark.parametrize("cost", ["g2o", "gtsam"])
def test_synthetic_world_noise_is_its_costs_error(cost):
    """The error of the world's cost at the truth is the noise drawn, exactly (synthetic.space docstring): the same
    generator's draws, scaled as the docstring says."""
    w = sphere_world(3, 6, seed=11, sigma_t=0.05, sigma_r=0.02, cost=cost)
    g = w.graph
    assert g.cost == cost == w.params["cost"]
    sd = np.r_[np.full(3, 0.05), np.full(3, 0.01 if cost == "g2o" else 0.02)]
    noise = np.random.default_rng(11).standard_normal((g.n_edges, 6)) * sd
    e = edge_errors3d(g, w.t, w.R)
    assert np.abs(e - (noise if cost == "g2o" else -noise)).max() < 1e-12
    assert np.allclose(g.information, np.diag(sd ** -2))
    # the two worlds weigh the Log error alike to first order
    other = sphere_world(3, 6, seed=11, sigma_t=0.05, sigma_r=0.02, cost="gtsam" if cost == "g2o" else "g2o")
    assert np.allclose(information_in_log_coordinates(g), information_in_log_coordinates(other.graph))


def test_default_world_and_generated_file_mean_g2os_cost(tmp_path):
    w = cube_grid_world(3, seed=2)
    assert w.graph.cost == "g2o"
    back = read_graph(write_graph(tmp_path / "w.g2o", w.graph))
    assert back.equals(w.graph, rtol=1e-13, atol=1e-14)
    assert chi2_3d(back, w.t, w.R) == pytest.approx(chi2_3d(w.graph, w.t, w.R), rel=1e-12)


# ------------------------------------------------------------------ information="blocks"
def _indefinite_file(tmp_path):
    """A generated world written to a file whose edges 3, 7 and 12 carry Ω = [[A, C], [Cᵀ, B]] with A, B positive
    definite and C large enough to make Ω indefinite (as some public 3-D graphs do); (path, their line numbers)."""
    w = cube_grid_world(3, seed=4)
    p = write_graph(tmp_path / "indefinite.g2o", w.graph)
    lines = p.read_text().splitlines()
    first_edge = next(k for k, line in enumerate(lines) if line.startswith("EDGE_SE3:QUAT"))
    bad = [first_edge + k for k in (3, 7, 12)]
    omega = np.diag([400.0, 400.0, 400.0, 2500.0, 2500.0, 2500.0])
    omega[:3, 3:] = omega[3:, :3] = 1500.0 * np.eye(3)  # 1500² > 400·2500: indefinite; the blocks are fine
    assert np.linalg.eigvalsh(omega).min() < 0
    upper = " ".join(repr(float(v)) for v in omega[np.triu_indices(6)])
    for k in bad:
        lines[k] = " ".join(lines[k].split()[:10]) + " " + upper
    p.write_text("\n".join(lines) + "\n")
    return p, [k + 1 for k in bad], w


def test_indefinite_information_is_refused_naming_blocks(tmp_path, capsys):
    p, bad, _ = _indefinite_file(tmp_path)
    with pytest.raises(ParseError) as err:
        read_graph(p)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{p}:{bad[0]}:")
    assert "information matrix is not positive definite" in msg
    assert "information='blocks'" in msg and "--information blocks" in msg
    assert main(["solve", str(p)]) == 2
    assert f"{p.name}:{bad[0]}:" in capsys.readouterr().err


def test_blocks_reading_solves_refines_and_certifies(tmp_path, capsys):
    p, bad, w = _indefinite_file(tmp_path)
    g = read_graph(p, information="blocks")
    assert np.abs(g.information[:, :3, 3:]).max() == 0.0
    gt = read_graph(p, information="blocks", cost="gtsam")
    assert gt.cost == "gtsam" and np.array_equal(g.information, gt.information)
    full = read_graph(write_graph(tmp_path / "ok.g2o", w.graph))
    assert full.with_blocks().equals(read_graph(tmp_path / "ok.g2o", information="blocks"))
    assert np.array_equal(without_cross_terms(full.information), full.with_blocks().information)
    res = lago3d(g)
    ref = refine3d(g, res.t, res.R)
    assert ref.converged and ref.chi2 <= res.chi2
    assert certify3d(g, res.t, res.R).certified
    out = tmp_path / "est.g2o"
    assert main(["solve", str(p), "--information", "blocks", "--refine", "--json", "-o", str(out)]) == 0
    solved = json.loads(capsys.readouterr().out)
    assert solved["cost"] == "g2o" and solved["chi2_refined"] == pytest.approx(ref.chi2, rel=1e-9)
    assert main(["certify", str(p), "--information", "blocks", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["certified"]
    assert main(["info", str(p), "--information", "blocks", "--cost", "gtsam", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["cost"] == "gtsam"


def test_lago3d_reports_the_cost_it_minimizes():
    """lago3d(cost=) and lago(cost=) run the route in that cost: χ² is that cost's at the estimate, the positions
    its exact minimizer at the rotations (every move of a free position costs)."""
    from lago_cvx import lago
    from lago_cvx.space import positions_closed_form

    w = sphere_world(4, 8, seed=6, sigma_r=0.05)
    for cost in ("g2o", "gtsam"):
        res = lago3d(w.graph, cost=cost)
        assert res.cost == cost and res.chi2 == chi2_3d(w.graph, res.t, res.R, cost=cost)
        assert lago(w.graph, cost=cost).chi2 == res.chi2
        g = w.graph.with_cost(cost)
        t, _ = positions_closed_form(g, res.R)
        best = chi2_3d(g, t, res.R)
        rng = np.random.default_rng(0)
        for _ in range(3):
            d = 1e-4 * rng.normal(size=t.shape)
            d[0] = 0.0
            assert chi2_3d(g, t + d, res.R) > best


def test_repair_reads_the_indefinite_file_and_blocks_that_fail_are_named(tmp_path, caplog):
    p, bad, _ = _indefinite_file(tmp_path)
    with caplog.at_level("WARNING", logger="lago_cvx.io"):
        g = read_graph(p, repair=True)
    assert "3 information matrix(es) not positive definite replaced" in caplog.text and f"line {bad[0]}" in caplog.text
    assert (np.linalg.eigvalsh(g.information[[3, 7, 12]]) > 0).all()
    # a matrix whose rotation block itself is indefinite: blocks cannot help, and the message does not offer them
    text = p.read_text().splitlines()
    toks = text[bad[1] - 1].split()
    toks[10 + 15] = "-2500.0"  # I44 (the first rotation entry) of the second such edge
    text[bad[1] - 1] = " ".join(toks)
    p.write_text("\n".join(text) + "\n")
    with pytest.raises(ParseError, match=rf":{bad[1]}: information matrix without its cross terms is not positive"):
        read_graph(p, information="blocks")
    with pytest.raises(ParseError) as err:
        read_graph(p)
    assert f":{bad[0]}:" in str(err.value)  # the first bad line: its blocks are fine, so blocks is named
    assert "information='blocks'" in str(err.value)

"""The chordal relaxation of the rotations and the chordal 2kπ regularization (issue 8).

Checks: noiseless exactness, cvxpy vs closed form (synthetic and every dataset), independence of the
data's 2π wrapping and of the spanning tree, agreement with the tree rounding at low noise, Gauss–Newton
from the chordal LAGO reaching the reference minimum on every dataset, and the rotation-noise sweep where
tree rounding fails and the chordal regularizer does not."""

from __future__ import annotations

import json
import logging
from dataclasses import replace

import numpy as np
import pytest

from lago_cvx import compare_methods, lago, read_graph, refine
from lago_cvx.regularization.chordal import chordal_closed_form, chordal_from_problem, chordal_system
from lago_cvx.cli import main
from lago_cvx.experiments import format_sweep, rotation_noise_sweep, true_cycle_integers
from lago_cvx.graph import spanning_tree
from lago_cvx.io import write_graph
from lago_cvx.uncertainty import edge_uncertainty
from lago_cvx.posegraph import wrap_angle
from lago_cvx.regularization import regularize
from lago_cvx.synthetic import circle_world, manhattan_world, random_graph

from lago_cvx.datasets import DATASET_TABLE, REFERENCE_CHI2
from conftest import dataset_path
from helpers import pose_error

NOISELESS = {
    "manhattan": lambda: manhattan_world(400, seed=3, sigma_xy=0.0, sigma_theta=0.0),
    "circle_5_laps": lambda: circle_world(150, laps=5, seed=2, sigma_xy=0.0, sigma_theta=0.0),
    "random_full_info": lambda: random_graph(80, 200, seed=4, spanning="odometry", sigma_xy=0.0,
                                             sigma_theta=0.0, information="full"),
}


def _info(graph):
    return 1.0 / edge_uncertainty(graph).var_delta


@pytest.mark.parametrize("world", sorted(NOISELESS))
def test_noiseless_relaxation_is_tight_and_exact(world):
    w = NOISELESS[world]()
    est = chordal_closed_form(w.graph, _info(w.graph))
    truth = w.truth[:, 2] - w.truth[0, 2]
    assert np.abs(wrap_angle(est.theta - truth)).max() < 1e-10
    assert np.abs(est.norms - 1.0).max() < 1e-10  # tight: every ‖r_i‖ = 1
    assert est.cost < 1e-20
    res = lago(w.graph, regularization="chordal", anchor_pose=w.truth[0])
    assert pose_error(res.poses, w.truth) < 1e-9


def test_system_rows_are_the_rotation_equation():
    """(C3) against the formula, every edge at the true rotations, ω = 4: rows √ω(r_j − R(δ) r_i) = 2(r_j − R(δ) r_i)."""
    w = manhattan_world(12, seed=0)
    g = w.graph
    M, b = chordal_system(g, np.full(g.n_edges, 4.0), anchor=0)
    assert M.shape == (2 * g.n_edges, 2 * (g.n_poses - 1))
    x = np.column_stack([np.cos(w.truth[1:, 2]), np.sin(w.truth[1:, 2])]).ravel()
    r = (M @ x - b).reshape(-1, 2)
    th = w.truth[:, 2]
    c, s = np.cos(g.delta), np.sin(g.delta)
    ri = np.column_stack([np.cos(th[g.tails]), np.sin(th[g.tails])])
    rj = np.column_stack([np.cos(th[g.heads]), np.sin(th[g.heads])])
    rot = np.column_stack([c * ri[:, 0] - s * ri[:, 1], s * ri[:, 0] + c * ri[:, 1]])
    assert np.allclose(r, 2.0 * (rj - rot), atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cvxpy_and_closed_form_agree_on_synthetic(seed):
    g = manhattan_world(300, seed=seed, sigma_theta=0.2).graph
    a = chordal_closed_form(g, _info(g), anchor=5)
    b, problem = chordal_from_problem(g, _info(g), anchor=5)
    assert "sum_squares" in str(problem.objective) or "quad_over_lin" in str(problem.objective)
    assert np.abs(a.vectors - b.vectors).max() <= 1e-6 * np.abs(a.vectors).max()
    assert a.cost == pytest.approx(b.cost, rel=1e-6)
    assert a.vectors[5].tolist() == [1.0, 0.0]


@pytest.mark.parametrize("rel", [row[0] for row in DATASET_TABLE])
def test_cvxpy_and_closed_form_agree_on_every_dataset(rel):
    g = read_graph(dataset_path(rel))
    _, report = compare_methods(g, regularization="chordal")
    d = report["max_rel_diff"]
    print(f"{rel}: chordal relaxation cvxpy vs closed form {d['chordal']:.2e}; phase1 {d['phase1']:.2e}, "
          f"phase3 {d['phase3']:.2e}")
    assert d["chordal"] <= 1e-6 and d["phase1"] <= 1e-6 and d["phase3"] <= 1e-6


def test_cvxpy_route_keeps_the_chordal_problem():
    g = manhattan_world(80, seed=1).graph
    res = lago(g, method="cvxpy", regularization="chordal")
    assert set(res.problems) == {"chordal", "phase1", "phase3", "positions"}
    ref = lago(g, regularization="chordal")
    assert np.abs(res.poses - ref.poses).max() < 1e-8


def test_independent_of_the_data_wrapping():
    """δ enters the relaxation only through cos δ, sin δ: adding 2π·(random integers) to the measured
    orientations changes neither the estimate nor the final poses."""
    w = manhattan_world(200, seed=5, sigma_theta=0.1)
    g = w.graph
    rng = np.random.default_rng(0)
    shifted = replace(g, delta=g.delta + 2 * np.pi * rng.integers(-3, 4, g.n_edges))
    a, b = lago(g, regularization="chordal"), lago(shifted, regularization="chordal")
    assert np.abs(a.regularization.chordal.vectors - b.regularization.chordal.vectors).max() < 1e-12
    assert np.abs(wrap_angle(a.poses[:, 2] - b.poses[:, 2])).max() < 1e-9
    assert np.abs(a.poses[:, :2] - b.poses[:, :2]).max() < 1e-9


def test_rounding_residuals_and_gauge():
    """(R-C): every edge's residual against φ̃ lies in (−π, π]; φ̃ is φ on the tree's branch; the
    phase-1 input is consistent: its cycle sums equal the cycle sums of the residuals."""
    g = manhattan_world(300, seed=2, sigma_theta=0.25).graph
    tree = spanning_tree(g, "bfs")
    reg = regularize(g, tree, regularization="chordal")
    r = reg.edge_residual
    assert np.all(r > -np.pi) and np.all(r <= np.pi)
    assert np.allclose(reg.delta_reg - (reg.reference[g.heads] - reg.reference[g.tails]), r)
    assert np.allclose(wrap_angle(reg.reference - reg.chordal.theta), 0.0, atol=1e-12)
    assert np.abs(reg.reference - tree.integrate(g)).max() <= np.pi + 1e-12
    cyc = reg.residual  # C δ_reg
    assert np.allclose(cyc, r[reg.chords] - tree.path_sums(g, r)[reg.chords])
    assert reg.summary()["regularization"] == "chordal"


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("tree", ["bfs", "odometry", "mst"])
def test_same_integers_as_tree_rounding_at_low_noise(seed, tree):
    w = manhattan_world(300, seed=seed, sigma_theta=0.02)
    t, c = lago(w.graph, spanning_tree=tree), lago(w.graph, spanning_tree=tree, regularization="chordal")
    assert np.array_equal(t.regularization.cycle_k, c.regularization.cycle_k)
    assert np.array_equal(c.regularization.cycle_k, true_cycle_integers(w.graph, c.tree, w.truth))
    assert np.abs(t.poses - c.poses).max() < 1e-9


def test_chordal_does_not_depend_on_the_tree():
    """The tree only fixes the 2π gauge of φ̃: the phase-1 orientations agree modulo 2π and the poses
    agree, whatever tree (here the odometric one, which misleads the tree rounding at this noise)."""
    w = manhattan_world(300, seed=0, sigma_theta=0.3)
    a = lago(w.graph, regularization="chordal")
    b = lago(w.graph, regularization="chordal", spanning_tree="odometry")
    assert np.abs(wrap_angle(a.poses[:, 2] - b.poses[:, 2])).max() < 1e-9
    assert np.abs(a.poses[:, :2] - b.poses[:, :2]).max() < 1e-9


# ----------------------------------------------------------------------------- real datasets
@pytest.mark.parametrize("rel", sorted(REFERENCE_CHI2))
def test_gauss_newton_from_chordal_lago_reaches_reference_minimum(rel):
    g = read_graph(dataset_path(rel))
    res = lago(g, regularization="chordal")
    gn = refine(g, res.poses)
    print(f"{rel}: chi2 chordal-LAGO {res.chi2:.6g} -> GN {gn.chi2:.6g} in {gn.iterations} iterations "
          f"(reference {REFERENCE_CHI2[rel]})")
    assert gn.chi2 == pytest.approx(REFERENCE_CHI2[rel], rel=1e-5)
    assert gn.converged


@pytest.mark.parametrize("rel", ["gtsam/noisyToyGraph.txt", "se-sync/MIT.g2o", "se-sync/intel.g2o"])
def test_same_integers_as_bfs_tree_on_real_data(rel):
    g = read_graph(dataset_path(rel))
    t, c = lago(g), lago(g, regularization="chordal")
    assert np.array_equal(t.regularization.cycle_k, c.regularization.cycle_k)


def test_chordal_rescues_the_odometric_tree_on_m3500a():
    """With the seed's odometric tree, tree rounding lands in a wrong basin on M3500a (GN ends ≈ 8779);
    the chordal regularizer on the same tree gives GN's 912.115."""
    g = read_graph(dataset_path("carlone/input_M3500a_g2o.g2o"))
    odo = lago(g, spanning_tree="odometry", regularization="tree")
    cho = lago(g, spanning_tree="odometry", regularization="chordal")
    assert odo.regularization.ambiguous.size > 0 and cho.regularization.ambiguous.size == 0
    assert refine(g, odo.poses).chi2 > 5 * REFERENCE_CHI2["carlone/input_M3500a_g2o.g2o"]
    assert refine(g, cho.poses).chi2 == pytest.approx(912.115, rel=1e-5)


# ----------------------------------------------------------------------------- the noise sweep
def test_rotation_noise_sweep_tree_rounding_fails_chordal_does_not(capsys):
    """Manhattan worlds (300 poses, 8 seeds) at σ_θ = 0.05 and 0.3 rad: at 0.05 every regularizer
    reaches the ground-truth optimum; at 0.3 the tree roundings mostly fail (wrong integers) while the
    chordal regularizer reaches it in every trial."""
    logging.disable(logging.WARNING)
    try:
        rows = rotation_noise_sweep([0.05, 0.3], seeds=range(8), n_poses=300)
    finally:
        logging.disable(logging.NOTSET)
    with capsys.disabled():
        print("\n" + format_sweep(rows))
    by = {(r["sigma_theta"], r["regularizer"]): r for r in rows}
    for name in ("tree (bfs)", "tree (odometry)", "chordal"):
        assert by[(0.05, name)]["optimal"] == 8 and by[(0.05, name)]["correct_integers"] == 8
    assert by[(0.3, "chordal")]["optimal"] == 8 and by[(0.3, "chordal")]["correct_integers"] == 8
    assert by[(0.3, "tree (bfs)")]["optimal"] <= 4
    assert by[(0.3, "tree (odometry)")]["optimal"] == 0


def test_cli_regularization_option(tmp_path, capsys):
    w = manhattan_world(300, seed=0, sigma_theta=0.3)
    f = tmp_path / "g.g2o"
    write_graph(f, w.graph, w.truth)
    assert main(["solve", str(f), "--regularization", "chordal", "--refine", "--json"]) == 0
    cho = json.loads(capsys.readouterr().out)
    assert main(["solve", str(f), "--route", "seed", "--refine", "--json"]) == 0
    odo = json.loads(capsys.readouterr().out)
    ref = refine(w.graph, w.truth).chi2
    assert cho["regularization"] == "chordal" and odo["regularization"] == "tree"
    assert cho["chi2_refined"] == pytest.approx(ref, rel=1e-6)
    assert odo["chi2_refined"] > 1.01 * ref
    assert main(["info", str(f), "--regularization", "chordal", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["regularization"] == "chordal" and info["n_regularized"] >= 0
    with pytest.raises(SystemExit):
        main(["solve", str(f), "--regularization", "integer-magic"])


def test_unknown_regularization_is_a_clear_error():
    g = manhattan_world(20, seed=0).graph
    with pytest.raises(ValueError, match="unknown regularization 'chordl'"):
        lago(g, regularization="chordl")


def test_anchored_lago_with_chordal_regularization():
    w = manhattan_world(300, seed=0, sigma_theta=0.3)
    anchors = {0: tuple(w.truth[0]), 150: tuple(w.truth[150])}
    res = lago(w.graph, anchors=anchors, regularization="chordal")
    assert res.regularization.regularization == "chordal"
    gn = refine(w.graph, res.poses)
    assert gn.chi2 <= refine(w.graph, w.truth).chi2 * (1 + 1e-6)

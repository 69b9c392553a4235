"""2kπ regularization (Section IV-E, Theorem 3, eqs. 20–23, Corollary 3)."""

import logging

import numpy as np
import pytest

from lago_cvx.graph import spanning_tree
from lago_cvx.io import read_graph
from lago_cvx.posegraph import PoseGraph
from lago_cvx.regularization import regularize
from lago_cvx.synthetic import manhattan_world, random_graph

from conftest import dataset_path
from helpers import winding_world


@pytest.mark.parametrize("kind", ["bfs", "odometry", "mst"])
def test_noiseless_winding_world_is_made_cycle_consistent(kind):
    _, g, t, C = winding_world(120, 5, 1, kind)
    reg = regularize(g, t)
    assert np.abs(C @ reg.delta_reg).max() < 1e-9          # Theorem 3: C δ_reg = 0
    assert np.abs(reg.cycle_residual(g)).max() < 1e-9
    np.testing.assert_allclose(reg.cycle_residual(g), reg.residual, atol=1e-12)
    assert reg.n_regularized > 0                              # the wraparound really occurs
    assert np.all(reg.k[t.tree_edges] == 0)                   # tree edges are never corrected
    assert reg.ambiguous.size == 0


def test_corrections_are_multiples_of_2pi_and_residual_in_half_open_interval():
    w = manhattan_world(800, seed=3, sigma_theta=0.05)
    g = w.graph
    reg = regularize(g, spanning_tree(g, "odometry"))
    np.testing.assert_allclose((reg.delta_reg - g.delta) / (2 * np.pi), reg.k, atol=1e-9)
    assert np.all(reg.residual > -np.pi) and np.all(reg.residual <= np.pi)
    np.testing.assert_allclose(reg.residual, reg.residual_before + 2 * np.pi * reg.k_chords, atol=1e-9)


def test_invariant_to_adding_2pi_k_to_measurements():
    w = random_graph(50, 110, seed=5, sigma_theta=0.05)
    g = w.graph
    rng = np.random.default_rng(0)
    shifted = PoseGraph(g.n_poses, g.tails, g.heads, g.delta_l,
                        g.delta + 2 * np.pi * rng.integers(-3, 4, g.n_edges), g.information)
    t = spanning_tree(g, "bfs")
    a, b = regularize(g, t), regularize(shifted, spanning_tree(shifted, "bfs"))
    np.testing.assert_allclose(a.residual, b.residual, atol=1e-9)
    # the regularized chords equal up to the tree's own 2π shifts: cycle sums identical
    np.testing.assert_allclose(a.cycle_residual(g), b.cycle_residual(shifted), atol=1e-9)


def test_tie_rule_and_ambiguity_warning(caplog):
    # triangle 0→1→2 and chord 0→2 whose cycle residual is exactly π before rounding
    tails, heads = np.array([0, 1, 0]), np.array([1, 2, 2])
    delta = np.array([np.pi / 2, np.pi / 2, 0.0])  # tree path says π, chord says 0: residual −π
    g = PoseGraph(3, tails, heads, np.ones((3, 2)), delta, np.broadcast_to(np.eye(3), (3, 3, 3)))
    with caplog.at_level(logging.WARNING, logger="lago_cvx.regularization"):
        reg = regularize(g, spanning_tree(g, "odometry"))
    assert reg.residual.tolist() == [pytest.approx(np.pi)]   # tie → +π (half-open (−π, π])
    assert reg.k_chords.tolist() == [1]
    assert reg.ambiguous.tolist() == [2]
    assert "0->2" in caplog.text and "ambiguous" in caplog.text


def test_noise_too_large_is_reported_not_silent():
    w = manhattan_world(1500, seed=2, sigma_theta=0.25)
    g = w.graph
    reg = regularize(g, spanning_tree(g, "odometry"))
    assert reg.ambiguous.size > 0
    assert np.all(np.abs(reg.residual[np.isin(reg.chords, reg.ambiguous)]) > np.pi - reg.margin)


def test_table1_intel_odometric_tree_198_corrections():
    """The seed's Table I: INTEL, odometric spanning tree, 198 chords need a non-zero k."""
    g = read_graph(dataset_path("carlone/INTEL_P_toro.graph"))
    reg = regularize(g, spanning_tree(g, "odometry"))
    assert (g.n_poses, g.n_odometric, g.n_loop_closures) == (1228, 1227, 278)
    assert reg.n_regularized == 198

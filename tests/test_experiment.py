"""The paper's Table II and Fig. 3, substituted on a synthetic world with ground truth (lecture 06, sections 5–6).

Table II scores estimates with the relative-relations metric of Kümmerle et al. (2009): over relations (i, j)
with true relative pose δ*_ij, ε_t = mean ‖trans(δ̂_ij ⊖ δ*_ij)‖² and ε_θ = mean rot(δ̂_ij ⊖ δ*_ij)², with
δ̂_ij = p̂_j ⊖ p̂_i (eq. (1)). Intel's benchmark relations and TORO are not available; the substitute uses the
edges of a synthetic world with their true relative poses and the package's Gauss–Newton and
Levenberg–Marquardt from odometry."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lago_cvx import lago
from lago_cvx.posegraph import between, wrap_angle
from lago_cvx.refinement import odometry_guess, refine
from lago_cvx.synthetic import manhattan_world


def relation_errors(graph, poses, truth):
    """(ε_t [m²], ε_θ [rad²]) over the edges of ``graph`` against the true relative poses."""
    d = between(between(truth[graph.tails], truth[graph.heads]), between(poses[graph.tails], poses[graph.heads]))
    return float(np.mean(np.sum(d[:, :2] ** 2, 1))), float(np.mean(wrap_angle(d[:, 2]) ** 2))


@pytest.fixture(scope="module")
def world():
    return manhattan_world(500, seed=1, sigma_xy=0.05, sigma_theta=0.02)


@pytest.mark.parametrize("scenario", ["diagonal", "identity"])
def test_table2_substitute_lago_as_accurate_as_converged_iterations(world, scenario):
    g = world.graph
    if scenario == "identity":  # the paper's second scenario, P_ij = I₃
        g = replace(g, information=np.broadcast_to(np.eye(3), g.information.shape).copy())
    start = odometry_guess(g)
    converged = refine(g, start, max_iterations=200)
    assert converged.converged
    eps_gn = relation_errors(world.graph, converged.poses, world.truth)
    eps_one = relation_errors(world.graph, refine(g, start, max_iterations=1).poses, world.truth)
    for route in ("seed", "default"):
        eps = relation_errors(world.graph, lago(g, route=route).poses, world.truth)
        assert eps[0] <= 1.05 * eps_gn[0] and eps[1] <= 1.05 * eps_gn[1], (route, eps, eps_gn)
        assert eps_one[0] > 5 * eps[0]  # one iteration from odometry is far worse than LAGO


def test_relation_errors_need_no_alignment(world):
    est = lago(world.graph, route="seed").poses
    moved = est.copy()
    c, s = np.cos(1.3), np.sin(1.3)
    moved[:, :2] = est[:, :2] @ np.array([[c, s], [-s, c]]) + [4.0, -2.0]
    moved[:, 2] += 1.3
    assert np.allclose(relation_errors(world.graph, est, world.truth),
                       relation_errors(world.graph, moved, world.truth), rtol=1e-9)


def test_fig3_iterations_one_at_a_time_and_prefixes(world):
    """Gauss–Newton keeps no state: single steps from where it stopped are the uninterrupted run.
    Levenberg–Marquardt stopped after k trials is the first k trials of the full run."""
    g = world.graph
    start = odometry_guess(g)
    full = refine(g, start)
    poses, chi = start, [full.log[0]["chi2"]]
    for _ in range(len(full.log) - 1):
        r = refine(g, poses, max_iterations=1)
        poses, chi = r.poses, chi + [r.chi2]
    assert np.allclose(chi, [e["chi2"] for e in full.log], rtol=1e-9)
    lm = refine(g, start, method="levenberg-marquardt")
    for k in (1, 2, 3):
        assert np.isclose(refine(g, start, method="levenberg-marquardt", max_iterations=k).chi2,
                          lm.log[k]["chi2"], rtol=1e-12)

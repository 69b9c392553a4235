"""Nonlinear refinement (lago_cvx.refine): Jacobian, convergence from LAGO on real data, local minima
from odometry, LM monotonicity, GN line-search fallback, dead reckoning, trajectory metrics.

Run with ``-s`` to see the per-dataset iteration counts and timings."""

from __future__ import annotations

import logging
import time
from collections import deque
from functools import lru_cache

import numpy as np
import pytest
from scipy.optimize import minimize

from lago_cvx import GraphError, PoseGraph, chi2, compose, lago, read_graph
from lago_cvx.posegraph import between, rot2, wrap_angle
from lago_cvx.metrics import ate, rotation_error
from lago_cvx.refinement import RefineResult, jacobian, odometry_guess, refine, whitened_residuals
from lago_cvx.synthetic import dead_reckoning, manhattan_world, random_graph

from conftest import dataset_path
from lago_cvx.datasets import REFERENCE_CHI2
from helpers import pose_error

#: Reference χ² minima of each file's own cost (lago_cvx.datasets; the files GN is checked on).
REFERENCE_MINIMA = {rel: REFERENCE_CHI2[rel] for rel in (
    "se-sync/MIT.g2o", "carlone/input_M3500a_g2o.g2o", "carlone/input_M3500_g2o.g2o", "carlone/FR079_P_toro.graph",
    "se-sync/intel.g2o", "carlone/INTEL_P_toro.graph", "se-sync/CSAIL.g2o", "se-sync/city10000.g2o",
    "carlone/M3500_P_toro.graph", "carlone/input_INTEL_g2o.g2o")}
#: At most this many Gauss–Newton iterations from LAGO (default route). Measured (g2o's cost): 3–7 on every file
#: but carlone/input_INTEL_g2o.g2o, 32 there: its information spans 11 … 1e8 (I_yy), so from a start already
#: 1.0025× the minimum GN's steps overshoot along the stiff directions and are halved (116 halvings in all);
#: from the seed's LAGO, 7945× the minimum, GN needs 4.
MAX_ITERATIONS_FROM_LAGO = 10
MAX_ITERATIONS_INPUT_INTEL = 40


@lru_cache(maxsize=None)
def _graph(rel):
    return read_graph(dataset_path(rel))


@lru_cache(maxsize=None)
def _lago_poses(rel):
    return lago(_graph(rel)).poses


def _perturbed(truth, seed, scale=(0.3, 0.3, 0.1), keep=0):
    rng = np.random.default_rng(seed)
    x = truth + rng.normal(0.0, scale, truth.shape)
    x[keep] = truth[keep]
    return x


def _monotone(res: RefineResult) -> bool:
    c = np.array([e["chi2"] for e in res.log])
    return bool(np.all(np.diff(c) <= 0.0))


# ------------------------------------------------------------------------------ Jacobian
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("anchor", [None, 5])
def test_jacobian_matches_finite_differences(seed, anchor):
    w = random_graph(12, 25, seed=seed, information="full")
    g = w.graph
    x = _perturbed(w.truth, seed + 10, scale=(0.2, 0.2, 0.05))
    a = 0 if anchor is None else g.index_of(anchor)
    J = jacobian(g, x, anchor=anchor).toarray()
    assert J.shape == (3 * g.n_edges, 3 * (g.n_poses - 1))
    free = [v for v in range(g.n_poses) if v != a]
    h = 1e-6
    fd = np.zeros_like(J)
    for col in range(J.shape[1]):
        v, comp = free[col // 3], col % 3
        xp, xm = x.copy(), x.copy()
        xp[v, comp] += h
        xm[v, comp] -= h
        fd[:, col] = (whitened_residuals(g, xp) - whitened_residuals(g, xm)).reshape(-1) / (2 * h)
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-6 * np.abs(J).max())


def test_whitened_residuals_give_chi2():
    w = random_graph(12, 25, seed=4, information="full")
    x = _perturbed(w.truth, 3)
    r = whitened_residuals(w.graph, x)
    assert r.shape == (25, 3)
    assert np.sum(r**2) == pytest.approx(chi2(w.graph, x), rel=1e-12)
    res = refine(w.graph, x, max_iterations=0)
    assert res.chi2 == pytest.approx(chi2(w.graph, x), rel=1e-12) and res.iterations == 0


# ------------------------------------------------------------------------------ synthetic convergence
@pytest.mark.parametrize("method", ["gauss-newton", "levenberg-marquardt"])
def test_noiseless_world_recovers_truth(method):
    w = manhattan_world(200, seed=1, sigma_xy=0, sigma_theta=0)
    x0 = _perturbed(w.truth, 7)  # anchor (pose 0) keeps its true value
    assert chi2(w.graph, x0) > 1e3
    res = refine(w.graph, x0, method=method)
    assert res.converged, res.reason
    assert pose_error(res.poses, w.truth) < 1e-8
    assert res.chi2 < 1e-12
    np.testing.assert_array_equal(res.poses[0], w.truth[0])


def test_anchor_is_held_fixed_and_can_be_chosen():
    w = random_graph(30, 60, seed=5, sigma_xy=0.05, sigma_theta=0.02)
    g = w.graph
    x0 = _perturbed(w.truth, 1, keep=[])
    r0 = refine(g, x0)
    r7 = refine(g, x0, anchor=int(g.ids[7]))
    np.testing.assert_array_equal(r0.poses[0], x0[0])
    np.testing.assert_array_equal(r7.poses[7], x0[7])
    assert r0.anchor == 0 and r7.anchor == 7
    # same minimum, up to the gauge
    assert r0.chi2 == pytest.approx(r7.chi2, rel=1e-8)


def test_lm_and_gn_agree_on_a_noisy_world():
    w = manhattan_world(300, seed=2)
    x0 = lago(w.graph, anchor_pose=w.truth[0]).poses
    gn = refine(w.graph, x0)
    lm = refine(w.graph, x0, method="levenberg-marquardt")
    assert gn.converged and lm.converged
    assert lm.chi2 == pytest.approx(gn.chi2, rel=1e-8)
    assert gn.chi2 <= gn.chi2_initial


# ------------------------------------------------------------------------------ monotonicity / fallback
@pytest.mark.parametrize("seed", [0, 2, 6, 7])
def test_lm_never_increases_chi2(seed):
    w = random_graph(30, 60, seed=seed, sigma_xy=0.1, sigma_theta=0.1)
    x0 = _perturbed(w.truth, seed, scale=(3.0, 3.0, 1.5))
    res = refine(w.graph, x0, method="levenberg-marquardt", max_iterations=200)
    assert _monotone(res)
    assert res.chi2 <= res.chi2_initial
    assert res.chi2 == pytest.approx(chi2(w.graph, res.poses), rel=1e-10)
    assert any(not e["accepted"] for e in res.log[1:])  # steps do get rejected (and χ² stays put)
    assert all("lambda" in e for e in res.log)
    assert res.iterations == sum(bool(e.get("accepted")) for e in res.log)


def test_gn_backtracking_fallback(caplog):
    w = random_graph(30, 60, seed=2, sigma_xy=0.1, sigma_theta=0.1)
    x0 = _perturbed(w.truth, 2, scale=(3.0, 3.0, 1.5))
    with caplog.at_level(logging.INFO, logger="lago_cvx.refinement"):
        res = refine(w.graph, x0)
    assert sum(e["halvings"] for e in res.log[1:]) > 0  # some full steps increased χ²
    assert any("backtracking" in m for m in caplog.messages)
    assert _monotone(res)
    assert res.converged and res.chi2 < 1e-3 * res.chi2_initial


@pytest.mark.parametrize("seed", range(6))
def test_gn_never_returns_a_larger_chi2(seed):
    w = random_graph(15, 30, seed=seed, sigma_xy=0.1, sigma_theta=0.1)
    rng = np.random.default_rng(seed)
    x0 = np.column_stack([rng.uniform(-10, 10, (15, 2)), rng.uniform(-np.pi, np.pi, 15)])
    res = refine(w.graph, x0, max_iterations=15)
    assert _monotone(res)
    assert res.chi2 <= res.chi2_initial


def test_log_and_result_fields(caplog):
    w = manhattan_world(100, seed=3)
    with caplog.at_level(logging.INFO, logger="lago_cvx.refinement"):
        res = refine(w.graph, lago(w.graph).poses)
    assert isinstance(res, RefineResult)
    assert res.poses.shape == (100, 3)
    assert res.log[0]["iteration"] == 0 and res.log[0]["chi2"] == res.chi2_initial
    assert all({"iteration", "chi2", "step_norm", "time"} <= set(e) for e in res.log)
    assert np.all(np.diff(res.times) >= 0)
    assert res.reason and res.converged
    assert any("GN iteration" in m for m in caplog.messages)


def test_invalid_arguments():
    w = random_graph(5, 6, seed=0)
    with pytest.raises(ValueError, match="method"):
        refine(w.graph, w.truth, method="newton")
    with pytest.raises(ValueError, match="shape"):
        refine(w.graph, w.truth[:3])
    with pytest.raises(ValueError, match="backend"):
        refine(w.graph, w.truth, backend="magic")
    split = PoseGraph(3, [0], [1], [[1.0, 0.0]], [0.1], [np.eye(3)])
    with pytest.raises(GraphError, match="not connected"):
        refine(split, np.zeros((3, 3)))


@pytest.mark.parametrize("method", ["gauss-newton", "levenberg-marquardt"])
def test_tiny_graphs(method):
    one = PoseGraph(1, np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3, 3)))
    res = refine(one, np.ones((1, 3)), method=method)
    assert res.converged and res.chi2 == 0.0
    np.testing.assert_array_equal(odometry_guess(one), np.zeros((1, 3)))
    two = PoseGraph(2, [0], [1], [[1.0, 2.0]], [0.5], [np.diag([4.0, 4.0, 9.0])])
    res = refine(two, np.zeros((2, 3)), method=method)
    assert res.converged and res.chi2 < 1e-20
    np.testing.assert_allclose(res.poses, [[0, 0, 0], [1, 2, 0.5]], atol=1e-12)
    np.testing.assert_allclose(odometry_guess(two), [[0, 0, 0], [1, 2, 0.5]], atol=1e-15)


# ------------------------------------------------------------------------------ dead reckoning
def _sequential_dead_reckoning(graph, tree_edges, anchor):
    """Reference: breadth-first over the tree edges, composing one measurement at a time."""
    n = graph.n_poses
    poses = np.full((n, 3), np.nan)
    poses[anchor] = 0.0
    adj = {v: [] for v in range(n)}
    for k in tree_edges:
        adj[int(graph.tails[k])].append(int(k))
        adj[int(graph.heads[k])].append(int(k))
    queue = deque([anchor])
    while queue:
        v = queue.popleft()
        for k in adj[v]:
            i, j = int(graph.tails[k]), int(graph.heads[k])
            z = graph.measurements[k]
            if v == i and np.isnan(poses[j, 0]):
                poses[j] = compose(poses[i], z)
                queue.append(j)
            elif v == j and np.isnan(poses[i, 0]):
                poses[i] = compose(poses[j], between(z, np.zeros(3)))  # i = j ⊕ (⊖z)
                queue.append(i)
    return poses


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("anchor_index", [0, 17])
def test_odometry_guess_equals_sequential_composition(seed, anchor_index):
    w = random_graph(60, 90, seed=seed, spanning="tree", p_reverse=0.5)
    g = w.graph
    tree = w.params["spanning_edges"]
    assert np.any(g.tails[tree] > g.heads[tree]) and np.any(g.tails[tree] < g.heads[tree])
    got = odometry_guess(g, spanning_tree=tree, anchor=int(g.ids[anchor_index]))
    want = _sequential_dead_reckoning(g, tree, anchor_index)
    np.testing.assert_allclose(got, want, atol=1e-9)
    np.testing.assert_array_equal(got[anchor_index], 0.0)
    # the generator's own dead reckoning (from the true root pose) is the same up to a rigid motion
    init = g.initial
    moved = compose(np.broadcast_to(init[anchor_index], got.shape), got)
    assert pose_error(moved, init) < 1e-8


def test_odometry_guess_on_a_chain_matches_dead_reckoning():
    w = manhattan_world(150, seed=4)
    g = w.graph
    got = odometry_guess(g)
    want = dead_reckoning(np.zeros(3), g.measurements[: g.n_poses - 1])  # edges 0 … n−2 are i → i+1
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_odometry_guess_on_reversed_edges():
    w = manhattan_world(80, seed=5)
    rev = w.graph.reversed_edges(np.arange(0, w.graph.n_edges, 3))
    np.testing.assert_allclose(odometry_guess(rev), odometry_guess(w.graph), atol=1e-9)


# ------------------------------------------------------------------------------ metrics
def test_ate_and_rotation_error():
    rng = np.random.default_rng(0)
    truth = np.column_stack([rng.uniform(-20, 20, (50, 2)), rng.uniform(-3, 3, 50)])
    moved = compose(np.broadcast_to([4.0, -2.0, 0.7], truth.shape), truth)  # rigid motion
    assert ate(moved, truth) < 1e-12 and rotation_error(moved, truth) < 1e-12
    assert ate(moved, truth, align=False) > 1.0
    assert rotation_error(moved, truth, align=False) == pytest.approx(0.7)
    noisy = moved + rng.normal(0, [0.3, 0.3, 0.05], truth.shape)
    raw = noisy - np.column_stack([truth[:, :2], truth[:, 2]])
    assert ate(truth + raw * [1, 1, 0], truth, align=False) == pytest.approx(
        np.sqrt(np.mean(np.sum(raw[:, :2] ** 2, 1))))

    # the closed-form alignment is the optimum over (φ, t)
    def rms(p):
        q = noisy[:, :2] @ rot2(p[0]).T + p[1:]
        return np.sqrt(np.mean(np.sum((q - truth[:, :2]) ** 2, 1)))
    best = minimize(rms, [-0.7, 0.0, 0.0], method="Nelder-Mead",
                    options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 5000}).fun
    assert ate(noisy, truth) == pytest.approx(best, rel=1e-6)
    assert ate(noisy, truth) <= ate(noisy, truth, align=False)
    assert rotation_error(noisy, truth) == pytest.approx(0.05, rel=0.5)


def test_refinement_improves_ate():
    w = manhattan_world(400, seed=6, sigma_xy=0.05, sigma_theta=0.02)
    odo = odometry_guess(w.graph)
    res = refine(w.graph, lago(w.graph).poses)
    assert ate(res.poses, w.truth) < ate(odo, w.truth)
    assert rotation_error(res.poses, w.truth) < 0.05


# ------------------------------------------------------------------------------ real data
@pytest.mark.parametrize("rel", list(REFERENCE_MINIMA))
def test_gauss_newton_from_lago_reaches_reference_minimum(rel):
    g = _graph(rel)
    x0 = _lago_poses(rel)
    t = time.perf_counter()
    res = refine(g, x0)
    elapsed = time.perf_counter() - t
    ref = REFERENCE_MINIMA[rel]
    per_iteration = elapsed / max(len(res.log) - 1, 1)
    print(f"\n{rel}: LAGO χ² {res.chi2_initial:.6g} → GN χ² {res.chi2:.6f} (ref {ref}) in "
          f"{res.iterations} iterations, {elapsed:.3f} s ({per_iteration:.3f} s/iteration); {res.reason}")
    assert res.converged, res.reason
    assert abs(res.chi2 - ref) <= 1e-3 * ref
    assert res.chi2 == pytest.approx(chi2(g, res.poses), rel=1e-10)
    assert res.iterations <= (MAX_ITERATIONS_INPUT_INTEL if rel == "carlone/input_INTEL_g2o.g2o"
                              else MAX_ITERATIONS_FROM_LAGO)


@pytest.mark.parametrize("rel", ["se-sync/MIT.g2o", "carlone/input_INTEL_g2o.g2o"])
def test_levenberg_marquardt_from_lago_real(rel):
    g = _graph(rel)
    res = refine(g, _lago_poses(rel), method="levenberg-marquardt", max_iterations=150)
    print(f"\n{rel}: LM χ² {res.chi2:.6f} in {res.iterations} accepted steps / {len(res.log) - 1} trials")
    assert _monotone(res)
    assert abs(res.chi2 - REFERENCE_MINIMA[rel]) <= 1e-3 * REFERENCE_MINIMA[rel]


@pytest.mark.parametrize("rel, start, factor", [
    ("se-sync/MIT.g2o", "odometry", 10.0),
    ("se-sync/MIT.g2o", "file", 10.0),
    # README 4.2 reports 6673.12 (7.3× the minimum) for plain GN from the file's guess; our
    # monotone GN (backtracking) ends in another local minimum, 7606.17 (8.3×). Neither is > 10×.
    ("carlone/input_M3500a_g2o.g2o", "odometry", 5.0),
])
def test_gauss_newton_from_odometry_stalls_in_local_minimum(rel, start, factor):
    g = _graph(rel)
    x0 = odometry_guess(g) if start == "odometry" else g.initial
    res = refine(g, x0, max_iterations=100)
    print(f"\n{rel} from {start}: χ² {res.chi2_initial:.4g} → {res.chi2:.4f} in {res.iterations} "
          f"iterations ({res.reason}); minimum {REFERENCE_MINIMA[rel]}")
    assert res.converged, res.reason  # a genuine stationary point, not an iteration cap
    assert res.chi2 > factor * REFERENCE_MINIMA[rel]
    # ...while the same solver from LAGO reaches the minimum (test above)


def test_odometry_guess_matches_file_initial_on_mit():
    g = _graph("se-sync/MIT.g2o")
    odo = odometry_guess(g)
    init = g.initial
    moved = compose(np.broadcast_to(init[0], odo.shape), odo)
    # the file's vertices are the dead reckoning of its odometry (up to the printed digits)
    assert np.max(np.abs(moved[:, :2] - init[:, :2])) < 1e-2 * max(1.0, np.abs(init[:, :2]).max())
    assert np.max(np.abs(wrap_angle(moved[:, 2] - init[:, 2]))) < 1e-2

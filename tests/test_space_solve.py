"""3-D LAGO: the chordal relaxation (cvxpy against the closed form, the weights), the positions at fixed
rotations, the routes of ``lago3d`` and ``lago()``'s dispatch, the SE(3) refinement (against GTSAM's LM), the
synthetic worlds, pickling."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from conftest import dataset_path
from lago_cvx import compare_methods, lago
from lago_cvx.errors import GraphError, OptionError
from lago_cvx.io import read_graph
from lago_cvx.posegraph3d import PoseGraph3D, chi2_3d, edge_errors3d
from lago_cvx.so3 import exp_so3
from lago_cvx.space import (Lago3DResult, chordal_closed_form, chordal_cvxpy, chordal_problem, compare_methods3d,
                            lago3d, position_problem, positions_closed_form, positions_cvxpy, refine3d)
from lago_cvx.space.chordal import rotation_weights
from lago_cvx.space.gauss_newton import jacobians, retract
from lago_cvx.synthetic.space import cube_grid_world, sphere_world, torus_world


def _rel(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(a)).max()


def _aligned_truth(world, anchor=0):
    """The truth in the anchor's frame (the estimate holds the anchor at the identity)."""
    R0, t0 = world.R[anchor], world.t[anchor]
    return (world.t - t0) @ R0, R0.T @ world.R


@pytest.fixture(scope="module")
def grid():
    return cube_grid_world(4, seed=7, sigma_t=0.05, sigma_r=0.02)


def _anisotropic(graph: PoseGraph3D, seed=0) -> PoseGraph3D:
    """The graph with random full (correlated, anisotropic) 6×6 information."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(graph.n_edges, 6, 6))
    info = A @ np.swapaxes(A, 1, 2) + np.diag([50, 50, 50, 200, 400, 800.0])
    from dataclasses import replace
    return replace(graph, information=info)


# ------------------------------------------------------------------ chordal relaxation
@pytest.mark.parametrize("weighting", ["isotropic", "anisotropic"])
def test_chordal_cvxpy_matches_closed_form(grid, weighting):
    g = _anisotropic(grid.graph)
    cf = chordal_closed_form(g, weighting=weighting)
    cx = chordal_cvxpy(g, weighting=weighting)
    assert cx.accuracy["status"] == "optimal"
    assert _rel(cf.relaxed, cx.relaxed) < 1e-6
    assert cf.cost == pytest.approx(cx.cost, rel=1e-6)
    assert cf.cost <= cf.cost_projected  # the relaxation's minimum is a lower bound


def test_chordal_problem_prints_like_its_equation(grid):
    problem, X, _ = chordal_problem(grid.graph)
    assert str(problem).splitlines()[0] == "minimize quad_over_lin(W @ (A @ X + -B), 1.0, None, False)"
    assert X.shape == (3 * (grid.graph.n_poses - 1), 3)


@pytest.mark.parametrize("name", ["se-sync-3d/smallGrid3D.g2o", "gtsam/pose3example-grid.txt"])
def test_check_on_datasets(name):
    g = read_graph(dataset_path(name))
    _, report = compare_methods3d(g)
    assert max(report["max_rel_diff"].values()) < 1e-6, report


def test_compare_methods_hands_a_3d_graph_to_compare_methods3d(grid):
    """One door: pipeline.compare_methods on a 3-D graph is compare_methods3d (route and anchor); the planar
    options are refused by name."""
    res, report = compare_methods(grid.graph, route="seed", anchor=3)
    res3, report3 = compare_methods3d(grid.graph, route="seed", anchor=3)
    assert np.array_equal(res.t, res3.t) and report["max_rel_diff"] == report3["max_rel_diff"]
    with pytest.raises(OptionError, match="spanning_tree"):
        compare_methods(grid.graph, spanning_tree="bfs")


def test_weights():
    w = cube_grid_world(3, seed=0)
    S = rotation_weights(w.graph, "isotropic")
    sigma_r = w.params["sigma_r"]
    assert np.allclose(S, np.sqrt(1 / (2 * sigma_r ** 2)) * np.eye(3))  # κ = 3 / (2 tr(σ² I))
    # isotropic information: the two weightings agree
    assert np.allclose(rotation_weights(w.graph, "anisotropic"), S)
    # anisotropic: tr(W) I − W = Ω_rr whenever ½tr(Ω_rr) I − Ω_rr is positive semidefinite
    from dataclasses import replace
    m = w.graph.n_edges
    Q = exp_so3(np.random.default_rng(5).normal(size=(m, 3)))
    lam = np.where(np.arange(m)[:, None] % 2 == 0, [300.0, 400.0, 500.0], [100.0, 100.0, 900.0])
    info = np.zeros((m, 6, 6))
    info[:, :3, :3] = 100 * np.eye(3)
    info[:, 3:, 3:] = Q @ (lam[:, :, None] * np.swapaxes(Q, 1, 2))
    ok = np.arange(m) % 2 == 0
    # the weights take the information in Log coordinates: Ω_rr for GTSAM's cost, ¼Ω_rr for g2o's (q_v ≈ φ/2)
    for cost, scale in (("gtsam", 1.0), ("g2o", 0.25)):
        S = rotation_weights(replace(w.graph, information=info, cost=cost), "anisotropic")
        W = S @ S
        back = np.trace(W, axis1=1, axis2=2)[:, None, None] * np.eye(3) - W
        assert np.allclose(back[ok], scale * info[ok, 3:, 3:])
        assert (np.linalg.eigvalsh(W[~ok]) > 0).all()  # the floor keeps the weights positive definite


def test_noiseless_world_is_recovered_exactly():
    w = sphere_world(4, 8, seed=0, sigma_t=1e-9, sigma_r=1e-9)
    for route in ("seed", "default"):
        res = lago3d(w.graph, route=route)
        t, R = _aligned_truth(w)
        assert np.abs(res.R - R).max() < 1e-6 and np.abs(res.t - t).max() < 1e-6


# ------------------------------------------------------------------ positions
def test_positions_cvxpy_match_closed_form_and_minimize_chi2(grid):
    g = _anisotropic(grid.graph, seed=2)
    R = chordal_closed_form(g).rotations
    tc, _ = positions_closed_form(g, R)
    tx, stats = positions_cvxpy(g, R)
    assert stats["status"] == "optimal" and _rel(tc, tx) < 1e-6
    best = chi2_3d(g, tc, R)
    rng = np.random.default_rng(0)
    for _ in range(5):  # the exact minimizer at these rotations: every move of the free positions costs
        d = rng.normal(size=tc.shape) * 1e-3
        d[0] = 0
        assert chi2_3d(g, tc + d, R) > best
    assert str(position_problem(g, R)[0]).startswith("minimize quad_over_lin(M @ t + -b, 1.0")


# ------------------------------------------------------------------ routes
@pytest.mark.parametrize("make", [lambda: sphere_world(6, 12, seed=1), lambda: torus_world(6, 12, seed=2),
                                  lambda: cube_grid_world(4, seed=3)], ids=["sphere", "torus", "grid"])
def test_routes_on_noisy_worlds(make):
    w = make()
    g = w.graph
    seed = lago3d(g, route="seed")
    default = lago3d(g)
    assert default.chi2 <= seed.chi2 == default.chi2_seed
    # at the maximum-likelihood level: below χ² at the truth (about 6m), above the refined minimum
    truth = chi2_3d(g, w.t, w.R)
    ref = refine3d(g, default.t, default.R)
    assert ref.chi2 <= default.chi2 < truth
    assert default.chi2 <= 1.05 * ref.chi2
    t, R = _aligned_truth(w)
    err = np.linalg.norm(default.t - t, axis=1).max()
    err_ml = np.linalg.norm(ref.t - t, axis=1).max()
    assert err <= 1.5 * err_ml + 1e-9  # as close to the truth as the optimum is, to noise level


def test_lago_dispatches_on_dim_and_results_pickle(grid):
    res = lago(grid.graph, route="seed")
    assert isinstance(res, Lago3DResult) and res.dim == 3 and res.route == "seed" and res.alpha is None
    back = pickle.loads(pickle.dumps(res))
    assert np.array_equal(back.R, res.R) and back.chi2 == res.chi2 and back.timings == res.timings
    ref = refine3d(grid.graph, res.t, res.R, max_iterations=3)
    assert pickle.loads(pickle.dumps(ref)).chi2 == ref.chi2
    with pytest.raises(OptionError, match="planar graphs only"):
        lago(grid.graph, regularization="tree")


def test_anchor_and_disconnected_graph(grid):
    g = grid.graph
    res = lago3d(g, anchor=int(g.ids[5]))
    assert res.anchor_index == 5 and np.allclose(res.R[5], np.eye(3)) and np.allclose(res.t[5], 0)
    assert res.chi2 == pytest.approx(lago3d(g).chi2, rel=1e-6)  # the gauge does not change χ²
    cut = g.subgraph_edges(~((g.tails < 3) ^ (g.heads < 3)))
    with pytest.raises(GraphError, match="not connected"):
        lago3d(cut)


# ------------------------------------------------------------------ refinement
def test_jacobians_against_finite_differences(grid):
    g = _anisotropic(grid.graph)
    res = lago3d(g, route="seed")
    t, R = res.t, res.R
    e, Ji, Jj = jacobians(g, t, R)
    n, h = g.n_poses, 1e-6
    k = 3  # an edge; its tail and head
    i, j = g.tails[k], g.heads[k]
    for pose, J in ((i, Ji[k]), (j, Jj[k])):
        num = np.empty((6, 6))
        for c in range(6):
            d = np.zeros((n, 6))
            d[pose, c] = h
            out = []
            for s in (1, -1):
                t2, R2 = retract(t, R, (s * d)[1:].ravel(), 0) if pose else (t + s * R[0] @ d[0, :3] * 0, R)
                out.append(edge_errors3d(g, t2, R2)[k])
            num[:, c] = (out[0] - out[1]) / (2 * h)
        if pose:
            assert np.abs(num - J).max() < 1e-5 * max(1.0, np.abs(J).max())


def test_refinement_reaches_gtsam_lm():
    gtsam = pytest.importorskip("gtsam")
    for name in ["gtsam/pose3example-grid.txt", "gtsam/pose3example.txt", "se-sync-3d/tinyGrid3D.g2o"]:
        p = str(dataset_path(name))
        g = read_graph(p, cost="gtsam")  # GTSAM's LM minimizes its own cost
        res = lago3d(g)
        ref = refine3d(g, res.t, res.R)
        graph, initial = gtsam.readG2o(p, True)
        fg = gtsam.NonlinearFactorGraph(graph)
        fg.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(), gtsam.noiseModel.Diagonal.Variances(np.full(6, 1e-8))))
        params = gtsam.LevenbergMarquardtParams()
        params.setRelativeErrorTol(1e-12)
        params.setAbsoluteErrorTol(1e-14)
        est = gtsam.LevenbergMarquardtOptimizer(fg, gtsam.InitializePose3.initialize(fg), params).optimize()
        lm = 2 * graph.error(est)
        assert ref.converged and ref.chi2 <= lm * (1 + 1e-6), (name, ref.chi2, lm)
        assert res.chi2 <= 2 * graph.error(gtsam.InitializePose3.initialize(fg)) * (1 + 1e-9), name


def test_offdiagonal_example_is_solved_and_refined():
    g = read_graph(dataset_path("gtsam/pose3example-offdiagonal.txt"))
    res = lago3d(g)
    ref = refine3d(g, res.t, res.R)
    assert res.chi2 < 1e-12 and ref.chi2 < 1e-12  # two poses, one edge: it is satisfied exactly
    assert np.allclose(exp_so3(np.zeros(3)), res.R[0])


# ------------------------------------------------------------------ certificate
def test_certificate_on_a_world_and_on_a_bad_point():
    from lago_cvx.space.certify import certify3d, sesync_cost3d
    w = torus_world(5, 10, seed=4)
    g = w.graph
    res = lago3d(g)
    cert = certify3d(g, res.t, res.R)
    assert cert.certified and cert.n_negative == 0, cert.verdict
    assert cert.lower_bound <= cert.cost and cert.relative_suboptimality_bound <= cert.tol
    assert cert.cost <= sesync_cost3d(g, res.t, res.R)  # the local solver only descends
    assert cert.cost == pytest.approx(cert.dual_value, rel=1e-9)  # a critical point: f = Σ tr Λ_i
    # far from any critical point (rotations scrambled, no local solver): never certified, bound still valid
    R = exp_so3(np.random.default_rng(0).normal(size=(g.n_poses, 3)))
    bad = certify3d(g, res.t, R, local=False)
    assert not bad.certified and bad.lower_bound <= cert.cost * (1 + 1e-9)


def test_certificate_on_small_grid():
    from lago_cvx.space.certify import certify3d
    g = read_graph(dataset_path("se-sync-3d/smallGrid3D.g2o"))
    res = lago3d(g)
    cert = certify3d(g, res.t, res.R)
    assert cert.certified, cert.verdict


def test_pose_covariances_against_dense_inverse(grid):
    from lago_cvx.space import pose_covariances3d
    from lago_cvx.space.gauss_newton import normal_equations, whitening
    g = _anisotropic(grid.graph, seed=3)
    res = lago3d(g)
    ref = refine3d(g, res.t, res.R)
    cov = pose_covariances3d(g, ref.t, ref.R)
    N, _, _ = normal_equations(g, ref.t, ref.R, whitening(g), 0)
    dense = np.linalg.inv(N.toarray())
    want = np.stack([dense[6 * k:6 * k + 6, 6 * k:6 * k + 6] for k in range(g.n_poses - 1)])
    assert np.abs(cov[0]).max() == 0.0
    assert np.allclose(cov[1:], want, rtol=1e-8, atol=1e-12 * np.abs(want).max())
    assert (np.linalg.eigvalsh(cov[1:]) > 0).all()


def test_fixed_poses():
    w = sphere_world(4, 8, seed=5, sigma_t=1e-9, sigma_r=1e-9)
    g = w.graph
    fixed = {0: (w.t[0], w.R[0]), 17: (w.t[17], w.R[17])}
    for route in ("seed", "default"):
        res = lago3d(g, route=route, fixed=fixed)  # noiseless: the truth, in the known poses' frame
        assert np.abs(res.R - w.R).max() < 1e-6 and np.abs(res.t - w.t).max() < 1e-6
    noisy = sphere_world(4, 8, seed=5)
    one = {0: (np.zeros(3), np.eye(3))}
    a, b = lago3d(noisy.graph, fixed=one), lago3d(noisy.graph)  # the anchor alone: the plain route
    assert a.chi2 == pytest.approx(b.chi2, rel=1e-9) and np.allclose(a.t, b.t, atol=1e-9)
    two = {0: (noisy.t[0], noisy.R[0]), 17: (noisy.t[17], noisy.R[17])}
    c = lago3d(noisy.graph, fixed=two)
    assert np.array_equal(c.t[17], noisy.t[17]) and c.chi2 <= c.chi2_seed
    assert c.chi2 >= refine3d(noisy.graph, a.t, a.R).chi2 * (1 - 1e-9)  # a constrained point: not below the minimum
    with pytest.raises(OptionError, match="not a rotation"):
        lago3d(noisy.graph, fixed={0: (np.zeros(3), 2 * np.eye(3))})


@pytest.mark.parametrize("route", ["seed", "default"])
def test_c_kernels_agree_with_the_numpy_fallback(route):
    """Every system of the route factored by the C kernels against the NumPy engine (their fallback without a
    compiler): the same estimate to rounding, and each engine used."""
    from lago_cvx.sparse import compiled

    w = torus_world(6, 12, seed=2)
    got = lago3d(w.graph, route=route)
    saved = list(compiled._C_KERNELS)
    compiled._C_KERNELS[:] = [None]
    try:
        ref = lago3d(w.graph, route=route)
    finally:
        compiled._C_KERNELS[:] = saved
    assert got.chi2 == pytest.approx(ref.chi2, rel=1e-10)
    assert got.chi2_seed == pytest.approx(ref.chi2_seed, rel=1e-10)
    assert _rel(ref.R, got.R) < 1e-8 and _rel(ref.t, got.t) < 1e-8

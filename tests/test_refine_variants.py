"""``refine`` with anchors, priors (full and position-only) and convex constraints, and the covariances of the
refined problem, checked against an independent optimizer and finite differences written here."""

from __future__ import annotations

import logging
from functools import lru_cache

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import least_squares

from lago_cvx import OptionError, lago, read_graph
from lago_cvx.refinement import refine
from lago_cvx.variants import constrained_lago, halfplane_constraint, orientation_bounds

from conftest import dataset_path

MIT = "se-sync/MIT.g2o"


@lru_cache(maxsize=None)
def _setup():
    """MIT, its unconstrained refined poses, two anchors and five position-only priors off the optimum."""
    g = read_graph(dataset_path(MIT))
    start = lago(g).poses
    free = refine(g, start)
    P = free.poses
    ids = g.ids
    anchors = {int(ids[0]): tuple(P[0]), int(ids[400]): tuple(P[400] + [0.3, -0.2, 0.02])}
    rng = np.random.default_rng(4)
    priors = {}
    for i in (60, 220, 330, 610, 780):
        A = rng.normal(size=(2, 2))
        priors[int(ids[i])] = ((P[i, 0] + rng.normal(0, 0.5), P[i, 1] + rng.normal(0, 0.5), None),
                               A @ A.T + 2.0 * np.eye(2))
    return g, start, free, anchors, priors


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _residuals(g, priors, poses):
    """Eq. (3) errors whitened by chol(Ω) (the graph's information, g2o's χ²), then the prior residuals."""
    pi, pj = poses[g.tails], poses[g.heads]
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    d = pj[:, :2] - pi[:, :2]
    e = np.column_stack([c * d[:, 0] + s * d[:, 1] - g.delta_l[:, 0], -s * d[:, 0] + c * d[:, 1] - g.delta_l[:, 1],
                         _wrap(pj[:, 2] - pi[:, 2] - g.delta)])
    L = np.linalg.cholesky(g.information)  # Ω = L Lᵀ: eᵀΩe = ‖Lᵀe‖²
    out = [np.einsum("kba,kb->ka", L, e).reshape(-1)]
    for pid, (mean, info) in priors.items():
        v = g.index_of(pid)
        Lq = np.linalg.cholesky(np.asarray(info, float))
        out.append(Lq.T @ (poses[v, :2] - np.asarray(mean[:2], float)))
    return np.concatenate(out)


def _free_mask(g, anchors):
    held = np.zeros((g.n_poses, 3), bool)
    for pid in anchors:
        held[g.index_of(pid)] = True
    return ~held.reshape(-1)


def _sparsity(g, anchors, priors):
    """Which free coordinate each residual row depends on, for the finite differences."""
    n, m = g.n_poses, g.n_edges
    rows, cols = [], []
    for k, (i, j) in enumerate(zip(g.tails, g.heads)):
        for a in range(3):
            rows += [3 * m * 0 + 3 * k + a] * 6
            cols += [3 * i, 3 * i + 1, 3 * i + 2, 3 * j, 3 * j + 1, 3 * j + 2]
    r = 3 * m
    for pid in priors:
        v = g.index_of(pid)
        for a in range(2):
            rows += [r + a] * 2
            cols += [3 * v, 3 * v + 1]
        r += 2
    S = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(r, 3 * n))
    return S[:, _free_mask(g, anchors)]


def test_anchors_and_gps_priors_reach_the_minimum_of_an_independent_optimizer():
    g, start, _, anchors, priors = _setup()
    res = refine(g, start, anchors=anchors, priors=priors)
    assert res.converged, res.reason
    for pid, val in anchors.items():  # anchors exact
        v = g.index_of(pid)
        assert res.poses[v, :2].tolist() == list(val[:2])
        assert abs(_wrap(res.poses[v, 2] - val[2])) == 0.0
    own = float(_residuals(g, priors, res.poses) @ _residuals(g, priors, res.poses))
    assert own == pytest.approx(res.chi2, rel=1e-12)
    mask = _free_mask(g, anchors)

    def fun(z):
        x = res.poses.reshape(-1).copy()
        x[mask] = z
        return _residuals(g, priors, x.reshape(-1, 3))

    sol = least_squares(fun, res.poses.reshape(-1)[mask], jac_sparsity=_sparsity(g, anchors, priors),
                        method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=50)
    best = 2 * sol.cost
    assert best >= res.chi2 * (1 - 1e-7), (best, res.chi2)
    # the priors pulled: the refined cost is above the unconstrained minimum, and the priors' own terms count
    assert res.chi2 > _setup()[2].chi2


def test_pose_covariances_are_the_inverse_gauss_newton_hessian():
    g, start, _, anchors, priors = _setup()
    res = refine(g, start, anchors=anchors, priors=priors)
    cov = res.pose_covariances()
    mask = _free_mask(g, anchors)
    x0 = res.poses.reshape(-1)
    r0 = _residuals(g, priors, res.poses)
    cols = np.flatnonzero(mask)
    J = np.empty((r0.size, cols.size))
    h = 1e-6
    for c, k in enumerate(cols):  # central differences, one coordinate at a time
        xp, xm = x0.copy(), x0.copy()
        xp[k] += h
        xm[k] -= h
        J[:, c] = (_residuals(g, priors, xp.reshape(-1, 3)) - _residuals(g, priors, xm.reshape(-1, 3))) / (2 * h)
    Sigma = np.linalg.inv(J.T @ J)
    full = np.zeros((x0.size, x0.size))
    full[np.ix_(cols, cols)] = Sigma
    blocks = np.stack([full[3 * v:3 * v + 3, 3 * v:3 * v + 3] for v in range(g.n_poses)])
    scale = np.abs(blocks).max()
    assert np.abs(cov - blocks).max() <= 1e-4 * scale
    for pid in anchors:  # held: zero
        assert not cov[g.index_of(pid)].any()
    assert (np.linalg.eigvalsh(cov[250]) > 0).all()


def test_position_only_prior_alone_fixes_the_translation():
    g, start, free, _, _ = _setup()
    P = free.poses
    pri = {int(g.ids[100]): ((P[100, 0] + 2.0, P[100, 1] - 1.0, None), 1e6 * np.eye(2))}
    res = refine(g, start, priors=pri)
    assert res.held.sum() == 1 and res.held[:, 2].sum() == 1  # the rotation still held at the reference
    assert np.allclose(res.poses[100, :2], P[100, :2] + [2.0, -1.0], atol=1e-4)
    assert res.chi2 == pytest.approx(free.chi2 + 0.0, rel=1e-6, abs=1e-3)


def test_bad_prior_names_the_fix():
    g, start, *_ = _setup()
    with pytest.raises(OptionError, match=r"prior .*not positive definite; for a position-only"):
        refine(g, start, priors={int(g.ids[3]): ((0.0, 0.0, 0.0), np.diag([1.0, 1.0, 0.0]))})


def _wall(g, P):
    """A wall x ≤ c through the middle of the data, on poses 300 … 499."""
    c = float(np.median(P[300:500, 0]))
    ids = g.ids[300:500]
    return c, ids, (lambda pv: [halfplane_constraint(pv, [[1.0, 0.0]], [c], poses=ids, name="wall")])


def test_a_wall_stays_feasible_through_refine():
    g, start, free, _, _ = _setup()
    c, ids, fn = _wall(g, free.poses)
    clago = constrained_lago(g, fn)
    assert clago.poses[300:500, 0].max() <= c + 1e-6
    res = refine(g, clago.poses, constraints=fn)
    assert res.converged, res.reason
    assert res.constraint_names == ["wall"]
    assert res.poses[300:500, 0].max() <= c + 1e-6
    assert free.chi2 < res.chi2 < clago.chi2, (free.chi2, res.chi2, clago.chi2)
    # the wall is active: the unconstrained optimum crosses it
    assert free.poses[300:500, 0].max() > c + 0.1


def test_a_heading_bound_stays_satisfied_after_refine():
    g, start, free, _, _ = _setup()
    v = 150
    target = free.poses[v, 2] + np.deg2rad(20.0)  # a compass says 20° more, within ±5°
    bound = np.deg2rad(5.0)

    def fn(pv):
        return orientation_bounds(pv, poses=[g.ids[v]], lower=-bound, upper=bound, center=target)

    clago = constrained_lago(g, fn)
    res = refine(g, clago.poses, constraints=fn)
    dev = _wrap(res.poses[v, 2] - target)
    assert abs(dev) <= bound + 1e-6
    assert abs(dev) == pytest.approx(bound, abs=1e-4)  # active
    assert res.chi2 > free.chi2
    plain = refine(g, clago.poses)  # what the constraint-blind refinement does: it undoes the bound
    assert abs(_wrap(plain.poses[v, 2] - target)) > bound + 0.1


def test_bare_cvxpy_constraints_and_bad_returns():
    g, start, free, _, _ = _setup()
    c = float(np.median(free.poses[300:500, 0]))
    res = refine(g, free.poses, constraints=lambda pv: pv.x[300:500] <= c, max_iterations=3)
    assert res.poses[300:500, 0].max() <= c + 1e-6
    assert res.constraint_names == ["constraint 0"]
    with pytest.raises(OptionError, match="returned bool"):
        refine(g, free.poses, constraints=lambda pv: True, max_iterations=1)
    with pytest.raises(OptionError, match="Gauss-Newton"):
        refine(g, free.poses, constraints=lambda pv: [], method="levenberg-marquardt")


def test_constraint_functions_see_positions_in_phase_one():
    """A constraint on pv.x in a raw lambda works (deferred to phase 3), no TypeError in phase 1."""
    g, start, free, _, _ = _setup()
    c = float(np.median(free.poses[300:500, 0]))
    res = constrained_lago(g, lambda pv: pv.x[300:500] <= c)
    assert res.poses[300:500, 0].max() <= c + 1e-6


def test_unwrapped_orientation_bounds_warn(caplog):
    g, *_ = _setup()
    with caplog.at_level(logging.WARNING, logger="lago_cvx.variants"):
        constrained_lago(g, lambda pv: orientation_bounds(pv, poses=[g.ids[5]], lower=-3.0, upper=3.0))
    assert any("without center=" in r.message for r in caplog.records)


def test_priors_and_plain_refine_load_no_cvxpy():
    """The unconstrained path stays as it was: no cvxpy (and, without priors, not even this module)."""
    import subprocess
    import sys

    code = ("import sys, numpy as np, lago_cvx as lc; w = lc.manhattan_world(60, seed=2); g = w.graph; "
            "r = lc.refine(g, lc.lago(g).poses); a = 'lago_cvx.refine_variants' in sys.modules; "
            "p = lc.refine(g, r.poses, priors={5: ((1.0, 2.0, None), np.eye(2))}); p.pose_covariances(); "
            "print(a, 'cvxpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


def test_lago_accepts_position_only_and_theta_only_priors():
    g, _, free, _, _ = _setup()
    P = free.poses
    gps = {int(g.ids[i]): ((P[i, 0] + 1.0, P[i, 1], None), 1e4 * np.eye(2)) for i in (100, 500)}
    res = lago(g, priors=gps)
    assert res.frame["position"] == "priors" and res.frame["orientation"].startswith("procrustes")
    moved = res.poses[[100, 500], :2] - P[[100, 500], :2]
    assert np.allclose(moved, [[1.0, 0.0], [1.0, 0.0]], atol=0.05)  # the data agree with a pure shift
    th = lago(g, priors={int(g.ids[100]): ((None, None, P[100, 2] + 0.5), 1e8)})
    assert abs(_wrap(th.poses[100, 2] - P[100, 2] - 0.5)) < 1e-3


def test_a_wall_far_from_the_data_is_said(caplog):
    """Phase 3 moving θ far (> 0.3 rad) from phase 1 means the constraints fight the data: a warning."""
    g, _, free, _, _ = _setup()
    c = float(free.poses[300:500, 0].min()) - 15.0  # every one of these poses 15 m beyond where the data put them
    with caplog.at_level(logging.WARNING, logger="lago_cvx.variants"):
        res = constrained_lago(g, lambda pv: halfplane_constraint(pv, [[1.0, 0.0]], [c], poses=g.ids[300:500]))
    moved = np.abs(res.poses[:, 2] - res.phase1.theta).max()
    said = any("phase 3 moved θ" in r.message for r in caplog.records)
    assert said == (moved > 0.3), moved
    assert said


def test_full_and_theta_priors_reach_the_minimum_on_a_small_world():
    """Full 3×3 and θ-only priors (no anchors: they fix the gauge): an independent optimizer on the same cost
    (eq. (3) plus eᵀΛe, θ wrapped) finds nothing lower, and ``chi2`` is that cost."""
    from lago_cvx import manhattan_world

    w = manhattan_world(80, seed=3)
    g = w.graph
    A = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, -0.2], [0.5, -0.2, 2.0]])
    priors = {10: (w.truth[10] + [0.3, -0.2, 0.1], A), 40: ((None, None, w.truth[40, 2] + 6.3), 50.0)}
    res = refine(g, lago(g).poses, priors=priors)
    assert res.converged and not res.held.any()

    def fun(z):
        x = z.reshape(-1, 3)
        pi, pj = x[g.tails], x[g.heads]
        c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        d = pj[:, :2] - pi[:, :2]
        e = np.column_stack([c * d[:, 0] + s * d[:, 1] - g.delta_l[:, 0], -s * d[:, 0] + c * d[:, 1] - g.delta_l[:, 1],
                             _wrap(pj[:, 2] - pi[:, 2] - g.delta)])
        L = np.linalg.cholesky(g.information)
        e10 = x[10] - priors[10][0]
        e10[2] = _wrap(e10[2])
        return np.concatenate([np.einsum("kba,kb->ka", L, e).reshape(-1), np.linalg.cholesky(A).T @ e10,
                               [np.sqrt(50.0) * _wrap(x[40, 2] - priors[40][0][2])]])

    r0 = fun(res.poses.reshape(-1))
    assert float(r0 @ r0) == pytest.approx(res.chi2, rel=1e-12)
    sol = least_squares(fun, res.poses.reshape(-1), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert 2 * sol.cost >= res.chi2 * (1 - 1e-9)
    cov = res.pose_covariances()
    assert np.all(np.linalg.eigvalsh(cov) > 0)  # every pose free, the priors fix the gauge

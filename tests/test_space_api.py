"""2-D and 3-D as one API: ``refine`` on either dimension with the same keywords and defaults, 3-D anchors, priors
and rotation constraints through ``lago`` and ``refine``, the covariances of the refined problem against a
finite-difference Jacobian written here, ``ate`` / ``rpe`` of either dimension, ``certify3d`` by id."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx import conventions
from lago_cvx.errors import OptionError
from lago_cvx.posegraph3d import edge_errors3d
from lago_cvx.so3 import exp_so3, log_so3
from lago_cvx.space import gravity_aligned, lago3d, pose_covariances3d, refine3d
from lago_cvx.space.certify import certify3d
from lago_cvx.space.variants import Variant3D, chordal_constrained
from lago_cvx.so3 import project_so3

from conftest import dataset_path


@pytest.fixture(scope="module")
def cube():
    return lc.cube_grid_world(4, seed=3)


@pytest.fixture(scope="module")
def small_grid():
    return lc.read_graph(dataset_path("se-sync-3d/smallGrid3D.g2o"))


# ------------------------------------------------------------------ one refine
def test_refine_has_the_same_defaults_in_both_dimensions():
    planar = inspect.signature(lc.refine).parameters
    space = inspect.signature(refine3d).parameters
    for name, value in (("method", conventions.REFINE_METHOD), ("max_iterations", conventions.REFINE_MAX_ITERATIONS),
                        ("tolerance", conventions.REFINE_TOLERANCE)):
        assert planar[name].default == space[name].default == value


def test_refine_takes_a_3d_result_or_pair_and_matches_refine3d(cube):
    g = cube.graph
    res = lc.lago(g)
    a = lc.refine(g, res)
    b = lc.refine(g, (res.t, res.R))
    c = refine3d(g, res.t, res.R)
    assert a.converged and a.chi2 == b.chi2 == c.chi2 and np.array_equal(a.t, c.t)
    assert a.chi2 < res.chi2 and a.chi2_initial == pytest.approx(res.chi2, rel=1e-12) and a.dim == 3
    assert a.poses[0] is a.t and a.iterations >= 1 and a.reason
    with pytest.raises(OptionError, match="3-D estimate"):
        lc.refine(g, res.t)
    with pytest.raises(OptionError, match="planar"):
        lc.refine(g, res, backend="qdldl")


def test_planar_refine_takes_a_result_and_is_unchanged():
    w = lc.manhattan_world(120, seed=4)
    res = lc.lago(w.graph)
    a, b = lc.refine(w.graph, res), lc.refine(w.graph, res.poses)
    assert a.chi2 == b.chi2 and np.array_equal(a.poses, b.poses) and a.method == "gauss-newton"


# ------------------------------------------------------------------ anchors
def _two_anchors(g, t, R, first: int, second: int) -> dict:
    return {int(g.ids[first]): (t[first], R[first]), int(g.ids[second]): (t[second], R[second])}


def _check_anchors_hold(g, anchors, start):
    runs = [lc.lago(g, anchors=anchors, method=method) for method in ("cvxpy", "closed_form")]
    assert runs[0].chi2 == pytest.approx(runs[1].chi2, rel=1e-6)  # cvxpy and the closed form: one problem
    for res in runs:
        for pid, (t, R) in anchors.items():
            i = g.index_of(pid)
            assert np.array_equal(res.t[i], t) and np.array_equal(res.R[i], R)
    ref = lc.refine(g, res, anchors=anchors)
    assert ref.converged
    for pid, (t, R) in anchors.items():
        i = g.index_of(pid)
        assert np.array_equal(ref.t[i], t) and np.array_equal(ref.R[i], R) and ref.held[i].all()
    free = lc.refine(g, start)
    assert ref.chi2 >= free.chi2 * (1 - 1e-9)  # a second anchor can only cost
    return res, ref


def test_two_anchors_hold_exactly_through_lago_and_refine_synthetic(cube):
    g = cube.graph
    anchors = _two_anchors(g, cube.t, cube.R, 0, 40)
    res, ref = _check_anchors_hold(g, anchors, lc.lago(g))
    # the old spelling: fixed= in lago3d, then refine with the same anchors (it drifted 0.3 m without them)
    old = lago3d(g, fixed=anchors)
    assert old.chi2 == pytest.approx(res.chi2, rel=1e-9)
    cov = ref.pose_covariances()
    assert cov.shape == (g.n_poses, 6, 6) and not cov[0].any() and not cov[40].any()
    assert np.linalg.eigvalsh(cov[20]).min() > 0


def test_two_anchors_hold_exactly_on_small_grid(small_grid):
    g = small_grid
    best = lc.refine(g, lc.lago(g))
    anchors = _two_anchors(g, best.t + 0.05, exp_so3(np.full((g.n_poses, 3), 0.02)) @ best.R, 0, 124)
    _, ref = _check_anchors_hold(g, anchors, best)
    assert ref.chi2 > best.chi2 * (1 + 1e-6)  # the anchors moved off the optimum: they are active
    assert np.linalg.eigvalsh(ref.pose_covariances()[60]).min() > 0


def test_partial_anchor_holds_what_it_gives(cube):
    g = cube.graph
    t0 = cube.t[10] + np.array([0.3, 0.0, 0.0])
    ref = lc.refine(g, lc.lago(g), anchors={int(g.ids[10]): (t0, None)})
    assert np.array_equal(ref.t[10], t0) and ref.held[10, :3].all() and not ref.held[10, 3:].any()
    with pytest.raises(OptionError, match="anchor 10"):
        lc.refine(g, lc.lago(g), anchors={10: (None, None)})


# ------------------------------------------------------------------ covariances against finite differences
def _residuals(g, t, R, priors):
    """Whitened residuals: edges L e (LᵀL = Ω) and priors U e_q, written here from the errors."""
    L = np.swapaxes(np.linalg.cholesky(g.information), 1, 2)
    out = [np.einsum("kij,kj->ki", L, edge_errors3d(g, t, R)).ravel()]
    for pid, (tb, Rb, info) in priors.items():
        i = g.index_of(pid)
        e = np.concatenate(([t[i] - tb] if tb is not None else []) + ([log_so3(Rb.T @ R[i])] if Rb is not None else []))
        out.append(np.linalg.cholesky(info).T @ e)
    return np.concatenate(out)


def _fd_covariances(g, t, R, free, priors, h=1e-6):
    """Blocks of (JᵀJ)⁻¹ over the tangent coordinates ``free`` (list of (pose, coordinate)), J by central
    differences with the right retraction R Exp(δφ), t + R δv."""
    J = []
    for i, c in free:
        cols = []
        for s in (h, -h):
            t2, R2 = t.copy(), R.copy()
            if c < 3:
                t2[i] = t[i] + R[i][:, c] * s
            else:
                w = np.zeros(3)
                w[c - 3] = s
                R2[i] = R[i] @ exp_so3(w[None])[0]
            cols.append(_residuals(g, t2, R2, priors))
        J.append((cols[0] - cols[1]) / (2 * h))
    J = np.array(J).T
    S = np.linalg.inv(J.T @ J)
    out = np.zeros((g.n_poses, 6, 6))
    for a, (i, c) in enumerate(free):
        for b, (k, d) in enumerate(free):
            if i == k:
                out[i, c, d] = S[a, b]
    return out


@pytest.mark.parametrize("case", ["two anchors", "priors"])
def test_covariances_after_refinement_are_the_inverse_hessian(case):
    w = lc.cube_grid_world(3, seed=5)
    g = w.graph
    if case == "two anchors":
        anchors, priors = _two_anchors(g, w.t, w.R, 0, 13), {}
    else:  # three position-only (GPS) priors and one rotation-only prior fix the frame; nothing is held
        anchors = {}
        priors = {int(g.ids[v]): (w.t[v], None, np.eye(3) / 0.1 ** 2) for v in (0, 8, 20)}
        priors[int(g.ids[26])] = (None, w.R[26], np.diag([400.0, 900.0, 2500.0]))
    ref = lc.refine(g, lc.lago(g), anchors=anchors or None, priors=priors or None)
    assert ref.converged
    chi = _residuals(g, ref.t, ref.R, priors)
    assert float(chi @ chi) == pytest.approx(ref.chi2, rel=1e-12)  # the cost refined is the one written here
    free = [(i, c) for i in range(g.n_poses) for c in range(6) if not ref.held[i, c]]
    assert len(free) == 6 * (g.n_poses - (2 if anchors else 0))
    expected = _fd_covariances(g, ref.t, ref.R, free, priors)
    got = ref.pose_covariances()
    assert np.abs(got - expected).max() <= 1e-4 * np.abs(expected).max()


def test_lago_result_covariances_are_the_functions(cube):
    res = lc.lago(cube.graph)
    assert np.allclose(res.pose_covariances(), pose_covariances3d(cube.graph, res.t, res.R), rtol=1e-10, atol=0)
    anchored = lc.lago(cube.graph, anchors=_two_anchors(cube.graph, cube.t, cube.R, 0, 40))
    cov = anchored.pose_covariances()
    assert not cov[40].any() and np.linalg.eigvalsh(cov[7]).min() > 0


# ------------------------------------------------------------------ rotation constraints
@pytest.fixture(scope="module")
def upright():
    """Gravity-aligned truth (rotations about z only), noisy rotations: the unconstrained estimate tilts."""
    return lc.cube_grid_world(4, seed=2, yaw_only=True, sigma_r=0.05)


def test_rotation_constraint_is_kept_through_the_projection(upright):
    g = upright.graph
    rc = gravity_aligned(g.ids)
    var = Variant3D(g, rotation_constraints=rc)
    R_cf, relaxed_cf = chordal_constrained(g, var)
    R_cx, relaxed_cx = chordal_constrained(g, var, method="cvxpy")
    assert np.abs(relaxed_cf - relaxed_cx).max() < 1e-6  # cvxpy and the closed form: one problem
    # the relaxation satisfies R e3 = e3 (a linear constraint) ...
    assert np.abs(relaxed_cf[:, :, 2] - [0, 0, 1]).max() < 1e-9
    # ... the SVD projection onto SO(3) breaks it, the constrained projection (PC) keeps it
    assert np.abs(project_so3(relaxed_cf)[:, :, 2] - [0, 0, 1]).max() > 1e-3
    assert np.abs(R_cf[:, :, 2] - [0, 0, 1]).max() < 1e-12 and np.abs(R_cx[:, :, 2] - [0, 0, 1]).max() < 1e-12
    assert np.allclose(R_cf @ np.swapaxes(R_cf, 1, 2), np.eye(3), atol=1e-12)


def test_rotation_constraint_active_and_satisfied_through_lago_and_refine(upright):
    g = upright.graph
    rc = gravity_aligned(g.ids)
    free_lago = lc.lago(g)
    tilt = np.degrees(np.arccos(np.clip(free_lago.R[:, 2, 2], -1, 1))).max()
    assert tilt > 0.5  # the unconstrained estimate is not gravity-aligned
    res = lc.lago(g, rotation_constraints=rc)
    cx = lc.lago(g, rotation_constraints=rc, method="cvxpy")
    assert cx.chi2 == pytest.approx(res.chi2, rel=1e-6)
    ref = lc.refine(g, res, constraints=rc)
    free = lc.refine(g, free_lago)
    for out in (res, cx, ref):
        assert np.abs(out.R[:, :, 2] - [0, 0, 1]).max() < 1e-9  # satisfied to the solver's tolerance
    assert ref.converged and free.chi2 < ref.chi2 <= res.chi2  # active: it costs
    cov = ref.pose_covariances()
    assert not cov[:, 3:5].any() and (cov[1:, 5, 5] > 0).all()  # only yaw is uncertain
    assert lc.ate(ref, upright) < lc.ate(free, upright) * 1.5


def test_rotation_constraints_checked(upright):
    g = upright.graph
    with pytest.raises(OptionError, match="one world direction"):
        lc.lago(g, rotation_constraints={0: ((0, 0, 1), (0, 0, 1)), 1: ((1, 0, 0), (1, 0, 0))})
    with pytest.raises(OptionError, match="3-D graphs only"):
        lc.lago(lc.manhattan_world(20, seed=1).graph, rotation_constraints={0: ((0, 0, 1), (0, 0, 1))})
    with pytest.raises(OptionError, match="R a = b"):
        lc.refine(g, lc.lago(g), constraints={0: (0, 0, 1)})


# ------------------------------------------------------------------ priors and given rotations in lago
def test_position_priors_fix_the_frame_in_lago_and_refine(cube):
    g = cube.graph
    gps = {int(g.ids[v]): (cube.t[v], None, np.eye(3) / 0.05 ** 2) for v in (0, 21, 42, 63)}
    res = lc.lago(g, priors=gps)
    assert lc.lago(g, priors=gps, method="cvxpy").chi2 == pytest.approx(res.chi2, rel=1e-6)
    ref = lc.refine(g, res, priors=gps)
    assert ref.converged and not ref.held.any()
    err = np.linalg.norm(ref.t[[0, 21, 42, 63]] - cube.t[[0, 21, 42, 63]], axis=1)
    assert err.max() < 0.2 and lc.ate(ref, cube, align=False) < 0.2  # in the priors' frame, no alignment
    assert ref.chi2 >= lc.refine(g, lc.lago(g)).chi2 * (1 - 1e-9)


def test_lago_continues_from_given_rotations(cube):
    g = cube.graph
    seed = lago3d(g, route="seed")
    cont = lago3d(g, route="seed", rotations=seed.R)
    assert np.allclose(cont.t, seed.t, atol=1e-8) and cont.chi2 == pytest.approx(seed.chi2, rel=1e-9)
    joint = lago3d(g, rotations=seed.R)
    assert joint.chi2 == pytest.approx(lago3d(g).chi2, rel=1e-9) and joint.alpha is not None
    G = exp_so3(np.array([[0.4, 0.1, -0.7]]))[0]  # another frame: the same estimate up to it
    assert lago3d(g, rotations=G @ seed.R).chi2 == pytest.approx(joint.chi2, rel=1e-9)
    cx = lago3d(g, rotations=seed.R, method="cvxpy")
    assert cx.chi2 == pytest.approx(joint.chi2, rel=1e-6)


# ------------------------------------------------------------------ metrics and certify3d
def test_ate_and_rpe_of_either_dimension(cube):
    res = lc.lago(cube.graph)
    G, s = exp_so3(np.array([[0.3, -0.2, 1.0]]))[0], np.array([1.0, 2.0, 3.0])
    moved = (res.t @ G.T + s, G @ res.R)
    assert lc.ate(moved, cube) == pytest.approx(lc.ate(res, cube.truth), rel=1e-9)
    assert lc.rpe(moved, cube) == pytest.approx(lc.rpe(res, cube), rel=1e-9) and lc.rpe(cube, cube) == 0.0
    # rpe by a loop over the relative poses
    d = 2
    errs = []
    for i in range(cube.graph.n_poses - d):
        Pt, PR = res.R[i].T @ (res.t[i + d] - res.t[i]), res.R[i].T @ res.R[i + d]
        Qt, QR = cube.R[i].T @ (cube.t[i + d] - cube.t[i]), cube.R[i].T @ cube.R[i + d]
        errs.append(QR.T @ (Pt - Qt))
        del PR
    assert lc.rpe(res, cube, delta=d) == pytest.approx(np.sqrt(np.mean(np.sum(np.square(errs), 1))), rel=1e-12)
    w = lc.manhattan_world(80, seed=2)
    r2 = lc.lago(w.graph)
    assert lc.ate(r2, w) == lc.ate(r2.poses, w.truth) > 0 and lc.rpe(w.truth, w) == 0.0
    with pytest.raises(OptionError, match="same dimension"):
        lc.ate(r2, cube)
    with pytest.raises(OptionError, match="delta"):
        lc.rpe(res, cube, delta=0)


def test_certify3d_takes_an_id(cube):
    g = cube.graph
    res = lc.lago(g)
    a = certify3d(g, res.t, res.R, anchor=int(g.ids[5]))
    b = certify3d(g, res.t, res.R, anchor_index=5)
    c = lc.certify3d(g, res)
    assert a.cost == pytest.approx(b.cost, rel=1e-12) and a.certified == b.certified == c.certified
    with pytest.raises(OptionError, match="not both"):
        certify3d(g, res, anchor=0, anchor_index=0)


def test_api_reference_lists_every_3d_module():
    import pkgutil
    import re
    from pathlib import Path

    import lago_cvx.space

    text = (Path(__file__).resolve().parents[1] / "docs" / "api.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"automodule:: (lago_cvx[\w.]*)", text))
    space = ["lago_cvx.space"] + [m.name for m in pkgutil.iter_modules(lago_cvx.space.__path__, "lago_cvx.space.")]
    wanted = space + ["lago_cvx.posegraph3d", "lago_cvx.so3", "lago_cvx.metrics3d", "lago_cvx.synthetic.space"]
    assert not sorted(set(wanted) - listed)
    assert "lago_cvx.space.chordal_problem" in text  # and which chordal_problem lc.chordal_problem is


def test_known_positions_without_a_rotation_fix_the_frame(cube):
    """Position anchors (t only) or two GPS priors: the chordal gauge is aligned onto them, then refine leaves the
    one rotation they do not fix (about the line through two positions) to the gauge."""
    g = cube.graph
    free = lc.refine(g, lc.lago(g))
    anchors = {int(g.ids[i]): (cube.t[i], None) for i in (0, 21, 63)}
    res = lc.lago(g, anchors=anchors)
    ref = lc.refine(g, res, anchors=anchors)
    assert ref.converged and free.chi2 * (1 - 1e-9) <= ref.chi2 < 1.01 * free.chi2  # the frame fits, little cost
    assert lc.ate(ref, cube, align=False) < 0.2 and np.array_equal(ref.t[21], cube.t[21])
    gps = {int(g.ids[i]): (cube.t[i], None, 400.0 * np.eye(3)) for i in (0, 63)}
    two = lc.refine(g, lc.lago(g, priors=gps), priors=gps)
    assert two.converged and two.chi2 < 1.01 * free.chi2
    assert np.linalg.eigvalsh(two.pose_covariances()[30]).min() > 0


def test_certify_dispatches_on_dim(cube):
    res = lc.lago(cube.graph)
    a, b = lc.certify(cube.graph, res), certify3d(cube.graph, res.t, res.R)
    assert type(a).__name__ == "Certificate3D" and a.cost == pytest.approx(b.cost, rel=1e-12)
    w = lc.manhattan_world(60, seed=1)
    r2 = lc.lago(w.graph)
    assert lc.certify(w.graph, r2).cost == pytest.approx(lc.certify(w.graph, r2.poses).cost, rel=1e-15)


def test_anchors_and_priors_in_space_agree_with_gtsam():
    """smallGrid3D in GTSAM's cost with two anchors (tight PriorFactorPose3), three GPS priors
    (PoseTranslationPrior3D) and a rotation prior (PoseRotationPrior3D): the same minimum and the same marginals
    (GTSAM's tangent is (δφ, δv), ours (δv, δφ): both perturb on the right)."""
    gtsam = pytest.importorskip("gtsam")
    path = dataset_path("se-sync-3d/smallGrid3D.g2o")
    g = lc.read_graph(path, cost="gtsam")
    best = lc.refine(g, lc.lago(g))
    anchors = {0: (best.t[0], best.R[0]), 124: (best.t[124] + [0.1, 0, 0], best.R[124])}
    gps = {v: (best.t[v] + 0.05, None, np.eye(3) / 0.05 ** 2) for v in (30, 60, 90)}
    rot = {45: (None, best.R[45] @ exp_so3(np.array([[0.02, 0.0, 0.0]]))[0], 1e4 * np.eye(3))}
    priors = {**gps, **rot}
    ours = lc.refine(g, lc.lago(g, anchors=anchors, priors=priors), anchors=anchors, priors=priors,
                     tolerance=1e-12, max_iterations=100)
    fg, init = gtsam.readG2o(str(path), True)
    info = gtsam.noiseModel.Gaussian.Information
    for v, (t, R) in anchors.items():
        fg.add(gtsam.PriorFactorPose3(v, gtsam.Pose3(gtsam.Rot3(R), t), info(1e12 * np.eye(6))))
    for v, (t, _, lam) in gps.items():
        fg.add(gtsam.PoseTranslationPrior3D(v, gtsam.Point3(*t), info(lam)))
    for v, (_, R, lam) in rot.items():
        fg.add(gtsam.PoseRotationPrior3D(v, gtsam.Rot3(R), info(lam)))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    params.setMaxIterations(200)
    est = gtsam.LevenbergMarquardtOptimizer(fg, init, params).optimize()
    assert ours.converged and 2 * fg.error(est) == pytest.approx(ours.chi2, rel=1e-9)
    swap = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])
    theirs = swap @ gtsam.Marginals(fg, est).marginalCovariance(60) @ swap.T
    mine = ours.pose_covariances()[60]
    assert np.abs(theirs - mine).max() <= 1e-6 * np.abs(mine).max()


def test_an_estimate_of_the_other_dimension_is_named(cube):
    planar = lc.manhattan_world(cube.graph.n_poses, seed=1)
    res3 = lc.lago(cube.graph)
    for estimate in (res3, (res3.t, res3.R)):
        with pytest.raises(OptionError, match="planar graph"):
            lc.refine(planar.graph, estimate)
    with pytest.raises(OptionError, match="3-D estimate"):
        lc.refine(cube.graph, lc.lago(planar.graph))

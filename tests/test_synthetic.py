"""Tests of the seeded synthetic worlds (lago_cvx.synthetic)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from lago_cvx.posegraph import between, is_spd, wrap_angle
from lago_cvx.synthetic import (OUTLIER_MIN_CHI2, REFERENCE_SIGMA_THETA, REFERENCE_SIGMA_XY,
                                SyntheticWorld, add_noise, circle_world, dead_reckoning,
                                manhattan_world, random_graph)

GENERATORS = {
    "manhattan": lambda **kw: manhattan_world(600, **kw),
    "manhattan_full": lambda **kw: manhattan_world(600, information="full", outlier_fraction=0.1, **kw),
    "circle": lambda **kw: circle_world(120, laps=2.5, **kw),
    "circle_int": lambda **kw: circle_world(90, laps=3, **kw),
    "random_tree": lambda **kw: random_graph(80, 200, **kw),
    "random_chain": lambda **kw: random_graph(80, 150, spanning="chain", outlier_fraction=0.2, **kw),
    "random_odometry": lambda **kw: random_graph(80, 79, spanning="odometry", information="full", **kw),
}
GEN_IDS = list(GENERATORS)


def _arrays(w: SyntheticWorld):
    g = w.graph
    return [g.tails, g.heads, g.delta_l, g.delta, g.information, g.initial, w.truth,
            w.params["outliers"], w.params["loop_closures"]]


def _residuals(w: SyntheticWorld) -> np.ndarray:
    """(m, 3) measurement − true relative pose, angle wrapped."""
    g = w.graph
    r = g.measurements - between(w.truth[g.tails], w.truth[g.heads])
    r[:, 2] = wrap_angle(r[:, 2])
    return r


def _whitened(w: SyntheticWorld) -> np.ndarray:
    """(m, 3) residuals whitened by the information: Lᵀ r with Ω = L Lᵀ (identity covariance)."""
    L = np.linalg.cholesky(w.graph.information)
    return np.einsum("kji,kj->ki", L, _residuals(w))


def _n_components(g) -> int:
    a = coo_matrix((np.ones(g.n_edges), (g.tails, g.heads)), shape=(g.n_poses, g.n_poses))
    return connected_components(a, directed=False)[0]


# ------------------------------------------------------------------------- determinism
@pytest.mark.parametrize("gen", GEN_IDS)
def test_same_seed_bit_identical(gen):
    a, b = GENERATORS[gen](seed=7), GENERATORS[gen](seed=7)
    for x, y in zip(_arrays(a), _arrays(b)):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert a.graph.equals(b.graph)


@pytest.mark.parametrize("gen", GEN_IDS)
def test_different_seed_differs(gen):
    a, b = GENERATORS[gen](seed=1), GENERATORS[gen](seed=2)
    assert not np.array_equal(a.graph.measurements, b.graph.measurements)  # also if shapes differ
    if gen.startswith(("manhattan", "random")):  # the circle's truth does not depend on the seed
        assert not np.array_equal(a.truth, b.truth)


def test_regenerate_from_params():
    """params hold every argument: calling the generator with them reproduces the world."""
    drop = {"generator", "outliers", "loop_closures", "spanning_edges"}
    for w, fn in [(manhattan_world(300, seed=4, p_turn=0.2, outlier_fraction=0.1), manhattan_world),
                  (circle_world(50, laps=2, seed=4), circle_world),
                  (random_graph(30, 60, seed=4, spanning="chain"), random_graph)]:
        kw = {k: v for k, v in w.params.items() if k not in drop}
        n = kw.pop("n_poses")
        args = (n, kw.pop("n_edges")) if fn is random_graph else (n,)
        w2 = fn(*args, **kw)
        assert w.params["generator"] == fn.__name__
        assert all(np.array_equal(x, y) for x, y in zip(_arrays(w), _arrays(w2)))


# ------------------------------------------------------------------- noiseless exactness
@pytest.mark.parametrize("gen", GEN_IDS)
def test_noiseless_measurements_exact(gen):
    w = GENERATORS[gen](seed=3, sigma_xy=0.0, sigma_theta=0.0)
    inl = ~w.outlier_mask
    r = _residuals(w)[inl]
    assert np.abs(r).max() <= 1e-12
    # stored δ is the wrapped true difference
    g = w.graph
    true = between(w.truth[g.tails], w.truth[g.heads])[inl]
    assert np.abs(wrap_angle(g.delta[inl] - wrap_angle(true[:, 2]))).max() <= 1e-12
    assert np.allclose(g.delta_l[inl], true[:, :2], rtol=0, atol=1e-12)


@pytest.mark.parametrize("gen", GEN_IDS)
def test_delta_wrapped(gen):
    d = GENERATORS[gen](seed=0).graph.delta
    assert d.min() >= -np.pi and d.max() < np.pi


def test_noiseless_information_uses_reference_sigmas():
    g = manhattan_world(100, sigma_xy=0.0, sigma_theta=0.0).graph
    expected = np.diag([1 / REFERENCE_SIGMA_XY**2, 1 / REFERENCE_SIGMA_XY**2, 1 / REFERENCE_SIGMA_THETA**2])
    assert np.allclose(g.information, expected)
    g = circle_world(50, sigma_xy=0.0, sigma_theta=0.0, info_sigma_xy=0.1, info_sigma_theta=0.01).graph
    assert np.allclose(g.information, np.diag([100.0, 100.0, 1e4]))
    g = manhattan_world(100, sigma_xy=0.2, sigma_theta=0.0).graph  # mixed: only θ noiseless
    assert np.allclose(g.information[0], np.diag([25.0, 25.0, 1 / REFERENCE_SIGMA_THETA**2]))


def test_noise_scales_with_sigma():
    """The standardized draws do not depend on the sigmas: same graph, residuals scale."""
    a = manhattan_world(400, seed=5, sigma_xy=0.05, sigma_theta=0.02)
    b = manhattan_world(400, seed=5, sigma_xy=0.10, sigma_theta=0.01)
    assert np.array_equal(a.graph.tails, b.graph.tails) and np.array_equal(a.graph.heads, b.graph.heads)
    ra, rb = _residuals(a), _residuals(b)
    assert np.allclose(rb[:, :2], 2 * ra[:, :2], atol=1e-9)
    assert np.allclose(rb[:, 2], 0.5 * ra[:, 2], atol=1e-9)


# ------------------------------------------------------------------------------ structure
@pytest.mark.parametrize("gen", GEN_IDS)
def test_connected(gen):
    g = GENERATORS[gen](seed=11).graph
    assert _n_components(g) == 1


@pytest.mark.parametrize("gen", ["manhattan", "manhattan_full", "circle", "circle_int", "random_odometry"])
def test_odometric_chain_present(gen):
    w = GENERATORS[gen](seed=0)
    g, n = w.graph, w.n_poses
    if gen == "random_odometry":
        sp = w.params["spanning_edges"]
        pairs = set(zip(g.tails[sp].tolist(), g.heads[sp].tolist()))
        assert pairs == {(i, i + 1) for i in range(n - 1)}
    else:
        assert np.array_equal(g.tails[: n - 1], np.arange(n - 1))
        assert np.array_equal(g.heads[: n - 1], np.arange(1, n))
        assert g.n_odometric == n - 1
        assert np.array_equal(w.params["loop_closures"], np.arange(n - 1, g.n_edges))


@pytest.mark.parametrize("gen", ["manhattan", "manhattan_full", "circle", "circle_int"])
def test_loop_closures_point_forward(gen):
    w = GENERATORS[gen](seed=2)
    g, lc = w.graph, w.params["loop_closures"]
    assert lc.size > 0
    assert np.all(g.tails[lc] < g.heads[lc])
    sep = w.params.get("min_loop_separation", 2)
    assert np.all(g.heads[lc] - g.tails[lc] >= sep)


def test_manhattan_truth_and_revisits():
    w = manhattan_world(2000, seed=1, sigma_xy=0, sigma_theta=0)
    t, g, n = w.truth, w.graph, 2000
    assert np.array_equal(t[0], [0.0, 0.0, 0.0])
    steps = np.hypot(*np.diff(t[:, :2], axis=0).T)
    assert np.allclose(steps, 1.0)
    q = t[:, 2] / (np.pi / 2)
    assert np.allclose(q, np.round(q))
    h = w.params["grid_extent"] // 2
    assert np.abs(t[:, :2]).max() <= h
    lc = w.params["loop_closures"]
    d = np.hypot(*(t[g.heads[lc], :2] - t[g.tails[lc], :2]).T)
    assert d.max() <= w.params["loop_closure_radius"]
    cap = w.params["max_loop_closures_per_pose"]
    assert np.bincount(g.heads[lc], minlength=n).max() <= cap
    # loop closures of revisits can have any relative orientation, also winding ones
    rel = (t[g.heads[lc], 2] - t[g.tails[lc], 2]) / (np.pi / 2)
    assert len(np.unique(np.round(rel) % 4)) == 4


def test_manhattan_m3500_like_default():
    w = manhattan_world(3500)
    g = w.graph
    ratio = g.n_edges / g.n_poses
    print(f"\nmanhattan_world(3500): {g.n_poses} poses, {g.n_edges} edges, "
          f"{g.n_loop_closures} loop closures, {ratio:.3f} edges/pose (M3500: 5453, 1954, 1.558)")
    assert g.n_odometric == 3499
    assert 1.35 <= ratio <= 1.8
    per_head = np.bincount(g.heads[w.params["loop_closures"]], minlength=3500)
    assert 0.45 <= np.mean(per_head == 0) <= 0.75  # M3500: 61 % of poses close no loop


def test_dead_reckoning_initial():
    w = manhattan_world(500, seed=3)
    g = w.graph
    assert np.array_equal(g.initial[0], w.truth[0])
    assert np.allclose(g.initial, dead_reckoning(w.truth[0], g.measurements[:499]))
    # one step by hand
    from lago_cvx.posegraph import compose
    assert np.allclose(g.initial[1], compose(w.truth[0], g.measurements[0]))
    # noiseless: dead reckoning recovers the truth (θ up to 2kπ, as δ is wrapped)
    for w in [manhattan_world(500, sigma_xy=0, sigma_theta=0), circle_world(60, laps=2, sigma_xy=0, sigma_theta=0),
              random_graph(60, 100, sigma_xy=0, sigma_theta=0)]:
        ini = w.graph.initial
        assert np.allclose(ini[:, :2], w.truth[:, :2], atol=1e-9)
        assert np.abs(wrap_angle(ini[:, 2] - w.truth[:, 2])).max() < 1e-9


def test_dead_reckoning_drifts_with_noise():
    w = manhattan_world(3000, seed=0)
    err = np.hypot(*(w.graph.initial[:, :2] - w.truth[:, :2]).T)
    assert err[-1] > 1.0  # noisy odometry accumulates drift


def test_circle_multi_lap_winding():
    n, laps = 300, 3
    w = circle_world(n, laps=laps)
    g, t = w.graph, w.truth
    span = np.ptp(t[:, 2])
    assert 6 * np.pi - 2 * np.pi * laps / n - 1e-9 <= span <= 6 * np.pi
    assert np.allclose(t[0], 0.0)
    assert np.allclose(np.hypot(t[:, 0], t[:, 1] - w.params["radius"]), w.params["radius"])
    lc = w.params["loop_closures"]
    # closures at the same place on earlier laps: true unwrapped δ is 2πq, stored δ ≈ 0
    true_dtheta = t[g.heads[lc], 2] - t[g.tails[lc], 2]
    same_place = np.hypot(*(t[g.heads[lc], :2] - t[g.tails[lc], :2]).T) < 1e-9
    assert same_place.sum() == 100 + 2 * 100  # lap 2 back to lap 1; lap 3 back to laps 1 and 2
    q = true_dtheta[same_place] / (2 * np.pi)
    assert set(np.round(q).astype(int).tolist()) == {1, 2}
    assert np.abs(g.delta[lc][same_place]).max() < 0.1
    # integer laps: the circle is closed by 0 → n−1
    assert np.any((g.tails[lc] == 0) & (g.heads[lc] == n - 1))


def test_circle_fractional_laps():
    w = circle_world(100, laps=1.5)
    g, lc = w.graph, w.params["loop_closures"]
    assert not np.any((g.tails[lc] == 0) & (g.heads[lc] == 99))
    assert lc.size == 33
    assert np.isclose(w.truth[-1, 2], 2 * np.pi * 1.5 * 99 / 100)
    assert circle_world(100, laps=2, loop_closures=False).graph.n_loop_closures == 0


def test_random_graph_properties():
    w = random_graph(200, 500, seed=9)
    g = w.graph
    assert g.n_poses == 200 and g.n_edges == 500
    assert w.truth[:, 2].min() < -2 * np.pi and w.truth[:, 2].max() > 2 * np.pi
    sp = w.params["spanning_edges"]
    assert sp.size == 199 and np.intersect1d(sp, w.params["loop_closures"]).size == 0
    assert _n_components(g.subgraph_edges(sp)) == 1  # the spanning edges alone connect the graph
    assert np.mean(g.tails > g.heads) > 0.3  # random directions
    assert np.all(g.tails != g.heads)
    # parallel edges are allowed: a dense graph has some
    d = random_graph(10, 300, seed=0).graph
    assert np.unique(np.sort(np.column_stack([d.tails, d.heads]), 1), axis=0).shape[0] < 300


def test_invalid_arguments():
    with pytest.raises(ValueError):
        random_graph(10, 5)
    with pytest.raises(ValueError):
        manhattan_world(10, sigma_xy=-1.0)
    with pytest.raises(ValueError):
        manhattan_world(10, information="block")
    with pytest.raises(ValueError):
        manhattan_world(10, min_loop_separation=1)
    with pytest.raises(ValueError):
        circle_world(10, laps=0)
    with pytest.raises(ValueError):
        manhattan_world(100, outlier_fraction=1.5)


def test_readonly():
    w = manhattan_world(50, outlier_fraction=0.5)
    for a in [w.truth, w.params["outliers"], w.graph.delta]:
        with pytest.raises(ValueError):
            a[0] = 0


# --------------------------------------------------------------------------- statistics
@pytest.mark.parametrize("information", ["diagonal", "full"])
def test_whitened_residuals_unit_variance(information):
    w = manhattan_world(20000, seed=0, information=information, sigma_xy=0.05, sigma_theta=0.02)
    z = _whitened(w)
    m = z.shape[0]
    assert m > 25000
    var = z.var(axis=0)
    assert np.all(np.abs(var - 1) < 0.04), var
    assert np.all(np.abs(z.mean(axis=0)) < 4 / np.sqrt(m))
    c = np.corrcoef(z.T)
    assert np.abs(c - np.eye(3)).max() < 0.03
    chi2 = (z**2).sum(1)
    assert abs(chi2.mean() - 3) < 0.1


def test_add_noise_helper():
    rng = np.random.default_rng(0)
    truth = np.column_stack([rng.normal(size=(1000, 2)), rng.uniform(-9, 9, 1000)])
    tails, heads = np.arange(999), np.arange(1, 1000)
    meas, info = add_noise(truth, tails, heads, sigma_xy=0.0, sigma_theta=0.0, rng=rng)
    assert meas.shape == (999, 3) and info.shape == (999, 3, 3)
    rel = between(truth[:-1], truth[1:])
    assert np.array_equal(meas[:, :2], rel[:, :2])
    assert np.array_equal(meas[:, 2], wrap_angle(rel[:, 2]))
    a = add_noise(truth, tails, heads, sigma_xy=0.1, sigma_theta=0.1, rng=np.random.default_rng(1))
    b = add_noise(truth, tails, heads, sigma_xy=0.1, sigma_theta=0.1, rng=np.random.default_rng(1))
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


# ---------------------------------------------------------------------------- outliers
def test_outliers_marked():
    clean = manhattan_world(3000, seed=2)
    w = manhattan_world(3000, seed=2, outlier_fraction=0.1)
    g, out, lc = w.graph, w.params["outliers"], w.params["loop_closures"]
    assert out.size == round(0.1 * lc.size) > 0
    assert np.all(np.isin(out, lc)) and np.all(np.diff(out) > 0)
    assert w.outlier_mask.sum() == out.size
    # false edges are really wrong, and still point forward with the required separation
    L = np.linalg.cholesky(g.information[out])
    z = np.einsum("kji,kj->ki", L, _residuals(w)[out])
    assert np.all((z**2).sum(1) >= OUTLIER_MIN_CHI2)
    assert np.all(g.heads[out] - g.tails[out] >= w.params["min_loop_separation"])
    # both kinds occur: wrong pose pairs and random measurements
    moved = g.heads[out] != clean.graph.heads[out]
    assert 0 < moved.sum() < out.size
    # everything else is the outlier-free world, untouched
    inl = ~w.outlier_mask
    assert np.array_equal(g.tails[inl], clean.graph.tails[inl])
    assert np.array_equal(g.heads[inl], clean.graph.heads[inl])
    assert np.array_equal(g.measurements[inl], clean.graph.measurements[inl])
    assert w.inlier_graph.n_edges == g.n_edges - out.size
    assert manhattan_world(300).params["outliers"].size == 0


def test_outliers_other_generators():
    w = circle_world(200, laps=3, outlier_fraction=0.25, sigma_xy=0, sigma_theta=0)
    assert w.params["outliers"].size == round(0.25 * w.params["loop_closures"].size)
    assert np.abs(_residuals(w)[~w.outlier_mask]).max() < 1e-12
    w = random_graph(100, 300, outlier_fraction=0.5)
    assert np.all(np.isin(w.params["outliers"], w.params["loop_closures"]))
    assert w.params["outliers"].size == round(0.5 * 201)


# ------------------------------------------------------------------- full information
def test_full_information_spd_with_cross_terms():
    w = manhattan_world(1000, seed=1, information="full")
    info = w.graph.information
    assert is_spd(info).all()
    assert np.linalg.eigvalsh(info).min() > 0
    assert np.allclose(info, np.swapaxes(info, 1, 2))
    d = np.sqrt(np.einsum("kii->ki", info))
    corr = info / d[:, :, None] / d[:, None, :]
    for a, b in [(0, 2), (1, 2), (0, 1)]:
        assert np.all(corr[:, a, b] != 0)
        assert np.mean(np.abs(corr[:, a, b]) > 0.1) > 0.5
    assert not np.allclose(info[0], info[1])  # one random matrix per edge
    # the covariance has the requested marginal sigmas
    cov = np.linalg.inv(info)
    assert np.allclose(np.sqrt(np.einsum("kii->ki", cov)), [0.05, 0.05, 0.02])


def test_full_information_noiseless():
    w = manhattan_world(300, information="full", sigma_xy=0, sigma_theta=0)
    assert np.abs(_residuals(w)).max() <= 1e-12
    assert is_spd(w.graph.information).all()


# ------------------------------------------------------------------------------ scale
def test_large_manhattan_builds():
    t0 = time.perf_counter()
    w = manhattan_world(100_000, seed=0)
    dt = time.perf_counter() - t0
    g = w.graph
    print(f"\nmanhattan_world(100000): {g.n_edges} edges ({g.n_loop_closures} loop closures) "
          f"built in {dt:.2f} s")
    assert g.n_poses == 100_000 and g.n_odometric == 99_999
    assert g.n_loop_closures > 30_000

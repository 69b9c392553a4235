"""Regularization as an integer program (lago_cvx.regularization.integer): eqs. (I2)/(I3) against the seed's
rounding.

Tests that need SCIP are skipped, with the reason printed, when pyscipopt is absent
(``pip install -e ".[mip]"``); the dependency-free enumeration is tested everywhere."""

import itertools
import logging
import sys

import cvxpy as cp
import numpy as np
import pytest

from lago_cvx import phases as P
from lago_cvx.errors import MissingSolverError, OptionError, SearchLimitError
from lago_cvx.experiments import format_integer_sweep, integer_noise_sweep, true_cycle_integers
from lago_cvx.graph import cycle_basis, reduced_incidence, spanning_tree
from lago_cvx.metrics import chi2
from lago_cvx.pipeline import lago
from lago_cvx.posegraph import PoseGraph, wrap_angle
from lago_cvx.regularization import integer as I
from lago_cvx.regularization.sphere import enumerate_integers
from lago_cvx.rounding import edge_integers
from lago_cvx.solvers import IntegerSearch
from lago_cvx.synthetic import circle_world, manhattan_world, random_graph
from lago_cvx.uncertainty import edge_uncertainty

try:
    import pyscipopt  # noqa: F401
    HAVE_SCIP = "SCIP" in cp.installed_solvers()
except ImportError:
    HAVE_SCIP = False

needs_scip = pytest.mark.skipif(not HAVE_SCIP, reason='SCIP not installed: pip install -e ".[mip]"')


@pytest.fixture(autouse=True)
def _quiet_regularization():
    # noisy worlds make the rounding log "ambiguous chord" warnings by design
    logging.getLogger("lago_cvx.regularization").setLevel(logging.ERROR)
    yield
    logging.getLogger("lago_cvx.regularization").setLevel(logging.NOTSET)


def _world(kind, n, sigma, seed):
    if kind == "manhattan":
        return manhattan_world(n, seed=seed, sigma_theta=sigma)
    return circle_world(n, laps=3, seed=seed, sigma_theta=sigma)


def _true_q(w, g, t):
    return true_cycle_integers(g, t, w.truth)


_SEARCH = {"solver", "form", "time_limit", "max_nodes", "max_shift", "exact", "solver_options"}


def _ip(g, t, **kw):
    """``integer_regularization`` with the search options given as keywords (``IntegerSearch`` fields)."""
    search = IntegerSearch(**{k: v for k, v in kw.items() if k in _SEARCH})
    return I.integer_regularization(g, t, search=search, **{k: v for k, v in kw.items() if k not in _SEARCH})


def _enumerate(data, *, max_shift=None, exact=True, max_nodes=2_000_000):
    lo, hi, _ = I.exact_box(data, max_shift=max_shift, exact=exact)
    return enumerate_integers(data, (lo, hi), max_nodes=max_nodes)


# Noisy cases (σθ = 0.3–0.5) where the weighted optimum and the rounding differ (found with the
# enumeration; the test below re-checks that they do): (n_poses, σθ, seed, tree).
DIFFERING = [(60, 0.3, 1, "odometry"), (60, 0.4, 1, "bfs"), (80, 0.3, 2, "odometry"), (40, 0.5, 4, "bfs"),
             (80, 0.5, 3, "bfs")]


# ----------------------------------------------------------------------------------- hand example
def _two_cycles_graph(n_shared=8):
    """Two fundamental cycles sharing a long noisy tree path.

    Poses 0 … N (N = n_shared) along the shared path (edges i → i+1, σ = 0.6 rad each), a branch
    N → N+1 (σ = 0.1), chords 0 → N and 0 → N+1 (σ = 0.1). All true orientations are 0 (so the true
    cycle integers are (0, 0)). The path's measurements sum to −3.1 rad (a 1.8σ error of the path),
    the chords read −0.1 and +0.1, the branch 0: cycle residuals r = Cδ = (3.0, 3.2)."""
    N = n_shared
    tails = np.r_[np.arange(N), N, 0, 0]
    heads = np.r_[np.arange(1, N + 1), N + 1, N, N + 1]
    sig = np.r_[np.full(N, 0.6), 0.1, 0.1, 0.1]
    delta = np.r_[np.full(N, -3.1 / N), 0.0, -0.1, 0.1]
    info = np.zeros((tails.size, 3, 3))
    info[:, 0, 0] = info[:, 1, 1] = 100.0
    info[:, 2, 2] = 1.0 / sig**2
    g = PoseGraph(N + 2, tails, heads, np.zeros((tails.size, 2)), delta, info)
    tree = spanning_tree(g, np.arange(N + 1))  # the path and the branch
    return g, tree


def test_hand_constructed_weighted_optimum_differs_from_rounding():
    g, t = _two_cycles_graph()
    N = 8
    np.testing.assert_array_equal(t.chords, [N + 1, N + 2])
    # By hand: r = (−0.1 − (−3.1), 0.1 − (−3.1 + 0)) = (3.0, 3.2). Rounding: 3.0 ∈ (−π, π] → k = 0,
    # 3.2 > π → k = −1: corrected residuals (3.0, −3.083) — a 2π jump between two cycles whose difference
    # is known to ±0.17 rad.
    r = np.array([3.0, 3.2])
    # S = C P Cᵀ (eq. 5): both cycles run the shared path the same way:
    # S11 = 8·0.36 + 0.01, S22 = 8·0.36 + 0.01 + 0.01 (branch), S12 = 8·0.36.
    S = np.array([[2.89, 2.88], [2.88, 2.90]])
    det = S[0, 0] * S[1, 1] - S[0, 1] ** 2  # 0.0866
    S_inv = np.array([[S[1, 1], -S[0, 1]], [-S[0, 1], S[0, 0]]]) / det

    def J(q):
        x = r + 2 * np.pi * np.asarray(q, float)
        return float(x @ S_inv @ x)

    costs = {q: J(q) for q in itertools.product(range(-3, 4), repeat=2)}
    best = min(costs, key=costs.get)
    assert best == (0, 0)
    # (0,0): xᵀS⁻¹x = (2.90·9 − 2·2.88·3·3.2 + 2.89·3.2²)/0.0866 = 0.3976/0.0866
    assert costs[(0, 0)] == pytest.approx(0.3976 / 0.0866, rel=1e-12)
    assert costs[(0, -1)] > 200 * costs[(0, 0)]
    assert costs[(-1, -1)] > costs[(0, 0)]  # the other joint correction is close but worse

    d = I.cycle_data(g, t)
    np.testing.assert_allclose(d.r, r, atol=1e-12)
    np.testing.assert_allclose(d.S, S, atol=1e-12)
    np.testing.assert_array_equal(d.k_round, [0, -1])  # the seed's per-chord rounding
    assert I.rounding_cost(g, t, data=d) == pytest.approx(costs[(0, -1)], rel=1e-10)

    res = _ip(g, t, solver="enumerate")
    np.testing.assert_array_equal(res.k_chords, [0, 0])
    assert res.objective == pytest.approx(costs[(0, 0)], rel=1e-10)
    assert res.n_differ == 1 and res.differing_chords.tolist() == [N + 2]
    # the truth (all orientations 0) agrees with the weighted optimum, not with the rounding
    q_true = I.cycle_integers(g, t, edge_integers(g, np.zeros(g.n_poses)))
    np.testing.assert_array_equal(q_true, [0, 0])


@needs_scip
@pytest.mark.parametrize("form", ["cycle", "phase1"])
def test_hand_constructed_with_scip(form):
    g, t = _two_cycles_graph()
    res = _ip(g, t, form=form, exact=False, max_shift=3)
    assert res.status == cp.OPTIMAL
    np.testing.assert_array_equal(res.k_chords, [0, 0])
    assert res.objective == pytest.approx(0.3976 / 0.0866, rel=1e-10)
    assert res.solver_value == pytest.approx(res.objective, rel=1e-5)
    cmp = I.compare_with_rounding(g, t, search=IntegerSearch(solver="SCIP", form=form))
    assert not cmp["equal"] and cmp["n_differ"] == 1 and cmp["improvement"] > 1000


# ------------------------------------------------------------------------------ the two forms
@needs_scip
@pytest.mark.parametrize("kind,n,sigma,seed", [("manhattan", 25, 0.05, 1), ("manhattan", 30, 0.3, 0),
                                               ("circle", 24, 0.1, 0)])
def test_cycle_and_phase1_forms_have_the_same_optimum(kind, n, sigma, seed):
    w = _world(kind, n, sigma, seed) if kind == "manhattan" else circle_world(n, laps=2, seed=seed,
                                                                              sigma_theta=sigma)
    g = w.graph
    t = spanning_tree(g, "bfs")
    d = I.cycle_data(g, t)
    assert d.n_chords >= 4
    # a plain box |k − k_round| ≤ 2 (5^l candidates), so the solver really searches
    a = _ip(g, t, form="cycle", exact=False, max_shift=2, data=d)
    b = _ip(g, t, form="phase1", exact=False, max_shift=2, data=d)
    assert a.status == b.status == cp.OPTIMAL
    np.testing.assert_array_equal(a.k, b.k)
    assert a.solver_value == pytest.approx(b.solver_value, rel=1e-5)
    assert a.objective == pytest.approx(b.objective, rel=1e-12)
    # eq. (2)'s θ is LAGO's phase 1 on δ_reg (to SCIP's cone feasibility tolerance, ~1e-4 rad here)
    ph1 = P.phase1_closed_form(g, b.delta_reg, edge_uncertainty(g), anchor=int(g.ids[t.root]))
    np.testing.assert_allclose(b.theta, ph1.theta, atol=2e-3)
    # the problems are explicit cvxpy objects one can print and extend
    assert "k" in a.variables and {"theta", "k"} <= set(b.variables)
    assert a.problem.is_mixed_integer() and b.problem.is_mixed_integer()


def test_phase1_cost_equals_cycle_cost():
    """Eq. (1) = eq. (3) for any integers: the θ-elimination identity, in closed form."""
    w = manhattan_world(60, seed=1, sigma_theta=0.3)
    g = w.graph
    t = spanning_tree(g, "odometry")
    unc = edge_uncertainty(g)
    d = I.cycle_data(g, t, unc=unc)
    rng = np.random.default_rng(0)
    for _ in range(5):
        k = rng.integers(-2, 3, g.n_edges)  # integers on tree edges too
        dreg = g.delta + 2 * np.pi * k
        ph1 = P.phase1_closed_form(g, dreg, unc, anchor=int(g.ids[t.root]))
        A2 = reduced_incidence(g, int(g.ids[t.root]))
        res = unc.sqrt_info_delta * (A2.T @ ph1.theta_free - dreg)
        assert res @ res == pytest.approx(I.weighted_cycle_cost(g, t, k, data=d), rel=1e-9)


# ------------------------------------------------------------------------ low noise = rounding
@needs_scip
@pytest.mark.parametrize("tree", ["bfs", "odometry"])
@pytest.mark.parametrize("kind,n", [("manhattan", 80), ("circle", 60)])
def test_ip_equals_rounding_and_truth_at_low_noise(kind, n, tree):
    for seed in range(3):
        w = _world(kind, n, 0.02, seed)
        g = w.graph
        t = spanning_tree(g, tree)
        res = _ip(g, t)
        assert res.chords.size > 0 and res.status == cp.OPTIMAL
        np.testing.assert_array_equal(res.k_chords, res.rounding_k_chords)
        np.testing.assert_array_equal(res.k_chords, _true_q(w, g, t))
        assert res.objective == pytest.approx(res.rounding_objective, rel=1e-12)
        # with the box (6) off the solver searches |k − k_round| ≤ 1 and still returns the rounding
        plain = _ip(g, t, exact=False, max_shift=1)
        np.testing.assert_array_equal(plain.k, res.k)


def test_enumeration_equals_rounding_at_low_noise_many_seeds():
    for seed in range(6):
        for tree in ("bfs", "odometry", "mst"):
            w = manhattan_world(100, seed=seed, sigma_theta=0.05)
            g = w.graph
            t = spanning_tree(g, tree)
            cmp = I.compare_with_rounding(g, t, search=IntegerSearch(solver="enumerate"))
            assert cmp["equal"] and cmp["improvement"] == 0.0


# ------------------------------------------------------------------ noisy: IP ≤ rounding, parting
def test_ip_never_costs_more_than_rounding_and_sometimes_less():
    strictly = 0
    for n, sigma, seed, tree in DIFFERING + [(60, 0.5, s, "bfs") for s in range(4)]:
        w = manhattan_world(n, seed=seed, sigma_theta=sigma)
        g = w.graph
        t = spanning_tree(g, tree)
        res = _ip(g, t, solver="enumerate")
        assert res.objective <= res.rounding_objective * (1 + 1e-12)
        strictly += res.objective < res.rounding_objective * (1 - 1e-9)
    for seed in range(6):  # random graphs (random edge directions, random true orientations)
        w = random_graph(30, 55, seed=seed, sigma_theta=0.4)
        g = w.graph
        res = _ip(g, spanning_tree(g, "bfs"), solver="enumerate")
        assert res.objective <= res.rounding_objective * (1 + 1e-12)
    assert strictly >= len(DIFFERING)


@needs_scip
@pytest.mark.parametrize("n,sigma,seed,tree", DIFFERING)
def test_enumeration_equals_scip_where_they_part_from_rounding(n, sigma, seed, tree):
    w = manhattan_world(n, seed=seed, sigma_theta=sigma)
    g = w.graph
    t = spanning_tree(g, tree)
    d = I.cycle_data(g, t)
    scip = _ip(g, t, data=d)
    enum = _ip(g, t, data=d, solver="enumerate")
    assert scip.status == cp.OPTIMAL
    assert scip.n_differ > 0  # the case really parts from the rounding
    np.testing.assert_array_equal(scip.k, enum.k)
    assert scip.objective == pytest.approx(enum.objective, rel=1e-12)
    assert scip.objective < scip.rounding_objective


def test_exact_box_loses_nothing():
    """The box (6) contains the optimum: a much wider plain box gives the same answer."""
    for n, sigma, seed, tree in DIFFERING:
        w = manhattan_world(n, seed=seed, sigma_theta=sigma)
        g = w.graph
        t = spanning_tree(g, tree)
        d = I.cycle_data(g, t)
        q, J, _ = _enumerate(d)
        q_wide, J_wide, _ = _enumerate(d, exact=False, max_shift=3)
        np.testing.assert_array_equal(q, q_wide)
        lo, hi, restricted = I.exact_box(d)
        assert not restricted and np.all((lo <= q) & (q <= hi))
        # at low noise the box is a single point: the rounding is certified optimal without search
    w = manhattan_world(100, seed=0, sigma_theta=0.02)
    d = I.cycle_data(w.graph, spanning_tree(w.graph, "bfs"))
    lo, hi, _ = I.exact_box(d)
    np.testing.assert_array_equal(lo, d.k_round)
    np.testing.assert_array_equal(hi, d.k_round)
    lo, hi, restricted = I.exact_box(I.cycle_data(*_two_cycles_graph()), max_shift=0)
    assert restricted


def test_ip_answer_does_not_depend_on_the_tree():
    """J is phase 1's cost, which has no tree: every tree gives the same optimum (up to the gauge)."""
    w = manhattan_world(60, seed=1, sigma_theta=0.4)
    g = w.graph
    unc = edge_uncertainty(g)
    results = [_ip(g, spanning_tree(g, kind), solver="enumerate", unc=unc)
               for kind in ("bfs", "odometry", "mst")]
    thetas = [P.phase1_closed_form(g, r.delta_reg, unc, anchor=0).theta for r in results]
    for r, th in zip(results[1:], thetas[1:]):
        assert r.objective == pytest.approx(results[0].objective, rel=1e-9)
        assert np.abs(wrap_angle(th - thetas[0])).max() < 1e-9
    # while the rounding does depend on it
    assert len({round(r.rounding_objective, 6) for r in results}) > 1


# -------------------------------------------------------------------------- cycle integers, gauge
def test_cycle_integers_are_gauge_invariant_and_match_the_cycle_basis():
    w = random_graph(25, 50, seed=2, sigma_theta=0.1)
    g = w.graph
    t = spanning_tree(g, "bfs")
    C = cycle_basis(g, t)
    rng = np.random.default_rng(1)
    k = rng.integers(-3, 4, g.n_edges)
    q = I.cycle_integers(g, t, k)
    np.testing.assert_array_equal(q, np.rint(C @ k).astype(int))
    # brief's definition: round((C(δ + 2πk) − Cδ)/2π)
    np.testing.assert_array_equal(q, np.rint((C @ (g.delta + 2 * np.pi * k) - C @ g.delta) / (2 * np.pi)))
    # integer pose shifts z move k by A2ᵀz and change nothing
    z = rng.integers(-2, 3, g.n_poses - 1)
    k2 = k + np.rint(reduced_incidence(g, 0).T @ z).astype(int)
    np.testing.assert_array_equal(I.cycle_integers(g, t, k2), q)
    d = I.cycle_data(g, t)
    assert I.weighted_cycle_cost(g, t, k2, data=d) == pytest.approx(I.weighted_cycle_cost(g, t, k, data=d))
    with pytest.raises(ValueError, match="integer"):
        I.cycle_integers(g, t, k + 0.5)
    # the ground-truth integers reproduce the true orientation differences
    kt = edge_integers(g, w.truth[:, 2])
    err = g.delta + 2 * np.pi * kt - (w.truth[g.heads, 2] - w.truth[g.tails, 2])
    assert np.abs(err).max() < 0.6


# --------------------------------------------------------------------------------- the phases
@pytest.mark.parametrize("solver", ["enumerate", pytest.param("SCIP", marks=needs_scip)])
def test_delta_reg_plugs_into_the_phases(solver):
    w = manhattan_world(60, seed=1, sigma_theta=0.3)
    g = w.graph
    t = spanning_tree(g, "odometry")
    unc = edge_uncertainty(g)
    res = _ip(g, t, solver=solver, unc=unc)
    assert res.n_differ > 0
    a = int(g.ids[t.root])
    ph1 = P.phase1_closed_form(g, res.delta_reg, unc, anchor=a)
    ph2 = P.phase2(g, ph1.theta, unc, anchor=a, delta_reg=res.delta_reg)
    ph3 = P.phase3_closed_form(g, ph2)
    assert np.all(np.isfinite(ph3.poses)) and ph3.poses.shape == (g.n_poses, 3)
    # phase 1's residual cost on δ_reg is the IP's objective (eq. (1) = eq. (3))
    r1 = unc.sqrt_info_delta * (reduced_incidence(g, a).T @ ph1.theta_free - res.delta_reg)
    assert r1 @ r1 == pytest.approx(res.objective, rel=1e-8)
    # corrected cycles: C δ_reg = r + 2πq
    C = cycle_basis(g, t)
    d = I.cycle_data(g, t, unc=unc)
    np.testing.assert_allclose(C @ res.delta_reg, d.r + 2 * np.pi * res.k_chords, atol=1e-9)
    # here the IP recovers the true cycle integers and the rounding does not; LAGO on the IP's δ_reg
    # is far better than LAGO with the seed's rounding (same tree, same phases)
    np.testing.assert_array_equal(res.k_chords, _true_q(w, g, t))
    base = lago(g, route="seed")
    assert chi2(g, ph3.poses) < 0.2 * base.chi2
    # and the phase-1 orientations are closer to the truth (modulo 2π) than with the rounding
    ph1r = P.phase1_closed_form(g, g.delta + 2 * np.pi * res.rounding_k, unc, anchor=a)
    err_ip = np.abs(wrap_angle(ph1.theta - w.truth[:, 2])).mean()
    err_round = np.abs(wrap_angle(ph1r.theta - w.truth[:, 2])).mean()
    assert err_ip < 0.5 * err_round
    # on rounding's δ_reg the same phases reproduce lago()
    np.testing.assert_allclose(ph1r.theta, base.phase1.theta, atol=1e-9)


# ------------------------------------------------------------------------------- solver plumbing
def test_missing_solver_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyscipopt", None)  # makes `import pyscipopt` raise ImportError
    g, t = _two_cycles_graph()
    with pytest.raises(MissingSolverError, match=r'pip install "lago-cvx\[mip\]"') as info:
        _ip(g, t, solver="SCIP")
    assert isinstance(info.value, ImportError)
    # the dependency-free path still works
    assert _ip(g, t, solver="enumerate").k_chords.tolist() == [0, 0]


def test_unknown_solver_and_bad_options():
    g, t = _two_cycles_graph()
    with pytest.raises(MissingSolverError, match="not installed"):
        _ip(g, t, solver="NO_SUCH_SOLVER")
    with pytest.raises(ValueError, match="form"):
        _ip(g, t, solver="enumerate", form="magic")
    with pytest.raises(ValueError, match="max_shift"):
        _ip(g, t, solver="enumerate", exact=False)


def test_enumeration_node_budget():
    w = manhattan_world(80, seed=2, sigma_theta=0.5)
    d = I.cycle_data(w.graph, spanning_tree(w.graph, "odometry"))
    with pytest.raises(SearchLimitError, match="after 5 nodes.*raise max_nodes") as info:
        _enumerate(d, exact=False, max_shift=3, max_nodes=5)
    assert isinstance(info.value, RuntimeError) and info.value.exit_status == 4


def test_tree_graph_has_nothing_to_decide():
    truth = np.array([[0, 0, 0], [1, 0, 3.0], [2, 0, -3.0]])
    from helpers import graph_from_truth
    g = graph_from_truth(truth, [0, 1], [1, 2])
    res = _ip(g, spanning_tree(g, "bfs"), solver="enumerate")
    assert res.chords.size == 0 and res.objective == 0.0 and np.all(res.k == 0)


def test_noise_sweep_rows():
    rows = integer_noise_sweep(sigmas=(0.02, 0.5), seeds=range(3), n_poses=60)
    assert [r["sigma_theta"] for r in rows] == [0.02, 0.5]
    low, high = rows
    assert low["cases"] == 3 and low["ip_eq_round"] == 1.0 and low["ip_eq_true"] == 1.0
    assert high["ip_better"] > 0 and high["J_round"] > high["J_ip"]
    table = format_integer_sweep(rows)
    assert table.count("\n") == 3 and "IP = round" in table


# ----------------------------------------------------------------------------- lago(regularization="integer")
def test_lago_integer_equals_tree_rounding_at_low_noise():
    g = manhattan_world(80, seed=3, sigma_theta=0.05).graph
    tree_res = lago(g, regularization="tree")
    int_res = lago(g, regularization="integer")
    assert int_res.regularization.regularization == "integer"
    assert int_res.regularization.integer.n_differ == 0
    np.testing.assert_array_equal(int_res.regularization.cycle_k, tree_res.regularization.cycle_k)
    np.testing.assert_allclose(int_res.poses, tree_res.poses, rtol=0, atol=1e-12)


def test_lago_integer_minimises_phase1_cost_where_rounding_does_not():
    # Manhattan, 100 poses, σθ = 0.4, seed 2: the weighted optimum moves 2 chords away from the rounding.
    w = manhattan_world(100, seed=2, sigma_theta=0.4)
    g = w.graph
    tree_res = lago(g, regularization="tree")
    int_res = lago(g, regularization="integer")
    ip = int_res.regularization.integer
    assert ip.n_differ > 0 and ip.status == cp.OPTIMAL
    # the phase-1 cost at the integer program's δ_reg is the optimum J, strictly below the rounding's
    def phase1_cost(res):
        d = res.regularization.delta_reg
        th = res.phase1.theta
        return float(np.sum((th[g.heads] - th[g.tails] - d) ** 2 / res.uncertainty.var_delta))
    assert phase1_cost(int_res) == pytest.approx(ip.objective, rel=1e-9)
    assert phase1_cost(tree_res) == pytest.approx(ip.rounding_objective, rel=1e-9)
    assert ip.objective < 0.99 * ip.rounding_objective
    # and here it is also the right answer: the truth's cycle integers, and GN from it reaches the
    # minimum GN reaches from the ground truth, which the tree rounding misses
    t = int_res.tree
    np.testing.assert_array_equal(int_res.regularization.cycle_k, _true_q(w, g, t))
    from lago_cvx.refinement import refine
    best = refine(g, w.truth).chi2
    assert refine(g, int_res.poses).chi2 == pytest.approx(best, rel=1e-6)
    assert refine(g, tree_res.poses).chi2 > 1.2 * best


@needs_scip
def test_lago_integer_cvxpy_scip_equals_enumeration():
    g = manhattan_world(100, seed=2, sigma_theta=0.4).graph
    a = lago(g, regularization="integer")
    b = lago(g, regularization="integer", method="cvxpy")
    assert set(b.problems) == {"integer", "phase1", "phase3", "positions"}
    assert b.problems["integer"].status == cp.OPTIMAL
    np.testing.assert_array_equal(a.regularization.k, b.regularization.k)
    np.testing.assert_allclose(b.poses, a.poses, rtol=0, atol=1e-6)


def test_lago_integer_rejects_too_many_chords(monkeypatch):
    monkeypatch.setattr(I, "MAX_INTEGER_CHORDS", 3)
    g = manhattan_world(60, seed=0, sigma_theta=0.05).graph
    with pytest.raises(OptionError, match="chords .*chordal regularization"):
        lago(g, regularization="integer")


def test_lago_integer_bad_method():
    from lago_cvx.regularization import regularize_integer
    g = manhattan_world(30, seed=0).graph
    with pytest.raises(ValueError, match="unknown method"):
        regularize_integer(g, spanning_tree(g, "bfs"), method="branch")


def test_lago_integer_repairs_odometric_tree_on_mit():
    from conftest import dataset_path
    from lago_cvx.datasets import REFERENCE_CHI2
    from lago_cvx.io import read_graph
    from lago_cvx.refinement import refine
    g = read_graph(dataset_path("se-sync/MIT.g2o"))
    tree_gn = refine(g, lago(g, route="seed").poses).chi2
    res = lago(g, route="seed", regularization="integer")
    assert res.regularization.integer.n_differ == 2
    assert refine(g, res.poses).chi2 == pytest.approx(REFERENCE_CHI2["se-sync/MIT.g2o"], rel=1e-5)
    assert tree_gn > 10 * REFERENCE_CHI2["se-sync/MIT.g2o"]


@needs_scip
@pytest.mark.parametrize("time_limit", [0.3, 2.0])
def test_scip_time_limit_never_returns_worse_than_rounding(time_limit, caplog):
    # 400 poses, 288 chords, 183 integers free in the box: SCIP cannot prove optimality in seconds (the
    # enumeration does in 0.05 s) and its incumbent, if any, can be far worse than the rounding (J 1e5
    # against 291 measured). Whatever SCIP reaches, the result costs at most the rounding's J.
    g = manhattan_world(400, seed=1, sigma_theta=0.1).graph
    t = spanning_tree(g, "bfs")
    data = I.cycle_data(g, t)
    best = _ip(g, t, solver="enumerate", data=data)
    with caplog.at_level(logging.WARNING, logger="lago_cvx.regularization.integer"):
        res = _ip(g, t, solver="SCIP", data=data, time_limit=time_limit)
    assert res.objective <= res.rounding_objective * (1 + 1e-12)
    assert res.objective >= best.objective * (1 - 1e-9)
    if res.status != cp.OPTIMAL:
        assert res.status == cp.OPTIMAL_INACCURATE and "time" in res.solver_status.lower()
        assert "not proven optimal" in caplog.text or "may not be optimal" in caplog.text

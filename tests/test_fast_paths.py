"""The performance work held to the numbers: the multifrontal factorization and its selected inversion
against dense linear algebra, the isotropic position fast path against the general one, the engine
against its fallback inside LAGO, the progress throttle, and when the chordal regularizer warns."""

from __future__ import annotations

import contextlib
import logging

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.sparse import multifrontal as mf
from lago_cvx.sparse import normal_equations as ne
from lago_cvx.sparse.normal_equations import GraphElimination, plan_from_pattern
from lago_cvx.positions import PositionSolver, isotropic
from lago_cvx.progress import Progress
from lago_cvx.uncertainty import edge_uncertainty

from helpers import graph_from_truth


def _full_info_world(n, seed):
    return lc.manhattan_world(n, seed=seed, information="full").graph


@pytest.fixture(params=[1, 2, 3], ids=["b1", "b2", "b3"])
def block_size(request):
    return request.param


@pytest.mark.parametrize("engine", ["c", "numpy"])
def test_factor_solve_and_selected_inverse_match_dense(block_size, engine, monkeypatch):
    """N = MᵀM of a random edge system: the multifrontal solve and the selected inverse (eq. (T)) agree with
    numpy's dense solve and inverse to 1e-9 relative — diagonal pose blocks and the blocks of every edge — on the
    C kernels' factor and on the NumPy fallback's."""
    from lago_cvx.sparse import compiled as C

    if engine == "numpy":
        monkeypatch.setattr(C, "_C_KERNELS", [None])
    g = lc.manhattan_world(160, seed=3).graph
    b = block_size
    el = GraphElimination(g, 0)
    rng = np.random.default_rng(0)
    m = g.n_edges
    A = rng.standard_normal((m, b + 1, b))
    B = rng.standard_normal((m, b + 1, b))
    system = ne.EdgeSystem(el.tails, el.heads, A, B, rng.standard_normal((m, b + 1)), el.d)
    M = system.sparse().toarray()
    N = M.T @ M
    f = el.factor(system)
    rhs = rng.standard_normal(el.d * b)
    x = f.solve(rhs)
    ref = np.linalg.solve(N, rhs)
    assert np.abs(x - ref).max() <= 1e-9 * np.abs(ref).max()
    prow, pcol, keep = el.pairs
    off = keep & (prow != pcol)
    diag, pairs = mf.inverse_blocks(f.numeric, prow[off], pcol[off])
    inv = np.linalg.inv(N)
    idx = np.arange(el.d * b).reshape(el.d, b)
    dref = np.stack([inv[np.ix_(v, v)] for v in idx])
    pref = np.stack([inv[np.ix_(idx[i], idx[j])] for i, j in zip(prow[off], pcol[off])])
    scale = np.abs(dref).max()
    assert np.abs(diag - dref).max() <= 1e-9 * scale
    assert np.abs(pairs - pref).max() <= 1e-9 * scale


def test_an_indefinite_matrix_is_refused_by_name():
    """A matrix that is not positive definite raises ``NotPositiveDefinite`` (a ``NumericalError``) from the NumPy
    fronts, never a raw LAPACK error (the C kernels: ``test_compiled``)."""
    from lago_cvx.sparse import block_factor, compiled as C

    g = lc.manhattan_world(120, seed=5).graph
    el = GraphElimination(g, 0)
    prow, pcol, keep = el.pairs
    lay = C.CompiledLayout.of(el.plan, 3)
    blocks = np.zeros((int(keep.sum()), 3, 3))
    diag = prow[keep] == pcol[keep]
    blocks[diag] = -np.eye(3)  # N = −(degree) I: negative definite
    with pytest.raises(mf.NotPositiveDefinite, match="not positive definite"):
        block_factor.factor(lay, lay.assembler(prow[keep], pcol[keep]), blocks, np.empty(int(lay.Lptr[-1])))


def test_blas_threads_sets_and_restores_the_thread_count():
    """``linalg.blas_threads`` leaves every BLAS alone unless the caller let the engine set it
    (``engine_threads(blas_threads=…)``); then it limits every loaded BLAS inside its block, lets the block change
    the limit, and restores the count it found — also when the block raises."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import scipy.linalg  # noqa: F401  (its BLAS loaded before counting, as blas_threads loads it)

    from lago_cvx.sparse.linalg import blas_threads

    def counts():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

    before = counts()
    if not before:
        pytest.skip("threadpoolctl finds no BLAS it can control in this build of NumPy/SciPy")
    from lago_cvx.sparse import engine_threads

    with blas_threads(1) as threads:  # not asked: nothing changes
        threads(1)
        assert counts() == before
    with engine_threads(blas_threads=1024), blas_threads(1) as threads:
        assert set(counts()) == {1}
        threads(None)
        assert counts() == before
        threads(1)
        assert set(counts()) == {1}
    assert counts() == before
    with pytest.raises(RuntimeError), engine_threads(blas_threads=1024), blas_threads(1):
        raise RuntimeError("inside")
    assert counts() == before


def _both(a, b):
    import contextlib

    stack = contextlib.ExitStack()
    stack.enter_context(a)
    stack.enter_context(b)
    return stack


def test_blas_threads_of_two_threads_restore_the_count_they_found():
    """The count restored is the one the process has when the block starts — not the one when the BLAS
    libraries were first found (a user may have changed it since) — and blocks of two threads that
    overlap (A enters, B enters, A leaves, B leaves) leave the count found before the first."""
    import threading

    threadpoolctl = pytest.importorskip("threadpoolctl")
    import scipy.linalg  # noqa: F401

    from lago_cvx.sparse import engine_threads
    from lago_cvx.sparse.linalg import blas_threads as engine_blas

    def blas_threads(n):  # as the engine runs when asked to set the BLAS threads
        return _both(engine_threads(blas_threads=1024), engine_blas(n))

    def counts():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

    with blas_threads(None):  # the libraries found (at the process's count)
        pass
    with threadpoolctl.threadpool_limits(1, user_api="blas"):  # the user changes it afterwards
        with blas_threads(None):
            pass
        assert set(counts()) <= {1}
    with threadpoolctl.threadpool_limits(2, user_api="blas"):
        before = counts()
        if not before or max(before) < 2:
            pytest.skip("no BLAS whose thread count can be raised to 2 here")
        a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()

        def a():
            with blas_threads(1):
                a_in.set()
                b_in.wait(10)
            a_out.set()

        def b():
            a_in.wait(10)
            with blas_threads(1):
                b_in.set()
                a_out.wait(10)

        ta, tb = threading.Thread(target=a), threading.Thread(target=b)
        ta.start(), tb.start()
        ta.join(20), tb.join(20)
        assert counts() == before


def test_plan_is_a_valid_elimination():
    """Every update row of a front lies in its parent's front (the extend-add needs it), pivots cover
    each pose once, and the structure contains every edge."""
    g = lc.manhattan_world(400, seed=1).graph
    d = g.n_poses - 1
    plan = plan_from_pattern(d, g.tails[(g.tails > 0) & (g.heads > 0)] - 1, g.heads[(g.tails > 0) & (g.heads > 0)] - 1)
    assert np.array_equal(np.sort(plan.position), np.arange(d))
    for f in range(plan.n_fronts):
        rows = plan.rows[plan.rptr[f]:plan.rptr[f + 1]]
        p = plan.parent[f]
        if p < 0:
            assert rows.size == 0
            continue
        front_p = np.r_[np.arange(plan.fptr[p], plan.fptr[p + 1]), plan.rows[plan.rptr[p]:plan.rptr[p + 1]]]
        assert np.isin(rows, front_p).all()
    assert plan.flops(3) > plan.flops(1) > 0


def test_pose_covariances_and_variances_match_the_dense_inverse():
    """LAGO's pose covariances (phase 3, eq. (15)) and phase-1 variances by selected inversion = blocks of
    the dense inverse, to 1e-9 relative, on a full-information world: phase 3 factored in C (the covariances then
    factor it again by the NumPy engine) and by the NumPy engine (the fallback without C kernels)."""
    g = _full_info_world(200, 4)
    for numpy in (False, True):
        with _numpy_engine(numpy):
            res = lc.lago(g)
        assert res.phase3.factor.pose_major.backend == ("multifrontal" if numpy else "compiled")
        cov = res.phase3.pose_covariances()
        full = np.linalg.inv(res.phase3.info.toarray())
        d = g.n_poses - 1
        free = np.delete(np.arange(g.n_poses), res.anchor_index)
        for r, i in enumerate(free):
            v = [2 * r, 2 * r + 1, 2 * d + r]
            assert np.abs(cov[i] - full[np.ix_(v, v)]).max() <= 1e-9 * np.abs(full).max()
        assert np.all(cov[res.anchor_index] == 0)
        var = res.phase1.variances()
        ref = np.diag(np.linalg.inv(res.phase1.info.toarray()))
        assert np.abs(var[free] - ref).max() <= 1e-9 * ref.max()


def test_a_phase_factor_is_the_phase_matrix_in_its_own_numbering():
    """``Phase.factor`` solves ``Phase.info`` and ``factor.matrix`` *is* ``info`` (whole, symmetric, same
    numbering) — in C and by the NumPy engine — so column solves on it give the covariance blocks (a renumbered,
    upper-triangular matrix once made them nonsense)."""
    g = lc.manhattan_world(150, seed=6).graph
    for numpy in (False, True):
        with _numpy_engine(numpy):
            res = lc.lago(g, information="marginal", positions="phase3", regularization="tree")
        ph = res.phase3
        info = ph.info.toarray()
        if ph.factor.matrix is not None:
            assert np.abs(ph.factor.matrix.toarray() - info).max() <= 1e-12 * np.abs(info).max()
        x = np.random.default_rng(0).standard_normal(info.shape[0])
        assert np.abs(info @ ph.factor.solve(x) - x).max() <= 1e-8 * np.abs(x).max()
        d = g.n_poses - 1
        free = np.delete(np.arange(g.n_poses), res.anchor_index)
        rows = np.stack([2 * np.arange(d), 2 * np.arange(d) + 1, 2 * d + np.arange(d)], 1)
        X = ph.factor.solve(np.eye(info.shape[0])[:, rows.reshape(-1)])[rows.reshape(-1)].reshape(d, 3, d, 3)
        blocks = X[np.arange(d), :, np.arange(d)]
        cov = ph.pose_covariances()[free]
        assert np.abs(blocks - cov).max() <= 1e-9 * np.abs(cov).max()


@contextlib.contextmanager
def _numpy_engine(on: bool = True):
    """The engine as after an install without a C compiler (the NumPy multifrontal), or as it is."""
    from lago_cvx.sparse import compiled as C

    saved = list(C._C_KERNELS)
    if on:
        C._C_KERNELS[:] = [None]
    try:
        yield
    finally:
        C._C_KERNELS[:] = saved


def test_the_c_kernels_and_the_numpy_fallback_give_the_same_lago():
    """The C kernels and the NumPy engine (forced, as without a compiler) solve the same systems: LAGO's poses
    agree to 1e-10."""
    g = lc.manhattan_world(300, seed=2).graph
    ref = lc.lago(g)
    with _numpy_engine():
        eng = lc.lago(g)
    assert eng.phase3.factor.pose_major.backend == "multifrontal"
    assert np.abs(eng.poses - ref.poses).max() <= 1e-10 * np.abs(ref.poses).max()
    assert eng.chi2 == pytest.approx(ref.chi2, rel=1e-10)


def test_isotropic_positions_fast_path_equals_the_general_path():
    """With Ω_pp = s I₂ the positions (P) are solved as two d × d Laplacian problems with one factorization;
    the general 2d × 2d path gives the same positions to 1e-10."""
    g = lc.manhattan_world(300, seed=7).graph
    unc = edge_uncertainty(g)
    assert isotropic(unc)
    el = GraphElimination(g, 0)
    theta = lc.lago(g).phase1.theta
    fast = PositionSolver(g, unc, el)
    slow = PositionSolver(g, unc, el)
    slow.isotropic = False
    for th in (theta, theta + 0.01 * np.sin(np.arange(g.n_poses))):
        a = fast(th, anchor_position=(1.0, -2.0)).poses
        b = slow(th, anchor_position=(1.0, -2.0)).poses
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    assert fast._factor is not None  # the one factorization, reused
    # and the whole LAGO route: same χ² either way
    res = lc.lago(g)
    assert not isotropic(edge_uncertainty(_full_info_world(50, 0)))
    ref = lc.lago(g, backend="qdldl")  # the sparse-design route of before
    assert res.chi2 == pytest.approx(ref.chi2, rel=1e-10)


def test_progress_is_throttled_and_bracketed(caplog):
    """The callback gets 0.0 at the start, at most one call per interval, and 1.0 at the end; the log
    gets INFO records only for a stage longer than the interval."""
    now = [0.0]
    calls = []
    tracker = Progress("test stage", callback=lambda s, f: calls.append((s, f, now[0])),
                       logger=logging.getLogger("lago_cvx.test"), interval=1.0, clock=lambda: now[0])
    with caplog.at_level(logging.INFO, logger="lago_cvx.test"):
        for i in range(100):
            now[0] = 0.05 * i  # 5 s in steps of 50 ms
            tracker.update(i, 100)
        tracker.finish()
        tracker.finish()  # once only
    fractions = [f for _, f, _ in calls]
    assert fractions[0] == 0.0 and fractions[-1] == 1.0
    times = [t for _, _, t in calls[1:-1]]
    assert 3 <= len(times) <= 5 and np.all(np.diff(times) >= 1.0 - 1e-12)
    assert all(s == "test stage" for s, _, _ in calls)
    assert sum("test stage" in r.message for r in caplog.records) == len(times) + 1
    # a quick stage: callback bracketed, no log record
    caplog.clear()
    quick = []
    with caplog.at_level(logging.INFO, logger="lago_cvx.test"):
        with Progress("quick", callback=lambda s, f: quick.append(f), logger=logging.getLogger("lago_cvx.test"),
                      clock=lambda: 0.0) as t:
            t.update(0.5)
    assert quick == [0.0, 1.0] and not caplog.records


def test_lago_reports_progress_through_its_callback(monkeypatch):
    """``lago(progress=...)`` reaches the long steps: phase 3's factorization reports (stage names, fractions in
    [0, 1], ending at 1.0)."""
    seen = []
    lc.lago(lc.manhattan_world(200, seed=0).graph, progress=lambda s, f: seen.append((s, f)))
    stages = {s for s, _ in seen}
    assert "phase 3" in stages
    assert all(0.0 <= f <= 1.0 for _, f in seen)
    assert [f for s, f in seen if s == "phase 3"][-1] == 1.0


def _ambiguous_pair_graph(delta_gap):
    """Poses 0, 1, 2 in a triangle plus a second edge 1 → 2 whose orientation disagrees with the first by
    ``delta_gap`` (rad)."""
    truth = np.array([[0, 0, 0], [1, 0, 0.5], [1, 1, 1.2]])
    g = graph_from_truth(truth, [0, 1, 0, 1], [1, 2, 2, 2])
    delta = g.delta.copy()
    delta[3] = delta[1] + delta_gap
    return lc.PoseGraph(3, g.tails, g.heads, g.delta_l, delta, g.information)


def test_chordal_warns_only_on_an_ambiguous_rounding(caplog):
    """Near-noiseless graphs: no warning. Two parallel measurements contradicting each other by ≈ π:
    the rounding is a near tie, warned and listed in ``ambiguous``. A small ‖r_i‖ alone is only a DEBUG
    record."""
    with caplog.at_level(logging.WARNING, logger="lago_cvx"):
        res = lc.lago(lc.manhattan_world(300, seed=0, sigma_theta=1e-4, sigma_xy=1e-4).graph)
    assert res.regularization.ambiguous.size == 0
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="lago_cvx"):
        res = lc.lago(_ambiguous_pair_graph(np.pi - 0.05))
    assert res.regularization.ambiguous.size > 0
    assert any("ambiguous" in r.message for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.DEBUG, logger="lago_cvx.regularization.chordal"):
        res = lc.lago(_ambiguous_pair_graph(1.0))  # disagreeing, but far from a tie
    assert res.regularization.ambiguous.size == 0
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.mark.parametrize("q, b, extra", [(1, 1, ()), (3, 3, ()), (2, 2, (4,)), (4, 3, (2, 3))])
def test_edge_operator_is_the_sparse_matrix(q, b, extra):
    """``EdgeSystem.matvec``/``rmatvec`` (the compiled loops) and the NumPy ``EdgeOperator`` (component-major products
    and one bincount, their fallback) equal M x and Mᵀ r with M the system's sparse matrix, for one and several right-hand sides, edges
    at the anchor (−1) at either end and parallel edges."""
    rng = np.random.default_rng(q * 10 + b)
    m, d = 60, 17
    tails, heads = rng.integers(-1, d, m), rng.integers(-1, d, m)
    tails[:5], heads[:5] = 3, 7  # parallel edges
    system = ne.EdgeSystem(tails, heads, rng.standard_normal((m, q, b)), rng.standard_normal((m, q, b)),
                           rng.standard_normal((m, q)), d)
    M = system.sparse().toarray()
    k = int(np.prod(extra, dtype=int))
    x = rng.standard_normal((d, b) + extra)
    r = rng.standard_normal((m, q) + extra)
    from lago_cvx.sparse.edge_system import EdgeOperator

    op = EdgeOperator(system)
    for mv, rv in ((system.matvec(x), system.rmatvec(r)), (op.matvec(x), op.rmatvec(r))):
        assert mv.shape == (m, q) + extra and rv.shape == (d, b) + extra
        assert np.allclose(mv.reshape(m * q, k), M @ x.reshape(d * b, k), rtol=1e-13, atol=1e-13)
        assert np.allclose(rv.reshape(d * b, k), M.T @ r.reshape(m * q, k), rtol=1e-13, atol=1e-13)


def _csgraph_postorder(parent):
    """The reversed depth-first preorder of ``scipy.sparse.csgraph`` from a virtual root above the roots."""
    import scipy.sparse as sp
    from scipy.sparse import csgraph

    n = parent.size
    par = np.where(parent < 0, n, parent)
    children = sp.csr_matrix((np.ones(n), (par, np.arange(n))), shape=(n + 1, n + 1))
    return csgraph.depth_first_order(children, n, directed=True, return_predecessors=False)[:0:-1].astype(np.int64)


def test_postorder_equals_scipys_depth_first_order():
    """``multifrontal._postorder`` gives exactly the order of the reversed depth-first preorder of
    ``scipy.sparse.csgraph`` (the elimination order, hence every result, is unchanged), in C and by the Python loops
    of the fallback, on random elimination trees, a star and a chain."""
    from lago_cvx.sparse import multifrontal
    from lago_cvx.sparse import compiled as C

    ways = {"python": multifrontal.postorder, "c": C.kernels()["postorder"]}
    rng = np.random.default_rng(3)
    forests = [np.array([-1]), np.array([-1, -1, -1]), np.array([1, 2, -1]), np.array([2, 2, -1, -1]),
               np.r_[np.full(500, 500), -1], np.r_[np.arange(1, 500), -1]]  # a star, a chain
    for n in (5, 40, 300, 2000):
        parent = np.full(n, -1, np.int64)
        for i in range(n - 1):
            if rng.random() < 0.9:
                parent[i] = rng.integers(i + 1, min(n, i + 1 + rng.integers(1, 30)))
        forests.append(parent)
    for parent in forests:
        parent = np.asarray(parent, np.int64)
        ref = _csgraph_postorder(parent)
        assert np.array_equal(multifrontal._postorder(parent), ref)
        for name, way in ways.items():
            assert np.array_equal(way(parent.copy()), ref), (name, parent[:20])
        place = np.empty(parent.size, np.int64)
        place[ref] = np.arange(parent.size)
        has = parent >= 0
        assert (place[has] < place[parent[has]]).all()  # children before parents

"""QDLDL called directly in the pose-level elimination order (``lago_cvx.sparse.ldl``,
``upper_pattern.BlockUpperPattern``): the scattered upper triangle is exactly MᵀM, the factor solves
like a dense solve, its column counts are the symbolic fill of that order, bad input is refused by name,
and LAGO gives the same answer through ``qdldl.Solver`` (the fallback when the C routines are not
exported as expected)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import lago_cvx as lc
from lago_cvx.sparse import ldl
from lago_cvx.sparse import normal_equations as ne
from lago_cvx.errors import NumericalError
from lago_cvx.sparse.normal_equations import GraphElimination

from helpers import graph_from_truth

pytestmark = pytest.mark.skipif(not ldl.available(), reason="qdldl's C routines are not exported by this build")


def _graph_with_parallel_edges(anchor_index):
    """A small graph with parallel edges in both directions, loops through the anchor and a pose whose
    only edges touch the anchor."""
    rng = np.random.default_rng(4)
    truth = np.c_[rng.uniform(-5, 5, (9, 2)), rng.uniform(-np.pi, np.pi, 9)]
    tails = [0, 1, 2, 3, 4, 5, 6, 7, 2, 3, 5, 0, 6, 1, 8, 8]
    heads = [1, 2, 3, 4, 5, 6, 7, 2, 1, 2, 1, 4, 3, 2, 0, anchor_index if anchor_index != 8 else 0]
    g = graph_from_truth(truth, np.array(tails), np.array(heads))
    return g


def _random_system(el, b, seed):
    rng = np.random.default_rng(seed)
    m = el.tails.size
    return ne.EdgeSystem(el.tails, el.heads, rng.standard_normal((m, b + 1, b)), rng.standard_normal((m, b + 1, b)),
                         rng.standard_normal((m, b + 1)), el.d)


@pytest.mark.parametrize("b", [1, 2, 3])
@pytest.mark.parametrize("anchor_index", [0, 4])
def test_scattered_upper_triangle_is_the_normal_matrix(b, anchor_index):
    """``BlockUpperPattern``: indptr/indices a valid upper-triangular CSC (sorted rows, diagonal last in
    every column), and the values it scatters from ``normal_blocks`` give MᵀM exactly as SciPy forms it,
    parallel edges summed and blocks of edges whose later-eliminated end is the head transposed."""
    g = _graph_with_parallel_edges(anchor_index)
    el = GraphElimination(g, anchor_index)
    system = _random_system(el, b, seed=b)
    pat = el.upper_pattern(b)
    n = el.d * b
    ip, ix = pat.indptr, pat.indices
    assert ip[0] == 0 and ip[-1] == pat.nnz == ix.size
    for j in range(n):
        col = ix[ip[j]:ip[j + 1]]
        assert np.all(np.diff(col) > 0) and col[-1] == j
    M = system.sparse()
    N = (M.T @ M).toarray()
    assert np.allclose(pat.matrix(pat.values(system.normal_blocks())).toarray(), N, rtol=1e-13, atol=1e-12)
    # in elimination order: the upper triangle of N permuted by the slots
    U = sp.csc_matrix((pat.values(system.normal_blocks()), ix, ip), shape=(n, n)).toarray()
    perm = pat.order
    assert np.allclose(U, np.triu(N[np.ix_(perm, perm)]), rtol=1e-13, atol=1e-12)


@pytest.mark.parametrize("b", [1, 2, 3])
def test_factor_solves_like_a_dense_solve(b):
    """The QDLDL factor in the pose order solves N x = y (one and several right-hand sides) to 1e-10
    relative against numpy, and ``GraphElimination.factor`` uses it (backend "qdldl")."""
    g = lc.manhattan_world(150, seed=2).graph
    el = GraphElimination(g, 0)
    system = _random_system(el, b, seed=7)
    M = system.sparse().toarray()
    N = M.T @ M
    f = el.factor(system, engine=False)
    assert isinstance(f, ne.QdldlFactor) and f.backend == "qdldl"
    rng = np.random.default_rng(1)
    y = rng.standard_normal(el.d * b)
    Y = rng.standard_normal((el.d * b, 3))
    scale = np.abs(np.linalg.solve(N, y)).max()
    assert np.abs(f.solve(y) - np.linalg.solve(N, y)).max() <= 1e-10 * scale
    X = f.solve(Y)
    assert X.shape == (el.d * b, 3)
    assert np.abs(X - np.linalg.solve(N, Y)).max() <= 1e-10 * np.abs(X).max()
    assert np.allclose(f.matrix.toarray(), N, rtol=1e-12, atol=1e-11)


def _symbolic_column_counts(U: np.ndarray) -> np.ndarray:
    """Entries strictly below the diagonal in each column of L, by eliminating the pattern of the dense
    symmetric matrix with upper triangle U column by column (the graph model of elimination)."""
    n = U.shape[0]
    S = (U != 0) | (U != 0).T
    counts = np.zeros(n, np.int64)
    for j in range(n):
        below = np.flatnonzero(S[j + 1:, j]) + j + 1
        counts[j] = below.size
        S[np.ix_(below, below)] = True  # the fill: the later neighbours of j become a clique
    return counts


def test_column_counts_are_the_fill_of_the_pose_order():
    """``LDLPattern.Lnz`` equals the symbolic fill of the given order (no reordering inside), and
    ``QdldlFactor.flops`` is Σ (count + 1)²."""
    g = lc.manhattan_world(60, seed=1).graph
    el = GraphElimination(g, 0)
    pat = el.upper_pattern(2)
    n = el.d * 2
    U = sp.csc_matrix((np.ones(pat.nnz), pat.indices, pat.indptr), shape=(n, n)).toarray()
    counts = _symbolic_column_counts(U)
    assert np.array_equal(pat.ldl.Lnz, counts)
    assert pat.ldl.nnz_L == counts.sum()
    f = el.factor(_random_system(el, 2, seed=0), engine=False)
    assert f.flops() == pytest.approx(float(((counts + 1.0) ** 2).sum()))


@pytest.mark.parametrize("b", [1, 2, 3])
@pytest.mark.parametrize("anchor_index", [0, 4])
def test_expanded_analysis_is_qdldl_etree_of_the_expanded_pattern(b, anchor_index):
    """``LDLPattern.expanded`` (the pose-level elimination tree and column counts expanded to b×b blocks)
    is exactly what ``QDLDL_etree`` computes on the b-expanded pattern, on a world and on a graph with
    parallel edges, loops through the anchor and a pose joined only to the anchor."""
    for g in (lc.manhattan_world(80, seed=5).graph, _graph_with_parallel_edges(anchor_index)):
        el = GraphElimination(g, anchor_index)
        pat = el.upper_pattern(b)
        direct = ldl.LDLPattern(pat.indptr, pat.indices)
        assert np.array_equal(pat.ldl.etree, direct.etree)
        assert np.array_equal(pat.ldl.Lnz, direct.Lnz)
        assert pat.ldl.nnz_L == direct.nnz_L and pat.ldl.n == direct.n


def test_bad_patterns_and_zero_pivots_are_refused_by_name():
    """A pattern that is not upper triangular, or a column without its diagonal, raises NumericalError
    from QDLDL_etree; a zero pivot raises it from QDLDL_factor — never a crash or a silent answer."""
    lower = sp.csc_matrix(np.array([[1.0, 0.0], [1.0, 1.0]]))
    with pytest.raises(NumericalError, match="not upper triangular"):
        ldl.LDLPattern(lower.indptr, lower.indices)
    empty = sp.csc_matrix((np.ones(1), np.array([0]), np.array([0, 1, 1])), shape=(2, 2))
    with pytest.raises(NumericalError, match="not upper triangular"):
        ldl.LDLPattern(empty.indptr, empty.indices)
    U = sp.csc_matrix(np.array([[1.0, 1.0], [0.0, 1.0]]))  # [[1, 1], [1, 1]]: second pivot 0
    pat = ldl.LDLPattern(U.indptr, U.indices)
    with pytest.raises(NumericalError, match="zero pivot"):
        pat.factor(U.data)
    with pytest.raises(ValueError, match="values for a pattern"):
        pat.factor(np.ones(5))


def test_missing_symbols_fall_back_to_qdldl_solver(monkeypatch):
    """When the ABI symbol is not exported (another build of qdldl) ``available()`` is False and LAGO
    factors through ``qdldl.Solver``; both routes give the same estimate (1e-12) on a real-size world,
    default and seed routes."""
    g = lc.manhattan_world(400, seed=3).graph
    direct = {r: lc.lago(g, route=r) for r in ("default", "seed")}
    monkeypatch.setattr(ldl, "_ABI_SYMBOL", "no_such_symbol_in_qdldl")
    monkeypatch.setattr(ldl, "_LIB", [])
    assert not ldl.available()
    el = GraphElimination(g, 0)
    assert el.upper_pattern(3) is None
    for r, ref in direct.items():
        res = lc.lago(g, route=r)
        assert res.phase3.factor.backend == "qdldl"
        assert np.abs(res.poses - ref.poses).max() <= 1e-12 * np.abs(ref.poses).max()
        assert res.chi2 == pytest.approx(ref.chi2, rel=1e-12)
    monkeypatch.setattr(ldl, "_LIB", [])  # the next caller looks again


def test_one_pattern_per_block_size_is_shared():
    """The pattern (and its etree) is built once per b for a graph and shared by every system of that
    size; the values differ per system."""
    g = lc.manhattan_world(80, seed=6).graph
    el = GraphElimination(g, 0)
    assert el.upper_pattern(2) is el.upper_pattern(2)
    assert el.upper_pattern(2) is not el.upper_pattern(3)
    s1, s2 = _random_system(el, 2, 1), _random_system(el, 2, 2)
    f1, f2 = el.factor(s1, engine=False), el.factor(s2, engine=False)
    y = np.ones(el.d * 2)
    for s, f in ((s1, f1), (s2, f2)):
        M = s.sparse()
        assert np.allclose((M.T @ M) @ f.solve(y), y, atol=1e-8)


def test_progress_is_reported_while_qdldl_runs(monkeypatch):
    """With a progress callback the factorization runs in a worker thread and reports (done, total):
    0 first, total last, never decreasing, and the factor is bit for bit the one of the plain call."""
    monkeypatch.setattr(ldl, "PROGRESS_POLL", 0.0)
    g = lc.manhattan_world(3000, seed=8).graph
    el = GraphElimination(g, 0)
    pat = el.upper_pattern(3)
    data = pat.values(_random_system(el, 3, seed=5).normal_blocks())
    calls = []
    watched = pat.ldl.factor(data, progress=lambda done, total: calls.append((done, total)))
    plain = pat.ldl.factor(data)
    total = calls[0][1]
    assert total == pytest.approx(pat.ldl.flops())
    assert calls[0][0] == 0.0 and calls[-1] == (total, total)
    done = [c[0] for c in calls]
    assert all(a <= b for a, b in zip(done, done[1:]))
    for name in ("Lp", "Li", "Lx", "D", "Dinv"):
        assert np.array_equal(getattr(watched, name), getattr(plain, name))
    # with work beside it as well: run once, before the progress, and the same factor
    beside, order = [], []
    both = pat.ldl.factor(data, progress=lambda done, total: order.append("progress"),
                          meanwhile=lambda: (beside.append(1), order.append("meanwhile")))
    assert beside == [1] and order[0] == "meanwhile" and order.count("meanwhile") == 1 and len(order) >= 3
    for name in ("Lp", "Li", "Lx", "D", "Dinv"):
        assert np.array_equal(getattr(both, name), getattr(plain, name))
    # and through the elimination, as LAGO calls it
    seen = []
    el.factor(_random_system(el, 3, seed=6), engine=False, progress=lambda i, n: seen.append(i / n))
    assert seen[0] == 0.0 and seen[-1] == 1.0


def test_a_failing_progress_callback_waits_for_qdldl(monkeypatch):
    """An exception from the callback is raised only after the C call has returned (it writes into
    arrays this side holds), and the pattern stays usable."""
    monkeypatch.setattr(ldl, "PROGRESS_POLL", 0.0)
    g = lc.manhattan_world(2000, seed=9).graph
    el = GraphElimination(g, 0)
    pat = el.upper_pattern(3)
    data = pat.values(_random_system(el, 3, seed=1).normal_blocks())

    def boom(done, total):
        raise RuntimeError("stop")

    with pytest.raises(RuntimeError, match="stop"):
        pat.ldl.factor(data, progress=boom)
    with pytest.raises(RuntimeError, match="beside"):  # so does one from the work beside it
        pat.ldl.factor(data, meanwhile=lambda: (_ for _ in ()).throw(RuntimeError("beside")))
    import threading
    assert not any(t.name == "qdldl-factor" and t.is_alive() for t in threading.enumerate())
    f = pat.ldl.factor(data)
    assert f.n_positive == pat.ldl.n


@pytest.mark.parametrize("q", [1, 2, 4])
@pytest.mark.parametrize("b", [1, 2, 3])
def test_normal_entries_are_the_normal_blocks(b, q):
    """``EdgeSystem.normal_entries`` (entry by entry) holds the blocks of ``normal_blocks`` (stacked
    products) to rounding, and the pattern scatters both to the same values."""
    g = _graph_with_parallel_edges(0)
    el = GraphElimination(g, 0)
    rng = np.random.default_rng(b * 10 + q)
    m = el.tails.size
    system = ne.EdgeSystem(el.tails, el.heads, rng.standard_normal((m, q, b)), rng.standard_normal((m, q, b)),
                           rng.standard_normal((m, q)), el.d)
    blocks = system.normal_blocks()
    entries = system.normal_entries()
    assert entries.shape == (3, b, b, m)
    np.testing.assert_allclose(entries.transpose(0, 3, 1, 2).reshape(3 * m, b, b), blocks, rtol=1e-13, atol=1e-13)
    pat = el.upper_pattern(b)
    np.testing.assert_allclose(pat.values_from_entries(entries), pat.values(blocks), rtol=1e-13, atol=1e-12)


def test_deferred_work_runs_beside_the_factorization(monkeypatch):
    """``GraphElimination.ahead``: the tasks run (once, in order, in the calling thread) while QDLDL
    factors the next system in a worker thread; the factor is bitwise the one without them; a task
    that raises keeps its error for whoever asks for its result, without touching the factorization;
    LAGO hands over phase 3's pattern and the polish's θ-independent factorization and gives the same
    estimate either way."""
    import threading

    monkeypatch.setattr(ne, "OVERLAP_MIN", 0)  # (small graphs: the engine works in one thread, OVERLAP_MIN)
    g = lc.manhattan_world(300, seed=6).graph
    el = GraphElimination(g, 0)
    system = _random_system(el, 2, seed=3)
    alone = el.factor(system, engine=False)
    ran = []
    first = el.ahead(lambda: ran.append(("first", threading.current_thread() is threading.main_thread())))
    failing = el.ahead(lambda: 1 / 0)
    el.ahead(lambda: ran.append(("pattern", el.upper_pattern(3) is not None)))
    beside = el.factor(system, engine=False)
    assert ran == [("first", True), ("pattern", True)] and el.deferred_work() is None
    assert first.done and failing.done
    with pytest.raises(ZeroDivisionError):
        failing.result()
    y = np.random.default_rng(0).standard_normal(el.d * 2)
    assert np.array_equal(alone.solve(y), beside.solve(y))
    assert 3 in el._upper_patterns
    # below OVERLAP_MIN nothing runs beside: the tasks wait to be asked for
    monkeypatch.setattr(ne, "OVERLAP_MIN", 10**9)
    later = el.ahead(lambda: 7)
    el.factor(system, engine=False)
    assert not later.done and later.result() == 7
    monkeypatch.setattr(ne, "OVERLAP_MIN", 0)
    # in LAGO: the same answer with the deferral switched off
    with_defer = lc.lago(g)
    monkeypatch.setattr(GraphElimination, "deferred_work", lambda self: None)
    without = lc.lago(g)  # the polish's two trials then solved together: the same to rounding
    assert np.allclose(with_defer.poses, without.poses, rtol=1e-12, atol=1e-12)


def test_deferred_tasks_left_over_are_dropped(monkeypatch):
    """When phase 3 goes to the multifrontal engine no QDLDL factorization runs the tasks handed over: the
    engine drops phase 3's QDLDL pattern, the polish factors its system once (the task handed over is
    run when first asked for, not again beside itself) and the estimate is the all-QDLDL one."""
    g = lc.manhattan_world(400, seed=1).graph
    reference = lc.lago(g, route="seed", positions="resolve")  # no chordal factorization to run tasks beside
    d = g.n_poses - 1
    sizes = []
    original = ldl.LDLFactor.__init__

    def counting(self, pattern, data, **kw):
        sizes.append(pattern.n)
        original(self, pattern, data, **kw)

    monkeypatch.setattr(ldl.LDLFactor, "__init__", counting)
    monkeypatch.setattr(ne, "ENGINE_MIN", 2 * d + 1)  # b = 3 by the engine, b = 1 and 2 by QDLDL
    res = lc.lago(g, route="seed", positions="resolve")
    from lago_cvx.sparse import amd

    # Ω_θ's (phase 1's Laplacian, by upper_pattern.PoseLaplacian when AMD is called directly), then the
    # polish's system, once
    assert sizes == ([d, d] if amd.available() else [d])
    assert np.allclose(res.poses, reference.poses, rtol=0, atol=1e-12)

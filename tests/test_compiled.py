"""The compiled multifrontal engine (lago_cvx.sparse.compiled) held to dense linear algebra, to the NumPy engine
and to QDLDL inside LAGO: every kernel path (the right-looking loop, LAPACK/BLAS by address, a large front
on every BLAS thread), one thread and subtrees shared between two, the stack sizes, refusal of a matrix
that is not positive definite, progress, and that importing the package loads no Numba."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.sparse import compiled as C
from lago_cvx.sparse import multifrontal as mf
from lago_cvx.sparse import normal_equations as ne
from lago_cvx.sparse.normal_equations import GraphElimination

pytestmark = pytest.mark.skipif(not C.available(), reason="Numba cannot be imported here")


@pytest.fixture(params=["loops", "blas", "blas-threaded"])
def kernel(request, monkeypatch):
    """Which dense kernel factors the fronts: all by the compiled loop, all by LAPACK/BLAS called from
    compiled code, or by LAPACK/BLAS with every front handed to the caller for every BLAS thread."""
    if request.param == "loops":
        monkeypatch.setattr(C, "SMALL_WORK", 10**18)
    else:
        monkeypatch.setattr(C, "SMALL_WORK", 0)
    if request.param == "blas-threaded":
        monkeypatch.setattr(C, "THREADED_FRONT", 0)
    return request.param


@pytest.fixture(params=[1, 2], ids=["one-thread", "two-threads"])
def threads(request, monkeypatch):
    """One thread, or the subtrees shared between two threads whatever the work (PARALLEL_WORK 0)."""
    monkeypatch.setattr(C, "cores", lambda: request.param)
    monkeypatch.setattr(C, "PARALLEL_WORK", 0.0)
    return request.param


def _random_system(g, b, seed=0, anchor=0):
    el = GraphElimination(g, anchor)
    rng = np.random.default_rng(seed)
    m = g.n_edges
    A = rng.standard_normal((m, b + 1, b))
    B = rng.standard_normal((m, b + 1, b))
    return el, ne.EdgeSystem(el.tails, el.heads, A, B, rng.standard_normal((m, b + 1)), el.d)


@pytest.mark.parametrize("b", [1, 2, 3])
def test_compiled_factor_solves_like_dense_algebra(b, kernel, threads):
    """N = MᵀM of a random edge system (E) on a 300-pose world: the compiled factor's solve of one and of
    three right-hand sides equals numpy's dense solve to 1e-10 relative, by every kernel path, on one
    thread and on two."""
    g = lc.manhattan_world(300, seed=5).graph
    el, system = _random_system(g, b, seed=b)
    f = el.factor(system, engine="compiled")
    assert isinstance(f, ne.CompiledPoseFactor)
    if threads == 2:
        assert f.compiled.layout.schedule is not None
    M = system.sparse().toarray()
    N = M.T @ M
    rng = np.random.default_rng(1)
    rhs = rng.standard_normal(el.d * b)
    ref = np.linalg.solve(N, rhs)
    assert np.abs(f.solve(rhs) - ref).max() <= 1e-10 * np.abs(ref).max()
    R = rng.standard_normal((el.d * b, 3))
    refR = np.linalg.solve(N, R)
    assert np.abs(f.solve(R) - refR).max() <= 1e-10 * np.abs(refR).max()


def test_compiled_factor_is_the_numpy_engines_factor(threads):
    """The same plan factored by both engines: the compiled L's block columns equal the NumPy engine's
    [L_PP; X] front by front (to rounding), so both are the same Cholesky factor of eq. (MF)."""
    g = lc.manhattan_world(200, seed=8).graph
    el, system = _random_system(g, 3, seed=4)
    cf = el.factor(system, engine="compiled").compiled
    pf = el.factor(system, engine=True).blocks
    lay, plan = cf.layout, el.plan
    L = np.zeros((lay.N, lay.N))
    for f in range(plan.n_fronts):
        k, r = plan.pivots[f] * 3, plan.n_rows[f] * 3
        D = k + r
        col = np.zeros((D, k))  # packed columns: column j holds rows j … D − 1
        for j in range(k):
            start = lay.Lptr[f] + j * D - j * (j - 1) // 2
            col[j:, j] = cf.L[start:start + D - j]
        piv = np.arange(plan.fptr[f] * 3, plan.fptr[f + 1] * 3)
        rows = (plan.rows[plan.rptr[f]:plan.rptr[f + 1]][:, None] * 3 + np.arange(3)).reshape(-1)
        L[np.ix_(piv, piv)] = np.tril(col[:k])
        L[np.ix_(rows, piv)] = col[k:]
    N = L @ L.T
    dense = system.sparse().toarray()
    order = np.argsort(el.slots(3))  # slot → pose-major variable
    ref = (dense.T @ dense)[np.ix_(order, order)]
    assert np.abs(N - ref).max() <= 1e-10 * np.abs(ref).max()
    x = np.random.default_rng(0).standard_normal(lay.N)
    assert np.allclose(cf.solve_slots(x), pf.solve_slots(x), rtol=0, atol=1e-9 * np.abs(pf.solve_slots(x)).max())


def test_stack_sizes_hold_every_update(threads):
    """The stacks are sized by simulation, not guessed: the factorization of a 2000-pose world runs with
    exactly those sizes (NumPy raises if a push overruns), and the simulated peak of the whole postorder
    equals the largest sum of live updates computed here in Python."""
    g = lc.manhattan_world(2000, seed=2).graph
    el, system = _random_system(g, 3)
    lay = C.CompiledLayout.of(el.plan, 3)
    R2 = (el.plan.n_rows * 3) ** 2
    live, peak = [], 0
    for f in range(el.plan.n_fronts):
        c = int(lay.nchild[f])
        if c:
            del live[-c:]
        if R2[f]:
            live.append(int(R2[f]))
        peak = max(peak, sum(live))
    seq = np.arange(el.plan.n_fronts)
    assert C.kernels()["stack_peak"](seq, lay.nchild, R2.astype(np.int64)) == peak
    el.factor(system, engine="compiled")


@pytest.mark.parametrize("where", ["loops", "blas"])
def test_a_matrix_that_is_not_positive_definite_is_refused(where, monkeypatch):
    """A system whose normal matrix is singular (a pose's block zeroed: every edge term of pose 7
    removed) raises multifrontal.NotPositiveDefinite naming a front, from the compiled loop and from
    LAPACK alike; LAGO's solve then falls back to the augmented system (tested elsewhere)."""
    monkeypatch.setattr(C, "SMALL_WORK", 10**18 if where == "loops" else 0)
    g = lc.manhattan_world(120, seed=1).graph
    el, system = _random_system(g, 2)
    A, B = system.A.copy(), system.B.copy()
    A[el.tails == 7] = 0.0
    B[el.heads == 7] = 0.0
    bad = ne.EdgeSystem(el.tails, el.heads, A, B, system.c, el.d)
    with pytest.raises(mf.NotPositiveDefinite, match="not positive definite"):
        el.factor(bad, engine="compiled")


def test_lago_by_the_compiled_engine_equals_lago_by_qdldl(monkeypatch):
    """Every closed-form system of LAGO (chordal relaxation, phase 1 where it is refactored, phase 3, the
    position re-solve) through the compiled engine (COMPILED_MIN 0) gives the estimate QDLDL gives, to
    1e-10 relative, by the default and the seed route; the covariances through it equal QDLDL's."""
    g = lc.manhattan_world(1500, seed=11).graph
    for route in ("default", "seed"):
        ref = lc.lago(g, route=route)
        monkeypatch.setattr(ne, "COMPILED_MIN", 0)
        res = lc.lago(g, route=route)
        monkeypatch.setattr(ne, "COMPILED_MIN", 10**12)
        assert res.phase3.factor.pose_major.backend == "compiled"
        assert ref.phase3.factor.pose_major.backend == "qdldl"
        scale = np.abs(ref.poses).max()
        assert np.abs(res.poses - ref.poses).max() <= 1e-10 * scale
        assert res.chi2 == pytest.approx(ref.chi2, rel=1e-10)
    cov = res.phase3.pose_covariances()
    cov_ref = ref.phase3.pose_covariances()
    assert np.abs(cov - cov_ref).max() <= 1e-9 * np.abs(cov_ref).max()


def test_factor_reports_its_progress(monkeypatch):
    """``progress(done, total)`` goes up to the total work, never down, from one thread or two."""
    g = lc.manhattan_world(800, seed=6).graph
    el, system = _random_system(g, 3)
    for t in (1, 2):
        monkeypatch.setattr(C, "cores", lambda t=t: t)
        monkeypatch.setattr(C, "PARALLEL_WORK", 0.0)
        seen = []
        el.plan.__dict__.pop("_compiled_layouts", None)
        el._assemblers.clear()
        el.factor(system, engine="compiled", progress=lambda i, n: seen.append((i, n)))
        assert seen and seen[-1][0] == pytest.approx(seen[-1][1])
        assert all(b[0] >= a[0] for a, b in zip(seen, seen[1:]))


def test_import_and_small_systems_load_no_numba():
    """``import lago_cvx`` and LAGO on a graph below COMPILED_MIN never import Numba (its import and the
    first call of cached kernels cost about half a second)."""
    code = ("import sys, lago_cvx as lc; g = lc.manhattan_world(300, seed=0).graph; lc.lago(g); "
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_symbolic_loops_compiled_and_in_python_give_the_same_plan(monkeypatch):
    """The amalgamation and height loops (lago_cvx.sparse.supernodes) compiled (COMPILED_LOOPS 0) and in Python
    give the same plan, array for array, on a 3000-pose world."""
    g = lc.manhattan_world(3000, seed=1).graph
    monkeypatch.setattr(mf, "COMPILED_LOOPS", 10**12)
    p1 = GraphElimination(g, 0).plan
    monkeypatch.setattr(mf, "COMPILED_LOOPS", 0)
    p2 = GraphElimination(g, 0).plan
    for name in ("position", "fptr", "rptr", "rows", "parent", "height"):
        assert np.array_equal(getattr(p1, name), getattr(p2, name)), name


def test_prepared_factorization_is_the_same(monkeypatch):
    """``GraphElimination.prepare(b)`` builds the layout, the assembler and a touched L in a worker thread;
    the factorization then uses that L (taken, not copied) and solves exactly as without preparation."""
    monkeypatch.setattr(ne, "COMPILED_MIN", 0)
    g = lc.manhattan_world(600, seed=9).graph
    el, system = _random_system(g, 3, seed=2)
    ref = el.factor(system, engine="compiled")
    el2, _ = _random_system(g, 3, seed=2)
    el2.prepare(3)
    assert 3 in el2._preparing
    el2._preparing[3].result()  # waits for the worker (its error raised here)
    lay = C.CompiledLayout.of(el2.plan, 3)
    reserved = lay._reserved
    f = el2.factor(system)
    assert f.compiled.L is reserved and "_reserved" not in lay.__dict__
    rhs = np.random.default_rng(3).standard_normal(el.d * 3)
    assert np.array_equal(f.solve(rhs), ref.solve(rhs))


def _block_map_reference(layout, prow, pcol):
    """The assembler's map by NumPy (the formulation before ``compiled_kernels.block_map``)."""
    plan = layout.plan
    idx = np.flatnonzero((prow >= 0) & (pcol >= 0))
    pr, pc = plan.position[prow[idx]], plan.position[pcol[idx]]
    tr = pr < pc
    lo, hi = np.where(tr, pr, pc), np.where(tr, pc, pr)
    f = np.repeat(np.arange(plan.n_fronts), plan.pivots)[lo]
    order = np.argsort(f, kind="stable")
    bptr = np.r_[0, np.cumsum(np.bincount(f, minlength=plan.n_fronts))]
    f = f[order]
    return idx[order], bptr, layout._pose_local(f, hi[order]), lo[order] - plan.fptr[f], tr[order]


@pytest.mark.parametrize("anchor", [0, 777])
def test_block_map_is_the_numpy_formulation(anchor):
    """The compiled map from N's blocks to their fronts (``CompiledAssembler``) equals the NumPy one, array
    for array, with the anchor's pairs dropped wherever the anchor is."""
    g = lc.manhattan_world(2000, seed=4).graph
    el = GraphElimination(g, anchor)
    prow, pcol, _ = el.pairs
    for b in (1, 3):
        lay = C.CompiledLayout.of(el.plan, b)
        asm = lay.assembler(prow, pcol)
        ref = _block_map_reference(lay, prow, pcol)
        for name, want in zip(("order", "bptr", "li", "lj", "transposed"), ref):
            assert np.array_equal(getattr(asm, name), want), name


def test_the_compiled_engines_relaxation_stores_fewer_zeros(monkeypatch):
    """When phase 3 will be factored by the compiled engine (3d ≥ COMPILED_MIN) the plan is amalgamated
    with ``COMPILED_RELAX``: fewer explicit zeros in L (more, smaller fronts) than with the NumPy engine's
    default, and the same solution to 1e-10."""
    g = lc.manhattan_world(3000, seed=2).graph
    monkeypatch.setattr(ne, "COMPILED_MIN", 10**12)
    el_default, system = _random_system(g, 3, seed=1)
    assert el_default.relaxation is None
    p0 = el_default.plan  # (built now: the plan is built on first use)
    monkeypatch.setattr(ne, "COMPILED_MIN", 0)
    el_tight, _ = _random_system(g, 3, seed=1)
    assert el_tight.relaxation == mf.COMPILED_RELAX
    p1 = el_tight.plan
    assert p1.nnz < p0.nnz and p1.n_fronts > p0.n_fronts
    rhs = np.random.default_rng(0).standard_normal(el_default.d * 3)
    x0 = el_default.factor(system, engine="compiled").solve(rhs)
    x1 = el_tight.factor(system, engine="compiled").solve(rhs)
    assert np.abs(x1 - x0).max() <= 1e-10 * np.abs(x0).max()


@pytest.mark.parametrize("anchor", [0, 1234])
@pytest.mark.parametrize("b, q", [(1, 1), (2, 2), (3, 3), (3, 4)])
def test_compiled_edge_operator_is_the_numpy_operator(b, q, anchor):
    """M x and Mᵀ r of a random edge system (E) by the compiled loops equal the NumPy ``EdgeOperator``'s
    bit for bit (same sums, same order), anchor terms dropped, for one right-hand side and for several."""
    g = lc.manhattan_world(3000, seed=1).graph
    el = GraphElimination(g, anchor)
    rng = np.random.default_rng(b * 10 + q)
    m = g.n_edges
    system = ne.EdgeSystem(el.tails, el.heads, rng.standard_normal((m, q, b)), rng.standard_normal((m, q, b)),
                           rng.standard_normal((m, q)), el.d)
    ref, op = ne.EdgeOperator(system), C.CompiledEdgeOperator(system)
    x, r = rng.standard_normal((el.d, b)), rng.standard_normal((m, q))
    assert np.array_equal(op.matvec(x), ref.matvec(x))
    assert np.array_equal(op.rmatvec(r), ref.rmatvec(r))
    x2, r2 = rng.standard_normal((el.d, b, 2)), rng.standard_normal((m, q, 2))
    assert np.array_equal(op.matvec(x2), ref.matvec(x2))
    assert np.array_equal(op.rmatvec(r2), ref.rmatvec(r2))


def test_large_systems_get_the_compiled_operator(monkeypatch):
    """``normal_equations.edge_operator`` is compiled from COMPILED_MIN unknowns, NumPy's below."""
    g = lc.manhattan_world(300, seed=0).graph
    el, system = _random_system(g, 3)
    monkeypatch.setattr(ne, "COMPILED_MIN", 10**12)
    assert isinstance(ne.edge_operator(system), ne.EdgeOperator)
    monkeypatch.setattr(ne, "COMPILED_MIN", 0)
    assert isinstance(ne.edge_operator(system), C.CompiledEdgeOperator)


def test_the_first_compilation_is_announced_only_without_any_cached_kernel(tmp_path):
    """``_on_disk``: an earlier process compiled kernels when any index file exists (the planar matrix-product kernels
    may never have been needed); none at all means Numba's first run here, which is announced."""
    from types import SimpleNamespace

    from lago_cvx.sparse.compiled import _on_disk

    def kernel(name, exists):
        path = tmp_path / f"{name}.nbi"
        if exists:
            path.write_text("")
        return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(path))))

    assert _on_disk({"a": kernel("a", True), "b": kernel("b", False)})
    assert not _on_disk({"c": kernel("c", False), "d": kernel("d", False)})

"""The compiled multifrontal engine (lago_cvx.sparse.compiled, C kernels) held to dense linear algebra and to the
NumPy engine (its fallback) inside LAGO: every kernel path (the right-looking loop, LAPACK/BLAS by address, a large
front on every BLAS thread), one thread and subtrees shared between two, the stack sizes, refusal of a matrix that
is not positive definite, progress, the wrappers' refusals, and threads factoring at once. Nothing here skips: the
C kernels are built by the install (``setup.py``), and a checkout without them fails these tests."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.sparse import compiled as C
from lago_cvx.sparse import engine_threads
from lago_cvx.sparse import multifrontal as mf
from lago_cvx.sparse import normal_equations as ne
from lago_cvx.sparse.edge_system import EdgeOperator
from lago_cvx.sparse.normal_equations import GraphElimination



@pytest.fixture
def numpy_engine(monkeypatch):
    """The C kernels as after an install without a compiler: the engine falls back to the NumPy multifrontal."""
    monkeypatch.setattr(C, "_C_KERNELS", [None])


def test_the_c_kernels_are_built_here():
    """The install builds the C kernels; a checkout without them fails here instead of skipping."""
    assert C.available(), "build them: python setup.py build_ext --inplace"


@pytest.fixture(params=["loops", "blas", "blas-threaded"])
def kernel(request, monkeypatch):
    """Which dense kernel factors the fronts: all by the compiled loop, all by LAPACK/BLAS called from
    compiled code (whether or not the engine may set the BLAS threads), or by LAPACK/BLAS with every front handed
    to the caller for every BLAS thread (the engine allowed two)."""
    work = 10**18 if request.param == "loops" else 0
    monkeypatch.setattr(C, "SMALL_WORK", work)
    monkeypatch.setattr(C, "ALONE_WORK", work)
    if request.param == "blas-threaded":
        monkeypatch.setattr(C, "THREADED_FRONT", 0)
        with engine_threads(blas_threads=2):
            yield request.param
    else:
        yield request.param


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
    f = el.factor(system)
    assert f.backend == "compiled"
    if threads == 2:
        assert f.numeric.layout.schedule_for(2) is not None
    M = system.sparse().toarray()
    N = M.T @ M
    rng = np.random.default_rng(1)
    rhs = rng.standard_normal(el.d * b)
    ref = np.linalg.solve(N, rhs)
    assert np.abs(f.solve(rhs) - ref).max() <= 1e-10 * np.abs(ref).max()
    R = rng.standard_normal((el.d * b, 3))
    refR = np.linalg.solve(N, R)
    assert np.abs(f.solve(R) - refR).max() <= 1e-10 * np.abs(refR).max()


def test_the_dense_algebra_test_reaches_every_part_of_the_blocked_loop():
    """The 300-pose world above reaches every part of the compiled loop (``ck_dense``: panels of 16 pivots, then
    the columns right of them in 4-column tiles of 2W rows plus a remainder): fronts with more than two panels,
    fronts whose width is not a multiple of 8 (row remainders) nor of 4 (a column remainder), and small fronts."""
    g = lc.manhattan_world(300, seed=5).graph
    lay = C.CompiledLayout.of(GraphElimination(g, 0).plan, 3)
    assert lay.K.max() > 32 and (lay.K < 16).any()
    assert ((lay.D - lay.K) % 8 != 0).any() and ((lay.D - lay.K) % 4 != 0).any()


def test_compiled_factor_is_the_numpy_engines_factor(threads):
    """The same plan factored by both engines: the C kernels' L, read front by front as [L_PP; X], is a Cholesky
    factor of N (eq. (MF)), and the NumPy fallback writes the same L (to rounding) and solves alike."""
    g = lc.manhattan_world(200, seed=8).graph
    el, system = _random_system(g, 3, seed=4)
    cf = el.factor(system).numeric
    saved = list(C._C_KERNELS)
    C._C_KERNELS[:] = [None]
    try:
        pf = el.factor(system).numeric
        xp = pf.solve_slots(np.random.default_rng(0).standard_normal(cf.layout.N))
    finally:
        C._C_KERNELS[:] = saved
    assert np.abs(pf.L - cf.L).max() <= 1e-10 * np.abs(cf.L).max()
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
    assert np.allclose(cf.solve_slots(x), xp, rtol=0, atol=1e-9 * np.abs(xp).max())


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
    el.factor(system)


@pytest.mark.parametrize("where", ["loops", "blas"])
def test_a_matrix_that_is_not_positive_definite_is_refused(where, monkeypatch):
    """A system whose normal matrix is singular (a pose's block zeroed: every edge term of pose 7
    removed) raises multifrontal.NotPositiveDefinite naming a front, from the compiled loop and from
    LAPACK alike; LAGO's solve then falls back to the augmented system (tested elsewhere)."""
    monkeypatch.setattr(C, "SMALL_WORK", 10**18 if where == "loops" else 0)
    monkeypatch.setattr(C, "ALONE_WORK", 10**18 if where == "loops" else 0)
    g = lc.manhattan_world(120, seed=1).graph
    el, system = _random_system(g, 2)
    A, B = system.A.copy(), system.B.copy()
    A[el.tails == 7] = 0.0
    B[el.heads == 7] = 0.0
    bad = ne.EdgeSystem(el.tails, el.heads, A, B, system.c, el.d)
    with pytest.raises(mf.NotPositiveDefinite, match="not positive definite"):
        el.factor(bad)


def test_lago_by_the_c_kernels_equals_lago_by_the_numpy_fallback(monkeypatch, caplog):
    """Every closed-form system of LAGO (chordal relaxation, phase 1, phase 3, the position re-solve) through the
    C kernels gives the estimate the NumPy multifrontal gives where they are missing (their fallback, announced by a
    warning), to 1e-10 relative, by the default and the seed route; the covariances too."""
    g = lc.manhattan_world(1500, seed=11).graph
    for route in ("default", "seed"):
        res = lc.lago(g, route=route)
        monkeypatch.setattr(C, "_C_KERNELS", [])
        monkeypatch.setenv("LAGO_CVX_NUMPY_ENGINE", "1")
        with caplog.at_level("WARNING", logger="lago_cvx.sparse.compiled"):
            ref = lc.lago(g, route=route)
        assert "NumPy multifrontal" in caplog.text
        monkeypatch.setattr(C, "_C_KERNELS", [])
        monkeypatch.delenv("LAGO_CVX_NUMPY_ENGINE")
        assert res.phase3.factor.pose_major.backend == "compiled"
        assert ref.phase3.factor.pose_major.backend == "multifrontal"
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
        el.factor(system, progress=lambda i, n: seen.append((i, n)))
        assert seen and seen[-1][0] == pytest.approx(seen[-1][1])
        assert all(b[0] >= a[0] for a, b in zip(seen, seen[1:]))


def test_symbolic_loops_in_c_and_in_python_give_the_same_plan(numpy_engine):
    """The amalgamation and postorder loops (lago_cvx.sparse.multifrontal) in C and in Python give the same
    plan, array for array, on a 3000-pose world."""
    g = lc.manhattan_world(3000, seed=1).graph
    el = GraphElimination(g, 0)
    both = (el.tails >= 0) & (el.heads >= 0)
    p1 = mf.plan_from_pattern(el.d, el.tails[both], el.heads[both], relaxation=mf.COMPILED_RELAX)
    C._C_KERNELS[:] = []
    p2 = mf.plan_from_pattern(el.d, el.tails[both], el.heads[both], relaxation=mf.COMPILED_RELAX)
    for name in ("position", "fptr", "rptr", "rows", "parent"):
        assert np.array_equal(getattr(p1, name), getattr(p2, name)), name


def test_prepared_factorization_is_the_same(monkeypatch):
    """``GraphElimination.prepare(b)`` builds the layout, the assembler and a touched L in a worker thread;
    the factorization then uses that L (taken, not copied) and solves exactly as without preparation."""
    monkeypatch.setattr(ne, "OVERLAP_MIN", 0)
    g = lc.manhattan_world(600, seed=9).graph
    el, system = _random_system(g, 3, seed=2)
    ref = el.factor(system)
    el2, _ = _random_system(g, 3, seed=2)
    el2.prepare(3)
    assert 3 in el2._preparing
    el2._preparing[3].result()  # waits for the worker (its error raised here)
    lay = C.CompiledLayout.of(el2.plan, 3)
    reserved = lay._reserved
    f = el2.factor(system)
    assert f.numeric.L is reserved and "_reserved" not in lay.__dict__
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


def test_the_compiled_engines_relaxation_stores_fewer_zeros():
    """The compiled engine's amalgamation ``COMPILED_RELAX`` stores fewer explicit zeros in L (more, smaller fronts)
    than the NumPy engine's default, for the same solution to 1e-10."""
    g = lc.manhattan_world(3000, seed=2).graph
    el, system = _random_system(g, 3, seed=1)
    both = (el.tails >= 0) & (el.heads >= 0)
    p0 = mf.plan_from_pattern(el.d, el.tails[both], el.heads[both])
    p1 = el.plan
    assert p1.nnz < p0.nnz and p1.n_fronts > p0.n_fronts
    rhs = np.random.default_rng(0).standard_normal(el.d * 3)
    x1 = el.factor(system).solve(rhs)
    el._plan = p0
    el._assemblers.clear()
    x0 = el.factor(system).solve(rhs)
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
    ref, op = EdgeOperator(system), C.CompiledEdgeOperator(system)
    x, r = rng.standard_normal((el.d, b)), rng.standard_normal((m, q))
    assert np.array_equal(op.matvec(x), ref.matvec(x))
    assert np.array_equal(op.rmatvec(r), ref.rmatvec(r))
    x2, r2 = rng.standard_normal((el.d, b, 2)), rng.standard_normal((m, q, 2))
    assert np.array_equal(op.matvec(x2), ref.matvec(x2))
    assert np.array_equal(op.rmatvec(r2), ref.rmatvec(r2))


def test_the_operator_is_compiled_unless_the_kernels_are_missing(numpy_engine):
    """``EdgeSystem.operator()`` is compiled whenever the C kernels load, NumPy's without them."""
    g = lc.manhattan_world(300, seed=0).graph
    el, system = _random_system(g, 3)
    assert isinstance(system.operator(), EdgeOperator)
    C._C_KERNELS[:] = []
    assert isinstance(system.operator(), C.CompiledEdgeOperator)


@pytest.mark.parametrize("q", [1, 2, 4])
@pytest.mark.parametrize("b", [1, 2, 3])
def test_normal_blocks_are_the_products_of_the_edge_blocks(b, q):
    """``EdgeSystem.normal_blocks`` are [A_kᵀA_k, B_kᵀB_k, B_kᵀA_k], and summed at ``pairs`` they are MᵀM."""
    g = lc.manhattan_world(200, seed=3).graph
    el = GraphElimination(g, 0)
    rng = np.random.default_rng(b * 10 + q)
    m = el.tails.size
    system = ne.EdgeSystem(el.tails, el.heads, rng.standard_normal((m, q, b)), rng.standard_normal((m, q, b)),
                           rng.standard_normal((m, q)), el.d)
    blocks = system.normal_blocks()
    prow, pcol, keep = el.pairs
    N = np.zeros((el.d, b, el.d, b))
    for i, j, blk in zip(prow[keep], pcol[keep], blocks[keep]):
        N[i, :, j] += blk
        if i != j:
            N[j, :, i] += blk.T
    M = system.sparse().toarray()
    np.testing.assert_allclose(N.reshape(el.d * b, -1), M.T @ M, rtol=1e-12, atol=1e-12)


def test_the_wrappers_refuse_what_the_c_code_cannot_read():
    """The ctypes wrappers check dtype, order and writability before the C code reads an array."""
    CK = C.kernels()
    el, system = _random_system(lc.manhattan_world(300, seed=0).graph, 2)
    lay = C.CompiledLayout.of(el.plan, 2)
    Y = np.zeros((2, lay.N))
    args = (np.arange(el.plan.n_fronts, dtype=np.int64), lay.b, lay.fptr, lay.rptr, lay.rows, lay.Lptr,
            np.ones(int(lay.Lptr[-1])), lay.rmax)
    with pytest.raises(ValueError, match="Y must be C-contiguous"):
        CK["forward"](np.zeros((lay.N, 2)).T, *args)
    with pytest.raises(ValueError, match="Y is written in place but is read-only"):
        Y.setflags(write=False)
        CK["backward"](Y, *args)
    with pytest.raises(TypeError, match="Y must be a float64 NumPy array, not float32"):
        CK["forward"](np.zeros((2, lay.N), np.float32), *args)
    with pytest.raises(TypeError, match="seq must be a int64 NumPy array, not int32"):
        CK["forward"](np.zeros((2, lay.N)), args[0].astype(np.int32), *args[1:])
    A, B = np.ascontiguousarray(system.A), np.ascontiguousarray(system.B)
    with pytest.raises(ValueError, match="x must be"):
        CK["edge_matvec"](A, B, system.tails, system.heads, np.zeros((el.d, lay.b + 1, 1)))


def test_threads_factoring_at_once_give_the_sequential_results(monkeypatch):
    """Two threads each factoring and solving its own system six times (at once, the GIL released in the C calls)
    give exactly the arrays of each system factored in a thread alone."""
    monkeypatch.setattr(C, "cores", lambda: 1)
    jobs = [_random_system(lc.manhattan_world(1000, seed=1).graph, 3, seed=1),
            _random_system(lc.manhattan_world(1000, seed=2).graph, 6, seed=2)]
    rhs = [np.random.default_rng(i).standard_normal(el.d * s.b) for i, (el, s) in enumerate(jobs)]
    got = [[], []]

    def work(i, times, start=None):
        el, system = jobs[i]
        if start is not None:
            start.wait()  # both threads begin together
        for _ in range(times):
            f = el.factor(system)
            got[i].append((f.numeric.L.copy(), f.solve(rhs[i])))

    def run(*jobs):
        threads = [threading.Thread(target=work, args=job) for job in jobs]
        for t in threads:
            t.start()
        for t in threads:
            t.join()

    run((0, 1))
    run((1, 1))  # one after the other: the references
    start = threading.Barrier(2)
    run((0, 6, start), (1, 6, start))  # at once
    for i in (0, 1):
        (L, x), *rest = got[i]
        assert len(rest) == 6
        assert all(np.array_equal(L, L2) and np.array_equal(x, x2) for L2, x2 in rest)


def test_the_ctypes_signatures_are_the_c_prototypes():
    """``c_kernels.SIGNATURES`` (result, then each argument: i int64, d double, p pointer, - void) is every exported
    function of ``_ckernels.c``, read from its prototypes."""
    import re
    from pathlib import Path

    from lago_cvx.sparse import c_kernels

    source = (Path(c_kernels.__file__).parent / "_ckernels.c").read_text()
    found = {}
    for ret, name, params in re.findall(r"CK_API (\w+) ck_(\w+)\(([^)]*)\)", source):
        kinds = ["p" if "*" in a else "d" if "double" in a else "i" for a in params.split(",")]
        found[name] = ("-" if ret == "void" else "d" if ret == "double" else "i") + "".join(kinds)
    assert found == c_kernels.SIGNATURES

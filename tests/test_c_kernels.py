"""The sparse engine's C kernels (lago_cvx.sparse.c_kernels, _ckernels.c through ctypes) held to their Numba twins
(compiled_kernels) bit for bit: every kernel on the engine's own inputs for b = 1, 2, 3, 6, a whole factorization
and solve, the refusal of a matrix that is not positive definite; the wrappers' refusal of arrays the C code
cannot read in place; no Numba in a process that uses them; threads factoring at once."""

from __future__ import annotations

import re
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.sparse import compiled as C
from lago_cvx.sparse import multifrontal as mf
from lago_cvx.sparse import normal_equations as ne
from lago_cvx.sparse import supernodes
from lago_cvx.sparse.normal_equations import GraphElimination

ck = pytest.importorskip("lago_cvx.sparse.c_kernels", reason="the C kernels are not built (no compiler at install)")
nk = pytest.importorskip("lago_cvx.sparse.compiled_kernels", reason="Numba cannot be imported here")
CK, NK = ck.KERNELS, nk.KERNELS


def _system(b, n=300, seed=0, anchor=0):
    g = lc.manhattan_world(n, seed=seed).graph
    el = GraphElimination(g, anchor)
    rng = np.random.default_rng(seed + 10 * b)
    m = g.n_edges
    A, B = rng.standard_normal((m, b + 1, b)), rng.standard_normal((m, b + 1, b))
    return el, ne.EdgeSystem(el.tails, el.heads, A, B, rng.standard_normal((m, b + 1)), el.d)


@pytest.fixture(scope="module", params=[1, 2, 3, 6])
def case(request):
    """A 300-pose world's elimination, its layout and block map for b, and a random edge system on it."""
    b = request.param
    el, system = _system(b, seed=b)
    lay = C.CompiledLayout.of(el.plan, b)
    prow, pcol, _ = el.pairs
    return el, system, lay, prow, pcol


def _factor(K, lay, asm, system, small_work, big):
    """(L, stack peak) of (MF) by kernels K, as ``compiled._Front.fronts`` drives them: ``run`` up to each front
    marked ``big``, which is assembled, factored by ``one`` and kept by ``finish``."""
    nf = lay.plan.n_fronts
    R = lay.plan.n_rows.astype(np.int64) * lay.b
    seq = np.arange(nf, dtype=np.int64)
    need = K["stack_peak"](seq, lay.nchild, R * R)
    F, stack, L = np.empty(max(lay.max_front, 1)), np.empty(max(need, 1)), np.zeros(int(lay.Lptr[-1]))
    st_front, st_off, state = np.zeros(nf + 1, np.int64), np.zeros(nf + 2, np.int64), np.zeros(1, np.int64)
    common = (lay.b, lay.fptr, lay.rptr, lay.rel, lay.nchild)
    data = (asm.bptr, asm.order, asm.li, asm.lj, asm.transposed, np.ascontiguousarray(system.A),
            np.ascontiguousarray(system.B))
    bufs = (F, stack, st_front, st_off, state)
    f = 0
    while f < nf:
        f = K["run"](f, nf, big, *common, lay.Lptr, *data, L, *bufs, small_work, K["fn"])
        assert f >= 0
        if f < nf:
            D = K["assemble"](f, *common, *data, *bufs)
            assert K["one"](f, lay.b, lay.fptr, lay.rptr, lay.Lptr, L, F, D, K["fn"]) == 0
            K["finish"](f, lay.b, lay.fptr, lay.rptr, lay.Lptr, L, *bufs)
            f += 1
    assert state[0] == 0  # every update popped by its parent
    return L, need


def test_the_kernel_tables_match():
    """Same names; the LAPACK/BLAS addresses found without Numba are Numba's; each ctypes signature is the C
    prototype's (read from _ckernels.c)."""
    assert set(CK) == set(NK)
    assert CK["fn"].dtype == np.int64 and np.array_equal(CK["fn"], NK["fn"])
    source = (Path(ck.__file__).parent / "_ckernels.c").read_text()
    protos = {name: (ret, args) for ret, name, args in re.findall(r"CK_API (\w+) ck_(\w+)\((.*?)\)\s*\{", source, re.S)}
    for name, sig in ck.SIGNATURES.items():
        ret, args = protos[name]
        want = {"i64": "i", "void": "-"}[ret] + "".join(
            "p" if "*" in a else "d" if a.split()[0] == "double" else "i" for a in args.split(","))
        assert sig == want, name


def test_block_map_and_local_indices_are_numbas(case):
    el, system, lay, prow, pcol = case
    front_of = np.repeat(np.arange(el.plan.n_fronts, dtype=np.int64), el.plan.pivots)
    args = (prow, pcol, el.plan.position.astype(np.int64), front_of, lay.fptr, lay.rptr, lay.rows)
    for got, want in zip(CK["block_map"](*args), NK["block_map"](*args)):
        assert got.dtype == want.dtype and np.array_equal(got, want)
    rf = np.repeat(np.arange(el.plan.n_fronts, dtype=np.int64), el.plan.n_rows)
    ok = el.plan.parent[rf] >= 0
    f, pos = np.ascontiguousarray(el.plan.parent[rf][ok]), np.ascontiguousarray(lay.rows[ok])
    got = CK["pose_local"](f, pos, lay.fptr, lay.rptr, lay.rows)
    assert got.size > 0 and np.array_equal(got, NK["pose_local"](f, pos, lay.fptr, lay.rptr, lay.rows))


@pytest.mark.parametrize("path", ["loops", "mixed", "blas", "big-fronts"])
def test_factor_and_solves_are_numbas_bit_for_bit(case, path):
    """L of (MF) by the right-looking loop, by LAPACK/BLAS, by both at SMALL_WORK, and with every third front
    handed back by ``run`` (assemble, one, finish); then forward and back sweeps of three right-hand sides."""
    el, system, lay, prow, pcol = case
    asm = lay.assembler(prow, pcol)
    small_work = {"loops": 10**18, "mixed": C.SMALL_WORK, "blas": 0, "big-fronts": C.SMALL_WORK}[path]
    big = np.arange(el.plan.n_fronts) % 3 == 1 if path == "big-fronts" else np.zeros(el.plan.n_fronts, bool)
    Lc, peak_c = _factor(CK, lay, asm, system, small_work, big)
    Ln, peak_n = _factor(NK, lay, asm, system, small_work, big)
    assert peak_c == peak_n and np.isfinite(Lc).all() and np.array_equal(Lc, Ln)
    every = np.arange(el.plan.n_fronts, dtype=np.int64)
    Y = np.random.default_rng(1).standard_normal((3, lay.N))
    out = []
    for K in (CK, NK):
        Z = Y.copy()
        args = (lay.b, lay.fptr, lay.rptr, lay.rows, lay.Lptr, Lc, lay.rmax)
        K["forward"](Z, every, *args)
        mid = Z.copy()
        K["backward"](Z, every[::-1].copy(), *args)
        out.append((mid, Z))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
    assert not np.array_equal(out[0][1], Y)


def test_edge_products_are_numbas(case):
    el, system, lay, prow, pcol = case
    A, B = np.ascontiguousarray(system.A), np.ascontiguousarray(system.B)
    t, h = system.tails.astype(np.int64), system.heads.astype(np.int64)
    rng = np.random.default_rng(3)
    x, r = rng.standard_normal((el.d, lay.b, 2)), rng.standard_normal((A.shape[0], A.shape[1], 2))
    assert np.array_equal(CK["edge_matvec"](A, B, t, h, x), NK["edge_matvec"](A, B, t, h, x))
    assert np.array_equal(CK["edge_rmatvec"](A, B, t, h, r, el.d), NK["edge_rmatvec"](A, B, t, h, r, el.d))


def test_tree_bookkeeping_is_numbas(case):
    """stack_peak over the postorder and over a worker's subsequence, subtrees, push."""
    el, system, lay, prow, pcol = case
    R = lay.plan.n_rows.astype(np.int64) * lay.b
    for seq in (np.arange(el.plan.n_fronts, dtype=np.int64), np.arange(el.plan.n_fronts // 2, dtype=np.int64)):
        assert CK["stack_peak"](seq, lay.nchild, R * R) == NK["stack_peak"](seq, lay.nchild, R * R)
    for got, want in zip(CK["subtrees"](el.plan.parent, lay.work), NK["subtrees"](el.plan.parent, lay.work)):
        assert got.dtype == want.dtype and np.array_equal(got, want)
    src = np.arange(50.0)
    stacks = []
    for K in (CK, NK):
        s = (np.zeros(20), np.zeros(4, np.int64), np.zeros(5, np.int64), np.zeros(1, np.int64))
        K["push"](src, 7, 6, *s, 3)
        K["push"](src, 30, 9, *s, 5)
        stacks.append(s)
    for a, b in zip(*stacks):
        assert np.array_equal(a, b)
    assert stacks[0][3][0] == 2 and np.array_equal(stacks[0][0][:15], np.r_[src[7:13], src[30:39]])


@pytest.mark.parametrize("seed", [0, 1])
def test_symbolic_loops_are_numbas_and_pythons(seed):
    """relax and heights on a random forest of 5000 supernodes (children first), with the engine's two
    amalgamations: the merges, the in-place updates and the heights equal Numba's and supernodes' own."""
    rng = np.random.default_rng(seed)
    ns = 5000
    parent = np.where(rng.random(ns) < 0.02, -1, np.arange(ns) + 1 + rng.integers(0, 20, ns))
    parent = np.where(parent >= ns, -1, parent).astype(np.int64)
    k, r = rng.integers(1, 6, ns).astype(np.int64), rng.integers(0, 30, ns).astype(np.int64)
    nnz = (k * (k + 1) // 2 + k * r - rng.integers(0, 3, ns)).astype(np.int64)
    for relaxation in ((mf.NRELAX, mf.ZRELAX), mf.COMPILED_RELAX):
        outs = []
        for relax in (CK["relax"], NK["relax"], supernodes.relax):
            kk, tn = k.copy(), nnz.copy()
            outs.append((relax(kk, r, tn, parent, *relaxation[0], *relaxation[1]), kk, tn))
        assert (outs[0][0] != np.arange(ns)).any()
        for other in outs[1:]:
            assert all(np.array_equal(a, b) for a, b in zip(outs[0], other))
    h = CK["heights"](parent)
    assert h.max() > 0 and np.array_equal(h, NK["heights"](parent)) and np.array_equal(h, supernodes.heights(parent))


def _engine_factor(which, monkeypatch, b, threads=1, seed=4):
    """A whole factorization by ``GraphElimination.factor(engine="compiled")`` with the kernels ``which`` (a new
    elimination each time) on ``threads`` threads; returns (L, solve of two right-hand sides)."""
    monkeypatch.setattr(C, "IMPLEMENTATION", which)
    monkeypatch.setattr(C, "cores", lambda: threads)
    monkeypatch.setattr(C, "PARALLEL_WORK", 0.0)
    el, system = _system(b, n=400, seed=seed)
    f = el.factor(system, engine="compiled")
    assert (f.compiled.layout.schedule is not None) == (threads > 1)
    rhs = np.random.default_rng(seed).standard_normal((el.d * b, 2))
    return f.compiled.L, f.solve(rhs)


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("b", [3, 6])
def test_a_whole_factorization_is_numbas(b, threads, monkeypatch):
    Lc, xc = _engine_factor("c", monkeypatch, b, threads)
    assert C.kernels() is CK
    Ln, xn = _engine_factor("numba", monkeypatch, b, threads)
    assert C.kernels() is NK
    assert np.array_equal(Lc, Ln) and np.array_equal(xc, xn)


@pytest.mark.parametrize("where", ["loops", "blas"])
def test_a_matrix_that_is_not_positive_definite_fails_alike(where, monkeypatch):
    """Pose 7's terms removed: NotPositiveDefinite naming the same front with C and with Numba."""
    monkeypatch.setattr(C, "SMALL_WORK", 10**18 if where == "loops" else 0)
    messages = []
    for which in ("c", "numba"):
        monkeypatch.setattr(C, "IMPLEMENTATION", which)
        el, system = _system(2, n=120, seed=1)
        A, B = system.A.copy(), system.B.copy()
        A[el.tails == 7] = 0.0
        B[el.heads == 7] = 0.0
        with pytest.raises(mf.NotPositiveDefinite, match="not positive definite") as err:
            el.factor(ne.EdgeSystem(el.tails, el.heads, A, B, system.c, el.d), engine="compiled")
        messages.append(str(err.value))
    assert messages[0] == messages[1]


def test_the_wrappers_refuse_what_the_c_code_cannot_read(case):
    el, system, lay, prow, pcol = case
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
    with pytest.raises(TypeError, match="fptr must be a int64 NumPy array, not list"):
        CK["pose_local"](args[0], args[0], list(lay.fptr), lay.rptr, lay.rows)
    k = np.ones(10, np.int64)[::2]
    with pytest.raises(ValueError, match="k must be C-contiguous"):
        CK["relax"](k, k.copy(), k.copy(), -k.copy(), 4, 16, 48, 0.8, 0.1, 0.05)
    A, B = np.ascontiguousarray(system.A), np.ascontiguousarray(system.B)
    with pytest.raises(ValueError, match="x must be"):
        CK["edge_matvec"](A, B, system.tails, system.heads, np.zeros((el.d, lay.b + 1, 1)))
    with pytest.raises(ValueError, match="beyond"):
        CK["push"](np.zeros(5), 2, 4, np.zeros(9), np.zeros(2, np.int64), np.zeros(3, np.int64),
                   np.zeros(1, np.int64), 0)
    with pytest.raises(ValueError, match="does not fit"):
        CK["push"](np.zeros(50), 2, 10, np.zeros(9), np.zeros(2, np.int64), np.zeros(3, np.int64),
                   np.zeros(1, np.int64), 0)


def test_the_c_kernels_load_no_numba():
    """A fresh process that loads the C kernels and factors by the compiled engine never imports Numba."""
    code = ("import sys\nfrom lago_cvx.sparse import c_kernels\nc_kernels.KERNELS\nprint('numba' in sys.modules)\n"
            "import lago_cvx as lc\nfrom lago_cvx.sparse import normal_equations as ne\n"
            "el = ne.GraphElimination(lc.manhattan_world(300, seed=0).graph, 0)\n"
            "import numpy as np\nA = np.random.default_rng(0).standard_normal((el.tails.size, 4, 3))\n"
            "f = el.factor(ne.EdgeSystem(el.tails, el.heads, A, A[::-1].copy(), A[:, :, 0], el.d), engine='compiled')\n"
            "print(type(f).__name__, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "CompiledPoseFactor", "False"]


def test_a_3d_solve_runs_on_the_c_kernels_without_numba(tmp_path):
    """``lago-cvx solve`` on a 3-D world: with the C kernels every 3-D system goes to the compiled engine
    (``wide.compiled_from()`` is 0) and the process never imports Numba; forced onto Numba's kernels (and, as they
    would not be below ``WIDE_COMPILED_MIN``, onto the compiled engine), the same process writes the same file."""
    world = str(tmp_path / "w.g2o")
    code = ("import sys\nfrom lago_cvx.cli import main\nfrom lago_cvx.sparse import compiled, wide\n"
            "compiled.use_kernels(sys.argv[1] or None)\n"
            "if sys.argv[1]:\n    wide.compiled_from = lambda: 0\n"
            "assert main(['solve', sys.argv[2], '-o', sys.argv[3]]) == 0\n"
            "print(wide.compiled_from(), 'numba' in sys.modules)")
    lc.cli.main(["generate", "--world", "sphere3d", "--poses", "300", "--seed", "2", "-o", world])
    outs = []
    for which in ("", "numba"):
        out = str(tmp_path / f"out{which}.g2o")
        run = subprocess.run([sys.executable, "-c", code, which, world, out], capture_output=True, text=True,
                             check=True)
        outs.append((run.stdout.splitlines()[-1], Path(out).read_bytes()))
    assert outs[0][0] == "0 False" and outs[1][0] == "0 True"
    assert outs[0][1] == outs[1][1]


def test_without_the_c_library_the_kernels_are_numbas():
    """A process where the C kernels cannot be imported (as after an install without a compiler): ``kernels()`` is
    Numba's, the engine available; asking for C then says it is not built; an unknown choice is refused."""
    code = ("import sys\nsys.modules['lago_cvx.sparse.c_kernels'] = None\nfrom lago_cvx.sparse import compiled\n"
            "print(compiled.available(), compiled.kernels()['run'].__module__)\ncompiled.use_kernels('c')\n"
            "try:\n    compiled.kernels()\nexcept ImportError as exc:\n    print('refused:', exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.splitlines() == ["True lago_cvx.sparse.compiled_kernels",
                                "refused: the sparse engine's C kernels are not built (lago_cvx/sparse/_ckernels.c)"]
    with pytest.raises(ValueError, match="'c', 'numba' or None"):
        C.use_kernels("fortran")


def test_threads_factoring_at_once_give_the_sequential_results(monkeypatch):
    """Two threads each factoring and solving its own system six times with the C kernels (at once, the GIL
    released in the C calls) give exactly the arrays of each system factored in a thread alone. (The reference
    is computed in a thread too: an OpenBLAS configured for several threads may round its one-thread calls from
    the main thread differently from those of other threads, whichever kernels call it.)"""
    monkeypatch.setattr(C, "IMPLEMENTATION", "c")
    monkeypatch.setattr(C, "cores", lambda: 1)
    jobs = [_system(3, n=1000, seed=1), _system(6, n=1000, seed=2)]
    rhs = [np.random.default_rng(i).standard_normal(el.d * s.b) for i, (el, s) in enumerate(jobs)]
    got = [[], []]

    def work(i, times, start=None):
        el, system = jobs[i]
        if start is not None:
            start.wait()  # both threads begin together
        for _ in range(times):
            f = el.factor(system, engine="compiled")
            got[i].append((f.compiled.L.copy(), f.solve(rhs[i])))

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

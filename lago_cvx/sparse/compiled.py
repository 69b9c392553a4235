r"""The multifrontal block Cholesky (MF) of ``multifrontal`` — the engine's one numeric factorization — front by
front in C, or, where no compiler was present at install (``available()`` False, said once as a warning), in NumPy
(``block_factor``) on the same storage. The loop over the fronts (postorder, children's updates on a stack popped by
their parent) is one C call (``c_kernels``), a few hundred nanoseconds per front where NumPy pays Python calls. A
front's dense partial Cholesky is the C loop blocked by panels and register tiles (``ck_dense``), or LAPACK/BLAS for
large fronts where the engine holds the BLAS threads (``SMALL_WORK``).

**Storage** (``CompiledLayout``). Variables are numbered by elimination slot, pose-major: slot = position·b +
component. Front f has k = |P_f|·b pivot and r = |R_f|·b update variables, D = k + r; its block column
[L_PP; X_f] is kept column by column from ``L[Lptr[f]]``, column j holding rows j … D − 1.

**Solve** N x = y (``CompiledFactor.solve_slots``): forward L z = y front by front (leaves up), back Lᵀ x = z.
**Two cores**: the C loop releases the GIL, so disjoint subtrees run at once (``CompiledLayout.schedule_for``).
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import MissingSolverError
from . import block_factor, kernel_checks
from .linalg import NotPositiveDefinite, blas_threads
from .threads import blas_limit, cores, spawn

__all__ = ["available", "kernels", "CompiledLayout", "CompiledAssembler", "CompiledFactor",
           "CompiledEdgeOperator"]

log = logging.getLogger(__name__)

#: A front whose k·D² (twice its multiply–adds) is below this is factored by the compiled blocked loop; a
#: larger one by LAPACK's ``potrf`` and BLAS's ``trsm``/``syrk`` (SciPy's), called by address from the compiled loop.
SMALL_WORK = 50_000

#: The same bound while the process's BLAS is left alone (no ``engine_threads(blas_threads=…)``): its threads cost
#: far more than they give on a busy machine (docs/performance.md, "The engine: one path").
ALONE_WORK = 1e10

#: Fronts with at least this many pivot variables run BLAS on every thread; the others on one.
THREADED_FRONT = 384

#: The least work (Σ k·D² over the fronts) for which the factorization's subtrees are shared among
#: threads at all; how many threads is ``threads.cores()``, read when a factorization is scheduled. Below it
#: the threads' start and the solves' sweeps split among them cost more than they share (the 3-D graphs' systems,
#: 7e7 to 3e9, gain nothing from two threads: ``benchmarks/space.md``); the planar systems it factors start near 9e9.
PARALLEL_WORK = 1e9

#: With a progress callback, each compiled call factors at most this share of the fronts (progress is reported
#: between calls); without one, a call runs every front up to the next large one.
CHUNK = 0.02


def kernels() -> dict:
    """The C kernels by name (``c_kernels.KERNELS``); ``MissingSolverError`` when they are not built."""
    if not available():
        raise MissingSolverError("the sparse engine's C kernels are not built (lago_cvx/sparse/_ckernels.c: "
                                 "reinstall lago-cvx with a C compiler present)")
    return _C_KERNELS[0]


def available() -> bool:
    """True when the C kernels load (tried once per process; a warning says so when they do not, and the engine
    uses the NumPy multifrontal instead). ``LAGO_CVX_NUMPY_ENGINE=1`` in the environment leaves them unloaded."""
    if not _C_KERNELS:
        import os

        try:
            if os.environ.get("LAGO_CVX_NUMPY_ENGINE", "").strip() not in ("", "0"):
                raise ImportError("LAGO_CVX_NUMPY_ENGINE is set")
            from . import c_kernels

            _C_KERNELS.append(c_kernels.KERNELS)
        except ImportError as exc:
            log.warning("sparse engine: C kernels unavailable (%s); factoring by the NumPy multifrontal (slower)", exc)
            _C_KERNELS.append(None)
    return _C_KERNELS[0] is not None


_C_KERNELS: list = []  # [c_kernels.KERNELS] or [None] once tried


class CompiledLayout:
    """The plan's fronts expanded to b×b blocks for the compiled kernels: ``Lptr`` (F + 1,) where each
    front's packed block column of L starts; ``rel`` the extend-add map (each update row pose's local pose
    index in its parent's front: pivots 0 … k−1, then k + its rank among the parent's rows); ``nchild``
    (F,) the children (updates on the stack) each front pops."""

    @classmethod
    def of(cls, plan, b: int) -> "CompiledLayout":
        """The layout of ``plan`` (a ``multifrontal.EliminationPlan``) with b×b blocks, built once per plan
        and b (kept with the plan)."""
        cache = plan.__dict__.setdefault("_compiled_layouts", {})
        if b not in cache:
            cache[b] = cls(plan, b)
        return cache[b]

    def __init__(self, plan, b: int):
        kernel_checks.plan(plan, b)  # O(d) once: a malformed plan raises PlanError before any compiled call
        self.plan = plan
        self.b = b = int(b)
        self.N = plan.d * b
        k, r = plan.pivots.astype(np.int64), plan.n_rows.astype(np.int64)
        F = plan.n_fronts
        self.fptr = np.ascontiguousarray(plan.fptr, np.int64)
        self.rptr = np.ascontiguousarray(plan.rptr, np.int64)
        self.rows = np.ascontiguousarray(plan.rows, np.int64)
        K, R, D = k * b, r * b, (k + r) * b
        self.Lptr = np.r_[0, np.cumsum(D * K - K * (K - 1) // 2)].astype(np.int64)
        self.nchild = np.bincount(plan.parent[plan.parent >= 0], minlength=F).astype(np.int64)
        par = plan.parent[np.repeat(np.arange(F), r)]  # (|rows|,) the parent of each update row's front
        self.rel = rel = np.full(par.size, -1, np.int64)
        ok = par >= 0
        if ok.any():
            rel[ok] = self._pose_local(par[ok], self.rows[ok])
        self.K, self.D = K, D
        self.work = K.astype(float) * D * D  # (F,) twice each front's multiply–adds
        self.max_front = int(D.max() ** 2) if F else 0
        self.rmax = int(R.max()) if F else 0
        self.big = K >= THREADED_FRONT  # (F,) the fronts factored alone, with every BLAS thread
        self.none_big = np.zeros(F, bool)  # in a worker thread, every front on one BLAS thread
        kernel_checks.layout(self)  # the extend-add map checked, the arrays frozen and registered for the kernels

    def _pose_local(self, f: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Local pose index of position ``pos`` in front ``f`` (pivots 0 … k−1, rows k + rank)."""
        if not available():
            plan = self.plan
            fr = np.repeat(np.arange(plan.n_fronts), plan.n_rows)
            rank = np.searchsorted(fr * plan.d + self.rows, f * plan.d + pos) - self.rptr[f]
            return np.where((pos >= self.fptr[f]) & (pos < self.fptr[f + 1]), pos - self.fptr[f],
                            self.fptr[f + 1] - self.fptr[f] + rank)
        return kernels()["pose_local"](np.ascontiguousarray(f, np.int64), np.ascontiguousarray(pos, np.int64),
                                       self.fptr, self.rptr, self.rows)

    def assembler(self, prow: np.ndarray, pcol: np.ndarray) -> "CompiledAssembler":
        return CompiledAssembler(self, prow, pcol)

    def factor(self, assembler: "CompiledAssembler", A: np.ndarray, B: np.ndarray, *,
               progress=None) -> "CompiledFactor":
        """Factor the normal matrix (N) of the edge system with blocks ``A``, ``B`` (m, q, b) (its ends those the
        assembler was built on) by (MF), fronts in postorder: with several cores (``threads.cores()``) and enough work,
        the subtrees of ``schedule_for`` in worker threads (one BLAS thread each, each with its own front buffer and
        stack), then the fronts above them in this thread, the children's updates copied across from the workers'
        stacks, large fronts with every BLAS thread. Without the C kernels, ``block_factor.factor`` fills the same L.
        ``progress(done, total)`` gets the multiply–adds done. Raises ``multifrontal.NotPositiveDefinite`` if a pivot
        block is not positive definite."""
        A = np.ascontiguousarray(A, dtype=float)
        B = np.ascontiguousarray(B, dtype=float)
        L = self.__dict__.pop("_reserved", None)
        if L is None:
            L = np.empty(int(self.Lptr[-1]))
        if not available():
            At, Bt = np.swapaxes(A, 1, 2), np.swapaxes(B, 1, 2)
            with blas_threads(1):
                block_factor.factor(self, assembler, np.concatenate([At @ A, Bt @ B, Bt @ A]), L, progress)
            return CompiledFactor(self, L, 1)
        kern = kernels()
        data = (assembler.bptr, assembler.order, assembler.li, assembler.lj, assembler.transposed, A, B)
        n_threads, nf = cores(), self.plan.n_fronts
        sched = self.schedule_for(n_threads)
        total = float(self.work.sum())
        done = [0.0]

        def report():
            if total > 0:
                progress(min(done[0], total), total)

        report = None if progress is None else report  # without one, each call runs as many fronts as it can

        with blas_threads(1) as threads:
            if sched is None:
                _Front(self, kern, data, L, nf, np.arange(nf)).fronts(0, nf, threads, done, report)
                return CompiledFactor(self, L, n_threads)
            roots_of, top, first, ext = sched
            workers = [_Front(self, kern, data, L, nf, seq) for seq in self.worker_fronts_for(n_threads)]
            errors: list = []

            def work(w, roots):
                try:
                    for r in roots:
                        w.fronts(int(first[r]), int(r) + 1, None, done, None)
                except BaseException as exc:  # raised in the calling thread
                    errors.append(exc)

            jobs = [spawn(work, w, roots, name="lago-fronts") for w, roots in zip(workers, roots_of)]
            for j in jobs:
                while j.is_alive():
                    j.join(0.25)
                    if report is not None:
                        report()
            if errors:
                raise errors[0]
            where = {}  # subtree root → (its worker, offset, size) of its update
            for w in workers:
                for t in range(int(w.state[0])):
                    where[int(w.st_front[t])] = (w, int(w.st_off[t]), int(w.st_off[t + 1] - w.st_off[t]))
            main = _Front(self, kern, data, L, nf, top, ext=(ext, where))
            for f in top.tolist():
                for c in ext.get(f, ()):  # pushed onto this thread's stack (NumPy refuses one that does not fit)
                    w, off, size = where[c]
                    t, o = int(main.state[0]), int(main.st_off[main.state[0]])
                    main.stack[o:o + size] = w.stack[off:off + size]
                    main.st_front[t], main.st_off[t + 1], main.state[0] = c, o + size, t + 1
                main.fronts(f, f + 1, threads, done, report)
        return CompiledFactor(self, L, n_threads)

    def schedule_for(self, n_threads: int):
        """How the fronts are shared among ``n_threads`` threads, or None to factor them in one: the front tree's
        largest subtrees are split (their root joins ``top``, the fronts left to this thread) until none holds more
        than 1/16 of the work, then dealt to the threads largest first. Returns (roots per thread, top fronts in
        postorder, first front of each subtree, {top front: its children that are subtree roots})."""
        known = self.__dict__.setdefault("_schedules", {})
        if n_threads in known:
            return known[n_threads]
        import heapq

        plan = self.plan
        total = float(self.work.sum())
        known[n_threads] = None
        if n_threads < 2 or total < PARALLEL_WORK or plan.n_fronts < 2:
            return None
        W, first = kernels()["subtrees"](plan.parent, self.work)
        kids = np.argsort(plan.parent, kind="stable")
        nroot = int((plan.parent < 0).sum())
        cptr = np.r_[0, np.cumsum(np.bincount(plan.parent[plan.parent >= 0], minlength=plan.n_fronts))]
        children = kids[nroot:]
        heap = [(-W[r], int(r)) for r in np.flatnonzero(plan.parent < 0)]
        heapq.heapify(heap)
        top = []
        while heap and -heap[0][0] > total / 16:
            _, f = heapq.heappop(heap)
            top.append(f)
            for c in children[cptr[f]:cptr[f + 1]].tolist():
                heapq.heappush(heap, (-W[c], c))
        roots = sorted((f for _, f in heap), key=lambda f: -W[f])
        load = [0.0] * n_threads
        roots_of = [[] for _ in range(n_threads)]
        for r in roots:  # largest first, to the least loaded thread
            i = int(np.argmin(load))
            roots_of[i].append(r)
            load[i] += W[r]
        roots_of = [np.array(sorted(x), np.int64) for x in roots_of]
        rootset = set(roots)
        ext = {}
        for f in top:
            ext[f] = [c for c in children[cptr[f]:cptr[f + 1]].tolist() if c in rootset]
        known[n_threads] = sched = (roots_of, np.array(sorted(top), np.int64), first, ext)
        log.debug("compiled engine: %d subtrees on %d threads (work %s), %d fronts above them", len(roots),
                  n_threads, [f"{x / total:.2f}" for x in load], len(top))
        return sched

    def reserve(self, *, threads: int | None = None) -> None:
        """Allocate the next factorization's L and touch every page of it now (from ``threads`` threads at once,
        default one per core, called where there is time: ``GraphElimination.prepare``), so that the factorization
        writes to memory already mapped."""
        if "_reserved" in self.__dict__:
            return
        threads = cores() if threads is None else max(1, int(threads))
        L = np.empty(int(self.Lptr[-1]))
        cuts = np.linspace(0, L.size // 512, threads + 1).astype(np.int64) * 512

        def touch(i):
            L[cuts[i]:cuts[i + 1]:512] = 0.0  # one write per 4 KiB page (NumPy releases the GIL)

        jobs = [spawn(touch, i, name="lago-touch") for i in range(1, threads)]
        touch(0)
        L[cuts[-1]::512] = 0.0
        for j in jobs:
            j.join()
        self._reserved = L

    def worker_fronts_for(self, n_threads: int) -> list:
        """Per worker thread of ``schedule_for(n_threads)``, its fronts in the order it factors them (its subtrees,
        each in postorder)."""
        known = self.__dict__.setdefault("_worker_fronts", {})
        if n_threads not in known:
            roots_of, _, first, _ = self.schedule_for(n_threads)
            known[n_threads] = [np.concatenate([np.arange(first[r], r + 1) for r in roots]).astype(np.int64)
                                if len(roots) else np.zeros(0, np.int64) for roots in roots_of]
        return known[n_threads]

    def pivot_slots(self, fronts: np.ndarray) -> np.ndarray:
        """The elimination slots of the pivots of ``fronts`` (contiguous per front)."""
        fronts = np.asarray(fronts, np.int64)
        lo, n = self.fptr[fronts] * self.b, (self.fptr[fronts + 1] - self.fptr[fronts]) * self.b
        return np.repeat(lo - np.r_[0, np.cumsum(n)[:-1]], n) + np.arange(int(n.sum()))


class _Front:
    """One thread's working set for (MF): its front buffer, its stack of updates (sized by simulating
    the fronts ``seq`` it will factor, in order), and the loop over a range of fronts."""

    def __init__(self, layout: CompiledLayout, kern, data, L, nf, seq, *, ext=None):
        self.layout, self.kern, self.data, self.L = layout, kern, data, L
        R = layout.plan.n_rows.astype(np.int64) * layout.b
        sizes = R * R
        seq, nchild = np.asarray(seq, np.int64), layout.nchild
        if ext is not None:  # the top fronts, each after its subtree-root children (pushed, popping nothing)
            seq = np.array([g for f in seq.tolist() for g in (*ext[0].get(f, ()), f)], np.int64)
            nchild = nchild.copy()
            nchild[[c for cs in ext[0].values() for c in cs]] = 0
        need = int(kern["stack_peak"](seq, nchild, sizes))
        self.F = np.empty(max(layout.max_front, 1))
        self.stack = np.empty(max(need, 1))
        self.st_front = np.zeros(nf + 1, np.int64)
        self.st_off = np.zeros(nf + 2, np.int64)
        self.state = np.zeros(1, np.int64)

    def fronts(self, f0: int, f1: int, threads, done: list, report) -> None:
        """Fronts f0 … f1 − 1 (whole subtrees, or a top front whose children's updates are on this stack): small
        runs inside one compiled call (``CHUNK`` of the fronts per call when ``report`` wants progress between calls,
        else as many as run before a large one); with ``threads`` (this thread sets the BLAS thread count) a large
        front alone, by LAPACK/BLAS on every BLAS thread. ``done[0]`` += their work."""
        lay = self.layout
        own = blas_limit() is not None  # the engine holds the BLAS threads: LAPACK/BLAS from SMALL_WORK on
        big = lay.big if threads is not None and own else lay.none_big
        step = max(int(lay.plan.n_fronts * CHUNK), 1) if report is not None else max(f1 - f0, 1)
        args = (lay.b, lay.fptr, lay.rptr, lay.rel, lay.nchild, lay.Lptr, *self.data, self.L, self.F, self.stack,
                self.st_front, self.st_off, self.state)
        f = f0
        while f < f1:
            alone = bool(big[f])
            if alone:
                threads(None)
            stop = self.kern["run"](f, f + 1 if alone else min(f + step, f1), lay.none_big if alone else big, *args,
                                    0 if alone else SMALL_WORK if own else ALONE_WORK, self.kern["fn"])
            if alone:
                threads(1)
            if stop < 0:
                raise NotPositiveDefinite(f"the matrix is not positive definite (front {-stop - 1})")
            done[0] += float(lay.work[f:stop].sum())
            f = stop
            if report is not None:
                report()


class CompiledAssembler:
    """Where the blocks of (N) go (computed once per graph and b): the pose pairs ``prow``, ``pcol`` (3m,)
    of ``GraphElimination.pairs`` — tail diagonals, head diagonals, (head, tail) — those with an end at
    the anchor (−1) dropped, sorted by the front whose pivot columns hold them (``bptr`` (F + 1,)
    boundaries, ``order`` their pair index kind·m + k), each at local block row ``li``, column ``lj`` of
    its front, ``transposed`` where the stored (lower) block is the pair's block transposed."""

    def __init__(self, layout: CompiledLayout, prow, pcol):
        plan = layout.plan
        prow, pcol = np.asarray(prow, np.int64), np.asarray(pcol, np.int64)
        front_of = np.repeat(np.arange(plan.n_fronts, dtype=np.int64), plan.pivots)  # (d,) by position
        if not available():  # the same map by NumPy
            idx = np.flatnonzero((prow >= 0) & (pcol >= 0))
            pr, pc = plan.position[prow[idx]], plan.position[pcol[idx]]
            tr = pr < pc
            lo, hi = np.where(tr, pr, pc), np.where(tr, pc, pr)
            f = front_of[lo]
            order = np.argsort(f, kind="stable")
            self.bptr = np.r_[0, np.cumsum(np.bincount(f, minlength=plan.n_fronts))].astype(np.int64)
            f = f[order]
            self.order, self.li, self.transposed = idx[order], layout._pose_local(f, hi[order]), tr[order]
            self.lj = lo[order] - plan.fptr[f]
            return
        self.order, self.bptr, self.li, self.lj, self.transposed = kernels()["block_map"](
            np.ascontiguousarray(prow, np.int64), np.ascontiguousarray(pcol, np.int64),
            np.ascontiguousarray(plan.position, np.int64), front_of, layout.fptr, layout.rptr, layout.rows)


class CompiledFactor:
    """N = L Lᵀ from ``CompiledLayout.factor``: ``solve_slots(y)`` for y (N,) or (N, r) in elimination
    slots."""

    def __init__(self, layout: CompiledLayout, L: np.ndarray, n_threads: int = 1):
        self.layout = layout
        self.L = L
        self.n_threads = n_threads  # the threads it was factored on: its solves sweep the same subtrees

    def solve_slots(self, y: np.ndarray) -> np.ndarray:
        """Solve N x = y for y (N,) or (N, r) in elimination slots; x likewise. On the threads it was factored on,
        each worker sweeps its own subtrees: forward on its own copy of y (the top slots' changes summed
        afterwards), back on y itself. Without the C kernels, ``block_factor.solve``."""
        lay = self.layout
        one = y.ndim == 1
        if not available():
            Y = np.array(y.reshape(lay.N, -1), dtype=float)
            with blas_threads(1):
                block_factor.solve(lay, self.L, Y)
            return Y[:, 0] if one else Y
        kern = kernels()
        Y = np.array(y.reshape(lay.N, -1).T, dtype=float, order="C")  # (r, N): each right-hand side contiguous
        args = (lay.b, lay.fptr, lay.rptr, lay.rows, lay.Lptr, self.L, lay.rmax)
        sched = lay.schedule_for(self.n_threads)
        if sched is None:
            every = np.arange(lay.plan.n_fronts, dtype=np.int64)
            kern["forward"](Y, every, *args)
            kern["backward"](Y, every[::-1].copy(), *args)
            return Y[0] if one else Y.T
        seqs, top = lay.worker_fronts_for(self.n_threads), sched[1]
        copies = [Y.copy() for _ in seqs]

        def each(fn, arrays, orders):
            jobs = [spawn(fn, a, o, *args, name="lago-solve") for a, o in zip(arrays, orders)]
            for j in jobs:
                j.join()

        each(kern["forward"], copies, seqs)
        T = lay.pivot_slots(top)
        base = Y[:, T]
        for seq, Yw in zip(seqs, copies):
            own = lay.pivot_slots(seq)
            Y[:, own] = Yw[:, own]
            Y[:, T] += Yw[:, T] - base
        kern["forward"](Y, top, *args)
        kern["backward"](Y, top[::-1].copy(), *args)
        each(kern["backward"], [Y] * len(seqs), [s[::-1].copy() for s in seqs])
        return Y[0] if one else Y.T

    def flops(self) -> float:
        return self.layout.plan.flops(self.layout.b)


class CompiledEdgeOperator:
    """M x and Mᵀ r of an edge system (E) (``edge_system.EdgeSystem``) by compiled loops over its edges, reading A, B
    (m, q, b) where they are: no transposed copies and no temporaries of length m (at a million poses the NumPy
    ``EdgeOperator``'s are 0.3 GiB of fresh memory: ``benchmarks/million.md``). The same sums in the same order as
    the NumPy operator, for one right-hand side or several (a trailing axis)."""

    def __init__(self, system):
        self.d = system.d
        kern = kernels()
        self._mv, self._rmv = kern["edge_matvec"], kern["edge_rmatvec"]
        self._A = np.ascontiguousarray(system.A, dtype=float)
        self._B = np.ascontiguousarray(system.B, dtype=float)
        self._t = np.ascontiguousarray(system.tails, np.int64)
        self._h = np.ascontiguousarray(system.heads, np.int64)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """M x (m, q[, r]) for x (d, b[, r])."""
        x3 = np.ascontiguousarray(x.reshape(x.shape[:2] + (int(np.prod(x.shape[2:])),)), dtype=float)
        out = self._mv(self._A, self._B, self._t, self._h, x3)
        return out.reshape(out.shape[:2] + x.shape[2:])

    def rmatvec(self, r: np.ndarray) -> np.ndarray:
        """Mᵀ r (d, b[, r]) for r (m, q[, r])."""
        r3 = np.ascontiguousarray(r.reshape(r.shape[:2] + (int(np.prod(r.shape[2:])),)), dtype=float)
        out = self._rmv(self._A, self._B, self._t, self._h, r3, self.d)
        return out.reshape(out.shape[:2] + r.shape[2:])

r"""Least squares on the pose graph, edge by edge, solved through the shared pose-level elimination.

Every closed form of LAGO (the chordal relaxation (C2), phase 1 eq. (13), phase 3 eqs. (12)/(15), the
positions (P)) minimises a sum of per-edge terms over the free poses x_i ∈ ℝ^b (i = 0 … d−1, the anchor
held fixed):

    minimise_x  Σ_k ‖A_k x_{t_k} + B_k x_{h_k} − c_k‖²,    A_k, B_k (q × b),  c_k (q,)            (E)

(t_k, h_k the free-pose indices of edge k's tail and head, −1 for the anchor, whose term is dropped;
the anchor's known value is already moved into c_k). Written as ‖M x − c‖² with the sparse whitened
design M (mq × db), its normal matrix N = MᵀM has the b×b blocks

    N_ii = Σ_{k: t_k = i} A_kᵀA_k + Σ_{k: h_k = i} B_kᵀB_k,    N_{h_k t_k} += B_kᵀA_k,              (N)

the anchor-reduced pose graph's pattern for every b. ``EdgeSystem`` holds (E) as arrays (m, q, b) and
applies M and Mᵀ edge by edge (no sparse matrix is built); ``GraphElimination`` holds the pose-level
symbolic analysis of one graph and anchor (``lago_cvx.sparse.multifrontal``), computed once and shared by every
system LAGO solves on that graph. Below ``ENGINE_MIN`` unknowns N is factored by QDLDL in that same
pose-level order, expanded to b components per pose (``BlockUpperPattern``: the upper triangle's CSC
pattern and a scatter map, built once per b; ``lago_cvx.sparse.ldl``), above it by the multifrontal engine —
compiled by Numba (``lago_cvx.sparse.compiled``) from ``COMPILED_MIN`` unknowns when Numba can be imported, the
NumPy engine (``lago_cvx.sparse.multifrontal``) otherwise.
Either way (E) is solved by the corrected semi-normal equations
(``lago_cvx.sparse.linalg.refine_normal_equations``), falling back to the augmented system as
``lago_cvx.sparse.linalg.solve_least_squares`` does.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .linalg import Factor, augmented_least_squares, refine_normal_equations
from . import compiled
from .compiled import CompiledPoseFactor
from .multifrontal import COMPILED_RELAX, BlockFactor, EliminationPlan, plan_from_pattern, plan_from_qdldl
from ..progress import Progress
from .upper_pattern import BlockUpperPattern, PoseLaplacian, PoseUpperPattern, QdldlFactor, matrix_blocks

__all__ = ["plan_from_pattern", "matrix_blocks", "EdgeSystem", "EdgeOperator", "GraphElimination", "PoseFactor", "BlockUpperPattern", "PoseUpperPattern", "QdldlFactor", "RenumberedFactor", "CompiledPoseFactor", "ENGINE_MIN", "COMPILED_MIN"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class EdgeSystem:
    """The least-squares problem (E): ``tails``, ``heads`` (m,) free-pose indices (−1: the anchor),
    ``A``, ``B`` (m, q, b), ``c`` (m, q) — or (m, q, r) for r problems with the same matrix, solved
    together; ``d`` free poses."""

    tails: np.ndarray
    heads: np.ndarray
    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    d: int

    @property
    def b(self) -> int:
        return self.A.shape[2]

    def operator(self) -> "EdgeOperator":
        """M and Mᵀ of this system with their set-up done once (for the refinement's repeated products): a
        ``compiled.CompiledEdgeOperator`` from ``COMPILED_MIN`` unknowns when Numba can be imported (the
        same sums in the same order), else an ``EdgeOperator``."""
        if self.d * self.b >= COMPILED_MIN and compiled.available():
            return compiled.CompiledEdgeOperator(self)
        return EdgeOperator(self)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """M x (m, q[, r]) for x (d, b[, r]): A_k x_{t_k} + B_k x_{h_k} (anchor terms 0)."""
        return self.operator().matvec(x)

    def rmatvec(self, r: np.ndarray) -> np.ndarray:
        """Mᵀ r (d, b[, r]) for r (m, q[, r]) (scatter-add by ``np.bincount``)."""
        return self.operator().rmatvec(r)

    def normal_blocks(self) -> np.ndarray:
        """The blocks of (N) in ``GraphElimination.pairs`` order: [A_kᵀA_k (tail diagonal), B_kᵀB_k (head
        diagonal), B_kᵀA_k (head row, tail column)], (3m, b, b)."""
        At = np.ascontiguousarray(np.swapaxes(self.A, 1, 2))  # contiguous: NumPy's stacked matmul is 2× faster
        Bt = np.ascontiguousarray(np.swapaxes(self.B, 1, 2))
        return np.concatenate([At @ self.A, Bt @ self.B, Bt @ self.A])

    def normal_entries(self) -> np.ndarray:
        """The same blocks entry by entry, (3, b, b, m): [k, r, c] the (r, c) entries of the k-th kind
        (A_kᵀA_k, B_kᵀB_k, B_kᵀA_k) for every edge, each a sum over the q rows of products of length-m
        vectors. For small m faster than the stacked products of ``normal_blocks`` (NumPy pays per 3×3
        matrix there: city10000's phase 3 8.7 ms against 13 ms, the chordal 2×2 blocks 4 against 9 ms;
        equal at 1.8 M edges)."""
        m, q, b = self.A.shape
        At = np.ascontiguousarray(self.A.transpose(1, 2, 0))  # (q, b, m)
        Bt = np.ascontiguousarray(self.B.transpose(1, 2, 0))
        out = np.empty((3, b, b, m))
        tmp = np.empty(m)
        for k, X, Y, symmetric in ((0, At, At, True), (1, Bt, Bt, True), (2, Bt, At, False)):
            for r in range(b):
                for c in range(r if symmetric else 0, b):
                    o = out[k, r, c]
                    np.multiply(X[0, r], Y[0, c], out=o)
                    for t in range(1, q):
                        np.multiply(X[t, r], Y[t, c], out=tmp)
                        o += tmp
                    if symmetric and c > r:
                        out[k, c, r] = o
        return out

    def sparse(self, var_index: np.ndarray | None = None) -> sp.csr_matrix:
        """M as a sparse (m·q) × (d·b) matrix, columns ``var_index`` (d, b) (default pose-major)."""
        m, q, b = self.A.shape
        var = (np.arange(self.d * b).reshape(self.d, b) if var_index is None
               else np.asarray(var_index, np.int64))
        rows = np.repeat(np.arange(m * q).reshape(m, q), b, axis=1).reshape(m, q * b)
        parts_r, parts_c, parts_v = [], [], []
        for ends, J in ((self.tails, self.A), (self.heads, self.B)):
            ok = ends >= 0
            parts_r.append(rows[ok].reshape(-1))
            parts_c.append(np.tile(var[ends[ok]], (1, q)).reshape(-1))
            parts_v.append(J[ok].reshape(-1))
        return sp.csr_matrix((np.concatenate(parts_v), (np.concatenate(parts_r), np.concatenate(parts_c))),
                             shape=(m * q, self.d * b))

    def cost(self, x: np.ndarray) -> float:
        r = self.matvec(x) - self.c
        return float(np.sum(r * r))


class EdgeOperator:
    """M x and Mᵀ r of an ``EdgeSystem`` (E), component-major: A, B kept as (q, b, m) and the ends with the
    anchor mapped to row d, so every product is b·q multiply–adds of length-m vectors (several times
    faster than ``np.einsum`` over (m, q, b)) and Mᵀ's scatter-add one ``np.bincount`` per component and
    right-hand side. Built once per solve (``GraphElimination.solve``, phase 1), not kept with the
    system."""

    def __init__(self, system: EdgeSystem):
        self.m, self.q, self.b = system.A.shape
        self.d = system.d
        self.At = np.ascontiguousarray(system.A.transpose(1, 2, 0))
        self.Bt = np.ascontiguousarray(system.B.transpose(1, 2, 0))
        self.t = np.where(system.tails < 0, self.d, system.tails)
        self.h = np.where(system.heads < 0, self.d, system.heads)
        self.ends = np.concatenate([self.t, self.h])  # (2m,): the tails, then the heads

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """M x (m, q[, r]) for x (d, b[, r])."""
        At, Bt, m, q, b = self.At, self.Bt, self.m, self.q, self.b
        extra = x.shape[2:]
        xe = np.zeros((b, *extra, self.d + 1))  # component-major, column d: the anchor's zero
        xe[..., :self.d] = np.moveaxis(x, 0, -1)
        xt, xh = np.take(xe, self.t, axis=-1), np.take(xe, self.h, axis=-1)  # (b, [r,] m)
        out = np.empty((q, *extra, m))
        for s_ in range(q):
            o = out[s_]
            np.multiply(At[s_, 0], xt[0], out=o)
            o += Bt[s_, 0] * xh[0]
            for c in range(1, b):
                o += At[s_, c] * xt[c]
                o += Bt[s_, c] * xh[c]
        return np.ascontiguousarray(np.moveaxis(out, -1, 0))

    def rmatvec(self, r: np.ndarray) -> np.ndarray:
        """Mᵀ r (d, b[, r]) for r (m, q[, r])."""
        At, Bt, m, q, b = self.At, self.Bt, self.m, self.q, self.b
        extra = r.shape[2:]
        k = int(np.prod(extra, dtype=np.int64))
        rt = np.moveaxis(r, 0, -1)  # (q, [r,] m)
        u = np.empty((b, *extra, 2 * m))  # per component: the tails' terms, then the heads'
        for c in range(b):
            ut, uh = u[c, ..., :m], u[c, ..., m:]
            np.multiply(At[0, c], rt[0], out=ut)
            np.multiply(Bt[0, c], rt[0], out=uh)
            for s_ in range(1, q):
                ut += At[s_, c] * rt[s_]
                uh += Bt[s_, c] * rt[s_]
        rows = u.reshape(b * k, 2 * m)
        out = np.empty((b * k, self.d))
        for i in range(b * k):  # one bincount per (component, right-hand side) over the shared ends
            out[i] = np.bincount(self.ends, rows[i], minlength=self.d + 1)[:self.d]
        return np.ascontiguousarray(np.moveaxis(out.reshape(b, *extra, self.d), -1, 0))


class PoseFactor(Factor):
    """A ``linalg.Factor`` of a system of (N) solved through the pose-level elimination: ``solve(rhs)``
    for rhs (d·b,) or (d·b, r) pose-major; ``blocks`` the ``multifrontal.BlockFactor``."""

    def __init__(self, blocks: BlockFactor, slots: np.ndarray):
        self.blocks = blocks
        self.slots = slots
        order = np.argsort(slots)

        def solve(rhs: np.ndarray) -> np.ndarray:
            return blocks.solve_slots(rhs[order])[slots]

        super().__init__(solve, slots.size, "multifrontal")


#: Systems with at least this many unknowns (d·b) are factored by the multifrontal engine
#: (``lago_cvx.sparse.multifrontal``), smaller ones by QDLDL in the pose-level order (``lago_cvx.sparse.ldl``), whose C
#: loop has no per-front Python cost. Measured (2 cores, a slow day of the shared machine; phase 3 from
#: benchmarks/perf.md's last table, four runs; b = 1, 2 by factor plus refined solve of the isotropic
#: positions and the chordal system, two runs each, the symbolic steps included):
#:   b = 3, 100 000 poses (300 k unknowns): QDLDL 1.7–1.9 s, engine 2.0–2.8;
#:   b = 3, 300 000 poses (900 k): 7.4–11.6 against 7.7–10.8 over six runs (four of perf.md, two of
#:   the seed route with ENGINE_MIN switched): means 9.0 and 9.1, parity;
#:   b = 3, 1 000 000 poses (3 M): 70–85 against 37–42;
#:   b = 2, 300 000 poses (600 k): 2.1–2.8 against 3.0–5.1;  b = 2, 1 000 000 poses (2 M): 22 against 17–19;
#:   b = 1, 300 000 poses: 1.2–1.3 against 2.6–4.1;  b = 1, 1 000 000 poses (1 M): 3.2–3.9 against 6.1–10.4.
#: So the threshold sits between 1 M and 2 M unknowns, at phase 3's parity around 300 000 poses. (Before
#: QDLDL was called in the pose order it ran its own AMD and the crossover was 250 000 unknowns.)
#: ``GraphElimination.factor(engine=...)`` forces either; ``Phase3.pose_covariances`` refactors a QDLDL
#: system by the engine for its selected inversion (``QdldlFactor.engine_factor``).
ENGINE_MIN = 1_200_000

#: Systems with at least this many unknowns are factored by the compiled engine (``lago_cvx.sparse.compiled``)
#: when Numba can be imported (it then takes the place of the NumPy engine above ``ENGINE_MIN`` too).
#: Phase 3 alone, a fresh process each (benchmarks/million.md): QDLDL against compiled + Numba's import
#: 0.280 against 0.235 + 0.160 s at 90 000 unknowns, 1.10 against 0.64 + 0.16 s at 300 000, 5.61 against
#: 1.62 + 0.17 s at 900 000 (another run: 0.375 against 0.216 + 0.160, 1.06 against 0.57 + 0.16, 4.41
#: against 1.50 + 0.16; with ``multifrontal.COMPILED_RELAX``; before it, 0.48 against 0.81 + 0.30, 2.31
#: against 1.68 + 0.32, 8.5 against 3.8 + 0.24). Kept where the gain is clear of the noise.
COMPILED_MIN = 300_000


class RenumberedFactor(Factor):
    """A pose-major factor (``PoseFactor`` or ``QdldlFactor``, variable i·b + c) seen in a system's own
    numbering: ``var_index`` (d, b) the system's index of (pose i, component c). ``pose_major`` the
    original factor (its ``blocks`` serve the selected inversion)."""

    def __init__(self, factor: Factor, var_index: np.ndarray):
        vi = np.asarray(var_index, np.int64).reshape(-1)
        self.pose_major = factor

        def solve(rhs: np.ndarray) -> np.ndarray:
            out = np.empty_like(rhs, dtype=float)
            out[vi] = factor.solve(rhs[vi])
            return out

        def renumbered():  # N in the system's numbering: entry (vi[k], vi[l]) = pose-major (k, l)
            m = factor.matrix
            if m is None:
                return None
            inv = np.empty_like(vi)
            inv[vi] = np.arange(vi.size)
            return sp.csc_matrix(m)[inv][:, inv]

        super().__init__(solve, vi.size, factor.backend, renumbered)


class GraphElimination:
    """The pose-level elimination of one graph and anchor (index ``anchor_index``), shared by its systems.

    ``d`` free poses; ``free_of`` (n,) each pose's free index (−1 at the anchor); ``tails``, ``heads``
    (m,) edges' ends as free indices; ``plan`` the ``EliminationPlan``. With ``weights`` (m,) the order
    is AMD's on the pose graph (``lago_cvx.sparse.amd``; through ``qdldl.Solver`` where AMD cannot be called
    directly) and the weighted Laplacian A2 diag(weights) A2ᵀ is factored in it and kept in ``laplacian``
    (phase 1's normal matrix when weights = 1/P_δ; None if it could not be factored): here, or on first
    read with ``factor_laplacian=False``."""

    def __init__(self, graph, anchor_index: int, *, weights: np.ndarray | None = None,
                 factor_laplacian: bool = True):
        import qdldl

        n = graph.n_poses
        self.n = n
        self.d = d = n - 1
        self.anchor_index = int(anchor_index)
        self.free_of = np.full(n, -1, np.int64)
        self.free_of[np.delete(np.arange(n), self.anchor_index)] = np.arange(d)
        self.tails = self.free_of[graph.tails]
        self.heads = self.free_of[graph.heads]
        self._assemblers = {}
        self._preparing: dict = {}
        self._laplacian, self._lap_pending, self._lap_lock = None, None, threading.Lock()
        both = (self.tails >= 0) & (self.heads >= 0)
        self._lo = np.minimum(self.tails, self.heads)[both]
        self._hi = np.maximum(self.tails, self.heads)[both]
        self._plan = None
        self._plan_lock = threading.Lock()
        self._upper_patterns = {}
        self._pose_pattern = None
        self._deferred: list = []
        if d == 0:
            self._plan = EliminationPlan(0, np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64),
                                         np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
            return
        if weights is not None and self._own_laplacian(np.asarray(weights, dtype=float), factor_laplacian):
            return
        if weights is not None:
            w = np.asarray(weights, dtype=float)
            lo, hi = self._lo, self._hi
            diag = np.bincount(self.tails[self.tails >= 0], w[self.tails >= 0], minlength=d) + \
                np.bincount(self.heads[self.heads >= 0], w[self.heads >= 0], minlength=d)
            Lap = sp.csc_matrix((np.r_[-w[both], diag], (np.r_[lo, np.arange(d)], np.r_[hi, np.arange(d)])),
                                shape=(d, d))
            try:
                solver = qdldl.Solver(Lap, upper=True)
                self._laplacian = (solver, Lap)
            except Exception as exc:  # not quasi-definite in floating point: the plan from the pattern alone
                log.info("weighted pose Laplacian not factored by QDLDL (%s); plan from the pattern", exc)

    def _own_laplacian(self, w: np.ndarray, now: bool) -> bool:
        """AMD of the pose graph called directly (``lago_cvx.sparse.amd``) and the weighted Laplacian factored on
        the graph's b = 1 pattern (``upper_pattern.PoseLaplacian``), here (``now``) or when ``laplacian`` is
        first read; False (nothing kept) when AMD cannot be called, and ``qdldl.Solver`` orders and factors
        the Laplacian instead."""
        from . import amd, ldl

        perm = amd.order(self.d, self._lo, self._hi) if ldl.available() else None
        if perm is None:
            return False
        self._position = np.empty(self.d, np.int64)
        self._position[perm] = np.arange(self.d)
        self._lap_pending = (w, perm)
        if now and self.laplacian is None:  # a zero pivot: as with qdldl.Solver, the plan from the pattern
            del self._position
            self._upper_patterns, self._pose_pattern = {}, None
        return True

    @property
    def laplacian(self):
        """(a factor with ``solve``, ``factors()`` and ``matrix()`` of the weighted pose Laplacian, None) —
        or ``(qdldl.Solver, its upper triangle)`` when AMD could not be called directly; None without
        weights or when QDLDL met a zero pivot. Factored on first read when the constructor was told to
        wait (``factor_laplacian=False``: the chordal route factors it beside its relaxation)."""
        if self._lap_pending is not None:
            with self._lap_lock:
                if self._lap_pending is not None:
                    w, perm = self._lap_pending
                    try:
                        self._laplacian = (PoseLaplacian(self.upper_pattern(1), w, perm), None)
                    except Exception as exc:
                        log.info("weighted pose Laplacian not factored by QDLDL (%s); plan from the pattern", exc)
                    self._lap_pending = None
        return self._laplacian

    @property
    def plan(self) -> EliminationPlan:
        """The pose-level ``EliminationPlan``, built on first use (the multifrontal engine and the selected
        inversion need it, QDLDL's solves do not): from the QDLDL factorization of the weighted Laplacian
        when there is one (its AMD ordering and L's pattern), else from the pattern."""
        if self._plan is not None:
            return self._plan
        with self._plan_lock:  # built once, whichever thread asks first (GraphElimination.prepare's or this)
            if self._plan is not None:
                return self._plan
            relaxation = self.relaxation
            if self.laplacian is not None:
                L, _, perm = self.laplacian[0].factors()
                self._plan = plan_from_qdldl(L, perm, relaxation=relaxation)
            else:
                self._plan = plan_from_pattern(self.d, self._lo, self._hi, relaxation=relaxation)
        return self._plan

    @property
    def relaxation(self):
        """The plan's amalgamation: ``multifrontal.COMPILED_RELAX`` when phase 3 (3d unknowns) will be
        factored by the compiled engine, else None (the NumPy engine's default)."""
        if self.d * 3 >= COMPILED_MIN and compiled.available():
            return COMPILED_RELAX
        return None

    @property
    def elimination_position(self) -> np.ndarray:
        """(d,) each free pose's place in the elimination order: the AMD order of the weighted Laplacian's
        QDLDL factorization when there is one (no plan built), else the plan's."""
        if "_position" not in self.__dict__:
            if self.laplacian is not None:
                perm = self.laplacian[0].factors()[2]
                pos = np.empty(self.d, np.int64)
                pos[np.asarray(perm, np.int64)] = np.arange(self.d)
                self._position = pos
            else:
                self._position = self.plan.position
        return self._position

    def defer(self, task) -> None:
        """Register ``task()``, work LAGO will need later on this graph (a pattern, a θ-independent
        factorization), to be done while QDLDL factors another system in a worker thread: on the second
        core, as ``ctypes`` releases the GIL. A task that fails is dropped (logged); whoever needs its
        result later computes it then and meets the error there."""
        self._deferred.append(task)

    def cancel_deferred(self) -> None:
        """Drop the tasks not run yet (no QDLDL factorization came to run them beside)."""
        self._deferred = []

    def deferred_work(self):
        """A callable running the deferred tasks (in order, each once), or None when there are none."""
        if not self._deferred:
            return None

        def run():
            tasks, self._deferred = self._deferred, []  # taken first: a task that factors starts no other
            for task in tasks:
                try:
                    task()
                except Exception as exc:  # redone, and raised, where it is needed
                    log.debug("deferred %r failed (%s): done when needed", task, exc)

        return run

    def upper_pattern(self, b: int) -> BlockUpperPattern | None:
        """The ``BlockUpperPattern`` of the systems with b×b blocks (built once per b), or None when QDLDL's
        C routines cannot be called directly (``ldl.available()``)."""
        from . import ldl

        if not ldl.available():
            return None
        if b not in self._upper_patterns:
            if self._pose_pattern is None:
                self._pose_pattern = PoseUpperPattern(self.elimination_position, self.pairs)
            self._upper_patterns[b] = BlockUpperPattern(self._pose_pattern, b)
        return self._upper_patterns[b]

    @property
    def pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(prow, pcol, keep) of the blocks ``EdgeSystem.normal_blocks`` returns: tail diagonals, head
        diagonals, (head, tail) off-diagonals; ``keep`` (3m,) those between free poses."""
        t, h = self.tails, self.heads
        prow = np.concatenate([t, h, h])
        pcol = np.concatenate([t, h, t])
        keep = (prow >= 0) & (pcol >= 0)
        return prow, pcol, keep

    def slots(self, b: int) -> np.ndarray:
        """Elimination slot of each pose-major variable i·b + c."""
        return (self.plan.position[:, None] * b + np.arange(b)).reshape(-1)

    def factor(self, system: EdgeSystem, *, progress=None, engine: bool | str | None = None) -> Factor:
        """Factor the normal matrix (N) of ``system``. ``engine`` None (the default) picks by size: the
        compiled multifrontal engine (a ``CompiledPoseFactor``, ``lago_cvx.sparse.compiled``) from
        ``COMPILED_MIN`` unknowns when Numba can be imported, else the NumPy multifrontal engine (a
        ``PoseFactor``) from ``ENGINE_MIN``, QDLDL (a ``QdldlFactor``) below; ``"compiled"``, True (the
        NumPy engine) or False (QDLDL) force one. Raises ``multifrontal.NotPositiveDefinite`` (or
        QDLDL's error) if N is not numerically SPD."""
        b = system.b
        job = self._preparing.pop(b, None)
        if job is not None:
            job.join()
        if engine == "compiled" or (engine is None and system.d * b >= COMPILED_MIN and compiled.available()):
            if ("compiled", b) not in self._assemblers:
                prow, pcol, _ = self.pairs
                lay = compiled.CompiledLayout.of(self.plan, b)
                self._assemblers["compiled", b] = (lay, lay.assembler(prow, pcol))
            lay, asm = self._assemblers["compiled", b]
            cf = lay.factor(asm, system.A, system.B, progress=progress)
            return compiled.CompiledPoseFactor(cf, self.slots(b), system, self)
        if not (engine if engine is not None else system.d * b >= ENGINE_MIN):
            prow, pcol, keep = self.pairs
            return QdldlFactor(system, (prow, pcol), keep, pattern=self.upper_pattern(b), elimination=self,
                               progress=progress)
        if b not in self._assemblers:
            prow, pcol, keep = self.pairs
            lay = self.plan.layout(b)
            self._assemblers[b] = (lay, lay.assembler(prow[keep], pcol[keep]), keep)
        lay, asm, keep = self._assemblers[b]
        blocks = system.normal_blocks()[keep]
        bf = lay.factor(asm, blocks, progress=progress)
        return PoseFactor(bf, self.slots(b))

    def prepare(self, b: int) -> None:
        """Start building, in a worker thread, what the compiled factorization of a system with b×b blocks
        will need — the plan, its ``compiled.CompiledLayout``, the assembler, and L's storage allocated
        and touched (``CompiledLayout.reserve``: first touches of fresh memory are costly, in a virtual
        machine more than 1 s per GiB) — while this thread goes on (phases 1 and 2 before phase 3).
        Nothing happens below ``COMPILED_MIN`` unknowns or without Numba; ``factor`` waits for the
        worker. A failure there is logged and the work redone where it is needed."""
        import threading

        if self.d * b < COMPILED_MIN or b in self._preparing or ("compiled", b) in self._assemblers:
            return

        def work():
            try:
                if not compiled.available():
                    return
                lay = compiled.CompiledLayout.of(self.plan, b)
                touch = threading.Thread(target=lay.reserve, daemon=True, name="lago-reserve")
                touch.start()  # L's pages faulted in beside the assembler's work
                prow, pcol, _ = self.pairs
                asm = lay.assembler(prow, pcol)
                touch.join()
                self._assemblers["compiled", b] = (lay, asm)
            except Exception as exc:  # redone, and raised, where it is needed
                log.debug("preparing the compiled factorization failed (%s): done when needed", exc)

        job = threading.Thread(target=work, daemon=True, name="lago-prepare")
        job.start()
        self._preparing[b] = job

    def solve(self, system: EdgeSystem, *, factor: PoseFactor | None = None, stage: str = "solve",
              progress=None):
        """Minimise (E): returns ``(x (d, b), factor, stats)`` with ``stats`` as
        ``linalg.solve_least_squares`` reports it (``factor`` None after the augmented-system fallback).
        A given ``factor`` (of the same normal matrix) is reused."""
        d, b = system.d, system.b
        stats = {"method": "normal equations", "refinement_steps": 0, "relative_correction": 0.0}
        if d == 0:
            return np.zeros((0, b) + system.c.shape[2:]), None, stats
        tracker = Progress(stage, callback=progress, logger=log) if progress is not None or d > 200_000 else None
        trusted = False
        x = None
        extra = system.c.shape[2:]  # several right-hand sides: (d·b, r)
        m, q = system.c.shape[:2]
        ahead = {}

        def operator_ahead():  # M's operator and Mᵀc, while QDLDL factors (they do not need the factor)
            ahead["op"] = system.operator()
            ahead["first"] = ahead["op"].rmatvec(system.c).reshape((d * b,) + extra)

        try:
            if factor is None:
                self.defer(operator_ahead)
                try:
                    factor = self.factor(system, progress=None if tracker is None else
                                         (lambda i, n: tracker.update(0.9 * i / n)))
                finally:
                    if operator_ahead in self._deferred:  # not run (no QDLDL factorization to run beside)
                        self._deferred.remove(operator_ahead)
            op = ahead.get("op") or system.operator()
            x, stats, trusted = refine_normal_equations(
                factor.solve,
                lambda v: op.matvec(v.reshape((d, b) + extra)).reshape((m * q,) + extra),
                lambda r: op.rmatvec(r.reshape((m, q) + extra)).reshape((d * b,) + extra),
                system.c.reshape((m * q,) + extra), first=ahead.get("first"))
        except Exception as exc:  # NotPositiveDefinite, QDLDL "not quasi-definite", LinAlgError
            log.info("normal equations could not be factored (%s): using the augmented system", exc)
        if not trusted:
            log.warning("least squares: normal equations too ill-conditioned (relative correction %.2g); "
                        "solving the augmented system instead", stats["relative_correction"])
            cc = system.c.reshape(system.c.shape[0] * system.c.shape[1], -1)
            M = system.sparse()
            x = np.stack([augmented_least_squares(M, cc[:, j]) for j in range(cc.shape[1])], 1)
            stats["method"] = "augmented system"
            factor = None
        if tracker is not None:
            tracker.finish()
        return x.reshape((d, b) + system.c.shape[2:]), factor, stats

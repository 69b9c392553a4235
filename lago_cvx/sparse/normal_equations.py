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
compiled (``lago_cvx.sparse.compiled``: C kernels, Numba's when they are not built) from ``COMPILED_MIN``
unknowns when it can run, the NumPy engine (``lago_cvx.sparse.multifrontal``) otherwise.
Either way (E) is solved by the corrected semi-normal equations
(``lago_cvx.sparse.linalg.refine_normal_equations``), falling back to the augmented system as
``lago_cvx.sparse.linalg.solve_least_squares`` does.
"""

from __future__ import annotations

import logging
import threading

import numpy as np
import scipy.sparse as sp

from .edge_system import EdgeOperator, EdgeSystem
from .linalg import Factor, augmented_least_squares, refine_normal_equations
from . import compiled
from .compiled import CompiledPoseFactor
from .block_factor import inverse_blocks
from .multifrontal import COMPILED_RELAX, BlockFactor, EliminationPlan, plan_from_pattern, plan_from_qdldl
from ..progress import Progress
from .threads import Ahead, cores, engine_threads, in_engine_threads, spawn, thread_settings
from .upper_pattern import BlockUpperPattern, PoseLaplacian, PoseUpperPattern, QdldlFactor, matrix_blocks
from . import wide as wide_policy

__all__ = ["plan_from_pattern", "matrix_blocks", "EdgeSystem", "EdgeOperator", "GraphElimination", "PoseFactor", "BlockUpperPattern", "PoseUpperPattern", "QdldlFactor", "RenumberedFactor", "CompiledPoseFactor", "ENGINE_MIN", "COMPILED_MIN", "COMPILED_FLOPS"]

log = logging.getLogger(__name__)


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
#: loop has no per-front Python cost. QDLDL is faster up to about 1 M unknowns, the engine from about 2 M (phase 3
#: of 100 000 – 1 000 000-pose worlds, b = 1, 2, 3: ``benchmarks/million.md``, ``benchmarks/scaling.md``).
#: ``GraphElimination.factor(engine=...)`` forces either; ``Phase3.pose_covariances`` refactors a QDLDL
#: system by the engine for its selected inversion (``QdldlFactor.engine_factor``).
ENGINE_MIN = 1_200_000

#: Systems with at least this many unknowns are factored by the compiled engine (``lago_cvx.sparse.compiled``)
#: when it can run (C kernels or Numba; it then takes the place of the NumPy engine above ``ENGINE_MIN`` too).
#: From here the compiled engine, its start included, beats QDLDL clear of the noise (phase 3 alone, fresh
#: processes, 90 000 – 900 000 unknowns: ``benchmarks/million.md``).
COMPILED_MIN = 300_000

#: Below ``COMPILED_MIN`` unknowns, a system whose factorization costs at least this many multiply–adds
#: (``EliminationPlan.flops(b)``, the Cholesky count Σ colcount²) is factored by the compiled engine too when its C
#: kernels are built (``compiled.native()``): QDLDL's scalar up-looking loop runs at about 1.3 GFlop/s where the
#: compiled engine's dense fronts run at 4–6. Long edges across a graph (false loop closures joining random poses)
#: fill the factor: on se-sync/city10000.g2o with 10 % of them phase 3 costs 4.8·10¹⁰ multiply–adds (1.75·10⁸
#: clean), 37 s by QDLDL, 8.7 s compiled; on M3500 with 30 %, 5.4·10⁹: 3.6 s and 1.6 s (``benchmarks/robust.md``).
#: Every clean planar file of the datasets stays far below (city10000: 1.75·10⁸ at b = 3), on its route as before.
COMPILED_FLOPS = 2e9

#: Below this many free poses the engine works in the caller's thread alone: no worker builds the
#: elimination, and QDLDL runs no handed-over work beside its factorizations (they run when asked for).
#: Handing work to a thread and taking the GIL back cost more than they save on small graphs (MIT, input_INTEL,
#: manhattan; city10000 gains: the in-process table of ``benchmarks/perf.md``).
OVERLAP_MIN = 2_500


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


def edge_operator(system: EdgeSystem):
    """M and Mᵀ of ``system`` with their set-up done once (for the refinement's repeated products): a
    ``compiled.CompiledEdgeOperator`` from ``COMPILED_MIN`` unknowns when the compiled engine can run (the same
    sums in the same order), else an ``EdgeOperator``."""
    if system.d * system.b >= COMPILED_MIN and compiled.available():
        return compiled.CompiledEdgeOperator(system)
    return EdgeOperator(system)


def marginal_blocks(N, var_index: np.ndarray, *, factor: Factor | None = None, progress=None) -> np.ndarray:
    """The diagonal b×b blocks (d, b, b) of N⁻¹ for the variables ``var_index`` (d, b) of each free pose —
    marginal covariances when N is an information matrix — by selected inversion (Takahashi's recurrences,
    eq. (T) of ``lago_cvx.sparse.multifrontal``), never a dense inverse. On ``factor`` when it is the
    engine's factor of N through a ``GraphElimination`` (a QDLDL factor is refactored by the multifrontal
    engine on the graph's shared plan), else on a factorization of N (a sparse matrix, or a function that
    builds it) on its own pose-level plan. ``progress(done, total)`` is told about the sweep."""
    pm = getattr(factor, "pose_major", factor)
    if hasattr(pm, "engine_factor"):
        pm = pm.engine_factor()
    if isinstance(pm, PoseFactor):
        return inverse_blocks(pm.blocks, progress=progress)[0]
    N = N() if callable(N) else N
    var_index = np.asarray(var_index, np.int64)
    d, b = var_index.shape
    prow, pcol, blocks = matrix_blocks(N, var_index)
    off = prow != pcol
    lay = plan_from_pattern(d, prow[off], pcol[off]).layout(b)
    return inverse_blocks(lay.factor(lay.assembler(prow, pcol), blocks), progress=progress)[0]


class GraphElimination:
    """The pose-level elimination of one graph and anchor (index ``anchor_index``), shared by its systems.

    ``d`` free poses; ``free_of`` (n,) each pose's free index (−1 at the anchor); ``tails``, ``heads``
    (m,) edges' ends as free indices; ``plan`` the ``EliminationPlan``. With ``weights`` (m,) the order
    is AMD's on the pose graph (``lago_cvx.sparse.amd``; through ``qdldl.Solver`` where AMD cannot be called
    directly) and the weighted Laplacian A2 diag(weights) A2ᵀ is factored in it: a system (E) with b = q = 1,
    A_k = −√w_k, B_k = √w_k (phase 1's, eq. (13)) is solved by that factorization.

    ``GraphElimination.start(graph, a, weights=…, expect=(2, 3, …))`` builds the same in a worker thread
    (AMD and QDLDL release the GIL) and returns at once; whatever needs it waits, and a failure there is
    raised to the caller that waits. ``expect`` announces the block sizes of the systems that will be
    factored, in order (the chordal relaxation's 2, phase 3's 3, the positions' 1 or 2): what each will
    need is prepared ahead — patterns beside another factorization, the compiled engine's layout and
    memory in a worker (``prepare``). ``ahead(task)`` hands over other work needed later (an
    ``Ahead``); the engine runs it beside the next QDLDL factorization, else it runs when first asked for.
    ``wide``: the block sizes of the systems that ``factor_wide`` will factor (3-D; ``wide_compiled``).
    ``workers`` caps the engine's own threads for everything done on this elimination (None: ``threads.cores()``;
    1: no thread besides the caller's); ``blas_threads`` lets the engine hold the process's BLAS to that many
    threads while it factors (None, the default: the BLAS settings are left alone; ``threads.engine_threads``)."""

    def __init__(self, graph, anchor_index: int, *, weights: np.ndarray | None = None,
                 factor_laplacian: bool | None = True, expect: tuple = (), wide: tuple = (),
                 workers: int | None = None, blas_threads: int | None = None, _background: bool = False):
        with engine_threads(workers=workers, blas_threads=blas_threads):  # checks both; None: the caller's context
            self.workers, self.blas_threads, alone = thread_settings() + (cores() == 1,)
        n = graph.n_poses
        self.n = n
        self.d = d = n - 1
        self.anchor_index = int(anchor_index)
        self.free_of = np.full(n, -1, np.int64)
        self.free_of[np.delete(np.arange(n), self.anchor_index)] = np.arange(d)
        self.tails = self.free_of[graph.tails]
        self.heads = self.free_of[graph.heads]
        self._weights = None if weights is None else np.asarray(weights, dtype=float)
        self._expected = [int(b) for b in expect]
        self._wide = tuple(int(b) for b in wide)
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
        self._tasks: list = []  # Ahead tasks waiting for a factorization to run beside
        self._internal: dict = {}  # the engine's own tasks among them, by key
        self._building = None
        if d == 0:
            self._plan = EliminationPlan(0, np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64),
                                         np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
            return
        if factor_laplacian is None:  # QDLDL will factor the chordal relaxation first: Ω_θ beside it
            factor_laplacian = not (self._expected[:1] == [2] and 2 * d < COMPILED_MIN)
        if _background and d >= OVERLAP_MIN and not alone:
            self._building = Ahead(self._build, factor_laplacian)
            spawn(self._building.run, name="lago-elimination")
        else:
            self._build(factor_laplacian)

    @classmethod
    def start(cls, graph, anchor_index: int, *, weights: np.ndarray, expect: tuple = (), workers: int | None = None,
              blas_threads: int | None = None) -> "GraphElimination":
        """The elimination built in a worker thread while the caller goes on (class docstring)."""
        return cls(graph, anchor_index, weights=weights, factor_laplacian=None, expect=expect, workers=workers,
                   blas_threads=blas_threads, _background=True)

    def _build(self, factor_laplacian: bool) -> None:
        """AMD and the weighted Laplacian's factorization (or, without weights, nothing: the plan is built
        from the pattern when first needed); with the Laplacian left for later, the chordal relaxation's
        pattern (b = 2) instead."""
        import qdldl

        d = self.d
        if self._weights is None:
            return
        if self._own_laplacian(self._weights, factor_laplacian):
            if not factor_laplacian:
                self._upper_pattern(2)
            return
        w = self._weights
        t, h = self.tails, self.heads
        both = (t >= 0) & (h >= 0)
        diag = np.bincount(t[t >= 0], w[t >= 0], minlength=d) + np.bincount(h[h >= 0], w[h >= 0], minlength=d)
        Lap = sp.csc_matrix((np.r_[-w[both], diag], (np.r_[self._lo, np.arange(d)], np.r_[self._hi, np.arange(d)])),
                            shape=(d, d))
        try:
            self._laplacian = (qdldl.Solver(Lap, upper=True), Lap)
        except Exception as exc:  # not quasi-definite in floating point: the plan from the pattern alone
            log.info("weighted pose Laplacian not factored by QDLDL (%s); plan from the pattern", exc)

    def _ready(self) -> None:
        """Wait for the worker building the elimination (``start``), raising its error here; the first time,
        set up what the announced systems need (class docstring)."""
        job = self._building
        if job is None:
            return
        job.result()
        self._building = None
        if self._expected:
            self.prepare(self._expected[0])
        for b in sorted(set(self._expected)):  # QDLDL's patterns, where QDLDL will factor
            if self.d * b < COMPILED_MIN:
                self._internal_task(("pattern", b), self._upper_pattern, b)
        self._internal_task(("laplacian",), self._factor_laplacian)

    def _own_laplacian(self, w: np.ndarray, now: bool) -> bool:
        """AMD of the pose graph called directly (``lago_cvx.sparse.amd``) and the weighted Laplacian factored
        on the graph's b = 1 pattern (``upper_pattern.PoseLaplacian``), here (``now``) or when ``laplacian``
        is first read; False (nothing kept) when AMD cannot be called, and ``qdldl.Solver`` orders and
        factors the Laplacian instead."""
        from . import amd, ldl

        perm = amd.order(self.d, self._lo, self._hi) if ldl.available() else None
        if perm is None:
            return False
        self._position = np.empty(self.d, np.int64)
        self._position[perm] = np.arange(self.d)
        self._lap_pending = (w, perm)
        if now and self._factor_laplacian() is None:  # a zero pivot: as qdldl.Solver, the plan from the pattern
            del self._position
            self._upper_patterns, self._pose_pattern = {}, None
        return True

    @property
    def laplacian(self):
        """(a factor with ``solve``, ``factors()`` and ``matrix()`` of the weighted pose Laplacian, None) —
        or ``(qdldl.Solver, its upper triangle)`` when AMD could not be called directly; None without
        weights or when QDLDL met a zero pivot."""
        self._ready()
        return self._factor_laplacian()

    def _factor_laplacian(self):
        if self._lap_pending is not None:
            with self._lap_lock:
                if self._lap_pending is not None:
                    w, perm = self._lap_pending
                    try:
                        self._laplacian = (PoseLaplacian(self._upper_pattern(1), w, perm), None)
                    except Exception as exc:
                        log.info("weighted pose Laplacian not factored by QDLDL (%s); plan from the pattern", exc)
                    self._lap_pending = None
        return self._laplacian

    @property
    def plan(self) -> EliminationPlan:
        """The pose-level ``EliminationPlan``, built on first use (the multifrontal engine and the selected
        inversion need it, QDLDL's solves do not): from the QDLDL factorization of the weighted Laplacian
        when there is one (its AMD ordering and L's pattern), else from the pattern."""
        self._ready()
        return self._get_plan()

    def _get_plan(self) -> EliminationPlan:
        if self._plan is not None:
            return self._plan
        with self._plan_lock:  # built once, whichever thread asks first (prepare's worker or this)
            if self._plan is not None:
                return self._plan
            relaxation = self.relaxation
            if self._factor_laplacian() is not None:
                L, _, perm = self._laplacian[0].factors()
                self._plan = plan_from_qdldl(L, perm, relaxation=relaxation)
            else:
                self._plan = plan_from_pattern(self.d, self._lo, self._hi, relaxation=relaxation)
        return self._plan

    @property
    def wide_compiled(self) -> bool:
        """The ``wide`` systems reach ``wide.compiled_from()`` unknowns: the compiled engine factors them all."""
        return bool(self._wide) and self.d * max(self._wide) >= wide_policy.compiled_from()

    @property
    def relaxation(self):
        """The plan's amalgamation: ``multifrontal.COMPILED_RELAX`` when phase 3 (3d unknowns) or the announced
        wide systems will be factored by the compiled engine, else None (the NumPy engine's default)."""
        if (self.d * 3 >= COMPILED_MIN or self.wide_compiled) and compiled.available():
            return COMPILED_RELAX
        return None

    @property
    def elimination_position(self) -> np.ndarray:
        """(d,) each free pose's place in the elimination order: the AMD order of the weighted Laplacian's
        QDLDL factorization when there is one (no plan built), else the plan's."""
        self._ready()
        return self._elimination_position()

    def _elimination_position(self) -> np.ndarray:  # (the worker's ``_build`` calls only private methods)
        if "_position" not in self.__dict__:
            if self._factor_laplacian() is not None:
                perm = self._laplacian[0].factors()[2]
                pos = np.empty(self.d, np.int64)
                pos[np.asarray(perm, np.int64)] = np.arange(self.d)
                self._position = pos
            else:
                self._position = self._get_plan().position
        return self._position

    # ------------------------------------------------------------------ work done ahead
    def ahead(self, task, *args) -> Ahead:
        """``task(*args)``, work needed later on this graph (a θ-independent factorization, a trial solve),
        done beside the next QDLDL factorization (on the second core: ``ctypes`` releases the GIL there) or
        else when its ``result()`` is first asked for; ``result()`` raises the task's error."""
        job = Ahead(task, *args)
        self._tasks.append(job)
        return job

    def _internal_task(self, key, task, *args) -> None:
        """The engine's own work ahead, queued before the tasks handed over by the caller."""
        if key not in self._internal:
            mine = sum(1 for t in self._tasks if any(t is j for j in self._internal.values()))
            self._internal[key] = job = Ahead(task, *args)
            self._tasks.insert(mine, job)

    def _drop_internal(self, key) -> None:
        job = self._internal.pop(key, None)
        if job is not None and job in self._tasks:
            self._tasks.remove(job)

    def deferred_work(self):
        """A callable running the tasks handed over ahead (in order, each once), or None when there are
        none or the graph is too small to gain from it (``OVERLAP_MIN``); called by QDLDL's factorization
        (``upper_pattern.QdldlFactor``) while its C call runs."""
        if not self._tasks or self.d < OVERLAP_MIN:
            return None

        def run():
            tasks, self._tasks = self._tasks, []  # taken first: a task that factors starts no other
            for job in tasks:
                job.run()  # an error is kept for whoever asks for the result

        return run

    # ------------------------------------------------------------------ patterns and factors
    def upper_pattern(self, b: int) -> BlockUpperPattern | None:
        """The ``BlockUpperPattern`` of the systems with b×b blocks (built once per b), or None when QDLDL's
        C routines cannot be called directly (``ldl.available()``)."""
        self._ready()
        job = self._internal.get(("pattern", b))
        if job is not None and job.done:
            job.result()  # its error, if building it failed beside a factorization
        return self._upper_pattern(b)

    def _upper_pattern(self, b: int) -> BlockUpperPattern | None:
        from . import ldl

        if not ldl.available():
            return None
        if b not in self._upper_patterns:
            if self._pose_pattern is None:
                self._pose_pattern = PoseUpperPattern(self._elimination_position(), self.pairs)
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

    def _is_laplacian(self, system: EdgeSystem) -> bool:
        """True for the system whose normal matrix is the weighted Laplacian factored ahead: b = q = 1 with
        B_k = √w_k = −A_k (to rounding) on this graph's edges."""
        if self._weights is None or system.b != 1 or system.A.shape[1] != 1 or system.d != self.d:
            return False
        Bk = system.B[:, 0, 0]
        return (Bk.shape == self._weights.shape and np.array_equal(system.A[:, 0, 0], -Bk)
                and np.array_equal(system.tails, self.tails) and np.array_equal(system.heads, self.heads)
                and np.allclose(Bk * Bk, self._weights, rtol=1e-12, atol=0.0))

    @in_engine_threads
    def factor(self, system: EdgeSystem, *, progress=None, engine: bool | str | None = None,
               solving: bool = False) -> Factor:
        """Factor the normal matrix (N) of ``system``. ``engine`` None (the default) picks: the weighted
        Laplacian's factorization when (N) is it (class docstring); else by size the compiled multifrontal
        engine (a ``CompiledPoseFactor``, ``lago_cvx.sparse.compiled``) from ``COMPILED_MIN`` unknowns when
        it can run, or from ``COMPILED_FLOPS`` multiply–adds with its C kernels; the NumPy multifrontal engine
        (a ``PoseFactor``) from ``ENGINE_MIN``, QDLDL (a ``QdldlFactor``) below; ``"compiled"``, True (the NumPy engine) or False (QDLDL) force one. Raises
        ``multifrontal.NotPositiveDefinite`` (or QDLDL's error) if N is not numerically SPD. The systems
        announced after this one are prepared once it is factored (``solving``: once ``solve`` is done
        with it, so that their preparation does not compete with its solves)."""
        self._ready()
        b = system.b
        if engine is None and self._is_laplacian(system) and self._factor_laplacian() is not None:
            return Factor(self._laplacian[0].solve, self.d, "qdldl", None)
        job = self._preparing.pop(b, None)
        if job is not None:
            job.result()
        compiled_route = engine == "compiled" or (engine is None and system.d * b >= COMPILED_MIN
                                                  and compiled.available()) or (
            engine is None and system.d == self.d and self.plan.flops(b) >= COMPILED_FLOPS and compiled.native())
        if compiled_route or (engine if engine is not None else system.d * b >= ENGINE_MIN):
            self._drop_internal(("pattern", b))  # QDLDL's pattern for b will not be needed
        try:
            if compiled_route:
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
        finally:
            if not solving:
                self._prepare_next(b)

    def _prepare_next(self, b: int) -> None:
        """After the next announced system (b×b blocks) is done with: the ones announced after it. A system
        that was not announced next (phase 1's Laplacian between them) changes nothing."""
        if self._expected and self._expected[0] == b:
            self._expected = self._expected[1:]
            for nb in self._expected:
                self.prepare(nb)

    @in_engine_threads
    def prepare(self, b: int) -> None:
        """Start building, in a worker thread, what the compiled factorization of a system with b×b blocks
        will need — the plan, its ``compiled.CompiledLayout``, the assembler, and L's storage allocated
        and touched (``CompiledLayout.reserve``: first touches of fresh memory are costly, above all in a
        virtual machine: ``benchmarks/million.md``) — while this thread goes on (phases 1 and 2 before phase 3).
        Nothing happens below ``COMPILED_MIN`` unknowns or without Numba; ``factor`` waits for the
        worker and raises its error."""
        if self.d * b < COMPILED_MIN or b in self._preparing or ("compiled", b) in self._assemblers or cores() == 1:
            return  # with one worker, ``factor`` builds what it needs when it needs it

        def work():
            if not compiled.available():
                return
            lay = compiled.CompiledLayout.of(self.plan, b)
            touch = spawn(lay.reserve, name="lago-reserve")  # L's pages faulted in beside the assembler's work
            prow, pcol, _ = self.pairs
            asm = lay.assembler(prow, pcol)
            touch.join()
            self._assemblers["compiled", b] = (lay, asm)

        job = Ahead(work)
        spawn(job.run, name="lago-prepare")
        self._preparing[b] = job

    def cost(self, system: EdgeSystem, x: np.ndarray) -> float:
        """‖M x − c‖² of ``system`` at x (d, b[, r]) (by the compiled products for large systems)."""
        r = edge_operator(system).matvec(x) - system.c
        return float(np.sum(r * r))

    @in_engine_threads
    def solve(self, system: EdgeSystem, *, factor: Factor | None = None, stage: str = "solve",
              progress=None):
        """Minimise (E): returns ``(x (d, b), factor, stats)`` with ``stats`` as
        ``linalg.solve_least_squares`` reports it (``factor`` None after the augmented-system fallback).
        A given ``factor`` (of the same normal matrix) is reused."""
        d, b = system.d, system.b
        stats = {"method": "normal equations", "refinement_steps": 0, "relative_correction": 0.0}
        if d == 0:
            return np.zeros((0, b) + system.c.shape[2:]), None, stats
        self._ready()  # the worker's error, if building the elimination failed, is raised here as it is
        tracker = Progress(stage, callback=progress, logger=log) if progress is not None or d > 200_000 else None
        trusted = False
        x = None
        extra = system.c.shape[2:]  # several right-hand sides: (d·b, r)
        m, q = system.c.shape[:2]

        def operator_and_first():  # M's operator and Mᵀc: they do not need the factor
            op = edge_operator(system)
            return op, op.rmatvec(system.c).reshape((d * b,) + extra)

        for attempt in range(2):  # the second with a factorization of its own, if the Laplacian's failed
            try:
                op, first = None, None
                if factor is None:
                    job = self.ahead(operator_and_first)
                    factor = self.factor(system, engine=None if attempt == 0 else False, solving=True,
                                         progress=None if tracker is None else
                                         (lambda i, n: tracker.update(0.9 * i / n)))
                    if job.done:
                        op, first = job.result()
                    elif job in self._tasks:  # not run (no QDLDL factorization to run beside)
                        self._tasks.remove(job)
                if op is None:
                    op = edge_operator(system)
                x, stats, trusted = refine_normal_equations(
                    factor.solve,
                    lambda v: op.matvec(v.reshape((d, b) + extra)).reshape((m * q,) + extra),
                    lambda r: op.rmatvec(r.reshape((m, q) + extra)).reshape((d * b,) + extra),
                    system.c.reshape((m * q,) + extra), first=first)
            except Exception as exc:  # NotPositiveDefinite, QDLDL "not quasi-definite", LinAlgError
                log.info("normal equations could not be factored (%s): using the augmented system", exc)
                break
            if trusted or attempt or factor.backend != "qdldl" or not self._is_laplacian(system):
                break
            factor = None
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
        self._prepare_next(b)
        return x.reshape((d, b) + system.c.shape[2:]), factor, stats

r"""Every closed form of LAGO (the chordal relaxation (C2), phase 1 eq. (13), phase 3 eqs. (12)/(15), the
positions (P), the 3-D systems) is a least-squares problem (E) (``edge_system``) on the free poses; written as
‖M x − c‖², its normal matrix N = MᵀM has the b×b blocks

    N_ii = Σ_{k: t_k = i} A_kᵀA_k + Σ_{k: h_k = i} B_kᵀB_k,    N_{h_k t_k} += B_kᵀA_k,              (N)

the anchor-reduced pose graph's pattern for every b. ``GraphElimination`` holds the pose-level symbolic analysis of
one graph and anchor (``multifrontal.EliminationPlan``), shared by every system on it, factors (N) by (MF) (in C,
``compiled``, or in NumPy, ``block_factor``) and solves (E) by the corrected semi-normal equations, falling back to
the augmented system (``linalg.refined_or_augmented``).
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import scipy.sparse as sp

from . import block_factor, compiled
from .block_factor import inverse_blocks
from .edge_system import EdgeSystem
from .linalg import Factor, refined_or_augmented
from .multifrontal import COMPILED_RELAX, EliminationPlan, plan_from_pattern
from ..progress import Progress
from .threads import Ahead, cores, engine_threads, in_engine_threads, spawn, thread_settings

__all__ = ["EdgeSystem", "GraphElimination", "PoseFactor", "RenumberedFactor", "marginal_blocks", "matrix_blocks",
           "OVERLAP_MIN"]

log = logging.getLogger(__name__)

#: Below this many free poses the engine works in the caller's thread alone: handing work to a thread and taking
#: the GIL back cost more than they save on small graphs.
OVERLAP_MIN = 2_500


class PoseFactor(Factor):
    """A system of (N) factored through a ``GraphElimination``: ``solve(rhs)`` for rhs (d·b,) or (d·b, r)
    pose-major; ``numeric`` the ``compiled.CompiledFactor`` (L packed front by front), which the selected inversion
    (``marginal_blocks``) reads."""

    def __init__(self, numeric, slots: np.ndarray, backend: str):
        self.numeric = numeric
        order = np.argsort(slots)

        def solve(rhs: np.ndarray) -> np.ndarray:
            return numeric.solve_slots(rhs[order])[slots]

        super().__init__(solve, slots.size, backend)

    def flops(self) -> float:
        """Σ colcount² over the columns of L (the fronts' explicit zeros included)."""
        return self.numeric.flops()


class RenumberedFactor(Factor):
    """A pose-major factor (variable i·b + c) seen in a system's own numbering: ``var_index`` (d, b) the system's
    index of (pose i, component c); ``pose_major`` the original factor."""

    def __init__(self, factor: Factor, var_index: np.ndarray):
        vi = np.asarray(var_index, np.int64).reshape(-1)
        self.pose_major = factor

        def solve(rhs: np.ndarray) -> np.ndarray:
            out = np.empty_like(rhs, dtype=float)
            out[vi] = factor.solve(rhs[vi])
            return out

        super().__init__(solve, vi.size, factor.backend)


def matrix_blocks(N: sp.spmatrix, var_index: np.ndarray):
    """The b×b blocks of a sparse symmetric N (system numbering ``var_index`` (d, b)) at every pose pair with an
    entry, each unordered pair once: ``(prow, pcol, blocks (q, b, b))`` with prow ≥ pcol."""
    var_index = np.asarray(var_index, np.int64)
    d, b = var_index.shape
    pose, comp = np.empty(d * b, np.int64), np.empty(d * b, np.int64)
    pose[var_index.reshape(-1)] = np.repeat(np.arange(d), b)
    comp[var_index.reshape(-1)] = np.tile(np.arange(b), d)
    C = sp.coo_matrix(N)
    pi, pj = pose[C.row], pose[C.col]
    low = pi >= pj
    uk, inv = np.unique(pi[low] * d + pj[low], return_inverse=True)
    blocks = np.zeros((uk.size, b, b))
    np.add.at(blocks, (inv, comp[C.row][low], comp[C.col][low]), C.data[low])
    same = (uk // d) == (uk % d)
    blocks[same] = np.tril(blocks[same]) + np.swapaxes(np.tril(blocks[same], -1), 1, 2)
    return uk // d, uk % d, blocks


def marginal_blocks(N, var_index: np.ndarray, *, factor: Factor | None = None, progress=None) -> np.ndarray:
    """The diagonal b×b blocks (d, b, b) of N⁻¹ for the variables ``var_index`` (d, b) of each free pose —
    marginal covariances when N is an information matrix — by selected inversion (eq. (T) of ``multifrontal``),
    never a dense inverse: on ``factor`` when it is a ``PoseFactor`` (possibly renumbered), else on a factorization
    of N (a sparse matrix, or a function that builds it) on its own pose-level plan."""
    pm = getattr(factor, "pose_major", factor)
    if isinstance(pm, PoseFactor):
        return inverse_blocks(pm.numeric, progress=progress)[0]
    N = N() if callable(N) else N
    var_index = np.asarray(var_index, np.int64)
    d, b = var_index.shape
    prow, pcol, blocks = matrix_blocks(N, var_index)
    off = prow != pcol
    lay = compiled.CompiledLayout.of(plan_from_pattern(d, prow[off], pcol[off]), b)
    L = np.empty(int(lay.Lptr[-1]))
    block_factor.factor(lay, lay.assembler(prow, pcol), blocks, L)  # N = Σ_q E_q blocks[q], front by front
    return inverse_blocks(compiled.CompiledFactor(lay, L), progress=progress)[0]


class GraphElimination:
    """The pose-level elimination of one graph and anchor (index ``anchor_index``), shared by its systems: ``d`` free
    poses; ``free_of`` (n,) each pose's free index (−1 at the anchor); ``tails``, ``heads`` (m,) edges' ends as free
    indices; ``plan`` the ``EliminationPlan`` (AMD on the pose graph's pattern, built once, on first use).
    ``start(…)`` builds the plan in a worker thread while the caller goes on (a failure there is raised to whoever
    waits); ``expect`` announces the block sizes of the systems to come, in order, each prepared in a worker
    (``prepare``) once the previous one is factored; ``ahead(task)`` hands over work needed later. ``workers`` caps
    the engine's own threads (None: ``threads.cores()``; 1: none besides the caller's); ``blas_threads`` lets the
    engine hold the process's BLAS to that many threads while it factors (None, the default: left alone)."""

    def __init__(self, graph, anchor_index: int, *, expect: tuple = (), workers: int | None = None,
                 blas_threads: int | None = None, _background: bool = False):
        with engine_threads(workers=workers, blas_threads=blas_threads):  # checks both; None: the caller's context
            self.workers, self.blas_threads, alone = thread_settings() + (cores() == 1,)
        n = graph.n_poses
        self.n, self.d = n, n - 1
        self.anchor_index = int(anchor_index)
        self.free_of = np.full(n, -1, np.int64)
        self.free_of[np.delete(np.arange(n), self.anchor_index)] = np.arange(self.d)
        self.tails, self.heads = self.free_of[graph.tails], self.free_of[graph.heads]
        self._expected = [int(b) for b in expect]
        self._assemblers: dict = {}
        self._preparing: dict = {}
        self._tasks: list = []
        self._plan = None
        self._building = None
        if self.d == 0:
            z = np.zeros(0, np.int64)
            self._plan = EliminationPlan(0, z, np.zeros(1, np.int64), np.zeros(1, np.int64), z, z)
        elif _background and self.d >= OVERLAP_MIN and not alone:
            self._building = Ahead(self._make_plan)
            spawn(self._building.run, name="lago-elimination")

    @classmethod
    def start(cls, graph, anchor_index: int, *, expect: tuple = (), workers: int | None = None,
              blas_threads: int | None = None) -> "GraphElimination":
        """The elimination built in a worker thread while the caller goes on (class docstring)."""
        return cls(graph, anchor_index, expect=expect, workers=workers, blas_threads=blas_threads, _background=True)

    def _make_plan(self) -> EliminationPlan:
        both = (self.tails >= 0) & (self.heads >= 0)
        relaxation = COMPILED_RELAX if compiled.available() else None
        self._plan = plan_from_pattern(self.d, self.tails[both], self.heads[both], relaxation=relaxation)
        return self._plan

    @property
    def plan(self) -> EliminationPlan:
        """The pose-level ``EliminationPlan``: built on first use, or by the worker of ``start`` (waited for)."""
        job, self._building = self._building, None
        if job is not None:
            job.result()
            if self._expected:
                self.prepare(self._expected[0])
        return self._plan if self._plan is not None else self._make_plan()

    @property
    def pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(prow, pcol, keep) of the blocks ``EdgeSystem.normal_blocks`` returns: tail diagonals, head diagonals,
        (head, tail) off-diagonals; ``keep`` (3m,) those between free poses."""
        t, h = self.tails, self.heads
        prow, pcol = np.concatenate([t, h, h]), np.concatenate([t, h, t])
        return prow, pcol, (prow >= 0) & (pcol >= 0)

    def slots(self, b: int) -> np.ndarray:
        """Elimination slot of each pose-major variable i·b + c."""
        return (self.plan.position[:, None] * b + np.arange(b)).reshape(-1)

    def ahead(self, task, *args) -> Ahead:
        """``task(*args)``, work needed later on this graph, run beside the next factorization (on another core,
        while the C loops release the GIL) or when its ``result()`` is first asked for (which raises its error)."""
        job = Ahead(task, *args)
        self._tasks.append(job)
        return job

    def _run_ahead(self) -> None:
        """The tasks handed over, in a worker thread beside a factorization (large graphs and several cores)."""
        if self._tasks and self.d >= OVERLAP_MIN and cores() > 1:
            tasks, self._tasks = self._tasks, []
            spawn(lambda: [job.run() for job in tasks], name="lago-ahead")

    @in_engine_threads
    def factor(self, system: EdgeSystem, *, progress=None, solving: bool = False) -> PoseFactor:
        """Factor the normal matrix (N) of ``system`` by (MF): in C when the kernels are built, else by NumPy
        (``block_factor``; the same storage). Raises ``multifrontal.NotPositiveDefinite`` if N is not numerically
        SPD. The systems announced after this one are prepared once it is factored (``solving``: once ``solve`` is
        done with it)."""
        b = system.b
        job = self._preparing.pop(b, None)
        if job is not None:
            job.result()
        try:
            if b not in self._assemblers:
                lay = compiled.CompiledLayout.of(self.plan, b)
                self._assemblers[b] = (lay, lay.assembler(*self.pairs[:2]))
            lay, asm = self._assemblers[b]
            self._run_ahead()
            cf = lay.factor(asm, system.A, system.B, progress=progress)
            return PoseFactor(cf, self.slots(b), "compiled" if compiled.available() else "multifrontal")
        finally:
            if not solving:
                self._prepare_next(b)

    def _prepare_next(self, b: int) -> None:
        """After the next announced system (b×b blocks) is done with: the ones announced after it."""
        if self._expected and self._expected[0] == b:
            self._expected = self._expected[1:]
            for nb in self._expected:
                self.prepare(nb)

    @in_engine_threads
    def prepare(self, b: int) -> None:
        """Build, in a worker thread, what the compiled factorization of a system with b×b blocks will need — its
        ``compiled.CompiledLayout``, the assembler, and L's storage allocated and touched (``CompiledLayout.reserve``:
        first touches of fresh memory are costly) — while this thread goes on. Nothing happens below ``OVERLAP_MIN``
        poses, with one worker or without the C kernels; ``factor`` waits for the worker and raises its error."""
        if (self.d < OVERLAP_MIN or b in self._preparing or b in self._assemblers or cores() == 1
                or not compiled.available()):
            return

        def work():
            lay = compiled.CompiledLayout.of(self.plan, b)
            touch = spawn(lay.reserve, name="lago-reserve")  # L's pages faulted in beside the assembler's work
            asm = lay.assembler(*self.pairs[:2])
            touch.join()
            self._assemblers[b] = (lay, asm)

        job = Ahead(work)
        spawn(job.run, name="lago-prepare")
        self._preparing[b] = job

    @in_engine_threads
    def solve(self, system: EdgeSystem, *, factor: Factor | None = None, stage: str = "solve", progress=None):
        """Minimise (E): returns ``(x (d, b), factor, stats)`` with ``stats`` as ``linalg.solve_least_squares``
        reports it (``factor`` None after the augmented-system fallback). A given ``factor`` (of the same normal
        matrix) is reused."""
        d, b = system.d, system.b
        if d == 0:
            return np.zeros((0, b) + system.c.shape[2:]), None, {"method": "normal equations",
                                                                 "refinement_steps": 0, "relative_correction": 0.0}
        self.plan  # noqa: B018  (built or waited for here: its error is raised as it is)
        tracker = Progress(stage, callback=progress, logger=log) if progress is not None or d > 200_000 else None
        extra = system.c.shape[2:]  # several right-hand sides: (d·b, r)
        m, q = system.c.shape[:2]
        given, M = factor, functools.cache(system.operator)  # M's operator, set up once, after the factorization
        x, factor, stats = refined_or_augmented(
            lambda: given if given is not None else self.factor(system, solving=True, progress=None if tracker is None
                                                                else (lambda i, n: tracker.update(0.9 * i / n))),
            lambda v: M().matvec(v.reshape((d, b) + extra)).reshape((m * q,) + extra),
            lambda r: M().rmatvec(r.reshape((m, q) + extra)).reshape((d * b,) + extra),
            system.c.reshape((m * q,) + extra), system.sparse)
        if tracker is not None:
            tracker.finish()
        self._prepare_next(b)
        return x.reshape((d, b) + extra), factor, stats

"""Systems that fill more per pose than the planar ones (3-D: the chordal relaxation and the positions with
b = 3 on mesh-like graphs, the joint step with b = 6): the compiled multifrontal engine sooner, one BLAS thread.

``factor_wide(elimination, system)`` and ``solve_wide(elimination, system)`` are ``GraphElimination.factor`` and
``.solve`` with this policy: every such system on the compiled engine when its C kernels are built, from
:data:`WIDE_COMPILED_MIN` unknowns with Numba's (``compiled_from``). The compiled engine's failure (no kernels, a
kernel that cannot compile, a matrix not positive definite) falls back to the engine's own choice, logged. A
``GraphElimination`` built with ``wide=(3, 6)`` (the block sizes of the wide systems it will factor) decides once for
all of them: when the largest reaches ``compiled_from()`` unknowns, the b = 3 systems are compiled too (the kernels
are loaded for the b = 6 one anyway), on a plan with the compiled engine's amalgamation.
"""

from __future__ import annotations

import logging

__all__ = ["WIDE_COMPILED_MIN", "compiled_from", "factor_wide", "solve_wide"]

log = logging.getLogger(__name__)

#: With Numba's kernels (the C library not built), the 3-D systems (b = 3: the chordal relaxation, the positions;
#: b = 6: the joint step) with at least this many unknowns d·b are factored by the engine's compiled multifrontal
#: engine (``GraphElimination.factor(engine="compiled")``), smaller ones as the engine chooses (QDLDL there). The
#: engine's own threshold is set by the planar systems (300 000 unknowns, b ≤ 3, little fill per unknown); a 3-D
#: graph fills more per pose and the 6×6 blocks multiply it by 36, where dense fronts pay far sooner; but Numba's
#: import and kernel loading cost a one-shot process more than a small 3-D graph gains, hence a threshold above
#: parking-garage's joint step (in process and whole processes: ``benchmarks/space.md``, ``benchmarks/spaceprocess.md``).
WIDE_COMPILED_MIN = 12_000


def compiled_from() -> int:
    """The least unknowns d·b of a 3-D system that the compiled engine factors: 0 with the C kernels
    (``compiled.native()``; they load in milliseconds, and the compiled route was as fast or faster on every 3-D graph
    measured: ``benchmarks/space.md``), :data:`WIDE_COMPILED_MIN` with Numba's."""
    from . import compiled

    return 0 if compiled.native() else WIDE_COMPILED_MIN


def _one_blas_thread():
    """``linalg.blas_threads(1)``: the compiled factorizations of the 3-D systems run with one BLAS thread when the
    caller let the engine set the BLAS thread count (``engine_threads(blas_threads=…)``); by default the process's
    setting is left alone. OpenBLAS's threads wait for each other by spinning, and with the other core busy the
    waits dominate (``benchmarks/`` 3-D in-process timings, docs/performance.md "3-D graphs")."""
    from .linalg import blas_threads

    return blas_threads(1)


def _compiled(elimination, system):
    """The compiled factorization (one BLAS thread), or None (logged) when it cannot be had."""
    try:
        with _one_blas_thread():
            return elimination.factor(system, engine="compiled")
    except Exception as exc:  # no Numba, a kernel that cannot compile, NotPositiveDefinite: the engine's way
        log.info("compiled factorization not used (%s): the engine's choice", exc)
        return None


def _use_compiled(elimination, system) -> bool:
    """From ``compiled_from()`` unknowns, this system's or the largest announced one's (module docstring)."""
    return system.d * system.b >= compiled_from() or getattr(elimination, "wide_compiled", False)


def factor_wide(elimination, system):
    """The factor of ``system``'s normal matrix (an ``EdgeSystem`` on ``elimination``, a ``GraphElimination``):
    compiled from ``compiled_from()`` unknowns (module docstring), else (or if the compiled engine cannot run,
    or finds the matrix not positive definite) as the engine chooses."""
    f = _compiled(elimination, system) if _use_compiled(elimination, system) else None
    return elimination.factor(system) if f is None else f


def solve_wide(elimination, system):
    """``elimination.solve(system)`` (x, factor, stats) on :func:`factor_wide`'s factorization: the corrected
    semi-normal equations, the engine's fallbacks (the augmented system) included."""
    f = _compiled(elimination, system) if _use_compiled(elimination, system) else None
    return elimination.solve(system) if f is None else elimination.solve(system, factor=f)

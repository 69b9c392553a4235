"""The sparse engine behind one door.

Everything that makes LAGO's closed forms fast — the pose-level ordering and symbolic analysis, the one numeric
factorization (the multifrontal block Cholesky in C, with its NumPy fallback), selected inversion, worker threads —
lives in this subpackage. The mathematics (phases, positions, regularizers, variants, refinement, certification)
imports only the names below, never a submodule: ``tests/test_architecture.py`` holds that.

The door, in the spirit of scikit-sparse's ``cholesky(A) -> Factor``:

* ``EdgeSystem(tails, heads, A, B, c, d)`` — a least-squares problem Σ_k ‖A_k x_{t_k} + B_k x_{h_k} − c_k‖²
  on the pose graph's pattern, b unknowns per pose (b = 1, 2, 3, 6, 9 …), q rows per edge;
* ``GraphElimination(graph, anchor_index, weights=…)`` — the symbolic analysis of one graph and anchor,
  shared by every system solved on it: ``.factor(system) -> Factor``, ``.solve(system) -> (x, factor, stats)``;
  ``GraphElimination.start(…, expect=…)`` builds it in a worker while the caller goes on, and
  ``.ahead(task)`` hands over work needed later (overlap and prefetching live here, not in the caller);
* ``factor_wide(elimination, system)`` / ``solve_wide`` — the same for the 3-D systems (the same path);
* ``factorize(N) -> Factor`` and ``solve_least_squares(M, b)`` for a sparse matrix of any other pattern;
* ``Factor`` — ``solve(rhs)``; ``marginal_blocks(N, var_index, factor=…)`` the diagonal blocks of N⁻¹ by
  selected inversion (``block_diagonal_inverse`` by column solves for small blocks of any factor);
* threads: ``cores()`` the engine's own threads; ``engine_threads(workers=…, blas_threads=…)`` caps them (SciPy's
  name) and, only when asked, the process's BLAS threads while the engine runs (left alone by default);
  ``threads_option`` runs a function with those keyword options inside it (``lago(…, workers=…)``).
"""

from __future__ import annotations

from .block_factor import inverse_blocks
from .linalg import (SOLVER_BACKENDS, Factor, augmented_least_squares, block_diagonal_inverse, factorize,
                     refine_normal_equations, solve_least_squares)
from .edge_system import EdgeSystem
from .normal_equations import GraphElimination, RenumberedFactor, factor_wide, marginal_blocks, solve_wide
from .threads import cores, engine_threads, threads_option

__all__ = [
    "EdgeSystem", "GraphElimination", "Factor", "factorize", "solve_least_squares", "refine_normal_equations",
    "augmented_least_squares", "block_diagonal_inverse", "inverse_blocks", "SOLVER_BACKENDS",
    "RenumberedFactor", "marginal_blocks", "cores", "factor_wide", "solve_wide",
    "engine_threads", "threads_option",
]

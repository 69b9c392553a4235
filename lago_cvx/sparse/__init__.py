"""The sparse engine behind one door.

The pose-level ordering and symbolic analysis, the one numeric factorization (the multifrontal block Cholesky in C,
with its NumPy fallback), selected inversion and worker threads live here. The mathematics imports only the names
below, never a submodule (``tests/test_architecture.py``). In the spirit of scikit-sparse's ``cholesky(A) -> Factor``:

* ``EdgeSystem(tails, heads, A, B, c, d)`` — Σ_k ‖A_k x_{t_k} + B_k x_{h_k} − c_k‖² on the pose graph's pattern,
  b unknowns per pose (b = 1, 2, 3, 6, 9 …), q rows per edge;
* ``GraphElimination(graph, anchor_index)`` — the symbolic analysis of one graph and anchor, shared by every system
  on it: ``.factor(system) -> Factor``, ``.solve(system) -> (x, factor, stats)``; ``.start(…, expect=…)`` builds it
  in a worker while the caller goes on, ``.ahead(task)`` hands over work needed later;
* ``factorize(N) -> Factor`` and ``solve_least_squares(M, b)`` for a sparse matrix of any other pattern;
* ``Factor.solve(rhs)``; ``marginal_blocks(N, var_index, factor=…)`` the diagonal blocks of N⁻¹ by selected inversion;
* ``cores()`` the engine's threads; ``engine_threads(workers=…, blas_threads=…)`` caps them (SciPy's name) and, only
  when asked, the process's BLAS threads; ``threads_option`` runs a function inside those of its keyword options.
"""

from __future__ import annotations

from .block_factor import inverse_blocks
from .edge_system import EdgeSystem
from .linalg import (SOLVER_BACKENDS, Factor, augmented_least_squares, factorize, refine_normal_equations,
                     solve_least_squares)
from .normal_equations import GraphElimination, RenumberedFactor, marginal_blocks
from .threads import cores, engine_threads, threads_option

__all__ = [
    "EdgeSystem", "GraphElimination", "Factor", "factorize", "solve_least_squares", "refine_normal_equations",
    "augmented_least_squares", "inverse_blocks", "SOLVER_BACKENDS", "RenumberedFactor", "marginal_blocks", "cores",
    "engine_threads", "threads_option",
]

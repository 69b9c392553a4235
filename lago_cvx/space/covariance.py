r"""First-order covariances of 3-D poses from the final factor.

At an estimate (t, R) — a minimum of χ² after ``refine3d``, or LAGO's — the Laplace approximation of the pose
posterior is Gaussian in the right-perturbation coordinates δ_i = (δv_i, δφ_i) of ``gauss_newton`` with covariance
Σ = (JᵀΩJ)⁻¹, the anchor held fixed (its covariance is zero: everything is relative to it). The 6×6 diagonal blocks
Σ_ii come from the factor of JᵀΩJ on the pose-level elimination by selected inversion (Takahashi;
``sparse.marginal_blocks``), never forming the inverse: translation first, in the pose's own frame.
"""

from __future__ import annotations

import numpy as np

from .gauss_newton import jacobians, whitening

__all__ = ["pose_covariances3d"]


def pose_covariances3d(graph, t, R, *, anchor=None) -> np.ndarray:
    """Σ_ii (n, 6, 6) of every pose at (t, R) (module docstring); zero at the anchor (a pose id, default the
    smallest)."""
    from ..sparse import EdgeSystem, GraphElimination, marginal_blocks

    a = graph.anchor_index(anchor)
    t, R = graph.check_poses(t, R)
    out = np.zeros((graph.n_poses, 6, 6))
    if graph.n_poses == 1:
        return out
    el = GraphElimination(graph, a)
    L = whitening(graph)
    e, Ji, Jj = jacobians(graph, t, R)
    system = EdgeSystem(el.tails, el.heads, L @ Ji, L @ Jj, -np.einsum("kij,kj->ki", L, e), el.d)
    diag = marginal_blocks(None, np.arange(el.d * 6).reshape(el.d, 6), factor=el.factor(system))
    out[np.flatnonzero(np.arange(graph.n_poses) != a)] = diag
    return out

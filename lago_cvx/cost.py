"""The cost of the full nonlinear problem, eq. (3) of the seed, in the g2o χ² convention.

For an edge i → j with measurement (Δˡ, δ) and information Ω the error is

    e_ij = [ R(θ_i)ᵀ(p_j − p_i) − Δˡ ;  wrap(θ_j − θ_i − δ) ]   (wrap to [−π, π)),

and the cost is χ² = Σ e_ijᵀ Ω_ij e_ij — **no factor ½**. This is what g2o reports as χ²; GTSAM's
``NonlinearFactorGraph.error()`` reports half of it (its factors carry ½‖·‖²). The SE-Sync objective
(datasets README 4.1) is a different function again. Every printed cost in lago_cvx is this χ².
"""

from __future__ import annotations

import numpy as np

from .posegraph import PoseGraph, wrap_angle

__all__ = ["edge_errors", "chi2", "chi2_parts", "whitened_errors"]


def edge_errors(graph: PoseGraph, poses) -> np.ndarray:
    """Errors e_ij of eq. (3), shape (m, 3), for ``poses`` of shape (n, 3)."""
    poses = np.asarray(poses, dtype=float)
    if poses.shape != (graph.n_poses, 3):
        raise ValueError(f"poses must have shape ({graph.n_poses}, 3), got {poses.shape}")
    pi, pj = poses[graph.tails], poses[graph.heads]
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
    e = np.empty((graph.n_edges, 3))
    e[:, 0] = c * dx + s * dy - graph.delta_l[:, 0]
    e[:, 1] = -s * dx + c * dy - graph.delta_l[:, 1]
    e[:, 2] = wrap_angle(pj[:, 2] - pi[:, 2] - graph.delta)
    return e


def chi2(graph: PoseGraph, poses) -> float:
    """χ² = Σ eᵀΩe over all edges (g2o convention, no ½; twice GTSAM's ``error()``)."""
    e = edge_errors(graph, poses)
    return float(np.einsum("ka,kab,kb->", e, graph.information, e))


def chi2_parts(graph: PoseGraph, poses) -> dict:
    """χ² split into its translational part (e_tᵀΩ_tt e_t), rotational part (Ω_θθ e_θ²) and the
    cross terms (2 e_tᵀΩ_tθ e_θ); the three add up to ``chi2``."""
    e = edge_errors(graph, poses)
    Om = graph.information
    t = float(np.einsum("ka,kab,kb->", e[:, :2], Om[:, :2, :2], e[:, :2]))
    r = float(np.sum(Om[:, 2, 2] * e[:, 2] ** 2))
    x = float(2.0 * np.einsum("ka,ka,k->", e[:, :2], Om[:, :2, 2], e[:, 2]))
    return {"chi2": t + r + x, "translation": t, "rotation": r, "cross": x}


def whitened_errors(graph: PoseGraph, poses) -> np.ndarray:
    """Per-edge √(eᵀΩe), shape (m,): large values flag suspicious (e.g. false) loop closures."""
    e = edge_errors(graph, poses)
    return np.sqrt(np.einsum("ka,kab,kb->k", e, graph.information, e))

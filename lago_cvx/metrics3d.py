r"""Trajectory errors in space, and what lets ``metrics.ate`` / ``metrics.rpe`` take any estimate of either dimension.

Absolute trajectory error (ATE). With positions p_i (estimate) and q_i (truth), i = 0 … n−1, the rigid alignment
without scale (Umeyama 1991, Kabsch) minimizing Σ‖G p_i + s − q_i‖² over G ∈ SO(3), s ∈ ℝ³ is

    H = Σ (p_i − p̄)(q_i − q̄)ᵀ = U S Vᵀ,   G = V diag(1, 1, det(VUᵀ)) Uᵀ,   s = q̄ − G p̄,              (U)

and ATE = √(1/n Σ‖G p_i + s − q_i‖²).

Relative pose error (RPE, Sturm et al., IROS 2012) over a step δ: with T_i the poses,
E_i = (Q_i⁻¹ Q_{i+δ})⁻¹ (P_i⁻¹ P_{i+δ}), i = 0 … n−1−δ (P the estimate, Q the truth, in graph order), and
RPE = √(1/(n−δ) Σ ‖trans(E_i)‖²), the translation RMSE; independent of the frame, no alignment needed.
"""

from __future__ import annotations

import numpy as np

from .errors import OptionError
from .posegraph import rot2

__all__ = ["as_trajectory", "poses_of", "ate3d", "rpe3d", "rpe2d", "umeyama"]


def as_trajectory(x, what: str):
    """``x`` as planar poses (n, 3) or a 3-D pair (t (n, 3), R (n, 3, 3)): an array, a pair, a result (``poses``
    planar, ``t`` and ``R`` 3-D: LAGO's, a refinement's, GNC's, SE-Sync's) or a generated world (its ``truth``);
    a one-line ``OptionError`` naming ``what`` for anything else."""
    if hasattr(x, "truth") and hasattr(x, "graph"):
        x = x.truth
    if hasattr(x, "t") and hasattr(x, "R"):
        x = (x.t, x.R)
    elif hasattr(x, "poses") and not isinstance(x, (np.ndarray, tuple, list)):
        x = x.poses
    try:
        if isinstance(x, (tuple, list)) and len(x) == 2 and np.ndim(x[1]) == 3:
            t, R = np.asarray(x[0], dtype=float), np.asarray(x[1], dtype=float)
            if t.ndim != 2 or t.shape[1] != 3 or R.shape != (t.shape[0], 3, 3) or t.shape[0] == 0:
                raise OptionError(f"{what}: a 3-D trajectory is t (n, 3), R (n, 3, 3); got {t.shape} and {R.shape}")
            return t, R
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, OptionError):
            raise
        raise OptionError(f"{what}: expected planar poses (n, 3), a pair (t (n, 3), R (n, 3, 3)) or a result; "
                          f"got {type(x).__name__}") from None
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] == 0:
        raise OptionError(f"{what}: expected planar poses (n, 3), a pair (t (n, 3), R (n, 3, 3)) or a result; "
                          f"got {type(x).__name__ if a.ndim == 0 else f'shape {a.shape}'}")
    return a


def poses_of(graph, x, what: str = "poses"):
    """``x`` as the poses of ``graph`` (a ``PoseGraph`` or ``PoseGraph3D``): an (n, 3) array for a planar graph,
    (t (n, 3), R (n, 3, 3)) for a 3-D one, n = ``graph.n_poses``; ``x`` anything ``as_trajectory`` takes. The one
    place a result becomes poses for χ², the SE-Sync cost and the writer; a one-line ``OptionError`` for poses of
    the other dimension or another length."""
    x = as_trajectory(x, what)
    three = graph.dim == 3
    if isinstance(x, tuple) != three:
        raise OptionError(f"{what}: a 3-D graph's poses are (t (n, 3), R (n, 3, 3)) or a 3-D result, not planar "
                          "poses" if three else
                          f"{what}: a planar graph's poses are an (n, 3) array or a planar result, not (t, R)")
    n = (x[0] if three else x).shape[0]
    if n != graph.n_poses:
        shapes = f"({graph.n_poses}, 3) and ({graph.n_poses}, 3, 3)" if three else f"({graph.n_poses}, 3)"
        got = f"{x[0].shape} and {x[1].shape}" if three else f"{x.shape}"
        raise OptionError(f"{what} must have shape {shapes} (the graph's {graph.n_poses} poses), got {got}")
    return x


def umeyama(p: np.ndarray, q: np.ndarray):
    """(G (3, 3), s (3,)) of eq. (U): G p_i + s ≈ q_i in least squares, p, q (n, 3)."""
    H = (p - p.mean(0)).T @ (q - q.mean(0))
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, 1.0 if np.linalg.det(Vt.T @ U.T) >= 0 else -1.0])
    G = Vt.T @ D @ U.T
    return G, q.mean(0) - G @ p.mean(0)


def ate3d(estimate, truth, *, align: bool = True) -> float:
    """ATE (module docstring) of 3-D trajectories (t, R) pairs; ``align=False``: the raw position RMS."""
    p, q = estimate[0], truth[0]
    if align:
        G, s = umeyama(p, q)
        p = p @ G.T + s
    return float(np.sqrt(np.mean(np.sum((p - q) ** 2, axis=1))))


def _check_delta(n: int, delta) -> int:
    if not (isinstance(delta, (int, np.integer)) and 1 <= delta < n):
        raise OptionError(f"rpe: delta must be an integer in 1 … n−1 = {n - 1}, got {delta!r}")
    return int(delta)


def rpe3d(estimate, truth, *, delta: int = 1) -> float:
    """RPE (module docstring) of 3-D trajectories (t, R)."""
    (tp, Rp), (tq, Rq) = estimate, truth
    d = _check_delta(tp.shape[0], delta)

    def rel(t, R):  # P_i⁻¹ P_{i+δ} = (R_iᵀR_{i+δ}, R_iᵀ(t_{i+δ} − t_i))
        Ri = np.swapaxes(R[:-d], 1, 2)
        return Ri @ R[d:], np.einsum("kij,kj->ki", Ri, t[d:] - t[:-d])

    Rp_, tp_ = rel(tp, Rp)
    Rq_, tq_ = rel(tq, Rq)
    err = np.einsum("kji,kj->ki", Rq_, tp_ - tq_)  # translation of (Q⁻¹Q′)⁻¹(P⁻¹P′)
    return float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))


def rpe2d(estimate: np.ndarray, truth: np.ndarray, *, delta: int = 1) -> float:
    """RPE (module docstring) of planar poses (n, 3)."""
    d = _check_delta(estimate.shape[0], delta)

    def rel(x):  # translation of P_i⁻¹ P_{i+δ}: R(θ_i)ᵀ(p_{i+δ} − p_i)
        return np.einsum("kji,kj->ki", rot2(x[:-d, 2]), x[d:, :2] - x[:-d, :2])

    err = np.einsum("kji,kj->ki", rot2(truth[d:, 2] - truth[:-d, 2]), rel(estimate) - rel(truth))
    return float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))

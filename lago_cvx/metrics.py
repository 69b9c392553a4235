"""How good an estimate is: the cost the graph means, trajectory errors against a ground truth after rigid
alignment, and the relative difference the cross-checks report.

For an edge i → j with measurement (Δˡ, δ) and the information Ω of eq. (3) (``PoseGraph.information``) the
error is

    e_ij = [ R(θ_i)ᵀ(p_j − p_i) − Δˡ ;  wrap(θ_j − θ_i − δ) ]   (wrap to [−π, π)),            eq. (3)

and the cost is χ² = Σ e_ijᵀ Ω_ij e_ij — **no factor ½**. For a graph of cost ``"paper"`` this is eq. (3); for
``"g2o"`` it is exactly the χ² g2o computes (``lago_cvx.posegraph``: Ω is the file's rotated into this frame).
For ``"gtsam"`` the translational error is GTSAM's Logmap's, ẽ_t = V(ε)⁻¹ e_t with ε = e_θ
(``posegraph.se2_v_inverse``), and χ² is twice GTSAM's ``NonlinearFactorGraph.error()`` (its factors carry
½‖·‖²). The SE-Sync objective (``lago_cvx.certification``) is a different function again.
"""

from __future__ import annotations

import numpy as np

from .stacks import row_blocks
from .errors import OptionError
from .metrics3d import poses_of
from .posegraph import PoseGraph, logmap_translation, rot2, wrap_angle
from .posegraph3d import chi2_3d, edge_errors3d
from .posegraph_base import as_graph

__all__ = ["edge_errors", "chi2", "chi2_parts", "whitened_errors", "alignment_angle", "alignment", "ate", "rpe",
           "rotation_error", "relative_difference"]


def edge_errors(graph: PoseGraph, poses) -> np.ndarray:
    """Errors e_ij of the graph's cost weighed by ``graph.information`` (module docstring: eq. (3), or GTSAM's
    [V(ε)⁻¹ e_t ; ε] for cost ``"gtsam"``), shape (m, 3), for ``poses`` (n, 3) or any planar result. For a 3-D graph
    ``posegraph3d.edge_errors3d``'s (m, 6), translation first (arguments as ``chi2``)."""
    graph, poses = _graph_poses(graph, poses)
    if graph.dim == 3:
        return edge_errors3d(graph, *poses)
    e = np.empty((graph.n_edges, 3))
    for k in row_blocks(graph.n_edges):  # (stacks.row_blocks: temporaries a block long)
        e[k] = _errors(graph, poses, k)
    return e


def _graph_poses(graph, poses):
    """(graph, poses): the graph (a generated world's ``graph`` taken; ``posegraph_base.as_graph``) and ``poses``
    as its poses, (n, 3) planar or (t, R) 3-D (``metrics3d.poses_of``: arrays, results, worlds' truths)."""
    graph = as_graph(graph)
    return graph, poses_of(graph, poses)


def _errors(graph: PoseGraph, poses: np.ndarray, k: slice) -> np.ndarray:
    """e_ij of eq. (3) for the edges ``k`` (a slice), shape (mb, 3)."""
    pi, pj = poses[graph.tails[k]], poses[graph.heads[k]]
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
    e = np.empty((pi.shape[0], 3))
    e[:, 0] = c * dx + s * dy - graph.delta_l[k, 0]
    e[:, 1] = -s * dx + c * dy - graph.delta_l[k, 1]
    e[:, 2] = wrap_angle(pj[:, 2] - pi[:, 2] - graph.delta[k])
    if graph.cost == "gtsam":  # GTSAM's Logmap: ẽ_t = V(ε)⁻¹ e_t
        logmap_translation(e)
    return e


def chi2(graph: PoseGraph, poses) -> float:
    """χ² = Σ eᵀΩe over all edges of ``graph`` in its cost (module docstring; no ½), a float.

    ``graph`` a ``PoseGraph`` or ``PoseGraph3D`` (or a generated world: its ``graph``); ``poses`` (n, 3) for a planar
    graph, (t (n, 3), R (n, 3, 3)) for a 3-D one, or any result the package returns (LAGO's, a refinement's, GNC's,
    SE-Sync's; a world: its truth). For a 3-D graph the value is ``chi2_3d(graph, t, R)``. A robust result's poses
    are scored over **every** edge of the graph passed in, rejected ones included (its own ``chi2`` is over the
    accepted edges only: pass ``result.graph`` for that). Poses of the other dimension, another length or another
    type: a one-line ``OptionError``; a ``graph`` that is not a pose graph: ``GraphError``."""
    graph, poses = _graph_poses(graph, poses)
    if graph.dim == 3:
        return chi2_3d(graph, *poses)
    total = 0.0
    for k in row_blocks(graph.n_edges):
        e = _errors(graph, poses, k)
        total += float(np.einsum("ka,kab,kb->", e, graph.information[k], e))
    return total


def chi2_parts(graph: PoseGraph, poses) -> dict:
    """χ² split into its translational part (e_tᵀΩ_tt e_t), rotational part (e_rᵀΩ_rr e_r; planar Ω_θθ e_θ²) and the
    cross terms (2 e_tᵀΩ_tr e_r); the three add up to ``chi2``. Arguments as ``chi2``, either dimension (3-D: e
    of ``edge_errors3d``, translation first)."""
    graph, poses = _graph_poses(graph, poses)
    e = edge_errors(graph, poses)
    Om = graph.information
    b = 3 if graph.dim == 3 else 2  # the translational block
    t = float(np.einsum("ka,kab,kb->", e[:, :b], Om[:, :b, :b], e[:, :b]))
    r = float(np.einsum("ka,kab,kb->", e[:, b:], Om[:, b:, b:], e[:, b:]))
    x = float(2.0 * np.einsum("ka,kab,kb->", e[:, :b], Om[:, :b, b:], e[:, b:]))
    return {"chi2": t + r + x, "translation": t, "rotation": r, "cross": x}


def whitened_errors(graph: PoseGraph, poses) -> np.ndarray:
    """Per-edge √(eᵀΩe), shape (m,): large values flag suspicious (e.g. false) loop closures. Arguments as
    ``chi2``, either dimension."""
    graph, poses = _graph_poses(graph, poses)
    e = edge_errors(graph, poses)
    return np.sqrt(np.einsum("ka,kab,kb->k", e, graph.information, e))


# ------------------------------------------------------------------ trajectory errors
def alignment_angle(src, dst) -> float:
    """φ minimising Σ‖R(φ)(s − s̄) − (d − d̄)‖² for 2-D points ``src``, ``dst`` (k, 2), equal weights
    (Kabsch / Umeyama without scale). In 2-D φ = atan2(H₀₁ − H₁₀, H₀₀ + H₁₁), H = S̄ᵀD̄ of the centred
    points, which is always a proper rotation."""
    S = np.asarray(src, dtype=float)
    D = np.asarray(dst, dtype=float)
    H = (S - S.mean(0)).T @ (D - D.mean(0))
    return float(np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1]))


def alignment(estimate, truth) -> tuple[float, np.ndarray]:
    """Best rigid 2-D alignment (rotation φ, translation t (2,)) with R(φ)·p_est + t ≈ p_truth in the
    least-squares sense, for poses (n, 3)."""
    estimate, truth = _check_pair(estimate, truth)
    phi = alignment_angle(estimate[:, :2], truth[:, :2])
    t = truth[:, :2].mean(0) - rot2(phi) @ estimate[:, :2].mean(0)
    return phi, t


def _check_pair(estimate, truth):
    estimate = np.asarray(estimate, dtype=float)
    truth = np.asarray(truth, dtype=float)
    if estimate.ndim != 2 or estimate.shape[1] != 3 or estimate.shape != truth.shape or estimate.shape[0] == 0:
        raise OptionError(f"estimate and truth must both have shape (n, 3), n ≥ 1; got {estimate.shape} "
                          f"and {truth.shape}")
    return estimate, truth


def ate(estimate, truth, *, align: bool = True) -> float:
    """Absolute trajectory error: RMS of the position errors ‖p_est − p_truth‖ over the n poses
    (both (n, 3)), after the best rigid 2-D alignment of the estimate onto the truth when ``align``
    (no scale), else raw. Either dimension: ``estimate`` and ``truth`` may be results, 3-D pairs (t, R) or
    generated worlds (their ``truth``); 3-D by SE(3) alignment (``metrics3d.ate3d``, Umeyama without scale)."""
    estimate, truth = _dispatch(estimate, truth)
    if isinstance(estimate, tuple):
        from .metrics3d import ate3d

        return ate3d(estimate, truth, align=align)
    estimate, truth = _check_pair(estimate, truth)
    p = estimate[:, :2]
    if align:
        phi, t = alignment(estimate, truth)
        p = p @ rot2(phi).T + t
    return float(np.sqrt(np.mean(np.sum((p - truth[:, :2]) ** 2, axis=1))))


def _dispatch(estimate, truth):
    """Both trajectories as planar (n, 3) arrays or 3-D (t, R) pairs (``metrics3d.as_trajectory``), of one
    dimension and length."""
    from .metrics3d import as_trajectory

    e, t = as_trajectory(estimate, "estimate"), as_trajectory(truth, "truth")
    if isinstance(e, tuple) != isinstance(t, tuple) or len(e[0] if isinstance(e, tuple) else e) != \
            len(t[0] if isinstance(t, tuple) else t):
        raise OptionError("estimate and truth must be trajectories of the same dimension and length")
    return e, t


def rpe(estimate, truth, *, delta: int = 1) -> float:
    """Relative pose error over ``delta`` steps in graph order: the RMS translation of
    (T̃_i⁻¹T̃_{i+δ})⁻¹(T_i⁻¹T_{i+δ}) (truth T̃), planar or 3-D (``metrics3d``; the same inputs as ``ate``;
    no alignment: the relative poses do not depend on the frame)."""
    from .metrics3d import rpe2d, rpe3d

    estimate, truth = _dispatch(estimate, truth)
    if isinstance(estimate, tuple):
        return rpe3d(estimate, truth, delta=delta)
    return rpe2d(*_check_pair(estimate, truth), delta=delta)


def rotation_error(estimate, truth, *, align: bool = True) -> float:
    """RMS wrapped orientation error (radians) over the n poses (both (n, 3)); with ``align`` the
    estimate is first rotated by the same rigid alignment as in ``ate`` (its angle is added to every θ)."""
    estimate, truth = _check_pair(estimate, truth)
    phi = alignment(estimate, truth)[0] if align else 0.0
    return float(np.sqrt(np.mean(wrap_angle(estimate[:, 2] + phi - truth[:, 2]) ** 2)))


# ------------------------------------------------------------------ cross-checks
def relative_difference(a, b) -> float:
    """‖a − b‖∞ / max(‖b‖∞, tiny): the "relative difference" the cvxpy/closed-form cross-checks report
    (0 for empty arrays)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.size == 0:
        return 0.0
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), np.finfo(float).tiny))

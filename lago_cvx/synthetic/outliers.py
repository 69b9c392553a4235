r"""False loop closures appended to any pose graph, planar or 3-D, the protocol of robust-SLAM benchmarks
(Sünderhauf & Protzel 2012; Yang et al. 2020, GNC): each false edge joins a random pair of poses (i, j)
drawn uniformly among the pairs that are neither equal nor consecutive in id (so it is never odometric),
and measures a relative pose drawn uniformly: the translation Δˡ uniform in the square [−b/2, b/2]² of
side ``box`` = b metres, the rotation δ uniform in [−π, π); its information Ω is that of a real edge of
the graph drawn uniformly, as the graph's cost gives it (a g2o graph's in the measurement's frame, moved
into eq. (3)'s frame for the new δ like every edge read from a file, ``lago_cvx.posegraph``). Nothing about the false edges is told to the estimator.

In 3-D (``PoseGraph3D``) the same, one dimension up: the translation t̃ uniform in the cube [−b/2, b/2]³, the
rotation R̃ uniform on SO(3) (the rotation of a unit quaternion drawn uniformly on S³: a normalized standard normal
4-vector), the 6×6 information of a real edge as it is stored (the information of the graph's cost, in the edge's own
frame in both 3-D costs, so no change of frame).

    add_false_loop_closures(graph, fraction, *, seed, box=20.0) -> (graph', outliers)

appends ⌊fraction · m⌋ such edges after the m edges of ``graph`` (file order is kept: edge k of
``graph`` is edge k of ``graph'``), and returns their indices m … m + q − 1 in ``graph'``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import OptionError
from ..posegraph import COST_FRAME, PoseGraph, to_tail_frame
from ..so3 import quat_to_rot

__all__ = ["add_false_loop_closures", "FALSE_LOOP_BOX"]

#: Side (metres) of the square (3-D: the cube) the false translations are drawn from.
FALSE_LOOP_BOX = 20.0


def add_false_loop_closures(graph: PoseGraph, fraction: float, *, seed: int = 0,
                            box: float = FALSE_LOOP_BOX) -> tuple[PoseGraph, np.ndarray]:
    """``graph`` with ⌊fraction · m⌋ false loop closures appended (module docstring), and their edge
    indices (q,) int64 in the new graph. ``seed`` seeds one ``np.random.default_rng``: the same arguments
    give the same graph. ``OptionError`` for a negative or non-finite fraction or box, or a
    graph with fewer than 3 poses or no edge (no non-consecutive pair or no information to copy)."""
    if not (np.isfinite(fraction) and fraction >= 0):
        raise OptionError(f"outlier fraction must be a finite number ≥ 0, got {fraction}")
    if not (np.isfinite(box) and box > 0):
        raise OptionError(f"box must be a finite number > 0, got {box}")
    m, n = graph.n_edges, graph.n_poses
    q = int(np.floor(fraction * m + 1e-9))
    if q == 0:
        return graph, np.zeros(0, np.int64)
    if n < 3 or m == 0:
        raise OptionError(f"false loop closures need at least 3 poses and one edge (graph has {n} poses, {m} edges)")
    rng = np.random.default_rng(seed)
    tails, heads = _pairs(graph.ids, q, rng)
    if getattr(graph, "dim", 2) == 3:
        return _append3d(graph, tails, heads, rng, box), np.arange(m, m + q, dtype=np.int64)
    delta_l = rng.uniform(-box / 2, box / 2, size=(q, 2))
    delta = rng.uniform(-np.pi, np.pi, size=q)
    # the information as the graph was given it (its cost's frame), moved into eq. (3)'s frame for the new δ
    frame = COST_FRAME[graph.cost]
    given = graph.information_in(frame)[rng.integers(0, m, size=q)]
    info = to_tail_frame(given, delta) if frame == "measurement" else given
    kept = None if graph.given_information is None else np.concatenate([graph.given_information, given])
    new = replace(graph, tails=np.r_[graph.tails, tails], heads=np.r_[graph.heads, heads],
                  delta_l=np.r_[graph.delta_l, delta_l], delta=np.r_[graph.delta, delta],
                  information=np.concatenate([graph.information, info]), given_information=kept)
    return new, np.arange(m, m + q, dtype=np.int64)


def _append3d(graph, tails, heads, rng, box):
    """The 3-D graph with false edges tails → heads (q,) appended (module docstring): t̃ (q, 3) uniform in the cube
    of side ``box``, R̃ (q, 3, 3) uniform on SO(3), the information (q, 6, 6) of real edges drawn uniformly."""
    q, m = tails.size, graph.n_edges
    delta_t = rng.uniform(-box / 2, box / 2, size=(q, 3))
    quat = rng.standard_normal((q, 4))
    delta_R = quat_to_rot(quat / np.linalg.norm(quat, axis=1, keepdims=True))
    info = graph.information[rng.integers(0, m, size=q)]
    return replace(graph, tails=np.r_[graph.tails, tails], heads=np.r_[graph.heads, heads],
                   delta_t=np.r_[graph.delta_t, delta_t], delta_R=np.concatenate([graph.delta_R, delta_R]),
                   information=np.concatenate([graph.information, info]))


def _pairs(ids: np.ndarray, q: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """q pose-index pairs (i, j), i ≠ j and |id_i − id_j| ≠ 1, uniform among those pairs (rejection)."""
    n = ids.size
    tails, heads = np.empty(0, np.int64), np.empty(0, np.int64)
    while tails.size < q:
        i = rng.integers(0, n, size=2 * (q - tails.size) + 8)
        j = rng.integers(0, n, size=i.size)
        ok = (i != j) & (np.abs(ids[i] - ids[j]) != 1)
        tails, heads = np.r_[tails, i[ok]], np.r_[heads, j[ok]]
    return tails[:q], heads[:q]

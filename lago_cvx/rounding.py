"""The one 2kπ rounding rule of lago_cvx, and the cycle residuals it is applied to.

Measured relative orientations δ are known only modulo 2π. Every place that decides an integer — the
seed's tree rounding (Theorem 3, eqs. (20)–(23)), the chordal and integer regularizers, orientation
anchors and prior means, the robust re-rounding, and the ground-truth integers of the experiments —
uses the same rule:

    k = branch(value, target):  the integer with  value + 2πk − target ∈ (−π, π],
        k = −⌈(value − target)/2π − ½⌉.                                                     (R)

Exact ties ((value − target)/2π exactly half-integer) go to +π: a tie means the measurement does not
decide k, and such cases are reported as ambiguous by the callers (together with any residual within
a margin of ±π).

For a spanning tree, the cycle residual of chord c = (i → j) is r_c = (Cδ)_c = δ_c − (θ_tree[j] −
θ_tree[i]) (eq. (20)), computed through the tree's path sums without forming C.
"""

from __future__ import annotations

import numpy as np

from .errors import GraphError
from .graph import SpanningTree
from .posegraph import PoseGraph

__all__ = ["TWO_PI", "MAX_ABS_ANGLE", "AMBIGUITY_MARGIN", "branch", "round_residual", "check_angles",
           "tree_cycle_residuals", "edge_integers"]

TWO_PI = 2.0 * np.pi

#: Largest accepted |δ| (radians). Beyond it δ mod 2π loses more than ~1e-10 rad to rounding
#: (ulp(1e6) ≈ 1.2e-10) and k would not fit the arithmetic; such a "measurement" is an input error.
MAX_ABS_ANGLE = 1e6

#: Default margin (radians): a residual (after rounding) within this distance of ±π is reported as
#: ambiguous. 0.5 rad ≈ 29°; a residual that large means the accumulated rotation error is of the
#: order of the decision boundary.
AMBIGUITY_MARGIN = 0.5


def branch(value, target) -> np.ndarray:
    """Rule (R): integers k (int64, broadcast shape) with value + 2πk − target ∈ (−π, π]."""
    diff = np.asarray(value, dtype=float) - np.asarray(target, dtype=float)
    return -np.ceil(diff / TWO_PI - 0.5).astype(np.int64)


def round_residual(residual) -> np.ndarray:
    """k = branch(residual, 0): the correction that brings a cycle residual into (−π, π] (eq. (22))."""
    return branch(residual, 0.0)


def edge_integers(graph: PoseGraph, theta) -> np.ndarray:
    """Per-edge integers k (m,) that put every measurement on the branch of the orientations ``theta``
    (n,): δ_e + 2πk_e − (θ_j − θ_i) ∈ (−π, π]. With the true orientations these are the true integers
    (while the per-edge noise stays below π)."""
    th = np.asarray(theta, dtype=float)
    return branch(graph.delta, th[graph.heads] - th[graph.tails])


def check_angles(graph: PoseGraph) -> None:
    """Raise ``GraphError`` naming the first edge whose |δ| exceeds ``MAX_ABS_ANGLE``."""
    big = np.flatnonzero(np.abs(graph.delta) > MAX_ABS_ANGLE)
    if big.size:
        k0 = big[0]
        raise GraphError(
            f"edge {graph.ids[graph.tails[k0]]}->{graph.ids[graph.heads[k0]]}: measured relative orientation "
            f"{graph.delta[k0]:.6g} rad is too large to be reduced modulo 2π accurately (|δ| > {MAX_ABS_ANGLE:g} rad"
            f"{f'; {big.size} such edges' if big.size > 1 else ''})")


def tree_cycle_residuals(graph: PoseGraph, tree: SpanningTree) -> np.ndarray:
    """r = C δ (l,): each chord's δ minus the tree path between its ends (eq. (20))."""
    c = tree.chords
    return graph.delta[c] - tree.path_sums(graph)[c]

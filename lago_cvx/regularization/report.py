"""What every regularizer returns: the regularized orientations δ_reg = δ + 2πk and how they were
decided (``RegularizationReport``), plus the ambiguity warning they share."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..graph import SpanningTree
from ..posegraph import PoseGraph
from ..rounding import TWO_PI

__all__ = ["RegularizationReport", "chord_report", "warn_ambiguous"]

log = logging.getLogger("lago_cvx.regularization")


@dataclass(frozen=True, eq=False)
class RegularizationReport:
    """Result of the 2kπ regularization (tree rounding, rounding against the chordal relaxation, or the
    integer program).

    ``delta_reg`` (m,) regularized relative orientations (tree rounding: tree edges unchanged);
    ``k`` (m,) integer correction per edge (tree rounding: 0 on tree edges); ``chords`` (l,) chord edge
    indices of ``tree``;
    ``residual_before`` (l,) r_c = (C δ)_c = δ_c − (θ_tree[j] − θ_tree[i]), the cycle residual before rounding;
    ``residual`` (l,) (C δ_reg)_c ∈ (−π, π] for the tree rounding (not bounded for the chordal one: there
    the bound (R-C) holds per edge, see ``edge_residual``);
    ``ambiguous`` edge indices whose rounding residual is within ``margin`` of ±π (chords for the tree
    rounding, any edge for the chordal one); ``theta_tree`` (n,) δ_reg integrated along the tree from
    its root (for the tree rounding: the "odometric" orientations of the tree, δ_reg = δ there);
    ``regularization`` "tree", "chordal" or "integer"; ``reference`` (n,) the orientations each edge was
    rounded against (θ_tree, or the chordal φ̃); ``edge_residual`` (m,) δ_reg − (reference_j − reference_i);
    ``chordal`` the ``ChordalEstimate`` (chordal only); ``problem`` its cvxpy problem (method "cvxpy"; for
    the integer regularization the mixed-integer cvxpy problem); ``integer`` the
    ``IntegerRegularization`` (integer only: objective, rounding's objective, solver)."""

    delta_reg: np.ndarray
    k: np.ndarray
    chords: np.ndarray
    residual_before: np.ndarray
    residual: np.ndarray
    ambiguous: np.ndarray
    theta_tree: np.ndarray
    margin: float
    tree: SpanningTree
    regularization: str = "tree"
    reference: np.ndarray | None = None
    edge_residual: np.ndarray | None = None
    chordal: object | None = None
    problem: object | None = None
    integer: object | None = None

    @property
    def n_regularized(self) -> int:
        """Number of fundamental cycles whose sum needed a non-zero 2kπ correction (the seed's Table I, last
        row: chords with k ≠ 0 for the tree rounding)."""
        return int(np.count_nonzero(self.cycle_k))

    @property
    def k_chords(self) -> np.ndarray:
        """k per chord, shape (l,) (the tree rounding's only non-zero entries)."""
        return self.k[self.chords]

    @property
    def cycle_k(self) -> np.ndarray:
        """Integer correction of each fundamental cycle sum, C k (l,): (C δ_reg − C δ)/2π. Two
        regularizations are equivalent (give the same phase-1 θ up to 2π per pose) iff these coincide;
        equals ``k_chords`` for the tree rounding."""
        return np.rint((self.residual - self.residual_before) / TWO_PI).astype(np.int64)

    def cycle_residual(self, graph: PoseGraph) -> np.ndarray:
        """C·δ_reg evaluated through the tree (no C formed), shape (l,); equals ``residual``."""
        return self.delta_reg[self.chords] - self.tree.path_sums(graph, self.delta_reg)[self.chords]

    def summary(self) -> dict:
        return {
            "regularization": self.regularization,
            "n_chords": int(self.chords.size),
            "n_regularized": self.n_regularized,
            "n_ambiguous": int(self.ambiguous.size),
            "max_abs_residual": float(np.abs(self.residual).max()) if self.residual.size else 0.0,
        }


def warn_ambiguous(graph: PoseGraph, ambiguous: np.ndarray, margin: float, what: str, why: str) -> None:
    """Log one warning listing (up to 10) ambiguous edges by their pose ids."""
    if ambiguous.size:
        ids = graph.ids
        listed = ", ".join(f"{ids[graph.tails[e]]}->{ids[graph.heads[e]]}" for e in ambiguous[:10])
        log.warning("regularization: %d %s(s) have a residual within %.3g rad of ±π, so their 2kπ correction is "
                    "ambiguous (%s): %s%s", ambiguous.size, what, margin, why, listed,
                    " ..." if ambiguous.size > 10 else "")


def chord_report(graph: PoseGraph, tree: SpanningTree, k: np.ndarray, *, margin: float, regularization: str,
                 why: str, **extra) -> RegularizationReport:
    """The report of a regularization whose integers k (m,) sit on the chords only (tree edges keep δ):
    the tree integration is unchanged, (C δ_reg)_c is the chord's residual, ambiguous chords are those
    within ``margin`` of ±π (or beyond), warned with ``why``."""
    theta_tree = tree.integrate(graph)
    path = theta_tree[graph.heads] - theta_tree[graph.tails]  # (m,), equals δ on tree edges
    c = tree.chords
    delta_reg = graph.delta + TWO_PI * k
    edge_residual = delta_reg - path  # 0 on tree edges, C δ_reg on chords
    residual = edge_residual[c]
    ambiguous = c[np.abs(residual) > np.pi - margin]
    warn_ambiguous(graph, ambiguous, margin, "chord", why)
    return RegularizationReport(delta_reg=delta_reg, k=k, chords=c, residual_before=graph.delta[c] - path[c],
                                residual=residual, ambiguous=ambiguous, theta_tree=theta_tree, margin=float(margin),
                                tree=tree, regularization=regularization, reference=theta_tree,
                                edge_residual=edge_residual, **extra)

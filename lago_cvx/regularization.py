"""Orientation regularization (the seed's Section IV-E: Theorem 3, eqs. (20)–(23), Corollary 3).

Measured relative orientations δ are only known modulo 2π (a sensor reports them in [−π, π)), but
phase 1 treats them as real numbers whose sums around every cycle vanish up to noise. Theorem 3
constructs integers k (one per chord of a spanning tree) such that the corrected measurements
δ_reg = δ + 2πk make every fundamental cycle consistent:

    θ_tree = orientations integrated along the spanning tree from the anchor (tree edges unchanged),
    for every chord c = (i → j):   r_c = (C δ)_c = δ_c − (θ_tree[j] − θ_tree[i])   (cycle residual),
                                   k_c = −round(r_c / 2π),   δ_reg,c = δ_c + 2π k_c,
    so that (C δ_reg)_c = r_c + 2π k_c ∈ (−π, π]                                 (eqs. 20–23).

Rounding rule for exact ties (r_c/2π exactly half-integer): ``k_c = −ceil(r_c/2π − 1/2)``, i.e. the
corrected residual always lies in the half-open interval (−π, π] (a tie gives +π). A tie
means the measurement is useless for deciding k; such chords and any chord whose residual lies within
``margin`` of ±π are listed in ``RegularizationReport.ambiguous`` (the seed's "noise too large" case:
the correct k is then not guaranteed, Corollary 3).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .graph import SpanningTree
from .posegraph import GraphError, PoseGraph

__all__ = ["RegularizationReport", "regularize", "AMBIGUITY_MARGIN"]

log = logging.getLogger(__name__)

#: Default margin (radians): a chord whose cycle residual (after rounding) is within this distance of
#: ±π is reported as ambiguous. 0.5 rad ≈ 29°; a residual that large means the tree path's
#: accumulated rotation error is of the order of the decision boundary.
AMBIGUITY_MARGIN = 0.5

#: Largest accepted |δ| (radians). Beyond it δ mod 2π loses more than ~1e-10 rad to rounding
#: (ulp(1e6) ≈ 1.2e-10) and k would not fit the arithmetic; such a "measurement" is an input error.
MAX_ABS_ANGLE = 1e6


@dataclass(frozen=True, eq=False)
class RegularizationReport:
    """Result of the 2kπ regularization along a spanning tree.

    ``delta_reg`` (m,) regularized relative orientations (tree edges unchanged);
    ``k`` (m,) integer correction per edge (0 on tree edges); ``chords`` (l,) chord edge indices;
    ``residual_before`` (l,) r_c = (C δ)_c = δ_c − (θ_tree[j] − θ_tree[i]), the cycle residual before rounding;
    ``residual`` (l,) (C δ_reg)_c = r_c + 2π k_c ∈ (−π, π], the cycle residual after rounding;
    ``ambiguous`` chord edge indices whose |residual| > π − margin; ``theta_tree`` (n,) the
    orientations integrated along the tree (the "odometric" orientations of the tree)."""

    delta_reg: np.ndarray
    k: np.ndarray
    chords: np.ndarray
    residual_before: np.ndarray
    residual: np.ndarray
    ambiguous: np.ndarray
    theta_tree: np.ndarray
    margin: float
    tree: SpanningTree

    @property
    def n_regularized(self) -> int:
        """Number of chords that needed a non-zero 2kπ correction (the seed's Table I, last row)."""
        return int(np.count_nonzero(self.k[self.chords]))

    @property
    def k_chords(self) -> np.ndarray:
        """k per chord, shape (l,)."""
        return self.k[self.chords]

    def cycle_residual(self, graph: PoseGraph) -> np.ndarray:
        """C·δ_reg evaluated through the tree (no C formed), shape (l,); equals ``residual``."""
        return self.delta_reg[self.chords] - self.tree.path_sums(graph, self.delta_reg)[self.chords]

    def summary(self) -> dict:
        return {
            "n_chords": int(self.chords.size),
            "n_regularized": self.n_regularized,
            "n_ambiguous": int(self.ambiguous.size),
            "max_abs_residual": float(np.abs(self.residual).max()) if self.residual.size else 0.0,
        }


def regularize(graph: PoseGraph, tree: SpanningTree, *, margin: float = AMBIGUITY_MARGIN) -> RegularizationReport:
    """2kπ regularization of the chords of ``tree`` (Theorem 3, eqs. (20)–(23)); vectorized, O(m + n log n).

    Returns a ``RegularizationReport``; logs a warning listing (up to 10) ambiguous chords."""
    big = np.flatnonzero(np.abs(graph.delta) > MAX_ABS_ANGLE)
    if big.size:
        k0 = big[0]
        raise GraphError(
            f"edge {graph.ids[graph.tails[k0]]}->{graph.ids[graph.heads[k0]]}: measured relative orientation "
            f"{graph.delta[k0]:.6g} rad is too large to be reduced modulo 2π accurately (|δ| > {MAX_ABS_ANGLE:g} rad"
            f"{f'; {big.size} such edges' if big.size > 1 else ''})")
    theta_tree = tree.integrate(graph)
    path = theta_tree[graph.heads] - theta_tree[graph.tails]  # (m,), equals δ on tree edges
    c = tree.chords
    before = graph.delta[c] - path[c]  # r = C δ
    k_c = -np.ceil(before / (2.0 * np.pi) - 0.5).astype(np.int64)  # tie rule: residual in (−π, π]
    k = np.zeros(graph.n_edges, np.int64)
    k[c] = k_c
    delta_reg = graph.delta + 2.0 * np.pi * k
    residual = delta_reg[c] - path[c]  # C δ_reg
    ambiguous = c[np.abs(residual) > np.pi - margin]
    if ambiguous.size:
        ids = graph.ids
        listed = ", ".join(f"{ids[graph.tails[e]]}->{ids[graph.heads[e]]}" for e in ambiguous[:10])
        log.warning("regularization: %d chord(s) have a cycle residual within %.3g rad of ±π, so their 2kπ "
                    "correction is ambiguous (rotation noise too large along the tree path): %s%s",
                    ambiguous.size, margin, listed, " ..." if ambiguous.size > 10 else "")
    return RegularizationReport(delta_reg=delta_reg, k=k, chords=c, residual_before=before, residual=residual,
                                ambiguous=ambiguous, theta_tree=theta_tree, margin=float(margin), tree=tree)

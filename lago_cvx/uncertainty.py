"""Per-edge uncertainty in the form LAGO's phases use it.

The seed assumes P_ij = blkdiag(P_Δ, P_δ) (its Remark 2); real files carry a full 3×3 information
Ω_ij with x–θ and y–θ cross terms. ``edge_uncertainty`` returns the **marginal covariances** of the
full matrix: Σ = Ω⁻¹, P_Δ,ij = Σ[0:2, 0:2], P_δ,ij = Σ[2, 2]. This keeps each measurement's own
accuracy and drops only the Δˡ–δ correlation, which the seed's phase split does not carry. P_Δ is
expressed in the frame of the tail (as Δˡ is).

Every step that weights orientations — the spanning trees, the three regularizers, phase 1 — takes
P_δ from here, so they all agree on what a measurement is worth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linalg import whitening_2x2
from .posegraph import PoseGraph

__all__ = ["EdgeUncertainty", "edge_uncertainty"]


@dataclass(frozen=True, eq=False)
class EdgeUncertainty:
    """Per-edge marginal uncertainties (see the module docstring).

    ``cov_delta_l`` (m, 2, 2) P_Δ,ij in the tail's frame; ``var_delta`` (m,) P_δ,ij;
    ``sqrt_info_delta_l`` (m, 2, 2) upper-triangular U with UᵀU = P_Δ,ij⁻¹;
    ``sqrt_info_delta`` (m,) 1/√P_δ,ij."""

    cov_delta_l: np.ndarray
    var_delta: np.ndarray
    sqrt_info_delta_l: np.ndarray
    sqrt_info_delta: np.ndarray

    @property
    def info_delta(self) -> np.ndarray:
        """1/P_δ,ij (m,): the rotational weight of each edge."""
        return 1.0 / self.var_delta


def edge_uncertainty(graph: PoseGraph) -> EdgeUncertainty:
    """Marginal covariances of Δˡ and δ from each edge's full information matrix (shapes above)."""
    cov = graph.covariance
    cov_l = cov[:, :2, :2]
    var_d = cov[:, 2, 2].copy()
    info_l = np.linalg.inv(cov_l) if graph.n_edges else np.zeros((0, 2, 2))
    info_l = 0.5 * (info_l + np.swapaxes(info_l, 1, 2))
    return EdgeUncertainty(cov_delta_l=cov_l, var_delta=var_d, sqrt_info_delta_l=whitening_2x2(info_l),
                           sqrt_info_delta=1.0 / np.sqrt(var_d))

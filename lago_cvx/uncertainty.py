"""Per-edge uncertainty in the forms LAGO's phases use it.

Each edge carries a 3×3 information Ω = Σ⁻¹ of its error e = [R_iᵀ(p_j − p_i) − Δˡ; θ_j − θ_i − δ]
(order x, y, θ; positions in the frame of the tail i). The seed assumes Σ = blkdiag(P_Δ, P_δ) (its
Remark 2); real files often carry x–θ and y–θ cross terms. Three views of the same Ω are needed:

* the **marginal** covariances P_Δ = Σ[0:2, 0:2] and P_δ = Σ[2, 2] — phase 1 estimates the orientations
  from δ alone, and the BLUE from δ alone weighs each δ by 1/P_δ, its marginal variance; the seed's
  phase 2 (eqs. (9)–(11)) propagates P_Δ;
* the **full** square root U (3×3, upper triangular, UᵀU = Ω) — the full-information phase 3 weighs
  each edge's joint position-and-orientation residual with it (``lago_cvx.phases``);
* the **conditional** position information Ω_pp = Ω[0:2, 0:2] and h = Ω_pp⁻¹Ω_pθ — with the
  orientations fixed, completing the square in e_t gives
  eᵀΩe = (e_t + h e_θ)ᵀΩ_pp(e_t + h e_θ) + e_θ²/P_δ, so positions are fitted to the shifted target
  Δˡ − h e_θ with weight Ω_pp (``lago_cvx.positions``).

With block-diagonal Ω the three agree: Ω_pp = P_Δ⁻¹, h = 0, U = blkdiag(P_Δ^{-1/2}, P_δ^{-1/2}).

Every step that weighs orientations — the spanning trees, the three regularizers, phase 1 — takes P_δ
from here, so they all agree on what a measurement is worth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linalg import whitening_2x2
from .posegraph import PoseGraph
from .smallmat import cholesky, spd_inverse
from .routes import INFORMATION_MODES

__all__ = ["EdgeUncertainty", "edge_uncertainty", "INFORMATION_MODES"]

# INFORMATION_MODES (from routes): how phases 2–3 use each edge's information — "full" (the whole 3×3 Ω,
# first-order optimal for any Ω) or "marginal" (the paper's blkdiag(P_Δ, P_δ), eqs. (9)–(15)).


@dataclass(frozen=True, eq=False)
class EdgeUncertainty:
    """Per-edge uncertainties (module docstring). Shapes for m edges:

    marginal — ``cov_delta_l`` (m, 2, 2) P_Δ in the tail's frame; ``var_delta`` (m,) P_δ;
    ``sqrt_info_delta_l`` (m, 2, 2) upper-triangular with UᵀU = P_Δ⁻¹; ``sqrt_info_delta`` (m,) 1/√P_δ.
    full — ``sqrt_info`` (m, 3, 3) upper-triangular with UᵀU = Ω.
    conditional — ``sqrt_info_pp`` (m, 2, 2) upper-triangular with UᵀU = Ω_pp; ``shift`` (m, 2)
    h = Ω_pp⁻¹Ω_pθ."""

    cov_delta_l: np.ndarray
    var_delta: np.ndarray
    sqrt_info_delta_l: np.ndarray
    sqrt_info_delta: np.ndarray
    sqrt_info: np.ndarray
    sqrt_info_pp: np.ndarray
    shift: np.ndarray

    @property
    def info_delta(self) -> np.ndarray:
        """1/P_δ (m,): the rotational weight of each edge."""
        return 1.0 / self.var_delta

    @property
    def block_diagonal(self) -> np.ndarray:
        """Bool (m,): the edge's Ω has no x–θ / y–θ terms (the seed's assumption holds exactly)."""
        return np.all(self.shift == 0.0, axis=1)


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def edge_uncertainty(graph: PoseGraph) -> EdgeUncertainty:
    """The marginal, full and conditional forms of every edge's information (shapes above)."""
    info = _sym(graph.information)
    m = graph.n_edges
    if m == 0:
        z2, z3 = np.zeros((0, 2, 2)), np.zeros((0, 3, 3))
        return EdgeUncertainty(z2, np.zeros(0), z2, np.zeros(0), z3, z2, np.zeros((0, 2)))
    cov = spd_inverse(info)  # closed forms on the (m, 3, 3) stack (lago_cvx.smallmat)
    cov_l = cov[:, :2, :2]
    var_d = cov[:, 2, 2].copy()
    info_l = spd_inverse(np.ascontiguousarray(cov_l))
    info_pp = info[:, :2, :2]
    shift = np.einsum("kab,kb->ka", spd_inverse(np.ascontiguousarray(info_pp)), info[:, :2, 2])
    sqrt_info = np.swapaxes(cholesky(info), 1, 2)  # UᵀU = Ω, U upper triangular
    return EdgeUncertainty(cov_delta_l=cov_l, var_delta=var_d, sqrt_info_delta_l=whitening_2x2(info_l),
                           sqrt_info_delta=1.0 / np.sqrt(var_d), sqrt_info=sqrt_info,
                           sqrt_info_pp=whitening_2x2(info_pp), shift=shift)

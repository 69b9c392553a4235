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

from functools import cached_property

import numpy as np

from .stacks import cholesky, row_blocks, spd_inverse, spd_inverse_corner, whitening_2x2
from .posegraph import PoseGraph
from .routes import INFORMATION_MODES

__all__ = ["EdgeUncertainty", "edge_uncertainty", "INFORMATION_MODES"]

# INFORMATION_MODES (from routes): how phases 2–3 use each edge's information — "full" (the whole 3×3 Ω,
# first-order optimal for any Ω) or "marginal" (the paper's blkdiag(P_Δ, P_δ), eqs. (9)–(15)).


def _item(pair: str, k: int, doc: str) -> property:
    """Read-only property ``doc``: item ``k`` of the cached tuple attribute ``pair`` (arrays computed
    together, read apart)."""
    return property(lambda self: getattr(self, pair)[k], doc=doc)


class EdgeUncertainty:
    """Per-edge uncertainties (module docstring) of the information stack ``information`` (m, 3, 3) (read
    through its symmetric part). Shapes for m edges:

    marginal — ``cov_delta_l`` (m, 2, 2) P_Δ in the tail's frame; ``var_delta`` (m,) P_δ;
    ``sqrt_info_delta_l`` (m, 2, 2) upper-triangular with UᵀU = P_Δ⁻¹; ``sqrt_info_delta`` (m,) 1/√P_δ.
    full — ``sqrt_info`` (m, 3, 3) upper-triangular with UᵀU = Ω.
    conditional — ``sqrt_info_pp`` (m, 2, 2) upper-triangular with UᵀU = Ω_pp; ``shift`` (m, 2)
    h = Ω_pp⁻¹Ω_pθ.

    Each form is computed when first read (a route uses some of them: the seed's the marginal ones, the
    default the full and conditional ones), a block of edges at a time (``stacks.row_blocks``), with the
    closed forms of ``lago_cvx.stacks``."""

    def __init__(self, information: np.ndarray):
        self.information = np.asarray(information, dtype=float)

    def _per_edge(self, fn, *shapes) -> list[np.ndarray]:
        """Outputs (m, *shape) of ``fn(Ω_k)`` (a block of symmetric Ω's → one array per shape)."""
        info = self.information
        m = info.shape[0]
        outs = [np.empty((m,) + sh) for sh in shapes]
        for k in row_blocks(m):
            for out, value in zip(outs, fn(_sym(info[k]))):
                out[k] = value
        return outs

    @cached_property
    def var_delta(self) -> np.ndarray:
        """P_δ = Σ[2, 2] (m,): ``stacks.spd_inverse_corner``, the one entry of Σ = Ω⁻¹ needed."""
        return self._per_edge(lambda om: (spd_inverse_corner(om),), ())[0]

    @cached_property
    def _marginal(self) -> tuple[np.ndarray, np.ndarray]:
        def fn(om):
            cov_l = np.ascontiguousarray(spd_inverse(om)[:, :2, :2])
            return cov_l, whitening_2x2(spd_inverse(cov_l))

        return tuple(self._per_edge(fn, (2, 2), (2, 2)))

    cov_delta_l = _item("_marginal", 0, "P_Δ = Σ[0:2, 0:2] (m, 2, 2).")
    sqrt_info_delta_l = _item("_marginal", 1, "(m, 2, 2) upper-triangular U with UᵀU = P_Δ⁻¹.")

    @cached_property
    def sqrt_info_delta(self) -> np.ndarray:
        """1/√P_δ (m,)."""
        return 1.0 / np.sqrt(self.var_delta)

    @cached_property
    def sqrt_info(self) -> np.ndarray:
        """(m, 3, 3) upper-triangular U with UᵀU = Ω."""
        return self._per_edge(lambda om: (np.swapaxes(cholesky(om), 1, 2),), (3, 3))[0]

    @cached_property
    def _conditional(self) -> tuple[np.ndarray, np.ndarray]:
        def fn(om):
            info_pp = np.ascontiguousarray(om[:, :2, :2])
            return whitening_2x2(info_pp), np.einsum("kab,kb->ka", spd_inverse(info_pp), om[:, :2, 2])

        return tuple(self._per_edge(fn, (2, 2), (2,)))

    sqrt_info_pp = _item("_conditional", 0, "(m, 2, 2) upper-triangular U with UᵀU = Ω_pp.")
    shift = _item("_conditional", 1, "h = Ω_pp⁻¹Ω_pθ (m, 2).")

    @property
    def info_delta(self) -> np.ndarray:
        """1/P_δ (m,): the rotational weight of each edge."""
        return 1.0 / self.var_delta

    def prepare(self, *, information: str, positions: str) -> None:
        """Compute now the forms phases 2–3 read with this ``information`` (``"full"``: ``sqrt_info``;
        ``"marginal"``: ``sqrt_info_delta_l``) and ``positions`` (``"resolve"``: ``sqrt_info_pp``), each
        otherwise computed when first read: ``lago`` does it while the engine builds the elimination."""
        if self.information.shape[0]:
            getattr(self, "sqrt_info_delta_l" if information == "marginal" else "sqrt_info")
            if positions == "resolve":
                getattr(self, "sqrt_info_pp")

    @property
    def block_diagonal(self) -> np.ndarray:
        """Bool (m,): the edge's Ω has no x–θ / y–θ terms (the seed's assumption holds exactly)."""
        return np.all(self.shift == 0.0, axis=1)


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def edge_uncertainty(graph: PoseGraph) -> EdgeUncertainty:
    """The marginal, full and conditional forms of every edge's information (shapes above; each computed
    when first read)."""
    return EdgeUncertainty(graph.information)

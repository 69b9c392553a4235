r"""Theorem 1 measured: what the paper claims about phase 3, what holds, and what does not.

Theorem 1 of the seed says that phase 3 is a local correction of the sub-optimal estimate
x̂ = [p̂; θ̂] — θ̂ from phase 1 (eq. (13)), p̂ the positions with θ̂ held fixed (eq. (14)) — "leading it
towards a minimum of the cost function". Its proof has two parts:

1. **the identity** x* = x̂ + [ρ̃; δ̃]: by block elimination of phase 3's normal equations (eq. (15)),
   θ* = θ̂ + δ̃ (eq. (16)) and p* = p̂ + ρ̃ (eq. (17)), and minimising the first-order expansion (18) of
   the cost around x̂ gives exactly these corrections;
2. **the claim** that this moves x̂ towards a minimum.

With H = MᵀM and g = MᵀWz the normal equations of phase 3 (M = WBᵀ, split into positions p and
orientations θ): p̂ = H_pp⁻¹(g_p − H_pθ θ̂) (phase 3's cost is exact at θ = θ̂, so this is eq. (14) — for
full information the exact positions given θ̂, ``lago_cvx.positions``), and

    δ̃ = S⁻¹ r_θ,   S = H_θθ − H_θp H_pp⁻¹ H_pθ,   r_θ = g_θ − H_θp p̂ − H_θθ θ̂         (eq. (16))
    ρ̃ = −H_pp⁻¹ H_pθ δ̃                                                               (eq. (17)).

``theorem1`` computes x̂ and the corrections this way — as the least-squares problems they are the
normal equations of (p̂ = argmin ‖M_p p − (Wz − M_θ θ̂)‖; [·; δ̃] = argmin ‖MΔ − (Wz − M x̂)‖, whose normal
equations are HΔ = [0; r_θ]; ρ̃ = argmin ‖M_p ρ + M_θ δ̃‖), each solved with corrected semi-normal
refinement (``lago_cvx.sparse.linalg.solve_least_squares``: accurate also for input_INTEL's cond ≈ 1e8) — and
reports how exactly x* − x̂ = [ρ̃; δ̃] holds (part 1: to rounding), and the χ² of eq. (3) — the cost the
graph means (``lago_cvx.conventions``) — at x̂, at x*, and at the positions re-solved for θ* (part 2: on INTEL
(both files), MIT and manhattan χ²(x*) > χ²(x̂), on INTEL_P 220.0 → 14 531; on CSAIL, intel, FR079, city10000
and the M3500 g2o files χ²(x*) < χ²(x̂); ``python benchmarks/run.py theorem1``). The expansion is not what
fails: eq. (18) weighs the position residuals with R(θ̂) frozen, and with those weights the step lowers the
cost (INTEL_P 220.0 → 214.3, :func:`frozen_and_model`); χ² weighs them with R at the returned orientations, and
on files with very anisotropic translational information a small turn of a pose moves cheap residuals onto a
stiff axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sparse import solve_least_squares
from .metrics import chi2, relative_difference
from .pipeline import lago
from .posegraph import PoseGraph, rot2
from .positions import resolve_positions
from .result import LagoResult

__all__ = ["Theorem1", "theorem1", "frozen_and_model"]


@dataclass(frozen=True, eq=False)
class Theorem1:
    """Theorem 1 on one graph (module docstring), in the anchor's frame (anchor at the origin).

    ``x_hat`` (3d,) = [p̂; θ̂] (eq. (14), (13)); ``x_star`` (3d,) phase 3's x*; ``theta_correction`` δ̃ (d,)
    (eq. (16)); ``position_correction`` ρ̃ (2d,) (eq. (17)); ``identity_error`` relative difference of
    x* − x̂ and [ρ̃; δ̃]; ``eq14_error`` relative difference of p̂ from H and from the position solve
    (``lago_cvx.positions``) at θ̂; ``chi2_suboptimal`` χ² at x̂, ``chi2_phase3`` at x*,
    ``chi2_resolved`` at [positions re-solved for θ*; θ*], ``chi2_lago`` at the result's poses (its
    route); ``result`` the ``LagoResult``."""

    x_hat: np.ndarray
    x_star: np.ndarray
    theta_correction: np.ndarray
    position_correction: np.ndarray
    identity_error: float
    eq14_error: float
    chi2_suboptimal: float
    chi2_phase3: float
    chi2_resolved: float
    chi2_lago: float
    result: LagoResult

    def poses(self, x: np.ndarray) -> np.ndarray:
        """ρ = [p (interleaved); θ] (3d,) of the free poses → poses (n, 3), the anchor at the origin."""
        return _poses(self.result, np.asarray(x, dtype=float))


def _poses(result: LagoResult, x: np.ndarray) -> np.ndarray:
    from .phases import _poses_from_x

    return _poses_from_x(result.graph.n_poses, result.anchor_index, x)


def theorem1(graph: PoseGraph, result: LagoResult | None = None, **lago_options) -> Theorem1:
    """Measure Theorem 1 on ``graph`` for ``result`` (default ``lago(graph, **lago_options)``, closed
    form, no ``anchors``): the identity x* = x̂ + [ρ̃; δ̃] of eqs. (16)–(17) and the χ² at x̂, x* and after
    re-solving the positions (module docstring). Sparse throughout (three least-squares solves and two
    position solves besides LAGO's own)."""
    res = lago(graph, **lago_options) if result is None else result
    ph2, ph3 = res.phase2, res.phase3
    d = graph.n_poses - 1
    M = (ph2.W @ ph2.Bt).tocsc()
    b = ph2.W @ ph2.z
    M_p, M_t = M[:, :2 * d], M[:, 2 * d:]
    theta_hat = res.phase1.theta_free
    p_hat = solve_least_squares(M_p, b - M_t @ theta_hat)[0]  # eq. (14): phase 3's cost at θ = θ̂
    x_hat = np.concatenate([p_hat, theta_hat])
    delta = solve_least_squares(M, b - M @ x_hat)[0][2 * d:]  # eq. (16): S δ̃ = r_θ by block elimination
    rho = solve_least_squares(M_p, -(M_t @ delta))[0]  # eq. (17): ρ̃ = −H_pp⁻¹ H_pθ δ̃
    exact_p = resolve_positions(graph, res.phase1.theta, res.uncertainty, anchor=res.anchor).poses[:, :2]
    p_hat_poses = _poses(res, x_hat)[:, :2]
    theta_star = _poses(res, ph3.x_star)[:, 2]
    resolved = resolve_positions(graph, theta_star, res.uncertainty, anchor=res.anchor).poses
    return Theorem1(
        x_hat=x_hat, x_star=ph3.x_star, theta_correction=delta, position_correction=rho,
        identity_error=relative_difference(ph3.x_star - x_hat, np.concatenate([rho, delta])),
        eq14_error=relative_difference(p_hat_poses, exact_p),
        chi2_suboptimal=chi2(graph, _poses(res, x_hat)), chi2_phase3=chi2(graph, _poses(res, ph3.x_star)),
        chi2_resolved=chi2(graph, resolved), chi2_lago=res.chi2, result=res)


def frozen_and_model(result: LagoResult, poses: np.ndarray) -> tuple[float, float]:
    """Where Theorem 1's claim breaks (module docstring): for ``poses`` (n, 3) in the anchor's frame, the
    χ² of eq. (6) with each edge's position weight frozen at θ̂ — (R(θ̂_i) P_Δˡ R(θ̂_i)ᵀ)⁻¹ instead of
    the same at the poses' own θ_i — with exact residuals, and the quadratic model of eq. (18): the same
    weights, the residual p_j − p_i − R(θ_i)Δˡ linearised in θ_i around θ̂_i. Both include the rotational
    term Σ (θ_j − θ_i − δ_reg)² / P_δ. ``result`` supplies θ̂ (phase 1), δ_reg and the per-edge 2×2
    position covariances P_Δˡ (its ``uncertainty``)."""
    g, unc = result.graph, result.uncertainty
    poses = np.asarray(poses, dtype=float)
    theta_hat = result.phase1.theta
    Rh = rot2(theta_hat[g.tails])
    weight = Rh @ np.linalg.inv(unc.cov_delta_l) @ np.swapaxes(Rh, 1, 2)       # frozen at θ̂: (m, 2, 2)
    dp = poses[g.heads, :2] - poses[g.tails, :2]
    exact = dp - np.einsum("kab,kb->ka", rot2(poses[g.tails, 2]), g.delta_l)
    turned = np.einsum("kab,kb->ka", Rh, g.delta_l)                            # R(θ̂_i) Δˡ
    perp = np.column_stack([-turned[:, 1], turned[:, 0]])                     # its derivative in θ_i
    linear = dp - turned - perp * (poses[g.tails, 2] - theta_hat[g.tails])[:, None]
    rot = float(np.sum((poses[g.heads, 2] - poses[g.tails, 2] - result.regularization.delta_reg) ** 2
                       / unc.var_delta))
    return (float(np.einsum("ka,kab,kb->", exact, weight, exact)) + rot,
            float(np.einsum("ka,kab,kb->", linear, weight, linear)) + rot)

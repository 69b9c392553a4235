"""Lecture 1, exercise 2 — the reduced cost of eq. (6) in code.

f(p, θ) = (A₂ᵀp − RΔˡ)ᵀ(R P_Δˡ Rᵀ)⁻¹(A₂ᵀp − RΔˡ) + (Aᵀθ − δ)ᵀP_δ⁻¹(Aᵀθ − δ), with the reduced A (pose 0
deleted), A₂ = A ⊗ I₂ and R = blkdiag of the tails' rotations. It equals lago_cvx.chi2 whenever every
angular residual already lies in [−π, π): the package wraps the angular residual, eq. (6) does not. Turn one
pose by 2π and the two differ (the configuration is the same, so chi2 does not change; eq. (6) does).
"""

import numpy as np
import scipy.sparse as sp

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.posegraph import rot2

setup("01_problem")


def cost_eq6(graph, poses):
    """Eq. (6) for block-diagonal information, pose 0 at the origin; poses (n + 1, 3)."""
    A = lc.reduced_incidence(graph)
    A2 = sp.kron(A, sp.identity(2)).tocsr()
    theta = poses[:, 2]
    R = sp.block_diag(rot2(theta[graph.tails]), format="csr")
    cov = graph.covariance
    P_dl = sp.block_diag(cov[:, :2, :2], format="csc")
    r_pos = A2.T @ poses[1:, :2].ravel() - R @ graph.delta_l.ravel()
    weight_pos = (R @ P_dl @ R.T).tocsc()
    r_rot = A.T @ theta[1:] - graph.delta
    return float(r_pos @ sp.linalg.spsolve(weight_pos, r_pos) + np.sum(r_rot**2 / cov[:, 2, 2]))


world = lc.manhattan_world(300, seed=3, sigma_xy=0.05, sigma_theta=0.02)
g = world.graph
x = world.truth - world.truth[0]                                   # pose 0 at the origin
x[:, :2] = (world.truth[:, :2] - world.truth[0, :2]) @ rot2(world.truth[0, 2])   # rotate into pose 0's frame
x[1:] += 0.01 * np.random.default_rng(0).standard_normal((g.n_poses - 1, 3))
lifted = lc.PoseGraph(g.n_poses, g.tails, g.heads, g.delta_l,
                      g.delta + 2 * np.pi * np.round((lc.incidence_matrix(g).T @ x[:, 2] - g.delta) / (2 * np.pi)),
                      g.information)                                # δ lifted to the branch of x: no wrap needed
f6, f_pkg = cost_eq6(lifted, x), lc.chi2(lifted, x)
check(abs(f6 - f_pkg) < 1e-9 * f_pkg, f"eq. (6) = lago_cvx.chi2 near the truth ({f6:.6f})")
turned = x.copy()
turned[5, 2] += 2 * np.pi
check(abs(lc.chi2(lifted, turned) - f_pkg) < 1e-9 * f_pkg, "chi2 wraps: turning pose 5 by 2π changes nothing")
check(cost_eq6(lifted, turned) > 100 * f_pkg, f"eq. (6) does not wrap: {cost_eq6(lifted, turned):.3g} — an angular residual of 2π")

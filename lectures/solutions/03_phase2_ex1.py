"""Lecture 3, exercise 1 — why W hardly depends on θ̂.

R(θ)ᵀ S R(θ) = S: S is the rotation by +90°, and plane rotations commute, so RᵀSR = RᵀRS = S. The block of
edge k of RᵀJ is R(θ̂_i)ᵀ S R(θ̂_i) Δˡ_k = S Δˡ_k, whatever θ̂. So in
    W = [[P_Δˡ^(−1/2) Rᵀ, −P_Δˡ^(−1/2) RᵀJ], [0, P_δ^(−1/2) Aᵀ]]
only the first block column (P_Δˡ^(−1/2) Rᵀ) changes with θ̂.
"""

import numpy as np

import lago_cvx as lc
from lago_cvx.course import S, check, setup
from lago_cvx import phases
from lago_cvx.posegraph import rot2
from lago_cvx.uncertainty import edge_uncertainty

setup("03_phase2")

angles = np.random.default_rng(0).uniform(-10, 10, 1000)
R = rot2(angles)
check(np.abs(np.transpose(R, (0, 2, 1)) @ S @ R - S).max() < 1e-12, "R(θ)ᵀ S R(θ) = S for 1000 random θ")

g = lc.random_graph(20, 35, seed=4).graph
unc = edge_uncertainty(g)
rng = np.random.default_rng(1)
theta_a, theta_b = rng.uniform(-np.pi, np.pi, (2, g.n_poses))
theta_a[0] = theta_b[0] = 0.0
W_a = phases.phase2(g, theta_a, unc, information="marginal").W.toarray()
W_b = phases.phase2(g, theta_b, unc, information="marginal").W.toarray()
m = g.n_edges
check(np.abs(W_a[:, 2 * m:] - W_b[:, 2 * m:]).max() < 1e-12, "the θ̂ columns of W (−P_Δˡ^(−1/2)SΔˡ, P_δ^(−1/2)Aᵀ) do not change")
check(np.abs(W_a[:, :2 * m] - W_b[:, :2 * m]).max() > 0.1, "only the first block column P_Δˡ^(−1/2)Rᵀ does")

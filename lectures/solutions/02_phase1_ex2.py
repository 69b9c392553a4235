"""Lecture 2, exercise 2 — a compass instead of an anchor.

Unknowns: all n + 1 orientations θ⁺. Data: the relative orientations δ_reg (weights P_δ^(−1/2)) and compass
readings c at the poses K with standard deviation σ_c. Cost ‖P_δ^(−1/2)(A_fullᵀθ⁺ − δ_reg)‖² + ‖(θ⁺_K − c)/σ_c‖².
Closed form: with the augmented design D = [A_full, E_K] (E_K the columns e_k, k ∈ K) and weights
w = [1/P_δ, 1/σ_c²], θ⁺ = (D diag(w) Dᵀ)⁻¹ D diag(w) [δ_reg; c]. D diag(w) Dᵀ = Laplacian + Σ_k e_k e_kᵀ/σ_c² is
positive definite for a connected graph with at least one compass reading — Proposition 1 with a soft
known orientation instead of a hard one.
"""

import cvxpy as cp
import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.graph import spanning_tree
from lago_cvx.regularization import regularize
from lago_cvx.solvers import solve
from lago_cvx.uncertainty import edge_uncertainty

setup("02_phase1")

world = lc.manhattan_world(80, seed=5, sigma_theta=0.03)
g = world.graph
reg, unc = regularize(g, spanning_tree(g, "odometry")), edge_uncertainty(g)
A_full = lc.incidence_matrix(g).toarray()
truth = world.truth[:, 2] - world.truth[0, 2] + reg.theta_tree[0]
rng = np.random.default_rng(3)
sigma_c = 0.05

θ = cp.Variable(g.n_poses, name="θ⁺")
w_δ = cp.Constant(np.sqrt(unc.info_delta), name="w_δ")
for K in ([10], [10, 40, 70]):
    c = cp.Parameter(len(K), name="c")
    objective = cp.sum_squares(cp.multiply(w_δ, A_full.T @ θ - reg.delta_reg)) + cp.sum_squares((θ[K] - c) / sigma_c)
    problem = cp.Problem(cp.Minimize(objective))
    D = np.hstack([A_full, np.eye(g.n_poses)[:, K]])
    w = np.concatenate([unc.info_delta, np.full(len(K), 1 / sigma_c**2)])
    normal = (D * w) @ D.T
    check(np.linalg.eigvalsh(normal)[0] > 0, f"{len(K)} compass reading(s): D diag(w) Dᵀ ≻ 0, a unique solution")
    check(problem.is_dpp(), "the compass problem is DPP: new readings re-solve without a rebuild")
    for trial in range(2):
        c.value = truth[K] + sigma_c * rng.standard_normal(len(K))
        solve(problem)
        closed = np.linalg.solve(normal, D @ (w * np.concatenate([reg.delta_reg, c.value])))
        err = np.abs(θ.value - closed).max()
        check(err < 1e-6, f"{len(K)} reading(s), draw {trial}: cvxpy = augmented closed form (|Δθ| = {err:.1e})")

"""Lecture 2, exercise 1 — P_θ of a chain.

For the path 0 → 1 → … → n anchored at 0, the reduced A is n × n, upper bidiagonal: column k (edge k−1 → k)
has +1 in row k and −1 in row k−1. Then Aᵀθ = (θ_k − θ_{k−1})_k, so Aᵀ is invertible and
P_θ = (A P_δ⁻¹ Aᵀ)⁻¹ = A⁻ᵀ P_δ A⁻¹. A⁻ᵀ is the summation matrix (lower triangular ones: θ_i = Σ_{k≤i} δ_k),
hence (P_θ)_ij = Σ_{k ≤ min(i,j)} σ_k²: the heading error is a random walk along the path.
"""

import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup

setup("02_phase1")

rng = np.random.default_rng(0)
n = 12
sigma = rng.uniform(0.01, 0.05, n)
info = np.zeros((n, 3, 3))
info[:, 0, 0] = info[:, 1, 1] = 1.0
info[:, 2, 2] = 1.0 / sigma**2
chain = lc.PoseGraph(n + 1, np.arange(n), np.arange(1, n + 1), np.ones((n, 2)), np.zeros(n), info)
A = lc.reduced_incidence(chain).toarray()
P_theta = np.linalg.inv((A / sigma**2) @ A.T)
cum = np.cumsum(sigma**2)
derived = cum[np.minimum.outer(np.arange(n), np.arange(n))]
check(np.abs(P_theta - derived).max() < 1e-12 * P_theta.max(), "(P_θ)_ij = Σ_{k ≤ min(i,j)} σ_k² on a chain")
check(np.allclose(np.linalg.inv(A.T), np.tril(np.ones((n, n)))), "A⁻ᵀ is the summation matrix (dead reckoning)")

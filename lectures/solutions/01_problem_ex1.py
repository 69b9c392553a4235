"""Lecture 1, exercise 1 — how far off is a factor ½?

At the true poses f = Σ eᵀP⁻¹e is a sum of 3m squared standard normals: E f = 3m, sd f = √(6m).
A factor-½ cost has E[f/2] = 3m/2, so it sits (3m − 3m/2)/√(6m) = √(3m/8) standard deviations below 3m.
√(3m/8) ≥ 3  ⟺  m ≥ 24: from 24 edges on, a wrong convention is a 3σ event on average.
"""

import math

import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.synthetic import add_noise

setup("01_problem")

m_min = math.ceil(8 * 3**2 / 3)
check(math.sqrt(3 * m_min / 8) >= 3 > math.sqrt(3 * (m_min - 1) / 8), f"the offset reaches 3σ from m = {m_min} edges on")

rng = np.random.default_rng(1)
for n_poses, n_edges in [(10, 24), (60, 120), (200, 400)]:
    world = lc.random_graph(n_poses, n_edges, seed=2)
    g = world.graph
    offsets = []
    for _ in range(300):
        meas, info = add_noise(world.truth, g.tails, g.heads, sigma_xy=0.05, sigma_theta=0.02, rng=rng)
        f = lc.chi2(lc.PoseGraph(g.n_poses, g.tails, g.heads, meas[:, :2], meas[:, 2], info), world.truth)
        offsets.append((f / 2 - 3 * n_edges) / np.sqrt(6 * n_edges))
    predicted = -np.sqrt(3 * n_edges / 8)
    # E[(f/2 − 3m)/√(6m)] = −√(3m/8) exactly; the mean of 300 draws has standard error 0.5/√300.
    check(abs(np.mean(offsets) - predicted) < 4 * 0.5 / np.sqrt(300),
          f"m = {n_edges}: mean offset of f/2 {np.mean(offsets):+.2f}σ, derived −√(3m/8) = {predicted:+.2f}σ")

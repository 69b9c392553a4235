"""Lecture 1, exercise 3 — how many minima does Gauss–Newton find?

On a small circle world, Gauss–Newton from 30 random configurations (positions in the box of the truth,
headings uniform in [−π, π)) ends in several distinct local minima at every noise level (their number does
not simply grow with the noise: with very certain headings the cost landscape is steep and the runs scatter
most); LAGO's estimate, used as a start, reaches the best minimum found.
"""

import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.refinement import refine

setup("01_problem")
rng = np.random.default_rng(0)
counts = {}
for sigma_theta in (0.01, 0.05, 0.15):
    world = lc.circle_world(16, laps=2, seed=1, sigma_xy=0.05, sigma_theta=sigma_theta)
    g = world.graph
    lo, hi = world.truth[:, :2].min(axis=0), world.truth[:, :2].max(axis=0)
    minima = []
    for _ in range(30):
        start = np.column_stack([rng.uniform(lo, hi, (g.n_poses, 2)), rng.uniform(-np.pi, np.pi, g.n_poses)])
        run = refine(g, start, max_iterations=100)
        if run.converged:
            minima.append(run.chi2)
    distinct = np.unique(np.round(np.log10(minima), 4))
    best = min(minima)
    from_lago = refine(g, lc.lago(g).poses, max_iterations=100).chi2
    counts[sigma_theta] = distinct.size
    print(f"σ_θ = {sigma_theta}: {len(minima)} of 30 runs converged, {distinct.size} distinct minima, "
          f"best {best:.3f}, worst {max(minima):.3g}; from LAGO {from_lago:.3f}")
    check(distinct.size > 1, f"σ_θ = {sigma_theta}: random starts end in {distinct.size} different minima")
    check(from_lago <= best * (1 + 1e-6), f"σ_θ = {sigma_theta}: LAGO's start reaches the best minimum found")

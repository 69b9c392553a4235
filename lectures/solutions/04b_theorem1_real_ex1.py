"""Lecture 4b, Exercise 1 — the guarded polish, by hand.

F(θ) = χ² with the positions re-solved exactly for the orientations θ (lago_cvx.positions). Keep phase 3's
θ* when F(θ*) ≤ F(θ̂); otherwise halve α from 1 (at most three times) until F(θ̂ + α(θ* − θ̂)) < F(θ̂), else
keep θ̂ (α = 0). Compared with the package's polish on CSAIL, where phase 3 overshoots (a synthetic world
when the datasets are absent).
"""

import lago_cvx as lc
from lago_cvx.positions import resolve_positions
from lago_cvx.course import check, paper_lago, real, setup

setup("04b_theorem1_real")

graph = real("se-sync/CSAIL.g2o")
if graph is None:
    graph = lc.manhattan_world(500, seed=2, sigma_xy=0.05, sigma_theta=0.03).graph

res = paper_lago(graph)                                   # phase-3 poses
theta_hat, theta_star = res.phase1.theta, res.phase3.poses[:, 2]


def F(theta):
    return lc.chi2(graph, resolve_positions(graph, theta, res.uncertainty).poses)


def guarded(theta_hat, theta_star, max_halvings=3):
    step = theta_star - theta_hat
    f_star, f_hat = F(theta_star), F(theta_hat)
    if f_star <= f_hat:
        return 1.0, f_star
    a = 1.0
    for _ in range(max_halvings):
        a /= 2
        f_a = F(theta_hat + a * step)
        if f_a < f_hat:
            return a, f_a
    return 0.0, f_hat


alpha, chi2 = guarded(theta_hat, theta_star)
pkg = paper_lago(graph, positions="resolve")
print(f"{graph.name}: χ²(phase 3) = {res.chi2:.3f}; guarded polish α = {alpha}, χ² = {chi2:.4f}")
check(alpha == pkg.polish.alpha and abs(chi2 - pkg.chi2) <= 1e-9 * pkg.chi2,
      f"my polish = the package's (α = {pkg.polish.alpha}, χ² = {pkg.chi2:.4f})")
check(chi2 <= min(res.chi2, F(theta_hat)), "never above phase 3's χ² nor F(θ̂)")

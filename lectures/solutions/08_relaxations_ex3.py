# Exercise 3 of lecture 8 — how far does the certificate's bound (B) reach?
#
# At any rotations (translations optimal) the certificate computes Λ_i and λ_min(S_Q), and
# f* ≥ Σ tr Λ_i + 2(n+1)·min(0, λ_min(S_Q)) (eq. (B)): a valid bound everywhere. At a global minimum it is
# tight (S_Q ⪰ 0, bound = f); away from one, λ_min(S_Q) < 0 and the bound is only as good as 2(n+1)|λ_min|
# allows. Measured below along the segment from raw LAGO to the certified minimum: the proven bound on f − f* is
# never below the true gap (it is valid) and stays within a small factor of it (about 2 on this world) —
# the certificate of a non-optimal point is a useful, not a loose, estimate of how far it is from optimal.
import matplotlib.pyplot as plt
import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup, show
from lago_cvx.certification import certify, optimal_translations, refine_sesync

setup("08_relaxations")
w = lc.manhattan_world(30, seed=1, sigma_theta=0.2, sigma_xy=0.2)
g = w.graph
raw = lc.lago(g).poses
best = refine_sesync(g, lc.refine(g, raw).poses)
c_best = certify(g, best.poses)
f_star = c_best.cost
check(c_best.relative_suboptimality_bound < 1e-6, "the refined point is certified: f* known to 1e-6")
alphas = np.linspace(0.0, 1.0, 11)
gaps, bounds = [], []
for a in alphas:
    th = raw[:, 2] + a * (best.poses[:, 2] - raw[:, 2])
    p = np.column_stack([optimal_translations(g, th), th])
    cert = certify(g, p, full=False)
    gaps.append(cert.cost - f_star)                      # true distance to the optimum
    bounds.append(cert.cost - cert.lower_bound)          # what the certificate proves at most
    check(cert.lower_bound <= f_star + c_best.suboptimality_bound, f"α = {a:.1f}: the bound (B) is valid")
for a, gp, b in zip(alphas, gaps, bounds):
    print(f"α = {a:.1f}: f − f* = {gp:9.4f}, proven f − f* ≤ {b:9.4f}")
fig, ax = plt.subplots(figsize=(5, 3.5))
ax.semilogy(alphas, np.maximum(gaps, 1e-12), "o-", label="true f − f*")
ax.semilogy(alphas, np.maximum(bounds, 1e-12), "s-", label="certificate's bound on f − f*")
ax.set(xlabel="α (0: raw LAGO, 1: certified minimum)", ylabel="cost above f*")
ax.legend(fontsize=8)
show(fig, "ex3_bound")
ratios = np.array(bounds[:-1]) / np.array(gaps[:-1])
print(f"proven bound / true gap along the segment: {ratios.min():.2f} … {ratios.max():.2f}")
check(ratios.min() >= 1.0 and ratios.max() < 3.0, "the bound is valid and within a factor 3 of the true gap")
check(bounds[-1] < 1e-5 * f_star, "…and vanishes at the minimum")

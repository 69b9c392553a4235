# Exercise 1 of lecture 8 — the failure probability of the tree rounding, eq. (W).
#
# Derivation. With true orientations θ, each measurement is δ_e = θ_j − θ_i + ε_e (mod 2π), ε_e ~ N(0, P_δ,e).
# Integrating δ along the tree and closing the fundamental cycle of chord c (Definition 1) gives the cycle
# residual (Cδ)_c = 2πK_c + Σ_{e∈c} ±ε_e, where K_c is the true number of turns (the true unwrapped
# orientations close the cycle exactly). Theorem 3's rounding picks k_c = −round((Cδ)_c / 2π); it equals −K_c
# iff the noise sum e_c = Σ ±ε_e lies in (−π, π]. e_c is Gaussian with variance σ_c² = Σ_{e∈c} P_δ,e = (|C| P_δ)_c
# (the noises are independent, signs do not matter), so P[wrong k_c] = P[|e_c| > π] = erfc(π / (√2 σ_c)), and the
# expected number of wrong integers along a tree is Σ_c erfc(π / (√2 σ_c)).
from dataclasses import replace

import numpy as np
from scipy.special import erfc

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.experiments import true_cycle_integers
from lago_cvx.posegraph import wrap_angle

setup("08_relaxations")
sigma, draws = 0.3, 150
w = lc.manhattan_world(300, seed=0, sigma_theta=sigma)
g = w.graph
true_rel = w.truth[g.heads, 2] - w.truth[g.tails, 2]
rng = np.random.default_rng(7)
for kind in ("odometry", "bfs"):
    tree = lc.spanning_tree(g, kind)
    sig_c = np.sqrt(abs(lc.cycle_basis(g, tree)) @ g.covariance[:, 2, 2])
    p = erfc(np.pi / (np.sqrt(2) * sig_c))
    expected, sd = p.sum(), np.sqrt(np.sum(p * (1 - p)))          # independent-chord variance (an approximation)
    counts = []
    for _ in range(draws):
        gd = replace(g, delta=wrap_angle(true_rel + sigma * rng.standard_normal(g.n_edges)))
        counts.append(int(np.count_nonzero(lc.regularize(gd, tree).k_chords != true_cycle_integers(gd, tree, w.truth))))
    mean = float(np.mean(counts))
    print(f"{kind:8s} tree: {tree.n_chords} chords, σ_c up to {sig_c.max():.2f} rad; expected wrong integers "
          f"{expected:.2f}, Monte Carlo mean {mean:.2f} over {draws} draws")
    # cycles share edges, so counts are correlated: allow 4 standard errors of the observed spread
    check(abs(mean - expected) <= 4 * max(np.std(counts), sd) / np.sqrt(draws) + 0.05,
          f"{kind} tree: (W) predicts the number of wrong integers")

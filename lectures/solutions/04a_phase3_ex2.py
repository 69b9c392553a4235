"""Lecture 4a, Exercise 2 — the springs of a single loop.

Derivation. Phase 3's multiplier gives every edge a spring force f_k = P_Δg,k⁻¹ d_k (section 1), and the
forces balance at every free pose, A₂ λ_Δ = 0. On a graph that is one cycle every pose has exactly two
edges; orient them all along the cycle (edge k from pose k to pose k+1, the last back to pose 0). The
balance at pose k+1 reads f_k − f_{k+1} = 0: the same force runs through the whole loop, one vector f.
At pose 0 it holds too (the anchor feels no net force). So the whole loop is a single tensioned ring:
the loop's misclosure is shared out among the edges in proportion to their compliance, d_k = P_Δg,k f.
"""

import numpy as np

import lago_cvx as lc
from lago_cvx.posegraph import rot2
from lago_cvx.course import S, check, paper_lago, setup

setup("04a_phase3")

rng = np.random.default_rng(7)
N = 12                                                          # poses 0 … 11 on one loop
angles = 2 * np.pi * np.arange(N) / N
truth = np.column_stack([5 * np.cos(angles), 5 * np.sin(angles), angles + np.pi / 2])
tails, heads = np.arange(N), (np.arange(N) + 1) % N             # edge k: pose k → pose k+1
rel = lc.between(truth[tails], truth[heads])
rel = rel + rng.standard_normal(rel.shape) * [0.05, 0.05, 0.02]   # noisy measurements
info = np.array([np.diag(rng.uniform([50, 50, 500], [400, 400, 3000])) for _ in range(N)])  # unequal springs
g = lc.PoseGraph(N, tails, heads, rel[:, :2], lc.posegraph.wrap_angle(rel[:, 2]), info)

res = paper_lago(g)
x = res.phase3.x_star
n = N - 1
p_s = np.vstack([[0.0, 0.0], x[:2 * n].reshape(n, 2)])
th_s = np.concatenate([[0.0], x[2 * n:]])
th_h = res.phase1.theta
dg = res.phase2.delta_g
d = p_s[heads] - p_s[tails] - dg - (dg @ S.T) * (th_s - th_h)[tails, None]     # linearised residual d_k
Rk = rot2(th_h[tails])
P_dg_inv = Rk @ np.linalg.inv(res.uncertainty.cov_delta_l) @ np.swapaxes(Rk, 1, 2)
f = np.einsum("kab,kb->ka", P_dg_inv, d)                                         # spring forces f_k

spread = np.abs(f - f.mean(0)).max() / np.linalg.norm(f, axis=1).max()
check(spread < 1e-8, f"one loop, one force: every edge carries f = {f.mean(0).round(4)} (spread {spread:.1e})")
stretch = np.linalg.norm(d, axis=1)
check(stretch.max() > 1.5 * stretch.min(), f"but the springs stretch unequally ({stretch.min():.4f} … "
      f"{stretch.max():.4f} m): the compliant ones give most")

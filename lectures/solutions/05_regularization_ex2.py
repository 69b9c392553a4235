"""Lecture 5, Exercise 2 — the paper's regularization from scratch (Theorem 3, eqs. (20)–(23)).

Integrate δ along a spanning tree from pose 0 in breadth-first order (θ_child = θ_parent ± δ_edge), take
each chord's circuit sum (C δ)_c = δ_c − (θ_j − θ_i), round it to k_c so that (C δ)_c + 2π k_c ∈ (−π, π], and
set δ_reg = δ + 2π k on the chords (the tree edges keep δ, eq. (23)). Compared with
lago_cvx.regularization.regularize, and with Table I on INTEL (odometric tree: 198 chords with k ≠ 0).
"""

from collections import deque

import numpy as np

import lago_cvx as lc
from lago_cvx.regularization import regularize
from lago_cvx.course import check, real, setup

setup("05_regularization")


def my_regularize(graph, tree_edges):
    """k (m,) and δ_reg (m,) for the spanning tree made of the edge indices ``tree_edges``."""
    n, m = graph.n_poses, graph.n_edges
    adjacency = [[] for _ in range(n)]
    for e in tree_edges:
        adjacency[graph.tails[e]].append((e, graph.heads[e], +1.0))
        adjacency[graph.heads[e]].append((e, graph.tails[e], -1.0))
    theta = np.full(n, np.nan)
    theta[0] = 0.0
    queue = deque([0])
    while queue:                                   # breadth-first walk of the tree from pose 0
        u = queue.popleft()
        for e, v, sign in adjacency[u]:
            if np.isnan(theta[v]):
                theta[v] = theta[u] + sign * graph.delta[e]
                queue.append(v)
    chords = np.setdiff1d(np.arange(m), tree_edges)
    circuit = graph.delta[chords] - (theta[graph.heads[chords]] - theta[graph.tails[chords]])   # (C δ)_c
    k = np.zeros(m, dtype=int)
    k[chords] = -np.ceil(circuit / (2 * np.pi) - 0.5).astype(int)        # residual + 2πk ∈ (−π, π]
    return k, graph.delta + 2 * np.pi * k


cases = [("Manhattan 800 poses, σ_θ = 0.05", lc.manhattan_world(800, seed=3, sigma_theta=0.05).graph),
         ("circle 120 poses, 5 laps", lc.circle_world(120, laps=5, seed=1, sigma_theta=0.02).graph)]
intel = real("carlone/INTEL_P_toro.graph")
if intel is not None:
    cases.append(("INTEL_P_toro", intel))
for name, g in cases:
    for kind in ("odometry", "bfs"):
        tree = lc.spanning_tree(g, kind)
        k, delta_reg = my_regularize(g, tree.tree_edges)
        pkg = regularize(g, tree)
        check(np.array_equal(k, pkg.k) and np.allclose(delta_reg, pkg.delta_reg, atol=1e-12),
              f"{name}, {kind} tree: my k = the package's ({np.count_nonzero(k)} chords corrected)")
        if name == "INTEL_P_toro" and kind == "odometry":
            check(np.count_nonzero(k) == 198, "Table I: 198 chords need a correction on INTEL (odometric tree)")

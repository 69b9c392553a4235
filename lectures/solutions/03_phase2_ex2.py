"""Lecture 3, exercise 2 — P_z times a vector, without P_z.

P_z v = H diag(P_Δˡ, P_θ) Hᵀ v with H = [[R, J], [0, I]]: for v = [a; b],
    Hᵀv = [Rᵀa; Jᵀa + b],   then [P_Δˡ Rᵀa; P_θ(Jᵀa + b)] = [s₁; s₂],   then H[s₁; s₂] = [R s₁ + J s₂; s₂].
P_θ x is one solve with phase 1's factorization of A P_δ⁻¹ Aᵀ: no dense matrix anywhere.
"""

import numpy as np
import scipy.sparse as sp

import lago_cvx as lc
from lago_cvx.course import check, paper_lago, real, setup
from lago_cvx.posegraph import rot2

setup("03_phase2")

graph = real("carlone/INTEL_P_toro.graph") or lc.manhattan_world(1000, seed=0).graph
res = paper_lago(graph)
m, n = graph.n_edges, graph.n_poses - 1
R = sp.block_diag(rot2(res.phase1.theta[graph.tails]), format="csr")
P_dl = sp.block_diag(res.uncertainty.cov_delta_l, format="csr")
J = res.phase2.jac
solve_theta = res.phase1.factor.solve


def pz_times(v):
    a, b = v[:2 * m], v[2 * m:]
    s1, s2 = P_dl @ (R.T @ a), solve_theta(J.T @ a + b)
    return np.concatenate([R @ s1 + J @ s2, s2])


WtW = (res.phase2.W.T @ res.phase2.W).tocsr()
rng = np.random.default_rng(0)
worst = max(np.linalg.norm(WtW @ pz_times(v) - v) / np.linalg.norm(v)
            for v in rng.standard_normal((5, 2 * m + n)))
print(graph, f"| P_z would have {(2 * m + n) ** 2:.2e} entries")
check(worst < 1e-8, f"WᵀW (P_z v) = v for 5 random v, matrix-free (worst relative error {worst:.1e})")

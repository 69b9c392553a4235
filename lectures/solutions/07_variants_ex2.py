# Exercise 2 of lecture 7 — the strain statistic of an orientation anchor from its dual value.
#
# With M = W Bᵀ the whitened design of phase 1 and column a the anchored orientation, eliminating the free
# coordinates U leaves the anchored cost as a function of the anchor's value, F(θ̄_a) = F(0) + g·φ + S·φ²,
# S = M_aᵀM_a − M_aᵀM_U(M_UᵀM_U)⁻¹M_UᵀM_a, g = ∂F/∂θ̄_a = −ν_a. Releasing the anchor minimises over φ:
# the cost drops by g²/(4S) = ν_a²/(4S), the Lagrange-multiplier statistic.
import numpy as np
import scipy.sparse.linalg as spla

import lago_cvx as lc
from lago_cvx.course import check, setup

setup("07_variants")
w = lc.manhattan_world(300, seed=3)
ids = [0, 120, 250]
res, report = lc.compare_methods(w.graph, anchors={i: tuple(w.truth[i]) for i in ids})
sys1 = res.phase1.system
K = np.flatnonzero(sys1.known)
nu = np.asarray(report["problems"]["phase1"].constraints[0].dual_value, dtype=float)
M = sys1.design()
a = w.graph.anchor_index(250)
U = ~sys1.known
MU, Ma = M[:, U], M[:, [a]]
N = (MU.T @ MU).tocsc()
b = (MU.T @ Ma).toarray().ravel()
S = float((Ma.T @ Ma).toarray()[0, 0] - b @ spla.spsolve(N, b))        # Schur complement
stat = nu[list(K).index(a)] ** 2 / (4 * S)
pkg = {s.id: s for s in res.strain}[250].chi2_theta
print(f"ν_250 = {nu[list(K).index(a)]:.4f}, S = {S:.2f}: ν²/(4S) = {stat:.6f}; package chi2_theta = {pkg:.6f}")
check(abs(stat - pkg) < 1e-6 * pkg, "ν²/(4S) from the cvxpy dual = the package's strain statistic")


def phase1_cost(known):
    """Optimal phase-1 cost with the coordinates ``known`` held at sys1.values (eq. (A2))."""
    Uk = ~known
    rhs = sys1.W @ sys1.z - M[:, known] @ sys1.values[known]
    xU = spla.lsqr(M[:, Uk], rhs, atol=1e-14, btol=1e-14, iter_lim=20000)[0]
    r = M[:, Uk] @ xU - rhs
    return float(r @ r)


released = sys1.known.copy()
released[a] = False
drop = phase1_cost(sys1.known) - phase1_cost(released)
print(f"phase-1 cost drop when anchor 250's orientation is released: {drop:.6f}")
check(abs(drop - stat) < 1e-5 * max(stat, 1e-12) + 1e-9, "…and equals the cost drop of releasing it")

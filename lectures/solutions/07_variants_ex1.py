# Exercise 1 of lecture 7 — the forces on the anchors balance.
#
# Phase 1: f(θ) = ‖W(Aᵀθ − δ_reg)‖², ∇f = 2 A W²(Aᵀθ − δ_reg). Every column of A has one −1 and one +1, so
# 1ᵀA = 0 and 1ᵀ∇f = 0 for every θ. At the optimum of (A1) the KKT conditions say ∇_U f = 0 (free poses) and
# ∇_K f + ν = 0 (anchors), hence  Σ_a ν_a = −1ᵀ∇_K f = −1ᵀ∇f = 0.  With a single anchor this forces ν = 0: one
# reference pose only fixes the gauge (lecture 6).
#
# Phase 3: the position columns of the design Bᵀ are those of Aᵀ ⊗ I₂ — every edge row holds p_j − p_i, so
# the x columns sum to zero in every row, and so do the y columns. The same argument gives Σ_a ν_x,a = 0 and
# Σ_a ν_y,a = 0: the position forces on the anchors balance component by component. (The orientation columns
# of phase 3 also carry the Jacobian J of R(θ̂_i)Δl, so no such exact balance holds for the θ part there.)
import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup

setup("07_variants")
w = lc.manhattan_world(300, seed=3)
n = w.graph.n_poses
for ids in ([0, 120, 250], [0]):
    anchors = {i: tuple(w.truth[i]) for i in ids}
    res, report = lc.compare_methods(w.graph, anchors=anchors)
    nu1 = np.asarray(report["problems"]["phase1"].constraints[0].dual_value, dtype=float)
    K3 = np.flatnonzero(res.phase3.system.known)
    nu3 = np.asarray(report["problems"]["phase3"].constraints[0].dual_value, dtype=float)
    pos = K3 < 2 * n
    nx, ny = nu3[pos & (K3 % 2 == 0)], nu3[pos & (K3 % 2 == 1)]
    scale1 = max(np.abs(nu1).max(), 1.0)
    print(f"anchors {ids}: phase-1 torques {np.round(nu1, 3)} (sum {nu1.sum():.1e}); "
          f"phase-3 forces x {np.round(nx, 2)}, y {np.round(ny, 2)}")
    check(abs(nu1.sum()) < 1e-7 * scale1, f"anchors {ids}: the phase-1 torques sum to zero")
    check(abs(nx.sum()) < 1e-6 * max(np.abs(nx).max(), 1.0) and abs(ny.sum()) < 1e-6 * max(np.abs(ny).max(), 1.0),
          f"anchors {ids}: the phase-3 position forces sum to zero, x and y separately")
    if len(ids) == 1:
        check(np.abs(nu1).max() < 1e-6 and np.abs(nu3[pos]).max() < 1e-6, "a single anchor feels no force at all")

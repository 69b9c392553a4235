# Exercise 1 of lecture 6 — the relative-relations metric of Table II needs no alignment.
#
# Derivation. For a rigid motion T = (t, φ) of the plane, T ⊕ p_i = (t + R(φ)p_i, φ + θ_i) (eq. (1)), and
# the relative pose (T ⊕ p_j) ⊖ (T ⊕ p_i) of eq. (1) has
#
#     position part     R(φ + θ_i)ᵀ[(t + R(φ)p_j) − (t + R(φ)p_i)] = R(θ_i)ᵀR(φ)ᵀR(φ)(p_j − p_i) = R(θ_i)ᵀ(p_j − p_i),
#     orientation part  (φ + θ_j) − (φ + θ_i) = θ_j − θ_i,
#
# so every relative pose p̂_j ⊖ p̂_i, hence ε_t and ε_θ, is unchanged: the metric compares the estimate with
# the truth through relative poses only. The absolute trajectory error compares positions directly and must
# first align the two frames.
import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.posegraph import between, compose, wrap_angle

setup("06_experiment")


def relation_errors(graph, poses, truth):
    est = between(poses[graph.tails], poses[graph.heads])
    ref = between(truth[graph.tails], truth[graph.heads])
    d = between(ref, est)
    return float(np.mean(np.sum(d[:, :2] ** 2, 1))), float(np.mean(wrap_angle(d[:, 2]) ** 2))


world = lc.manhattan_world(300, seed=4, sigma_theta=0.02)
est = lc.lago(world.graph, route="seed").poses
T = np.array([12.3, -4.5, 2.1])                            # a rigid motion (x, y, φ)
moved = compose(np.broadcast_to(T, est.shape), est)        # T ⊕ p_i for every pose
e0, e1 = relation_errors(world.graph, est, world.truth), relation_errors(world.graph, moved, world.truth)
print(f"ε before (ε_t, ε_θ) = ({e0[0]:.6e}, {e0[1]:.6e}), after moving the estimate: ({e1[0]:.6e}, {e1[1]:.6e})")
check(np.allclose(e0, e1, rtol=1e-9, atol=0), "ε_t and ε_θ are invariant to a rigid motion of the estimate")
a0, a1 = lc.ate(est, world.truth, align=False), lc.ate(moved, world.truth, align=False)
print(f"ATE without alignment: {a0:.3f} m before, {a1:.3f} m after")
check(a1 > 10 * a0, "the unaligned absolute trajectory error is not")
check(abs(lc.ate(est, world.truth) - lc.ate(moved, world.truth)) < 1e-9, "…until both are aligned (lc.ate default)")

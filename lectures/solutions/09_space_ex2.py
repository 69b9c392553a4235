# Exercise 2 of lecture 9 — on a tree the chordal relaxation is exact.
#
# On a spanning tree every pose is reached from the anchor by exactly one path. Compose R₀ = I,
# R_{k+1} = R_k R̃_{k,k+1} along it: every residual R_j − R_i R̃_ij of (C) is then exactly zero, whatever the noise,
# so (C) = 0 there. (C) ≥ 0, so these rotations are a minimizer — and the only one, since the tree's (N) is
# nonsingular (connected, anchored). The relaxed matrices are rotations and the projection changes nothing.
# A loop closure adds a residual that the tree's rotations do not satisfy (the noise around its cycle); (C) then
# trades it against the tree's residuals, shrinking the matrices. The costliest closures are those whose cycles
# disagree most (the anchor's distance and the cycle's length matter too): the angle of (R_i R̃_ij)ᵀ R_j, with R composed along the tree — the noise accumulated around it.
import numpy as np
from scipy.stats import spearmanr

from lago_cvx.course import check, setup
from lago_cvx.so3 import log_so3
from lago_cvx.space import chordal_closed_form
from lago_cvx.synthetic.space import sphere_world

setup("09_space")
w = sphere_world(5, 12, seed=4, sigma_t=0.05, sigma_r=0.1)
g = w.graph
odo = g.is_odometric
tree = g.subgraph_edges(odo)
ch = chordal_closed_form(tree)
composed = np.empty((g.n_poses, 3, 3))
composed[0] = np.eye(3)
for k, (i, j) in enumerate(zip(tree.tails, tree.heads)):          # the odometry in order: i = k, j = k + 1
    composed[j] = composed[i] @ tree.delta_R[k]
print(f"tree: (C) = {ch.cost:.1e}; largest |relaxed − composed| = {np.abs(ch.relaxed - composed).max():.1e}")
check(ch.cost < 1e-20 and np.abs(ch.relaxed - composed).max() < 1e-10,
      "on the odometry tree the relaxed matrices are the composed rotations, (C) = 0")
check(np.abs(ch.rotations - ch.relaxed).max() < 1e-10, "…so the projection onto SO(3) changes nothing")

closures = np.flatnonzero(~odo)
alone, disagreement = [], []
for e in closures:                                   # the tree plus this one loop closure
    mask = odo.copy()
    mask[e] = True
    c = chordal_closed_form(g.subgraph_edges(mask))
    alone.append(np.linalg.norm(c.relaxed - c.rotations, axis=(1, 2)).max())
    i, j = g.tails[e], g.heads[e]                    # the cycle's disagreement: angle of (R_i R̃_ij)ᵀ R_j on the tree
    disagreement.append(np.linalg.norm(log_so3((composed[i] @ g.delta_R[e]).T @ composed[j])))
alone, disagreement = np.array(alone), np.array(disagreement)
rho = spearmanr(alone, disagreement).correlation
worst = closures[int(np.argmax(alone))]
print(f"{len(closures)} loop closures, each alone with the tree: largest distance from SO(3) {alone.min():.2e} … "
      f"{alone.max():.2e}; the costliest is {g.tails[worst]} → {g.heads[worst]}, whose cycle disagrees by "
      f"{disagreement[np.argmax(alone)]:.3f} rad (largest: {disagreement.max():.3f}); rank correlation with the disagreement {rho:+.2f}")
check(alone.min() > 1e-4, "a single loop closure is enough to move the relaxed matrices off SO(3)")
top = np.argsort(disagreement)[-3:]
check(rho > 0.6 and int(np.argmax(alone)) in top,
      "the more a cycle disagrees, the further its loop closure moves the matrices off SO(3); the costliest "
      "closure is among the three most disagreeing cycles")

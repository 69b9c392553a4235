# Exercise 3 of lecture 7 — the Huber threshold M.
#
# Huber's loss is quadratic up to ‖r_k‖ = M and linear beyond: an edge pulls with at most 2M. For M → ∞ it
# is least squares again (every false loop closure pulls in full, plain LAGO's error); for small M every
# edge — true ones too — is in the linear regime and the fit is ℓ1-like. Measured on the world of section 6:
# the error grows steadily with M (the smallest M tested is the best, and still far from the outlier-free
# error: the bounded pulls of many false loop closures add up whatever M is). Gating only uses the convex
# estimate to classify edges, so it recovers the outlier-free LAGO over a wide range of M; at the largest M
# the convex estimate is bent enough that the classification starts to slip.
import matplotlib.pyplot as plt
import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup, show
from lago_cvx import variants as V

setup("07_variants")
wo = lc.manhattan_world(500, seed=0, outlier_fraction=0.1)
ref = lc.ate(lc.lago(wo.inlier_graph).poses, wo.truth)
Ms = [1.0, 3.0, 10.0, 30.0]
huber = [lc.ate(V.robust_lago(wo.graph, threshold=M).poses, wo.truth) / ref for M in Ms]
gated = [lc.ate(V.robust_lago(wo.graph, threshold=M, gate=V.GATE_THRESHOLD).poses, wo.truth) / ref for M in Ms]
plain = lc.ate(lc.lago(wo.graph).poses, wo.truth) / ref
for M, h, gt in zip(Ms, huber, gated):
    print(f"M = {M:5.1f}: Huber ATE {h:6.1f}× the outlier-free LAGO, Huber + gating {gt:5.2f}×")
print(f"plain LAGO: {plain:.1f}×")
fig, ax = plt.subplots(figsize=(5, 3.5))
ax.semilogx(Ms, huber, "o-", label="Huber (convex)")
ax.semilogx(Ms, gated, "s-", label="Huber, then gating")
ax.axhline(plain, color="k", ls=":", label="plain LAGO")
ax.set(xlabel="threshold M (whitened units)", ylabel="ATE / ATE without outliers", yscale="log")
ax.legend(fontsize=8)
show(fig, "ex3_threshold")
check(min(huber) > 2, "no threshold makes the convex loss reach the outlier-free error")
check(all(np.diff(huber) > 0) and huber[-1] < plain, "the error grows with M towards plain LAGO's")
check(sum(gt < 1.05 for gt in gated) >= 3, "gating recovers the outlier-free LAGO over a range of thresholds")

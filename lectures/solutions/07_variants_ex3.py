# Exercise 3 of lecture 7 — the truncation c̄² of graduated non-convexity.
#
# An inlier's whitened residual r² = eᵀΩe is χ²-distributed with 3 degrees of freedom when the measurement
# model is right, so truncating at a χ²₃ quantile (0.99 → 11.34) rejects about 1 % of the true edges at
# most (fewer: at the optimum the residuals are smaller than the noise). A tiny c̄² rejects true edges by the
# hundred (their ordinary noise is "too large") and the estimate loses constraints; a huge c̄² accepts the
# false loop closures whose error, however large, stays below it, and at the largest value tested GNC is
# plain least squares again. Measured on the world of section 6: every false loop closure is rejected from
# c̄² = 0.5 to 100, the true edges rejected fall from hundreds to none, and the error is the outlier-free
# one from the χ²₃ quantile up.
import matplotlib.pyplot as plt
import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup, show
from lago_cvx import variants as V

setup("07_variants")
wo = lc.manhattan_world(500, seed=0, outlier_fraction=0.1)
om = wo.outlier_mask
ref = lc.ate(lc.lago(wo.inlier_graph).poses, wo.truth)
plain = lc.ate(lc.lago(wo.graph).poses, wo.truth) / ref
c2s = [0.5, 2.0, V.RobustSettings().c2, 100.0, 1e4]
ratio, false_rej, true_rej = [], [], []
for c2 in c2s:
    res = lc.lago(wo.graph, robust=V.RobustSettings(threshold=c2))
    rejected = np.zeros(wo.graph.n_edges, bool)
    rejected[res.rejected_edges] = True
    ratio.append(lc.ate(res.poses, wo.truth) / ref)
    false_rej.append(int((rejected & om).sum()))
    true_rej.append(int((rejected & ~om).sum()))
    print(f"c̄² = {c2:8.2f}: ATE {ratio[-1]:6.2f}× the outlier-free LAGO, false edges rejected {false_rej[-1]} "
          f"of {om.sum()}, true edges rejected {true_rej[-1]}")
print(f"plain LAGO: {plain:.1f}×")
fig, ax = plt.subplots(figsize=(5, 3.5))
ax.semilogx(c2s, ratio, "o-", label="GNC (TLS)")
ax.axhline(plain, color="k", ls=":", label="plain LAGO")
ax.axvline(c2s[2], color="0.6", ls="--", label="χ²₃ at 0.99")
ax.set(xlabel="truncation c̄² (whitened, squared)", ylabel="ATE / ATE without outliers", yscale="log")
ax.legend(fontsize=8)
show(fig, "ex3_truncation")
check(true_rej[0] > 100 and true_rej[2] <= 0.01 * (~om).sum(), "a tiny c̄² rejects true edges by the hundred")
check(all(f == om.sum() for f in false_rej[:4]) and ratio[2] < 1.05, "from the χ²₃ quantile up to 100: every "
      "false loop closure rejected, the outlier-free error")
check(ratio[-1] > 10 and false_rej[-1] < om.sum(), "a huge c̄² accepts the false loop closures: least squares again")

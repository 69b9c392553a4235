"""Lecture 2, exercise 3 — which loop closure helps most?

With the odometric path alone (anchored at pose 0), P₀ = (A P_δ⁻¹ Aᵀ)⁻¹. Adding one edge e = e_j − e_i (in
reduced coordinates) with variance σ² is a rank-one update of the information, so by Sherman–Morrison
    tr P_new = tr P₀ − ‖P₀ e‖² / (σ² + eᵀP₀e).
For a chain eᵀP₀e = Σ σ_k² over the odometric edges between i and j: the cycle the edge closes. Long cycles
help most — but not only length counts (‖P₀e‖² also grows with the distance from the anchor).
"""

import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.uncertainty import edge_uncertainty

setup("02_phase1")

g = lc.manhattan_world(200, seed=2).graph
unc = edge_uncertainty(g)
odo = g.is_odometric
A = lc.reduced_incidence(g).toarray()
P0 = np.linalg.inv((A[:, odo] * unc.info_delta[odo]) @ A[:, odo].T)
gains, lengths, mismatch = [], [], 0.0
for k in np.flatnonzero(~odo):
    e = A[:, k]
    info = (A[:, odo] * unc.info_delta[odo]) @ A[:, odo].T + np.outer(e, e) * unc.info_delta[k]
    exact = np.trace(P0) - np.trace(np.linalg.inv(info))
    sherman_morrison = np.sum((P0 @ e) ** 2) / (unc.var_delta[k] + e @ P0 @ e)
    mismatch = max(mismatch, abs(exact - sherman_morrison) / np.trace(P0))
    gains.append(exact)
    lengths.append(abs(int(g.heads[k]) - int(g.tails[k])))
check(mismatch < 1e-9, f"for all {len(gains)} loop closures the drop of tr P_θ is the Sherman–Morrison formula")
best = int(np.argmax(gains))
ranks = lambda v: np.argsort(np.argsort(v))
correlation = np.corrcoef(ranks(np.array(lengths)), ranks(np.array(gains)))[0, 1]
print(f"best loop closure closes a cycle of {lengths[best]} odometric edges (longest: {max(lengths)}); "
      f"rank correlation of cycle length and gain: {correlation:.2f}")
check(correlation > 0.5, "longer cycles reduce tr P_θ more")

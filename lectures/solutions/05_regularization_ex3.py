"""Lecture 5, Exercise 3 — how much rotation noise can each regularizer take?

Manhattan worlds of 500 poses, 3 seeds per noise level. For the tree rounding on the odometric tree (the
paper's), on the BFS tree, and for the chordal regularizer: the number of fundamental circuits (of the BFS
tree) whose 2kπ differs from the truth, and χ² of LAGO (the paper's phases) relative to LAGO run with the
true integers. The first noise level with a wrong circuit is the regularizer's tolerance; beyond it χ² rises
above what the true integers give.
"""
import sys, pathlib; sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # lectures/

import numpy as np

import lago_cvx as lc
from lago_cvx import phases as P
from lago_cvx.uncertainty import edge_uncertainty
from _lecture import check, paper_lago, setup

setup("05_regularization")


def phases_with(graph, delta_reg):
    """The paper's phases 1–3 on given regularized orientations (no regularization step)."""
    unc = edge_uncertainty(graph)
    ph1 = P.phase1_closed_form(graph, delta_reg, unc)
    return P.phase3_closed_form(graph, P.phase2(graph, ph1.theta, unc, information="marginal")).poses


SIGMAS = [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4]
OPTIONS = {"odometric tree": dict(spanning_tree="odometry"), "BFS tree": dict(spanning_tree="bfs"),
           "chordal": dict(spanning_tree="bfs", regularization="chordal")}
rows = {k: [] for k in OPTIONS}            # per world: (σ_θ, wrong circuits, χ² / χ² with the true integers)
for sig in SIGMAS:
    for seed in range(3):
        w = lc.manhattan_world(500, seed=seed, sigma_theta=sig)
        g = w.graph
        wrap = np.rint((g.delta - (w.truth[g.heads, 2] - w.truth[g.tails, 2])) / (2 * np.pi))
        true_chi2 = lc.chi2(g, phases_with(g, g.delta - 2 * np.pi * wrap))          # the true integers
        bfs = lc.spanning_tree(g, "bfs")

        def circuit(x):                      # C x for the BFS tree's circuits, through tree path sums
            return x[bfs.chords] - bfs.path_sums(g, x)[bfs.chords]

        for label, opts in OPTIONS.items():
            r = paper_lago(g, **opts)
            n_wrong = int(np.count_nonzero(np.rint(circuit(r.regularization.delta_reg - g.delta) / (2 * np.pi))
                                           + np.rint(circuit(wrap))))
            rows[label].append((sig, n_wrong, r.chi2 / true_chi2))

print(f"{'σ_θ':>5s} " + " ".join(f"{k + ': wrong, χ²/true (3 worlds)':>44s}" for k in OPTIONS))
for i, sig in enumerate(SIGMAS):
    cells = []
    for k in OPTIONS:
        sel = rows[k][3 * i:3 * i + 3]
        cells.append(f"{sum(r[1] for r in sel):8d}, " + " ".join(f"{r[2]:9.3f}" for r in sel))
    print(f"{sig:5.2f} " + " ".join(f"{c:>44s}" for c in cells))

first = {k: min((r[0] for r in rows[k] if r[1]), default=np.inf) for k in OPTIONS}
print("first noise level with a wrong circuit:", first)
check(first["odometric tree"] <= first["BFS tree"] <= first["chordal"],
      "tolerance: odometric tree ≤ BFS tree ≤ chordal regularizer")
for label in OPTIONS:
    check(all(abs(r[2] - 1) < 1e-9 for r in rows[label] if r[1] == 0),
          f"{label}: in every world with all circuits right, LAGO = LAGO with the true integers")
worst = max(r[2] for r in rows["odometric tree"])
check(worst > 2, f"odometric tree: wrong circuits can multiply χ² (worst world {worst:.0f}×)")
wrong_worlds = [r for k in OPTIONS for r in rows[k] if r[1]]
check(all(r[2] > 1.01 for r in wrong_worlds),
      f"in all {len(wrong_worlds)} (world, regularizer) pairs with a wrong circuit, χ² is above the true integers' "
      f"(least {min(r[2] for r in wrong_worlds):.2f}×)")

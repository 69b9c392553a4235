# Exercise 2 of lecture 6 — Table I for every graph, with the odometric and the breadth-first tree.
#
# For every real graph present (and, always, a synthetic world): poses, odometric edges, loop closures, and
# the chords whose 2kπ correction is non-zero (the rounding of Theorem 3, eq. (23)) along each tree.
# Corollary 3 is checked on every file: with the odometric tree the chords are exactly the loop closures.
# What the comparison shows: on every graph here the breadth-first tree needs no more corrections than the
# odometric one (an observation, not a theorem): its paths to the root are the shortest, so a chord's
# cycle accumulates fewer of the robot's turns.
import numpy as np

import lago_cvx as lc
from lago_cvx.course import check, real, setup
from lago_cvx.datasets import DATASET_FILES

setup("06_experiment")

graphs = {"synthetic Manhattan world (500 poses)": lc.manhattan_world(500, seed=0).graph}
for rel in DATASET_FILES:
    g = real(rel)
    if g is not None:
        graphs[rel] = g
print(f"{'graph':40s} {'poses':>6s} {'odometric':>9s} {'loop cl.':>9s} {'k≠0 odometric':>14s} {'k≠0 BFS':>8s}")
for name, g in graphs.items():
    odo, bfs = lc.spanning_tree(g, "odometry"), lc.spanning_tree(g, "bfs")
    n_odo = lc.regularize(g, odo).n_regularized
    n_bfs = lc.regularize(g, bfs).n_regularized
    print(f"{name:40s} {g.n_poses:6d} {g.n_odometric:9d} {g.n_loop_closures:9d} {n_odo:14d} {n_bfs:8d}")
    check(np.array_equal(odo.chords, np.flatnonzero(~g.is_odometric)), f"{name}: Corollary 3 (chords = loop closures)")
    check(n_bfs <= n_odo, f"{name}: the BFS tree needs no more corrections ({n_bfs} ≤ {n_odo})")
    if name == "carlone/INTEL_P_toro.graph":
        check((g.n_poses, g.n_odometric, g.n_loop_closures, n_odo) == (1228, 1227, 278, 198), "INTEL: Table I")

"""Lecture 5, Exercise 1 — coordinates in the fundamental basis.

Derivation. Let T be a spanning tree with chords k and fundamental circuits c⁽ᵏ⁾ (Definition 1): c⁽ᵏ⁾ is +1 on
its chord k, 0 on every other chord, and ±1 on its tree path. For a cycle vector c (A c = 0) put
c' = c − Σ_k c_k c⁽ᵏ⁾. Then A c' = 0 and c' is zero on every chord, so c' lives on the tree edges alone. A
non-zero vector on a tree always has a pose of the tree where exactly one used edge ends — a leaf of the
support forest — and there (A c')_v = ±c'_e ≠ 0; hence c' = 0 and c = Σ_k c_k c⁽ᵏ⁾. Every cycle is a
combination of the fundamental circuits with its own chord entries as coefficients: they span the cycle
space, and being independent (the identity block of C = [I_l B]) they are a basis — Theorem 2.

Check: every fundamental circuit of the BFS tree is a cycle, so C_bfs = C_bfs[:, chords of T_odo] · C_odo.
"""

import lago_cvx as lc
from lago_cvx.course import check, real, setup

setup("05_regularization")

graphs = [("Manhattan 500 poses", lc.manhattan_world(500, seed=3).graph),
          ("circle 90 poses, 3 laps", lc.circle_world(90, laps=3, seed=1).graph)]
intel = real("carlone/INTEL_P_toro.graph")
if intel is not None:
    graphs.append(("INTEL_P_toro", intel))
for name, g in graphs:
    t_odo, t_bfs = lc.spanning_tree(g, "odometry"), lc.spanning_tree(g, "bfs")
    C_odo, C_bfs = lc.cycle_basis(g, t_odo), lc.cycle_basis(g, t_bfs)
    coords = C_bfs[:, t_odo.chords]                     # the chord entries of each BFS circuit
    err = abs(coords @ C_odo - C_bfs).max()
    check(err == 0, f"{name}: each of the {C_bfs.shape[0]} BFS circuits = Σ (its odometric-chord entries) × "
          "odometric circuits, exactly")
    # and the other way round
    check(abs(C_odo[:, t_bfs.chords] @ C_bfs - C_odo).max() == 0, f"{name}: and the odometric circuits in the BFS basis")

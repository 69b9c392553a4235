# Exercise 2 of lecture 8 — the relaxed lengths from the connection Laplacian.
#
# (C) in complex form: z_i = cos θ_i + i sin θ_i relaxed to any complex number, and
#     Σ_e ω_e |z_j − e^{iδ_e} z_i|² = ‖D z‖² = z^H L z,  D = √ω (U_heads − diag(e^{iδ}) U_tails),  L = D^H D.
# With z_a = 1 fixed, the minimiser over the others solves L_UU z_U = −L_Ua, i.e. (L z)_U = 0: z is
# proportional to L⁻¹u_a (whose U-rows of L·L⁻¹u_a vanish), normalised so that z_a = 1 — eq. (G).
# A pose ℓ on a dangling chain appears in exactly one edge towards the rest (its parent p): the term
# ω|z_ℓ − e^{iδ} z_p|² can be made zero by z_ℓ = e^{iδ} z_p, which changes nothing else — so at the optimum
# ‖r_ℓ‖ = ‖r_p‖, and by induction the whole chain keeps its attachment point's length.
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import lago_cvx as lc
from lago_cvx.course import check, setup
from lago_cvx.graph import prune_leaves
from lago_cvx.regularization.chordal import chordal_closed_form
from lago_cvx.uncertainty import edge_uncertainty

setup("08_relaxations")
w = lc.manhattan_world(300, seed=0, sigma_theta=0.05)
g = w.graph
n, m = g.n_poses, g.n_edges
omega = edge_uncertainty(g).info_delta
D = sp.csr_matrix((np.sqrt(omega), (np.arange(m), g.heads)), shape=(m, n)) \
    - sp.csr_matrix((np.sqrt(omega) * np.exp(1j * g.delta), (np.arange(m), g.tails)), shape=(m, n))
L = (D.conj().T @ D).tocsc()
for a in (0, 150):
    u = np.zeros(n, complex)
    u[a] = 1.0
    col = spla.spsolve(L, u)
    z = col / col[a]
    est = chordal_closed_form(g, omega, anchor=int(g.ids[a]))
    err = np.abs(z - (est.vectors[:, 0] + 1j * est.vectors[:, 1])).max()
    check(err < 1e-8 and abs(1 / col[a].real - est.cost) < 1e-8 * est.cost,
          f"anchor {a}: (G) holds ({err:.1e}); minimum cost 1/(L⁻¹)_aa = {est.cost:.4f}")

est = chordal_closed_form(g, omega)
pruning = prune_leaves(g)
dangling = np.setdiff1d(np.arange(n), pruning.index)
print(f"{dangling.size} poses hang on dangling chains: {dangling.tolist()}")
check(dangling.size > 0, "this world has dangling chains")
worst = 0.0
for leaf, edge, is_head in pruning.rounds:            # every peeled pose and the edge that attached it
    other = np.where(is_head, g.tails[edge], g.heads[edge])
    worst = max(worst, float(np.abs(est.norms[leaf] - est.norms[other]).max()))
check(worst < 1e-9, f"along a dangling chain every ‖r_i‖ equals its neighbour's towards the core ({worst:.1e})")

"""Lecture 4a, Exercise 1 — the information matrix of phase 3, block by block.

Derivation. Eq. (11) gives P_z = H blkdiag(P_Δl, P_θ) Hᵀ with H = (lecture 3's H) [[R, J], [0, I_n]], so
P_z⁻¹ = H⁻ᵀ blkdiag(P_Δl⁻¹, P_θ⁻¹) H⁻¹ with H⁻¹ = [[Rᵀ, −RᵀJ], [0, I_n]]. With Bᵀ = [[A₂ᵀ, 0], [0, I_n]]
(eq. (12)):

    H⁻¹Bᵀ = [[RᵀA₂ᵀ, −RᵀJ], [0, I_n]],
    B P_z⁻¹ Bᵀ = (H⁻¹Bᵀ)ᵀ blkdiag(P_Δl⁻¹, P_θ⁻¹) (H⁻¹Bᵀ)
               = [[A₂ R P_Δl⁻¹ Rᵀ A₂ᵀ,   −A₂ R P_Δl⁻¹ Rᵀ J],
                  [−Jᵀ R P_Δl⁻¹ Rᵀ A₂ᵀ,  P_θ⁻¹ + Jᵀ R P_Δl⁻¹ Rᵀ J]],

and R P_Δl⁻¹ Rᵀ = (R P_Δl Rᵀ)⁻¹ = P_Δg⁻¹ because R is orthogonal. The Schur complement of the position
block, P_θ⁻¹ + JᵀP_Δg⁻¹J − JᵀP_Δg⁻¹A₂ᵀ P_p̂ A₂P_Δg⁻¹J with P_p̂ = (A₂P_Δg⁻¹A₂ᵀ)⁻¹, is the inverse of the
orientation block of P_ρ* = (B P_z⁻¹ Bᵀ)⁻¹ (block inversion) — the P_θ* of eqs. (16)–(17).
"""

import numpy as np
import scipy.linalg as sla

import lago_cvx as lc
from lago_cvx.posegraph import rot2
from lago_cvx.course import check, paper_lago, setup

setup("04a_phase3")

g = lc.random_graph(20, 40, seed=3, sigma_xy=0.1, sigma_theta=0.05).graph
res = paper_lago(g)
n, m = g.n_poses - 1, g.n_edges

A2 = np.kron(lc.reduced_incidence(g).toarray(), np.eye(2))          # the paper's A₂ = A ⊗ I₂
R = sla.block_diag(*rot2(res.phase1.theta[g.tails]))
J = res.phase2.jac.toarray()
Pdg_inv = np.linalg.inv(R @ sla.block_diag(*res.uncertainty.cov_delta_l) @ R.T)
P_theta_inv = res.phase1.info.toarray()

blocks = np.block([[A2 @ Pdg_inv @ A2.T, -A2 @ Pdg_inv @ J],
                   [-J.T @ Pdg_inv @ A2.T, P_theta_inv + J.T @ Pdg_inv @ J]])
info = res.phase3.info.toarray()
err = np.abs(blocks - info).max() / np.abs(info).max()
check(err < 1e-9, f"B P_z⁻¹ Bᵀ has the derived blocks ({err:.1e})")

P_phat = np.linalg.inv(A2 @ Pdg_inv @ A2.T)
schur = P_theta_inv + J.T @ Pdg_inv @ J - J.T @ Pdg_inv @ A2.T @ P_phat @ A2 @ Pdg_inv @ J
P_theta_star = np.linalg.inv(info)[2 * n:, 2 * n:]
err = np.abs(np.linalg.inv(schur) - P_theta_star).max() / np.abs(P_theta_star).max()
check(err < 1e-9, f"the Schur complement of the position block is P_θ*⁻¹ ({err:.1e})")

r"""The SE-Sync cost of a planar pose graph and its quadratic form (Rosen, Carlone, Bandeira, Leonard,
*SE-Sync: A certifiably correct algorithm for synchronization over the special Euclidean group*, IJRR
38(2–3), 2019; below "SE-Sync"), specialised to d = 2 with the translations kept in the variable. Equation
labels (S1)… are this package's own, not the seed's.

The cost (SE-Sync's Problem 1, eq. (12); datasets README §4.1) — **not** χ², the cost the file means
----------------------------------------------------------------------------------------------------
For poses x_i = (t_i, θ_i), R_i = R(θ_i), and an edge i → j with measurement (t̃_ij, R̃_ij = R(δ_ij))
(``graph.delta_l``, ``graph.delta``)::

    f(x) = Σ_(i,j) [ κ_ij ‖R_j − R_i R̃_ij‖_F²  +  τ_ij ‖t_j − t_i − R_i t̃_ij‖² ]          (S1)

with **no ½**, and the weights SE-Sync's g2o reader derives from the 3×3 information Ω (order x, y, θ)::

    τ_ij = 2 / tr(Ω_tt⁻¹)   (Ω_tt = Ω[0:2, 0:2], inverted as a 2×2 matrix),   κ_ij = Ω[2, 2].   (S2)

The x–θ / y–θ cross terms of Ω are ignored. In 2-D ‖R(a) − R(b)‖_F² = 4(1 − cos(a − b)), so with
e_ij = θ_j − θ_i − δ_ij the rotation term is 4κ(1 − cos e) = 8κ sin²(e/2) ≈ 2κe².

Relation to ``lago_cvx.metrics.chi2`` (χ² = Σ eᵀΩe, e = [R_iᵀ(t_j − t_i) − t̃ ; wrap(e)]):
* translation: ‖t_j − t_i − R_i t̃‖ = ‖R_iᵀ(t_j − t_i) − t̃‖ (rotations are isometries), so the term is
  τ‖e_t‖², equal to e_tᵀΩ_tt e_t **only** when Ω_tt = τ·I (isotropic; τ is then the common value);
  otherwise τ is the harmonic mean of Ω_tt's eigenvalues and the two differ;
* rotation: 4κ(1 − cos e) ≈ 2κe², **twice** χ²'s κe² for small residuals, and bounded (≤ 8κ);
* cross terms: dropped by (S1).
Hence f* ≠ χ²* (CSAIL: f* = 31.7037, χ²* = 40.5551, g2o's χ²), and the minimisers differ slightly too.
τ and κ are unchanged by a rotation of Ω's translational block (tr((RΩ_ttRᵀ)⁻¹) = tr(Ω_tt⁻¹)), so f is the
same whichever frame the file's information is read in (``lago_cvx.conventions``).

The quadratic form — ``data_matrix``
-----------------------------------
Stack the poses in Y ∈ ℝ^{2×3n}, **per pose one translation column and two rotation columns**::

    Y = [ t_0 | R_0 | t_1 | R_1 | … ],   column 3i = t_i,   columns 3i+1, 3i+2 = R_i.               (S4)

Each term of (S1) is ‖Y a‖² with a vector or 3n×2 matrix a, so f = Σ‖Y a‖_F² = tr(Y M Yᵀ) with::

    M = Σ_(i,j) [ κ_ij A_ij A_ijᵀ + τ_ij b_ij b_ijᵀ ]   (3n × 3n, sparse, symmetric PSD),          (S5)
    A_ij = E_j − E_i R̃_ij   (3n×2; E_i selects columns 3i+1, 3i+2),
    b_ij = e_{3j} − e_{3i} − E_i t̃_ij   (3n),

i.e. per edge, on the indices (3i | 3i+1, 3i+2 | 3j | 3j+1, 3j+2):
M[t_i,t_i] = M[t_j,t_j] += τ, M[t_i,t_j] −= τ, M[t_i,R_i] += τ t̃ᵀ, M[t_j,R_i] −= τ t̃ᵀ,
M[R_i,R_i] += κI + τ t̃t̃ᵀ, M[R_j,R_j] += κI, M[R_i,R_j] −= κR̃ (and the symmetric entries).
M has nnz ≈ 9(n + 2m); the vector 1_t (ones on the translation indices) spans a null space
(the global-translation gauge: M 1_t = 0).

Also here: the multipliers Λ(Y) of eq. (S7), the certificate matrix S = M − Λ̂ of eq. (S6), its
translation-free (Schur) form S_Q, and the optimal translations for given rotations (all used by
``certificate.py`` and ``sdp.py``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..graph import _reduced_incidence
from ..sparse import factorize, solve_least_squares
from ..metrics3d import poses_of
from ..posegraph import PoseGraph, rot2, wrap_angle
from ..posegraph_base import as_graph

__all__ = ["edge_residuals", "sesync_weights", "sesync_cost", "stacked_variable", "poses_from_stacked", "data_matrix",
           "multipliers", "lambda_hat", "certificate_matrix", "reduced_certificate_matrix", "optimal_translations",
           "rotation_index", "grounded_index"]


def sesync_weights(graph: PoseGraph) -> tuple[np.ndarray, np.ndarray]:
    """SE-Sync weights of eq. (S2): ``kappa`` (m,) = Ω[2, 2] and ``tau`` (m,) = 2 / tr(Ω_tt⁻¹).

    For Ω_tt = [[a, b], [b, c]], tr(Ω_tt⁻¹) = (a + c)/(ac − b²), so τ = 2(ac − b²)/(a + c)."""
    info = graph.information
    a, b, c = info[:, 0, 0], 0.5 * (info[:, 0, 1] + info[:, 1, 0]), info[:, 1, 1]
    tau = 2.0 * (a * c - b * b) / (a + c)
    kappa = info[:, 2, 2].copy()
    return kappa, tau


def edge_residuals(graph: PoseGraph, poses: np.ndarray):
    """Translation error d = t_j − t_i − R_i t̃ (m, 2), v = R_i t̃ (m, 2) and e = wrap(θ_j − θ_i − δ) (m,)."""
    pi, pj = poses[graph.tails], poses[graph.heads]
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    tl = graph.delta_l
    v = np.column_stack([c * tl[:, 0] - s * tl[:, 1], s * tl[:, 0] + c * tl[:, 1]])
    d = pj[:, :2] - pi[:, :2] - v
    e = wrap_angle(pj[:, 2] - pi[:, 2] - graph.delta)
    return d, v, e


def sesync_cost(graph: PoseGraph, poses) -> float:
    """f(x) of eq. (S1) (no ½) for ``poses`` (n, 3): Σ τ‖t_j − t_i − R_i t̃‖² + 4κ(1 − cos e), over every edge of
    ``graph``. ``poses`` may be any result (``metrics.chi2``'s arguments: arrays, LAGO's, a refinement's, GNC's,
    SE-Sync's result); for a 3-D graph, (t, R) or a 3-D result, the value is ``space.certify.sesync_cost3d``'s."""
    graph = as_graph(graph)
    poses = poses_of(graph, poses)
    if graph.dim == 3:
        from ..space.certify import sesync_cost3d

        return sesync_cost3d(graph, *graph.check_poses(*poses))
    poses = graph.check_poses(poses)
    kappa, tau = sesync_weights(graph)
    d, _, e = edge_residuals(graph, poses)
    # 4κ(1 − cos e) = 8κ sin²(e/2): the second form keeps relative accuracy for small e
    return float(np.sum(tau * np.einsum("ka,ka->k", d, d)) + np.sum(8.0 * kappa * np.sin(0.5 * e) ** 2))


def stacked_variable(poses) -> np.ndarray:
    """Y of eq. (S4), shape (2, 3n): column 3i = t_i, columns 3i+1, 3i+2 = R(θ_i)."""
    poses = np.asarray(poses, dtype=float)
    n = poses.shape[0]
    Y = np.empty((2, n, 3))
    Y[:, :, 0] = poses[:, :2].T
    Y[:, :, 1:] = np.transpose(rot2(poses[:, 2]), (1, 0, 2))  # Y[a, i, 1 + b] = R_i[a, b]
    return Y.reshape(2, 3 * n)


def poses_from_stacked(Y) -> np.ndarray:
    """Inverse of ``stacked_variable`` for Y (2, 3n) whose rotation blocks are rotations: (n, 3) poses;
    θ_i = atan2(R_i[1, 0] − R_i[0, 1], R_i[0, 0] + R_i[1, 1]) (also the angle of the nearest rotation
    for any block, the 2-D orthogonal Procrustes solution)."""
    Y = np.asarray(Y, dtype=float)
    n = Y.shape[1] // 3
    B = Y.reshape(2, n, 3)
    R = B[:, :, 1:]  # R[a, i, b]
    theta = np.arctan2(R[1, :, 0] - R[0, :, 1], R[0, :, 0] + R[1, :, 1])
    return np.column_stack([B[0, :, 0], B[1, :, 0], theta])


def _edge_blocks(graph: PoseGraph):
    """Per-edge 6×6 blocks of M (eq. (S5)) on the local indices (t_i, R_i, t_j, R_j), shape (m, 6, 6),
    and the matching global indices (m, 6)."""
    m = graph.n_edges
    kappa, tau = sesync_weights(graph)
    Rt = rot2(graph.delta)  # (m, 2, 2)
    A = np.zeros((m, 6, 2))
    A[:, 1:3, :] = -Rt
    A[:, 4, 0] = 1.0
    A[:, 5, 1] = 1.0
    b = np.zeros((m, 6))
    b[:, 0] = -1.0
    b[:, 1:3] = -graph.delta_l
    b[:, 3] = 1.0
    blocks = (kappa[:, None, None] * np.einsum("kpa,kqa->kpq", A, A)
              + tau[:, None, None] * np.einsum("kp,kq->kpq", b, b))
    idx = np.concatenate([3 * graph.tails[:, None] + np.arange(3), 3 * graph.heads[:, None] + np.arange(3)], 1)
    return blocks, idx


def data_matrix(graph: PoseGraph) -> sp.csr_matrix:
    """M of eq. (S5), shape (3n, 3n), CSR, symmetric PSD, with f(x) = tr(Y M Yᵀ) for Y = ``stacked_variable``."""
    blocks, idx = _edge_blocks(graph)
    rows = np.broadcast_to(idx[:, :, None], blocks.shape).reshape(-1)
    cols = np.broadcast_to(idx[:, None, :], blocks.shape).reshape(-1)
    N = 3 * graph.n_poses
    M = sp.csr_matrix((blocks.reshape(-1), (rows, cols)), shape=(N, N))
    M.sum_duplicates()
    return M


def rotation_index(n: int) -> np.ndarray:
    """Indices of the rotation columns of Y, shape (n, 2): [3i+1, 3i+2]."""
    return 3 * np.arange(n)[:, None] + np.array([1, 2])


def multipliers(M: sp.spmatrix, Y: np.ndarray) -> np.ndarray:
    """Λ_i of eq. (S7), shape (n, 2, 2): sym((M Yᵀ)_{R_i} R_i) for M (3n, 3n) and Y (2, 3n)."""
    n = Y.shape[1] // 3
    rot = rotation_index(n)
    MY = np.asarray(M @ Y.T)  # (3n, 2)
    B = MY[rot]  # (n, 2, 2): rows 3i+1, 3i+2 of M Yᵀ
    R = np.transpose(Y[:, rot], (1, 0, 2))  # (n, 2, 2): R[i] = Y[:, 3i+1:3i+3]
    L = B @ R
    return 0.5 * (L + np.swapaxes(L, 1, 2))


def lambda_hat(lam: np.ndarray) -> sp.csr_matrix:
    """Λ̂ (3n, 3n): the blocks Λ_i (n, 2, 2) on the rotation indices, zeros on translations."""
    n = lam.shape[0]
    rot = rotation_index(n)
    rows = np.broadcast_to(rot[:, :, None], lam.shape).reshape(-1)
    cols = np.broadcast_to(rot[:, None, :], lam.shape).reshape(-1)
    return sp.csr_matrix((lam.reshape(-1), (rows, cols)), shape=(3 * n, 3 * n))


def certificate_matrix(graph: PoseGraph, poses) -> sp.csr_matrix:
    """S = M − Λ̂(Y) of eq. (S6), shape (3n, 3n), sparse symmetric, at ``poses`` (n, 3)."""
    Y = stacked_variable(graph.check_poses(poses))
    M = data_matrix(graph)
    return (M - lambda_hat(multipliers(M, Y))).tocsr()


def grounded_index(n: int, a: int) -> np.ndarray:
    """Indices 0 … 3n−1 without the translation index 3a of the pose of index ``a``, shape (3n−1,)."""
    return np.delete(np.arange(3 * n), 3 * a)


def _schur_solver(M: sp.spmatrix, a: int, backend: str = "auto"):
    """x ↦ L_τ⁺-type solve used by the Schur complement Q = M_RR − M_Rt L_τ⁺ M_tR: returns the
    translation indices (n,), the rotation indices (2n,) and a function solving the grounded
    Laplacian system (anchor translation removed) for right-hand sides with zero sum."""
    n = M.shape[0] // 3
    t_idx = 3 * np.arange(n)
    r_idx = rotation_index(n).reshape(-1)
    Ltt = sp.csc_matrix(M[t_idx][:, t_idx])
    keep = np.delete(np.arange(n), a)
    factor = factorize(Ltt[keep][:, keep], backend=backend)

    def solve(b: np.ndarray) -> np.ndarray:
        x = np.zeros((n,) + b.shape[1:])
        x[keep] = factor.solve(b[keep])
        return x

    return t_idx, r_idx, solve


def reduced_certificate_matrix(graph: PoseGraph, poses, *, anchor=None) -> np.ndarray:
    """S_Q = Q − blkdiag(Λ_i), **dense** (2n, 2n): SE-Sync's certificate matrix with the translations
    eliminated (Q = M_RR − M_Rt L_τ⁺ M_tR). For small graphs and cross-checks only (O(n²) memory)."""
    poses = graph.check_poses(poses)
    M = data_matrix(graph).tocsr()
    Y = stacked_variable(poses)
    t_idx, r_idx, solve = _schur_solver(M, graph.anchor_index(anchor))
    MtR = M[t_idx][:, r_idx].toarray()
    Q = M[r_idx][:, r_idx].toarray() - MtR.T @ solve(MtR)
    lam = multipliers(M, Y)
    n = graph.n_poses
    Lam = np.zeros((2 * n, 2 * n))
    ii = 2 * np.arange(n)[:, None] + np.arange(2)
    Lam[ii[:, :, None], ii[:, None, :]] = lam
    S = Q - Lam
    return 0.5 * (S + S.T)


def optimal_translations(graph: PoseGraph, theta, *, anchor=None, anchor_translation=(0.0, 0.0),
                         backend: str = "auto") -> np.ndarray:
    """Translations minimising f for fixed orientations ``theta`` (n,): the weighted linear least squares
    min Σ τ‖t_j − t_i − R(θ_i) t̃‖², i.e. L_τ t = A(τ ⊙ R(θ_i)t̃) with L_τ = A diag(τ) Aᵀ (A the n × m
    incidence matrix), solved with the anchor's translation fixed to ``anchor_translation`` by
    ``lago_cvx.sparse.linalg.solve_least_squares`` on √τ·A2ᵀ (m × (n−1)). Returns (n, 2)."""
    theta = np.asarray(theta, dtype=float)
    _, tau = sesync_weights(graph)
    v = np.einsum("kab,kb->ka", rot2(theta[graph.tails]), graph.delta_l)  # R_i t̃ (m, 2)
    t0 = np.asarray(anchor_translation, dtype=float).reshape(2)
    out = np.broadcast_to(t0, (graph.n_poses, 2)).copy()
    if graph.n_poses == 1:
        return out
    W = sp.diags(np.sqrt(tau))
    a = graph.anchor_index(anchor)
    A2t = (W @ _reduced_incidence(graph, a).T).tocsc()  # (m, n−1)
    x, _, _, _ = solve_least_squares(A2t, np.sqrt(tau)[:, None] * v, backend=backend)
    out[np.delete(np.arange(graph.n_poses), a)] += x
    return out

r"""LAGO in space with several poses known exactly (``lago3d(graph, fixed={id: (t, R), …})``).

Every stage of ``pipeline`` carries over with the known poses' unknowns moved to the right-hand side instead of the
one anchor's: the chordal relaxation (C) with the known rotations' blocks R_kᵀ, the positions (P) with the known
positions, the joint Gauss–Newton step on the other poses only; the guard is the same. The frame is the known poses'
(no anchor is put at the identity). Solved through ``linalg.solve_least_squares`` / ``linalg.factorize`` on the
sparse matrices of ``blocks.edge_matrix`` (the pose-level elimination has room for one anchor only).
"""

from __future__ import annotations

import numpy as np

from ..errors import GraphError, OptionError
from ..sparse import factorize, solve_least_squares
from ..posegraph3d import chi2_3d
from ..so3 import exp_so3, project_so3
from .blocks import block_diagonal, edge_matrix
from .chordal import rotation_weights
from .gauss_newton import jacobians, whitening
from .positions import _whitened_edges

__all__ = ["check_fixed", "chordal_fixed", "positions_fixed", "joint_step_fixed"]


def check_fixed(graph, fixed, what: str = "fixed pose") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(indices (k,), t (k, 3), R (k, 3, 3)) of ``fixed`` = {id: (t (3,), R (3, 3))}; ``OptionError`` for a value
    that is not a finite position and rotation (named ``what``), ``GraphError`` for an unknown id."""
    if not fixed:
        raise OptionError("fixed must name at least one pose: {id: (t, R)}")
    idx, ts, Rs = [], [], []
    for pid, value in fixed.items():
        try:
            t, R = (np.asarray(v, dtype=float) for v in value)
        except (TypeError, ValueError):
            raise OptionError(f"{what} {pid}: expected (t (3,), R (3, 3))") from None
        if t.shape != (3,) or R.shape != (3, 3) or not (np.isfinite(t).all() and np.isfinite(R).all()):
            raise OptionError(f"{what} {pid}: expected a finite t (3,) and R (3, 3)")
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) <= 0:
            raise OptionError(f"{what} {pid}: R is not a rotation matrix")
        idx.append(graph.index_of(pid))
        ts.append(t)
        Rs.append(R)
    idx = np.asarray(idx, np.int64)
    if np.unique(idx).size != idx.size:
        raise GraphError("a pose is fixed twice")
    return idx, np.array(ts), np.array(Rs)


def _cols(known: np.ndarray, n: int, d: int):
    mask = np.zeros(n, bool)
    mask[known] = True
    cols = (np.arange(n)[:, None] * d + np.arange(d)).reshape(n, d)
    return cols[~mask].ravel(), cols[known].ravel(), ~mask


def chordal_fixed(graph, known, R_known, *, weighting: str = "isotropic") -> np.ndarray:
    """Rotations (n, 3, 3) by (C) with the rotations of ``known`` fixed, projected onto SO(3)."""
    n, m = graph.n_poses, graph.n_edges
    A = edge_matrix(graph.tails, graph.heads, np.broadcast_to(np.eye(3), (m, 3, 3)),
                    -np.swapaxes(graph.delta_R, 1, 2), n)
    W = block_diagonal(rotation_weights(graph, weighting))
    free, kc, is_free = _cols(known, n, 3)
    R = np.empty((n, 3, 3))
    R[known] = R_known
    if free.size:
        B = -(A[:, kc] @ np.swapaxes(R_known, 1, 2).reshape(-1, 3))
        X, _, _, _ = solve_least_squares(W @ A[:, free], W @ B)
        R[is_free] = project_so3(np.swapaxes(X.reshape(-1, 3, 3), 1, 2))
    return R


def positions_fixed(graph, R, known, t_known) -> np.ndarray:
    """Positions (n, 3) by (P) at rotations R with the positions of ``known`` fixed."""
    n = graph.n_poses
    LB, Lc = _whitened_edges(graph, R)
    M = edge_matrix(graph.tails, graph.heads, LB, -LB, n)
    free, kc, is_free = _cols(known, n, 3)
    t = np.empty((n, 3))
    t[known] = t_known
    if free.size:
        x, _, _, _ = solve_least_squares(M[:, free], Lc.ravel() - M[:, kc] @ t_known.ravel())
        t[is_free] = x.reshape(-1, 3)
    return t


def joint_step_fixed(graph, t, R, known) -> np.ndarray:
    """δφ (n, 3) of the Gauss–Newton step of χ² on the poses not in ``known`` (zero at the known ones)."""
    n = graph.n_poses
    L = whitening(graph)
    e, Ji, Jj = jacobians(graph, t, R)
    free, _, is_free = _cols(known, n, 6)
    dphi = np.zeros((n, 3))
    if free.size:
        M = edge_matrix(graph.tails, graph.heads, L @ Jj, L @ Ji, n)[:, free].tocsc()
        g = M.T @ np.einsum("kij,kj->ki", L, e).ravel()
        dphi[is_free] = -factorize((M.T @ M).tocsc()).solve(g).reshape(-1, 6)[:, 3:]
    return dphi


def lago3d_fixed(graph, fixed, *, route: str, weighting: str, max_halvings: int):
    """(t, R, χ², χ²_seed, alpha, trials) of the route with the poses of ``fixed`` known (module docstring)."""
    known, t_known, R_known = check_fixed(graph, fixed)
    R = chordal_fixed(graph, known, R_known, weighting=weighting)
    t = positions_fixed(graph, R, known, t_known)
    seed = cost = chi2_3d(graph, t, R)
    alpha, trials = None, ()
    if route == "default" and graph.n_edges and known.size < graph.n_poses:
        dphi = joint_step_fixed(graph, t, R, known)
        trials, alpha = [(0.0, seed)], 1.0
        best = None
        for _ in range(max_halvings + 1):
            R2 = R @ exp_so3(alpha * dphi)
            t2 = positions_fixed(graph, R2, known, t_known)
            c = chi2_3d(graph, t2, R2)
            trials.append((alpha, c))
            if c <= seed:
                best = (t2, R2, c)
                break
            alpha *= 0.5
        if best is None:
            alpha = 0.0
        else:
            t, R, cost = best
        trials = tuple(trials)
    return t, R, cost, seed, alpha, trials

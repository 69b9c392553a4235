r"""LAGO in space with anchors, priors and linear constraints on rotations
(``lago3d(graph, anchors=, priors=, rotation_constraints=, rotations=)``).

Each stage of ``pipeline`` carries over, in closed form (sparse least squares, ``sparse.solve_least_squares``) and
as a cvxpy problem (Clarabel), the same problem both ways:

(C′) the chordal relaxation over X = [R_0ᵀ; …; R_{n−1}ᵀ] (3n × 3), min Σ_ij ‖S_ij (X_j − R̃_ijᵀ X_i)‖²_F +
     Σ_q κ_q ‖X_v − R̄_vᵀ‖²_F (rotation priors, κ_q = 3 / (2 tr Λ_q,rr⁻¹), SE-Sync's isotropic weight of
     ``chordal``) subject to X_k = R_kᵀ (known rotations: anchors, or the reference's when no rotation is known)
     and aᵀX_i = bᵀ (R_i a = b, ``space.constraints``). In closed form the constraints are eliminated:
     X = T Z + X₀ with T = blkdiag(I₃ for a free pose, N_a (3 × 2) for a constrained one, nothing for a known one)
     and X₀ = blkdiag(0, a bᵀ, R_kᵀ) — a least-squares problem in Z with three right-hand sides. Then each
     rotation is projected: onto {R a = b} by eq. (PC) where constrained (the constraint holds to rounding), onto
     SO(3) by the SVD elsewhere. With ``rotations=`` given, (C′) is skipped.
(P′) the positions at those rotations, min Σ_ij ‖L_ij(B_ij(t_j − t_i) − c_ij)‖² (``positions``, exact in the
     graph's cost) + Σ_q ‖U_q(t_v − t̄_q)‖² (position priors, U_qᵀU_q = Λ_q,tt) with known positions fixed (the
     reference's at 0 when no position is known).
(J′) the joint step: the Gauss–Newton step of χ̄² (edges and priors) on the restricted tangent steps of
     ``space.refine`` (anchors held, δφ_i ∥ a_i for a constrained pose, so the constraints keep holding), the
     rotations moved by α δφ and (P′) re-solved, α = 1, ½, … kept only when χ̄² does not increase.

The frame: the anchors' when they give a rotation and a position; otherwise the reference pose (``anchor``, or
with rotation constraints and no anchor the first constrained pose, at R₀ with R₀ a = b: every rotation with
R a = b is R₀ times a rotation about a, the freedom a global rotation about b leaves) holds what is left. When
known positions (anchors' or priors') but no known rotation fix the frame, the estimate of (C′)–(P′) without them
is first moved rigidly onto them (Kabsch; about b alone under rotation constraints), then (P′) is solved with them.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import OptionError
from ..so3 import exp_so3, project_so3
from ..sparse import solve_least_squares
from ..stacks import spd_inverse
from .blocks import block_diagonal, edge_matrix
from .chordal import rotation_weights
from .constraints import check_rotation_constraints, frame_of, null_basis, project_constrained
from .positions import _whitened_edges
from .refine import Problem3D, check_anchors3d, check_priors3d

__all__ = ["Variant3D", "chordal_constrained", "positions_with_priors", "lago3d_variant"]


class Variant3D:
    """The normalized inputs: ``anchors`` [(i, t or None, R or None)], ``priors`` [(i, t̄, R̄, U)],
    ``constraints`` (indices, a, b), ``reference`` (index) and the rotation the reference is held at, ``R0``."""

    def __init__(self, graph, *, anchors=None, priors=None, rotation_constraints=None, anchor=None):
        self.anchors = check_anchors3d(graph, anchors)
        self.priors = check_priors3d(graph, priors)
        self.constraints = (check_rotation_constraints(graph, rotation_constraints) if rotation_constraints
                            else (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))))
        ci, ca, cb = self.constraints
        if ci.size and np.linalg.matrix_rank(cb, tol=1e-9) > 1:
            raise OptionError("rotation constraints: every b must be along one world direction (R_i a_i = ±b)")
        self.known_R = {i: R for i, _, R in self.anchors if R is not None}
        self.known_t = {i: t for i, t, _ in self.anchors if t is not None}
        self.rot_priors = [p for p in self.priors if p[2] is not None]
        self.pos_priors = [p for p in self.priors if p[1] is not None]
        rot_fixed = bool(self.known_R or self.rot_priors)
        if anchor is None and ci.size and not rot_fixed:
            self.reference = int(ci[np.argmin(graph.ids[ci])])
        else:
            self.reference = graph.anchor_index(anchor)
        self.R0 = np.eye(3)
        hit = np.flatnonzero(ci == self.reference)
        if hit.size:
            k = hit[0]
            self.R0 = frame_of(cb[k])[0] @ frame_of(ca[k])[0].T
        elif ci.size and not rot_fixed:
            raise OptionError(f"anchor {graph.ids[self.reference]}: with rotation constraints and no known rotation "
                              "the frame is held at a constrained pose; name one, or leave anchor unset")
        self.hold_R = {} if rot_fixed else {self.reference: self.R0}
        self.hold_t = {} if (self.known_t or self.pos_priors) else {self.reference: np.zeros(3)}


def _substitution(n: int, fixed: dict, ci, ca, cb):
    """(T (3n × d) sparse, X₀ (3n × 3)) of X = T Z + X₀ (module docstring, (C′))."""
    X0 = np.zeros((3 * n, 3))
    cols = 0
    con = {int(i): (a, b) for i, a, b in zip(ci, ca, cb)}
    rows, cc, vals = [], [], []
    for i in range(n):
        if i in fixed:
            X0[3 * i:3 * i + 3] = fixed[i].T
            continue
        if i in con:
            a, b = con[i]
            X0[3 * i:3 * i + 3] = np.outer(a, b)
            N = null_basis(a[None])[0]
        else:
            N = np.eye(3)
        r, c = np.nonzero(np.ones_like(N))
        rows.append(3 * i + r)
        cc.append(cols + c)
        vals.append(N[r, c])
        cols += N.shape[1]
    T = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cc))), shape=(3 * n, cols)) \
        if rows else sp.csc_matrix((3 * n, 0))
    return T, X0


def chordal_constrained(graph, var: Variant3D, *, weighting: str = "isotropic", method: str = "closed_form",
                        settings=None):
    """(rotations (n, 3, 3), relaxed (n, 3, 3)) of (C′) (module docstring), in closed form or by cvxpy."""
    n, m = graph.n_poses, graph.n_edges
    A = edge_matrix(graph.tails, graph.heads, np.broadcast_to(np.eye(3), (m, 3, 3)),
                    -np.swapaxes(graph.delta_R, 1, 2), n)
    W = block_diagonal(rotation_weights(graph, weighting))
    rows_A, rows_B = [W @ A], [np.zeros((3 * m, 3))]
    for i, _, Rb, U in var.rot_priors:  # κ‖X_v − R̄ᵀ‖²
        Lam = U.T @ U
        Orr = Lam[3:, 3:] if Lam.shape[0] == 6 else Lam
        s = np.sqrt(3.0 / (2.0 * np.trace(spd_inverse(Orr[None])[0])))
        rows_A.append(sp.csc_matrix((np.full(3, s), (np.arange(3), 3 * i + np.arange(3))), shape=(3, 3 * n)))
        rows_B.append(s * Rb.T)
    Afull, Bfull = sp.vstack(rows_A, format="csc"), np.vstack(rows_B)
    fixed = {**var.known_R, **var.hold_R}
    ci, ca, cb = var.constraints
    if method == "cvxpy":
        import cvxpy as cp

        from ..solvers import named_constant, solve

        X = cp.Variable((3 * n, 3), name="X")
        cons = [X[3 * i:3 * i + 3, :] == Rk.T for i, Rk in fixed.items()]
        cons += [a @ X[3 * i:3 * i + 3, :] == b for i, a, b in zip(ci, ca, cb) if int(i) not in fixed]
        problem = cp.Problem(cp.Minimize(cp.sum_squares(named_constant(Afull, "A") @ X - named_constant(Bfull, "B"))),
                             cons)
        solve(problem, settings, what="the constrained chordal relaxation (3-D rotations)")
        Xv = np.asarray(X.value)
    else:
        T, X0 = _substitution(n, fixed, ci, ca, cb)
        Xv = X0.copy()
        if T.shape[1]:
            Z, _, _, _ = solve_least_squares((Afull @ T).tocsc(), Bfull - Afull @ X0)
            Xv += T @ Z
    relaxed = np.swapaxes(Xv.reshape(n, 3, 3), 1, 2)
    R = project_so3(relaxed)
    if ci.size:
        R[ci] = project_constrained(relaxed[ci], ca, cb)
    for i, Rk in fixed.items():
        R[i] = Rk
    return R, relaxed


def positions_with_priors(graph, R, var: Variant3D, *, method: str = "closed_form", settings=None, priors=True):
    """t (n, 3) of (P′) at rotations R (module docstring); ``priors=False`` leaves the known positions (anchors and
    priors) out and holds the reference at 0 instead: the shape to align onto them (``_align_to_known``)."""
    n = graph.n_poses
    LB, Lc = _whitened_edges(graph, R)
    rows_M, rows_b = [edge_matrix(graph.tails, graph.heads, LB, -LB, n)], [Lc.ravel()]
    known = dict(var.known_t) if priors else {}
    if priors:
        known.update(var.hold_t)
        for i, tb, _, U in var.pos_priors:
            Ut = U[:3, :3] if U.shape[0] == 3 else np.linalg.cholesky((U.T @ U)[:3, :3]).T
            rows_M.append(sp.csc_matrix((Ut.ravel(), (np.repeat(np.arange(3), 3), 3 * i + np.tile(np.arange(3), 3))),
                                        shape=(3, 3 * n)))
            rows_b.append(Ut @ tb)
    elif not known:
        known = {var.reference: np.zeros(3)}
    M, b = sp.vstack(rows_M, format="csc"), np.concatenate(rows_b)
    mask = np.zeros(n, bool)
    mask[list(known)] = True
    cols = np.arange(3 * n).reshape(n, 3)
    t = np.zeros((n, 3))
    for i, ti in known.items():
        t[i] = ti
    rhs = b - M[:, cols[mask].ravel()] @ t[mask].ravel()
    Mf = M[:, cols[~mask].ravel()]
    if method == "cvxpy":
        import cvxpy as cp

        from ..solvers import named_constant, solve

        x = cp.Variable(Mf.shape[1], name="t")
        solve(cp.Problem(cp.Minimize(cp.sum_squares(named_constant(Mf, "M") @ x - named_constant(rhs, "b")))),
              settings, what="the 3-D positions with priors")
        t[~mask] = np.asarray(x.value).reshape(-1, 3)
    else:
        x, _, _, _ = solve_least_squares(Mf.tocsc(), rhs)
        t[~mask] = x.reshape(-1, 3)
    return t


def _align_to_known(t, R, var: Variant3D):
    """(t, R) moved rigidly, G t + s and G R, so that the known positions (anchors' and priors' means) are best
    matched (Kabsch; G a rotation about b under rotation constraints)."""
    known = list(var.known_t.items()) + [(p[0], p[1]) for p in var.pos_priors]
    idx = np.array([i for i, _ in known])
    src, dst = t[idx], np.array([q for _, q in known])
    H = (src - src.mean(0)).T @ (dst - dst.mean(0))
    ci, _, cb = var.constraints
    if ci.size:  # a rotation about b: the 2-D polar factor in b's frame (as eq. (PC))
        Q = frame_of(cb[0])[0]
        K = Q.T @ H.T @ Q
        psi = np.arctan2(K[1, 0] - K[0, 1], K[0, 0] + K[1, 1])
        G = Q @ exp_so3(np.array([[0.0, 0.0, psi]]))[0] @ Q.T
    else:
        U, _, Vt = np.linalg.svd(H)
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
        G = Vt.T @ D @ U.T
    s = dst.mean(0) - G @ src.mean(0)
    return t @ G.T + s, G @ R


def lago3d_variant(graph, *, anchors=None, priors=None, rotation_constraints=None, rotations=None, anchor=None,
                   route: str = "default", method: str = "closed_form", weighting: str = "isotropic",
                   settings=None, max_halvings: int = 3):
    """(t, R, χ̄², χ̄²_seed, alpha, trials, var) of (C′) → (P′) → (J′) (module docstring)."""
    var = Variant3D(graph, anchors=anchors, priors=priors, rotation_constraints=rotation_constraints, anchor=anchor)
    ci, ca, cb = var.constraints
    if rotations is None:
        R, _ = chordal_constrained(graph, var, weighting=weighting, method=method, settings=settings)
    else:
        _, R = graph.check_poses(np.zeros((graph.n_poses, 3)), rotations)
        if ci.size:
            R[ci] = project_constrained(R[ci], ca, cb)
        for i, Rk in var.known_R.items():
            R[i] = Rk
    if (var.pos_priors or var.known_t) and not var.known_R and not var.rot_priors:
        t = positions_with_priors(graph, R, var, method=method, settings=settings, priors=False)
        t, R = _align_to_known(t, R, var)
    t = positions_with_priors(graph, R, var, method=method, settings=settings)
    prob = Problem3D(graph, t, R, reference=var.reference, anchors=var.anchors, priors=var.priors,
                     constraints=var.constraints)
    seed = cost = prob.chi2(t, R)
    alpha, trials = None, ()
    if route == "default" and graph.n_edges and prob.dim:
        xi, _ = prob.step(t, R)
        dphi = (prob.B @ xi).reshape(-1, 6)[:, 3:]
        trials, alpha = [(0.0, seed)], 1.0
        for _ in range(max_halvings + 1):
            R2 = R @ exp_so3(alpha * dphi)
            t2 = positions_with_priors(graph, R2, var, method=method, settings=settings)
            c = prob.chi2(t2, R2)
            trials.append((alpha, c))
            if c <= seed:
                t, R, cost = t2, R2, c
                break
            alpha *= 0.5
        else:
            alpha = 0.0
        trials = tuple(trials)
    return t, R, float(cost), float(seed), alpha, trials, var

r"""Linear constraints on rotations, R_i a_i = b (an axis of the pose, a_i in its own frame, along a direction b of
the world): a gravity-aligned pose (an IMU's vertical) is R_i e₃ = e₃. One form for ``lago`` and ``refine`` in space:
``rotation_constraints={id: (a, b)}`` (``gravity_aligned(ids)`` builds the common case).

The set {R ∈ SO(3) : R a = b}
==============================
With P, Q rotations such that P e₃ = a and Q e₃ = b (``frame_of``), every such R is R = Q Rot_z(ψ) Pᵀ: a circle.

* **Projection** of a 3×3 matrix M (the chordal relaxation's answer) onto it, in Frobenius norm: maximize
  tr(Rᵀ M) = tr(Rot_z(ψ)ᵀ K), K = Qᵀ M P, = cos ψ (K₀₀ + K₁₁) + sin ψ (K₁₀ − K₀₁) + K₂₂, so

      ψ = atan2(K₁₀ − K₀₁, K₀₀ + K₁₁)                                                          (PC)

  — the 2-D polar factor of K's upper 2×2 block (``project_constrained``). The SVD projection onto SO(3) would
  break R a = b (by degrees when the relaxation is not tight); this keeps it to rounding.
* **In the chordal relaxation** R a = b is linear: with x_i^k = (row k of R_i)ᵀ, x_i^k · a = b_k for k = 0, 1, 2 —
  the same constraint vector a in each of the three right-hand sides, so one null-space change of variables
  x_i^k = b_k a + N_a y_i^k (N_a (3, 2) an orthonormal basis of a⊥) serves the three (``space.variants``).
* **In a Gauss–Newton step** (right retraction R ← R Exp(δφ)): R Exp(δφ) a = b ⇔ Exp(δφ) a = a ⇔ δφ ∥ a (for
  ‖δφ‖ < π), a linear subspace of the tangent space — the constraint holds **exactly** at every iterate when δφ_i
  is restricted to span(a_i) (``space.refine``).
"""

from __future__ import annotations

import numpy as np

from ..errors import OptionError

__all__ = ["gravity_aligned", "check_rotation_constraints", "frame_of", "project_constrained", "null_basis",
           "constraint_violation"]


def gravity_aligned(ids, axis=(0.0, 0.0, 1.0)) -> dict:
    """``{id: (axis, axis)}``: the poses ``ids`` keep their ``axis`` (default z) along the world's same axis,
    R_i e₃ = e₃ — gravity-aligned orientations, free in yaw only."""
    a = np.asarray(axis, dtype=float)
    return {int(i): (a, a) for i in np.atleast_1d(ids)}


def check_rotation_constraints(graph, constraints) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(indices (k,), a (k, 3), b (k, 3)) of ``{id: (a, b)}`` with a, b normalized; ``OptionError`` for a value
    that is not a pair of finite non-zero 3-vectors or a pose constrained twice, ``GraphError`` for an unknown id."""
    if not isinstance(constraints, dict):
        raise OptionError("rotation constraints: expected {id: (a, b)}, R_id a = b (a in the pose's frame, b in the "
                          "world's; e.g. lago_cvx.space.gravity_aligned(ids))")
    idx, A, B = [], [], []
    for pid, value in constraints.items():
        try:
            a, b = (np.asarray(v, dtype=float).reshape(3) for v in value)
        except (TypeError, ValueError):
            raise OptionError(f"rotation constraint on pose {pid}: expected (a (3,), b (3,)), R a = b") from None
        na, nb = np.linalg.norm(a), np.linalg.norm(b)
        if not (np.isfinite(a).all() and np.isfinite(b).all() and na > 0 and nb > 0):
            raise OptionError(f"rotation constraint on pose {pid}: a and b must be finite and non-zero")
        idx.append(graph.index_of(pid))
        A.append(a / na)
        B.append(b / nb)
    idx = np.asarray(idx, np.int64)
    if np.unique(idx).size != idx.size:
        raise OptionError("rotation constraints: a pose is constrained twice")
    return idx, np.array(A).reshape(-1, 3), np.array(B).reshape(-1, 3)


def frame_of(v: np.ndarray) -> np.ndarray:
    """Rotations P (k, 3, 3) with P e₃ = v for unit vectors v (k, 3): the third column v, the first two an
    orthonormal basis of v⊥ (Householder-free: the axis least aligned with v, crossed)."""
    v = np.atleast_2d(v)
    e = np.eye(3)[np.argmin(np.abs(v), axis=1)]
    x = np.cross(e, v)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return np.stack([x, np.cross(v, x), v], axis=2)


def null_basis(a: np.ndarray) -> np.ndarray:
    """N_a (k, 3, 2): orthonormal bases of a⊥ for unit vectors a (k, 3)."""
    return frame_of(a)[:, :, :2]


def project_constrained(M: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The nearest R (k, 3, 3) in Frobenius norm to each M (k, 3, 3) with R ∈ SO(3) and R a = b, eq. (PC)."""
    P, Q = frame_of(a), frame_of(b)
    K = np.swapaxes(Q, 1, 2) @ M @ P
    psi = np.arctan2(K[:, 1, 0] - K[:, 0, 1], K[:, 0, 0] + K[:, 1, 1])
    c, s = np.cos(psi), np.sin(psi)
    Z = np.zeros((len(psi), 3, 3))
    Z[:, 0, 0], Z[:, 0, 1], Z[:, 1, 0], Z[:, 1, 1], Z[:, 2, 2] = c, -s, s, c, 1.0
    return Q @ Z @ np.swapaxes(P, 1, 2)


def constraint_violation(R: np.ndarray, idx: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """max_i ‖R_i a_i − b_i‖ (0 without constraints)."""
    if idx.size == 0:
        return 0.0
    return float(np.linalg.norm(np.einsum("kij,kj->ki", R[idx], a) - b, axis=1).max())

r"""Rotations and rigid motions in space: SO(3) and SE(3), vectorized over stacks.

Conventions (those of GTSAM and of the g2o files' information matrices):

* a rotation vector φ ∈ ℝ³ gives R = Exp(φ) = I + sinθ/θ [φ]× + (1 − cosθ)/θ² [φ]×², θ = ‖φ‖ (Rodrigues);
* a pose T = (R, t) maps a point x of its frame to R x + t; T_i⁻¹ T_j is pose j in the frame of i;
* a tangent vector of SE(3) is ordered **(v, φ), translation first**, like the g2o information matrices
  (GTSAM orders (φ, v); the g2o readers permute the information, which is the same thing);
* Log(T) = (V(φ)⁻¹ t, φ) with φ = Log(R) and V(φ) = I + (1 − cosθ)/θ² [φ]× + (θ − sinθ)/θ³ [φ]×² — the
  exact logarithm of SE(3), which is what GTSAM's ``BetweenFactor<Pose3>`` measures the error with.

Quaternions are (qx, qy, qz, qw), scalar last, as in g2o files.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hat", "exp_so3", "log_so3", "quat_to_rot", "rot_to_quat", "project_so3", "v_inverse", "log_se3",
           "adjoint", "right_jacobian_inverse"]


def hat(w) -> np.ndarray:
    """[w]×, the skew matrix with [w]× x = w × x: shape (..., 3, 3) for w of shape (..., 3)."""
    w = np.asarray(w, dtype=float)
    z = np.zeros(w.shape[:-1])
    x, y, c = w[..., 0], w[..., 1], w[..., 2]
    return np.stack([np.stack([z, -c, y], -1), np.stack([c, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def _angle(w, small_below: float):
    """θ² = ‖φ‖², the mask θ < ``small_below`` where Taylor terms replace the closed forms, and θ with 1 put
    where the mask holds (so the closed forms never divide by zero); φ as a float array (..., 3), the others
    shape (...)."""
    w = np.asarray(w, dtype=float)
    th2 = np.einsum("...i,...i->...", w, w)
    th = np.sqrt(th2)
    small = th < small_below
    return w, th2, small, np.where(small, 1.0, th)


def exp_so3(w) -> np.ndarray:
    """Exp(φ) by Rodrigues' formula, shape (..., 3, 3) for φ (..., 3); Taylor terms below θ = 1e-4."""
    w, th2, small, safe = _angle(w, 1e-4)
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    K = hat(w)
    return np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)


def rot_to_quat(R) -> np.ndarray:
    """Unit quaternions (qx, qy, qz, qw) with qw ≥ 0 of rotation matrices (..., 3, 3) (Shepperd's method:
    the largest of the four squared components is computed first, so it is accurate for every angle)."""
    R = np.asarray(R, dtype=float)
    shape = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    tr = R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]
    cand = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], -1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((R.shape[0], 4))
    for case in range(4):
        s = np.flatnonzero(k == case)
        if not s.size:
            continue
        r = R[s]
        if case == 0:
            w = 0.5 * np.sqrt(np.maximum(1.0 + tr[s], 0.0))
            f = 0.25 / w
            q[s] = np.stack([(r[:, 2, 1] - r[:, 1, 2]) * f, (r[:, 0, 2] - r[:, 2, 0]) * f,
                             (r[:, 1, 0] - r[:, 0, 1]) * f, w], -1)
        else:
            i = case - 1
            j, m = (i + 1) % 3, (i + 2) % 3
            v = 0.5 * np.sqrt(np.maximum(1.0 + r[:, i, i] - r[:, j, j] - r[:, m, m], 0.0))
            f = 0.25 / v
            out = np.empty((s.size, 4))
            out[:, i] = v
            out[:, j] = (r[:, j, i] + r[:, i, j]) * f
            out[:, m] = (r[:, m, i] + r[:, i, m]) * f
            out[:, 3] = (r[:, m, j] - r[:, j, m]) * f
            q[s] = out
    q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
    return q.reshape(shape + (4,))


def quat_to_rot(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) = (qx, qy, qz, qw), normalized first."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def log_so3(R) -> np.ndarray:
    """Log(R), shape (..., 3), the rotation vector of angle in [0, π]; through the quaternion
    (φ = 2 atan2(‖q_v‖, q_w) q_v/‖q_v‖), accurate near 0 and near π alike."""
    q = rot_to_quat(R)
    v, w = q[..., :3], q[..., 3]
    n = np.linalg.norm(v, axis=-1)
    small = n < 1e-8
    safe = np.where(small, 1.0, n)
    scale = np.where(small, 2.0 / np.maximum(w, 1e-300), 2.0 * np.arctan2(n, w) / safe)
    return v * scale[..., None]


def project_so3(M) -> np.ndarray:
    """The nearest rotation in Frobenius norm to each M (..., 3, 3): U diag(1, 1, det(UVᵀ)) Vᵀ from
    M = U S Vᵀ. The sign fix keeps det = +1 (a reflection is never returned); it costs the smallest
    singular value's direction when det M < 0."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float))
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def v_inverse(w) -> np.ndarray:
    """V(φ)⁻¹ = I − ½[φ]× + (1/θ²)(1 − (θ/2)cot(θ/2)) [φ]×², shape (..., 3, 3) (Taylor below θ = 1e-3)."""
    w, th2, small, safe = _angle(w, 1e-3)
    c = np.where(small, 1.0 / 12.0 + th2 / 720.0,
                 (1.0 - 0.5 * safe / np.tan(0.5 * safe)) / (safe * safe))
    K = hat(w)
    return np.eye(3) - 0.5 * K + c[..., None, None] * (K @ K)


def log_se3(R, t) -> np.ndarray:
    """Log(T) of T = (R, t) as (..., 6) = (V(φ)⁻¹ t, φ), translation first."""
    phi = log_so3(R)
    v = np.einsum("...ij,...j->...i", v_inverse(phi), np.asarray(t, dtype=float))
    return np.concatenate([v, phi], -1)


def adjoint(R, t) -> np.ndarray:
    """Ad(T) in the (v, φ) order: [[R, [t]×R], [0, R]], shape (..., 6, 6); Exp(Ad(T)ξ) = T Exp(ξ) T⁻¹."""
    R = np.asarray(R, dtype=float)
    out = np.zeros(R.shape[:-2] + (6, 6))
    out[..., :3, :3] = R
    out[..., 3:, 3:] = R
    out[..., :3, 3:] = hat(t) @ R
    return out


def _series_or(th, small, series, closed):
    """``series(θ²)`` where ``small``, else ``closed(θ)`` (evaluated at a safe θ)."""
    safe = np.where(small, 1.0, th)
    return np.where(small, series(th * th), closed(safe))


def right_jacobian_inverse(xi) -> np.ndarray:
    """J_r⁻¹(ξ) of SE(3), shape (..., 6, 6) for ξ = (ρ, φ) (..., 6): Log(Exp(ξ) Exp(δ)) = ξ + J_r⁻¹(ξ) δ + O(δ²).

    In closed form (Barfoot, *State Estimation for Robotics*, §7.1.5, with J_r(ξ) = J_l(−ξ)):
    J_r⁻¹(ξ) = [[J⁻¹, −J⁻¹ Q J⁻¹], [0, J⁻¹]], J⁻¹ = J_r⁻¹(φ) of SO(3) = I + ½[φ]× + c₁[φ]×², and
    Q = Q_l(−ρ, −φ) = ½P + a(ΦP + PΦ + ΦPΦ) + b(Φ²P + PΦ² − 3ΦPΦ) + c(ΦPΦ² + Φ²PΦ) with P = [−ρ]×,
    Φ = [−φ]×, a = (θ − sinθ)/θ³, b = (θ² + 2cosθ − 2)/(2θ⁴), c = (2θ − 3sinθ + θcosθ)/(2θ⁵); their Taylor
    series below θ = 0.1, where the closed forms cancel."""
    xi = np.asarray(xi, dtype=float)
    phi = xi[..., 3:]
    th = np.linalg.norm(phi, axis=-1)
    small = th < 0.1
    c1 = _series_or(th, small, lambda t2: 1 / 12 + t2 / 720 + t2 * t2 / 30240,
                    lambda t: 1 / (t * t) - (1 + np.cos(t)) / (2 * t * np.sin(t)))
    a = _series_or(th, small, lambda t2: 1 / 6 - t2 / 120 + t2 * t2 / 5040, lambda t: (t - np.sin(t)) / t ** 3)
    b = _series_or(th, small, lambda t2: 1 / 24 - t2 / 720 + t2 * t2 / 40320,
                   lambda t: (t * t + 2 * np.cos(t) - 2) / (2 * t ** 4))
    c = _series_or(th, small, lambda t2: 1 / 120 - t2 / 2520 + t2 * t2 / 120960,
                   lambda t: (2 * t - 3 * np.sin(t) + t * np.cos(t)) / (2 * t ** 5))
    F, P = hat(-phi), hat(-xi[..., :3])
    e = (...,) + (None, None)
    FP, PF = F @ P, P @ F
    FPF = FP @ F
    F2 = F @ F
    Q = 0.5 * P + a[e] * (FP + PF + FPF) + b[e] * (F @ FP + PF @ F - 3 * FPF) + c[e] * (FPF @ F + F @ FPF)
    Jinv = np.eye(3) - 0.5 * F + c1[e] * F2   # J_r⁻¹(φ) = I + ½[φ]× + c₁[φ]×², [φ]× = −F
    out = np.zeros(xi.shape[:-1] + (6, 6))
    out[..., :3, :3] = Jinv
    out[..., 3:, 3:] = Jinv
    out[..., :3, 3:] = -Jinv @ Q @ Jinv
    return out

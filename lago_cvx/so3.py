r"""Rotations and rigid motions in space: SO(3) and SE(3), vectorized over stacks.

Conventions (those of GTSAM and of the g2o files' information matrices):

* a rotation vector φ ∈ ℝ³ gives R = Exp(φ) = I + sinθ/θ [φ]× + (1 − cosθ)/θ² [φ]×², θ = ‖φ‖ (Rodrigues);
* a pose T = (R, t) maps a point x of its frame to R x + t; T_i⁻¹ T_j is pose j in the frame of i;
* a tangent vector of SE(3) is ordered **(v, φ), translation first**, like the g2o information matrices
  (GTSAM orders (φ, v); the g2o readers permute the information, which is the same thing);
* Log(T) = (V(φ)⁻¹ t, φ) with φ = Log(R) and V(φ) = I + (1 − cosθ)/θ² [φ]× + (θ − sinθ)/θ³ [φ]×² — the
  exact logarithm of SE(3), which is what GTSAM's ``BetweenFactor<Pose3>`` measures the error with (g2o's
  ``EDGE_SE3:QUAT`` takes the translation and the quaternion's vector part instead: ``lago_cvx.posegraph3d``).

Quaternions are (qx, qy, qz, qw), scalar last, as in g2o files.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hat", "exp_so3", "log_so3", "quat_to_rot", "rot_to_quat", "project_so3", "v_inverse", "log_se3",
           "adjoint", "right_jacobian_inverse", "entries", "matrices", "product", "transposed", "apply", "cross",
           "log_rotations", "v_inverse_entries", "v_inverse_apply", "quaternions"]


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
    return np.ascontiguousarray(_quaternions(entries(R)).T).reshape(R.shape[:-2] + (4,))


def _quaternions(E) -> np.ndarray:
    """(4, N): ``rot_to_quat`` of rotations given as ``entries``. Each of Shepperd's four formulas, then per
    rotation the one whose pivot (1 + tr R, or 1 + 2R_ii − tr R) is largest."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = E
    tr = r00 + r11 + r22
    k = np.argmax(np.stack([tr, r00, r11, r22]), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = 0.5 * np.sqrt(np.maximum(1.0 + tr, 0.0))
        x = 0.5 * np.sqrt(np.maximum(1.0 + r00 - r11 - r22, 0.0))
        y = 0.5 * np.sqrt(np.maximum(1.0 + r11 - r22 - r00, 0.0))
        z = 0.5 * np.sqrt(np.maximum(1.0 + r22 - r00 - r11, 0.0))
        fw, fx, fy, fz = 0.25 / w, 0.25 / x, 0.25 / y, 0.25 / z
        q = np.choose(k, [np.array([(r21 - r12) * fw, (r02 - r20) * fw, (r10 - r01) * fw, w]),
                          np.array([x, (r10 + r01) * fx, (r20 + r02) * fx, (r21 - r12) * fx]),
                          np.array([(r01 + r10) * fy, y, (r21 + r12) * fy, (r02 - r20) * fy]),
                          np.array([(r02 + r20) * fz, (r12 + r21) * fz, z, (r10 - r01) * fz])])
    return q * np.where(q[3] < 0, -1.0, 1.0)


def quaternions(E) -> np.ndarray:
    """(4, N): the unit quaternions (x, y, z, w), w ≥ 0, of rotations given as ``entries`` (``rot_to_quat``'s, entry
    by entry; g2o's ``EDGE_SE3:QUAT`` error takes the first three, ``lago_cvx.posegraph3d``)."""
    return _quaternions(E)


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
    R = np.asarray(R, dtype=float)
    return np.ascontiguousarray(np.array(log_rotations(entries(R))).T).reshape(R.shape[:-2] + (3,))


def log_rotations(E) -> list:
    """``log_so3`` of rotations given as ``entries``: φ as three (N,) arrays."""
    q = _quaternions(E)
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    small = n < 1e-8
    safe = np.where(small, 1.0, n)
    scale = np.where(small, 2.0 / np.maximum(q[3], 1e-300), 2.0 * np.arctan2(n, q[3]) / safe)
    return [q[0] * scale, q[1] * scale, q[2] * scale]


def project_so3(M) -> np.ndarray:
    """The nearest rotation in Frobenius norm to each M (..., 3, 3): U diag(1, 1, det(UVᵀ)) Vᵀ from the SVD
    M = U S Vᵀ. The sign fix keeps det = +1 (a reflection is never returned); it costs the smallest singular
    value's direction when det M < 0.

    Where det M > 0 that matrix is M's orthogonal polar factor, and it is computed as such: by Newton's iteration
    X ← ½(γX + (γX)⁻ᵀ), X₀ = M, with Frobenius-norm scaling γ = (‖X⁻¹‖_F/‖X‖_F)^½ while far from convergence
    (Higham, *Functions of Matrices*, 2008, chapter 8), on the nine entries of all matrices at once
    (X⁻ᵀ = cof(X)/det X), until no matrix moves by more than :data:`POLAR_TOLERANCE` (the iteration converges
    quadratically, so the last step leaves an error of its square). The SVD takes every other matrix (det M ≤ 0,
    not finite, or not converged in :data:`POLAR_ITERATIONS`), and is the reference the tests hold the iteration
    to. The same matrices to rounding, several times faster than LAPACK's SVD per matrix (``benchmarks/space.md``)."""
    M = np.asarray(M, dtype=float)
    shape = M.shape
    M = M.reshape(-1, 3, 3)
    X = entries(M)
    todo = np.isfinite(M).all(axis=(1, 2)) & (_det(X, _cofactors(X)) > 0)
    X = [[x[todo] for x in row] for row in X]
    scale = True
    with np.errstate(all="ignore"):
        for _ in range(POLAR_ITERATIONS):
            C = _cofactors(X)
            det = _det(X, C)
            g = np.sqrt(np.sqrt(_frobenius2(C)) / np.abs(det) / np.sqrt(_frobenius2(X))) if scale else 1.0
            new = [[0.5 * (g * x + c / (g * det)) for x, c in zip(xr, cr)] for xr, cr in zip(X, C)]
            moved = np.sqrt(_frobenius2([[a - b for a, b in zip(nr, xr)] for nr, xr in zip(new, X)]))
            X = new
            scale = moved.max(initial=0.0) > 1e-2
            if moved.max(initial=0.0) <= POLAR_TOLERANCE:
                break
    out = np.empty_like(M)
    done = np.flatnonzero(todo)[moved <= POLAR_TOLERANCE]
    out[done] = matrices(X)[moved <= POLAR_TOLERANCE]
    rest = np.ones(len(M), bool)
    rest[done] = False
    if rest.any():
        out[rest] = _project_svd(M[rest])
    return out.reshape(shape)


#: ``project_so3``'s Newton iteration stops once no matrix moves by more than this (Frobenius norm) …
POLAR_TOLERANCE = 1e-8
#: … or after this many steps (the matrices not converged then go to the SVD).
POLAR_ITERATIONS = 50


def _project_svd(M) -> np.ndarray:
    """``project_so3`` by the SVD, M (N, 3, 3)."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def entries(M, index=None) -> list:
    """The entries of 3×3 matrices M (N, 3, 3) (or of M[index]) as rows of contiguous (N,) arrays,
    [[M_00, M_01, M_02], …]: arithmetic on them (``product``, ``apply``, formulas entry by entry) runs over all N
    matrices at once, where NumPy's loops over (N, 3, 3) stacks pay their overhead per last axis of length 3
    (``benchmarks/space.md``). ``M`` may also be given as its (9, N) rows
    ``M.reshape(-1, 9).T`` (contiguous)."""
    M = np.asarray(M, dtype=float)
    E = M if M.ndim == 2 and M.shape[0] == 9 else np.ascontiguousarray(M.reshape(-1, 9).T)
    if index is not None:
        E = E[:, index]
    return [[E[3 * i + j] for j in range(3)] for i in range(3)]


def matrices(E) -> np.ndarray:
    """(N, 3, 3) from ``entries`` (a scalar entry is broadcast)."""
    n = max(np.size(x) for row in E for x in row)
    return np.moveaxis(np.array([[np.broadcast_to(x, (n,)) for x in row] for row in E]), -1, 0)


def product(A, B) -> list:
    """A B of matrices given as ``entries``."""
    return [[A[i][0] * B[0][j] + A[i][1] * B[1][j] + A[i][2] * B[2][j] for j in range(3)] for i in range(3)]


def transposed(A) -> list:
    """Aᵀ of matrices given as ``entries``."""
    return [[A[j][i] for j in range(3)] for i in range(3)]


def apply(A, v) -> list:
    """A v of matrices given as ``entries`` and vectors as three (N,) arrays."""
    return [A[i][0] * v[0] + A[i][1] * v[1] + A[i][2] * v[2] for i in range(3)]


def cross(a, b) -> list:
    """a × b of vectors given as three (N,) arrays."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _cofactors(X) -> list:
    """cof(X) = det(X) X⁻ᵀ: its rows are the cross products of X's rows (1 × 2, 2 × 0, 0 × 1)."""
    return [cross(X[1], X[2]), cross(X[2], X[0]), cross(X[0], X[1])]


def _det(X, C):
    """det X from its first row and its cofactors."""
    return X[0][0] * C[0][0] + X[0][1] * C[0][1] + X[0][2] * C[0][2]


def _frobenius2(X):
    """‖X‖²_F of entry-wise matrices."""
    return sum(x * x for row in X for x in row)


def v_inverse(w) -> np.ndarray:
    """V(φ)⁻¹ = I − ½[φ]× + (1/θ²)(1 − (θ/2)cot(θ/2)) [φ]×², shape (..., 3, 3) (Taylor below θ = 1e-3)."""
    w = np.asarray(w, dtype=float)
    phi = list(np.ascontiguousarray(w.reshape(-1, 3).T))
    return matrices(v_inverse_entries(phi)).reshape(w.shape[:-1] + (3, 3))


def _v_coefficient(phi):
    """(1/θ²)(1 − (θ/2)cot(θ/2)) of ``v_inverse`` for φ as three (N,) arrays."""
    th2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    small = th2 < 1e-6
    safe = np.where(small, 1.0, np.sqrt(th2))
    return np.where(small, 1.0 / 12.0 + th2 / 720.0, (1.0 - 0.5 * safe / np.tan(0.5 * safe)) / (safe * safe)), th2


def v_inverse_entries(phi) -> list:
    """``v_inverse`` as ``entries``, with [φ]×² = φφᵀ − θ²I."""
    c, th2 = _v_coefficient(phi)
    K = _hat_entries(phi)
    return [[(1.0 if i == j else 0.0) - 0.5 * K[i][j] + c * (phi[i] * phi[j] - (th2 if i == j else 0.0))
             for j in range(3)] for i in range(3)]


def v_inverse_apply(phi, t) -> list:
    """V(φ)⁻¹ t = t − ½ φ × t + c φ × (φ × t) for φ, t given as three (N,) arrays each."""
    c, _ = _v_coefficient(phi)
    u = cross(phi, t)
    uu = cross(phi, u)
    return [t[i] - 0.5 * u[i] + c * uu[i] for i in range(3)]


def log_se3(R, t) -> np.ndarray:
    """Log(T) of T = (R, t) as (..., 6) = (V(φ)⁻¹ t, φ), translation first."""
    R = np.asarray(R, dtype=float)
    t = np.asarray(t, dtype=float)
    phi = log_rotations(entries(R))
    v = v_inverse_apply(phi, list(np.ascontiguousarray(t.reshape(-1, 3).T)))
    return np.ascontiguousarray(np.array(v + phi).T).reshape(R.shape[:-2] + (6,))


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
    series below θ = 0.1, where the closed forms cancel.

    With f = −φ, p = −ρ, s = f·p, g = f × p and [a]×[b]× = b aᵀ − (a·b) I, the products of skew matrices in Q are
    outer products: ΦP = p fᵀ − sI, PΦ = f pᵀ − sI, ΦPΦ = −sΦ, Φ²P + PΦ² = f gᵀ − g fᵀ − 2θ²P,
    ΦPΦ² + Φ²PΦ = −2sΦ² and Φ² = f fᵀ − θ²I, so

        Q = (½ − 2bθ²) P + (3b − a) s Φ + a (p fᵀ + f pᵀ − 2sI) + b (f gᵀ − g fᵀ) − 2cs Φ²,

    evaluated entry by entry over all ξ at once (``entries``)."""
    xi = np.asarray(xi, dtype=float)
    shape = xi.shape[:-1]
    x = np.ascontiguousarray(xi.reshape(-1, 6).T)
    f, p = -x[3:], -x[:3]
    th2 = f[0] * f[0] + f[1] * f[1] + f[2] * f[2]
    th = np.sqrt(th2)
    small = th < 0.1
    c1 = _series_or(th, small, lambda t2: 1 / 12 + t2 / 720 + t2 * t2 / 30240,
                    lambda t: 1 / (t * t) - (1 + np.cos(t)) / (2 * t * np.sin(t)))
    a = _series_or(th, small, lambda t2: 1 / 6 - t2 / 120 + t2 * t2 / 5040, lambda t: (t - np.sin(t)) / t ** 3)
    b = _series_or(th, small, lambda t2: 1 / 24 - t2 / 720 + t2 * t2 / 40320,
                   lambda t: (t * t + 2 * np.cos(t) - 2) / (2 * t ** 4))
    c = _series_or(th, small, lambda t2: 1 / 120 - t2 / 2520 + t2 * t2 / 120960,
                   lambda t: (2 * t - 3 * np.sin(t) + t * np.cos(t)) / (2 * t ** 5))
    s = f[0] * p[0] + f[1] * p[1] + f[2] * p[2]
    g = cross(f, p)
    Phi, P = _hat_entries(f), _hat_entries(p)
    Phi2 = [[f[i] * f[j] - (th2 if i == j else 0.0) for j in range(3)] for i in range(3)]
    alpha, beta, two_as, two_cs = 0.5 - 2 * b * th2, (3 * b - a) * s, 2 * a * s, 2 * c * s
    Q = [[alpha * P[i][j] + beta * Phi[i][j] + a * (p[i] * f[j] + f[i] * p[j]) + b * (f[i] * g[j] - g[i] * f[j])
          - two_cs * Phi2[i][j] - (two_as if i == j else 0.0) for j in range(3)] for i in range(3)]
    Jinv = [[(1.0 if i == j else 0.0) - 0.5 * Phi[i][j] + c1 * Phi2[i][j] for j in range(3)] for i in range(3)]
    J = matrices(Jinv)
    out = np.zeros((J.shape[0], 6, 6))
    out[:, :3, :3] = J
    out[:, 3:, 3:] = J
    out[:, :3, 3:] = -matrices(product(product(Jinv, Q), Jinv))
    return out.reshape(shape + (6, 6))


def _hat_entries(w) -> list:
    """[w]× as entries (``entries``) of w given as three (N,) arrays."""
    return [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]

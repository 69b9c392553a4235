"""The immutable planar pose graph (the seed's Section III).

A pose graph has ``n_poses`` poses ``(x, y, θ)`` and ``n_edges`` edges. Edge ``k`` goes from its
*tail* ``i = tails[k]`` to its *head* ``j = heads[k]`` and carries the measurement of pose ``j`` in the
frame of pose ``i``:

* ``delta_l[k]`` — Δˡ_ij, relative position of j in the frame of i, shape ``(2,)``;
* ``delta[k]``   — δ_ij, relative orientation θ_j − θ_i, a scalar (radians, not wrapped);
* ``information[k]`` — the 3×3 information matrix Ω_ij of the error
  ``e = [R_iᵀ(p_j − p_i) − Δˡ_ij ; θ_j − θ_i − δ_ij]`` (order x, y, θ; translational block in the
  frame of the tail i — the g2o convention; TORO files are converted on reading, see ``lago_cvx.io``).

Everything is stored as NumPy arrays (never per-edge Python objects) and made read-only, so a
``PoseGraph`` can be shared freely; "modifying" methods return a new graph.

Poses are indexed ``0 … n_poses−1``; ``ids`` keeps the identifiers used in the file (for writing
back and for messages). ``initial`` is the optional initial guess read from vertex lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .sparse import row_blocks, spd_inverse
from .errors import GraphError, OptionError
from .posegraph_base import PoseGraphBase, pose_ids, readonly

__all__ = ["PoseGraph", "wrap_angle", "rot2", "compose", "between", "is_spd"]


def wrap_angle(a):
    """Wrap angle(s) to [−π, π)."""
    a = np.asarray(a, dtype=float)
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def rot2(theta):
    """Rotation matrices R(θ), shape ``(..., 2, 2)`` for θ of shape ``(...)``."""
    theta = np.asarray(theta, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def compose(a, b):
    """Pose compounding a ⊕ b (the seed's eq. (1)), for arrays of shape ``(..., 3)``."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, a[..., 2] + b[..., 2]], -1)


def between(a, b):
    """Relative pose ⊖a ⊕ b: pose b in the frame of a (θ not wrapped), shapes ``(..., 3)``."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx = b[..., 0] - a[..., 0]
    dy = b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, b[..., 2] - a[..., 2]], -1)


@dataclass(frozen=True, eq=False, repr=False)
class PoseGraph(PoseGraphBase):
    """Immutable planar pose graph. See the module docstring for the conventions.

    Shapes: ``tails, heads`` (m,) int64 pose indices; ``delta_l`` (m, 2); ``delta`` (m,);
    ``information`` (m, 3, 3) symmetric positive definite; ``initial`` (n, 3) or None;
    ``ids`` (n,) int64 file identifiers (default ``arange(n)``).
    """

    delta_l: np.ndarray
    delta: np.ndarray
    information: np.ndarray
    initial: np.ndarray | None = None
    ids: np.ndarray | None = None
    name: str = field(default="")

    MEASUREMENTS = (("delta_l", (2,)), ("delta", ()), ("information", (3, 3)))  # class attribute (PoseGraphBase)

    def __post_init__(self):
        n, tails, heads, (delta_l, delta, info) = self._checked_edges()
        if not (np.isfinite(delta_l).all() and np.isfinite(delta).all() and np.isfinite(info).all()):
            bad = ~(np.isfinite(delta_l).all(1) & np.isfinite(delta) & np.isfinite(info).all((1, 2)))
            raise GraphError(f"non-finite measurement or information in edge(s) {np.flatnonzero(bad)[:5].tolist()}")
        bad = np.flatnonzero(~is_spd(info))
        if bad.size:
            raise GraphError(
                f"information matrix of edge(s) {bad[:5].tolist()} is not symmetric positive definite")
        initial = self.initial
        if initial is not None:
            initial = np.asarray(initial, dtype=float)
            if initial.shape != (n, 3):
                raise GraphError(f"initial poses must have shape ({n}, 3), got {initial.shape}")
            if not np.isfinite(initial).all():
                raise GraphError("initial poses must be finite")
            initial = readonly(initial)
        ids = pose_ids(n, self.ids)
        self._store_readonly(tails=tails, heads=heads, delta_l=delta_l, delta=delta, information=info, ids=ids)
        object.__setattr__(self, "initial", initial)

    # ----------------------------------------------------------------- sizes
    @property
    def dim(self) -> int:
        """2: the poses are planar (``lago_cvx.posegraph3d.PoseGraph3D.dim`` is 3)."""
        return 2

    @property
    def measurements(self) -> np.ndarray:
        """All measurements as an (m, 3) array ``[Δˡ_x, Δˡ_y, δ]``."""
        return np.column_stack([self.delta_l, self.delta])

    def check_poses(self, poses) -> np.ndarray:
        """``poses`` as a new float array of shape (n, 3); ``OptionError`` (a ValueError) if the shape is
        wrong or a value is not finite."""
        poses = np.array(poses, dtype=float)
        if poses.shape != (self.n_poses, 3):
            raise OptionError(f"poses must have shape ({self.n_poses}, 3), got {poses.shape}")
        if not np.isfinite(poses).all():
            raise OptionError("poses must be finite")
        return poses

    # ------------------------------------------------------------ covariances
    @property
    def covariance(self) -> np.ndarray:
        """Per-edge covariance Ω⁻¹, shape (m, 3, 3) (closed form, ``lago_cvx.sparse.smallmat``)."""
        return spd_inverse(self.information)

    def delta_variance(self, edges=None) -> np.ndarray:
        """P_δ = (Ω⁻¹)[2, 2] of the edges ``edges`` (indices, default all), shape (len(edges),): the same
        numbers as ``covariance[edges, 2, 2]``, a block of edges at a time (``arrays.row_blocks``)."""
        idx = np.arange(self.n_edges) if edges is None else np.asarray(edges, np.int64)
        out = np.empty(idx.size)
        for k in row_blocks(idx.size):
            out[k] = spd_inverse(self.information[idx[k]])[:, 2, 2]
        return out

    # ------------------------------------------------------------ derivations
    def with_initial(self, poses) -> "PoseGraph":
        """A copy with ``initial`` replaced (``poses`` of shape (n, 3) or None)."""
        return replace(self, initial=None if poses is None else np.asarray(poses, dtype=float))

    def reversed_edges(self, mask) -> "PoseGraph":
        """A copy where the edges selected by ``mask`` (bool (m,) or indices) are reversed.

        Reversing i→j with measurement t = (Δˡ, δ) gives j→i with measurement ⊖t = (−R(δ)ᵀΔˡ, −δ).
        To first order the reversed error is e' = −M e with M = [[R(δ)ᵀ, −R(δ)ᵀSΔˡ], [0, 1]],
        S = [[0, −1], [1, 0]], so the information that keeps eᵀΩe unchanged is Ω' = Tᵀ Ω T with
        T = M⁻¹ = [[R(δ), SΔˡ], [0, 1]] (the SE(2) adjoint of the measurement).
        """
        sel = np.zeros(self.n_edges, bool)
        sel[mask] = True
        tails = np.where(sel, self.heads, self.tails)
        heads = np.where(sel, self.tails, self.heads)
        meas = self.measurements
        inv = between(meas, np.zeros(3))  # ⊖t
        meas = np.where(sel[:, None], inv, meas)
        T = np.zeros((self.n_edges, 3, 3))
        T[:, :2, :2] = rot2(self.delta)
        T[:, 0, 2] = -self.delta_l[:, 1]
        T[:, 1, 2] = self.delta_l[:, 0]
        T[:, 2, 2] = 1.0
        info_rev = np.swapaxes(T, 1, 2) @ self.information @ T
        info = np.where(sel[:, None, None], 0.5 * (info_rev + np.swapaxes(info_rev, 1, 2)), self.information)
        return replace(self, tails=tails, heads=heads, delta_l=meas[:, :2], delta=meas[:, 2], information=info)

    def equals(self, other: "PoseGraph", *, rtol: float = 0.0, atol: float = 0.0) -> bool:
        """Same poses, ids, edges and (within tolerance) measurements, information and initial guess."""
        if (self.n_poses != other.n_poses or self.n_edges != other.n_edges
                or not np.array_equal(self.ids, other.ids)
                or not np.array_equal(self.tails, other.tails) or not np.array_equal(self.heads, other.heads)):
            return False
        if (self.initial is None) != (other.initial is None):
            return False
        pairs = [(self.delta_l, other.delta_l), (self.delta, other.delta), (self.information, other.information)]
        if self.initial is not None:
            pairs.append((self.initial, other.initial))
        return all(np.allclose(a, b, rtol=rtol, atol=atol) for a, b in pairs)


def is_spd(info: np.ndarray, *, rtol: float = 1e-9) -> np.ndarray:
    """Boolean (m,): each 3×3 matrix in ``info`` (m, 3, 3) is symmetric (to ``rtol`` of its largest
    entry) and positive definite (Cholesky succeeds on its symmetric part). Vectorized.

    Sylvester's criterion on the symmetric part S: the leading principal minors S₀₀, the 2×2 minor and
    det S are positive (and finite). det S is expanded by cofactors where that cannot change its sign
    against LAPACK's LU determinant — entries within 1e±50 and |det S| above 1e-10·max|Ω|³, far beyond
    the rounding of either (≈ 1e-14·max|Ω|³) — and taken from ``np.linalg.det`` for the other rows
    (nearly singular, extreme or non-finite), so the answer is LAPACK's throughout, at a fraction of
    its cost. Rows are processed in cache-sized blocks."""
    info = np.asarray(info, dtype=float)
    m = info.shape[0]
    out = np.empty(m, bool)
    block = 1 << 14
    for start in range(0, m, block):
        out[start:start + block] = _is_spd_block(info[start:start + block], rtol)
    return out


def _is_spd_block(info: np.ndarray, rtol: float) -> np.ndarray:
    m = info.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):  # absurd magnitudes (1e308) → not PD, no warning
        a0, a1, a2, a3, a4, a5, a6, a7, a8 = cols = np.ascontiguousarray(info.reshape(m, 9).T)
        scale = np.abs(a0)
        for x in cols[1:]:
            np.maximum(scale, np.abs(x), out=scale)  # NaN propagates, as in max()
        asym = np.abs(a1 - a3)
        for x, y in ((a2, a6), (a5, a7), (a0, a0), (a4, a4), (a8, a8)):  # x − x: NaN for a non-finite x
            np.maximum(asym, np.abs(x - y), out=asym)
        sym = asym <= rtol * np.maximum(scale, 1e-300)
        s00, s11, s22 = 0.5 * (a0 + a0), 0.5 * (a4 + a4), 0.5 * (a8 + a8)
        s01, s02, s12 = 0.5 * (a1 + a3), 0.5 * (a2 + a6), 0.5 * (a5 + a7)
        d2 = s00 * s11 - s01 * s01
        d3 = s00 * (s11 * s22 - s12 * s12) - s01 * (s01 * s22 - s12 * s02) + s02 * (s01 * s12 - s11 * s02)
        finite = np.isfinite(d2)
        for x in (s00, s11, s22, s01, s02, s12):
            finite &= np.isfinite(x)
        sure = (scale > 1e-50) & (scale < 1e50) & (np.abs(d3) > 1e-10 * scale ** 3)
        redo = np.flatnonzero(~sure)
        if redo.size:
            r = info[redo]
            d3[redo] = np.linalg.det(0.5 * (r + np.swapaxes(r, 1, 2)))
        finite &= np.isfinite(d3)
        pd = (s00 > 0) & (d2 > 0) & (d3 > 0)
    return sym & pd & finite

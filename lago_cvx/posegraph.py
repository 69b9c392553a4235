"""The immutable planar pose graph (the seed's Section III).

A pose graph has ``n_poses`` poses ``(x, y, θ)`` and ``n_edges`` edges. Edge ``k`` goes from its
*tail* ``i = tails[k]`` to its *head* ``j = heads[k]`` and carries the measurement of pose ``j`` in the
frame of pose ``i``:

* ``delta_l[k]`` — Δˡ_ij, relative position of j in the frame of i, shape ``(2,)``;
* ``delta[k]``   — δ_ij, relative orientation θ_j − θ_i, a scalar (radians, not wrapped);
* ``information[k]`` — the 3×3 information matrix Ω_ij of the seed's error, eq. (3),
  ``e = [R_iᵀ(p_j − p_i) − Δˡ_ij ; θ_j − θ_i − δ_ij]`` (order x, y, θ; translational block in the
  frame of the tail i): the matrix every equation of LAGO weighs.

The cost a graph means (``cost``, ``lago_cvx.conventions``)
------------------------------------------------------------
``cost`` names the error its edges were given for: ``"paper"`` (eq. (3); TORO files, and the default of a
graph built in Python), ``"g2o"`` (g2o files) or ``"gtsam"``. A file's information Ω_f is written for its
cost's error, and the two planar frames are related exactly:

* g2o's error is e_g2o = blkdiag(R(δ)ᵀ, 1)·e (its translation is t2v(Z⁻¹X_i⁻¹X_j)'s, in the measurement's
  frame), so e_g2oᵀ Ω_f e_g2o = eᵀ (T Ω_f Tᵀ) e with T = blkdiag(R(δ), 1): a g2o graph's ``information`` is
  T Ω_f Tᵀ (:func:`to_tail_frame`), and eq. (3) with it **is** g2o's χ², at every pose — LAGO, the refinement
  and χ² need nothing else. This is where the frame changes, once, on reading (``lago_cvx.io``) or in
  :meth:`PoseGraph.with_cost`.
* GTSAM's error is Log(Z⁻¹X_i⁻¹X_j) = [V(ε)⁻¹ R(δ)ᵀ e_t ; ε], ε = wrap(θ_j − θ_i − δ), V the SE(2) left
  Jacobian (:func:`se2_v_inverse`); R(δ) and V(ε)⁻¹ commute, so with the same T Ω_f Tᵀ its χ² is
  Σ ẽᵀ Ω ẽ, ẽ = [V(ε)⁻¹ e_t ; ε] (``lago_cvx.metrics.edge_errors``). To first order (ε → 0) it is g2o's.
* ``given_information`` keeps Ω_f as given when it differs from ``information`` (g2o, gtsam), so that a
  written file reproduces the input bit for bit; None otherwise.

Everything is stored as NumPy arrays (never per-edge Python objects) and made read-only, so a
``PoseGraph`` can be shared freely; "modifying" methods return a new graph.

Poses are indexed ``0 … n_poses−1``; ``ids`` keeps the identifiers used in the file (for writing
back and for messages). ``initial`` is the optional initial guess read from vertex lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .stacks import row_blocks, spd_inverse
from .conventions import check_cost
from .errors import GraphError, OptionError
from .posegraph_base import PoseGraphBase, pose_ids, readonly

__all__ = ["PoseGraph", "wrap_angle", "rot2", "compose", "between", "is_spd", "to_tail_frame",
           "to_measurement_frame", "se2_v_inverse", "logmap_translation", "COST_FRAME"]

#: The frame of the translational residual each cost's information is written in.
COST_FRAME = {"paper": "tail", "g2o": "measurement", "gtsam": "measurement"}


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


def _frame_change(info: np.ndarray, delta: np.ndarray, forward: bool) -> np.ndarray:
    """T Ω Tᵀ (``forward``) or Tᵀ Ω T, T = blkdiag(R(δ), 1), for (m, 3, 3) stacks; exactly symmetric. Edges
    whose translational block is isotropic (Ω_xx = Ω_yy, Ω_xy = Ω_xθ = Ω_yθ = 0) are the same in both frames
    and are kept bit for bit."""
    info = np.asarray(info, dtype=float)
    delta = np.asarray(delta, dtype=float)
    iso = ((info[:, 0, 0] == info[:, 1, 1]) & (info[:, 0, 1] == 0) & (info[:, 1, 0] == 0) & (info[:, 0, 2] == 0)
           & (info[:, 1, 2] == 0) & (info[:, 2, 0] == 0) & (info[:, 2, 1] == 0))
    out = info.copy()
    k = np.flatnonzero(~iso)
    if k.size:
        T = np.zeros((k.size, 3, 3))
        T[:, :2, :2] = rot2(delta[k])
        T[:, 2, 2] = 1.0
        Tt = np.swapaxes(T, 1, 2)
        with np.errstate(over="ignore", invalid="ignore"):  # overflow: reported by the graph's checks
            r = T @ info[k] @ Tt if forward else Tt @ info[k] @ T
        out[k] = 0.5 * (r + np.swapaxes(r, 1, 2))
    return out


def to_tail_frame(info_measurement: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Ω = T Ω_f Tᵀ, T = blkdiag(R(δ), 1): information written for g2o's error (translation in the
    measurement's frame) as the information of eq. (3) (translation in the tail's frame), shapes (m, 3, 3),
    (m,) → (m, 3, 3); the same cost at every pose (module docstring)."""
    return _frame_change(info_measurement, delta, True)


def to_measurement_frame(info_tail: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """The inverse of :func:`to_tail_frame`: Ω_f = Tᵀ Ω T."""
    return _frame_change(info_tail, delta, False)


def se2_v_inverse(eps):
    """(α, β, α′) of V(ε)⁻¹ = α I + β J, J = [[0, 1], [−1, 0]], the inverse of SE(2)'s left Jacobian, with
    α = (ε/2)·cot(ε/2), β = ε/2 and α′ = dα/dε = ½cot(ε/2) − (ε/4)/sin²(ε/2) (β′ = ½): GTSAM's
    ``Pose2::Logmap`` translation is V(ε)⁻¹ t. Shapes follow ``eps``; Taylor series below |ε| = 0.01
    (α = 1 − ε²/12 − ε⁴/720 − ε⁶/30240, α′ = −ε/6 − ε³/180 − ε⁵/5040; the next terms are below 1e-17)."""
    eps = np.asarray(eps, dtype=float)
    small = np.abs(eps) < 1e-2
    e = np.where(small, 1.0, eps)
    h = 0.5 * e
    cot = np.cos(h) / np.sin(h)
    alpha = np.where(small, 1.0 - eps ** 2 / 12.0 - eps ** 4 / 720.0 - eps ** 6 / 30240.0, h * cot)
    dalpha = np.where(small, -eps / 6.0 - eps ** 3 / 180.0 - eps ** 5 / 5040.0,
                      0.5 * cot - 0.25 * e / np.sin(h) ** 2)
    return alpha, 0.5 * eps, dalpha


def logmap_translation(e: np.ndarray):
    """GTSAM's translational error in place: e[:, :2] ← V(ε)⁻¹ e[:, :2], ε = e[:, 2], for errors e (m, 3) of
    eq. (3) (module docstring). Returns (α, β, α′, e_x, e_y), each (m,), what the Jacobian of the result needs
    (``lago_cvx.refinement``)."""
    alpha, beta, dalpha = se2_v_inverse(e[:, 2])
    ex, ey = e[:, 0].copy(), e[:, 1].copy()
    e[:, 0] = alpha * ex + beta * ey
    e[:, 1] = alpha * ey - beta * ex
    return alpha, beta, dalpha, ex, ey


@dataclass(frozen=True, eq=False, repr=False)
class PoseGraph(PoseGraphBase):
    """Immutable planar pose graph. See the module docstring for the conventions.

    Shapes: ``tails, heads`` (m,) int64 pose indices; ``delta_l`` (m, 2); ``delta`` (m,);
    ``information`` (m, 3, 3) symmetric positive definite; ``initial`` (n, 3) or None;
    ``ids`` (n,) int64 file identifiers (default ``arange(n)``); ``cost`` one of ``lago_cvx.conventions.COSTS``
    (default ``"paper"``: ``information`` is the given Ω of eq. (3)); ``given_information`` (m, 3, 3) or None.
    """

    delta_l: np.ndarray
    delta: np.ndarray
    information: np.ndarray
    initial: np.ndarray | None = None
    ids: np.ndarray | None = None
    name: str = field(default="")
    cost: str = "paper"
    given_information: np.ndarray | None = None

    MEASUREMENTS = (("delta_l", (2,)), ("delta", ()), ("information", (3, 3)))  # class attribute (PoseGraphBase)
    OPTIONAL_MEASUREMENTS = ("given_information",)

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
        object.__setattr__(self, "cost", check_cost(self.cost))
        given = self.given_information
        if given is not None:
            given = np.asarray(given, dtype=float)
            if given.shape != info.shape or not np.isfinite(given).all():
                raise GraphError(f"given_information must be finite with shape {info.shape}, got {given.shape}")
            given = readonly(given)
        self._store_readonly(tails=tails, heads=heads, delta_l=delta_l, delta=delta, information=info, ids=ids)
        object.__setattr__(self, "initial", initial)
        object.__setattr__(self, "given_information", given)

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
        try:
            poses = np.array(poses, dtype=float)
        except (TypeError, ValueError):  # ragged: e.g. a 3-D pair (t, R) given for a planar graph
            raise OptionError(f"poses must be an array of shape ({self.n_poses}, 3) (a planar graph's; a 3-D "
                              "estimate is (t, R))") from None
        if poses.shape != (self.n_poses, 3):
            raise OptionError(f"poses must have shape ({self.n_poses}, 3), got {poses.shape}")
        if not np.isfinite(poses).all():
            raise OptionError("poses must be finite")
        return poses

    # ------------------------------------------------------------ covariances
    @property
    def covariance(self) -> np.ndarray:
        """Per-edge covariance Ω⁻¹, shape (m, 3, 3) (closed form, ``lago_cvx.stacks``)."""
        return spd_inverse(self.information)

    def delta_variance(self, edges=None) -> np.ndarray:
        """P_δ = (Ω⁻¹)[2, 2] of the edges ``edges`` (indices, default all), shape (len(edges),): the same
        numbers as ``covariance[edges, 2, 2]``, a block of edges at a time (``stacks.row_blocks``)."""
        idx = np.arange(self.n_edges) if edges is None else np.asarray(edges, np.int64)
        out = np.empty(idx.size)
        for k in row_blocks(idx.size):
            out[k] = spd_inverse(self.information[idx[k]])[:, 2, 2]
        return out

    def information_in(self, frame: str) -> np.ndarray:
        """The information matrices (m, 3, 3) written for the translational residual in ``frame``: ``"tail"``
        (eq. (3), TORO's) or ``"measurement"`` (g2o's, GTSAM's); the given matrices bit for bit when they are
        in that frame (module docstring)."""
        if frame not in ("tail", "measurement"):
            raise OptionError(f"frame must be 'tail' or 'measurement', got {frame!r}")
        if self.given_information is not None and COST_FRAME[self.cost] == frame:
            return self.given_information
        return self.information if frame == "tail" else to_measurement_frame(self.information, self.delta)

    # ------------------------------------------------------------ derivations
    def with_cost(self, cost: str) -> "PoseGraph":
        """The graph whose given information matrices are read as the information of ``cost``'s error
        (``lago_cvx.conventions.COSTS``): for ``"g2o"`` and ``"gtsam"`` ``information`` becomes T Ω_f Tᵀ
        (:func:`to_tail_frame`), for ``"paper"`` Ω_f itself. ``self`` when the cost is already ``cost``."""
        cost = check_cost(cost)
        if cost == self.cost:
            return self
        given = self.information_in(COST_FRAME[self.cost])
        if COST_FRAME[cost] == "tail":
            return replace(self, information=given, cost=cost, given_information=None)
        return replace(self, information=to_tail_frame(given, self.delta), cost=cost, given_information=given)

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
        return replace(self, tails=tails, heads=heads, delta_l=meas[:, :2], delta=meas[:, 2], information=info,
                       given_information=None)

    def equals(self, other: "PoseGraph", *, rtol: float = 0.0, atol: float = 0.0) -> bool:
        """Same poses, ids, edges and (within tolerance) measurements, information of eq. (3) and initial guess,
        and the same cost function: ``"paper"`` and ``"g2o"`` graphs with equal information are one cost (module
        docstring), ``"gtsam"``'s is another. ``cost`` and ``given_information`` themselves are not compared."""
        if (self.n_poses != other.n_poses or self.n_edges != other.n_edges
                or not np.array_equal(self.ids, other.ids)
                or not np.array_equal(self.tails, other.tails) or not np.array_equal(self.heads, other.heads)):
            return False
        if (self.initial is None) != (other.initial is None) or (self.cost == "gtsam") != (other.cost == "gtsam"):
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

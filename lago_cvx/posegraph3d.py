r"""The immutable 3-D pose graph: poses in SE(3), edges measuring one pose in the frame of another.

A ``PoseGraph3D`` has ``n_poses`` poses T_i = (R_i, t_i), R_i ∈ SO(3), t_i ∈ ℝ³, and ``n_edges`` edges.
Edge ``k`` goes from its tail ``i = tails[k]`` to its head ``j = heads[k]`` and carries

* ``delta_t[k]`` — t̃_ij, the position of j in the frame of i, shape ``(3,)``;
* ``delta_R[k]`` — R̃_ij, the orientation of j in the frame of i, shape ``(3, 3)`` (a rotation);
* ``information[k]`` — the 6×6 information Ω_ij of the error of the graph's ``cost``, in the order
  **(translation, rotation)** — the g2o files' order; stored as given (the same matrix for both costs).

The two costs (``cost``, ``lago_cvx.conventions.COSTS_3D``)
------------------------------------------------------------
Both errors are coordinates of the same rigid motion, the edge's error E = Z⁻¹ T_i⁻¹ T_j = (R_E, t_E) with
Z = T̃_ij = (R̃_ij, t̃_ij), R_E = R̃ᵀR_iᵀR_j and t_E = R̃ᵀ(R_iᵀ(t_j − t_i) − t̃) (:func:`edge_rotations`):

* ``"g2o"`` — g2o's ``EDGE_SE3:QUAT`` error, e = [t_E ; q_v] ∈ ℝ⁶, q = (q_v, w) the unit quaternion of R_E with
  the sign chosen so that **w ≥ 0** (g2o's ``toCompactQuaternion``), q_v = (x, y, z) its vector part
  (:func:`g2o_errors`). The default for files (``conventions.COST_OF_FORMAT``) and for graphs built in Python.
* ``"gtsam"`` — GTSAM's ``BetweenFactor<Pose3>``, e = Log(E) = [V(φ)⁻¹ t_E ; φ], φ = Log(R_E) ∈ ℝ³ of angle in
  [0, π], V the left Jacobian of SO(3) (:mod:`lago_cvx.so3`; :func:`log_errors`): GTSAM's ``2 * graph.error()``
  after ``gtsam.readG2o(file, True)``, which takes a g2o file's matrix as this error's information.

The cost is χ² = Σ e_ijᵀ Ω_ij e_ij (no ½) with the cost's e (:func:`chi2_3d`). At zero error the two agree to first
order: q_v = sin(θ/2) φ/θ ≈ φ/2 and V(φ)⁻¹t_E ≈ t_E, so e_g2o ≈ S e_gtsam with S = blkdiag(I₃, ½I₃), and a g2o
Ω weighs the Log error like S Ω S (:func:`information_in_log_coordinates`). Beyond first order they differ
(the quaternion's vector part saturates: ‖q_v‖ = sin(θ/2) ≤ 1), and so do their minima.

Everything is stored in NumPy arrays made read-only (as :class:`~lago_cvx.posegraph.PoseGraph`);
``dim`` is 3, the planar graph's is 2, so code that takes either dispatches on ``graph.dim``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .conventions import check_cost
from .errors import GraphError, OptionError
from .posegraph_base import PoseGraphBase, pose_ids, readonly
from .so3 import apply, entries, log_rotations, matrices, product, quaternions, transposed, v_inverse_apply

__all__ = ["PoseGraph3D", "is_spd6", "edge_rotations", "edge_translations", "g2o_errors", "log_errors",
           "edge_errors3d", "chi2_3d", "relative_poses", "LOG_SCALE", "information_in_log_coordinates",
           "without_cross_terms", "g2o_error_derivative", "g2o_errors_and_derivative"]

#: S = blkdiag(I₃, ½I₃): g2o's error is S times GTSAM's to first order at zero error (module docstring).
LOG_SCALE = np.diag([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])


def ldl_pivots(S: np.ndarray) -> np.ndarray:
    """The pivots d (m, k) of S_e = L_e D_e L_eᵀ (unit lower L_e, no pivoting) of every symmetric S_e of ``S``
    (m, k, k), its lower triangle read. S_e is positive definite iff every pivot is > 0 (after a zero or negative
    pivot the later ones are meaningless, possibly NaN: they are then not > 0 either)."""
    m, k, _ = S.shape
    return _pivots(np.asarray(S, dtype=float).reshape(m, k * k).T.copy(), k)       # a copy: worked on in place


def _pivots(F: np.ndarray, k: int) -> np.ndarray:
    """:func:`ldl_pivots` on F (k·k, m): entry (r, c) of every matrix as the contiguous row r·k + c; k vectorized
    elimination steps on the lower triangle, in place."""
    d = np.empty((F.shape[1], k))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for j in range(k):
            d[:, j] = F[j * k + j]
            for r in range(j + 1, k):
                lrj = F[r * k + j] / d[:, j]                                # L_e[r, j]
                for c in range(j + 1, r + 1):
                    F[r * k + c] -= lrj * F[c * k + j]
    return d


def is_spd6(info: np.ndarray, *, rtol: float = 1e-9) -> np.ndarray:
    """Boolean (m,): each matrix of ``info`` (m, k, k) is finite, symmetric to ``rtol`` of its largest entry,
    and positive definite (every LDLᵀ pivot > 0, :func:`ldl_pivots`)."""
    info = np.asarray(info, dtype=float)
    m, k = info.shape[0], info.shape[-1]
    if m == 0:
        return np.zeros(0, bool)
    F = info.reshape(m, k * k).T.copy()                         # (k·k, m), one row per entry; a copy
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.isfinite(F).all(axis=0)
        F[:, ~finite] = 0.0
        scale = np.abs(F).max(axis=0)
        upper = [(r, c) for r in range(k) for c in range(r + 1, k)]
        asym = np.zeros(m)
        for r, c in upper:
            np.maximum(asym, np.abs(F[r * k + c] - F[c * k + r]), out=asym)
        sym = asym <= rtol * np.maximum(scale, 1e-300)
        for r, c in upper:                                        # the symmetric part's lower triangle
            F[c * k + r] = 0.5 * (F[c * k + r] + F[r * k + c])
        pivots = _pivots(F, k)
    return finite & sym & (pivots > 0).all(axis=1)


def _is_rotation(R: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-1, -2))
    return (err < tol) & (np.linalg.det(R) > 0)


def relative_poses(t, R, tails, heads):
    """(R_iᵀR_j, R_iᵀ(t_j − t_i)) of every edge, shapes (m, 3, 3) and (m, 3)."""
    Ri = R[tails]
    Rt = np.swapaxes(Ri, 1, 2)
    return Rt @ R[heads], np.einsum("kij,kj->ki", Rt, t[heads] - t[tails])


def edge_rotations(graph: "PoseGraph3D", R):
    """(Gᵀ, E) of every edge as ``so3.entries``: G = R_i R̃_ij and E = R̃_ijᵀ R_iᵀ R_j = Gᵀ R_j, the rotation of the
    edge's error T̃_ij⁻¹ T_i⁻¹ T_j, for rotations R (n, 3, 3)."""
    rows = np.ascontiguousarray(np.asarray(R, dtype=float).reshape(-1, 9).T)
    GT = transposed(product(entries(rows, graph.tails), entries(graph.delta_R)))
    return GT, product(GT, entries(rows, graph.heads))


def edge_translations(graph: "PoseGraph3D", t, GT) -> list:
    """t_E = Gᵀ(t_j − t_i) − R̃ᵀt̃ of every edge (module docstring), three (m,) arrays, for positions t (n, 3) and
    Gᵀ = R̃ᵀR_iᵀ of :func:`edge_rotations`."""
    t = np.asarray(t, dtype=float)
    d = np.ascontiguousarray((t[graph.heads] - t[graph.tails]).T)
    return [a - b for a, b in zip(apply(GT, d), apply(transposed(entries(graph.delta_R)),
                                                      np.ascontiguousarray(graph.delta_t.T)))]


def _g2o_parts(graph: "PoseGraph3D", t, R):
    """(e (m, 6), R_E as ``so3.entries``, q (4, m)): g2o's errors, the error rotations and their unit quaternions
    (x, y, z, w), w ≥ 0 (``so3.rot_to_quat``'s sign)."""
    GT, E = edge_rotations(graph, R)
    q = quaternions(E)
    return np.ascontiguousarray(np.array(edge_translations(graph, t, GT) + [q[0], q[1], q[2]]).T), E, q


def g2o_errors(graph: "PoseGraph3D", t, R) -> np.ndarray:
    """g2o's e_ij = [t_E ; q_v(R_E)] (module docstring), shape (m, 6), for poses t (n, 3), R (n, 3, 3)."""
    return _g2o_parts(graph, t, R)[0]


def g2o_errors_and_derivative(graph: "PoseGraph3D", t, R):
    """(e (m, 6), D (m, 6, 6)): g2o's errors at poses t (n, 3), R (n, 3, 3) and :func:`g2o_error_derivative` of
    each."""
    e, E, q = _g2o_parts(graph, t, R)
    return e, g2o_error_derivative(matrices(E), np.ascontiguousarray(q.T))


def log_errors(graph: "PoseGraph3D", t, R) -> np.ndarray:
    """GTSAM's e_ij = Log(E) = [V(φ)⁻¹ t_E ; φ] (module docstring), shape (m, 6), for poses t (n, 3),
    R (n, 3, 3); Log by ``so3.log_se3``'s formulas, entry by entry over the edges."""
    GT, E = edge_rotations(graph, R)
    phi = log_rotations(E)
    return np.ascontiguousarray(np.array(v_inverse_apply(phi, edge_translations(graph, t, GT)) + phi).T)


def edge_errors3d(graph: "PoseGraph3D", t, R, *, cost: str | None = None) -> np.ndarray:
    """The errors e_ij (m, 6), translation first, of ``cost`` (default the graph's; module docstring) at poses
    t (n, 3), R (n, 3, 3): :func:`g2o_errors` or :func:`log_errors`."""
    cost = graph.cost if cost is None else check_cost(cost, dim=3)
    return (g2o_errors if cost == "g2o" else log_errors)(graph, t, R)


def chi2_3d(graph: "PoseGraph3D", t, R, *, cost: str | None = None) -> float:
    """χ² = Σ e_ijᵀ Ω_ij e_ij (no ½) of ``cost`` (default the graph's: g2o's χ² or GTSAM's 2·error()) at poses
    t (n, 3), R (n, 3, 3)."""
    e = edge_errors3d(graph, t, R, cost=cost)
    return float(np.einsum("ki,kij,kj->", e, graph.information, e))


def g2o_error_derivative(E_R: np.ndarray, q: np.ndarray) -> np.ndarray:
    r"""D = ∂e_g2o(E·Exp(η))/∂η at η = 0, shape (m, 6, 6), for error rotations E_R (m, 3, 3) and their quaternions
    q (m, 4) = (q_v, w), w ≥ 0; η = (ρ, φ) in the order (translation, rotation), E·Exp(η) ≈ (R_E(I + [φ]×),
    t_E + R_E ρ).

    Translation: t_E ← t_E + R_E ρ, so ∂t_E/∂ρ = R_E and ∂t_E/∂φ = 0. Rotation: the quaternion of R_E Exp(φ) is
    q ⊗ (φ/2, 1) + O(‖φ‖²), whose vector part is q_v + ½(w φ + q_v × φ): ∂q_v/∂φ = ½(w I + [q_v]×), ∂q_v/∂ρ = 0.
    The sign rule w ≥ 0 is kept by the step when w > 0 (at w = 0, a half turn, e is discontinuous). At zero error
    (R_E = I, q = (0, 1)) D = S = blkdiag(I₃, ½I₃) (:data:`LOG_SCALE`)."""
    from .so3 import hat

    m = E_R.shape[0]
    D = np.zeros((m, 6, 6))
    D[:, :3, :3] = E_R
    D[:, 3:, 3:] = 0.5 * (q[:, 3, None, None] * np.eye(3) + hat(q[:, :3]))
    return D


def information_in_log_coordinates(graph: "PoseGraph3D") -> np.ndarray:
    r"""The information (m, 6, 6) with which the graph's χ² weighs the Log error e = Log(E) = (ρ, φ) to second
    order at zero error — what a step that speaks Log coordinates (the chordal relaxation's rotational weights, the
    SE-Sync-style isotropic weights) must take from an edge.

    ``"gtsam"``: Ω itself (its error is Log(E)). ``"g2o"``: S Ω S with S = blkdiag(I₃, ½I₃) (:data:`LOG_SCALE`).
    Derivation: at E = Exp(ξ), ξ = (ρ, φ) small, t_E = V(φ)ρ = ρ + O(‖ξ‖²) and q_v = sin(θ/2)φ/θ = φ/2 + O(θ³), so
    e_g2o = S ξ + O(‖ξ‖²) and e_g2oᵀ Ω e_g2o = ξᵀ (S Ω S) ξ + O(‖ξ‖³): the rotation block is ¼Ω_rr, the cross
    blocks ½Ω_tr, the translation block Ω_tt (the derivative of :func:`g2o_error_derivative` at E = I is S)."""
    if graph.cost == "gtsam":
        return graph.information
    return LOG_SCALE @ graph.information @ LOG_SCALE


def without_cross_terms(info: np.ndarray) -> np.ndarray:
    """``information="blocks"``: a copy of ``info`` (m, 6, 6) with the translation–rotation blocks Ω_tr, Ω_rt set
    to zero, as SE-Sync reads a file (its model has independent translation and rotation noise)."""
    out = np.array(info, dtype=float)
    out[:, :3, 3:] = 0.0
    out[:, 3:, :3] = 0.0
    return out


@dataclass(frozen=True, eq=False, repr=False)
class PoseGraph3D(PoseGraphBase):
    """Immutable 3-D pose graph (module docstring). Shapes: ``tails, heads`` (m,) int64 pose indices;
    ``delta_t`` (m, 3); ``delta_R`` (m, 3, 3) rotations; ``information`` (m, 6, 6) symmetric positive
    definite, order (translation, rotation) of the cost's error; ``initial_t`` (n, 3) and ``initial_R`` (n, 3, 3),
    both or neither (the vertex lines of a file); ``ids`` (n,) int64 file identifiers (default ``arange(n)``);
    ``cost`` ``"g2o"`` (the default, as for files: a graph written to a g2o file and read back means the same
    cost) or ``"gtsam"`` (``conventions.COSTS_3D``; ``"paper"`` is planar and refused)."""

    delta_t: np.ndarray
    delta_R: np.ndarray
    information: np.ndarray
    initial_t: np.ndarray | None = None
    initial_R: np.ndarray | None = None
    ids: np.ndarray | None = None
    name: str = field(default="")
    cost: str = "g2o"

    dim = 3  # class attribute: the dimension of the space the poses live in
    MEASUREMENTS = (("delta_t", (3,)), ("delta_R", (3, 3)), ("information", (6, 6)))  # class attribute (PoseGraphBase)

    def __post_init__(self):
        n, tails, heads, (dt, dR, info) = self._checked_edges()
        m = tails.shape[0]
        bad = np.flatnonzero(~(np.isfinite(dt).all(1) & np.isfinite(dR).all((1, 2))))
        if bad.size:
            raise GraphError(f"non-finite measurement in edge(s) {bad[:5].tolist()}")
        bad = np.flatnonzero(~_is_rotation(dR)) if m else bad
        if bad.size:
            raise GraphError(f"measured rotation of edge(s) {bad[:5].tolist()} is not a rotation matrix")
        bad = np.flatnonzero(~is_spd6(info))
        if bad.size:
            raise GraphError(f"information matrix of edge(s) {bad[:5].tolist()} is not symmetric positive definite")
        it, iR = self.initial_t, self.initial_R
        if (it is None) != (iR is None):
            raise GraphError("initial_t and initial_R must be given together")
        if it is not None:
            it, iR = np.asarray(it, dtype=float), np.asarray(iR, dtype=float)
            if it.shape != (n, 3) or iR.shape != (n, 3, 3):
                raise GraphError(f"initial poses must have shapes ({n}, 3) and ({n}, 3, 3), got {it.shape}, "
                                 f"{iR.shape}")
            if not (np.isfinite(it).all() and np.isfinite(iR).all()):
                raise GraphError("initial poses must be finite")
            it, iR = readonly(it), readonly(iR)
        ids = pose_ids(n, self.ids)
        object.__setattr__(self, "cost", check_cost(self.cost, dim=3))
        self._store_readonly(tails=tails, heads=heads, delta_t=dt, delta_R=dR, information=info, ids=ids)
        object.__setattr__(self, "initial_t", it)
        object.__setattr__(self, "initial_R", iR)

    # ----------------------------------------------------------------- sizes and ids
    @property
    def initial(self):
        """The file's guess as a pair (t (n, 3), R (n, 3, 3)), or None."""
        return None if self.initial_t is None else (self.initial_t, self.initial_R)

    def check_poses(self, t, R):
        """(t, R) as new float arrays of shapes (n, 3), (n, 3, 3); ``OptionError`` otherwise."""
        t, R = np.array(t, dtype=float), np.array(R, dtype=float)
        if t.shape != (self.n_poses, 3) or R.shape != (self.n_poses, 3, 3):
            raise OptionError(f"poses must have shapes ({self.n_poses}, 3) and ({self.n_poses}, 3, 3), got "
                              f"{t.shape} and {R.shape}")
        if not (np.isfinite(t).all() and np.isfinite(R).all()):
            raise OptionError("poses must be finite")
        return t, R

    def with_initial(self, t, R) -> "PoseGraph3D":
        return replace(self, initial_t=t, initial_R=R)

    def with_cost(self, cost: str) -> "PoseGraph3D":
        """The graph whose information is read as the information of ``cost``'s error (module docstring): the same
        measurements and the same 6×6 matrices, another χ². ``self`` when the cost is already ``cost``."""
        cost = check_cost(cost, dim=3)
        return self if cost == self.cost else replace(self, cost=cost)

    def with_blocks(self) -> "PoseGraph3D":
        """The graph with its translation–rotation cross terms dropped (:func:`without_cross_terms`;
        ``read_graph(path, information="blocks")``); the same cost. ``GraphError`` when a block is not positive
        definite."""
        return replace(self, information=without_cross_terms(self.information))

    def equals(self, other: "PoseGraph3D", *, rtol: float = 0.0, atol: float = 0.0) -> bool:
        """Same poses, ids, cost, edges and (within tolerance) measurements, information and initial guess."""
        if (getattr(other, "dim", 2) != 3 or self.cost != other.cost or self.n_poses != other.n_poses
                or self.n_edges != other.n_edges
                or not np.array_equal(self.ids, other.ids) or not np.array_equal(self.tails, other.tails)
                or not np.array_equal(self.heads, other.heads) or (self.initial is None) != (other.initial is None)):
            return False
        pairs = [(self.delta_t, other.delta_t), (self.delta_R, other.delta_R), (self.information, other.information)]
        if self.initial is not None:
            pairs += [(self.initial_t, other.initial_t), (self.initial_R, other.initial_R)]
        return all(np.allclose(a, b, rtol=rtol, atol=atol) for a, b in pairs)

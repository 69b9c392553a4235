"""Nonlinear refinement of a planar pose graph (Gauss–Newton / Levenberg–Marquardt), dead-reckoning
initial guesses and trajectory error metrics.

LAGO (``lago_cvx.pipeline``) gives a linear approximation of the maximum-likelihood estimate. This module
minimises the **full nonlinear cost** the graph means — eq. (3) of the seed, g2o's χ² or GTSAM's (``lago_cvx.conventions``;
no factor ½), starting from any guess — typically LAGO's — so that the two can be
compared, and LAGO can be used as an initialization of an iterative solver (the seed's Section V).

Problem
-------
Unknowns: the poses x_v = (p_v, θ_v) = (x_v, y_v, θ_v), v = 0 … n−1, shape (n, 3), less a set K of
*held* coordinates (a boolean mask (n, 3)). By default K is the anchor pose a, held at the value it has in
the input poses, so the unknown vector has dimension 3(n − 1). With known poses (``anchors=``, full or
partial, as in ``lago``) K is their known coordinates, set to the given values, plus what fixes the gauge
they leave open (``held_coordinates``); as in the variants engine (``lago_cvx.variants``, (V2)) the held
columns leave J, so the system is over the d = 3n − |K| unknown coordinates, numbered in pose-major
order (x_0, y_0, θ_0, x_1, …) without the held ones.

For an edge k: i → j with measurement (Δˡ, δ) and information Ω (3×3, eq. (3)'s frame, ``lago_cvx.posegraph``) the error is

    e_k = [ R_iᵀ(p_j − p_i) − Δˡ ;  wrap(θ_j − θ_i − δ) ]          (3,)

and the cost χ² = Σ_k e_kᵀ Ω_k e_k.

Whitening. With the upper Cholesky factor U_k of Ω_k (U_kᵀU_k = Ω_k, full 3×3, cross terms
included; U = Lᵀ for L = ``np.linalg.cholesky(Ω)``, vectorized over edges) the whitened residual is
r_k = U_k e_k and χ² = Σ ‖r_k‖² = ‖r‖², r of shape (3m,).

Jacobian blocks. Let c = cos θ_i, s = sin θ_i, d = p_j − p_i and u = R_iᵀ d (so e_t = u − Δˡ).
Then, in the order (x, y, θ):

    ∂e/∂x_i = [[−c, −s,  u_y],        ∂e/∂x_j = [[ c, s, 0],
               [ s, −c, −u_x],                   [−s, c, 0],
               [ 0,  0,  −1 ]]                   [ 0, 0, 1]]

(∂(R_iᵀd)/∂θ_i = (u_y, −u_x); the wrap is piecewise constant, so it does not enter the derivative).

The cost. ``Ω`` is the graph's information of eq. (3) (``lago_cvx.posegraph``): for a graph of cost
``"paper"`` or ``"g2o"`` the χ² above *is* that cost, exactly. For ``"gtsam"`` the translational error is
GTSAM's Logmap's, ẽ_t = V(ε)⁻¹ e_t with ε = e_θ and V(ε)⁻¹ = α(ε) I + (ε/2) J, J = [[0, 1], [−1, 0]]
(``posegraph.se2_v_inverse``); its blocks are

    ∂ẽ_t/∂x = V(ε)⁻¹ ∂e_t/∂x + (α′(ε) e_t + ½ J e_t) ∂ε/∂x,      ∂ε/∂x_i = (0, 0, −1), ∂ε/∂x_j = (0, 0, 1),

and the rotational row is unchanged.
The whitened blocks U_k·∂e/∂x_i and U_k·∂e/∂x_j (each 3×3, dense because U mixes the rows) fill
rows 3k … 3k+2 of ONE sparse Jacobian J of shape (3m, d), 18 entries per edge minus the held
columns. Its CSR structure (row pointers, column indices, and the gather index that
drops the held entries and sorts the columns of every row) does not change between iterations
and is built once; an iteration only computes the (m, 3, 6) block values — no Python loop over
edges.

Gauss–Newton. Solve the normal equations JᵀJ·dx = −Jᵀr (``lago_cvx.sparse.linalg.factorize``, the same
sparse SPD machinery — QDLDL / SuperLU / CHOLMOD — as LAGO's closed form) and update additively,
x ← x + dx, which is exact for this (x, y, θ) parametrization (θ stays unwrapped; residuals wrap).
With g = Jᵀr and H = JᵀJ the linear model ‖r + J dx‖² predicts the decrease −gᵀdx for the GN step.
If a GN step increases χ², the step is halved (backtracking line search, at most
``MAX_HALVINGS`` times) and this is logged.

Levenberg–Marquardt. Solve (H + λ·D) dx = −g with D = diag(H) (Marquardt's scaling); the predicted
decrease is L(0) − L(dx) = −gᵀdx + λ·dxᵀD dx > 0 and the gain ratio ρ = actual / predicted decides:
ρ > 0 accepts the step and sets λ ← λ·max(1/3, 1 − (2ρ − 1)³), ν ← 2; otherwise the step is
rejected, λ ← λ·ν, ν ← 2ν (Nielsen's rule). Rejected steps never change the poses, so χ² is monotone.

Stopping: relative χ² decrease below ``tolerance``; step ‖dx‖∞ ≤ ``STEP_TOLERANCE``·(1 + ‖x‖∞);
``max_iterations`` (GN: iterations; LM: trials, accepted or not); LM also stops when λ exceeds
``MAX_LAMBDA``. The returned χ² is never larger than the starting one.

Also here: ``odometry_guess`` (dead reckoning along a spanning tree, vectorized by pointer jumping).
Trajectory errors (``ate``, ``rotation_error``) are in ``lago_cvx.metrics``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .reports import refine_repr, refine_summary
from .conventions import REFINE_MAX_ITERATIONS, REFINE_METHOD, REFINE_TOLERANCE
from .errors import OptionError, check_choice
from .posegraph_base import as_graph
from .graph import accumulate_to_root, check_connected, spanning_tree as build_tree
from .metrics3d import poses_of
from .sparse import SOLVER_BACKENDS, factorize
from .posegraph import PoseGraph, logmap_translation, rot2, wrap_angle
from .rounding import TWO_PI

__all__ = ["RefineResult", "refine", "REFINE_METHODS", "odometry_guess", "jacobian", "whitened_residuals",
           "check_iteration_args", "prepare", "small_step", "STEP_TOLERANCE", "held_coordinates"]

log = logging.getLogger(__name__)

#: Accepted values of ``refine(method=...)``.
REFINE_METHODS = ("gauss-newton", "levenberg-marquardt")
#: Maximum number of step halvings of the Gauss–Newton backtracking line search.
MAX_HALVINGS = 10
#: A step with ‖dx‖∞ ≤ STEP_TOLERANCE·(1 + ‖x‖∞) counts as "no further change" (converged).
STEP_TOLERANCE = 1e-12
#: Initial Levenberg–Marquardt damping (relative to diag(JᵀJ)).
INITIAL_LAMBDA = 1e-7
#: LM gives up (the point is stationary to working precision) once λ exceeds this.
MAX_LAMBDA = 1e16


@dataclass(eq=False)
class RefineResult:
    """Outcome of ``refine``."""

    #: The refined estimate (n, 3) (θ unwrapped).
    poses: np.ndarray
    #: Its χ² (the graph's cost, no ½).
    chi2: float
    #: The χ² of the starting poses.
    chi2_initial: float
    #: The number of accepted steps.
    iterations: int
    #: True when a convergence test (not ``max_iterations``, not a failed line search) stopped the solver.
    converged: bool
    #: One dict per iteration (entry 0 = the start) with keys ``iteration`` (accepted steps so far), ``chi2``
    #: (current χ², after the iteration), ``step_norm`` (‖dx‖∞ of the step tried), ``time`` (seconds since
    #: the start) and, for LM, ``lambda`` (damping used) and ``accepted``; for GN ``halvings`` (line-search
    #: halvings).
    log: list = field(default_factory=list)
    #: What stopped the solver.
    reason: str = ""
    #: The method, one of ``REFINE_METHODS``.
    method: str = ""
    #: The id of the reference pose (the one fixed pose without ``anchors``).
    anchor: int = 0
    #: The sparse solver used.
    backend: str = ""
    #: (n, 3) bool, the coordinates held fixed.
    held: np.ndarray | None = None
    #: The cost minimised (``lago_cvx.conventions.COSTS``).
    cost: str = "paper"
    #: The names of the constraints kept (``refine(constraints=...)``), else empty.
    constraint_names: list = field(default_factory=list)
    #: The least-squares problem refined (edge residuals, priors, held coordinates).
    problem: object = field(default=None, repr=False)

    def pose_covariances(self) -> np.ndarray:
        """Marginal covariances (n, 3, 3) of (x, y, θ) of every pose at the refined estimate: the diagonal
        blocks of (JᵀJ)⁻¹, J the whitened Jacobian of the refined problem (edges and priors), held coordinates
        zero; with constraints, the unconstrained Hessian's (``lago_cvx.refine_variants``, R3)."""
        from .refine_variants import pose_covariances

        return pose_covariances(self.problem, self.poses)

    @property
    def times(self) -> np.ndarray:
        """Seconds since the start at each log entry, shape (len(log),)."""
        return np.array([e["time"] for e in self.log])

    def __repr__(self) -> str:
        return refine_repr(self)

    def summary(self):
        """The numbers of the refinement as a small table (``reports.Summary``, also a dict)."""
        return refine_summary(self)


# ------------------------------------------------------------------------------ the problem
class _Problem:
    """Precomputed, iteration-independent data of the least-squares problem.

    ``held`` (n, 3) bool the held coordinates K (default: the three of pose ``anchor``); ``U`` (m, 3, 3)
    upper Cholesky factors; ``indptr`` (3m + 1,), ``indices`` (nnz,), ``take`` (nnz,) the fixed CSR
    structure of J (``take`` gathers from the flattened (m, 3, 6) block values)."""

    def __init__(self, graph: PoseGraph, anchor: int, held: np.ndarray | None = None):
        n, m = graph.n_poses, graph.n_edges
        self.graph = graph
        self.n, self.m, self.anchor = n, m, anchor
        self.tails, self.heads = graph.tails, graph.heads
        self.delta_l, self.delta = graph.delta_l, graph.delta
        self.gtsam = graph.cost == "gtsam"
        info = 0.5 * (graph.information + np.swapaxes(graph.information, 1, 2))
        self.U = np.ascontiguousarray(np.swapaxes(np.linalg.cholesky(info), 1, 2))  # UᵀU = Ω
        if held is None:
            held = np.zeros((n, 3), bool)
            held[anchor] = True
        self.held = held
        self.dim = int(n * 3 - held.sum())
        # reduced column of every (pose, component) in pose-major order; −1 for the held coordinates
        col = np.full(3 * n, -1, np.int64)
        col[~held.reshape(-1)] = np.arange(self.dim)
        col = col.reshape(n, 3)
        self.col = col
        # block column order per edge: tail block then head block, swapped when head < tail so
        # that the column indices of every CSR row come out sorted
        cols = np.concatenate([col[self.tails], col[self.heads]], axis=1)  # (m, 6)
        swap = self.heads < self.tails
        order = np.where(swap[:, None], np.array([3, 4, 5, 0, 1, 2]), np.arange(6))  # (m, 6)
        cols = np.take_along_axis(cols, order, axis=1)
        flat = (np.arange(m)[:, None, None] * 18 + np.arange(3)[None, :, None] * 6
                + order[:, None, :])  # (m, 3, 6) index into the (m, 3, 6) values, flattened
        cols3 = np.broadcast_to(cols[:, None, :], (m, 3, 6))
        keep = cols3 >= 0
        self.take = flat[keep]
        self.indices = cols3[keep].astype(np.int32 if self.dim < 2**31 else np.int64)
        counts = keep.reshape(3 * m, 6).sum(1)
        self.indptr = np.concatenate([[0], np.cumsum(counts)]).astype(self.indices.dtype)

    # -- residuals
    def errors(self, poses: np.ndarray):
        """Errors e (m, 3) of the graph's cost (for ``"gtsam"`` ẽ, module docstring) and u = R_iᵀ(p_j − p_i)
        (m, 2), cos θ_i, sin θ_i (m,)."""
        pi, pj = poses[self.tails], poses[self.heads]
        c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
        u = np.column_stack([c * dx + s * dy, -s * dx + c * dy])
        e = np.empty((self.m, 3))
        e[:, :2] = u - self.delta_l
        e[:, 2] = wrap_angle(pj[:, 2] - pi[:, 2] - self.delta)
        if self.gtsam:
            self._logmap(e)
        return e, u, c, s

    def _logmap(self, e: np.ndarray) -> None:
        """GTSAM's translational error in place (``posegraph.logmap_translation``); keeps what the Jacobian needs."""
        self._v = logmap_translation(e)

    def residuals(self, poses: np.ndarray) -> np.ndarray:
        """Whitened residuals r = U e, shape (m, 3)."""
        e = self.errors(poses)[0]
        return np.einsum("kab,kb->ka", self.U, e)

    def chi2(self, poses: np.ndarray) -> float:
        r = self.residuals(poses)
        return float(np.einsum("ka,ka->", r, r))

    # -- Jacobian
    def linearize(self, poses: np.ndarray):
        """Whitened residual vector r (3m,) and sparse Jacobian J (3m, d) CSR at ``poses``."""
        e, u, c, s = self.errors(poses)
        r = np.einsum("kab,kb->ka", self.U, e).reshape(-1)
        Jj = np.zeros((self.m, 3, 3))
        Jj[:, 0, 0] = c
        Jj[:, 0, 1] = s
        Jj[:, 1, 0] = -s
        Jj[:, 1, 1] = c
        Jj[:, 2, 2] = 1.0
        Ji = -Jj
        Ji[:, 0, 2] = u[:, 1]
        Ji[:, 1, 2] = -u[:, 0]
        if self.gtsam:  # ∂ẽ_t = V⁻¹ ∂e_t + (α′ e_t + ½ J e_t) ∂ε (module docstring)
            alpha, beta, dalpha, ex, ey = self._v
            for J, sign in ((Ji, -1.0), (Jj, 1.0)):
                r0, r1 = J[:, 0, :].copy(), J[:, 1, :].copy()
                J[:, 0, :] = alpha[:, None] * r0 + beta[:, None] * r1
                J[:, 1, :] = alpha[:, None] * r1 - beta[:, None] * r0
                J[:, 0, 2] += sign * (dalpha * ex + 0.5 * ey)
                J[:, 1, 2] += sign * (dalpha * ey - 0.5 * ex)
        blocks = np.concatenate([self.U @ Ji, self.U @ Jj], axis=2)  # (m, 3, 6)
        data = blocks.reshape(-1)[self.take]
        J = sp.csr_matrix((data, self.indices, self.indptr), shape=(3 * self.m, self.dim))
        J.has_sorted_indices = True
        return r, J

    def update(self, poses: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """Additive update x ← x + dx of the unknown coordinates (dx of shape (d,))."""
        new = poses.copy()
        new[~self.held] += dx
        return new


def check_iteration_args(max_iterations: int, tolerance: float) -> None:
    """``OptionError`` for a negative iteration count or a negative / NaN tolerance (shared with
    ``lago_cvx.certification.refine_sesync``)."""
    if not int(max_iterations) >= 0:
        raise OptionError(f"max_iterations must be >= 0, got {max_iterations}")
    if not tolerance >= 0:
        raise OptionError(f"tolerance must be >= 0, got {tolerance}")


def prepare(graph: PoseGraph, poses, *, anchor, max_iterations: int, tolerance: float) -> tuple[np.ndarray, int]:
    """What both refinements (χ² here, the SE-Sync cost in ``lago_cvx.certification``) check first: the
    starting poses as a new (n, 3) array (``poses`` an array or any planar result: ``metrics3d.poses_of``) and the
    anchor's index (``anchor`` a pose id, default the smallest). ``OptionError`` for bad arguments, ``GraphError``
    for a disconnected graph."""
    check_iteration_args(max_iterations, tolerance)
    x = graph.check_poses(poses_of(graph, poses))
    a = graph.anchor_index(anchor)
    check_connected(graph)
    return x, a


def whitened_residuals(graph: PoseGraph, poses) -> np.ndarray:
    """Whitened residuals r = U e (m, 3), U the upper Cholesky factor of each Ω; Σ‖r‖² = χ²."""
    return _Problem(graph, 0).residuals(graph.check_poses(poses))


def jacobian(graph: PoseGraph, poses, *, anchor=None) -> sp.csr_matrix:
    """The analytic sparse Jacobian of the whitened residuals (3m, 3(n−1)) at ``poses``; the anchor's
    (a pose id, default the smallest) columns are removed. Row 3k + a is component a of edge k."""
    prob = _Problem(graph, graph.anchor_index(anchor))
    return prob.linearize(graph.check_poses(poses))[1]


def held_coordinates(graph: PoseGraph, poses: np.ndarray, anchors, anchor=None,
                     priors=None) -> tuple[np.ndarray, np.ndarray, int]:
    """The coordinates ``refine`` holds fixed for known poses ``anchors`` ({id: (x, y, θ)}, None or NaN for
    an unknown component, as in ``lago``): returns (held (n, 3) bool, start (n, 3) the poses with the known
    values put in, reference index). ``priors`` ({id: (mean, information)}) fix the gauge as anchors
    do (a position prior the translation, a θ prior or two distinct known positions the rotation) but are
    not held.

    K = the known coordinates; a known θ is put on the branch nearest the starting pose's (θ + 2πk, the
    residuals wrap, so the cost does not change). The gauge the anchors leave open is held at the
    reference pose (``anchor`` if given, else as ``lago_cvx.variants.anchors.choose_reference``) at its
    starting value: its position when no position is known; its orientation when no orientation is
    known and fewer than two distinct positions are (two fix the rotation)."""
    from .refine_variants import prior_positions
    from .variants.anchors import choose_reference, normalize_anchors, normalize_priors

    known = normalize_anchors(graph, anchors)
    pri_pos, pri_theta = prior_positions(graph, priors)
    x = np.array(poses, dtype=float)
    held = np.zeros((graph.n_poses, 3), bool)
    for a in known:  # loop over anchors (few)
        if a.position is not None:
            held[a.index, :2] = True
            x[a.index, :2] = a.position
        if a.theta is not None:
            held[a.index, 2] = True
            x[a.index, 2] = a.theta + TWO_PI * np.round((x[a.index, 2] - a.theta) / TWO_PI)
    ref = choose_reference(graph, known, normalize_priors(graph, priors), anchor)
    positions = np.array([a.position for a in known if a.position is not None] + [m for _, m in pri_pos])
    positions = positions.reshape(-1, 2)
    if not held[:, :2].any() and not pri_pos:
        held[ref, :2] = True
    if not held[:, 2].any() and not pri_theta and not (positions.shape[0] >= 2 and np.ptp(positions, axis=0).any()):
        held[ref, 2] = True
    return held, x, ref


# ------------------------------------------------------------------------------ the solvers
def refine(graph: PoseGraph, estimate, *, method: str = REFINE_METHOD, max_iterations: int = REFINE_MAX_ITERATIONS,
           tolerance: float = REFINE_TOLERANCE, anchor=None, anchors=None, priors=None, constraints=None,
           backend: str = "auto", cost: str | None = None, solver_settings=None):
    """Minimise the graph's nonlinear χ² over the SE(2) poses, starting from ``estimate`` (poses (n, 3), or a
    result with ``poses``): eq. (3) with the information of the graph's cost — exactly g2o's χ² for cost
    ``"g2o"``, GTSAM's 2·error() for ``"gtsam"`` (module docstring).

    A 3-D graph (``graph.dim == 3``) is refined on SE(3) by ``lago_cvx.space.refine`` with the same keywords and
    defaults: ``estimate`` a pair (t, R) or a result with ``t`` and ``R``; ``anchors`` ``{id: (t, R)}`` (either may
    be None); ``priors`` ``{id: (t̄ or None, R̄ or None, Λ)}``; ``constraints`` rotation constraints
    ``{id: (a, b)}``, R_id a = b (``space.gravity_aligned``); it returns a ``Refine3DResult`` (``t``, ``R``,
    ``chi2``, ``pose_covariances()`` 6×6 …). The defaults (``lago_cvx.conventions``: Gauss–Newton, relative
    tolerance 1e-9, 50 iterations) are the same in both dimensions; that module says why.

    Parameters (keyword-only):
      method — ``"gauss-newton"`` (plain steps, backtracking line search if a step increases χ²) or
        ``"levenberg-marquardt"`` (Marquardt damping λ·diag(JᵀJ), Nielsen's λ update).
      max_iterations — GN iterations / LM trials.
      tolerance — stop when the relative χ² decrease of an iteration is below this.
      anchor — id of the pose held fixed (as in ``lago``; default the smallest id, i.e. index 0 for
        files read by ``lago_cvx.io``); it keeps the value it has in ``poses``. With ``anchors``: the
        reference pose that holds the gauge the anchors leave open (``held_coordinates``).
      anchors — known poses ``{id: (x, y, θ)}`` (or pairs; None or NaN for an unknown component: partial
        anchors), as in ``lago(anchors=...)``: their known coordinates are set to the given values (θ
        modulo 2π) and held fixed, removed from the system; ``result.held`` says which coordinates were.
      backend — sparse solver, see ``lago_cvx.sparse.linalg.factorize``.
      cost — the cost to minimise, one of ``lago_cvx.conventions.COSTS`` (``graph.with_cost(cost)``); None: the
        graph's own (``graph.cost``, the file format's when read from a file).
      priors — soft absolute measurements ``{id: (mean, information)}`` as in ``lago``: full (x, y, θ) with a
        3×3 information, ``((x, y, None), Λ 2×2)`` (position / GPS) or ``((None, None, θ), λ)``; their χ²
        terms join the cost and they fix the gauge as anchors do (``lago_cvx.refine_variants``, R1).
      constraints — convex constraints kept feasible at every step: ``f(pv)`` returning cvxpy constraints or
        ``NamedConstraint``s on ``pv.x``, ``pv.y``, ``pv.theta`` (n,) (pose index order, as in
        ``constrained_lago``), or such a list; Gauss–Newton steps solved as convex problems by Clarabel
        (``solver_settings``) with a line search (R2); ``method`` must be ``"gauss-newton"``. Without
        ``priors`` and ``constraints`` nothing of this is loaded.
    ``result.pose_covariances()`` gives the marginal covariances of the refined problem (R3).
    Returns a ``RefineResult``. See the module docstring for the maths. Raises ``GraphError`` for a
    disconnected graph (its normal equations are singular), ``OptionError`` (a ``ValueError``) for bad
    arguments or anchors.
    """
    check_choice("method", method, REFINE_METHODS)
    check_choice("backend", backend, SOLVER_BACKENDS)
    graph = as_graph(graph)  # a generated world's graph; a one-line GraphError for anything else
    if getattr(graph, "dim", 2) == 3:
        from .space.refine import estimate3d, refine3d

        if backend != "auto" or solver_settings is not None:
            raise OptionError("backend, solver_settings: planar refinement only (3-D steps use the sparse engine)")
        return refine3d(graph, *estimate3d(estimate), cost=cost, method=method, anchor=anchor, anchors=anchors,
                        priors=priors, constraints=constraints, max_iterations=max_iterations, tolerance=tolerance)
    if cost is not None:
        graph = graph.with_cost(cost)
    poses = estimate.poses if hasattr(estimate, "poses") and not isinstance(estimate, np.ndarray) else estimate
    x, a = prepare(graph, poses, anchor=anchor, max_iterations=max_iterations, tolerance=tolerance)
    held = None
    if constraints is not None and method != "gauss-newton":
        raise OptionError("constraints: refine keeps constraints with Gauss-Newton steps; use method='gauss-newton'")
    if anchors is not None or priors is not None:
        held, x, a = held_coordinates(graph, x, anchors or {}, anchor, priors)
    t0 = time.perf_counter()
    prob = _Problem(graph, a, held)
    if priors is not None:
        from .refine_variants import with_priors

        prob = with_priors(prob, graph, priors)
    chi = prob.chi2(x)
    chi_initial = chi
    entries = [{"iteration": 0, "chi2": chi, "step_norm": 0.0, "time": time.perf_counter() - t0}]
    if method == "levenberg-marquardt":
        entries[0]["lambda"] = None
    result = RefineResult(poses=x, chi2=chi, chi2_initial=chi, iterations=0, converged=False, log=entries,
                          method=method, anchor=int(graph.ids[a]), backend="", held=prob.held, cost=graph.cost,
                          problem=prob)
    if prob.dim == 0 or graph.n_edges == 0:
        result.converged, result.reason = True, "nothing to optimize"
        return result
    if constraints is not None:
        from .refine_variants import constrained_gauss_newton

        constrained_gauss_newton(graph, prob, result, constraints, max_iterations, tolerance, t0, solver_settings)
    elif method == "gauss-newton":
        _gauss_newton(prob, result, max_iterations, tolerance, t0, backend)
    else:
        _levenberg_marquardt(prob, result, max_iterations, tolerance, t0, backend)
    log.info("refine (%s): χ² %.6g → %.6g in %d accepted steps, %.3f s; %s", method, chi_initial,
             result.chi2, result.iterations, time.perf_counter() - t0, result.reason)
    return result


def small_step(dx: np.ndarray, x: np.ndarray) -> bool:
    """The step test shared by both refinements: ‖dx‖∞ ≤ ``STEP_TOLERANCE``·(1 + ‖x‖∞)."""
    return float(np.max(np.abs(dx))) <= STEP_TOLERANCE * (1.0 + float(np.max(np.abs(x))))


def _normal_equations(prob: _Problem, x: np.ndarray):
    r, J = prob.linearize(x)
    Jt = J.T.tocsr()
    H = (Jt @ J).tocsc()
    g = Jt @ r
    return H, g


def _gauss_newton(prob: _Problem, res: RefineResult, max_iterations: int, tol: float, t0: float,
                  backend: str = "auto") -> None:
    x, chi = res.poses, res.chi2
    res.reason = "max_iterations reached"
    for it in range(1, max_iterations + 1):
        H, g = _normal_equations(prob, x)
        try:
            factor = factorize(H, backend=backend)
        except RuntimeError as exc:  # exactly singular normal equations
            res.reason = f"singular normal equations ({exc})"
            break
        res.backend = factor.backend
        dx = -factor.solve(g)
        step = float(np.max(np.abs(dx)))
        if not np.isfinite(dx).all():
            res.reason = "non-finite Gauss-Newton step (singular normal equations)"
            break
        if small_step(dx, x):
            res.converged, res.reason = True, f"step norm {step:.3g} below tolerance"
            res.log.append({"iteration": res.iterations, "chi2": chi, "step_norm": step,
                            "time": time.perf_counter() - t0, "halvings": 0})
            break
        predicted = -float(g @ dx)  # model decrease of the full GN step
        alpha, halvings = 1.0, 0
        new = prob.update(x, dx)
        chi_new = prob.chi2(new)
        if abs(chi - chi_new) <= tol * max(chi, np.finfo(float).tiny) and chi_new <= chi:
            x, chi = new, chi_new
            res.iterations += 1
            res.converged, res.reason = True, "relative χ² decrease below tolerance"
            res.log.append({"iteration": res.iterations, "chi2": chi, "step_norm": step,
                            "time": time.perf_counter() - t0, "halvings": 0})
            log.info("GN iteration %d: χ² = %.10g, |dx| = %.3g", res.iterations, chi, step)
            break
        while not chi_new < chi and halvings < MAX_HALVINGS:
            halvings += 1
            alpha *= 0.5
            new = prob.update(x, alpha * dx)
            chi_new = prob.chi2(new)
        if halvings:
            log.info("GN iteration %d: full step increased χ²; backtracking line search used %d "
                     "halving(s), step %.3g", it, halvings, alpha)
        if not chi_new < chi:
            # no decrease along the GN direction: stationary to working precision if the model
            # predicts (almost) nothing, otherwise a genuine failure
            res.log.append({"iteration": res.iterations, "chi2": chi, "step_norm": step,
                            "time": time.perf_counter() - t0, "halvings": halvings})
            if predicted <= 10 * tol * max(chi, np.finfo(float).tiny):
                res.converged, res.reason = True, "no further decrease (stationary to working precision)"
            else:
                res.reason = (f"line search failed: χ² did not decrease after {halvings} halvings "
                              f"(predicted decrease {predicted:.3g})")
            log.info("GN iteration %d: %s", it, res.reason)
            break
        rel = (chi - chi_new) / max(chi, np.finfo(float).tiny)
        x, chi = new, chi_new
        res.iterations += 1
        res.log.append({"iteration": res.iterations, "chi2": chi, "step_norm": alpha * step,
                        "time": time.perf_counter() - t0, "halvings": halvings})
        log.info("GN iteration %d: χ² = %.10g, |dx| = %.3g", res.iterations, chi, alpha * step)
        if rel < tol:
            res.converged, res.reason = True, "relative χ² decrease below tolerance"
            break
    res.poses, res.chi2 = x, chi


def _levenberg_marquardt(prob: _Problem, res: RefineResult, max_iterations: int, tol: float, t0: float,
                         backend: str) -> None:
    x, chi = res.poses, res.chi2
    lam, nu = INITIAL_LAMBDA, 2.0
    res.reason = "max_iterations reached"
    H, g = _normal_equations(prob, x)
    D = H.diagonal()
    D = np.maximum(D, 1e-12 * max(float(D.max()), np.finfo(float).tiny))
    for _trial in range(max_iterations):
        A = (H + sp.diags(lam * D)).tocsc()
        try:
            factor = factorize(A, backend=backend)
            dx = -factor.solve(g)
            res.backend = factor.backend
        except RuntimeError:
            dx = np.full(prob.dim, np.nan)
        step = float(np.max(np.abs(dx))) if np.isfinite(dx).all() else np.inf
        entry = {"iteration": res.iterations, "chi2": chi, "step_norm": step, "lambda": lam, "accepted": False}
        if np.isfinite(step) and small_step(dx, x):
            entry["time"] = time.perf_counter() - t0
            res.log.append(entry)
            res.converged, res.reason = True, f"step norm {step:.3g} below tolerance"
            break
        if np.isfinite(step):
            new = prob.update(x, dx)
            chi_new = prob.chi2(new)
            predicted = -float(g @ dx) + lam * float(dx @ (D * dx))
        else:
            chi_new, predicted = np.inf, 1.0
        small_change = abs(chi - chi_new) <= tol * max(chi, np.finfo(float).tiny)
        rho = (chi - chi_new) / predicted if predicted > 0 else -1.0
        if chi_new < chi and rho > 0:
            x, chi = new, chi_new
            res.iterations += 1
            entry.update(iteration=res.iterations, chi2=chi, accepted=True)
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            lam *= nu
            nu *= 2.0
        entry["time"] = time.perf_counter() - t0
        res.log.append(entry)
        log.info("LM trial %d: %s, χ² = %.10g, |dx| = %.3g, λ = %.3g", _trial + 1,
                 "accepted" if entry["accepted"] else "rejected", chi, step, entry["lambda"])
        if small_change:
            res.converged, res.reason = True, "relative χ² change below tolerance"
            break
        if lam > MAX_LAMBDA:
            res.converged = True
            res.reason = "damping exceeded MAX_LAMBDA (no decrease possible: stationary to working precision)"
            break
        if entry["accepted"]:
            H, g = _normal_equations(prob, x)
            D = np.maximum(H.diagonal(), 1e-12 * max(float(H.diagonal().max()), np.finfo(float).tiny))
    res.poses, res.chi2 = x, chi


# ------------------------------------------------------------------------------ dead reckoning
def odometry_guess(graph: PoseGraph, *, spanning_tree="odometry", anchor=None) -> np.ndarray:
    """Dead reckoning: compose the measurements along a spanning tree from the anchor at the origin.

    ``spanning_tree`` — anything ``lago_cvx.graph.spanning_tree`` accepts (``"odometry"`` default:
    the chain of consecutive ids; ``"bfs"``, ``"mst"``, or edge indices). ``anchor`` — pose id
    (default the smallest). Returns (n, 3) poses, θ unwrapped.

    For a child c reached from its parent p through tree edge k (measurement Δˡ_k, δ_k):
      * forward edge p → c:  c = p ⊕ z_k, so θ_c = θ_p + δ_k and p_c = p_p + R(θ_p)·Δˡ_k;
      * backward edge c → p: p = c ⊕ z_k, so θ_c = θ_p − δ_k and p_c = p_p − R(θ_c)·Δˡ_k.
    The orientations come from ``SpanningTree.integrate``; the global position steps above only need
    the (already known) orientations, so positions are their sums along the path to the root,
    accumulated by the same pointer jumping (O(n log depth), no loop over poses)."""
    tree = build_tree(graph, spanning_tree, anchor=anchor)
    theta = tree.integrate(graph)
    n = graph.n_poses
    steps = np.zeros((n, 2))
    child = np.flatnonzero(tree.parent >= 0)
    if child.size:
        k = tree.parent_edge[child]
        fwd = tree.forward[child]
        ang = np.where(fwd, theta[tree.parent[child]], theta[child])
        rotated = np.einsum("kab,kb->ka", rot2(ang), graph.delta_l[k])
        steps[child] = np.where(fwd[:, None], rotated, -rotated)
    x = accumulate_to_root(tree.parent, steps[:, 0])
    y = accumulate_to_root(tree.parent, steps[:, 1])
    return np.column_stack([x, y, theta])

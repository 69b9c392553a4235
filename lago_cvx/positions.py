r"""The positions that minimise χ² exactly for given orientations (beyond the seed: the "position polish").

With the orientations θ held fixed, the cost of eq. (3) is exactly quadratic in the positions. Per
edge k = (i → j), with the orientation error ē_k = wrap(θ_j − θ_i − δ_k) now a constant and the error
e_t = R(θ_i)ᵀ(p_j − p_i) − Δˡ_k, completing the square with Ω = [[Ω_pp, Ω_pθ], [Ω_θp, Ω_θθ]] gives

    e_kᵀΩ_k e_k = (e_t + h_k ē_k)ᵀ Ω_pp,k (e_t + h_k ē_k) + ē_k² / P_δ,k,     h_k = Ω_pp,k⁻¹ Ω_pθ,k,

so the positions are the weighted least-squares fit of

    p_j − p_i ≈ R(θ_i) t_k,   t_k = Δˡ_k − h_k ē_k,   with information R(θ_i) Ω_pp,k R(θ_i)ᵀ, i.e.
    minimise Σ_k ‖C_k R(θ_i)ᵀ (p_j − p_i − R(θ_i) t_k)‖²,   C_kᵀC_k = Ω_pp,k,                        (P)

a 2(n−1) × 2(n−1) SPD system with the sparsity of the seed's eq. (14) (A₂ ⊗ I₂ weighted Laplacian).
Ω_pp is the *conditional* information of Δˡ given δ, not the inverse of the marginal covariance P_Δ
that the seed's phase 2 uses; with block-diagonal Ω they coincide, h = 0, and (P) at θ = θ̂ is exactly
eq. (14), the seed's sub-optimal positions p̂ (Theorem 1).

(P) is the exact minimiser of χ² over the positions, so χ²(positions of (P), θ) ≤ χ²(any positions, θ):
run after phase 3 it can only lower χ² (``lago(..., positions="resolve")``). Both forms: ``position_problem``
(cvxpy, ``cp.sum_squares(W @ (Bᵀp − g))``) and ``resolve_positions`` (sparse closed form).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import partial

import numpy as np
import scipy.sparse as sp

from .sparse import EdgeSystem, Factor, GraphElimination, solve_least_squares
from .stacks import rotate
from .graph import _reduced_incidence, free_poses
from .phases import Lazy, _normal_matrix
from .posegraph import PoseGraph, rot2, wrap_angle
from .solvers import ClarabelSettings, named_constant, parameter, solve
from .uncertainty import EdgeUncertainty

__all__ = ["Positions", "position_system", "position_targets", "position_problem", "resolve_positions", "positions_from_problem",
           "PositionSolver", "isotropic", "Polish", "polish", "MAX_HALVINGS"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Positions:
    """Positions solving (P): ``poses`` (n, 3) = [positions (anchor at ``anchor_position``); θ as given];
    ``info`` sparse (2d, 2d) = MᵀM, the information of the free positions (θ fixed); ``anchor_index``;
    ``factor``/``stats`` of the closed form."""

    poses: np.ndarray
    info: sp.csr_matrix = Lazy()
    anchor_index: int = 0
    factor: Factor | None = None
    stats: dict | None = None


def position_system(graph: PoseGraph, theta, unc: EdgeUncertainty, *, anchor=None, anchor_position=(0.0, 0.0)):
    """The whitened system of (P): ``(W, Bt, g)`` with W (2m × 2m) block-diagonal C_k R(θ_i)ᵀ, Bt = A2ᵀ ⊗ I₂
    (2m × 2d) and g (2m,) = R(θ_i) t_k minus the anchor's fixed position moved to the right, so that (P)
    is ‖W (Bt p − g)‖² over the free positions p (2d,), interleaved in the order of ``free_poses``."""
    theta = np.asarray(theta, dtype=float)
    a = graph.anchor_index(anchor)
    m = graph.n_edges
    g = position_targets(graph, theta, unc, graph.tails == a, graph.heads == a, anchor_position)
    blocks = unc.sqrt_info_pp @ np.swapaxes(rot2(theta[graph.tails]), 1, 2)  # C_k R(θ_i)ᵀ
    k2 = np.stack([2 * np.arange(m), 2 * np.arange(m) + 1], 1)
    W = sp.csr_matrix((blocks.reshape(-1), (np.repeat(k2, 2, axis=1).reshape(-1), np.tile(k2, (1, 2)).reshape(-1))),
                      shape=(2 * m, 2 * m))
    Bt = sp.kron(_reduced_incidence(graph, a).T, sp.identity(2), format="csr")
    return W, Bt, g.reshape(-1)


def position_targets(graph: PoseGraph, theta: np.ndarray, unc: EdgeUncertainty, tail_known: np.ndarray,
                     head_known: np.ndarray, anchor_position=(0.0, 0.0)) -> np.ndarray:
    """The targets of (P), g_k = R(θ_i)(Δˡ_k − h_k e_θ,k) (m, 2) with e_θ,k = wrap(θ_j − θ_i − δ_k) and
    h_k = Ω_pp⁻¹Ω_pθ (eq. (14) when Ω is block-diagonal: h = 0); the anchor's known position moved to the
    right-hand side of p_j − p_i where ``tail_known`` / ``head_known`` (m,) say an end is the anchor."""
    e = wrap_angle(theta[graph.heads] - theta[graph.tails] - graph.delta)
    g = rotate(theta[graph.tails], graph.delta_l - unc.shift * e[:, None])
    p0 = np.asarray(anchor_position, dtype=float).reshape(2)
    return g + (np.asarray(tail_known, float) - np.asarray(head_known, float))[:, None] * p0


def _poses(graph: PoseGraph, theta, a: int, p_free: np.ndarray, anchor_position) -> np.ndarray:
    poses = np.zeros((graph.n_poses, 3))
    poses[:, 2] = theta
    poses[a, :2] = anchor_position
    poses[free_poses(graph.n_poses, a), :2] = p_free.reshape(-1, 2)
    return poses


def isotropic(unc: EdgeUncertainty) -> bool:
    """True when every edge's conditional position information is isotropic, Ω_pp,k = s_k I₂ (exactly):
    then R(θ_i) Ω_pp,k R(θ_i)ᵀ = s_k I₂ for every θ, and (P) splits into two weighted-Laplacian problems,
    one for x and one for y, with the same θ-independent matrix L_s = A2 diag(s) A2ᵀ."""
    C = unc.sqrt_info_pp
    return bool(C.shape[0] == 0 or (np.all(C[:, 0, 1] == 0.0) and np.all(C[:, 0, 0] == C[:, 1, 1])))


class PositionSolver:
    """(P) in closed form for many orientations of one graph (the polish solves it two to five times).

    General information: each θ gives the 2d × 2d system of ``position_system``, factored through the
    pose-level elimination (b = 2). Isotropic translational information (``isotropic``; city10000, the
    M3500 g2o files, every synthetic world with diagonal information): C_k = √s_k I₂, so
    ‖C_k R(θ_i)ᵀ(p_j − p_i − g_k)‖² = s_k ‖p_j − p_i − g_k‖² — (P) is min Σ_k s_k ‖p_j − p_i − g_k‖²,
    two weighted-Laplacian least-squares problems (x and y) with the matrix L_s = A2 diag(s) A2ᵀ
    (d × d) that does not depend on θ: it is factored once (b = 1) and reused for every θ and both
    coordinates. Same minimiser, a quarter of the fill and one factorization instead of one per θ.

    ``solver(theta, anchor_position=(0, 0)) -> Positions``. Built before the orientations are known, it
    tells the elimination which system it will factor (b = 1 isotropic, else 2) and, when isotropic, hands
    the θ-independent factorization over to be done ahead (``GraphElimination.ahead``)."""

    def __init__(self, graph: PoseGraph, unc: EdgeUncertainty, elimination: GraphElimination):
        self.graph, self.unc, self.elim = graph, unc, elimination
        self.isotropic = isotropic(unc)
        self._factor = None
        self._at = []  # (theta, Ahead): orientations whose solve was handed over ahead
        if self.isotropic and elimination.d:
            system = self._isotropic_system(np.zeros((graph.n_edges, 1, 1)))
            self._factor = elimination.ahead(elimination.factor, system)

    def _targets(self, theta: np.ndarray, p0: np.ndarray) -> np.ndarray:
        """(P)'s targets g_k (m, 2) at ``theta``, the anchor's p0 on the right-hand side."""
        return position_targets(self.graph, theta, self.unc, self.elim.tails < 0, self.elim.heads < 0, p0)

    def __call__(self, theta, *, anchor_position=(0.0, 0.0)) -> "Positions":
        return self.many([theta], anchor_position=anchor_position)[0]

    def _isotropic_system(self, c: np.ndarray) -> EdgeSystem:
        """The isotropic system (x and y of every θ as right-hand sides c (m, 1, r)): weights √s_k."""
        m = self.graph.n_edges
        s = self.unc.sqrt_info_pp[:, 0, 0]  # √s_k
        return EdgeSystem(self.elim.tails, self.elim.heads, (-s).reshape(m, 1, 1), s.reshape(m, 1, 1), c,
                          self.elim.d)

    def expect(self, theta) -> None:
        """(P) at ``theta`` and its χ² will be asked for: with isotropic information (one factorization for
        every θ) they are solved ahead, beside the next factorization (``lago``: θ̂ beside phase 3's)."""
        if self.isotropic and self.elim.d:
            theta = np.asarray(theta, dtype=float)
            self._at.append((theta, self.elim.ahead(self._solved_with_cost, theta)))

    def _solved_with_cost(self, theta):
        from .metrics import chi2

        pos = self(theta)
        return pos, chi2(self.graph, pos.poses)

    def expected(self, theta):
        """(Positions, χ²) at ``theta`` when ``expect(theta)`` handed it over, else None."""
        for i, (th, job) in enumerate(self._at):
            if np.array_equal(th, theta):
                del self._at[i]
                return job.result()
        return None

    def _shared_factor(self):
        if self._factor is not None and not isinstance(self._factor, Factor):
            try:
                self._factor = self._factor.result()  # the factorization done ahead
            except Exception as exc:  # redone by the solve, which falls back as it does for any system
                log.info("the positions' factorization done ahead failed (%s): factored again", exc)
                self._factor = None
        return self._factor

    def many(self, thetas, *, anchor_position=(0.0, 0.0)) -> list["Positions"]:
        """(P) for each orientation vector of ``thetas`` (a sequence of (n,)). With isotropic information
        they are right-hand sides of one system, solved together (one refinement for all: x and y of
        every θ, c (m, 1, 2·len(thetas))); otherwise one system per θ."""
        el = self.elim
        p0 = np.asarray(anchor_position, dtype=float).reshape(2)
        thetas = [np.asarray(theta, dtype=float) for theta in thetas]
        if not self.isotropic:
            return [self._general(theta, p0) for theta in thetas]
        m, d = self.graph.n_edges, el.d
        s = self.unc.sqrt_info_pp[:, 0, 0]  # √s_k
        c = np.stack([s[:, None] * self._targets(theta, p0) for theta in thetas], axis=2)  # (m, 2, k)
        system = self._isotropic_system(c.reshape(m, 1, 2 * len(thetas)))
        # factored on the first call (inside solve: with its progress), reused by every later θ
        x, self._factor, stats = el.solve(system, factor=self._shared_factor(), stage="positions")
        x = x.reshape(d, 2, len(thetas))

        info = partial(_isotropic_info, el.tails, el.heads, el.d, s * s)
        return [Positions(_poses(self.graph, theta, el.anchor_index, x[:, :, i].reshape(-1), p0), info,
                          el.anchor_index, self._factor, stats) for i, theta in enumerate(thetas)]

    def _general(self, theta: np.ndarray, p0: np.ndarray) -> "Positions":
        """(P) at one θ with general information: the 2d × 2d system of weights C_k R(θ_i)ᵀ."""
        g, el = self.graph, self.elim
        d = el.d
        Ri, gk = rot2(theta[g.tails]), self._targets(theta, p0)
        Wk = self.unc.sqrt_info_pp @ np.swapaxes(Ri, 1, 2)  # C_k R(θ_i)ᵀ
        system = EdgeSystem(el.tails, el.heads, -Wk, Wk, np.einsum("kab,kb->ka", Wk, gk), d)
        x, factor, stats = el.solve(system, stage="positions")

        return Positions(_poses(g, theta, el.anchor_index, x.reshape(-1), p0), partial(_normal_matrix, system),
                         el.anchor_index, factor,
                         stats)


def _laplacian(t: np.ndarray, h: np.ndarray, d: int, w: np.ndarray) -> sp.csr_matrix:
    """A2 diag(w) A2ᵀ (d × d) on the free poses; ``t``, ``h`` (m,) the edges' free indices (−1: anchor)."""
    both = (t >= 0) & (h >= 0)
    diag = np.bincount(t[t >= 0], w[t >= 0], minlength=d) + np.bincount(h[h >= 0], w[h >= 0], minlength=d)
    return sp.csr_matrix((np.r_[-w[both], -w[both], diag], (np.r_[t[both], h[both], np.arange(d)],
                                                             np.r_[h[both], t[both], np.arange(d)])),
                         shape=(d, d))


def _isotropic_info(t: np.ndarray, h: np.ndarray, d: int, s2: np.ndarray) -> sp.csr_matrix:
    """The information of the free positions (2d × 2d) under isotropic weights s_k: L_s ⊗ I₂."""
    return sp.kron(_laplacian(t, h, d, s2), sp.identity(2), format="csr")


def resolve_positions(graph: PoseGraph, theta, unc: EdgeUncertainty, *, anchor=None, anchor_position=(0.0, 0.0),
                      backend: str = "auto", solver: PositionSolver | None = None) -> Positions:
    """(P) in closed form: the positions minimising χ² for the orientations ``theta`` (n,), the anchor's
    position fixed at ``anchor_position``; one sparse factorization of the 2d × 2d normal matrix with
    corrected semi-normal refinement. ``backend="auto"``: through ``PositionSolver`` (``solver`` reused
    when given: with isotropic information its factorization is shared by every θ); another backend:
    ``linalg.solve_least_squares`` on the sparse system of ``position_system``."""
    a = graph.anchor_index(anchor)
    if backend == "auto":
        if solver is None or solver.elim.anchor_index != a:
            solver = PositionSolver(graph, unc, GraphElimination(graph, a))
        return solver(theta, anchor_position=anchor_position)
    W, Bt, g = position_system(graph, theta, unc, anchor=anchor, anchor_position=anchor_position)
    p, info, factor, stats = solve_least_squares((W @ Bt).tocsc(), W @ g, backend=backend)
    return Positions(_poses(graph, theta, a, p, anchor_position), info.tocsr(), a, factor, stats)


def position_problem(graph: PoseGraph, theta, unc: EdgeUncertainty, *, anchor=None, anchor_position=(0.0, 0.0)):
    """(P) as a cvxpy problem: minimise ‖W (A₂ᵀp − g)‖² over the free positions p (2d,), A₂ = A ⊗ I₂ (A
    the reduced incidence matrix), g the per-edge targets R(θ_i)(Δˡ − Ω_pp⁻¹Ω_pθ ē_θ) and W the square
    root of the conditional information R Ω_pp Rᵀ (eq. (14) when Ω is block-diagonal).

    ``print(problem)`` reads ``minimize quad_over_lin(W @ (A₂ᵀ @ p + -g), 1.0, …)``; g is a
    ``cp.Parameter``. Returns ``(problem, p)``."""
    import cvxpy as cp

    W, Bt, g = position_system(graph, theta, unc, anchor=anchor, anchor_position=anchor_position)
    p = cp.Variable(Bt.shape[1], name="p")
    objective = cp.sum_squares(named_constant(sp.csc_matrix(W), "W")
                               @ (named_constant(sp.csc_matrix(Bt), "A₂ᵀ") @ p - parameter(g, "g")))
    return cp.Problem(cp.Minimize(objective)), p


def positions_from_problem(graph: PoseGraph, theta, unc: EdgeUncertainty, *, anchor=None,
                           anchor_position=(0.0, 0.0), settings: ClarabelSettings | None = None):
    """Build and solve (P) as a cvxpy problem with Clarabel; returns (Positions, problem)."""
    a = graph.anchor_index(anchor)
    problem, p = position_problem(graph, theta, unc, anchor=anchor, anchor_position=anchor_position)
    W, Bt, _ = position_system(graph, theta, unc, anchor=anchor, anchor_position=anchor_position)
    M = W @ Bt
    if p.size == 0:
        return Positions(_poses(graph, theta, a, np.zeros(0), anchor_position), (M.T @ M).tocsr(), a), problem
    solve(problem, settings, what="the position polish")
    pv = np.asarray(p.value, dtype=float)
    return Positions(_poses(graph, theta, a, pv, anchor_position), (M.T @ M).tocsr(), a), problem


# ------------------------------------------------------------------------ after phase 3
#: Step halvings the polish tries when the phase-3 orientations are worse than phase 1's.
MAX_HALVINGS = 3


@dataclass(frozen=True, eq=False)
class Polish:
    """The position polish after phase 3 (``lago(..., positions="resolve")``).

    ``positions`` the solution of (P) at the orientations chosen, θ = θ̂ + α(θ* − θ̂) with ``alpha``
    (1: phase 3's θ*, 0: phase 1's θ̂); ``trials`` the (α, χ²) pairs evaluated, in order."""

    positions: Positions
    alpha: float
    trials: tuple

    @property
    def poses(self) -> np.ndarray:
        return self.positions.poses


def polish(graph: PoseGraph, theta_hat, theta_star, unc: EdgeUncertainty, *, solve_positions, objective=None,
           max_halvings: int = MAX_HALVINGS, solve_many=None, base: "Positions | None" = None,
           base_cost: float | None = None) -> Polish:
    """Positions by (P) at phase 3's orientations θ*, guarded by phase 1's θ̂.

    Let F(θ) = χ²(positions of (P) at θ, θ), the cost with the positions eliminated exactly. Phase 3's
    step θ* − θ̂ is the Gauss–Newton step of eq. (18), taken with the position weights frozen at θ̂; on
    graphs with very anisotropic translational information it can raise the true cost, so that
    F(θ*) > F(θ̂) (no public file in its own cost: there F(θ*) < F(θ̂) and α = 1; CSAIL's g2o file read
    with ``cost="paper"``, its matrices taken as eq. (3)'s: F(θ*) 65.81 > F(θ̂) 63.94, α = 0.5 gives 63.79).
    Then the step is halved (at most ``max_halvings`` times) until F drops below F(θ̂), and the best θ
    seen is kept: F(result) ≤ min(F(θ*), F(θ̂)) ≤ χ²(phase 3) always. Usually F(θ*) ≤ F(θ̂) and the cost
    is two solves of (P). ``solve_positions(theta) -> Positions`` solves (P) (closed
    form or cvxpy); ``solve_many(thetas) -> list[Positions]``, when given, solves the first two trials
    together (``PositionSolver.many``); ``base``, when given, is (P) at θ̂ solved already (``lago``
    solves it beside phase 3's factorization) and ``base_cost`` its cost, when computed already;
    ``objective(poses)`` is the cost compared (default χ²; the variants add their priors)."""
    from .metrics import chi2

    cost = (lambda poses: chi2(graph, poses)) if objective is None else objective
    theta_hat = np.asarray(theta_hat, dtype=float)
    step = np.asarray(theta_star, dtype=float) - theta_hat
    if base is not None:
        best = solve_positions(theta_hat + step)
    elif solve_many is not None:
        best, base = solve_many([theta_hat + step, theta_hat])
    else:
        best, base = solve_positions(theta_hat + step), solve_positions(theta_hat)
    trials = [(1.0, cost(best.poses)), (0.0, cost(base.poses) if base_cost is None else float(base_cost))]
    alpha = 1.0
    if trials[0][1] > trials[1][1]:
        best, alpha = base, 0.0
        a = 1.0
        for _ in range(max_halvings):
            a *= 0.5
            cand = solve_positions(theta_hat + a * step)
            trials.append((a, cost(cand.poses)))
            if trials[-1][1] < trials[1][1]:
                best, alpha = cand, a
                break
    return Polish(best, alpha, tuple(trials))

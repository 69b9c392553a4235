r"""SE-Sync's optimality certificate (Rosen et al. 2019, §4.2) for the cost of eq. (S1), decided by one
sparse LDLᵀ inertia count.

Problem (S1) is min tr(M YᵀY) over Y with R_i ∈ SO(2). Lagrangian of the constraints R_iᵀR_i = I₂ with
symmetric multipliers Λ_i (2×2): L = tr(Y M Yᵀ) − Σ tr(Λ_i(R_iᵀR_i − I)); stationarity gives::

    S Yᵀ = 0,   S = M − Λ̂,   Λ̂ = blkdiag(0, Λ_0, 0, Λ_1, …)  (zeros on translations),            (S6)
    Λ_i = sym( [M YᵀY]_{R_i R_i} ) = sym( (M Yᵀ)_{R_i} R_i )      (SE-Sync's Λ(Y)).                 (S7)

Weak duality: for any Λ with S = M − Λ̂ ⪰ 0 and any feasible Y, f(Y) = tr(S YᵀY) + Σ tr Λ_i ≥ Σ tr Λ_i.
So if Y is a critical point (S6) and S ⪰ 0, then Σ tr Λ_i = f(Y) (the translation rows of (MYᵀ) vanish)
and Y is a **global** minimiser (SE-Sync Theorem 7, our S is theirs before translation elimination).

Schur complement. With L_τ = M_tt (the τ-weighted Laplacian, n × n) and
Q = M_RR − M_Rt L_τ⁺ M_tR (2n × 2n, dense — SE-Sync's translation-free data matrix),
S ⪰ 0 ⟺ S_Q = Q − Λ ⪰ 0 (Haynsworth: the translation block of S is L_τ ⪰ 0 and M 1_t = 0).
Grounding the anchor's translation column gives S_g (3n−1) and, for every σ,
In(S_g − σ Î_R) = In(L_g) + In(S_Q − σI) with L_g ≻ 0 the grounded Laplacian (Î_R = identity on rotation
indices, 0 on translations). So **one sparse LDLᵀ of S_g + ηÎ_R (QDLDL, AMD ordering) counts the
eigenvalues of S_Q below −η**: zero negative pivots proves λ_min(S_Q) ≥ −η, i.e. S + ηÎ_R ⪰ 0. The
spectrum of S_Q near its bottom comes from shift-invert Lanczos on b ↦ [(S_g − σÎ_R)⁻¹(0; b)]_R with σ
below λ_min (found by inertia bisection, started from the bound λ_min ≥ −max_i λ_max(Λ_i) since Q ⪰ 0).
At a certified optimum S_Q has exactly the two null vectors Y_Rᵀ (its third eigenvalue is the margin).
The full S has a third, structural null vector 1_t; its λ_min is computed the same way without grounding.

``certify`` first replaces the translations by the optimal ones for the given rotations (one linear
solve, as SE-Sync eliminates them), so Σ tr Λ_i = f exactly and the verdict is about the rotations.

Tolerances. Two numbers, with different jobs.

* The **numerical floor** η = ``NUMERICAL_TOL``·‖M‖₂ (‖M‖₂ by Lanczos; NUMERICAL_TOL = 1e-12):
  floating-point S is known only to ~1e-16‖M‖ entrywise and the LDLᵀ is backward stable only to a
  modest multiple of that, so no eigenvalue of S_Q above −η can be told from zero. The inertia count
  of S_g + ηÎ_R proves λ_min(S_Q) ≥ −η, hence the dual-feasible shift below. The optima of the SE-Sync
  datasets have λ_min(S_Q) ≈ ±5e-13 (absolute) and pass even at 1e-15.
* The **decision** is relative to the cost's scale: the point is *certified* only when the proven
  relative suboptimality (f − f*_lower)/f is at most ``tol`` (default ``CERTIFY_TOL`` = 1e-3), with
  f*_lower the lower bound of eq. (S8) below. f − f*_lower = (f − Σ tr Λ_i) + 2n·|shift| counts both the
  distance from a critical point and the floor, so a point whose cost is tiny next to ‖M‖ (a nearly
  noise-free graph: f ≈ 1e-4 with ‖M‖ ≈ 1e5) is "not certified: bound too weak" rather than certified
  with a vacuous bound. At the default, the datasets' optima are certified with bounds of 4e-6 (CSAIL)
  … 1e-7 (city10000). A point whose cost is above a cost known to be reachable (``known_cost``) is
  never certified.

Lower bound when the certificate fails. With μ = max(0, −λ_min(S_Q)), Λ' = Λ − μI makes
Q − Λ' = S_Q + μI ⪰ 0, i.e. Λ' is dual feasible, so

    f* ≥ d(Λ') = Σ tr Λ_i − 2nμ                                                                       (S8)

(made rigorous by using μ + η). At a suboptimal critical point this bound is valid but usually weak
(2n·μ); the SDP optimum (section 4) is the best such bound.

"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..conventions import CERTIFY_TOL
from ..errors import GraphError, OptionError, SolverError
from ..graph import check_connected
from ..optimality import ProvenBound, absolute_test, check_abs_tol, relative_suboptimality
from ..posegraph import PoseGraph
from ..reports import Summary, fmt_timings, short_repr
from .sesync import (data_matrix, grounded_index, lambda_hat, multipliers, optimal_translations, sesync_cost,
                     stacked_variable)

__all__ = ["CERTIFY_TOL", "NUMERICAL_TOL", "Certificate", "certify", "dual_lower_bound"]

log = logging.getLogger("lago_cvx.certification")


#: Below this dimension the shift-inverted operator is formed densely instead of running Lanczos.
DENSE_LIMIT = 64

#: Numerical floor of the PSD test, relative to ‖M‖₂: η = NUMERICAL_TOL·‖M‖₂. Measured: the optima of the
#: five SE-Sync datasets still pass at 1e-15 (their computed λ_min(S_Q) is ≈ −5e-13, i.e. ~1e-17‖M‖);
#: 1e-12 leaves three orders of magnitude for rounding in S and in the factorization.
NUMERICAL_TOL = 1e-12


class _ShiftedLDL:
    """K(σ) = K0 − σ·diag(D) (K0 sparse symmetric (N, N), D (N,) of 0/1) factored by QDLDL (AMD
    ordering, no pivoting) with a fixed pattern: ``inertia(σ)`` returns the number of negative pivots of
    LDLᵀ, i.e. (Sylvester) the number of negative eigenvalues of K(σ); ``solve`` uses the last factor."""

    def __init__(self, K0: sp.spmatrix, D: np.ndarray):
        import qdldl

        K0 = sp.csc_matrix(K0)
        N = K0.shape[0]
        U = sp.triu(K0 + sp.eye(N, format="csc"), format="csc")  # the +I forces every diagonal entry
        U.sort_indices()
        self.diag_pos = U.indptr[1:] - 1  # last entry of each column of an upper-triangular CSC
        self.diag0 = K0.diagonal()
        self.D = np.asarray(D, dtype=float)
        U.data[self.diag_pos] = self.diag0
        self.U = U
        self._qdldl = qdldl
        self._solver = None
        self.sigma = None

    def inertia(self, sigma: float) -> int:
        """Number of negative eigenvalues of K(σ) (a zero pivot counts as negative: K(σ) not ≻ 0)."""
        self.U.data[self.diag_pos] = self.diag0 - sigma * self.D
        try:
            if self._solver is None:
                self._solver = self._qdldl.Solver(self.U, upper=True)
            else:
                self._solver.update(self.U, upper=True)
        except Exception:  # QDLDL stops at an exactly zero pivot
            self._solver, self.sigma = None, None
            return 1
        self.sigma = sigma
        d = self._solver.factors()[1]
        return int(np.count_nonzero(~(d > 0)))

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._solver.solve(np.ascontiguousarray(b, dtype=float))


def _bottom_eigenvalues(ldl: _ShiftedLDL, sel: np.ndarray, *, lower: float, upper: float, k: int,
                        negative_at_upper: int, rel_width: float = 0.05, max_bisections: int = 60):
    """The k smallest eigenvalues of the operator T with (T − σI)⁻¹ b = [K(σ)⁻¹ E b]_sel (E the
    embedding of ``sel`` into ℝ^N): T = S_Q for the grounded reduced certificate, T = S for the full one.

    ``lower`` is a proven lower bound of λ_min(T); ``upper`` a shift at which ``negative_at_upper``
    eigenvalues lie below. If that count is positive, the bracket [lower, upper] is bisected with
    inertia counts until its width is ``rel_width``·|upper| (λ_min is then the dominant eigenvalue of
    the shift-inverted operator and Lanczos converges in a few steps); otherwise σ = upper − |upper|
    (= −2η) is used, just below the proven bound λ_min ≥ −η. Returns (eigenvalues ascending (k,), σ used)."""
    if negative_at_upper > 0:
        lo, hi = lower, upper
        for _ in range(max_bisections):
            if hi - lo <= rel_width * abs(hi):
                break
            mid = 0.5 * (lo + hi)
            if ldl.inertia(mid) == 0:
                lo = mid
            else:
                hi = mid
        sigma = lo
    else:
        sigma = upper - abs(upper)  # upper = −η: σ = −2η < λ_min
    if ldl.inertia(sigma) != 0:  # should not happen: lower is a proven bound
        raise SolverError(f"certificate: K(σ) is not positive definite at σ = {sigma:.3g}")
    N = ldl.U.shape[0]
    d = sel.size
    k = max(1, min(k, d - 1))

    def op(b):
        full = np.zeros(N)
        full[sel] = np.ravel(b)
        return ldl.solve(full)[sel]

    if d <= DENSE_LIMIT:  # small: the whole shift-inverted operator, column by column
        T = np.column_stack([op(e) for e in np.eye(d)])
        nu = np.linalg.eigvalsh(0.5 * (T + T.T))[::-1][:k]
    else:
        A = spla.LinearOperator((d, d), matvec=op, dtype=float)
        v0 = np.random.default_rng(0).standard_normal(d)
        nu = spla.eigsh(A, k=k, which="LA", v0=v0, return_eigenvectors=False, tol=1e-12)
    return np.sort(sigma + 1.0 / nu), sigma


@dataclass(eq=False)
class Certificate(ProvenBound):
    """Outcome of ``certify`` (see the module docstring, section 3).

    ``certified`` — True iff the proven relative suboptimality ``relative_suboptimality_bound`` =
    (f − ``lower_bound``)/f is at most ``tol`` (and f is not above ``known_cost``);
    ``verdict`` — one line saying so or why not ("not certified: bound too weak" when S_Q passes the
    PSD test but the bound it proves is larger than ``tol``). ``tol`` the relative tolerance used, ``abs_tol`` the
    absolute one (0: none; ``optimality.absolute_test``).
    ``cost`` f at the certified point (translations re-optimised for the given rotations when
    ``optimize_translations``; ``cost_input`` at the poses as given); ``poses`` that point (n, 3).
    ``dual_value`` Σ tr Λ_i (= ``cost`` when translations are optimal); ``multipliers`` Λ (n, 2, 2).
    ``lambda_min`` λ_min(S_Q) (SE-Sync's certificate matrix, translations eliminated) by shift-invert
    Lanczos; ``eigenvalues`` the ``n_eigenvalues`` smallest of S_Q (at an optimum two are ≈ 0, the
    third is the margin); ``lambda_min_full`` λ_min(S) of the full 3n × 3n S (≤ 0 always: S 1_t = 0;
    NaN unless ``full``). ``eta`` = NUMERICAL_TOL·‖M‖₂, ``norm_M`` ‖M‖₂; ``n_negative`` eigenvalues of S_Q below
    −η (inertia count). ``residual`` ‖S Yᵀ‖_F (first-order condition (S6)), ``residual_rel`` =
    residual/(‖M‖₂ √(2n)). ``lower_bound`` a proven lower bound on f* (eq. (S8) with the shift ``shift``:
    Λ + shift·I is dual feasible), ``suboptimality_bound`` = cost − lower_bound, and
    ``suboptimality_estimate`` = 2n·max(0, −λ_min) (to Lanczos accuracy, SE-Sync's number).
    ``times`` seconds per step."""

    cost_input: float
    eigenvalues: np.ndarray
    lambda_min_full: float
    norm_M: float
    residual: float
    suboptimality_bound: float
    suboptimality_estimate: float
    poses: np.ndarray
    multipliers: np.ndarray
    tol: float = CERTIFY_TOL
    abs_tol: float = 0.0
    times: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        """A few lines whatever the size: verdict, f and the proven bound, the spectrum's bottom, time."""
        n = self.poses.shape[0]
        return short_repr("Certificate", f"{'CERTIFIED globally optimal' if self.certified else 'NOT certified'}: "
                          f"{n} poses", [
                              f"f = {self.cost:.10g} (SE-Sync cost at the given rotations, translations "
                              f"re-optimised; {self.cost_input:.10g} at the poses as given)",
                              f"proven f* ≥ {self.lower_bound:.10g}: (f − bound)/f ≤ "
                              f"{self.relative_suboptimality_bound:.3g}, tol {self.tol:.3g}",
                              f"λ_min(S_Q) = {self.lambda_min:.3g}, η = {self.eta:.3g}, {self.n_negative} "
                              f"eigenvalue(s) below −η; ‖SYᵀ‖ = {self.residual:.3g}",
                              "time " + fmt_timings(self.times)])

    def summary(self) -> Summary:
        """The certificate's numbers as a dict that prints as a small table."""
        return Summary("Certificate (SE-Sync, Rosen et al. 2019)", [
            ("certified", "certified", bool(self.certified)), ("n_poses", "poses", int(self.poses.shape[0])),
            ("f", "f, translations re-optimised", self.cost), ("f_input", "f at the poses as given", self.cost_input),
            ("lower_bound", "proven f* ≥", self.lower_bound),
            ("relative_suboptimality_bound", "(f − bound)/f ≤", self.relative_suboptimality_bound),
            ("tol", "tol", self.tol), ("lambda_min", "λ_min(S_Q)", self.lambda_min), ("eta", "floor η", self.eta),
            ("n_negative", "eigenvalues < −η", int(self.n_negative)), ("residual", "‖SYᵀ‖", self.residual),
        ], timings=self.times)




def _norm2(M: sp.spmatrix) -> float:
    """‖M‖₂ = λ_max(M) for the PSD M (Lanczos, 1e-6 relative; dense for tiny M)."""
    if M.shape[0] <= DENSE_LIMIT:
        return float(np.linalg.eigvalsh(M.toarray())[-1])
    v0 = np.ones(M.shape[0])
    return float(spla.eigsh(M, k=1, which="LA", v0=v0, tol=1e-6, return_eigenvectors=False)[0])


def certify(graph: PoseGraph, poses, *, tol: float = CERTIFY_TOL, abs_tol: float = 0.0,
            optimize_translations: bool = True, anchor=None, n_eigenvalues: int = 3, full: bool = True,
            known_cost: float | None = None) -> Certificate:
    """SE-Sync's verification (Rosen et al. 2019, §4.2) of ``poses`` (n, 3) for the cost of eq. (S1).

    Keyword-only: ``tol`` the largest relative suboptimality bound (f − f*_lower)/f accepted as certified
    (0 < tol ≤ ``CERTIFY_TOL`` = 1e-3; the PSD test itself uses the floor η = ``NUMERICAL_TOL``·‖M‖₂, see
    the module docstring); ``abs_tol`` ≥ 0 an absolute threshold, as SE-Sync's (0, the default: none): the point
    is also certified when the proven gap f − f*_lower ≤ ``abs_tol`` or λ_min(S_Q) ≥ −``abs_tol`` (proven by an
    inertia count; ``absolute_test``), which is what a nearly noise-free graph, whose f is tiny next to ‖M‖, can
    pass; ``known_cost`` a cost known to be reachable (e.g. of a refined estimate): a
    point above it is never certified; ``optimize_translations`` replace the translations by the optimal
    ones for the given rotations first (exact linear solve; then Σ tr Λ_i = f and the certificate is on
    the rotations, as in SE-Sync); ``anchor`` pose id whose translation is grounded (default the
    smallest id); ``n_eigenvalues`` how many of S_Q's smallest eigenvalues to report; ``full`` also
    compute λ_min of the full S.

    Cost: one sparse LDLᵀ of S_g + ηÎ_R (3n−1 square) for the verdict, a few more (same pattern) for
    the spectrum; city10000 (30 000 × 30 000) takes about a second.

    ``poses`` may be a result (its ``poses``). A 3-D graph goes to ``lago_cvx.space.certify.certify3d`` with
    ``tol`` and ``anchor`` (``poses`` a pair (t, R) or a 3-D result)."""
    if not (0 < tol <= CERTIFY_TOL):
        raise OptionError(f"tol must be in (0, {CERTIFY_TOL:g}] (a relative suboptimality bound), got {tol}")
    check_abs_tol(abs_tol)
    if getattr(graph, "dim", 2) == 3:
        from ..space.certify import certify3d

        return certify3d(graph, poses, tol=tol, abs_tol=abs_tol, anchor=anchor)
    poses = poses.poses if hasattr(poses, "poses") and not isinstance(poses, np.ndarray) else poses
    if graph.n_edges == 0:
        raise GraphError(f"the graph has {graph.n_poses} pose(s) and no edges: nothing to certify")
    times = {}
    t_all = time.perf_counter()
    poses_in = graph.check_poses(poses)
    check_connected(graph)
    a = graph.anchor_index(anchor)
    n = graph.n_poses
    cost_input = sesync_cost(graph, poses_in)
    x = poses_in.copy()
    t = time.perf_counter()
    if optimize_translations:
        x[:, :2] = optimal_translations(graph, x[:, 2], anchor=int(graph.ids[a]), anchor_translation=x[a, :2])
    times["translations"] = time.perf_counter() - t
    t = time.perf_counter()
    M = data_matrix(graph)
    Y = stacked_variable(x)
    lam = multipliers(M, Y)
    S = (M - lambda_hat(lam)).tocsr()
    cost = sesync_cost(graph, x)  # a sum of squares (≥ 0), not tr(Y M Yᵀ), which cancels to ±1e-11 near 0
    dual = float(np.trace(lam, axis1=1, axis2=2).sum())
    residual = float(np.linalg.norm(S @ Y.T))
    norm_M = _norm2(M)
    eta = NUMERICAL_TOL * norm_M
    times["assemble"] = time.perf_counter() - t

    # the verdict: inertia of S_g + ηÎ_R (grounded), = In(L_g) + In(S_Q + ηI)
    t = time.perf_counter()
    keep = grounded_index(n, a)
    Sg = S[keep][:, keep]
    is_rot = (keep % 3 != 0).astype(float)
    ldl = _ShiftedLDL(Sg, is_rot)
    n_negative = ldl.inertia(-eta)
    times["inertia"] = time.perf_counter() - t

    # the spectrum of S_Q near its bottom; Q ⪰ 0 gives λ_min(S_Q) ≥ −max_i λ_max(Λ_i)
    t = time.perf_counter()
    lam_max = float(np.linalg.eigvalsh(lam)[:, -1].max()) if n else 0.0
    lower = -max(lam_max, 0.0) - eta - 1e-12 * norm_M
    eigs, _ = _bottom_eigenvalues(ldl, np.flatnonzero(is_rot), lower=lower, upper=-eta, k=n_eigenvalues,
                                  negative_at_upper=n_negative)
    lambda_min = float(eigs[0])
    if n_negative == 0:
        shift = -eta
    else:  # a proven shift: largest bisection point below λ_min, verified by inertia
        shift = lambda_min - eta
        if ldl.inertia(shift) != 0:
            shift = lower
    times["spectrum"] = time.perf_counter() - t

    lambda_min_full = float("nan")
    if full:
        t = time.perf_counter()
        ldl_full = _ShiftedLDL(S, np.ones(3 * n))
        neg_full = ldl_full.inertia(-eta)
        eig_full, _ = _bottom_eigenvalues(ldl_full, np.arange(3 * n), lower=lower, upper=-eta, k=1,
                                          negative_at_upper=neg_full)
        lambda_min_full = float(eig_full[0])
        times["spectrum_full"] = time.perf_counter() - t

    lower_bound = max(dual + 2 * n * shift, 0.0)  # f ≥ 0: a negative bound says nothing more than 0
    sub_bound = cost - lower_bound
    sub_est = 2 * n * max(0.0, -lambda_min)
    residual_rel = residual / max(norm_M * np.sqrt(2 * n), np.finfo(float).tiny)
    rel = relative_suboptimality(cost, lower_bound)
    above_known = known_cost is not None and cost > known_cost * (1 + 1e-9) + np.finfo(float).tiny
    absolute = None if above_known or rel <= tol else absolute_test(
        sub_bound, abs_tol, eta, lambda: ldl.inertia(-abs_tol) == 0)
    certified = bool((rel <= tol or absolute is not None) and not above_known)
    kind = ("not a critical point" if residual_rel > np.sqrt(NUMERICAL_TOL) else "approximately a critical point")
    if absolute is not None:
        verdict = (f"globally optimal within the absolute tolerance {abs_tol:.3g} (certified): {absolute}; "
                   f"relative bound {rel:.2g} > tol {tol:.2g}")
    elif certified:
        verdict = (f"globally optimal (certified): f − f* ≤ {sub_bound:.3g} ({rel:.2g} relative ≤ tol {tol:.2g}); "
                   f"λ_min(S_Q) = {lambda_min:.3g} ≥ −η = {-eta:.3g}")
    elif above_known:
        verdict = (f"not certified: f = {cost:.10g} is above the cost {known_cost:.10g} of a point already found "
                   f"(proven f* ≥ {lower_bound:.6g})")
    elif n_negative == 0:
        verdict = (f"not certified: bound too weak: λ_min(S_Q) ≥ −η = {-eta:.3g} proves only f − f* ≤ "
                   f"{sub_bound:.3g} ({rel:.2g} relative > tol {tol:.2g}; {kind}, ‖SYᵀ‖ = {residual:.3g})")
    else:
        verdict = (f"NOT certified ({kind}, ‖SYᵀ‖ = {residual:.3g}): {n_negative} eigenvalue(s) of S_Q below "
                   f"−η = {-eta:.3g}, λ_min = {lambda_min:.4g}; f* ≥ {lower_bound:.6g}")
    times["total"] = time.perf_counter() - t_all
    log.info("certify: %s (%.3f s)", verdict, times["total"])
    return Certificate(certified=certified, verdict=verdict, cost=cost, cost_input=cost_input, dual_value=dual,
                       lambda_min=lambda_min, eigenvalues=eigs, lambda_min_full=lambda_min_full, eta=eta,
                       norm_M=norm_M, n_negative=n_negative, residual=residual, residual_rel=residual_rel,
                       lower_bound=lower_bound, shift=shift, suboptimality_bound=sub_bound,
                       suboptimality_estimate=sub_est, poses=x, multipliers=lam, tol=tol, abs_tol=abs_tol,
                       times=times)


def dual_lower_bound(graph: PoseGraph, lam: np.ndarray, a: int) -> float:
    """A proven lower bound on f* from any multipliers ``lam`` (n, 2, 2), anchor index ``a``:
    Σ tr Λ_i + 2n·min(0, σ) with σ ≤ λ_min(S_Q(Λ)) proven by an LDLᵀ inertia count (eq. (S8); σ = −η
    with η = NUMERICAL_TOL·‖M‖₂ when S_Q(Λ) ⪰ −ηI, else just below the Lanczos λ_min). A graph without
    edges (e.g. the 2-core of a tree: the anchor alone) has f ≡ 0, so its bound is 0."""
    n = graph.n_poses
    if graph.n_edges == 0:
        return 0.0
    M = data_matrix(graph)
    S = (M - lambda_hat(lam)).tocsr()
    keep = grounded_index(n, a)
    is_rot = (keep % 3 != 0).astype(float)
    ldl = _ShiftedLDL(S[keep][:, keep], is_rot)
    norm_M = _norm2(M)
    eta = NUMERICAL_TOL * norm_M
    neg = ldl.inertia(-eta)
    dual = float(np.trace(lam, axis1=1, axis2=2).sum())
    if neg == 0:
        return dual - 2 * n * eta
    lam_max = float(np.linalg.eigvalsh(lam)[:, -1].max())
    lower = -max(lam_max, 0.0) - eta - 1e-12 * norm_M
    eigs, sigma = _bottom_eigenvalues(ldl, np.flatnonzero(is_rot), lower=lower, upper=-eta, k=1,
                                      negative_at_upper=neg)
    shift = float(eigs[0]) - 1e-3 * abs(float(eigs[0])) - eta
    if ldl.inertia(shift) != 0:
        shift = sigma
    return dual + 2 * n * min(shift, 0.0)

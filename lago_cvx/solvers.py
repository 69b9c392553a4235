"""Solver settings (frozen dataclasses) and the one place a cvxpy problem is solved with Clarabel.

Every cvxpy route of lago_cvx — phases 1 and 3, the chordal relaxation, the constrained and robust
variants, the SDP relaxation — calls ``solve``, which runs Clarabel with a ``ClarabelSettings`` and
checks the status the same way everywhere: ``optimal`` passes, ``optimal_inaccurate`` passes with a
warning, anything else raises ``SolverError`` naming the status (unless the caller lists it in
``allow``, e.g. to diagnose infeasible constraints).

cvxpy is imported only inside the functions that build or solve a problem: ``import lago_cvx`` and the
closed-form route never load it.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from .errors import OptionError, SolverError, check_integer, check_real

__all__ = [
    "named_constant", "parameter",
    "METHODS", "ClarabelSettings", "LEAST_SQUARES", "ROBUST", "SDP", "IntegerSearch",
    "OK_STATUSES", "INFEASIBLE_STATUSES", "solve", "check_method",
]

log = logging.getLogger(__name__)

#: The two routes of every phase: ``"closed_form"`` (sparse factorizations) and ``"cvxpy"`` (the explicit
#: convex problem, solved by Clarabel).
METHODS = ("closed_form", "cvxpy")

#: cvxpy statuses accepted as a solution (the second with a warning).
OK_STATUSES = ("optimal", "optimal_inaccurate")
#: cvxpy statuses of an infeasible problem.
INFEASIBLE_STATUSES = ("infeasible", "infeasible_inaccurate")


def check_method(method: str) -> None:
    """Raise ``OptionError`` unless ``method`` is one of ``METHODS``."""
    if method not in METHODS:
        raise OptionError(f"unknown method {method!r}; expected one of {METHODS}")


@dataclass(frozen=True)
class ClarabelSettings:
    """Clarabel options (names as in Clarabel's ``DefaultSettings``). A field left ``None`` takes the
    value of the preset of the route that solves (``LEAST_SQUARES`` for phases 1 and 3 and the chordal
    relaxation, ``ROBUST`` for robust losses, ``SDP`` for the relaxation), and where the preset leaves
    it ``None`` too, Clarabel's own default. ``verbose`` prints Clarabel's log. ``direct_solve_method``
    picks Clarabel's KKT factorization (``"qdldl"``, ``"faer"``, …; None = Clarabel's choice): problems with
    equality constraints on top of a least-squares objective (e.g. a residual written as a constraint)
    may need ``"qdldl"`` with ``static_regularization_constant=1e-8``."""

    static_regularization_constant: float | None = None
    direct_solve_method: str | None = None
    iterative_refinement_enable: bool | None = None
    iterative_refinement_reltol: float | None = None
    iterative_refinement_abstol: float | None = None
    iterative_refinement_max_iter: int | None = None
    tol_gap_abs: float | None = None
    tol_gap_rel: float | None = None
    tol_feas: float | None = None
    max_iter: int | None = None
    chordal_decomposition_enable: bool | None = None
    chordal_decomposition_merge_method: str | None = None
    chordal_decomposition_compact: bool | None = None
    chordal_decomposition_complete_dual: bool | None = None
    verbose: bool | None = None

    def __post_init__(self):
        for f in fields(self):  # None, or a value of the field's kind (Clarabel would refuse it only when solving)
            v, kind = getattr(self, f.name), str(f.type)
            if v is None:
                continue
            if kind.startswith("bool"):
                if not isinstance(v, (bool, np.bool_)):
                    raise OptionError(f"ClarabelSettings.{f.name} must be None, True or False, got {v!r}")
                object.__setattr__(self, f.name, bool(v))
            elif kind.startswith("int"):
                object.__setattr__(self, f.name, check_integer(f"ClarabelSettings.{f.name}", v, low=1))
            elif kind.startswith("float"):
                object.__setattr__(self, f.name, check_real(f"ClarabelSettings.{f.name}", v, low=0.0, open_low=False))
            elif not isinstance(v, str):
                raise OptionError(f"ClarabelSettings.{f.name} must be None or a name, got {v!r}")

    def over(self, preset: "ClarabelSettings | None") -> "ClarabelSettings":
        """These settings with every ``None`` field taken from ``preset``."""
        if preset is None:
            return self
        return replace(preset, **{f.name: getattr(self, f.name) for f in fields(self)
                                  if getattr(self, f.name) is not None})

    def solver_kwargs(self) -> dict:
        """Keyword arguments for ``problem.solve(solver=cp.CLARABEL, ...)`` (``None`` fields dropped)."""
        return {k: v for k, v in asdict(self).items() if v is not None and k != "verbose"}


#: Phases 1 and 3 and the chordal relaxation. Clarabel's defaults (static regularization 1e-8, gaps
#: 1e-8) leave ~1e-7 relative disagreement with the closed form on large graphs; a tiny static
#: regularization plus iterative refinement and tight tolerances give ~1e-12 agreement.
LEAST_SQUARES = ClarabelSettings(
    static_regularization_constant=1e-11, iterative_refinement_enable=True, iterative_refinement_reltol=1e-15,
    iterative_refinement_abstol=1e-15, iterative_refinement_max_iter=50, tol_gap_abs=1e-12, tol_gap_rel=1e-12,
    tol_feas=1e-12, max_iter=100)

#: Robust (Huber / ℓ1) variants: their second-order-cone structure cannot reach the 1e-12 gaps of
#: ``LEAST_SQUARES`` (Clarabel then reports "inaccurate"); 1e-9 is ample for an estimate whose
#: statistical error is ~1e-2.
ROBUST = replace(LEAST_SQUARES, tol_gap_abs=1e-9, tol_gap_rel=1e-9, tol_feas=1e-9,
                 static_regularization_constant=1e-8)

#: The SDP relaxation. Not ``LEAST_SQUARES``: a static regularization of 1e-11 and 1e-12 tolerances make
#: Clarabel fail on these SDPs; at its defaults (1e-8) it stops at the accuracy the data allow. Chordal
#: decomposition is Clarabel's default; the clique merging is "parent_child" because the default
#: "clique_graph" merge did not finish on the first 200 poses of manhattan where parent_child did
#: (``benchmarks/certify.md``).
SDP = ClarabelSettings(max_iter=300, chordal_decomposition_enable=True,
                       chordal_decomposition_merge_method="parent_child",
                       chordal_decomposition_complete_dual=True)


@dataclass(frozen=True)
class IntegerSearch:
    """How ``regularization="integer"`` searches the cycle integers (``lago_cvx.regularization.integer``).

    ``solver`` — ``"enumerate"`` (exact sphere decoding, no dependency), ``"SCIP"`` (mixed-integer
    cvxpy problem, ``pip install "lago-cvx[mip]"``) or another cvxpy mixed-integer solver name; ``None``
    lets the caller decide (``lago``: the enumeration for the closed form, SCIP for ``method="cvxpy"``).
    ``form`` — ``"cycle"`` (eq. (3) of that module, l integers) or ``"phase1"`` (θ and k; slow beyond a
    few dozen poses); the enumeration always uses the cycle form. ``time_limit`` — seconds for the MIP
    solver. ``max_nodes`` — node budget of the enumeration (``SearchLimitError`` beyond it).
    ``max_shift`` — optional extra box |k − k_round| ≤ max_shift. ``exact`` — impose the exact box that
    contains every optimum (default); ``exact=False`` (with ``max_shift``) searches the plain box, to check
    that the exact box loses nothing. ``solver_options`` — extra keyword arguments for
    ``problem.solve`` (for SCIP, ``scip_params`` is merged with the time limit)."""

    solver: str | None = None
    form: str = "cycle"
    time_limit: float = 60.0
    max_nodes: int = 2_000_000
    max_shift: int | None = None
    exact: bool = True
    solver_options: Mapping = field(default_factory=dict, hash=False)  # a dict: settings hash without it

    def __post_init__(self):
        if self.form not in ("cycle", "phase1"):
            raise OptionError(f"unknown form {self.form!r}; expected 'cycle' or 'phase1'")
        if not (self.solver is None or isinstance(self.solver, str)):
            raise OptionError(f"solver must be None or a name, got {self.solver!r}")
        object.__setattr__(self, "time_limit", check_real("time_limit", self.time_limit, low=0.0))
        object.__setattr__(self, "max_nodes", check_integer("max_nodes", self.max_nodes, low=1))
        object.__setattr__(self, "max_shift", check_integer("max_shift", self.max_shift, low=0, optional=True))
        if not self.exact and self.max_shift is None:
            raise OptionError("exact=False needs max_shift (the integers would be unbounded)")


def _settings(settings, preset: ClarabelSettings) -> ClarabelSettings:
    if settings is None:
        return preset
    if not isinstance(settings, ClarabelSettings):
        raise OptionError(f"solver settings must be a lago_cvx.ClarabelSettings, got {type(settings).__name__}")
    return settings.over(preset)


def solve(problem, settings: ClarabelSettings | None = None, *, preset: ClarabelSettings = LEAST_SQUARES,
          what: str = "the problem", allow: tuple = ()) -> str:
    """Solve the cvxpy ``problem`` with Clarabel (``settings`` over ``preset``) and return its status.

    ``optimal`` passes; ``optimal_inaccurate`` passes with a warning naming ``what``; a status in
    ``allow`` (e.g. ``INFEASIBLE_STATUSES``) is returned for the caller to handle; anything else — and a
    solver crash — raises ``SolverError`` naming ``what`` and the status."""
    import cvxpy as cp

    opts = _settings(settings, preset)
    try:
        with warnings.catch_warnings():  # cvxpy's "solution may be inaccurate": the status says it
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            problem.solve(solver=cp.CLARABEL, verbose=bool(opts.verbose), **opts.solver_kwargs())
    except cp.error.SolverError as exc:
        raise SolverError(f"Clarabel failed on {what}: {exc}", "solver_error") from None
    status = problem.status
    # Clarabel's solver object, kept by cvxpy for a re-solve, is engine state that cannot be pickled or
    # copied: dropped, so that results holding their problems can be (a re-solve builds it again).
    getattr(problem, "_solver_cache", {}).clear()
    if status in allow:
        return status
    if status not in OK_STATUSES:
        raise SolverError(f"Clarabel did not solve {what}: status {status!r}", status)
    if status == "optimal_inaccurate":
        log.warning("Clarabel reports an inaccurate solution for %s (status %s)", what, status)
    return status


# --------------------------------------------------------------------- readable cvxpy problems
def named_constant(value, label: str):
    """A cvxpy constant (dense or scipy.sparse ``value``) that ``print(problem)`` shows as ``label``, so
    that a problem reads like its equation: ``minimize quad_over_lin(W @ (z + -(Bᵀ @ ρ)), 1.0, …)`` (cvxpy
    writes ‖v‖² = ``sum_squares(v)`` as ``quad_over_lin(v, 1)``). The value is used as given."""
    from .cvxpy_names import NamedConstant

    return NamedConstant(value, label)


def parameter(value, label: str, **attributes):
    """A named ``cp.Parameter`` holding ``value`` (1-D or 2-D, dense): change ``.value`` and re-solve without
    rebuilding the problem (the builders keep their problems DPP)."""
    import cvxpy as cp
    import numpy as np

    value = np.asarray(value, dtype=float)
    par = cp.Parameter(value.shape, name=label, **attributes)
    par.value = value
    return par

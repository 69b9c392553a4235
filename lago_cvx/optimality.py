r"""What an optimality certificate proves, the planar one (``certification.certificate``) and the 3-D one
(``space.certify``) alike: a proven lower bound f*_lower ≤ f* on the optimal cost and, from it, the relative
suboptimality of the point certified,

    (f − f*_lower) / f,  f ≥ 0,

which the point is *certified* by when it is at most ``tol`` (``conventions.CERTIFY_TOL``). A relative test can never
pass on a nearly noise-free graph: f is then tiny next to the numerical floor's contribution d·n·η to the gap (f ≈ 2e-4
with a relative gap of 0.6). SE-Sync's own test is absolute; ``absolute_test`` offers it beside the relative one: with
``abs_tol`` > 0 the point is also certified when the proven gap f − f*_lower ≤ abs_tol, or when λ_min(S) ≥ −abs_tol
is proven (then Λ − abs_tol·I is dual feasible and f* ≥ Σ tr Λ_i − d·n·abs_tol: a weaker statement, SE-Sync's; it is
tried only when abs_tol is at least the numerical floor η, below which no inertia count can prove it). ``ProvenBound`` holds
the numbers both certificates report, in this order; each adds its own fields after them.
"""

from __future__ import annotations

from dataclasses import dataclass

import math
from typing import Callable

from .errors import OptionError

__all__ = ["relative_suboptimality", "check_abs_tol", "absolute_test", "ProvenBound"]


def relative_suboptimality(cost: float, lower_bound: float) -> float:
    """(f − f*_lower)/f, scalars, with f ≥ 0: a zero cost gives 0 when the bound reaches it, else +inf (also +inf
    for f*_lower = −inf, no bound proven)."""
    gap = cost - lower_bound
    if cost > 0:
        return gap / cost
    return 0.0 if gap <= 0 else float("inf")


def check_abs_tol(abs_tol: float) -> None:
    """``OptionError`` unless ``abs_tol`` is a finite number ≥ 0 (0: no absolute test)."""
    if not (isinstance(abs_tol, (int, float)) and math.isfinite(abs_tol) and abs_tol >= 0):
        raise OptionError(f"abs_tol must be a finite number >= 0 (an absolute threshold on the SE-Sync cost), "
                          f"got {abs_tol!r}")


def absolute_test(gap: float, abs_tol: float, eta: float, eigenvalue_above: Callable[[], bool]) -> str | None:
    """SE-Sync's absolute test (module docstring): None when ``abs_tol`` is 0 or the test fails, else the reason it
    passes: the proven ``gap`` f − f*_lower ≤ ``abs_tol``, or ``eigenvalue_above()`` (an inertia count, called only
    then) proving λ_min ≥ −abs_tol — only when abs_tol ≥ the numerical floor ``eta``: no count resolves an eigenvalue
    finer than η, so a smaller threshold can only be met by the gap."""
    if abs_tol <= 0:
        return None
    if gap <= abs_tol:
        return f"proven gap f − f* ≤ {gap:.3g} ≤ abs_tol"
    if abs_tol >= eta and eigenvalue_above():
        return "λ_min ≥ −abs_tol proven (SE-Sync's test)"
    return None


@dataclass(eq=False)
class ProvenBound:
    """The first fields of an optimality certificate: ``certified`` (relative suboptimality ≤ tol), ``verdict`` one
    line saying so or why not, ``cost`` f at the point certified, ``dual_value`` Σ tr Λ_i, ``lower_bound`` the
    proven f*_lower, ``shift`` the μ with Λ − μI dual feasible that proves it, ``eta`` η the numerical floor,
    ``n_negative`` eigenvalues (pivots) of the certificate matrix below −η, ``lambda_min`` its smallest eigenvalue,
    ``residual_rel`` the relative first-order residual ‖S Yᵀ‖_F / (‖M‖ √(dn)). Each certificate's docstring says
    how it computes them."""

    certified: bool
    verdict: str
    cost: float
    dual_value: float
    lower_bound: float
    shift: float
    eta: float
    n_negative: int
    lambda_min: float
    residual_rel: float

    @property
    def relative_suboptimality_bound(self) -> float:
        """(f − lower_bound)/f: relative distance to the global optimum proven by the certificate."""
        return relative_suboptimality(self.cost, self.lower_bound)

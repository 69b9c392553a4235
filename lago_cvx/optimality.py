r"""What an optimality certificate proves, the planar one (``certification.certificate``) and the 3-D one
(``space.certify``) alike: a proven lower bound f*_lower ≤ f* on the optimal cost and, from it, the relative
suboptimality of the point certified,

    (f − f*_lower) / f,  f ≥ 0,

which the point is *certified* by when it is at most ``tol`` (``conventions.CERTIFY_TOL``). ``ProvenBound`` holds
the numbers both certificates report, in this order; each adds its own fields after them.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["relative_suboptimality", "ProvenBound"]


def relative_suboptimality(cost: float, lower_bound: float) -> float:
    """(f − f*_lower)/f, scalars, with f ≥ 0: a zero cost gives 0 when the bound reaches it, else +inf (also +inf
    for f*_lower = −inf, no bound proven)."""
    gap = cost - lower_bound
    if cost > 0:
        return gap / cost
    return 0.0 if gap <= 0 else float("inf")


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

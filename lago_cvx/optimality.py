r"""What an optimality certificate proves, the planar one (``certification.certificate``) and the 3-D one
(``space.certify``) alike: a proven lower bound f*_lower ≤ f* on the optimal cost and, from it, the relative
suboptimality of the point certified,

    (f − f*_lower) / f,  f ≥ 0,

which the point is *certified* by when it is at most ``tol`` (``conventions.CERTIFY_TOL``).
"""

from __future__ import annotations

__all__ = ["relative_suboptimality", "ProvenBound"]


def relative_suboptimality(cost: float, lower_bound: float) -> float:
    """(f − f*_lower)/f, scalars, with f ≥ 0: a zero cost gives 0 when the bound reaches it, else +inf (also +inf
    for f*_lower = −inf, no bound proven)."""
    gap = cost - lower_bound
    if cost > 0:
        return gap / cost
    return 0.0 if gap <= 0 else float("inf")


class ProvenBound:
    """The certificates' shared property, from their fields ``cost`` (f) and ``lower_bound`` (f*_lower)."""

    @property
    def relative_suboptimality_bound(self) -> float:
        """(f − lower_bound)/f: relative distance to the global optimum proven by the certificate."""
        return relative_suboptimality(self.cost, self.lower_bound)

"""Named routes through LAGO: which spanning tree, regularization, use of the information and positions
``lago`` takes when those keywords are left ``None``.

* ``"seed"`` — exactly the paper's procedure (Section V): the odometric spanning tree, the rounding of
  Theorem 3, phases 2–3 of eqs. (9)–(15) with blkdiag(P_Δ, P_δ), and phase 3's poses.
* ``"default"`` — chosen by measurement (README, "The default route"; ``python benchmarks/run.py route``):
  the BFS tree (shallow tree paths), the chordal regularizer (the integers from a global estimate of the
  rotations, no tree path to accumulate noise along), phases 2–3 from each edge's full 3×3 information
  (first-order optimal for any information), and the positions re-solved exactly for the orientations.
"""

from __future__ import annotations

from .errors import OptionError

__all__ = ["ROUTES", "REGULARIZATIONS", "INFORMATION_MODES", "POSITIONS", "resolve_route"]

#: The 2kπ regularizers (``lago_cvx.regularization``).
REGULARIZATIONS = ("tree", "chordal", "integer")
#: How phases 2–3 use each edge's information (``lago_cvx.uncertainty``, ``lago_cvx.phases.phase2``).
INFORMATION_MODES = ("full", "marginal")
#: What the positions of the result are: phase 3's (the seed) or re-solved exactly for the orientations
#: (``lago_cvx.positions``).
POSITIONS = ("phase3", "resolve")

ROUTES = {
    "default": {"spanning_tree": "bfs", "regularization": "chordal", "information": "full",
                "positions": "resolve"},
    "seed": {"spanning_tree": "odometry", "regularization": "tree", "information": "marginal",
             "positions": "phase3"},
}


def resolve_route(route: str, **choices) -> tuple[dict, str]:
    """The route's choices with every keyword given (not None) in ``choices`` overriding it, and the name
    to record: the route's, or ``"custom"`` when something was overridden."""
    if route not in ROUTES:
        raise OptionError(f"unknown route {route!r}; expected one of {tuple(ROUTES)}")
    given = {k: v for k, v in choices.items() if v is not None}
    same = all(isinstance(v, str) and ROUTES[route].get(k) == v for k, v in given.items())
    return {**ROUTES[route], **given}, route if same else "custom"

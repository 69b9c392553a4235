"""The 2kπ regularization of the relative orientations: which integer k makes δ + 2πk consistent
around every cycle (the seed's Section IV-E).

Three regularizers, one report (``RegularizationReport``):

* ``"tree"`` (``tree.py``) — the seed's Theorem 3: round each chord's cycle residual along a spanning
  tree (eqs. (20)–(23));
* ``"chordal"`` (``chordal.py``) — beyond the seed: round every edge against the chordal relaxation of
  the rotations, a global estimate that needs no tree;
* ``"integer"`` (``integer.py``, ``sphere.py``) — beyond the seed: the weighted integer least-squares
  problem that the rounding approximates, solved exactly.

All three use the rounding rule of ``lago_cvx.rounding``.
"""

from __future__ import annotations

from ..graph import SpanningTree
from ..posegraph import PoseGraph
from ..rounding import AMBIGUITY_MARGIN
from ..routes import REGULARIZATIONS
from ..solvers import ClarabelSettings, IntegerSearch
from .chordal import regularize_chordal
from .integer import MAX_INTEGER_CHORDS, regularize_integer
from .report import RegularizationReport
from .tree import regularize_tree

__all__ = ["REGULARIZATIONS", "MAX_INTEGER_CHORDS", "RegularizationReport", "regularize", "regularize_tree",
           "regularize_chordal", "regularize_integer"]

#: The regularizers: ``"tree"`` (the seed's Theorem 3), ``"chordal"`` (rounding against the chordal
#: relaxation) and ``"integer"`` (the weighted integer least-squares problem the rounding approximates).


def regularize(graph: PoseGraph, tree: SpanningTree, *, regularization: str = "tree",
               margin: float = AMBIGUITY_MARGIN, method: str = "closed_form", backend: str = "auto",
               settings: ClarabelSettings | None = None, search: IntegerSearch | None = None,
               progress=None, uncertainty=None, elimination=None) -> RegularizationReport:
    """2kπ regularization of the relative orientations.

    regularization — ``"tree"`` (``regularize_tree``), ``"chordal"`` (``regularize_chordal``) or
      ``"integer"`` (``regularize_integer``). ``method`` (``"closed_form"`` | ``"cvxpy"``), ``backend``
      and ``settings`` concern the chordal relaxation; for ``"integer"`` ``method`` picks the solver
      (exact enumeration | SCIP through cvxpy) unless ``search`` names one. margin — ambiguity margin
      (rad). progress — an optional ``lago_cvx.progress.ProgressCallback`` (the integer search reports
      through it). ``uncertainty`` (the graph's ``EdgeUncertainty``) and ``elimination`` (a
      ``normal_equations.GraphElimination`` anchored at the tree's root) are reused by the chordal
      relaxation when given."""
    if regularization == "tree":
        return regularize_tree(graph, tree, margin=margin)
    if regularization == "chordal":
        return regularize_chordal(graph, tree, margin=margin, method=method, backend=backend, settings=settings,
                                  uncertainty=uncertainty, elimination=elimination)
    if regularization == "integer":
        return regularize_integer(graph, tree, margin=margin, method=method, search=search, progress=progress)
    from ..errors import OptionError

    raise OptionError(f"unknown regularization {regularization!r}; expected one of {REGULARIZATIONS}")

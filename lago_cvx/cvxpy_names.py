"""Named cvxpy constants: ``print(problem)`` shows ``W``, ``Aᵀ``, ``P_δ^(-1/2)`` instead of their entries.

A module of its own, imported only when a cvxpy problem is built (``lago_cvx.solvers.named_constant``), so
that ``import lago_cvx`` never loads cvxpy, and at module level, so that problems built from these
constants survive ``pickle`` and ``copy.deepcopy`` (a class defined inside a function does not).
"""

from __future__ import annotations

import cvxpy as cp

__all__ = ["NamedConstant"]


class NamedConstant(cp.Constant):
    """A cvxpy constant that prints as its label (``A``, ``Bᵀ``, ``W``) instead of its entries."""

    def __init__(self, value, label: str):
        super().__init__(value)
        self._label = label

    def name(self) -> str:
        return self._label

"""What the C kernels (``c_kernels``) read without checking, checked before any of them runs, raising ``PlanError``
(a ``LagoError`` and a ``ValueError``) instead of reading or writing out of bounds.

* ``plan(plan, b)`` — once per plan and block size, O(n), when ``compiled.CompiledLayout`` is built: ``parent`` a
  forest in postorder, ``position`` a permutation, ``fptr``/``rptr`` pointers from 0 to the sizes they point into,
  ``rows`` positions in [0, d), every front's order D = (k + r)·b at most 2³¹ − 1 (LAPACK/BLAS take 32-bit sizes:
  checked, never narrowed); then ``layout(lay)`` checks the extend-add map ``rel`` against the parents' fronts and
  registers the layout's arrays, made read-only.
* ``arrays(fptr, …)`` — per kernel call, O(1): the plan arrays handed to a kernel are those of one registered
  layout (by identity), whose sizes bound the call's fronts and buffers. Anything else is refused.
"""

from __future__ import annotations

import weakref

import numpy as np

from ..errors import PlanError

__all__ = ["INT_MAX", "ints", "forest", "fronts", "plan", "layout", "arrays", "need"]

#: The largest size LAPACK/BLAS (32-bit Fortran integers) accept.
INT_MAX = 2**31 - 1

_LAYOUTS: dict = {}  # id(fptr) → (sizes, {name: weak reference of the registered array})


def need(ok: bool, message: str) -> None:
    if not ok:
        raise PlanError("sparse engine: " + message)


def ints(a, name: str, lo: int | None = None, hi: int | None = None) -> np.ndarray:
    """``a`` a 1-D integer array with every entry in [lo, hi)."""
    a = np.asarray(a)
    need(a.ndim == 1 and a.dtype.kind in "iu", f"{name} must be a 1-D integer array, not {a.dtype} {a.shape}")
    if a.size and lo is not None:
        need(int(a.min()) >= lo and int(a.max()) < hi, f"{name} has entries outside [{lo}, {hi})")
    return a


def forest(parent, name: str = "parent", *, postorder: bool = False) -> np.ndarray:
    """``parent`` (n,): each entry −1 (a root) or a node in [0, n) (with ``postorder``, a later one)."""
    parent = ints(parent, name, -1, np.size(parent))
    if postorder:
        i = np.flatnonzero(parent >= 0)
        need(not (parent[i] <= i).any(), f"{name} is not in postorder (a parent at or before its child)")
    return parent


def _pointers(ptr, count: int, end: int, name: str) -> np.ndarray:
    ptr = ints(ptr, name)
    need(ptr.size == count + 1 and int(ptr[0]) == 0 and not (np.diff(ptr) < 0).any() and int(ptr[-1]) == end,
         f"{name} must be {count + 1} non-decreasing pointers from 0 to {end}")
    return ptr


def fronts(fptr, rptr, rows) -> tuple[int, int]:
    """(F, d) of the fronts' pointers and rows, checked in O(F + |rows|) (module docstring)."""
    F = np.size(fptr) - 1
    need(F >= 0, "fptr is empty")
    d = int(np.asarray(fptr)[-1]) if np.size(fptr) else 0
    _pointers(fptr, F, d, "fptr")
    _pointers(rptr, F, np.size(rows), "rptr")
    ints(rows, "rows", 0, max(d, 1))
    return F, d


def plan(p, b: int) -> None:
    """An ``EliminationPlan`` with b×b blocks, before its fronts reach compiled code (module docstring)."""
    d, F = int(p.d), int(np.size(p.parent))
    need(int(b) >= 1, f"block size {b} < 1")
    forest(p.parent, postorder=True)
    pos = ints(p.position, "position", 0, max(d, 1))
    need(pos.size == d and (d == 0 or np.bincount(pos, minlength=d).max() == 1), "position is not a permutation")
    need(fronts(p.fptr, p.rptr, p.rows) == (F, d), f"fptr must have {F + 1} entries ending at {d}")
    k, r = np.diff(p.fptr), np.diff(p.rptr)
    need(not F or int(((k + r) * int(b)).max()) <= INT_MAX, f"a front exceeds LAPACK's 32-bit sizes ({INT_MAX})")


def layout(lay) -> None:
    """A ``compiled.CompiledLayout`` built on a checked plan: its extend-add map inside the parents' fronts; then its
    arrays are made read-only and registered for ``arrays``."""
    p = lay.plan
    par = np.repeat(p.parent, np.diff(p.rptr))
    ok = par >= 0
    need(not (lay.rel[ok] < 0).any() and not (lay.rel[ok] >= np.diff(p.fptr)[par[ok]] + np.diff(p.rptr)[par[ok]]).any(),
         "an update row lies outside its parent's front")
    named = dict(fptr=lay.fptr, rptr=lay.rptr, rows=lay.rows, Lptr=lay.Lptr, rel=lay.rel, nchild=lay.nchild)
    for a in named.values():
        a.flags.writeable = False
    sizes = dict(F=p.n_fronts, d=p.d, b=lay.b, maxD=int(lay.D.max()) if p.n_fronts else 0, rmax=lay.rmax,
                 Lsize=int(lay.Lptr[-1]), D=lay.D)
    if len(_LAYOUTS) > 256:  # forget the layouts no longer alive
        for key in [key for key, (_, refs) in _LAYOUTS.items() if refs["fptr"]() is None]:
            del _LAYOUTS[key]
    _LAYOUTS[id(lay.fptr), lay.b] = (sizes, {name: weakref.ref(a) for name, a in named.items()})


def arrays(b, fptr, **given) -> dict:
    """The sizes of the registered layout whose arrays (``fptr`` and ``given``, by name) these are, with block size
    ``b``; PlanError for arrays of no checked layout."""
    hit = _LAYOUTS.get((id(fptr), int(b)))
    need(hit is not None and hit[1]["fptr"]() is fptr
         and all(hit[1][name]() is a for name, a in given.items()),
         "the plan's arrays must be those of a checked layout (compiled.CompiledLayout)")
    return hit[0]

"""The approximate minimum degree ordering (AMD) of the pose graph, by the AMD routine that ships inside
the ``qdldl`` package, called through ``ctypes``.

``qdldl.Solver(A)`` orders A by AMD before it factors. LAGO orders the anchor-reduced pose graph once
and uses that order for every system of the graph (``lago_cvx.sparse.normal_equations``). Calling AMD directly,
instead of through ``qdldl.Solver`` on the weighted Laplacian, gives the same permutation, and

* the call releases the GIL (``ctypes``), so the spanning tree is built beside it; ``qdldl.Solver``
  holds the GIL for its whole call;
* the Laplacian is then factored by QDLDL's own routines on the graph's pattern (``lago_cvx.sparse.ldl``),
  whose symbolic analysis every later system reuses.

The routine is SuiteSparse's ``amd_l_order(n, Ap, Ai, P, Control, Info)`` for 64-bit integers
(``SuiteSparse_long``): the CSC pattern of a symmetric matrix (both triangles, rows sorted, no
duplicates), ``P`` (n,) out, the pivot order. Default controls (``Control`` = NULL: dense rows at
10·√n, aggressive absorption). ``available()`` is False if the symbol is not exported (another build of
qdldl); callers then fall back to ``qdldl.Solver``.
"""

from __future__ import annotations

import ctypes
import logging

import numpy as np

from .arrays import unique_sorted

__all__ = ["available", "order"]

log = logging.getLogger(__name__)

_AMD: list = []  # [the typed routine or None], resolved on first use
_AMD_OK, _AMD_OK_BUT_JUMBLED = 0, 1  # amd.h


def _routine():
    if not _AMD:
        fn = None
        try:
            from .ldl import _library

            lib = _library()  # the qdldl extension, when its ABI is the expected one (lago_cvx.sparse.ldl)
            if lib is not None and hasattr(lib, "amd_l_order"):
                fn = lib.amd_l_order
                fn.restype = ctypes.c_longlong
                fn.argtypes = [ctypes.c_longlong] + [ctypes.c_void_p] * 5
        except Exception as exc:  # no qdldl, or an object ctypes cannot open
            log.debug("AMD not callable directly (%s)", exc)
        _AMD.append(fn)
    return _AMD[0]


def available() -> bool:
    """True when ``amd_l_order`` can be called (module docstring)."""
    return _routine() is not None


def order(d: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """AMD's order (d,) of the graph on d vertices with edges (lo, hi) (lo < hi, repeats allowed): the
    vertex eliminated at each position. None when AMD cannot be called or reports an error."""
    fn = _routine()
    if fn is None:
        return None
    lo = np.asarray(lo, np.int64)
    hi = np.asarray(hi, np.int64)
    key = unique_sorted(np.concatenate([hi * d + lo, lo * d + hi]))  # both triangles, column-major
    col, row = np.divmod(key, d)
    Ap = np.zeros(d + 1, np.int64)
    np.cumsum(np.bincount(col, minlength=d), out=Ap[1:])
    Ai = np.ascontiguousarray(row)
    P = np.empty(d, np.int64)
    status = fn(d, Ap.ctypes.data, Ai.ctypes.data, P.ctypes.data, None, None)
    if status not in (_AMD_OK, _AMD_OK_BUT_JUMBLED):
        log.info("AMD reported status %d: ordering through qdldl.Solver instead", status)
        return None
    return P

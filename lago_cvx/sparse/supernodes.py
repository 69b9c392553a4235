r"""The two sequential loops of the pose-level symbolic analysis (``multifrontal.plan_from_qdldl``), as
plain functions on NumPy arrays: compiled in C (``_ckernels.c`` through ``c_kernels``) at every size when that
library was built at install; else by Numba (``compiled_kernels``) from ``multifrontal.COMPILED_LOOPS`` poses and as
Python below (Numba's import and cached kernels cost about half a second per process, the C library a few
milliseconds) — with the same arithmetic every way (``multifrontal._loops``).

* ``relax`` — relaxed amalgamation (CHOLMOD's rule, ``multifrontal.NRELAX``/``ZRELAX``): supernode c is
  merged into its parent p when the merged front has few pivots, or few explicit zeros;
* ``heights`` — each front's height in the front tree (0 at the leaves).
"""

from __future__ import annotations

import numpy as np

__all__ = ["relax", "heights"]


def relax(k, r, true_nnz, sparent, n0, n1, n2, z0, z1, z2):
    """Supernodes 0 … ns−1 in topological order (children first): ``k`` (ns,) pivots, ``r`` (ns,) update
    rows, ``true_nnz`` (ns,) entries of L without explicit zeros, ``sparent`` (ns,) parent (−1 at a root).
    ``k`` and ``true_nnz`` are updated in place as children merge. Returns (ns,) the supernode each was
    merged into (itself when it survives; one step, not followed to the end)."""
    ns = k.size
    top = np.arange(ns)
    for c in range(ns):
        p = sparent[c]
        if p < 0:
            continue
        kk = k[c] + k[p]
        total = kk * (kk + 1) // 2 + kk * r[p]
        zf = (total - true_nnz[c] - true_nnz[p]) / total
        if kk <= n0 or (kk <= n1 and zf < z0) or (kk <= n2 and zf < z1) or zf < z2:
            k[p] = kk
            true_nnz[p] += true_nnz[c]
            top[c] = p
    return top


def heights(parent):
    """(F,) the height of each front of the forest ``parent`` (fronts in topological order, −1 at a
    root): 0 at a leaf, else 1 + the largest height of its children."""
    n = parent.size
    h = np.zeros(n, np.int64)
    for f in range(n):
        p = parent[f]
        if p >= 0 and h[p] < h[f] + 1:
            h[p] = h[f] + 1
    return h

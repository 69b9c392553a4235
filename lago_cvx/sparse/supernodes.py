r"""The two sequential loops of the pose-level symbolic analysis (``multifrontal.plan_from_qdldl``), as
plain functions on NumPy arrays: compiled in C (``_ckernels.c`` through ``c_kernels``) at every size when that
library was built at install; else by Numba (``compiled_kernels``) from ``multifrontal.COMPILED_LOOPS`` poses and as
Python below (Numba's import and cached kernels cost about half a second per process, the C library a few
milliseconds) — with the same arithmetic every way (``multifrontal._loops``).

* ``relax`` — relaxed amalgamation (CHOLMOD's rule, ``multifrontal.NRELAX``/``ZRELAX``): supernode c is
  merged into its parent p when the merged front has few pivots, or few explicit zeros;
* ``heights`` — each front's height in the front tree (0 at the leaves);
* ``postorder`` — the elimination tree's postorder (children before parents), linear in its nodes at every shape
  (a star as a chain).
"""

from __future__ import annotations

import numpy as np

__all__ = ["relax", "heights", "postorder"]


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


def postorder(parent):
    """(n,) ``order[t]`` the node visited t-th by the postorder of the forest ``parent`` (n,) (−1 at a root, else
    parent[i] > i, as in an elimination tree): the reverse of the depth-first preorder that visits children by
    increasing index (``scipy.sparse.csgraph.depth_first_order``'s), i.e. each node right after its subtree, siblings
    by decreasing index. Two passes: subtree sizes (children first), then each node's interval in its parent's
    (parents first), O(n) (on Python lists, faster than on NumPy scalars)."""
    n = parent.size
    par = np.where(parent < 0, n, parent).tolist()
    size = [1] * (n + 1)
    for i in range(n):  # children before parents; the virtual root n above the roots
        size[par[i]] += size[i]
    free = [0] * (n + 1)  # next free place in each node's interval; the virtual root's starts at 0
    where = [0] * n
    for i in range(n - 1, -1, -1):  # parents before children, siblings by decreasing index
        lo = free[par[i]]
        free[par[i]] = lo + size[i]
        free[i] = lo
        where[i] = lo + size[i] - 1  # a node follows its subtree
    order = np.empty(n, np.int64)
    order[np.asarray(where, np.int64)] = np.arange(n)
    return order

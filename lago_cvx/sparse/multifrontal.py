r"""Multifrontal block Cholesky on the pose graph: the symbolic analysis shared by every LAGO system.

Every sparse system of LAGO's closed forms has the sparsity of the anchor-reduced pose graph with b×b blocks, one
block row per free pose (d = n − 1): b = 1 phase 1 (eq. (13)), b = 2 the chordal relaxation (C3) and the positions
(P), b = 3 phase 3 (eqs. (12), (15)) and the 3-D relaxation and positions, b = 6 the 3-D joint step. So one
fill-reducing ordering and one elimination tree, computed once **at the pose level**, serve them all.

**Symbolic analysis** (``EliminationPlan``, O(n) after the ordering). AMD's ordering of the d × d pose pattern
and the pattern of its factor (``qdldl.Solver``'s public ``factors()`` on a diagonally dominant matrix of that
pattern); the elimination tree (parent of column j = first off-diagonal row of L's column j), its postorder, the
fundamental supernodes (chains j → j + 1 whose columns share their structure) and a relaxed amalgamation of small
supernodes into *fronts* (a few explicit zeros traded for fewer, larger dense blocks). Front f has pivot poses P_f
(contiguous in the final order) and update rows R_f (later poses, sorted); R_f ⊂ P_parent ∪ R_parent.

**Numeric factorization** N = L Lᵀ, front by front from the leaves up (``compiled``: in C, or ``block_factor``
in NumPy where the C kernels were not built):

    F_f = [[F_PP, ·], [F_RP, F_RR]] = N's entries in the columns P_f + Σ_children U_c   (extend-add)
    L_PP = chol(F_PP),    X_f = F_RP L_PP⁻ᵀ,    U_f = F_RR − X_f X_fᵀ                          (MF)

L's block column of P_f is [L_PP; X_f]. **Selected inversion** (Takahashi, Fagan, Chen 1973; Erisman, Tinney
1975): with Σ = N⁻¹ = L⁻ᵀL⁻¹ and the fronts taken from the root down, Σ_RR is a submatrix of the parent front's Σ
and

    Y = X_f L_PP⁻¹,    Σ_RP = −Σ_RR Y,    Σ_PP = L_PP⁻ᵀ L_PP⁻¹ − Yᵀ Σ_RP                       (T)

(from Σ L = L⁻ᵀ, whose block column P reads [Σ_PP Σ_PR; Σ_RP Σ_RR][L_PP; X] = [L_PP⁻ᵀ; 0]): every entry of Σ on
the pattern of L, never forming N⁻¹ (``block_factor.inverse_blocks``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .block_factor import inverse_blocks
from .linalg import NotPositiveDefinite

__all__ = ["EliminationPlan", "plan_from_pattern", "NotPositiveDefinite", "inverse_blocks",
           "NRELAX", "ZRELAX", "COMPILED_RELAX"]

#: Relaxed amalgamation (CHOLMOD's defaults): a child front is merged into its parent when the merged
#: front has at most NRELAX[0] pivots, or at most NRELAX[1] pivots and a fraction of explicit zeros
#: below ZRELAX[0], at most NRELAX[2] and below ZRELAX[1], or any size below ZRELAX[2].
NRELAX = (4, 16, 48)
ZRELAX = (0.8, 0.1, 0.05)

#: The amalgamation for the C kernels, whose cost per front is a few hundred nanoseconds, not a Python call:
#: fewer explicit zeros, so a smaller L for the same factorization time (``benchmarks/million.md``).
COMPILED_RELAX = ((2, 8, 32), (0.8, 0.1, 0.05))


def _postorder(parent: np.ndarray) -> np.ndarray:
    """``postorder`` of an elimination tree (parent[i] > i, −1 at roots), O(n) at every shape (a star
    as a chain; ``csgraph.depth_first_order`` is quadratic on a star)."""
    return _loops()[1](np.ascontiguousarray(parent, np.int64))


def _loops():
    """``relax`` and ``postorder``, the symbolic analysis's sequential loops: in C when the kernels are built
    (``compiled.available()``), else the Python below (the same operations: the same plan either way, tested)."""
    from . import compiled

    if compiled.available():
        K = compiled.kernels()
        return K["relax"], K["postorder"]
    return relax, postorder


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


@dataclass(eq=False)
class EliminationPlan:
    """The pose-level symbolic analysis (module docstring) of a d × d pattern: ``d`` poses; ``position`` (d,) each
    pose's place in the elimination order; fronts f = 0 … F−1 in elimination order (children before parents): pivots
    the positions ``fptr[f] … fptr[f+1]−1``, update rows ``rows[rptr[f]:rptr[f+1]]`` (positions, increasing),
    ``parent`` (F,) (−1 at a root). ``nnz`` the pose-level entries of L including the amalgamation's explicit zeros;
    ``flops(b)`` the multiply–adds of (MF) with b×b blocks."""

    d: int
    position: np.ndarray
    fptr: np.ndarray
    rptr: np.ndarray
    rows: np.ndarray
    parent: np.ndarray

    @property
    def n_fronts(self) -> int:
        return int(self.parent.size)

    @property
    def pivots(self) -> np.ndarray:
        return np.diff(self.fptr)

    @property
    def n_rows(self) -> np.ndarray:
        return np.diff(self.rptr)

    @property
    def nnz(self) -> int:
        k, r = self.pivots, self.n_rows
        return int((k * (k + 1) // 2 + k * r).sum())

    def flops(self, b: int = 1) -> float:
        """Σ over the scalar columns of L (b×b-block expansion) of colcount²: the multiply–adds of a Cholesky
        factorization."""
        k, r = self.pivots.astype(float) * b, self.n_rows.astype(float) * b
        # column t of a front (t = 0 … kb−1) has kb − t + rb entries (diagonal included)
        return float((k * (k + 1) * (2 * k + 1) / 6 + k * (k + 1) * r + k * r * r).sum())


def plan_from_pattern(d: int, rows: np.ndarray, cols: np.ndarray, *, relaxation=None) -> EliminationPlan:
    """The plan of the d × d pose pattern with off-diagonal entries (rows[k], cols[k]) (either orientation,
    duplicates allowed). ``relaxation`` (nrelax, zrelax) of the amalgamation, default (``NRELAX``, ``ZRELAX``);
    ``COMPILED_RELAX`` for the compiled engine."""
    import qdldl

    nrelax, zrelax = (NRELAX, ZRELAX) if relaxation is None else relaxation
    d, rows, cols = int(d), np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    keep = rows != cols
    lo, hi = np.minimum(rows[keep], cols[keep]), np.maximum(rows[keep], cols[keep])
    deg = np.bincount(np.r_[lo, hi], minlength=d).astype(float)
    A = sp.csc_matrix((np.r_[-np.ones(lo.size), deg + 1.0], (np.r_[lo, np.arange(d)], np.r_[hi, np.arange(d)])),
                      shape=(d, d))
    A.sum_duplicates()
    # AMD and P A Pᵀ = (I + L) D (I + L)ᵀ of a diagonally dominant A of the pattern: L (d, d) strictly lower, columns
    # and rows in elimination order, perm (d,) the pose eliminated at each position
    L, _, perm = qdldl.Solver(A, upper=True).factors()
    L = sp.csc_matrix(L)
    ip, ix = L.indptr.astype(np.int64), L.indices.astype(np.int64)
    cnt = np.diff(ip)
    parent = np.full(d, -1, np.int64)
    has = np.flatnonzero(cnt > 0)
    if has.size:
        parent[has] = np.minimum.reduceat(ix, ip[has])
    # postorder relabelling: same tree, same fill, supernodes contiguous
    order = _postorder(parent)  # old position visited t-th
    post = np.empty(d, np.int64)
    post[order] = np.arange(d)
    cnt_p = cnt[order]
    parent_p = np.where(parent[order] >= 0, post[np.maximum(parent[order], 0)], -1)
    # fundamental supernodes: j and j + 1 together when j + 1 is j's only parent-child link and the
    # structure of column j is {j + 1} ∪ structure of column j + 1
    nchild = np.bincount(parent_p[parent_p >= 0], minlength=d)
    j = np.arange(d - 1)
    chain = (parent_p[:-1] == j + 1) & (cnt_p[1:] == cnt_p[:-1] - 1) & (nchild[1:] == 1)
    starts = np.flatnonzero(np.r_[True, ~chain])
    ends = np.r_[starts[1:], d]
    ns = starts.size
    snode_of = np.repeat(np.arange(ns), ends - starts)
    last = ends - 1
    sparent = np.where(parent_p[last] >= 0, snode_of[np.maximum(parent_p[last], 0)], -1)
    # relaxed amalgamation: children first (supernodes are in topological order)
    relax = _loops()[0]
    k = (ends - starts).astype(np.int64)
    true_nnz = np.add.reduceat(cnt_p + 1, starts).astype(np.int64) if d else np.zeros(0, np.int64)
    top = relax(k, cnt_p[last].astype(np.int64), true_nnz, sparent.astype(np.int64), *nrelax, *zrelax)
    top = np.asarray(top, np.int64)
    while True:  # follow merges to the surviving supernode
        nxt = top[top]
        if np.array_equal(nxt, top):
            break
        top = nxt
    fronts = np.flatnonzero(top == np.arange(ns))  # increasing: topological
    fid = np.full(ns, -1, np.int64)
    fid[fronts] = np.arange(fronts.size)
    n_fronts = fronts.size
    front_of_post = fid[top[snode_of]]  # (d,) front of each postorder position
    final = np.lexsort((np.arange(d), front_of_post))  # postorder positions in final order
    newpos = np.empty(d, np.int64)
    newpos[final] = np.arange(d)
    fptr = np.r_[0, np.cumsum(np.bincount(front_of_post, minlength=n_fronts))].astype(np.int64)
    # rows of a front: structure of the last column of its surviving supernode
    col_old = order[last[fronts]]  # old position of that column
    lens = cnt[col_old]
    src = np.repeat(ip[col_old] - (np.cumsum(lens) - lens), lens) + np.arange(int(lens.sum()))
    fr = np.repeat(np.arange(n_fronts), lens)
    key = np.sort(fr * max(d, 1) + newpos[post[ix[src]]])
    rows = key - fr * max(d, 1)
    rptr = np.r_[0, np.cumsum(lens)].astype(np.int64)
    sp_top = sparent[fronts]
    fparent = np.where(sp_top >= 0, fid[top[np.maximum(sp_top, 0)]], -1)
    position = np.empty(d, np.int64)
    position[np.asarray(perm, np.int64)] = newpos[post]  # pose → old position → postorder → final
    return EliminationPlan(d=d, position=position, fptr=fptr, rptr=rptr, rows=rows, parent=fparent)

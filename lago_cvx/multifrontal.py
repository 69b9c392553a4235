r"""Multifrontal block Cholesky on the pose graph: one symbolic analysis shared by every LAGO system,
batched dense kernels, and selected inversion (Takahashi) for marginal covariances.

Every sparse system of LAGO's closed forms has the sparsity of the anchor-reduced pose graph with b×b
blocks, one block row per free pose (d = n − 1 of them):

* b = 1 — phase 1, eq. (13): Ω_θ = A2 P_δ⁻¹ A2ᵀ (d × d); the positions (P) with isotropic information;
* b = 2 — the chordal relaxation (C3), MᵀM (2d × 2d); the positions (P) in general;
* b = 3 — phase 3, eqs. (12), (15): Ω* = B P_z⁻¹ Bᵀ (3d × 3d).

So one fill-reducing ordering and one elimination tree, computed once **at the pose level**, serve them
all; the b×b blocks are dense and are factored by dense LAPACK/BLAS kernels.

**Symbolic analysis** (``EliminationPlan``). An AMD ordering of the d × d pose pattern and the pattern of
its Cholesky factor (taken from QDLDL, which runs AMD); the elimination tree (parent of column j = first
off-diagonal row of L's column j), a postorder of it, the fundamental supernodes (chains j → j + 1 whose
columns share their structure) and a relaxed amalgamation of small supernodes into *fronts* (a few
explicit zeros traded for fewer, larger dense blocks). Front f has pivot poses P_f (contiguous in the
final elimination order) and update rows R_f (later poses, sorted); R_f ⊂ P_parent ∪ R_parent.

**Numeric factorization** N = L Lᵀ (``BlockLayout.factor``), front by front from the leaves up:

    F_f = [[F_PP, ·], [F_RP, F_RR]] = N's entries in the columns P_f + Σ_children U_c   (extend-add)
    L_PP = chol(F_PP),    X_f = F_RP L_PP⁻ᵀ,    U_f = F_RR − X_f X_fᵀ                          (MF)

L's block column of P_f is [L_PP; X_f]. Fronts at the same height of the front tree are independent;
those of similar size are padded to a common size (identity on padded pivots, zero padded rows) and
factored together by stacked LAPACK/BLAS calls, so the Python cost is per group of fronts, not per front.
Large fronts are factored one by one with exact sizes (``potrf``/``trsm``).

**Solve** N x = y: forward L_PP z_P = y_P, y_R −= X z_P (leaves up); back x_P = L_PP⁻ᵀ(z_P − Xᵀx_R).

**Selected inversion** (Takahashi, Fagan, Chen 1973; Erisman, Tinney 1975): with Σ = N⁻¹ = L⁻ᵀL⁻¹ and
the fronts taken from the root down, Σ_RR is known (a submatrix of the parent front's Σ, as
R_f ⊂ P_parent ∪ R_parent) and

    Y = X_f L_PP⁻¹,    Σ_RP = −Σ_RR Y,    Σ_PP = L_PP⁻ᵀ L_PP⁻¹ − Yᵀ Σ_RP                       (T)

(from Σ L = L⁻ᵀ, whose block column P reads [Σ_PP Σ_PR; Σ_RP Σ_RR][L_PP; X] = [L_PP⁻ᵀ; 0]). This gives
every entry of Σ on the pattern of L — each pose's b×b block and the block of every pose pair joined by an
edge — in about the time of two factorizations and the memory of the fronts, never forming N⁻¹.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .errors import NumericalError

__all__ = ["EliminationPlan", "BlockLayout", "BlockFactor", "plan_from_qdldl", "NotPositiveDefinite",
           "inverse_blocks"]

log = logging.getLogger(__name__)

#: Relaxed amalgamation (CHOLMOD's defaults): a child front is merged into its parent when the merged
#: front has at most NRELAX[0] pivots, or at most NRELAX[1] pivots and a fraction of explicit zeros
#: below ZRELAX[0], at most NRELAX[2] and below ZRELAX[1], or any size below ZRELAX[2].
NRELAX = (4, 16, 48)
ZRELAX = (0.8, 0.1, 0.05)

#: Fronts with at least this many pivot variables (k·b) are factored one at a time with exact sizes;
#: smaller ones are padded and batched.
SINGLE_FRONT = 96

#: Pose-count ladder the small fronts are padded to (steps of about 1.25).
_LADDER = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112,
                    128, 160, 192, 224, 256, 320, 384, 448, 512, 640, 768, 896, 1024])


class NotPositiveDefinite(NumericalError):
    """A front's pivot block was not numerically positive definite (the matrix is not SPD in floating
    point)."""


def _seg_arange(lengths: np.ndarray) -> np.ndarray:
    """Concatenated aranges: [0..l₀−1, 0..l₁−1, …] for ``lengths`` (k,)."""
    lengths = np.asarray(lengths, np.int64)
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    starts = np.cumsum(lengths) - lengths
    return np.arange(total, dtype=np.int64) - np.repeat(starts, lengths)


def _pad(x: np.ndarray) -> np.ndarray:
    """Smallest ladder value ≥ x (beyond the ladder: x itself)."""
    i = np.searchsorted(_LADDER, x)
    return np.where(i < _LADDER.size, _LADDER[np.minimum(i, _LADDER.size - 1)], x)


def _postorder(parent: np.ndarray) -> np.ndarray:
    """A postorder of the forest ``parent`` (−1 at roots): ``order[t]`` = the node visited t-th, children
    before parents. The reverse of a depth-first preorder (C, ``scipy.sparse.csgraph``)."""
    from scipy.sparse import csgraph

    n = parent.size
    par = np.where(parent < 0, n, parent)  # a virtual root n above the roots
    children = sp.csr_matrix((np.ones(n), (par, np.arange(n))), shape=(n + 1, n + 1))
    pre = csgraph.depth_first_order(children, n, directed=True, return_predecessors=False)
    return pre[:0:-1].astype(np.int64)  # drop the virtual root (first in preorder), reverse


@dataclass(eq=False)
class EliminationPlan:
    """The pose-level symbolic analysis (module docstring) of a d × d pattern.

    ``d`` poses; ``position`` (d,) each pose's place in the elimination order; fronts f = 0 … F−1 in
    elimination order (children before parents): pivots are the positions ``fptr[f] … fptr[f+1]−1``,
    update rows ``rows[rptr[f]:rptr[f+1]]`` (positions, increasing), ``parent`` (F,) (−1 at a root),
    ``height`` (F,) (0 at leaves). ``nnz`` the pose-level entries of L including the explicit zeros of
    the amalgamation; ``flops(b)`` the multiply–adds of (MF) with b×b blocks (Σ over the columns of L of
    colcount², the Cholesky flop count)."""

    d: int
    position: np.ndarray
    fptr: np.ndarray
    rptr: np.ndarray
    rows: np.ndarray
    parent: np.ndarray
    height: np.ndarray

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
        """Σ over the scalar columns of L (b×b-block expansion) of colcount²: the multiply–adds of a
        Cholesky factorization."""
        k, r = self.pivots.astype(float) * b, self.n_rows.astype(float) * b
        # column t of a front (t = 0 … kb−1) has kb − t + rb entries (diagonal included)
        return float((k * (k + 1) * (2 * k + 1) / 6 + k * (k + 1) * r + k * r * r).sum())

    def layout(self, b: int) -> "BlockLayout":
        cache = self.__dict__.setdefault("_layouts", {})
        if b not in cache:
            cache[b] = BlockLayout(self, b)
        return cache[b]


def plan_from_qdldl(L: sp.csc_matrix, perm: np.ndarray) -> EliminationPlan:
    """The plan from a pose-level factorization ``P A Pᵀ = (I + L) D (I + L)ᵀ`` as ``qdldl.Solver.factors()``
    returns it: ``L`` (d, d) strictly lower (CSC, columns and rows in elimination order, any row order
    within a column), ``perm`` (d,) the pose eliminated at each position."""
    d = int(perm.size)
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
    k = (ends - starts).tolist()
    r = cnt_p[last].tolist()
    true_nnz = np.add.reduceat(cnt_p + 1, starts).tolist() if d else []
    top = list(range(ns))
    sparent_l = sparent.tolist()
    n0, n1, n2 = NRELAX
    z0, z1, z2 = ZRELAX
    for c in range(ns):
        p = sparent_l[c]
        if p < 0:
            continue
        kk = k[c] + k[p]
        total = kk * (kk + 1) // 2 + kk * r[p]
        zf = (total - true_nnz[c] - true_nnz[p]) / total
        if kk <= n0 or (kk <= n1 and zf < z0) or (kk <= n2 and zf < z1) or zf < z2:
            k[p] = kk
            true_nnz[p] += true_nnz[c]
            top[c] = p
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
    src = np.repeat(ip[col_old], lens) + _seg_arange(lens)
    fr = np.repeat(np.arange(n_fronts), lens)
    key = np.sort(fr * max(d, 1) + newpos[post[ix[src]]])
    rows = key - fr * max(d, 1)
    rptr = np.r_[0, np.cumsum(lens)].astype(np.int64)
    sp_top = sparent[fronts]
    fparent = np.where(sp_top >= 0, fid[top[np.maximum(sp_top, 0)]], -1)
    height = np.zeros(n_fronts, np.int64)
    fp = fparent.tolist()
    hl = [0] * n_fronts
    for f in range(n_fronts):
        p = fp[f]
        if p >= 0 and hl[p] < hl[f] + 1:
            hl[p] = hl[f] + 1
    height[:] = hl
    position = np.empty(d, np.int64)
    position[np.asarray(perm, np.int64)] = newpos[post]  # pose → old position → postorder → final
    return EliminationPlan(d=d, position=position, fptr=fptr, rptr=rptr, rows=rows, parent=fparent,
                           height=height)


@dataclass(eq=False)
class _Group:
    """Fronts factored together: ``fronts`` (B,), padded pivot/row pose counts K, R (exact for a single
    front), ``piv`` (B, K·b) and ``rowv`` (B, R·b) the variables' elimination slots (padding → the dummy
    slot N), ``pad_diag`` the flat positions of padded pivot diagonals in the group buffer (B, D, D)."""

    fronts: np.ndarray
    K: int
    R: int
    b: int
    piv: np.ndarray
    rowv: np.ndarray
    single: bool
    pad_diag: np.ndarray

    @property
    def D(self) -> int:
        return (self.K + self.R) * self.b


class BlockLayout:
    """The plan expanded to b×b blocks: groups of fronts with their index maps (module docstring).

    Variables are numbered in elimination order, pose-major: slot = position·b + component; ``slots``
    maps a system's variable numbering into it. ``rel[f]`` (r_f·b,) the local variable index, in its
    parent's front, of each update row variable of front f (the extend-add map)."""

    def __init__(self, plan: EliminationPlan, b: int):
        self.plan = plan
        self.b = b = int(b)
        self.N = plan.d * b
        k, r = plan.pivots, plan.n_rows
        F = plan.n_fronts
        self.group_of = np.full(F, -1, np.int64)
        self.slot_of_front = np.full(F, -1, np.int64)
        big = k * b >= SINGLE_FRONT
        kp, rp = _pad(k), _pad(r)
        self.K_of = np.where(big, k, kp)  # pivot poses of each front's buffer
        groups = []
        if F:
            order = np.lexsort((np.where(big, np.arange(F), -1), rp, kp, big, plan.height))
            hk = np.stack([plan.height[order], big[order], kp[order], rp[order],
                           np.where(big[order], order, -1)], 1)
            cut = np.flatnonzero(np.any(hk[1:] != hk[:-1], axis=1)) + 1
            groups = np.split(order, cut)
        comp = np.arange(b)
        self.groups: list[_Group] = []
        for gi, fs in enumerate(groups):
            single = bool(big[fs[0]]) or fs.size == 1
            K = int(k[fs[0]]) if single else int(kp[fs[0]])
            R = int(r[fs[0]]) if single else int(rp[fs[0]])
            self.K_of[fs] = K
            self.group_of[fs] = gi
            self.slot_of_front[fs] = np.arange(fs.size)
            t = np.arange(K)
            valid = t[None, :] < k[fs][:, None]
            pos = plan.fptr[fs][:, None] + t[None, :]
            piv = np.where(valid[:, :, None], pos[:, :, None] * b + comp, self.N).reshape(fs.size, K * b)
            t = np.arange(R)
            valid_r = t[None, :] < r[fs][:, None]
            rpos = plan.rows[np.where(valid_r, plan.rptr[fs][:, None] + t[None, :], 0)] if plan.rows.size else \
                np.zeros((fs.size, R), np.int64)
            rowv = np.where(valid_r[:, :, None], rpos[:, :, None] * b + comp, self.N).reshape(fs.size, R * b)
            D = (K + R) * b
            pv = np.flatnonzero(~np.repeat(valid, b, axis=1).reshape(-1))
            s_, v_ = np.divmod(pv, K * b)
            self.groups.append(_Group(fs, K, R, b, piv, rowv, single, s_ * D * D + v_ * D + v_))
        # extend-add maps, all fronts at once
        rf = np.repeat(np.arange(F), r)
        par = plan.parent[rf]
        ok = par >= 0
        loc = np.full(rf.size, -1, np.int64)
        if ok.any():
            loc[ok] = self._pose_local(par[ok], plan.rows[ok])
        relv = (loc[:, None] * b + comp).reshape(-1)
        self.rel = np.split(relv, plan.rptr[1:-1] * b) if F else []
        children = np.argsort(plan.parent, kind="stable")
        nroot = int((plan.parent < 0).sum())
        self.children = np.split(children[nroot:], np.cumsum(np.bincount(plan.parent[plan.parent >= 0],
                                                                          minlength=F))[:-1]) if F else []

    def _pose_local(self, f: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Local pose index of position ``pos`` in front ``f`` (arrays of one shape; pos must be in the
        front): pivots 0 … k−1, update rows K + their rank (K the front's padded pivot count)."""
        plan = self.plan
        is_piv = (pos >= plan.fptr[f]) & (pos < plan.fptr[f + 1])
        d = max(plan.d, 1)
        fr = np.repeat(np.arange(plan.n_fronts), plan.n_rows)
        rank = np.searchsorted(fr * d + plan.rows, f * d + pos) - plan.rptr[f]
        return np.where(is_piv, pos - plan.fptr[f], self.K_of[f] + rank)

    def slots(self, var_index: np.ndarray) -> np.ndarray:
        """Elimination slot of every variable of a system numbered by ``var_index`` (d, b) (variable of
        (free pose, component)): ``out[var_index[i, c]] = position[i]·b + c``."""
        var_index = np.asarray(var_index, np.int64).reshape(self.plan.d, self.b)
        out = np.empty(self.N, np.int64)
        out[var_index.reshape(-1)] = (self.plan.position[:, None] * self.b + np.arange(self.b)).reshape(-1)
        return out

    # ---------------------------------------------------------------------------- assembly
    def block_targets(self, prow: np.ndarray, pcol: np.ndarray):
        """Where the b×b block (prow, pcol) of N (free-pose indices, a pair joined by an edge or a pose
        with itself) lives: ``(group, offset, D, transposed)`` per pair, ``offset`` the flat position of
        the block's (0, 0) entry in the group buffer (lower triangle: row = the later-eliminated pose);
        ``transposed`` True where the stored block is the given block's transpose."""
        plan = self.plan
        pr, pc = plan.position[prow], plan.position[pcol]
        tr = pr < pc
        lo_pos, hi_pos = np.where(tr, pr, pc), np.where(tr, pc, pr)
        f = np.searchsorted(plan.fptr, lo_pos, side="right") - 1
        g = self.group_of[f]
        D = np.array([G.D for G in self.groups], np.int64)[g]
        li = self._pose_local(f, hi_pos)
        lj = lo_pos - plan.fptr[f]
        b = self.b
        offset = self.slot_of_front[f] * D * D + li * b * D + lj * b
        return g, offset, D, tr

    def assembler(self, prow: np.ndarray, pcol: np.ndarray) -> "BlockAssembler":
        """An assembler for matrices given as b×b blocks at the pose pairs (prow[q], pcol[q]) (each
        unordered pair at most once per matrix entry; duplicates are summed)."""
        return BlockAssembler(self, prow, pcol)

    def factor(self, assembler: "BlockAssembler", blocks: np.ndarray, *, progress=None) -> "BlockFactor":
        """Factor N = Σ_q E_q blocks[q] by (MF) (blocks (q, b, b) at the assembler's pose pairs).
        Raises ``NotPositiveDefinite`` if a pivot block is not positive definite."""
        from scipy.linalg import blas, lapack

        values, dest = assembler.scalars(blocks)
        b, nG = self.b, len(self.groups)
        L11, Linv, X = [], [], []
        update = [None] * self.plan.n_fronts  # U_f, until the parent has used it
        for gi, g in enumerate(self.groups):
            B, D, Kb = g.fronts.size, g.D, g.K * b
            Rb = D - Kb
            sl = slice(assembler.gptr[gi], assembler.gptr[gi + 1])
            Fm = np.bincount(np.concatenate([dest[sl], g.pad_diag]),
                             weights=np.concatenate([values[sl], np.ones(g.pad_diag.size)]),
                             minlength=B * D * D).reshape(B, D, D)
            c = np.empty((B, Kb, Kb))
            ci = None if g.single else np.empty((B, Kb, Kb))
            Xi = np.empty((B, Rb, Kb))
            for s_, f in enumerate(g.fronts.tolist()):
                A = Fm[s_]
                for ch in self.children[f].tolist():  # extend-add
                    rel = self.rel[ch]
                    A[rel[:, None], rel] += update[ch]
                    update[ch] = None
                cf, info = lapack.dpotrf(A[:Kb, :Kb].T, lower=0, clean=1)  # Fortran view: upper = Lᵀ
                if info != 0:
                    raise NotPositiveDefinite(f"the matrix is not positive definite (front {f})")
                c[s_] = cf.T
                if ci is not None:
                    ci[s_] = lapack.dtrtri(cf, lower=0)[0].T
                if Rb:
                    Xi[s_] = blas.dtrsm(1.0, cf, A[Kb:, :Kb].T, side=0, lower=0, trans_a=1).T
            if Rb:
                U = Fm[:, Kb:, Kb:] - Xi @ np.swapaxes(Xi, 1, 2)
                for s_, f in enumerate(g.fronts.tolist()):
                    nv = self.rel[f].size
                    update[f] = U[s_, :nv, :nv] if nv < Rb else U[s_]
            L11.append(c)
            Linv.append(ci)
            X.append(Xi)
            if progress is not None:
                progress(gi + 1, nG)
        return BlockFactor(self, L11, Linv, X)


class BlockAssembler:
    """Scalar destinations of b×b blocks at fixed pose pairs (computed once, reused for every matrix of
    that pattern): ``scalars(blocks)`` → (values, flat destinations) sorted by group, ``gptr`` the
    group boundaries."""

    def __init__(self, layout: BlockLayout, prow, pcol):
        self.layout = layout
        b = layout.b
        prow = np.asarray(prow, np.int64)
        pcol = np.asarray(pcol, np.int64)
        g, off, D, tr = layout.block_targets(prow, pcol)
        cr, cc = np.divmod(np.arange(b * b), b)  # entry (cr, cc) of the given block
        # stored at (cr, cc) or, transposed, at (cc, cr)
        rr = np.where(tr[:, None], cc[None, :], cr[None, :])
        ccs = np.where(tr[:, None], cr[None, :], cc[None, :])
        dest = off[:, None] + rr * D[:, None] + ccs
        same = prow == pcol
        keep = np.ones(dest.shape, bool)
        keep[same] = (cr >= cc)[None, :]  # a diagonal block: its lower triangle only
        gg = np.broadcast_to(g[:, None], dest.shape)
        order = np.argsort(gg[keep], kind="stable")
        self.src = np.flatnonzero(keep.reshape(-1))[order]  # index into blocks.reshape(-1)
        self.dest = dest[keep][order]
        self.gptr = np.searchsorted(gg[keep][order], np.arange(len(layout.groups) + 1))
        self.n_blocks = prow.size

    def scalars(self, blocks: np.ndarray):
        blocks = np.asarray(blocks, dtype=float).reshape(self.n_blocks * self.layout.b ** 2)
        return blocks[self.src], self.dest


class BlockFactor:
    """N = L Lᵀ by (MF): ``solve(rhs)`` for rhs (N,) or (N, r) in elimination-slot order (see
    ``BlockLayout``); ``selected_inverse`` the entries of N⁻¹ on the pattern of L (T)."""

    def __init__(self, layout: BlockLayout, L11, Linv, X):
        self.layout = layout
        self.L11, self.Linv, self.X = L11, Linv, X

    def solve(self, rhs: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """Solve N x = rhs for rhs (N,) or (N, r) in a system's own variable numbering, ``slots`` its
        elimination slots (``BlockLayout.slots``)."""
        rhs = np.asarray(rhs, dtype=float)
        return self.solve_slots(rhs[np.argsort(slots)])[slots]

    def _levels(self):
        """The factor regrouped for solves: per height of the front tree, all its fronts padded to the
        level's largest pivot and row counts, with L_PP⁻¹ (identity on padding) and X (zero on padding)
        — a solve then costs a few stacked products per level, whatever the number of fronts."""
        from scipy.linalg import lapack

        cache = self.__dict__.get("_level_cache")
        if cache is not None:
            return cache
        lay = self.layout
        b, N = lay.b, lay.N
        height = lay.plan.height
        levels = []
        by_level: dict[int, list] = {}
        for gi, g in enumerate(lay.groups):
            by_level.setdefault(int(height[g.fronts[0]]), []).append(gi)
        for h in sorted(by_level):
            gis = by_level[h]
            Kb = max(lay.groups[gi].K * b for gi in gis)
            Rb = max(lay.groups[gi].R * b for gi in gis)
            Bt = sum(lay.groups[gi].fronts.size for gi in gis)
            Li = np.zeros((Bt, Kb, Kb))
            Li[:, np.arange(Kb), np.arange(Kb)] = 1.0
            X = np.zeros((Bt, Rb, Kb))
            piv = np.full((Bt, Kb), N, np.int64)
            rowv = np.full((Bt, Rb), N, np.int64)
            o = 0
            for gi in gis:
                g = lay.groups[gi]
                B, kb, rb = g.fronts.size, g.K * b, g.R * b
                ci = self.Linv[gi]
                if ci is None:
                    ci = np.tril(lapack.dtrtri(self.L11[gi][0], lower=1)[0])[None]
                Li[o:o + B, :kb, :kb] = ci
                X[o:o + B, :rb, :kb] = self.X[gi]
                piv[o:o + B, :kb] = g.piv
                rowv[o:o + B, :rb] = g.rowv
                o += B
            levels.append((Li, X, piv, rowv))
        self._level_cache = levels
        return levels

    def solve_slots(self, y: np.ndarray) -> np.ndarray:
        """Solve N x = y with y (N,) or (N, r) indexed by elimination slots; returns x likewise."""
        lay = self.layout
        one = y.ndim == 1
        r = 1 if one else y.shape[1]
        Y = np.zeros((lay.N + 1, r))
        Y[:-1] = y.reshape(lay.N, r)
        levels = self._levels()
        n1 = lay.N + 1
        for Li, X, piv, rowv in levels:  # forward: z_P = L_PP⁻¹ y_P, y_R −= X z_P
            z = Li @ Y[piv]
            Y[piv] = z
            if X.shape[1]:
                upd = (X @ z).reshape(-1, r)
                idx = rowv.reshape(-1)
                for j in range(r):
                    Y[:, j] -= np.bincount(idx, upd[:, j], minlength=n1)
            Y[-1] = 0.0
        for Li, X, piv, rowv in reversed(levels):  # back: x_P = L_PP⁻ᵀ (z_P − Xᵀ x_R)
            z = Y[piv]
            if X.shape[1]:
                z = z - np.swapaxes(X, 1, 2) @ Y[rowv]
            Y[piv] = np.swapaxes(Li, 1, 2) @ z
            Y[-1] = 0.0
        out = Y[:-1]
        return out[:, 0] if one else out

    def selected_inverse(self, *, progress=None):
        """Σ = N⁻¹ on every front by (T), from the root down. Returns, per group, the dense front blocks
        Σ_f (B, D, D) in the group's local variable order (zero on padded variables)."""
        from scipy.linalg import lapack

        lay = self.layout
        nG = len(lay.groups)
        sig: list = [None] * nG
        for gi in range(nG - 1, -1, -1):
            g = lay.groups[gi]
            B, D, Kb = g.fronts.size, g.D, g.K * lay.b
            Rb = D - Kb
            c, ci, X = self.L11[gi], self.Linv[gi], self.X[gi]
            if ci is None:
                ci = np.tril(lapack.dtrtri(c[0], lower=1)[0])[None]
            S = np.zeros((B, D, D))
            if Rb:
                SRR = np.zeros((B, Rb, Rb))
                for s_, f in enumerate(g.fronts.tolist()):
                    p = lay.plan.parent[f]
                    rel = lay.rel[f]
                    nv = rel.size
                    SRR[s_, :nv, :nv] = sig[lay.group_of[p]][lay.slot_of_front[p]][rel[:, None], rel]
                Y = X @ ci
                SRP = -(SRR @ Y)
                S[:, :Kb, :Kb] = np.swapaxes(ci, 1, 2) @ ci - np.swapaxes(Y, 1, 2) @ SRP
                S[:, Kb:, Kb:] = SRR
                S[:, Kb:, :Kb] = SRP
                S[:, :Kb, Kb:] = np.swapaxes(SRP, 1, 2)
            else:
                S[:, :Kb, :Kb] = np.swapaxes(ci, 1, 2) @ ci
            sig[gi] = S
            if progress is not None:
                progress(nG - gi, nG)
        return sig


def inverse_blocks(factor: BlockFactor, prow=None, pcol=None, *, progress=None):
    """Blocks of Σ = N⁻¹ by selected inversion (T): ``diag`` (d, b, b) the b×b block of every pose (in
    pose order) and, when ``prow``/``pcol`` (q,) are given — pose pairs on the pattern of L, e.g. the
    ends of edges — ``pairs`` (q, b, b) with pairs[t] = Σ[prow[t], pcol[t]] (rows: prow's variables).
    Returns ``(diag, pairs)`` (``pairs`` None without pairs)."""
    lay = factor.layout
    plan, b = lay.plan, lay.b
    sig = factor.selected_inverse(progress=progress)
    pose_at = np.empty(plan.d, np.int64)
    pose_at[plan.position] = np.arange(plan.d)
    diag = np.zeros((plan.d, b, b))
    for g, S in zip(lay.groups, sig):
        B, K = g.fronts.size, g.K
        Sr = S[:, :K * b, :K * b].reshape(B, K, b, K, b)
        t = np.arange(K)
        blk = Sr[:, t, :, t, :]  # (K, B, b, b)
        pos = g.piv[:, ::b].T  # (K, B) slots of component 0
        ok = pos < lay.N
        diag[pose_at[pos[ok] // b]] = blk[ok]
    pairs = None
    if prow is not None:
        grp, off, D, tr = lay.block_targets(np.asarray(prow, np.int64), np.asarray(pcol, np.int64))
        cr, cc = np.divmod(np.arange(b * b), b)
        rr = np.where(tr[:, None], cc[None, :], cr[None, :])
        ccs = np.where(tr[:, None], cr[None, :], cc[None, :])
        flat = off[:, None] + rr * D[:, None] + ccs
        pairs = np.empty((grp.size, b * b))
        for gi in np.unique(grp):
            sel = grp == gi
            pairs[sel] = sig[gi].reshape(-1)[flat[sel]]
        pairs = pairs.reshape(-1, b, b)
    return diag, pairs

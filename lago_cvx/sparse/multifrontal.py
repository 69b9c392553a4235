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
factored together by stacked calls (Cholesky, products), with a few NumPy calls per front left (the
extend-add of its children, L_PP⁻¹ by ``trtri``). Large fronts are factored one by one with exact sizes
(``potrf``/``trsm``/``syrk``) on every BLAS thread, small ones on one (``linalg.blas_threads``).

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

from .block_factor import BlockFactor, inverse_blocks
from .linalg import NotPositiveDefinite, blas_threads

__all__ = ["EliminationPlan", "BlockLayout", "BlockFactor", "plan_from_qdldl", "plan_from_pattern", "NotPositiveDefinite",
           "inverse_blocks"]

log = logging.getLogger(__name__)

#: Relaxed amalgamation (CHOLMOD's defaults): a child front is merged into its parent when the merged
#: front has at most NRELAX[0] pivots, or at most NRELAX[1] pivots and a fraction of explicit zeros
#: below ZRELAX[0], at most NRELAX[2] and below ZRELAX[1], or any size below ZRELAX[2].
NRELAX = (4, 16, 48)
ZRELAX = (0.8, 0.1, 0.05)

#: The amalgamation for the compiled engine (``lago_cvx.sparse.compiled``), whose cost per front is a few hundred
#: nanoseconds, not a Python call: fewer explicit zeros, so a smaller L (less memory to fault in, shorter
#: solves) for the same factorization time (phase 3 of the 1 000 000-pose world: L 1.85 GiB with ``NRELAX``/
#: ``ZRELAX``, 1.48 GiB with these; tighter still cost time). Whole runs: ``benchmarks/million.md``.
COMPILED_RELAX = ((2, 8, 32), (0.8, 0.1, 0.05))

#: Fronts with at least this many pivot variables (k·b) are factored one at a time with exact sizes;
#: smaller ones are padded and batched.
SINGLE_FRONT = 96

#: Fronts with at least this many pivot variables are factored with every BLAS thread; smaller ones
#: with one — when the caller let the engine set the BLAS threads (``threads.engine_threads``): threads cost far
#: more than they give on small dense blocks (``benchmarks/million.md``).
THREADED_FRONT = 384

#: Pose-count ladder the small fronts are padded to (steps of about 1.25).
_LADDER = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112,
                    128, 160, 192, 224, 256, 320, 384, 448, 512, 640, 768, 896, 1024])


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
    """``supernodes.postorder`` of an elimination tree (parent[i] > i, −1 at roots), O(n) at every shape (a star
    as a chain; ``csgraph.depth_first_order`` is quadratic on a star)."""
    return _loops()[2](np.ascontiguousarray(parent, np.int64))


def _loops():
    """``supernodes.relax``, ``supernodes.heights`` and ``supernodes.postorder``: in C when the kernels are built
    (``compiled.available()``), else as Python (the same integer loops and floating-point operations: the same plan
    either way, tested)."""
    from . import compiled, supernodes

    if compiled.available():
        K = compiled.kernels()
        return K["relax"], K["heights"], K["postorder"]
    return supernodes.relax, supernodes.heights, supernodes.postorder


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


def plan_from_qdldl(L: sp.csc_matrix, perm: np.ndarray, *, relaxation=None) -> EliminationPlan:
    """The plan from a pose-level factorization ``P A Pᵀ = (I + L) D (I + L)ᵀ`` as ``qdldl.Solver.factors()``
    returns it: ``L`` (d, d) strictly lower (CSC, columns and rows in elimination order, any row order
    within a column), ``perm`` (d,) the pose eliminated at each position. ``relaxation`` (nrelax, zrelax)
    of the amalgamation, default (``NRELAX``, ``ZRELAX``); ``COMPILED_RELAX`` for the compiled engine."""
    nrelax, zrelax = (NRELAX, ZRELAX) if relaxation is None else relaxation
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
    relax, heights, _ = _loops()
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
    src = np.repeat(ip[col_old], lens) + _seg_arange(lens)
    fr = np.repeat(np.arange(n_fronts), lens)
    key = np.sort(fr * max(d, 1) + newpos[post[ix[src]]])
    rows = key - fr * max(d, 1)
    rptr = np.r_[0, np.cumsum(lens)].astype(np.int64)
    sp_top = sparent[fronts]
    fparent = np.where(sp_top >= 0, fid[top[np.maximum(sp_top, 0)]], -1)
    height = np.asarray(heights(fparent.astype(np.int64)), np.int64)
    position = np.empty(d, np.int64)
    position[np.asarray(perm, np.int64)] = newpos[post]  # pose → old position → postorder → final
    return EliminationPlan(d=d, position=position, fptr=fptr, rptr=rptr, rows=rows, parent=fparent,
                           height=height)


def plan_from_pattern(d: int, rows: np.ndarray, cols: np.ndarray, *, relaxation=None) -> EliminationPlan:
    """The plan of the d × d pose pattern with off-diagonal entries (rows[k], cols[k]) (either
    orientation, duplicates allowed): AMD and the factor's pattern from QDLDL on a diagonally dominant
    matrix of that pattern; ``relaxation`` as in ``plan_from_qdldl``."""
    import qdldl

    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    keep = rows != cols
    lo, hi = np.minimum(rows[keep], cols[keep]), np.maximum(rows[keep], cols[keep])
    deg = np.bincount(np.r_[lo, hi], minlength=d).astype(float)
    A = sp.csc_matrix((np.r_[-np.ones(lo.size), deg + 1.0], (np.r_[lo, np.arange(d)], np.r_[hi, np.arange(d)])),
                      shape=(d, d))
    A.sum_duplicates()
    s = qdldl.Solver(A, upper=True)
    L, _, perm = s.factors()
    return plan_from_qdldl(L, perm, relaxation=relaxation)


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
        Raises ``NotPositiveDefinite`` if a pivot block is not positive definite.

        Only lower triangles are kept: the assembly writes N's lower triangle, an update U_f is passed
        on as its lower-triangle entries (rel is increasing, so they land in the parent's lower
        triangle), and every kernel reads the lower triangle. A batch of small fronts is factored by
        stacked LAPACK calls (one Python call per group); a large front by potrf, trsm and syrk, with
        the BLAS threads ``blas_threads`` allows."""
        from scipy.linalg import blas, lapack

        blocks = np.asarray(blocks, dtype=float).reshape(assembler.n_blocks, self.b, self.b)
        b, nG = self.b, len(self.groups)
        L11, Linv, X = [], [], []
        update = [None] * self.plan.n_fronts  # lower-triangle entries of U_f, until the parent adds them
        tri: dict = {}
        work = np.empty(max((G.fronts.size * G.D * G.D for G in self.groups), default=0))
        with blas_threads(1) as threads:
            for gi, g in enumerate(self.groups):
                B, D, Kb = g.fronts.size, g.D, g.K * b
                Rb = D - Kb
                dest, values = assembler.group(gi, blocks)
                Fm = work[:B * D * D]  # one buffer for every group: no fresh pages to fault in
                Fm.fill(0.0)
                np.add.at(Fm, dest, values)
                Fm[g.pad_diag] = 1.0
                for s_, f in enumerate(g.fronts.tolist()):  # extend-add, flat indices into the front
                    base = s_ * D * D
                    for ch in self.children[f].tolist():
                        rel = self.rel[ch]
                        ii, jj = _tril(tri, rel.size)
                        Fm[base + rel[ii] * D + rel[jj]] += update[ch]
                        update[ch] = None
                Fm = Fm.reshape(B, D, D)
                if g.single:
                    threads(None if Kb >= THREADED_FRONT else 1)
                    A = Fm[0]
                    cf, info = lapack.dpotrf(A[:Kb, :Kb].T, lower=0, clean=1)  # Fortran: upper = Lᵀ
                    if info != 0:
                        raise NotPositiveDefinite(f"the matrix is not positive definite (front {g.fronts[0]})")
                    c, ci = cf.T[None], None
                    Xi = np.empty((1, Rb, Kb))
                    if Rb:
                        Xt = blas.dtrsm(1.0, cf, A[Kb:, :Kb].T, side=0, lower=0, trans_a=1)  # Xᵀ (Kb, Rb)
                        Xi[0] = Xt.T
                        U = blas.dsyrk(-1.0, Xt, beta=1.0, c=A[Kb:, Kb:].T, trans=1, lower=0,
                                       overwrite_c=1).T[None]  # upper of the transpose = lower of U
                    threads(1)
                else:
                    try:
                        c = np.linalg.cholesky(Fm[:, :Kb, :Kb])
                    except np.linalg.LinAlgError:
                        raise NotPositiveDefinite("the matrix is not positive definite (fronts "
                                                  f"{g.fronts[0]}…{g.fronts[-1]})") from None
                    ci = np.empty_like(c)
                    for s_ in range(B):  # L_PP⁻¹ front by front (faster than a stacked general inverse)
                        ci[s_] = lapack.dtrtri(c[s_].T, lower=0)[0].T
                    Xi = Fm[:, Kb:, :Kb] @ np.swapaxes(ci, 1, 2)
                    if Rb:
                        U = Fm[:, Kb:, Kb:] - Xi @ np.swapaxes(Xi, 1, 2)
                if Rb:
                    for s_, f in enumerate(g.fronts.tolist()):
                        ii, jj = _tril(tri, self.rel[f].size)
                        update[f] = U[s_][ii, jj]
                L11.append(c)
                Linv.append(ci)
                X.append(Xi)
                if progress is not None:
                    progress(gi + 1, nG)
        return BlockFactor(self, L11, Linv, X)


def _tril(cache: dict, n: int):
    """``np.tril_indices(n)``, cached per n."""
    t = cache.get(n)
    if t is None:
        t = cache[n] = np.tril_indices(n)
    return t


class BlockAssembler:
    """Where b×b blocks at fixed pose pairs go in the fronts (computed once, reused for every matrix of
    that pattern): the blocks sorted by group (``order``), each block's flat offset in its group buffer
    (``offset``) and whether it is stored transposed (``transposed``); ``gptr`` the group boundaries.
    A block is added whole at its place in the lower triangle; on a diagonal block that also writes
    the upper triangle, which no kernel reads."""

    def __init__(self, layout: BlockLayout, prow, pcol):
        self.layout = layout
        prow = np.asarray(prow, np.int64)
        pcol = np.asarray(pcol, np.int64)
        g, off, _, tr = layout.block_targets(prow, pcol)
        # a stable radix sort of the blocks on their (small integer) group
        self.order = np.argsort(g.astype(np.int16 if len(layout.groups) < 2 ** 15 else np.int32), kind="stable")
        self.offset = off[self.order]
        self.transposed = tr[self.order]
        self.gptr = np.r_[0, np.cumsum(np.bincount(g, minlength=len(layout.groups)))]
        self.n_blocks = prow.size

    def group(self, gi: int, blocks: np.ndarray):
        """(flat destinations, values) of group ``gi``'s blocks of ``blocks`` (q, b, b)."""
        sl = slice(self.gptr[gi], self.gptr[gi + 1])
        vals = blocks[self.order[sl]]
        tr = self.transposed[sl]
        if tr.any():
            vals[tr] = np.swapaxes(vals[tr], 1, 2)
        b, D = self.layout.b, self.layout.groups[gi].D
        local = np.arange(b)[:, None] * D + np.arange(b)
        return (self.offset[sl][:, None, None] + local).reshape(-1), vals.reshape(-1)
